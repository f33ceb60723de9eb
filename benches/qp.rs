//! Criterion benchmark: the two-arm closed-chain velocity QP (13 joints of `two-irp6`).
//!
//! * `closed-chain-two-irp6-solve`: the one-shot [`ClosedChainQp`] (fresh clarabel per call).
//! * `carry/*`: one control step of [`ClosedChainController`] on a recorded carry (the bar moving
//!   along a closed path near a table and a wall for 5 s at 1 kHz: 13 variables, 6 closure
//!   equalities, 26 bounds, up to 16 velocity dampers) with each backend. Before criterion runs,
//!   each backend replays the whole carry once and the per-step percentiles are printed.

use std::hint::black_box;
use std::time::{Duration, Instant};

use criterion::{Criterion, criterion_group, criterion_main};
use embodied_executor::closed_chain::*;
use embodied_models::Robot;
use embodied_models::nalgebra::{DVector, Isometry3, Vector3, Vector6};

const DT: f64 = 1e-3;
const STEPS: usize = 5000;

/// One recorded step's inputs.
struct Step {
    q: Vec<f64>,
    kin: ChainKinematics,
    v_a: Vector6<f64>,
    e_r: Vector6<f64>,
    dampers: Vec<VelocityDamper>,
}

impl Step {
    fn input(&self) -> StepInput<'_> {
        StepInput {
            q: &self.q,
            j_a: &self.kin.j_a,
            j_r: &self.kin.j_r,
            v_a: self.v_a,
            e_r: self.e_r,
            dampers: &self.dampers,
            reference: None,
        }
    }
}

/// Desired absolute pose and twist at time `t`: a smooth closed loop of a few cm with a yaw swing.
fn path(start: &Isometry3<f64>, t: f64) -> (Isometry3<f64>, Vector6<f64>) {
    let w = std::f64::consts::TAU / 5.0;
    let (s, c, s2, c2) = ((w * t).sin(), (w * t).cos(), (2.0 * w * t).sin(), (2.0 * w * t).cos());
    let dp = Vector3::new(0.04 * s, 0.03 * (1.0 - c), -0.04 * (1.0 - c));
    let v = Vector3::new(0.04 * w * c, 0.03 * w * s, -0.04 * w * s);
    let yaw = 0.15 * s2;
    let wz = 0.3 * w * c2;
    let pose = Isometry3::from_parts(
        (start.translation.vector + dp).into(),
        embodied_models::nalgebra::UnitQuaternion::from_scaled_axis(Vector3::z() * yaw) * start.rotation,
    );
    (pose, Vector6::new(v.x, v.y, v.z, 0.0, 0.0, wz))
}

/// Witness frames: the tool and flange of each arm and two links before the flange.
fn witness_frames(robot: &Robot) -> Vec<(usize, Isometry3<f64>)> {
    let mut frames = Vec::new();
    for ee in robot.end_effectors() {
        let chain = robot.chain_to(ee.link);
        let wrist = |k: usize| chain.len().checked_sub(k).map_or(ee.link, |j| robot.joints()[chain[j]].child_link);
        frames.extend([
            (ee.link, ee.tool),
            (ee.link, Isometry3::identity()),
            (wrist(3), Isometry3::identity()),
            (wrist(4), Isometry3::identity()),
        ]);
    }
    frames
}

/// Velocity dampers against a table (plane z = `table`, below) and a wall (plane y = `wall`,
/// beside) for the witness frames.
fn dampers(robot: &Robot, q: &[f64], table: f64, wall: f64, params: &DamperParams) -> Vec<VelocityDamper> {
    let poses = robot.forward_kinematics(q);
    let fixed = embodied_models::nalgebra::Matrix6xX::zeros(q.len());
    let mut rows = Vec::new();
    for (link, frame) in witness_frames(robot) {
        let p = (poses[link] * frame).translation.vector;
        let jac = robot.jacobian_with_poses(&poses, link, &frame);
        for (normal, distance) in [(Vector3::z(), p.z - table), (-Vector3::y(), wall - p.y)] {
            if let Some(d) = VelocityDamper::from_witness(&normal, &jac, &fixed, distance, params) {
                rows.push(d);
            }
        }
    }
    rows.truncate(16);
    rows
}

/// Simulate the carry with the dense controller and record every step's inputs.
fn record() -> Vec<Step> {
    let robot = embodied_models::builtin("two-irp6").expect("built-in robot");
    let mut q = robot.home().to_vec();
    let kin0 = ChainKinematics::new(&robot, &q).expect("kinematics");
    let reference = kin0.relative_pose();
    let start = kin0.absolute_pose();
    let params = DamperParams { xi: 0.3, safety: 0.01, influence: 0.15 };
    // Obstacles just inside the influence distance of the lowest and the outermost witness
    // point: the path (8 cm down, 6 cm toward the wall) brings them within damping range, and the
    // wall dampers stop the bar short of the wall.
    let poses = robot.forward_kinematics(&q);
    let points: Vec<Vector3<f64>> =
        witness_frames(&robot).iter().map(|(l, f)| (poses[*l] * f).translation.vector).collect();
    let table = points.iter().map(|p| p.z).fold(f64::INFINITY, f64::min) - 0.1;
    let wall = points.iter().map(|p| p.y).fold(f64::NEG_INFINITY, f64::max) + 0.05;
    let mut ctl =
        ClosedChainController::new(robot.limits(), ClosedChainConfig { dt: DT, ..ClosedChainConfig::default() })
            .expect("controller");
    let mut steps = Vec::with_capacity(STEPS);
    for k in 0..STEPS {
        let kin = ChainKinematics::new(&robot, &q).expect("kinematics");
        let (desired, twist) = path(&start, k as f64 * DT);
        let v_a = twist + pose_error(&desired, &kin.absolute_pose()) * 10.0;
        let e_r = relative_pose_error(&kin.tool1, &kin.tool2, &reference);
        let step = Step { q: q.clone(), dampers: dampers(&robot, &q, table, wall, &params), kin, v_a, e_r };
        let sol = ctl.step(&step.input()).unwrap_or_else(|e| panic!("carry step {k}: {e}"));
        for (qi, v) in q.iter_mut().zip(sol.qd.iter()) {
            *qi += v * DT;
        }
        steps.push(step);
    }
    steps
}

fn percentile(sorted: &[u64], p: f64) -> u64 {
    let i = ((sorted.len() as f64 - 1.0) * p).round() as usize;
    sorted[i.min(sorted.len() - 1)]
}

/// Replay summary of one backend.
struct Replay {
    /// Sorted per-step times, ns.
    times: Vec<u64>,
    slacked: usize,
    fell_back: usize,
    /// Steps with at least one damper row binding.
    damper_bound: usize,
    iterations: usize,
    worst_closure: f64,
}

/// Replay the carry with `backend`, timing each step.
fn replay(steps: &[Step], backend: QpBackend) -> Replay {
    let robot = embodied_models::builtin("two-irp6").expect("built-in robot");
    let mut ctl = ClosedChainController::new(
        robot.limits(),
        ClosedChainConfig { dt: DT, backend, ..ClosedChainConfig::default() },
    )
    .expect("controller");
    let mut r = Replay {
        times: Vec::with_capacity(steps.len()),
        slacked: 0,
        fell_back: 0,
        damper_bound: 0,
        iterations: 0,
        worst_closure: 0.0,
    };
    for s in steps {
        let t = Instant::now();
        let sol = ctl.step(&s.input());
        r.times.push(t.elapsed().as_nanos() as u64);
        let sol = sol.expect("replayed step");
        r.slacked += usize::from(sol.closure == ClosureMode::Slacked);
        r.fell_back += usize::from(sol.fell_back);
        r.damper_bound += usize::from(s.dampers.iter().any(|d| d.b - d.a.dot(&sol.qd) < 1e-7));
        r.iterations += sol.iterations;
        r.worst_closure = r.worst_closure.max(sol.closure_residual);
        black_box(&sol);
    }
    r.times.sort_unstable();
    r
}

fn bench(c: &mut Criterion) {
    let steps = record();
    println!("\ncarry: {} steps of {} ms (13 vars, 6 equalities, 26 bounds, <= 16 dampers)", steps.len(), DT * 1e3);
    let max_rows = steps.iter().map(|s| s.dampers.len()).max().unwrap_or(0);
    println!(
        "damper rows per step: mean {:.1}, max {max_rows}",
        steps.iter().map(|s| s.dampers.len()).sum::<usize>() as f64 / steps.len() as f64
    );
    let mut p50s = Vec::new();
    for backend in [QpBackend::ClarabelFresh, QpBackend::Clarabel, QpBackend::Dense] {
        let r = replay(&steps, backend);
        let t = &r.times;
        let mean = t.iter().sum::<u64>() as f64 / t.len() as f64;
        println!(
            "{backend:?}: p50 {:.1} us, p90 {:.1} us, p99 {:.1} us, max {:.1} us, mean {:.1} us; slacked {}, fell back {}, \
             damper-bound steps {}, mean iterations {:.1}, worst closure residual {:.1e}",
            percentile(t, 0.5) as f64 / 1e3,
            percentile(t, 0.9) as f64 / 1e3,
            percentile(t, 0.99) as f64 / 1e3,
            t[t.len() - 1] as f64 / 1e3,
            mean / 1e3,
            r.slacked,
            r.fell_back,
            r.damper_bound,
            r.iterations as f64 / t.len() as f64,
            r.worst_closure,
        );
        p50s.push(percentile(t, 0.5) as f64);
    }
    println!(
        "p50 ratio clarabel-fresh / dense {:.0}x, clarabel-update / dense {:.0}x\n",
        p50s[0] / p50s[2],
        p50s[1] / p50s[2]
    );

    let mut g = c.benchmark_group("qp");
    g.sample_size(30).measurement_time(Duration::from_secs(3)).warm_up_time(Duration::from_secs(1));
    {
        let robot = embodied_models::builtin("two-irp6").expect("built-in robot");
        let q = robot.home().to_vec();
        let (e1, e2) = (&robot.end_effectors()[0], &robot.end_effectors()[1]);
        let j1 = robot.jacobian(&q, e1.link, &e1.tool);
        let j2 = robot.jacobian(&q, e2.link, &e2.tool);
        let (_, t1) = robot.end_effector_poses(&q, 0);
        let (_, t2) = robot.end_effector_poses(&q, 1);
        let (lower, upper) = velocity_bounds(&q, &robot.limits(), 0.01);
        let qp = ClosedChainQp {
            j_a: absolute_jacobian(&j1, &j2),
            v_a: DVector::from_vec(vec![0.0, 0.0, 0.05, 0.0, 0.0, 0.0]),
            j_r: relative_jacobian(&j1, &j2, &t1, &t2),
            lambda: 1e-4,
            lower,
            upper,
        };
        g.bench_function("closed-chain-two-irp6-solve", |b| b.iter(|| black_box(qp.solve().is_ok())));
    }
    let robot = embodied_models::builtin("two-irp6").expect("built-in robot");
    for (name, backend) in [
        ("carry/clarabel-fresh", QpBackend::ClarabelFresh),
        ("carry/clarabel-update", QpBackend::Clarabel),
        ("carry/dense", QpBackend::Dense),
    ] {
        let mut ctl = ClosedChainController::new(
            robot.limits(),
            ClosedChainConfig { dt: DT, backend, ..ClosedChainConfig::default() },
        )
        .expect("controller");
        let mut k = 0;
        g.bench_function(name, |b| {
            b.iter(|| {
                let s = &steps[k % steps.len()];
                k += 1;
                black_box(ctl.step(&s.input()).is_ok())
            })
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
