//! The `[model]` table of a scene (or a model file): states, parameters,
//! equations, the map (a period, or a Poincaré section) and events, checked
//! and parsed into a [`Model`]. Every error names its key, and for an
//! expression the column: `model.equations.v: unknown name 'zeta2' (column 6)`.

use crate::error::{Error, Result};
use crate::model::language::expr::{Expr, Names, Var};

/// A model as the scene gives it, its expressions parsed.
#[derive(Clone, Debug)]
pub struct Model {
    pub name: String,
    /// Names of states and parameters, in order (expressions index them).
    pub names: Names,
    /// Parameter defaults, in `names.parameters` order.
    pub defaults: Vec<f64>,
    /// Each parameter's allowed range, inclusive, in the same order
    /// (`zeta = { value = 0.05, min = 0 }`; unbounded by default).
    pub ranges: Vec<(f64, f64)>,
    /// d(state)/dt, one per state, in `names.states` order.
    pub equations: Vec<Expr>,
    pub map: Map,
    pub events: Vec<Event>,
    /// Surfaces across which the field switches (no reset): `step(name)`
    /// and `sign(name)` in the equations read their sides.
    pub switches: Vec<Switch>,
    /// States that are angles (`angles = ["theta"]`): wrapped into
    /// [-π, π) at the end of every map iteration, so that a rotating
    /// pendulum's angle stays of size π and its perturbation with it.
    pub angles: Vec<usize>,
}

/// How the flow is reduced to a map.
#[derive(Clone, Debug)]
pub enum Map {
    /// The stroboscopic (time-T) map of a T-periodic flow; T is an
    /// expression of the parameters.
    Period(Expr),
    /// The Poincaré map of a section `state = at`, crossed in `direction`.
    Section {
        state: usize,
        at: Expr,
        increasing: bool,
    },
}

/// An event: when `surface` crosses 0 from below, the states in `reset`
/// take their new values (the others keep theirs).
#[derive(Clone, Debug)]
pub struct Event {
    pub name: String,
    pub surface: Expr,
    /// (state, new value), in the order written.
    pub reset: Vec<(usize, Expr)>,
}

/// A switch: the field is discontinuous across `surface` = 0, and the
/// equations read which side the motion is on.
#[derive(Clone, Debug)]
pub struct Switch {
    pub name: String,
    pub surface: Expr,
    /// The stick limit (`stick_limit`): the motion stays on the surface
    /// while the mean of the two sides' rates is below it in size (static
    /// friction); `None` for Filippov's rule.
    pub stick_limit: Option<Expr>,
}

/// Switches a model may have: each doubles the fields compiled (one per
/// region of the sides).
pub const MAX_SWITCHES: usize = 3;

fn invalid(key: &str, reason: impl Into<String>) -> Error {
    Error::invalid(key, reason)
}

/// Words an expression gives a meaning of its own.
const RESERVED: [&str; 2] = ["t", "pi"];
const FUNCTIONS: [&str; 14] = [
    "sin", "cos", "tan", "exp", "log", "sqrt", "abs", "tanh", "atan2", "min", "max", "pow", "step",
    "sign",
];

fn check_name(key: &str, name: &str) -> Result<()> {
    let mut chars = name.chars();
    let first_ok = chars.next().is_some_and(|c| c.is_alphabetic() || c == '_');
    if !first_ok || !chars.all(|c| c.is_alphanumeric() || c == '_') {
        return Err(invalid(
            key,
            format!("{name:?} is not a name (letters, digits and _, not starting with a digit)"),
        ));
    }
    if RESERVED.contains(&name) || FUNCTIONS.contains(&name) {
        return Err(invalid(
            key,
            format!("'{name}' is reserved (time t, pi and the functions)"),
        ));
    }
    Ok(())
}

fn string<'a>(value: &'a toml::Value, key: &str) -> Result<&'a str> {
    value
        .as_str()
        .ok_or_else(|| invalid(key, format!("expected a string, got {value}")))
}

fn table<'a>(value: &'a toml::Value, key: &str) -> Result<&'a toml::Table> {
    value
        .as_table()
        .ok_or_else(|| invalid(key, format!("expected a table, got {value}")))
}

/// Parses `text` at `key`, its names restricted to what `allowed` accepts
/// (a period may not read the states, for instance).
fn expression(
    text: &toml::Value,
    key: &str,
    names: &Names,
    allowed: impl Fn(Var) -> Option<&'static str>,
) -> Result<Expr> {
    let text = string(text, key)?;
    let expr = Expr::parse(text, names).map_err(|e| invalid(key, e.to_string()))?;
    for (j, switch) in names.switches.iter().enumerate() {
        if let (true, Some(why)) = (expr.uses(Var::Side(j)), allowed(Var::Side(j))) {
            return Err(invalid(
                key,
                format!("may not read the switch '{switch}' (step or sign): {why}"),
            ));
        }
    }
    for (i, state) in names.states.iter().enumerate() {
        if let (true, Some(why)) = (expr.uses(Var::State(i)), allowed(Var::State(i))) {
            return Err(invalid(
                key,
                format!("may not use the state '{state}': {why}"),
            ));
        }
    }
    if let (true, Some(why)) = (expr.uses(Var::Time), allowed(Var::Time)) {
        return Err(invalid(key, format!("may not use the time 't': {why}")));
    }
    Ok(expr)
}

/// Refuses a key of `table` (at `key`) that is not one of `allowed`, saying
/// what `what` ("a model") has.
fn known_keys(table: &toml::Table, key: &str, what: &str, allowed: &[&str]) -> Result<()> {
    match table.keys().find(|k| !allowed.contains(&k.as_str())) {
        None => Ok(()),
        Some(k) => {
            let (last, rest) = allowed.split_last().expect("some keys are allowed");
            Err(invalid(
                &format!("{key}.{k}"),
                format!("unknown key ({what} has {} and {last})", rest.join(", ")),
            ))
        }
    }
}

/// A parameter's default and allowed range: a number, or a table
/// `{ value = 0.05, min = 0, max = 1 }` (`min` and `max` optional,
/// inclusive), so that a value outside the range the model means is
/// refused naming the parameter rather than run.
fn parameter(v: &toml::Value, key: &str) -> Result<(f64, (f64, f64))> {
    let number = |v: &toml::Value, key: &str| -> Result<f64> {
        let x = match v {
            toml::Value::Float(x) => *x,
            toml::Value::Integer(x) => *x as f64,
            other => return Err(invalid(key, format!("expected a number, got {other}"))),
        };
        if !x.is_finite() {
            return Err(invalid(key, format!("must be finite, got {x}")));
        }
        Ok(x)
    };
    let toml::Value::Table(t) = v else {
        return Ok((number(v, key)?, (f64::NEG_INFINITY, f64::INFINITY)));
    };
    known_keys(t, key, "a parameter", &["value", "min", "max"])?;
    let value = match t.get("value") {
        Some(v) => number(v, &format!("{key}.value"))?,
        None => return Err(invalid(key, "a parameter's table needs `value`")),
    };
    let bound = |name: &str, unbounded: f64| -> Result<f64> {
        t.get(name)
            .map_or(Ok(unbounded), |v| number(v, &format!("{key}.{name}")))
    };
    let (min, max) = (
        bound("min", f64::NEG_INFINITY)?,
        bound("max", f64::INFINITY)?,
    );
    if min > max {
        return Err(invalid(key, format!("min {min} exceeds max {max}")));
    }
    if !(min..=max).contains(&value) {
        return Err(invalid(
            &format!("{key}.value"),
            format!("{value} lies outside [{min}, {max}]"),
        ));
    }
    Ok((value, (min, max)))
}

/// The equations: anything.
fn any(_: Var) -> Option<&'static str> {
    None
}

fn parameters_only(_: Var) -> Option<&'static str> {
    Some("it must be a function of the parameters alone")
}

/// An event's surface or reset: anything but a switch's side, which is
/// substituted per region of the switches in the equations alone.
fn no_sides(v: Var) -> Option<&'static str> {
    match v {
        Var::Side(_) => Some("only the equations may read the switches' sides"),
        _ => None,
    }
}

/// A switch's surface or stick limit: the state, not the time, nor a side
/// (the surface decides the side).
fn switch_state(v: Var) -> Option<&'static str> {
    match v {
        Var::Time => Some("a switching surface and its stick limit are functions of the state"),
        Var::Side(_) => Some("only the equations may read the switches' sides"),
        _ => None,
    }
}

/// Refuses a surface that no motion can cross: one constant in the states
/// and the time (`"0"`, `"x - x"`), whose derivatives all fold to 0.
fn crossable(surface: &Expr, names: &Names, key: &str) -> Result<()> {
    let varies = (0..names.states.len())
        .map(Var::State)
        .chain([Var::Time])
        .any(|v| surface.derivative(v) != Expr::Num(0.0));
    if varies {
        Ok(())
    } else {
        Err(invalid(
            key,
            "does not depend on the state or the time, so nothing ever crosses it: \
             write the surface whose zero the event or switch is",
        ))
    }
}

/// The value of a stick limit at `params` where it is a function of the
/// parameters alone and negative or not a number: the motion sticks while
/// the rates' mean is below the limit in size, so such a limit means
/// nothing. `None` where it is fine, or depends on the state.
pub fn bad_stick_limit(limit: &Expr, params: &[f64]) -> Option<f64> {
    if crate::model::language::expr::reads_state_or_time(limit) {
        return None;
    }
    let value = limit.eval(&[], params, 0.0);
    (!(value >= 0.0 && value.is_finite())).then_some(value)
}

pub const STICK_LIMIT_RULE: &str = "must be a finite number ≥ 0 (the size of the force that holds)";

impl Model {
    /// Parses the `[model]` table; `key` names it in messages ("model").
    /// Its parts are read in the order they depend on one another: states
    /// and parameters name what the switches' surfaces read, the switches
    /// name the sides the equations read.
    pub fn parse(table_value: &toml::Value, key: &str) -> Result<Model> {
        let root = table(table_value, key)?;
        let at = |name: &str| format!("{key}.{name}");
        known_keys(
            root,
            key,
            "a model",
            &[
                "name",
                "states",
                "parameters",
                "equations",
                "map",
                "events",
                "switches",
                "angles",
            ],
        )?;
        let name = match root.get("name") {
            Some(v) => string(v, &at("name"))?.to_owned(),
            None => "model".to_owned(),
        };
        let states = parse_states(root.get("states"), &at("states"))?;
        let (parameters, defaults, ranges) =
            parse_parameters(root.get("parameters"), &at("parameters"), &states)?;
        let mut names = Names {
            states: states.clone(),
            parameters,
            switches: Vec::new(),
        };
        let switches =
            parse_switches(root.get("switches"), &at("switches"), &mut names, &defaults)?;
        names.switches = switches.iter().map(|s| s.name.clone()).collect();
        let equations = parse_equations(root.get("equations"), &at("equations"), &names)?;
        let map = parse_map(root.get("map"), &at("map"), &names)?;
        let events = parse_events(root.get("events"), &at("events"), &names)?;
        let angles = parse_angles(root.get("angles"), &at("angles"), &states, &map)?;
        Ok(Model {
            name,
            names,
            defaults,
            ranges,
            equations,
            map,
            events,
            switches,
            angles,
        })
    }

    /// The map period T at parameter values `params` (a period map only).
    pub fn period(&self, params: &[f64]) -> Option<f64> {
        match &self.map {
            Map::Period(t) => Some(t.eval(&[], params, 0.0)),
            Map::Section { .. } => None,
        }
    }

    /// Checks that the period is a finite number > 0 at `params`; `at`
    /// says which swept value they are, for the message.
    pub fn check_period(&self, params: &[f64], key: &str, at: &str) -> Result<()> {
        match self.period(params) {
            Some(t) if !(t.is_finite() && t > 0.0) => Err(invalid(
                &format!("{key}.map.period"),
                format!("must be a finite number > 0, got {t} (at {at})"),
            )),
            _ => Ok(()),
        }
    }
}

/// `states = [...]`: distinct names, at least one.
fn parse_states(value: Option<&toml::Value>, states_key: &str) -> Result<Vec<String>> {
    let states: Vec<String> = match value {
        None => return Err(invalid(states_key, "is required: the states, in order")),
        Some(toml::Value::Array(items)) if !items.is_empty() => items
            .iter()
            .map(|v| string(v, states_key).map(str::to_owned))
            .collect::<Result<_>>()?,
        Some(other) => {
            return Err(invalid(
                states_key,
                format!("expected a non-empty array of names, got {other}"),
            ))
        }
    };
    for (i, s) in states.iter().enumerate() {
        check_name(states_key, s)?;
        if states[..i].contains(s) {
            return Err(invalid(states_key, format!("'{s}' is listed twice")));
        }
    }
    Ok(states)
}

/// `[model.parameters]`: their names, defaults and ranges, in the order
/// written; no name may also be a state's.
#[allow(clippy::type_complexity)]
fn parse_parameters(
    value: Option<&toml::Value>,
    parameters_key: &str,
    states: &[String],
) -> Result<(Vec<String>, Vec<f64>, Vec<(f64, f64)>)> {
    let mut parameters = Vec::new();
    let mut defaults = Vec::new();
    let mut ranges = Vec::new();
    if let Some(value) = value {
        for (p, v) in table(value, parameters_key)? {
            let key = format!("{parameters_key}.{p}");
            check_name(&key, p)?;
            if states.contains(p) {
                return Err(invalid(
                    &key,
                    format!("'{p}' is both a state and a parameter"),
                ));
            }
            let (number, range) = parameter(v, &key)?;
            parameters.push(p.clone());
            defaults.push(number);
            ranges.push(range);
        }
    }
    Ok((parameters, defaults, ranges))
}

/// `[[model.switches]]`, at most [`MAX_SWITCHES`]; `names.switches` is
/// set to every name written before any surface is read, so that a surface
/// or stick limit naming a switch is told why it may not, not that the
/// switch does not exist. `defaults` check the stick limits.
fn parse_switches(
    value: Option<&toml::Value>,
    switches_key: &str,
    names: &mut Names,
    defaults: &[f64],
) -> Result<Vec<Switch>> {
    let mut switches = Vec::new();
    let Some(value) = value else {
        return Ok(switches);
    };
    let items = value
        .as_array()
        .ok_or_else(|| invalid(switches_key, "expected [[model.switches]] tables"))?;
    names.switches = items
        .iter()
        .filter_map(|i| i.get("name").and_then(toml::Value::as_str))
        .map(str::to_owned)
        .collect();
    for (n, item) in items.iter().enumerate() {
        let switch = parse_switch(
            item,
            &format!("{switches_key}[{n}]"),
            names,
            defaults,
            &switches,
        )?;
        switches.push(switch);
    }
    if switches.len() > MAX_SWITCHES {
        return Err(invalid(
            switches_key,
            format!(
                "{} switches: at most {MAX_SWITCHES} are supported",
                switches.len()
            ),
        ));
    }
    Ok(switches)
}

/// One switch: its name (not one of the `earlier` switches'), its surface
/// (which must be crossable) and its stick limit, if any.
fn parse_switch(
    item: &toml::Value,
    key: &str,
    names: &Names,
    defaults: &[f64],
    earlier: &[Switch],
) -> Result<Switch> {
    let switch = table(item, key)?;
    known_keys(switch, key, "a switch", &["name", "surface", "stick_limit"])?;
    let name_key = format!("{key}.name");
    let name = string(
        switch
            .get("name")
            .ok_or_else(|| invalid(&name_key, "is required: step(name) and sign(name) read it"))?,
        &name_key,
    )?
    .to_owned();
    check_name(&name_key, &name)?;
    if names.states.contains(&name) || names.parameters.contains(&name) {
        return Err(invalid(
            &name_key,
            format!("'{name}' is already a state or a parameter"),
        ));
    }
    if earlier.iter().any(|s| s.name == name) {
        return Err(invalid(&name_key, format!("'{name}' names two switches")));
    }
    let surface_key = format!("{key}.surface");
    let surface = expression(
        switch.get("surface").ok_or_else(|| {
            invalid(
                &surface_key,
                "is required: the field switches where it crosses 0",
            )
        })?,
        &surface_key,
        names,
        switch_state,
    )?;
    crossable(&surface, names, &surface_key)?;
    let stick_limit = match switch.get("stick_limit") {
        None => None,
        Some(text) => {
            let limit_key = format!("{key}.stick_limit");
            let limit = expression(text, &limit_key, names, switch_state)?;
            if let Some(value) = bad_stick_limit(&limit, defaults) {
                return Err(invalid(
                    &limit_key,
                    format!("{STICK_LIMIT_RULE}, got {value} at the defaults"),
                ));
            }
            Some(limit)
        }
    };
    Ok(Switch {
        name,
        surface,
        stick_limit,
    })
}

/// `[model.equations]`: one for every state, and none for anything else.
fn parse_equations(
    value: Option<&toml::Value>,
    equations_key: &str,
    names: &Names,
) -> Result<Vec<Expr>> {
    let states = &names.states;
    let written =
        value.ok_or_else(|| invalid(equations_key, "is required: d(state)/dt for every state"))?;
    let written = table(written, equations_key)?;
    for k in written.keys() {
        if !states.contains(k) {
            return Err(invalid(
                &format!("{equations_key}.{k}"),
                format!("'{k}' is not a state (states: {})", states.join(", ")),
            ));
        }
    }
    states
        .iter()
        .map(|s| {
            let key = format!("{equations_key}.{s}");
            let text = written.get(s).ok_or_else(|| {
                invalid(equations_key, format!("no equation for the state '{s}'"))
            })?;
            expression(text, &key, names, any)
        })
        .collect::<Result<Vec<_>>>()
}

/// `[model.map]`: a period, or a Poincaré section.
fn parse_map(value: Option<&toml::Value>, map_key: &str, names: &Names) -> Result<Map> {
    let map_table = value.ok_or_else(|| {
        invalid(
            map_key,
            "is required: period = \"...\" or section = { ... }",
        )
    })?;
    let map_table = table(map_table, map_key)?;
    known_keys(map_table, map_key, "a map", &["period", "section"])?;
    match (map_table.get("period"), map_table.get("section")) {
        (Some(_), Some(_)) => Err(invalid(map_key, "give period or section, not both")),
        (None, None) => Err(invalid(
            map_key,
            "give period = \"...\" or section = { ... }",
        )),
        (Some(period), None) => Ok(Map::Period(expression(
            period,
            &format!("{map_key}.period"),
            names,
            parameters_only,
        )?)),
        (None, Some(section)) => parse_section(section, &format!("{map_key}.section"), names),
    }
}

/// `section = { state, at, direction }`: the state whose value `at` is the
/// section, crossed increasing unless `direction` says otherwise.
fn parse_section(section: &toml::Value, key: &str, names: &Names) -> Result<Map> {
    let states = &names.states;
    let section = table(section, key)?;
    known_keys(section, key, "a section", &["state", "at", "direction"])?;
    let state_key = format!("{key}.state");
    let state_name = string(
        section.get("state").ok_or_else(|| {
            invalid(
                &state_key,
                "is required: the state that defines the section",
            )
        })?,
        &state_key,
    )?;
    let state = states.iter().position(|s| s == state_name).ok_or_else(|| {
        invalid(
            &state_key,
            format!(
                "'{state_name}' is not a state (states: {})",
                states.join(", ")
            ),
        )
    })?;
    if states.len() < 2 {
        return Err(invalid(
            &state_key,
            "a section needs a flow of at least 2 states",
        ));
    }
    let at_key = format!("{key}.at");
    let at = expression(
        section
            .get("at")
            .ok_or_else(|| invalid(&at_key, "is required: where the section lies"))?,
        &at_key,
        names,
        parameters_only,
    )?;
    let increasing = match section
        .get("direction")
        .map(|d| string(d, &format!("{key}.direction")))
    {
        None => true,
        Some(Ok("increasing")) => true,
        Some(Ok("decreasing")) => false,
        Some(Ok(other)) => {
            return Err(invalid(
                &format!("{key}.direction"),
                format!("expected \"increasing\" or \"decreasing\", got {other:?}"),
            ))
        }
        Some(Err(e)) => return Err(e),
    };
    Ok(Map::Section {
        state,
        at,
        increasing,
    })
}

/// `[[model.events]]`, in the order written.
fn parse_events(
    value: Option<&toml::Value>,
    events_key: &str,
    names: &Names,
) -> Result<Vec<Event>> {
    let Some(value) = value else {
        return Ok(Vec::new());
    };
    let items = value
        .as_array()
        .ok_or_else(|| invalid(events_key, "expected [[model.events]] tables"))?;
    items
        .iter()
        .enumerate()
        .map(|(n, item)| parse_event(item, n, &format!("{events_key}[{n}]"), names))
        .collect()
}

/// Event `n`: its name (by default "event n"), its surface (which must be
/// crossable) and its reset.
fn parse_event(item: &toml::Value, n: usize, key: &str, names: &Names) -> Result<Event> {
    let states = &names.states;
    let event = table(item, key)?;
    known_keys(event, key, "an event", &["name", "surface", "reset"])?;
    let name = match event.get("name") {
        Some(v) => {
            let name_key = format!("{key}.name");
            let name = string(v, &name_key)?;
            // The name heads the event's column of spectrum.csv.
            if !name.chars().any(char::is_alphanumeric) {
                return Err(invalid(
                    &name_key,
                    format!(
                        "{:?} has no letter or digit to name the event's column by",
                        crate::error::clip(name)
                    ),
                ));
            }
            name.to_owned()
        }
        None => format!("event {n}"),
    };
    let surface_key = format!("{key}.surface");
    let surface = expression(
        event.get("surface").ok_or_else(|| {
            invalid(
                &surface_key,
                "is required: the event fires where it crosses 0 from below",
            )
        })?,
        &surface_key,
        names,
        no_sides,
    )?;
    crossable(&surface, names, &surface_key)?;
    let mut reset = Vec::new();
    if let Some(r) = event.get("reset") {
        let reset_key = format!("{key}.reset");
        for (s, text) in table(r, &reset_key)? {
            let state = states.iter().position(|x| x == s).ok_or_else(|| {
                invalid(
                    &format!("{reset_key}.{s}"),
                    format!("'{s}' is not a state (states: {})", states.join(", ")),
                )
            })?;
            reset.push((
                state,
                expression(text, &format!("{reset_key}.{s}"), names, no_sides)?,
            ));
        }
    }
    Ok(Event {
        name,
        surface,
        reset,
    })
}

/// `angles = [...]`: distinct states, in a period map only.
fn parse_angles(
    value: Option<&toml::Value>,
    angles_key: &str,
    states: &[String],
    map: &Map,
) -> Result<Vec<usize>> {
    let mut angles = Vec::new();
    if let Some(value) = value {
        let items = value
            .as_array()
            .ok_or_else(|| invalid(angles_key, "expected an array of state names"))?;
        for item in items {
            let name = string(item, angles_key)?;
            let state = states.iter().position(|s| s == name).ok_or_else(|| {
                invalid(
                    angles_key,
                    format!("'{name}' is not a state (states: {})", states.join(", ")),
                )
            })?;
            if angles.contains(&state) {
                return Err(invalid(angles_key, format!("'{name}' is listed twice")));
            }
            if matches!(map, Map::Section { .. }) {
                return Err(invalid(
                    angles_key,
                    "angles in a model with a Poincaré section are not supported yet",
                ));
            }
            angles.push(state);
        }
    }
    Ok(angles)
}
