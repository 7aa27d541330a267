//! Command-line values `bench` and `paper_figures` both read (they need no window, so they do
//! not take `common`), as clap value parsers and arguments.

use bevy_soft_body::core::ImpulseSettings;

/// The paper's method's tolerances, given on the command line or left at the paper's defaults.
#[derive(clap::Args)]
pub struct ToleranceArgs {
    /// The paper's method's `ImpulseSettings::tolerance`
    #[arg(long, value_parser = fraction)]
    pub tolerance: Option<f32>,
    /// The paper's method's `ImpulseSettings::ring_tet_tolerance`
    #[arg(long, value_parser = fraction)]
    pub ring_tet_tolerance: Option<f32>,
}

impl ToleranceArgs {
    /// The paper's settings with these tolerances.
    pub fn settings(&self) -> ImpulseSettings {
        let paper = ImpulseSettings::PAPER;
        ImpulseSettings {
            tolerance: self.tolerance.unwrap_or(paper.tolerance),
            ring_tet_tolerance: self.ring_tet_tolerance.unwrap_or(paper.ring_tet_tolerance),
            ..paper
        }
    }
}

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
