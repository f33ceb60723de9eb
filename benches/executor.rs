//! Criterion benchmarks: executor (filled in by its issue).
fn main() {}
