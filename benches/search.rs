//! Criterion benchmarks: search (filled in by its issue).
fn main() {}
