//! Criterion benchmarks of the executor: the runtime's own step overhead (trivial agents) and
//! 1,000 simple embodied agents at 1 kHz (target: one step well under 1 ms on 2 cores).

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

criterion_group!(benches, bench);
criterion_main!(benches);
