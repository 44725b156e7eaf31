//! `[sweep]` resolved into its axes: each axis's values generated or given,
//! and checked against the system at every value and, for a map over two
//! parameters, at every point of the grid.

use super::defaults::{positive, DEFAULT_COUNT};
use super::raw::{RawAxis, RawSweep};
use super::types::{Axis, Sweep};
use crate::error::{clip, number, Error, Result};
use crate::system::{Params, SystemInfo};

/// The sweep's axes, the second (if any) a different parameter.
pub(super) fn resolve_sweep(
    info: &'static SystemInfo,
    params: &Params,
    raw: RawSweep,
) -> Result<Sweep> {
    let first = resolve_axis(info, params, raw.first(), "sweep")?;
    let second = match raw.second {
        None => None,
        Some(axis) => {
            if axis.parameter.is_none() {
                return Err(Error::invalid(
                    "sweep.second.parameter",
                    "is required: which parameter is the second axis",
                ));
            }
            let second = resolve_axis(info, params, axis, "sweep.second")?;
            if second.index == first.index {
                return Err(Error::invalid(
                    "sweep.second.parameter",
                    format!("{} is already the first axis", second.parameter),
                ));
            }
            Some(second)
        }
    };
    // Each axis was checked with the other at its [system] value; the
    // grid's corners must be valid too (a check may couple parameters).
    if let Some(second) = &second {
        let mut p = params.clone();
        for &x in &first.values {
            for &y in &second.values {
                p.set(first.index, x);
                p.set(second.index, y);
                (info.check)(&p).map_err(|(name, reason)| {
                    Error::invalid(
                        info.key(name),
                        format!(
                            "{reason} (at {} = {}, {} = {})",
                            first.parameter,
                            number(x),
                            second.parameter,
                            number(y)
                        ),
                    )
                })?;
            }
        }
    }
    Ok(Sweep {
        first,
        second,
        starts: None,
        seeds: None,
    })
}

/// One axis of `[sweep]` (`table` names it in messages: "sweep" or
/// "sweep.second").
fn resolve_axis(
    info: &'static SystemInfo,
    params: &Params,
    raw: RawAxis,
    table: &str,
) -> Result<Axis> {
    let key = |name: &str| format!("{table}.{name}");
    let parameter = raw
        .parameter
        .unwrap_or_else(|| info.default_sweep.to_owned());
    let index = info.parameter_index(&parameter).ok_or_else(|| {
        Error::invalid(
            key("parameter"),
            format!(
                "{} has no parameter `{}` (its parameters: {})",
                info.kind,
                clip(&parameter),
                info.parameter_names()
            ),
        )
    })?;
    // Which key a bad value came from ("from" for a generated one, "to" for
    // the last), and the values.
    let (values, source) = match (raw.values, raw.from, raw.to) {
        (Some(_), Some(_), _) | (Some(_), _, Some(_)) => {
            return Err(Error::invalid(
                key("values"),
                "give either values or from/to/count, not both",
            ))
        }
        (Some(_), None, None) if raw.count.is_some() => {
            return Err(Error::invalid(
                key("count"),
                "goes with from and to, not with values",
            ))
        }
        (Some(values), None, None) => {
            if values.is_empty() {
                return Err(Error::invalid(
                    key("values"),
                    "must hold at least one value",
                ));
            }
            (values, "values")
        }
        (None, Some(from), Some(to)) => {
            let count = positive(&key("count"), raw.count, DEFAULT_COUNT)?;
            for (name, v) in [("from", from), ("to", to)] {
                if !v.is_finite() {
                    return Err(Error::invalid(
                        key(name),
                        format!("must be finite, got {v}"),
                    ));
                }
            }
            let values = if count == 1 {
                vec![from]
            } else {
                (0..count)
                    .map(|k| from + (to - from) * k as f64 / (count - 1) as f64)
                    .collect()
            };
            (values, "from")
        }
        (None, Some(_), None) => {
            return Err(Error::invalid(
                key("to"),
                format!("is required with {}", key("from")),
            ))
        }
        (None, None, Some(_)) => {
            return Err(Error::invalid(
                key("from"),
                format!("is required with {}", key("to")),
            ))
        }
        (None, None, None) => {
            if raw.count.is_some() {
                return Err(Error::invalid(
                    key("count"),
                    format!("needs {} and {}", key("from"), key("to")),
                ));
            }
            (vec![params.values[index]], "system")
        }
    };
    let mut p = params.clone();
    for (k, value) in values.iter().enumerate() {
        p.set(index, *value);
        (info.check)(&p).map_err(|(name, reason)| {
            if name == parameter {
                let at = match source {
                    "from" if k + 1 == values.len() && values.len() > 1 => key("to"),
                    "system" => info.key(&parameter),
                    other => key(other),
                };
                Error::invalid(
                    at,
                    format!("{parameter} = {}: {parameter} {reason}", number(*value)),
                )
            } else {
                Error::invalid(
                    info.key(name),
                    format!("{reason} (with {parameter} = {})", number(*value)),
                )
            }
        })?;
    }
    Ok(Axis {
        parameter,
        index,
        values,
    })
}
