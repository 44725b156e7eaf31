//! Every shader variant validates with naga, without an adapter, the
//! built-ins' and those of the system files generated from models
//! (src/model/codegen/wgsl.rs); f64 variants call no transcendental builtin;
//! variants leave out what a scene does not need.

use lyapsweep::backend::gpu::shader::{Kernel, Variant};
use lyapsweep::integrate::ImpactLocation;
use lyapsweep::method::jacobian::Difference;
use lyapsweep::scene::Precision;
use lyapsweep::system::{SystemInfo, SYSTEMS};
use naga::valid::{Capabilities, ValidationFlags, Validator};

/// A model that calls every function an expression may, on four states
/// (the widest State), with the forcing clock in two places.
const EVERY_FUNCTION: &str = r#"
[model]
name = "every-function"
states = ["x", "v", "u", "w"]
[model.parameters]
a = 0.5
b = 2.0
eta = 1.0
[model.equations]
x = "v"
v = "sin(x) + cos(v) + tan(a*x) + exp(-v) + log(1 + x*x) + sqrt(abs(v)) - tanh(u) + atan2(v, x)*min(x, w) / max(1, a) + pow(abs(x), b) - x^3 + 0.1*cos(eta*t)"
u = "-a*u + sin(t*eta)*x - 1e-300*w"
w = "-u/exp(b)"
[model.map]
period = "2*pi/eta"
"#;

/// A model without parameters: WGSL has no empty struct, so its Params
/// holds one unused field and load_params builds `Params()`. (A scene
/// cannot run it, having no parameter to sweep; the system is built from
/// the table directly.)
const NO_PARAMETERS: &str = r#"
name = "no-parameters"
states = ["x", "v"]
[equations]
x = "v"
v = "-0.1*v - x + cos(t)"
[map]
period = "2*pi"
"#;

fn no_parameters() -> &'static SystemInfo {
    use lyapsweep::model::compiled::Code;
    use lyapsweep::model::Model;
    use lyapsweep::system::model::info;
    let table: toml::Value = toml::from_str(NO_PARAMETERS).unwrap();
    let model = Model::parse(&table, "model").unwrap();
    info(Code::compile(model, "model").unwrap())
}

fn scene_system(text: &str) -> &'static SystemInfo {
    lyapsweep::scene::parse(text, "test", "test", &[])
        .expect("a valid scene")
        .system
}

/// Every models/*.toml, by file name, as its scene's system.
fn model_files() -> Vec<(String, &'static SystemInfo)> {
    let folder = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("models");
    let mut models: Vec<(String, &'static SystemInfo)> = std::fs::read_dir(&folder)
        .unwrap()
        .map(|entry| entry.unwrap().path())
        .filter(|path| path.extension().is_some_and(|e| e == "toml"))
        .map(|path| {
            let name = path.file_name().unwrap().to_string_lossy().into_owned();
            (name, scene_system(&format!("model = {path:?}\n")))
        })
        .collect();
    models.sort_by(|a, b| a.0.cmp(&b.0));
    models
}

/// Every system with a WGSL file: the built-ins, the models of models/
/// that the kernels run, and the every-function model.
fn gpu_systems() -> Vec<&'static SystemInfo> {
    let mut systems: Vec<&'static SystemInfo> = SYSTEMS.to_vec();
    systems.extend(
        model_files()
            .into_iter()
            .map(|(_, s)| s)
            .filter(|s| s.wgsl.is_some()),
    );
    systems.push(scene_system(EVERY_FUNCTION));
    systems.push(no_parameters());
    systems
}

fn all_variants() -> Vec<Variant> {
    let mut variants = Vec::new();
    for system in gpu_systems() {
        for precision in [Precision::F64, Precision::F32] {
            for lyapunov in [true, false] {
                let walls: &[bool] = if system.wall_reachable.is_some() {
                    &[true, false]
                } else {
                    &[false]
                };
                for &wall in walls {
                    for impact_location in [ImpactLocation::Newton, ImpactLocation::Linear] {
                        for difference in [Difference::Forward, Difference::Central] {
                            variants.push(Variant {
                                system,
                                precision,
                                lyapunov,
                                difference,
                                wall,
                                impact_location,
                            });
                        }
                    }
                }
            }
        }
    }
    variants
}

fn module(variant: &Variant, kernel: Kernel) -> naga::Module {
    let source = variant.source(kernel);
    let module = naga::front::wgsl::parse_str(&source).unwrap_or_else(|e| {
        panic!(
            "{} {kernel:?}: {}",
            variant.name(),
            e.emit_to_string(&source)
        )
    });
    Validator::new(ValidationFlags::all(), Capabilities::FLOAT64)
        .validate(&module)
        .unwrap_or_else(|e| {
            panic!(
                "{} {kernel:?}: {}",
                variant.name(),
                e.emit_to_string(&source)
            )
        });
    module
}

#[test]
fn every_variant_validates() {
    let variants = all_variants();
    assert!(variants.len() >= 40);
    for v in &variants {
        for &kernel in v.kernels() {
            module(v, kernel);
        }
    }
}

#[test]
fn no_variant_calls_a_transcendental_builtin() {
    use naga::MathFunction as M;
    // Undefined on f64 under Vulkan (SPIR-V GLSL.std.450 is 16/32-bit only).
    let forbidden = [
        M::Sin,
        M::Cos,
        M::Tan,
        M::Asin,
        M::Acos,
        M::Atan,
        M::Atan2,
        M::Sinh,
        M::Cosh,
        M::Tanh,
        M::Exp,
        M::Exp2,
        M::Log,
        M::Log2,
        M::Pow,
    ];
    for v in all_variants() {
        // A model's f32 variant may: its functions are WGSL's on f32
        // (shaders/shared/model_functions.wgsl). Built-in kernels call none
        // in either precision.
        if v.precision == Precision::F32 && v.system.model.is_some() {
            continue;
        }
        for &kernel in v.kernels() {
            let m = module(&v, kernel);
            let functions = m
                .functions
                .iter()
                .map(|(_, f)| f)
                .chain(m.entry_points.iter().map(|e| &e.function));
            for f in functions {
                for (_, e) in f.expressions.iter() {
                    if let naga::Expression::Math { fun, .. } = e {
                        assert!(
                            !forbidden.contains(fun),
                            "{} {kernel:?} calls {fun:?}",
                            v.name()
                        );
                    }
                }
            }
        }
    }
}

fn has_function(m: &naga::Module, name: &str) -> bool {
    m.functions
        .iter()
        .any(|(_, f)| f.name.as_deref() == Some(name))
}

fn has_global(m: &naga::Module, name: &str) -> bool {
    m.global_variables
        .iter()
        .any(|(_, g)| g.name.as_deref() == Some(name))
}

#[test]
fn variants_leave_out_what_the_scene_does_not_need() {
    let oscillator = lyapsweep::system::by_kind("impact-oscillator").unwrap();
    let full = Variant {
        system: oscillator,
        precision: Precision::F64,
        lyapunov: true,
        difference: Difference::Forward,
        wall: true,
        impact_location: ImpactLocation::Newton,
    };
    let integrate = module(&full, Kernel::Integrate);
    let finish = module(&full, Kernel::Finish);
    assert!(
        has_function(&integrate, "resolve_impacts") && has_function(&integrate, "locate_newton")
    );
    assert!(
        has_global(&finish, "jac")
            && has_global(&finish, "deltas")
            && has_global(&finish, "points")
    );
    assert_eq!(full.trajectories(), 3);
    assert_eq!(
        Variant {
            difference: Difference::Central,
            ..full
        }
        .trajectories(),
        5
    );

    // A wall the sweep cannot reach: no impact code at all.
    let no_wall = Variant {
        wall: false,
        ..full
    };
    let m = module(&no_wall, Kernel::Integrate);
    for f in [
        "resolve_impacts",
        "locate_newton",
        "locate_linear",
        "hermite_peak",
    ] {
        assert!(!has_function(&m, f), "{f} compiled without a wall");
    }
    assert!(!no_wall
        .source(Kernel::Integrate)
        .contains("wall_position(p)"));

    // The paper's linear location compiles no Newton search.
    let linear = Variant {
        impact_location: ImpactLocation::Linear,
        ..full
    };
    let m = module(&linear, Kernel::Integrate);
    assert!(has_function(&m, "locate_linear") && !has_function(&m, "locate_newton"));

    // No exponents: no perturbed copies, no Jacobian or perturbation buffers.
    let reference_only = Variant {
        lyapunov: false,
        ..full
    };
    assert_eq!(reference_only.trajectories(), 1);
    let m = module(&reference_only, Kernel::Finish);
    assert!(!has_global(&m, "jac") && !has_global(&m, "deltas"));

    // f32 compensates the state update; f64 does not need to.
    assert!(Variant {
        precision: Precision::F32,
        ..full
    }
    .source(Kernel::Integrate)
    .contains("= (y1 - y) - corrected"));
    assert!(!full.source(Kernel::Integrate).contains("corrected"));
}

#[test]
fn a_scene_picks_only_the_parts_it_needs() {
    use lyapsweep::backend::gpu::plan::variant;
    let scene = |extra: &str| {
        let text = format!("[system]\nkind = \"impact-oscillator\"\n{extra}");
        lyapsweep::scene::parse(&text, "test", "test", &[]).unwrap()
    };
    // The seed's wall at 2 is within reach of the forced response.
    let seed = variant(
        &scene("[sweep]\nfrom = 0.5\nto = 1.5\ncount = 11"),
        Precision::F64,
    );
    assert!(seed.wall && seed.lyapunov);
    // A wall beyond |X_p| + √(u² + u'²) for every swept η is never reached.
    let far = variant(
        &scene("wall = 30.0\n[sweep]\nfrom = 0.5\nto = 1.5\ncount = 11"),
        Precision::F64,
    );
    assert!(!far.wall, "{}", far.name());
    assert!(far.name().contains("no-wall"));
    // ... but near resonance the response grows: η = 1 with ζ = 0.05 reaches 10.
    let resonant = variant(
        &scene("wall = 9.0\n[sweep]\nvalues = [1.0]"),
        Precision::F64,
    );
    assert!(resonant.wall);
    let bifurcation_only = variant(
        &scene("[output]\nlyapunov = \"none\"\nbifurcation_points = 10"),
        Precision::F32,
    );
    assert!(!bifurcation_only.lyapunov);
    assert_eq!(bifurcation_only.trajectories(), 1);
}

#[test]
fn the_models_the_kernels_run_and_why_not_the_others() {
    let runs: Vec<(String, bool)> = model_files()
        .into_iter()
        .map(|(name, s)| (name, s.wgsl.is_some()))
        .collect();
    let expected = [
        // A stop and a switch together (one vec4 of counts for both).
        ("belt-into-stop.toml", true),
        ("duffing.toml", true),
        ("forced-pendulum.toml", true),
        // A switch with a stick limit, slid on (stick-slip): the kernels
        // slide on one switch.
        ("friction-belt.toml", true),
        // The `impact-oscillator` kind: one stop.
        ("impact-oscillator.toml", true),
        // Two stops on x, from below and from above.
        ("impact-pair.toml", true),
        // The `lorenz` kind's time-T map.
        ("lorenz-flow.toml", true),
        // Poincaré sections: the section kernel steps, the host locates
        // the crossings and builds the factors.
        ("lorenz.toml", true),
        ("rossler.toml", true),
        // A switch crossed transversally (the field continuous across it):
        // the trajectories carry their region.
        ("soft-stop.toml", true),
        // Two switches with stick limits, slid on one at a time or at
        // once: CPU only so far.
        ("two-block-belt.toml", false),
        // A stop on the third of four states.
        ("two-mass-chain.toml", true),
        ("van-der-pol.toml", true),
        // A general event that moves with the clock (its surface and reset
        // read cos(w*t) and sin(w*t), the forcing phase).
        ("vibrating-table.toml", true),
    ];
    let expected: Vec<(String, bool)> = expected.iter().map(|(n, r)| (n.to_string(), *r)).collect();
    assert_eq!(runs, expected);
    assert!(scene_system(EVERY_FUNCTION).wgsl.is_some());
    assert!(no_parameters()
        .wgsl
        .unwrap()
        .source
        .contains("unused: real"));
}

#[test]
fn a_model_gets_math64_only_in_f64_and_only_when_it_calls_a_function() {
    let systems = model_files();
    let system = |name: &str| systems.iter().find(|(n, _)| n == name).unwrap().1;
    let variant = |system, precision| Variant {
        system,
        precision,
        lyapunov: true,
        difference: Difference::Central,
        wall: system.wall_reachable.is_some(),
        impact_location: ImpactLocation::Newton,
    };
    let pendulum = system("forced-pendulum.toml");
    // sin θ: the wrapper, math64 behind it in f64, WGSL's sin in f32.
    let f64_source = variant(pendulum, Precision::F64).source(Kernel::Integrate);
    assert!(f64_source.contains("sin_r(y.x)") && f64_source.contains("fn sin64("));
    let f32_source = variant(pendulum, Precision::F32).source(Kernel::Integrate);
    assert!(f32_source.contains("fn sin_r(") && !f32_source.contains("fn sin64("));
    // cos(ηt) is the clock, not a call; no other function: neither file.
    for name in ["impact-oscillator.toml", "duffing.toml"] {
        let source = variant(system(name), Precision::F64).source(Kernel::Finish);
        assert!(source.contains("phase.x"), "{name}");
        assert!(
            !source.contains("fn sin64(") && !source.contains("fn sin_r("),
            "{name}"
        );
    }
    // Surface code (the region, the surfaces' values, ln |det S|) only for
    // models with events or switches: the stop models' kernels are the
    // ones they were (their speed measured in docs/BENCHMARKS-GPU.md, "What lavapipe
    // runs").
    for (name, surfaces) in [
        ("impact-oscillator.toml", false),
        ("impact-pair.toml", false),
        ("two-mass-chain.toml", false),
        ("soft-stop.toml", true),
        ("vibrating-table.toml", true),
    ] {
        let v = variant(system(name), Precision::F64);
        for &kernel in v.kernels() {
            let source = v.source(kernel);
            for part in ["fn surface_values(", "TRAJ_REGION", "fluxes", "fn log64("] {
                assert_eq!(source.contains(part), surfaces, "{name} {kernel:?}: {part}");
            }
        }
    }
    // The seed as a model: the retired hand-written file's operations
    // (`(-2ζ)·v - x + f·cos`, which the model matched to the bit), one per
    // line as the tape orders them, its wall from the stop.
    let seed = system("impact-oscillator.toml").wgsl.unwrap().source;
    assert!(
        seed.contains(
            "let v7: real = -real(2.0);\n    let v8: real = v7 * p.p_zeta;\n    \
             let v9: real = v8 * y.y - y.x;\n    let v10: real = p.p_f * phase.x + v9;"
        ),
        "{seed}"
    );
    assert!(seed.contains("fn wall_position(p: Params)"), "{seed}");
}

#[test]
fn a_system_file_s_features_are_what_its_text_holds() {
    // The kernels' defines follow the emitter's typed features; the text
    // they describe must hold each exactly when the feature says so.
    for system in gpu_systems() {
        let file = system.wgsl.unwrap();
        let source = file.source;
        assert_eq!(
            file.surfaces,
            source.contains("const SURFACES: u32"),
            "{}",
            system.kind
        );
        assert_eq!(
            file.section,
            source.contains("const SECTION_STATE: u32"),
            "{}",
            system.kind
        );
        assert_eq!(
            file.wraps_angles,
            source.contains("fn wrap_angles("),
            "{}",
            system.kind
        );
    }
}

#[test]
fn a_section_model_runs_the_section_kernel_alone_and_period_maps_never_do() {
    let systems = model_files();
    let system = |name: &str| systems.iter().find(|(n, _)| n == name).unwrap().1;
    for name in ["lorenz.toml", "rossler.toml"] {
        let v = Variant {
            system: system(name),
            precision: Precision::F64,
            lyapunov: true,
            difference: Difference::Central,
            wall: false,
            impact_location: ImpactLocation::Newton,
        };
        assert!(v.section(), "{name}");
        assert_eq!(v.kernels(), &[Kernel::Section]);
        let source = v.source(Kernel::Section);
        // The flow's three states, and the map's two coordinates.
        assert!(source.contains("alias State = vec3<real>;"), "{name}");
        assert!(source.contains("const SECTION_STATE: u32 = "), "{name}");
        let m = module(&v, Kernel::Section);
        assert!(has_function(&m, "crossed") && !has_function(&m, "resolve_impacts"));
        assert!(!has_global(&m, "jac") && !has_global(&m, "traj"));
    }
    // The period maps' kernels know nothing of sections.
    for v in all_variants().iter().filter(|v| !v.section()) {
        for &kernel in v.kernels() {
            let source = v.source(kernel);
            assert!(
                !source.contains("SECTION_") && !source.contains("fn crossed("),
                "{} {kernel:?}",
                v.name()
            );
        }
    }
}
