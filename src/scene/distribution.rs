//! `attractors.distribution`: how random starts (`starts = N`) are drawn
//! over the box, so that the basin fractions estimate basin stability
//! (Menck, Heitzig, Marwan and Kurths, Nat. Phys. 9, 89, 2013): the
//! probability that a start drawn from the distribution ends on each
//! attractor, with its binomial standard error √(f(1-f)/N).
//!
//! - `{ kind = "uniform" }` (the default): uniform in the box.
//! - `{ kind = "normal", mean = { x = …, … }, sd = { x = …, … } }`: each
//!   state of the box drawn from a normal distribution, truncated to the
//!   box (a draw outside it is drawn again): the box stays the states a
//!   start may take.

use std::collections::BTreeMap;

use serde::Deserialize;

use crate::error::{number, Error, Result};

/// `attractors.distribution` as the file gives it.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawDistribution {
    kind: String,
    mean: Option<BTreeMap<String, f64>>,
    sd: Option<BTreeMap<String, f64>>,
}

/// How random starts are drawn over the box.
#[derive(Clone, Debug, Default, PartialEq)]
pub enum Distribution {
    /// Uniform in the box.
    #[default]
    Uniform,
    /// Normal along each state of the box, (mean, sd) in the box's order,
    /// truncated to the box.
    Normal(Vec<(f64, f64)>),
}

/// The widest normal accepted, in widths of the box along its state: a
/// wider one is nearly uniform over the box (and a truncated draw would
/// take hundreds of tries).
const WIDEST: f64 = 100.0;

impl RawDistribution {
    /// The distribution checked against the box (`bounds`: state index,
    /// low, high; `names`: the states' names), every error naming its key.
    pub(super) fn resolve(
        self,
        bounds: &[(usize, f64, f64)],
        names: &[String],
    ) -> Result<Distribution> {
        match self.kind.as_str() {
            "uniform" => {
                for (given, key) in [(&self.mean, "mean"), (&self.sd, "sd")] {
                    if given.is_some() {
                        return Err(Error::invalid(
                            format!("attractors.distribution.{key}"),
                            "applies to kind = \"normal\", not to \"uniform\"",
                        ));
                    }
                }
                Ok(Distribution::Uniform)
            }
            "normal" => {
                let mean = self.mean.unwrap_or_default();
                let sd = self.sd.unwrap_or_default();
                normal(&mean, &sd, bounds, names).map(Distribution::Normal)
            }
            other => Err(Error::invalid(
                "attractors.distribution.kind",
                format!("must be \"uniform\" or \"normal\", got \"{other}\""),
            )),
        }
    }
}

/// A normal's (mean, sd) per state of the box: each given for every state
/// the box names and no other, the mean finite within the box, the sd
/// positive and at most [`WIDEST`] of the box's widths.
fn normal(
    mean: &BTreeMap<String, f64>,
    sd: &BTreeMap<String, f64>,
    bounds: &[(usize, f64, f64)],
    names: &[String],
) -> Result<Vec<(f64, f64)>> {
    let boxed: Vec<&str> = bounds.iter().map(|b| names[b.0].as_str()).collect();
    for (table, key) in [(mean, "mean"), (sd, "sd")] {
        if let Some(name) = table.keys().find(|n| !boxed.contains(&n.as_str())) {
            return Err(Error::invalid(
                format!("attractors.distribution.{key}.{name}"),
                format!("is not a state of the box ({})", boxed.join(", ")),
            ));
        }
    }
    bounds
        .iter()
        .map(|&(i, lo, hi)| {
            let name = &names[i];
            let given = |table: &BTreeMap<String, f64>, key: &str| {
                table.get(name).copied().ok_or_else(|| {
                    Error::invalid(
                        format!("attractors.distribution.{key}"),
                        format!("needs a value for {name}, a state of the box"),
                    )
                })
            };
            let (m, s) = (given(mean, "mean")?, given(sd, "sd")?);
            if !(lo..=hi).contains(&m) {
                return Err(Error::invalid(
                    format!("attractors.distribution.mean.{name}"),
                    format!(
                        "must lie within the box's [{}, {}], got {}",
                        number(lo),
                        number(hi),
                        number(m)
                    ),
                ));
            }
            let widest = WIDEST * (hi - lo);
            if !(s > 0.0 && s <= widest) {
                return Err(Error::invalid(
                    format!("attractors.distribution.sd.{name}"),
                    format!(
                        "must be positive and at most {WIDEST} times the box's width ({}), got {}",
                        number(widest),
                        number(s)
                    ),
                ));
            }
            Ok((m, s))
        })
        .collect()
}

impl Distribution {
    /// One start: the box's states drawn from the distribution with `rng`,
    /// the others at `initial_state`.
    pub(super) fn draw(
        &self,
        rng: &mut fastrand::Rng,
        bounds: &[(usize, f64, f64)],
        initial_state: &[f64],
    ) -> Vec<f64> {
        let mut state = initial_state.to_vec();
        for (k, &(i, lo, hi)) in bounds.iter().enumerate() {
            state[i] = match self {
                Distribution::Uniform => lo + (hi - lo) * rng.f64(),
                Distribution::Normal(params) => {
                    let (mean, sd) = params[k];
                    loop {
                        let x = mean + sd * standard_normal(rng);
                        if (lo..=hi).contains(&x) {
                            break x;
                        }
                    }
                }
            };
        }
        state
    }
}

/// A standard normal number by the Box–Muller transform (1 - u keeps the
/// logarithm's argument in (0, 1]).
fn standard_normal(rng: &mut fastrand::Rng) -> f64 {
    let (u, v) = (1.0 - rng.f64(), rng.f64());
    (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Box–Muller's numbers have the standard normal's mean, variance and
    /// share within one sd (0.6827) to their sampling error; a normal
    /// truncated to the box stays in it.
    #[test]
    fn normal_draws_have_the_normal_s_moments_and_stay_in_the_box() {
        let mut rng = fastrand::Rng::with_seed(3);
        let n = 200_000;
        let z: Vec<f64> = (0..n).map(|_| standard_normal(&mut rng)).collect();
        let mean = z.iter().sum::<f64>() / n as f64;
        let variance = z.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n as f64;
        let within = z.iter().filter(|x| x.abs() <= 1.0).count() as f64 / n as f64;
        assert!(mean.abs() < 5.0 / (n as f64).sqrt(), "{mean}");
        assert!((variance - 1.0).abs() < 0.02, "{variance}");
        assert!((within - 0.6827).abs() < 0.005, "{within}");
        let normal = Distribution::Normal(vec![(1.8, 0.5)]);
        for _ in 0..1000 {
            let x = normal.draw(&mut rng, &[(0, -3.0, 1.9)], &[0.0, 0.0])[0];
            assert!((-3.0..=1.9).contains(&x), "{x}");
        }
    }
}
