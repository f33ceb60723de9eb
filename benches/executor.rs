//! Criterion benchmarks of the executor: the runtime's own step overhead (trivial agents),
//! 1,000 simple embodied agents at 1 kHz (target: one step well under 1 ms on 2 cores), and the
//! online plan gate's check of one plan, sampled and certified.

use std::hint::black_box;
use std::time::Duration;

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use embodied_executor::*;

fn trivial_runtime(n: usize, record: bool) -> Runtime {
    let mut rt =
        Runtime::new(RuntimeConfig { record, parallelism: Parallelism::Sequential, ..RuntimeConfig::default() });
    for k in 0..n {
        let program = Reactive::priority("main").main_reaction(Primitive::new(
            "tick",
            1,
            |c: &mut u64, _: &InputImages, _: &mut OutputImages| *c += 1,
        ));
        rt.add_agent(Agent::new(format!("a{k}"), 0u64, program));
    }
    rt
}

fn simple_runtime(n: usize, parallelism: Parallelism, tasks_per_thread: usize) -> Runtime {
    let robot = std::sync::Arc::new(embodied_models::builtin("rnt").expect("built-in robot"));
    let mut rt = Runtime::new(RuntimeConfig { seed: 1, parallelism, tasks_per_thread, ..RuntimeConfig::default() });
    for k in 0..n {
        let phase = k as f64 * 0.01;
        let program = Reactive::priority("main")
            .rule(
                Predicate::new("too-fast", |_: &(), i: &InputImages| i.qd().iter().any(|v| v.abs() > 10.0)),
                Primitive::new("halt", 1, SafeHalt),
            )
            .main_reaction(Primitive::new("track", 1, move |_: &mut (), i: &InputImages, o: &mut OutputImages| {
                let mut q = [0.0; 6];
                q.copy_from_slice(&i.sensor(0).values[..6]);
                q[0] = 0.5 * (i.step() as f64 * 0.002 + phase).sin();
                o.set_position_target(&q, &[0.0; 6]);
            }));
        let agent = Agent::embodied(format!("arm{k}"), robot.clone(), None, (), program)
            .expect("agent")
            .with_sensor(JointState, SensorConfig::default())
            .with_receptors(ReceptorSpec { encoder_noise: 1e-5, ..ReceptorSpec::default() });
        rt.add_agent(agent);
    }
    rt
}

fn bench(c: &mut Criterion) {
    let mut g = c.benchmark_group("executor");
    g.sample_size(20).measurement_time(Duration::from_secs(3)).warm_up_time(Duration::from_secs(1));
    for record in [false, true] {
        let mut rt = trivial_runtime(1000, record);
        g.throughput(Throughput::Elements(1000));
        g.bench_function(
            BenchmarkId::new("trivial-1000-agent-steps", if record { "record" } else { "no-record" }),
            |b| b.iter(|| black_box(rt.step().is_ok())),
        );
    }
    // "rayon": one chunk per thread (one fork-join per step); "rayon-4-tasks-per-thread": finer
    // chunks, so that an idle thread can take over work from a descheduled one on a busy machine.
    let rayon = Parallelism::Rayon { min_agents: 256 };
    for (name, parallelism, tasks) in
        [("sequential", Parallelism::Sequential, 1), ("rayon", rayon, 1), ("rayon-4-tasks-per-thread", rayon, 4)]
    {
        let mut rt = simple_runtime(1000, parallelism, tasks);
        g.throughput(Throughput::Elements(1000));
        g.bench_function(BenchmarkId::new("simple-1000-agents-1kHz-step", name), |b| {
            b.iter(|| black_box(rt.step().is_ok()))
        });
    }
    // The same agents, fewer of them: per agent-step, the difference to the 1,000-agent
    // sequential step is what 1,000 agents' data not fitting in cache costs.
    let mut rt = simple_runtime(100, Parallelism::Sequential, 1);
    g.throughput(Throughput::Elements(100));
    g.bench_function(BenchmarkId::new("simple-100-agents-1kHz-step", "sequential"), |b| {
        b.iter(|| black_box(rt.step().is_ok()))
    });
    g.finish();
}

/// The check the online plan gate runs on every plan (`PlanVerifier`), by mode: one RNT plan
/// around a ball on the straight line, as the executor's planner makes it (knots only).
fn plan_gate(c: &mut Criterion) {
    use embodied_models::{CollisionModel, Environment, Obstacle, Shape};
    use embodied_planner::motion::{Goal, MotionSettings, plan_motion};
    use embodied_planner::trajectory::time_parameterize;
    use embodied_planner::verify::Verifier;
    let robot = embodied_models::builtin("rnt").expect("built-in robot");
    let (start, goal) = ([-0.5, -1.4, -1.0, 0.0, 0.3, 0.0], [0.8, -1.2, -1.2, 0.0, 0.5, 0.0]);
    let mid: Vec<f64> = start.iter().zip(goal).map(|(a, b)| 0.5 * (a + b)).collect();
    let p = robot.end_effector_poses(&mid, 0).1.translation.vector;
    let ball = Obstacle::new("ball", nalgebra::Isometry3::translation(p.x, p.y, p.z), Shape::sphere(0.08));
    let model = CollisionModel::new(&robot, Environment::new().with(ball));
    let plan = plan_motion(&model, &start, &Goal::Configuration(goal.to_vec()), &MotionSettings::default())
        .expect("a plan around the ball");
    let trajectory = time_parameterize(&plan.path, &robot, 0.0);
    let mut g = c.benchmark_group("plan-gate");
    g.sample_size(20).measurement_time(Duration::from_secs(3)).warm_up_time(Duration::from_secs(1));
    for (name, verifier) in [("sampled-0.01", Verifier::sampled(0.01)), ("certified", Verifier::default())] {
        verifier.verify_trajectory(&model, &trajectory).expect("the plan passes the gate");
        g.bench_function(BenchmarkId::new("rnt-around-ball", name), |b| {
            b.iter(|| black_box(verifier.verify_trajectory(&model, &trajectory).is_ok()))
        });
    }
    g.finish();
}

/// Per control step: the safety limiter on one RNT with and without its screws' speed check
/// (a command that drives both screws past their limits, so the check also scales), and the
/// polishing regulator's per-step work (the joint motion per unit depth along the face's
/// normal, through the position Jacobian).
fn actuators_and_regulator(c: &mut Criterion) {
    use embodied_models::nalgebra::Vector3;
    let robot = embodied_models::builtin("rnt").expect("built-in robot");
    let mut q = robot.home().to_vec();
    q[1] = -1.55;
    let mut wanted = vec![0.0; q.len()];
    wanted[1] = 0.5;
    wanted[2] = 0.5;
    let command = JointCommand { mode: CommandMode::Velocity, q: q.clone(), qd: wanted };
    let mut g = c.benchmark_group("control-step");
    g.sample_size(30).measurement_time(Duration::from_secs(2)).warm_up_time(Duration::from_secs(1));
    for (name, screws) in [("joints-only", false), ("joints-and-screws", true)] {
        let servo = ServoModel::new(robot.limits(), &q).expect("servo");
        let limiter = if screws {
            SafetyLimiter::new(servo).with_actuators(robot.actuators().to_vec())
        } else {
            SafetyLimiter::new(servo)
        };
        let mut out = JointCommand { mode: CommandMode::Position, q: vec![0.0; q.len()], qd: vec![0.0; q.len()] };
        g.bench_function(BenchmarkId::new("rnt-safety-limiter", name), |b| {
            b.iter(|| {
                limiter.limit_into(black_box(&command), 0.001, &mut out);
                black_box(out.qd[1])
            })
        });
    }
    let mut shifted = vec![0.0; q.len()];
    g.bench_function(BenchmarkId::new("rnt-polish-regulator", "normal-shift"), |b| {
        b.iter(|| {
            embodied_system::polish::shifted(&robot, black_box(&q), &Vector3::new(0.0, 0.0, -1.0), &mut shifted);
            black_box(shifted[1])
        })
    });
    g.finish();
}

/// One step of the controlled stop along a planned RNT trajectory ([`PathHalt`]): mid-segment
/// (the current rate fits at once) and 0.99 ms before a rest point that falls between two
/// control steps, where no step along the path fits and the halt searches for the one that
/// leaves the velocity windows least.
fn path_halt(c: &mut Criterion) {
    let robot = embodied_models::builtin("rnt").expect("built-in robot");
    let limits = robot.limits();
    let fractions = [
        [
            0.09879427978446371,
            0.47129435000963066,
            0.5525882118533709,
            0.837757492358771,
            0.6526821213244488,
            0.8631178715522773,
        ],
        [
            0.4706624776609378,
            0.5069973139779048,
            0.0808183200302009,
            0.47032643447886224,
            0.5354701481952567,
            0.7801090359131163,
        ],
        [
            0.8642494678126619,
            0.8780675046467484,
            0.7216257905760672,
            0.15379125886340161,
            0.46867387522105763,
            0.7183235795517346,
        ],
        [
            0.7081108702058331,
            0.16362078449549772,
            0.4851340161501141,
            0.5592889740542857,
            0.5939174527924926,
            0.5821563964527552,
        ],
        [
            0.7024359045281402,
            0.12121521484052279,
            0.8190684640437105,
            0.07702320643190415,
            0.11857814596360573,
            0.203136409979362,
        ],
    ];
    let waypoints: Vec<Vec<f64>> = fractions
        .iter()
        .map(|f| f.iter().zip(&limits).map(|(x, l)| l.lower + x * (l.upper - l.lower)).collect())
        .collect();
    let traj = embodied_planner::trajectory::time_parameterize(&waypoints, &robot, 0.0);
    // The rest point of the third waypoint.
    let rests: Vec<f64> =
        traj.t.iter().zip(&traj.qd).filter(|(_, v)| v.iter().all(|x| *x == 0.0)).map(|(t, _)| *t).collect();
    let rest = rests.get(2).copied().unwrap_or(0.5 * traj.duration());
    let dt = 0.001;
    let mut g = c.benchmark_group("control-step");
    g.sample_size(30).measurement_time(Duration::from_secs(2)).warm_up_time(Duration::from_secs(1));
    for (name, follow) in [("mid-segment", (0.5 * rest / dt) as usize), ("before-a-rest-point", (rest / dt) as usize)] {
        // Follow the trajectory at its own pace through the limiter, then halt.
        let start = traj.sample(0.0).0;
        let mut servo = SafetyLimiter::new(ServoModel::new(limits.clone(), &start).expect("servo"));
        let mut cmd = JointCommand::hold(&start);
        for k in 1..=follow {
            let (next, prev) = (traj.sample(k as f64 * dt).0, traj.sample((k - 1) as f64 * dt).0);
            cmd.mode = CommandMode::Position;
            for j in 0..next.len() {
                cmd.qd[j] = (next[j] - prev[j]) / dt;
                cmd.q[j] = next[j];
            }
            servo.execute(&cmd, dt);
        }
        let halt = PathHalt::new(follow as f64 * dt, 1.0);
        let (q, qd) = (servo.q().to_vec(), servo.qd().to_vec());
        g.bench_function(BenchmarkId::new("rnt-path-halt", name), |b| {
            b.iter(|| {
                let mut h = halt.clone();
                h.command_into(&traj, black_box(&q), black_box(&qd), &limits, dt, &mut cmd);
                black_box(cmd.q[0])
            })
        });
    }
    g.finish();
}

criterion_group!(benches, bench, plan_gate, actuators_and_regulator, path_halt);
criterion_main!(benches);
