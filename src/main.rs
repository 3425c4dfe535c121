//! The `camloop` binary: argument parsing and exit codes; the work lives in the library.

fn main() {}
