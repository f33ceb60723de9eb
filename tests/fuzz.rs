//! The short fuzzing pass of CI: every loader fed structure-aware random inputs (`embodied fuzz`,
//! fewer inputs than the long runs of docs/benchmarks.md), none may panic, every refusal names
//! its file, and each loader both accepts and refuses some, so the generators reach past the
//! syntax into the checks.
//!
//! `FUZZ_INPUTS=N` and `FUZZ_SEED=S` change the pass (the release command
//! `embodied fuzz --inputs N --seed S` runs the same inputs).
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use embodied::fuzz::{FuzzSettings, LOADERS, fuzz, render};

#[test]
fn every_loader_survives_generated_inputs() {
    let dir = common::TempDir::new("fuzz");
    let inputs: u64 = std::env::var("FUZZ_INPUTS").ok().and_then(|s| s.parse().ok()).unwrap_or(2000);
    let seed: u64 = std::env::var("FUZZ_SEED").ok().and_then(|s| s.parse().ok()).unwrap_or(1);
    let mut reports = Vec::new();
    for loader in LOADERS {
        let settings = FuzzSettings { loaders: vec![loader.to_string()], inputs, seed, dir: dir.join(loader) };
        let report = fuzz(&settings, |_| {}).expect("fuzz ran");
        eprint!("{}", render(&report));
        reports.extend(report.loaders);
    }
    for r in &reports {
        assert_eq!(r.panics, 0, "{}: panics {:?}", r.loader, r.panic_samples);
        assert_eq!(r.unnamed_errors, 0, "{}: an error names no file: {:?}", r.loader, r.unnamed_sample);
        assert!(r.accepted > 0 && r.refused > 0, "{}: {} accepted, {} refused", r.loader, r.accepted, r.refused);
        assert_eq!(r.accepted + r.refused, r.inputs);
    }
}
