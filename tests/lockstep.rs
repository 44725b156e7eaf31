//! Neighbouring lanes of a CPU sweep are stepped together (their transients'
//! references, and while they average their references and copies, as
//! batches across lanes, in the models' native step loop): each lane's
//! numbers must be those of the lane run alone, to the bit.

mod common;

use lyapsweep::method::runner;
use lyapsweep::plan::method_settings;
use lyapsweep::scene::{Backend, Precision};

/// Every lane of `scene` run alone and with its neighbours; the results'
/// every field (exponents, counts, status) compared to the bit (through
/// their debug forms, which print each f64 exactly, NaN included).
fn assert_lanes_together_are_lanes_alone(name: &str, overrides: &[&str]) {
    let scene = common::committed_scene(name, overrides);
    let settings = method_settings(&scene, Backend::Cpu, Precision::F64);
    let lanes = common::cpu_lanes(&scene, &settings);
    let run = runner(scene.system);
    let together: Vec<String> = lanes
        .chunks(8)
        .flat_map(|chunk| (run.run_lanes)(chunk))
        .map(|r| format!("{r:?}"))
        .collect();
    for (k, lane) in lanes.iter().enumerate() {
        let alone = format!("{:?}", (run.run_lane)(lane));
        assert_eq!(together[k], alone, "{name}, lane {k}");
    }
}

/// The seed's oscillator over the η of the paper's figure: impacts,
/// grazing iterations re-estimated by a lane alone, lanes with a period of
/// their own; eleven lanes, so a batch of 8 and one of 3.
#[test]
fn the_seed_s_lanes_together_are_its_lanes_alone() {
    assert_lanes_together_are_lanes_alone(
        "seed-fig3.toml",
        &[
            "sweep.count=11",
            "integration.transient=30",
            "integration.iterations=40",
            "integration.steps_per_period=400",
            "output.bifurcation_points=10",
        ],
    );
}

/// Models without stops (Duffing), with two (the impact pair), in four
/// dimensions (the chain), with a divergence integrated along the
/// reference (van der Pol, which averages alone), and with a general
/// surface (the vibrating table, which steps in the step loop alone).
#[test]
fn models_lanes_together_are_their_lanes_alone() {
    let short = [
        "sweep.count=10",
        "integration.transient=20",
        "integration.iterations=20",
        "output.bifurcation_points=10",
    ];
    for name in [
        "duffing.toml",
        "impact-pair.toml",
        "two-mass-chain.toml",
        "van-der-pol.toml",
        "vibrating-table.toml",
    ] {
        assert_lanes_together_are_lanes_alone(name, &short);
    }
}

/// Lanes of a basin grid that stop early on a known orbit
/// (`attractors.early_stop`) leave the batch of references stepped
/// together: every lane's result, stopped or run whole, is still the
/// lane's alone, to the bit. The seed at η = 0.6, the free orbit known
/// (the impacting one not: its lanes run whole beside the stopped ones).
#[test]
fn lanes_that_stop_early_together_are_lanes_alone() {
    let text = format!(
        "{}[sweep]\nparameter = \"eta\"\nvalues = [0.6]\n[attractors]\ngrid = [7, 5]\nbox = {{ x = [-3, 1.9], v = [-3, 3] }}\nbasins = 1\nearly_stop = 3\n",
        common::SEED
    );
    let scene = common::scene(
        &text,
        &[
            "integration.transient=120",
            "integration.iterations=20",
            "integration.steps_per_period=400",
            "output.bifurcation_points=4",
        ],
    );
    let settings = method_settings(&scene, Backend::Cpu, Precision::F64);
    assert_eq!(settings.early_stop, 3);
    let run = runner(scene.system);
    let whole: Vec<_> = common::cpu_lanes(&scene, &settings)
        .iter()
        .map(|lane| (run.run_lane)(lane))
        .collect();
    let free = whole
        .iter()
        .find(|r| r.impacts_per_period == 0.0 && r.orbit_period == Some(1))
        .expect("a start on the free orbit");
    let known = [lyapsweep::method::lane::KnownOrbit {
        points: free.orbit.clone(),
        result: free.clone(),
    }];
    let lanes: Vec<_> = common::cpu_lanes(&scene, &settings)
        .into_iter()
        .map(|lane| lyapsweep::method::Lane {
            known: &known,
            ..lane
        })
        .collect();
    let together: Vec<_> = lanes.chunks(8).flat_map(|c| (run.run_lanes)(c)).collect();
    let mut stopped = 0;
    for (k, lane) in lanes.iter().enumerate() {
        let alone = (run.run_lane)(lane);
        assert_eq!(
            format!("{:?}", together[k]),
            format!("{alone:?}"),
            "lane {k}"
        );
        if let lyapsweep::method::LaneStatus::EarlyStop { .. } = alone.status {
            stopped += 1;
            assert_eq!(alone.orbit, free.orbit, "lane {k}");
            assert_eq!(alone.settled, whole[k].settled, "lane {k}");
        } else {
            assert_eq!(format!("{alone:?}"), format!("{:?}", whole[k]), "lane {k}");
        }
    }
    assert!(stopped > 5 && stopped < lanes.len(), "{stopped} stopped");
}
