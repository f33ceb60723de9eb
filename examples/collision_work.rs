//! Exact collision checks as the MotionBenchMaker planner runs them: the spherized UR5 with the
//! same disabled pairs as `embodied bench mbm`, in the scenes of a spread of problems.
//!
//! ```text
//! cargo run --release --example collision_work -- URDF SRDF PROBLEMS [PROBLEMS_USED] [ROUNDS]
//! ```
//!
//! For each problem it draws 256 collision-free and 256 random configurations, then times
//! `collides_with` over them `ROUNDS` times and prints the median per-problem time per check.
//! It is also a fixed workload for instruction counts, which do not drift with the machine's load:
//! `valgrind --tool=callgrind --toggle-collect='*collides_with*' target/release/examples/collision_work ...`.

use std::hint::black_box;
use std::process::ExitCode;
use std::time::Instant;

use embodied::mbm::{MbmArgs, sample_problems};
use embodied_models::Rng;

fn main() -> ExitCode {
    let argv: Vec<String> = std::env::args().skip(1).collect();
    if argv.len() < 3 {
        eprintln!("usage: collision_work URDF SRDF PROBLEMS [PROBLEMS_USED] [ROUNDS]");
        return ExitCode::from(2);
    }
    let number = |i: usize, default: usize, what: &str| -> Result<usize, String> {
        argv.get(i).map_or(Ok(default), |v| v.parse().map_err(|_| format!("{what} must be a count, got `{v}`")))
    };
    let (used, rounds) = match (number(3, 12, "PROBLEMS_USED"), number(4, 20, "ROUNDS")) {
        (Ok(u), Ok(r)) if u > 0 && r > 0 => (u, r),
        (Ok(_), Ok(_)) => {
            eprintln!("PROBLEMS_USED and ROUNDS must be at least 1");
            return ExitCode::from(2);
        }
        (Err(e), _) | (_, Err(e)) => {
            eprintln!("{e}");
            return ExitCode::from(2);
        }
    };
    let args = MbmArgs::new(&argv[0], &argv[1], &argv[2]);
    let problems = match sample_problems(&args, used) {
        Ok(p) => p,
        Err(e) => {
            eprintln!("{e}");
            return ExitCode::from(1);
        }
    };
    let mut free_ns = Vec::new();
    let mut random_ns = Vec::new();
    let mut colliding = 0usize;
    let mut drawn = 0usize;
    for (k, p) in problems.iter().enumerate() {
        let robot = p.model.robot();
        let mut rng = Rng::new(k as u64 + 1);
        let random: Vec<Vec<f64>> = (0..256).map(|_| robot.random_configuration(&mut rng)).collect();
        let mut free = Vec::new();
        while free.len() < 256 && drawn < 1_000_000 {
            drawn += 1;
            let q = robot.random_configuration(&mut rng);
            if !p.model.collides(&q) {
                free.push(q);
            }
        }
        colliding += random.iter().filter(|q| p.model.collides(q)).count();
        let mut scratch = p.model.scratch();
        for (set, out) in [(&free, &mut free_ns), (&random, &mut random_ns)] {
            if set.is_empty() {
                continue;
            }
            let start = Instant::now();
            for _ in 0..rounds {
                for q in set.iter() {
                    black_box(p.model.collides_with(black_box(q), &mut scratch));
                }
            }
            out.push(start.elapsed().as_nanos() as f64 / (rounds * set.len()) as f64);
        }
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
    };
    println!(
        "{} problems ({}), {} self pairs checked: collides_with median over problems: free {:.0} ns, random {:.0} ns \
         ({colliding}/{} random configurations collide)",
        problems.len(),
        problems.first().map_or("-", |p| p.name.as_str()),
        problems.first().map_or(0, |p| p.model.self_collision_pairs().len()),
        median(&mut free_ns),
        median(&mut random_ns),
        256 * problems.len()
    );
    ExitCode::SUCCESS
}
