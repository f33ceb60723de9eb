//! Criterion benchmarks: kinematics (filled in by its issue).
fn main() {}
