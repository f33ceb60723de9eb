//! Measure the motion planner on MotionBenchMaker problems (release mode):
//!
//! ```text
//! cargo run --release --example mbm -- URDF SRDF PROBLEMS [DEADLINE_MS] [OUT.json|-] [RESOLUTION]
//! ```
//!
//! Prints the per-family table and writes the full report (every path) as JSON when asked.

use std::process::ExitCode;

use embodied::mbm::{MbmArgs, render_table, run_mbm};

fn main() -> ExitCode {
    let argv: Vec<String> = std::env::args().skip(1).collect();
    if argv.len() < 3 {
        eprintln!("usage: mbm URDF SRDF PROBLEMS [DEADLINE_MS] [OUT.json|-] [RESOLUTION]");
        return ExitCode::from(2);
    }
    let mut args = MbmArgs::new(&argv[0], &argv[1], &argv[2]);
    if let Some(ms) = argv.get(3) {
        match ms.parse() {
            Ok(v) => args.deadline_ms = v,
            Err(_) => {
                eprintln!("DEADLINE_MS must be a number, got `{ms}`");
                return ExitCode::from(2);
            }
        }
    }
    if let Some(r) = argv.get(5) {
        match r.parse() {
            Ok(v) => args.resolution = v,
            Err(_) => {
                eprintln!("RESOLUTION must be a number, got `{r}`");
                return ExitCode::from(2);
            }
        }
    }
    let report = match run_mbm(&args, &mut |done, total| {
        if done % 25 == 0 || done == total {
            eprintln!("{done}/{total}");
        }
    }) {
        Ok(r) => r,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(2);
        }
    };
    print!("{}", render_table(&report));
    for p in report.problems.iter().filter(|p| !p.solved) {
        println!("{}#{} {:?}: {}", p.family, p.index, p.status, p.message.as_deref().unwrap_or(""));
    }
    if let Some(out) = argv.get(4).filter(|o| o.as_str() != "-") {
        let text = match serde_json::to_string(&report) {
            Ok(t) => t,
            Err(e) => {
                eprintln!("error: {e}");
                return ExitCode::from(2);
            }
        };
        if let Err(e) = std::fs::write(out, text) {
            eprintln!("cannot write {out}: {e}");
            return ExitCode::from(2);
        }
    }
    ExitCode::SUCCESS
}
