//! A model with general surfaces (switches, events) steps between its
//! crossings in the C compiler's loop over its regions
//! (`model::native::library::SwitchLoops`); where that loop is not built, the
//! integrator's own step loop takes every step. The two must give every
//! lane the same numbers, to the bit.

mod common;

use lyapsweep::method::{runner, Lane};
use lyapsweep::model::compiled::Code;
use lyapsweep::model::Model;
use lyapsweep::plan::method_settings;
use lyapsweep::scene::{Backend, Precision};
use lyapsweep::system::Params;

/// Every lane of the committed scene `name` (whose model is
/// models/`name`), in batches of 16 as the CPU path runs them, with the
/// regions' loop and with the model compiled again without it; the
/// results' every field compared through their debug forms (each f64
/// exactly, NaN included).
fn assert_the_regions_loop_changes_nothing(name: &str, overrides: &[&str]) {
    let scene = common::committed_scene(name, overrides);
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("models")
        .join(name);
    let table = lyapsweep::model::read_table(&path).unwrap();
    let table = table.get("model").cloned().unwrap_or(table);
    let mut code = Code::compile(Model::parse(&table, "model").unwrap(), "model").unwrap();
    // Not a skip where there is no C compiler: the test fails and says why.
    match &code.switch_loops {
        Some(Ok(_)) => {}
        other => panic!("{name}: the regions' loop was not built: {other:?}"),
    }
    code.switch_loops = None;
    let without = lyapsweep::system::model::info(code);
    let settings = method_settings(&scene, Backend::Cpu, Precision::F64);
    let lanes = common::cpu_lanes(&scene, &settings);
    let lanes_without: Vec<Lane> = lanes
        .iter()
        .map(|lane| Lane {
            params: Params {
                info: without,
                values: lane.params.values.clone(),
            },
            settings: &settings,
            initial_state: lane.initial_state.clone(),
            known: &[],
        })
        .collect();
    let run = |lanes: &[Lane], info| -> Vec<String> {
        let run = runner(info);
        lanes
            .chunks(16)
            .flat_map(|chunk| (run.run_lanes)(chunk))
            .map(|r| format!("{r:?}"))
            .collect()
    };
    let with = run(&lanes, scene.system);
    let stepped = run(&lanes_without, without);
    for (k, (a, b)) in with.iter().zip(&stepped).enumerate() {
        assert_eq!(a, b, "{name}, lane {k}");
    }
}

/// A soft stop (a switch, two regions), a belt and a stop (a switch that
/// slides and a stop), a vibrating table (an event moving with the clock,
/// whose crossings can accumulate and hold the ball) and two blocks on a
/// belt (two switches, four regions, sliding on both): 20 lanes each, a
/// batch of 16 and one of 4.
#[test]
fn the_regions_step_loop_gives_the_integrator_s_numbers() {
    let short = [
        "sweep.count=20",
        "integration.transient=20",
        "integration.iterations=30",
        "output.bifurcation_points=10",
    ];
    for name in [
        "soft-stop.toml",
        "belt-into-stop.toml",
        "vibrating-table.toml",
        "two-block-belt.toml",
    ] {
        assert_the_regions_loop_changes_nothing(name, &short);
    }
}
