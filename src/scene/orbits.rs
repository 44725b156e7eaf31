//! `[orbits]`: periodic orbits followed through the sweep's range, stable
//! and unstable, with their bifurcations (`crate::orbit`). An empty table
//! asks for the defaults: every periodic orbit the sweep's lanes end on
//! (with `[attractors]`, every periodic attractor), each branch once.
//! With `[sweep.second]`, branches are followed in the first parameter at
//! every value of the second, each value's from its own lanes, and a
//! listed orbit names its second value (`second = 1.0`).
//!
//! ```toml
//! [orbits]
//! from_sweep = true        # start from the sweep's periodic orbits
//! list = [{ value = 0.6, state = [1.2, 0.3], period = 1 }]   # and these
//! max_period = 12          # longest period traced (map iterations)
//! max_points = 400         # points a branch takes each way
//! min_step = 1e-9          # arclength steps (default: the range × 1e-9
//! max_step = 0.02          #   and the range / 50)
//! tolerance = 1e-10        # Newton's residual, relative to max(1, |x|)
//! locate_tolerance = 1e-10 # a bifurcation's location in the parameter
//! ```

use serde::Deserialize;

use crate::error::{number, Error, Result};
use crate::orbit::newton::NewtonSettings;
use crate::orbit::trace::TraceSettings;
use crate::system::{Params, SystemInfo};

/// A swept parameter as the table is checked against it: its name, its
/// index among the system's parameters, its values (the sweep's types
/// import this file, so it does not import theirs).
pub(super) struct Swept<'a> {
    pub(super) parameter: &'a str,
    pub(super) index: usize,
    pub(super) values: &'a [f64],
}

/// The default longest period traced: `[attractors]`' default, the
/// longest a lane's orbit is tested for without it.
pub const DEFAULT_ORBIT_MAX_PERIOD: usize = super::starts::DEFAULT_MAX_PERIOD;
/// The default points of a branch each way: the seed's branches over
/// η ∈ [0.5, 1.5] take at most 271 in all where they end at a bound,
/// a grazing or close; one that creeps along a grazing impact in tiny
/// steps (its period-2 branch near η = 0.83) took 2000 at 2000, most of
/// the stage's time; such a branch now ends at the grazing it creeps
/// towards, or stalled (`orbit::trace`'s `creeping_end`).
pub const DEFAULT_MAX_POINTS: usize = 400;
/// The longest period the table accepts: Newton's work grows with it,
/// and a lane's orbit is never tested beyond `attractors.max_period`.
const MAX_PERIOD_LIMIT: usize = 1024;
/// The most points a branch may take each way.
const MAX_POINTS_LIMIT: usize = 1_000_000;

/// `[orbits]` as the file gives it.
#[derive(Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawOrbits {
    from_sweep: Option<bool>,
    list: Option<Vec<RawListed>>,
    max_period: Option<usize>,
    max_points: Option<usize>,
    min_step: Option<f64>,
    max_step: Option<f64>,
    tolerance: Option<f64>,
    locate_tolerance: Option<f64>,
}

/// One orbit of `list`.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawListed {
    value: f64,
    second: Option<f64>,
    state: Vec<f64>,
    period: usize,
}

/// An orbit the scene lists: where a branch is traced from.
#[derive(Clone, Debug, PartialEq)]
pub struct ListedOrbit {
    /// The swept parameter's value.
    pub value: f64,
    /// With two swept parameters, the second's value: the orbit's branch
    /// is followed in the first at this value of the second.
    pub second: Option<f64>,
    pub state: Vec<f64>,
    pub period: usize,
}

/// `[orbits]`, checked.
#[derive(Clone, Debug, PartialEq)]
pub struct Orbits {
    pub from_sweep: bool,
    pub list: Vec<ListedOrbit>,
    pub trace: TraceSettings,
}

/// A number of the table: finite and > 0.
fn positive(key: &str, value: f64) -> Result<f64> {
    if value.is_finite() && value > 0.0 {
        Ok(value)
    } else {
        Err(Error::invalid(
            key,
            format!("must be a finite number > 0, got {}", number(value)),
        ))
    }
}

/// The table checked against the system and the sweep: branches are
/// followed in the first swept parameter over its range (with a second,
/// at each of its values).
impl Swept<'_> {
    /// The lowest and the highest of the axis's values.
    fn bounds(&self) -> (f64, f64) {
        let low = self.values.iter().copied().fold(f64::INFINITY, f64::min);
        let high = self
            .values
            .iter()
            .copied()
            .fold(f64::NEG_INFINITY, f64::max);
        (low, high)
    }
}

pub(super) fn resolve_orbits(
    raw: RawOrbits,
    info: &SystemInfo,
    params: &Params,
    axis: Swept,
    second: Option<Swept>,
) -> Result<Orbits> {
    let (low, high) = axis.bounds();
    let range = high - low;
    if !(range.is_finite() && range > 0.0) {
        return Err(Error::invalid(
            "orbits",
            format!(
                "follows branches over the sweep's range of {}, which must span more than one value",
                axis.parameter
            ),
        ));
    }
    let max_period = raw.max_period.unwrap_or(DEFAULT_ORBIT_MAX_PERIOD);
    if !(1..=MAX_PERIOD_LIMIT).contains(&max_period) {
        return Err(Error::invalid(
            "orbits.max_period",
            format!("must be from 1 to {MAX_PERIOD_LIMIT}, got {max_period}"),
        ));
    }
    let max_points = raw.max_points.unwrap_or(DEFAULT_MAX_POINTS);
    if !(2..=MAX_POINTS_LIMIT).contains(&max_points) {
        return Err(Error::invalid(
            "orbits.max_points",
            format!("must be from 2 to {MAX_POINTS_LIMIT}, got {max_points}"),
        ));
    }
    let min_step = positive("orbits.min_step", raw.min_step.unwrap_or(range * 1e-9))?;
    let max_step = positive("orbits.max_step", raw.max_step.unwrap_or(range / 50.0))?;
    if max_step > range {
        return Err(Error::invalid(
            "orbits.max_step",
            format!(
                "must be at most the sweep's range ({}), got {}",
                number(range),
                number(max_step)
            ),
        ));
    }
    if min_step > max_step {
        return Err(Error::invalid(
            "orbits.min_step",
            format!(
                "must be at most max_step ({}), got {}",
                number(max_step),
                number(min_step)
            ),
        ));
    }
    let tolerance = positive("orbits.tolerance", raw.tolerance.unwrap_or(1e-10))?;
    if tolerance > 1e-3 {
        return Err(Error::invalid(
            "orbits.tolerance",
            format!(
                "must be at most 1e-3 (a relative residual), got {}",
                number(tolerance)
            ),
        ));
    }
    let locate_tolerance = positive(
        "orbits.locate_tolerance",
        raw.locate_tolerance.unwrap_or(1e-10),
    )?;
    if locate_tolerance > max_step {
        return Err(Error::invalid(
            "orbits.locate_tolerance",
            format!(
                "must be at most max_step ({}), got {}",
                number(max_step),
                number(locate_tolerance)
            ),
        ));
    }
    let list = listed(
        raw.list.unwrap_or_default(),
        info,
        params,
        (&axis, second.as_ref()),
        (low, high),
        max_period,
    )?;
    let from_sweep = raw.from_sweep.unwrap_or(true);
    Ok(Orbits {
        from_sweep,
        list,
        trace: TraceSettings {
            parameter: axis.index,
            bounds: (low, high),
            newton: NewtonSettings {
                tolerance,
                ..NewtonSettings::default()
            },
            max_period,
            max_points,
            step: (max_step / 4.0).max(min_step),
            min_step,
            max_step,
            locate_tolerance,
        },
    })
}

/// `list`'s orbits, each checked: a value in the sweep's range (with a
/// second swept parameter, a `second` in its range, and without, none), a
/// whole finite state the system admits there, a period from 1 to
/// `max_period`.
fn listed(
    raw: Vec<RawListed>,
    info: &SystemInfo,
    params: &Params,
    (axis, second): (&Swept, Option<&Swept>),
    (low, high): (f64, f64),
    max_period: usize,
) -> Result<Vec<ListedOrbit>> {
    let dim = info.dimension();
    let names = info.state_names.to_vec();
    raw.into_iter()
        .enumerate()
        .map(|(i, orbit)| {
            let key = |field: &str| format!("orbits.list[{i}].{field}");
            if !(orbit.value.is_finite() && (low..=high).contains(&orbit.value)) {
                return Err(Error::invalid(
                    key("value"),
                    format!(
                        "must lie in the sweep's range of {} [{}, {}], got {}",
                        axis.parameter,
                        number(low),
                        number(high),
                        number(orbit.value)
                    ),
                ));
            }
            let second_value = listed_second(&key("second"), orbit.second, second)?;
            if orbit.state.len() != dim {
                return Err(Error::invalid(
                    key("state"),
                    format!(
                        "has {} numbers; a state has {dim} ({})",
                        orbit.state.len(),
                        names.join(", ")
                    ),
                ));
            }
            if let Some(v) = orbit.state.iter().find(|v| !v.is_finite()) {
                return Err(Error::invalid(
                    key("state"),
                    format!("must be finite, got {}", number(*v)),
                ));
            }
            let mut at = params.clone();
            at.set(axis.index, orbit.value);
            let mut place = format!("{} = {}", axis.parameter, number(orbit.value));
            if let (Some(axis), Some(value)) = (second, second_value) {
                at.set(axis.index, value);
                place.push_str(&format!(", {} = {}", axis.parameter, number(value)));
            }
            (info.check_state)(&at, &orbit.state)
                .map_err(|reason| Error::invalid(key("state"), format!("{reason} (at {place})")))?;
            if !(1..=max_period).contains(&orbit.period) {
                return Err(Error::invalid(
                    key("period"),
                    format!(
                        "must be from 1 to max_period ({max_period}), got {}",
                        orbit.period
                    ),
                ));
            }
            Ok(ListedOrbit {
                value: orbit.value,
                second: second_value,
                state: orbit.state,
                period: orbit.period,
            })
        })
        .collect()
}

/// A listed orbit's `second` (named `key`): required with a second swept
/// parameter, in its range; refused without one.
fn listed_second(key: &str, value: Option<f64>, second: Option<&Swept>) -> Result<Option<f64>> {
    let Some(axis) = second else {
        return match value {
            None => Ok(None),
            Some(_) => Err(Error::invalid(
                key,
                "is the second swept parameter's value; this sweep has one parameter: drop it",
            )),
        };
    };
    let (low, high) = axis.bounds();
    match value {
        None => Err(Error::invalid(
            key,
            format!(
                "is required with two swept parameters: the value of {} the orbit's branch is followed at",
                axis.parameter
            ),
        )),
        Some(v) if v.is_finite() && (low..=high).contains(&v) => Ok(Some(v)),
        Some(v) => Err(Error::invalid(
            key,
            format!(
                "must lie in the sweep's range of {} [{}, {}], got {}",
                axis.parameter,
                number(low),
                number(high),
                number(v)
            ),
        )),
    }
}
