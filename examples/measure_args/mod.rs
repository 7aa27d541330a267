//! Command-line values `bench` and `paper_figures` both read (they need no window, so they do
//! not take `common`), as clap value parsers.

/// A relative tolerance (`--tolerance 0.005`): a finite number, not negative.
pub fn fraction(value: &str) -> Result<f32, String> {
    value
        .parse::<f32>()
        .ok()
        .filter(|x| x.is_finite() && *x >= 0.0)
        .ok_or(format!("`{value}` is not a number of 0 or more"))
}

/// XPBD's substeps (`--xpbd-substeps 2`): 1 to 1000.
pub fn substeps(value: &str) -> Result<u32, String> {
    value
        .parse()
        .ok()
        .filter(|n| (1..=1000).contains(n))
        .ok_or(format!("`{value}` is not 1 to 1000"))
}
