//! The command-line values `bench` and `paper_figures` both read (they need no window, so they
//! do not take `common`).

/// A relative tolerance given after `flag` (`--tolerance 0.005`): a finite number, not negative.
pub fn fraction(flag: &str, value: Option<String>) -> Result<f32, String> {
    let value = value.ok_or(format!("{flag} needs a number"))?;
    value
        .parse::<f32>()
        .ok()
        .filter(|x| x.is_finite() && *x >= 0.0)
        .ok_or(format!("{flag}: `{value}` is not a number of 0 or more"))
}

/// XPBD's substeps given after `flag` (`--xpbd-substeps 2`): 1 to 1000.
pub fn substeps(flag: &str, value: Option<String>) -> Result<u32, String> {
    let value = value.ok_or(format!("{flag} needs a number"))?;
    value
        .parse()
        .ok()
        .filter(|n| (1..=1000).contains(n))
        .ok_or(format!("{flag}: `{value}` is not 1 to 1000"))
}
