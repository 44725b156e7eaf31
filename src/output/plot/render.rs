//! The drawing backend's choice: each figure is drawn by one function
//! generic over plotters' `DrawingBackend`, into memory as RGB pixels (the
//! PNG, and what the tests read) or as SVG text (bitmaps embedded as PNG
//! images, see [`svg_raster`]); both files are written whole.

use std::fs;
use std::io;
use std::path::{Path, PathBuf};

use plotters::coord::Shift;
use plotters::prelude::*;

use super::figure::{encode_png, register_font};
use super::svg_raster;
use crate::error::{Error, Result};

/// A figure of a fixed size that any plotters backend can draw.
pub(super) trait Figure {
    const SIZE: (u32, u32);
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Drawn<DB>;
}

/// What a drawing step returns: plotters' error for the backend in use.
pub(super) type Drawn<DB> =
    std::result::Result<(), DrawingAreaErrorKind<<DB as DrawingBackend>::ErrorType>>;

/// Draws `figure` as `<dir>/<stem>.png` and `.svg`. Both are drawn under
/// temporary names before either is renamed, so a failed drawing leaves
/// neither a figure nor a temporary behind.
pub(super) fn write<F: Figure>(figure: &F, dir: &Path, stem: &str) -> Result<Vec<PathBuf>> {
    let png = dir.join(format!("{stem}.png"));
    let svg = dir.join(format!("{stem}.svg"));
    let temporary = |extension: &str| {
        dir.join(format!(
            ".{stem}.{}.partial.{extension}",
            std::process::id()
        ))
    };
    let (png_partial, svg_partial) = (temporary("png"), temporary("svg"));
    let failed = |path: &Path| {
        let path = path.to_owned();
        move |source| Error::Write { path, source }
    };
    let result = write_png(&png_partial, &pixels(figure), F::SIZE)
        .map_err(failed(&png))
        .and_then(|()| render_svg(figure, &svg_partial).map_err(failed(&svg)))
        .and_then(|()| fs::rename(&png_partial, &png).map_err(failed(&png)))
        .and_then(|()| fs::rename(&svg_partial, &svg).map_err(failed(&svg)));
    if result.is_err() {
        for partial in [&png_partial, &svg_partial] {
            let _ = fs::remove_file(partial);
        }
    }
    result.map(|()| vec![png, svg])
}

/// Draws `figure` as SVG into `file` (bitmaps embedded as PNG images, see
/// [`svg_raster`]), and flushes that file to disk so that the rename that
/// follows never exposes an empty figure.
pub(super) fn render_svg<F: Figure>(figure: &F, file: &Path) -> io::Result<()> {
    register_font();
    let text = svg_raster::render(F::SIZE, |root| {
        figure.draw(&root).and_then(|()| root.present())
    })
    .map_err(|e| io::Error::other(e.to_string()))?;
    let mut out = fs::File::create(file)?;
    io::Write::write_all(&mut out, text.as_bytes())?;
    out.sync_all()
}

/// Writes RGB `pixels` of `size` as a PNG file, flushed to disk.
pub fn write_png(file: &Path, pixels: &[u8], size: (u32, u32)) -> io::Result<()> {
    let encoded = encode_png(pixels, size)?;
    let mut out = fs::File::create(file)?;
    io::Write::write_all(&mut out, &encoded)?;
    out.sync_all()
}

/// Draws `figure` into memory as RGB pixels.
pub(super) fn pixels<F: Figure>(figure: &F) -> Vec<u8> {
    register_font();
    let (width, height) = F::SIZE;
    let mut buffer = vec![0; width as usize * height as usize * 3];
    let root = BitMapBackend::with_buffer(&mut buffer, F::SIZE).into_drawing_area();
    figure
        .draw(&root)
        .and_then(|()| root.present())
        .unwrap_or_else(|e| panic!("drawing into memory with the embedded font cannot fail: {e}"));
    drop(root);
    buffer
}
