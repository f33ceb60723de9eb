//! Criterion benchmarks: motion (filled in by its issue).
fn main() {}
