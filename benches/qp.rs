//! Criterion benchmarks: qp (filled in by its issue).
fn main() {}
