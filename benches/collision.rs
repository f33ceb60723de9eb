//! Criterion benchmarks: collision (filled in by its issue).
fn main() {}
