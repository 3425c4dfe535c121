//! Dashboard benchmarks (placeholder while the dashboard is written).
fn main() {}
