//! The basin images of `attractors.basins`: for each of the first values,
//! `basins-<k>.npy` (k the value's index in the grid's order), every
//! start's label as a 2-D array of little-endian i32 in NumPy's format
//! (`numpy.load` reads it; rows along the second state, columns along the
//! first), and with figures on `basins-<k>.png` and `.svg`; the measures
//! of each value go to `attractors.csv` (see `attractor_table`).

use std::io::Write;
use std::path::{Path, PathBuf};

use super::files::{number, write_file};
use crate::attractor::basins::{self, BasinImage, Entropy, Uncertainty};
use crate::attractor::Attractors;
use crate::error::Result;
use crate::scene::{Layout, Scene};

/// The prefix of the basin files' names.
pub const BASINS_PREFIX: &str = "basins-";

/// The labels file of value `point`.
pub fn labels_file(point: usize) -> String {
    format!("{BASINS_PREFIX}{point}.npy")
}

/// Whether `name` is a basin file lyapsweep writes with this extension
/// (`npy`, `png` or `svg`): `basins-<k>.<extension>`.
pub fn is_basin_file(name: &str, extension: &str) -> bool {
    name.strip_prefix(BASINS_PREFIX)
        .and_then(|rest| rest.strip_suffix(extension))
        .and_then(|rest| rest.strip_suffix('.'))
        .is_some_and(|k| !k.is_empty() && k.bytes().all(|b| b.is_ascii_digit()))
}

/// One value's labels and the measures read from them.
pub struct ValueBasins {
    pub image: BasinImage,
    pub entropy: Entropy,
    pub uncertainty: Option<Uncertainty>,
}

/// The basin images of the first `attractors.basins` values (none for a
/// scene without them).
pub fn value_basins(scene: &Scene, found: &Attractors) -> Vec<ValueBasins> {
    let Some(starts) = &scene.sweep.starts else {
        return Vec::new();
    };
    let Layout::Grid { counts } = &starts.layout else {
        return Vec::new();
    };
    let values = starts.basins.values.min(found.values.len());
    if values == 0 || counts.len() != 2 {
        return Vec::new();
    }
    (0..values)
        .map(|point| {
            let image = basins::image(found, point, (counts[0], counts[1]));
            let entropy = basins::entropy(&image, starts.basins.box_side);
            let uncertainty = basins::uncertainty(&image);
            ValueBasins {
                image,
                entropy,
                uncertainty,
            }
        })
        .collect()
}

/// The bytes of a 2-D array of i32 in NumPy's `.npy` format, version 1.0:
/// the magic string, the header's length, a Python dict naming the type,
/// the order and the shape, padded with spaces to a multiple of 64 bytes
/// ending in a newline, then the numbers.
pub fn npy_bytes(image: &BasinImage) -> Vec<u8> {
    let mut header = format!(
        "{{'descr': '<i4', 'fortran_order': False, 'shape': ({}, {}), }}",
        image.ny, image.nx
    );
    let unpadded = 10 + header.len() + 1;
    header.push_str(&" ".repeat((64 - unpadded % 64) % 64));
    header.push('\n');
    let mut bytes = Vec::with_capacity(10 + header.len() + 4 * image.labels.len());
    bytes.extend_from_slice(b"\x93NUMPY\x01\x00");
    bytes.extend_from_slice(&(header.len() as u16).to_le_bytes());
    bytes.extend_from_slice(header.as_bytes());
    for label in &image.labels {
        bytes.extend_from_slice(&label.to_le_bytes());
    }
    bytes
}

/// Writes each value's labels into `dir`; returns the paths.
pub fn write_labels(basins: &[ValueBasins], dir: &Path) -> Result<Vec<PathBuf>> {
    let mut written = Vec::new();
    for (point, value) in basins.iter().enumerate() {
        let path = dir.join(labels_file(point));
        let bytes = npy_bytes(&value.image);
        write_file(&path, |file| file.write_all(&bytes))?;
        written.push(path);
    }
    Ok(written)
}

/// Draws each value's basin image into `dir`; returns the paths.
pub fn draw(
    scene: &Scene,
    found: &Attractors,
    basins: &[ValueBasins],
    dir: &Path,
) -> Result<Vec<PathBuf>> {
    let starts = scene.sweep.starts.as_ref().expect("basins need starts");
    let [ax, ay] = starts.basins.axes;
    let mut written = Vec::new();
    for (point, value) in basins.iter().enumerate() {
        let (nx, ny) = (value.image.nx, value.image.ny);
        let x = (0..nx).map(|i| starts.states[i][ax]).collect();
        let y = (0..ny).map(|j| starts.states[j * nx][ay]).collect();
        let at: Vec<String> = scene
            .sweep
            .axes()
            .zip(scene.sweep.values_at_point(point))
            .map(|(axis, v)| format!("{} = {}", axis.parameter, number(v)))
            .collect();
        let data = super::plot::BasinData {
            title: format!(
                "{}: basins at {} (S_b {:.3}, S_bb {:.3})",
                scene.name,
                at.join(", "),
                value.entropy.basin,
                value.entropy.boundary
            ),
            x_name: scene.system.state_names[ax].to_string(),
            y_name: scene.system.state_names[ay].to_string(),
            x,
            y,
            labels: value.image.labels.clone(),
            entries: entries(found, point, &value.image),
        };
        let stem = format!("{BASINS_PREFIX}{point}");
        written.extend(super::plot::basin_map(&data, dir, &stem)?);
    }
    Ok(written)
}

/// The labels of an image in the order of their attractors at the value,
/// failed lanes and inadmissible starts last, each with what the caption
/// says of it: period, impacts a period, λ1 and the basin fraction (of the
/// admissible starts, as in `attractors.csv`).
fn entries(found: &Attractors, point: usize, image: &BasinImage) -> Vec<(i32, String)> {
    let count = |label: i32| image.labels.iter().filter(|&&l| l == label).count() as f64;
    let inadmissible = count(basins::INADMISSIBLE);
    let admissible = image.labels.len() as f64 - inadmissible;
    let share = |label: i32| count(label) / admissible;
    let mut entries: Vec<(i32, String)> = Vec::new();
    for a in &found.values[point].attractors {
        let Some(branch) = a.branch else { continue };
        let label = branch as i32;
        if entries.iter().any(|e| e.0 == label) || share(label) == 0.0 {
            continue;
        }
        let lane = &a.first.lane;
        let period = lane
            .orbit_period
            .map_or("aperiodic".to_owned(), |p| format!("period {p}"));
        let lambda1 = lane
            .exponents
            .first()
            .map_or(String::new(), |l| format!(", λ1 {l:.3}"));
        entries.push((
            label,
            format!(
                "branch {label}: {period}, {} impacts{lambda1}, {:.1}%",
                number(lane.impacts_per_period),
                100.0 * share(label)
            ),
        ));
    }
    let failed = share(basins::FAILED);
    if failed > 0.0 {
        entries.push((
            basins::FAILED,
            format!("grey: failed, {:.1}%", 100.0 * failed),
        ));
    }
    if inadmissible > 0.0 {
        entries.push((
            basins::INADMISSIBLE,
            format!(
                "dark: outside the admissible states (not run), {:.1}% of the grid",
                100.0 * inadmissible / image.labels.len() as f64
            ),
        ));
    }
    entries
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The header is padded to 64 bytes and names the shape rows first.
    #[test]
    fn npy_header_is_aligned_and_names_the_shape() {
        let image = BasinImage {
            nx: 3,
            ny: 2,
            labels: vec![0, 1, -1, 2, 0, 1],
        };
        let bytes = npy_bytes(&image);
        let header_len = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
        assert_eq!((10 + header_len) % 64, 0);
        let header = std::str::from_utf8(&bytes[10..10 + header_len]).unwrap();
        assert!(header.contains("'shape': (2, 3)"), "{header}");
        assert!(header.ends_with('\n'));
        assert_eq!(bytes.len(), 10 + header_len + 24);
        assert_eq!(&bytes[10 + header_len + 8..][..4], &(-1i32).to_le_bytes());
        assert!(is_basin_file("basins-12.npy", "npy"));
        assert!(!is_basin_file("basins-.npy", "npy"));
        assert!(!is_basin_file("basins-1x.png", "png"));
    }
}
