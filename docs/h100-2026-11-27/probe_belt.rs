//! Device probe (not kept in the build): the belt-into-a-stop lanes of
//! tests/gpu_models.rs as the kernels alone end them (no CPU recomputation),
//! with the reference's state at every map iteration, to compare adapters.
use lyapsweep::backend::gpu::{context, sweep};
use lyapsweep::backend::{self, RunOptions};
use lyapsweep::scene::{self, Backend, Precision};

const MODEL: &str = r#"
[model]
name = "belt-and-stop"
states = ["x", "v"]
[model.parameters]
zeta = 0.05
mu = 0.5
vb = 0.2
f = 1.0
eta = 0.8
gap = 0.4
ks = 5.0
[[model.switches]]
name = "slip"
surface = "v - vb"
[model.equations]
x = "v"
v = "-2*zeta*v - x - mu*sign(slip) + f*cos(eta*t)"
[model.map]
period = "2*pi/eta"
[[model.events]]
name = "stop"
surface = "x - gap"
reset = { v = "-0.5*v" }
"#;

fn main() {
    let body = "[sweep]\nparameter = \"eta\"\nvalues = [0.3]\n\
                [integration]\nsteps_per_period = 600\ntransient = 0\niterations = 200\n\
                [output]\nbifurcation_points = 200\n[run]\nvalidate = 0\nbackend = \"gpu\"\n";
    let scene = scene::parse(&format!("{MODEL}\n{body}"), "probe", "probe", &[]).unwrap();
    let (adapter, summary) = context::choose(context::Want::Any, Precision::F64, None)
        .unwrap()
        .unwrap();
    println!("adapter {}", summary.name);
    let gpu = context::open(adapter, summary, Precision::F64).unwrap();
    let mut settings = backend::method_settings(&scene, Backend::Gpu, Precision::F64);
    backend::follow_gpu_plan(&scene, &mut settings).unwrap();
    let variant = backend::variant(&scene, Precision::F64);
    let options = RunOptions { dispatch_steps: std::env::var("PROBE_CHUNK").ok().map(|w| w.parse().unwrap()), ..Default::default() };
    let run = sweep::run(&gpu, &scene, &variant, &settings, &options).unwrap();
    for (k, lane) in run.lanes.iter().enumerate() {
        println!("lane {k}: {} {:?} impacts {}", lane.status, lane.exponents, lane.impacts_per_period);
    }
    println!("retries {} chunk {}", run.retries, run.chunk_steps);
    let lane = &run.lanes[0];
    for (i, p) in lane.bifurcation.chunks(2).enumerate() {
        println!("{i} {:e} {:e} {:016x} {:016x}", p[0], p[1], p[0].to_bits(), p[1].to_bits());
    }
}
