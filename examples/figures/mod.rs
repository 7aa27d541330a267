//! The volume-error figures `paper_figures` and `game_figures` draw (they need no window, so
//! they do not take `common`).

use plotters::coord::Shift;
use plotters::prelude::*;

/// One method's curve in a panel: its legend label and its (time s, volume error %) points.
pub struct Curve<'a> {
    pub label: String,
    pub points: &'a mut dyn Iterator<Item = (f64, f64)>,
}

/// Registers the built-in font under "sans-serif" (once per figure; plotters has none of its
/// own without system fonts).
pub fn register_font() -> Result<(), Box<dyn std::error::Error>> {
    plotters::style::register_font(
        "sans-serif",
        FontStyle::Normal,
        epaint_default_fonts::UBUNTU_LIGHT,
    )
    .map_err(|_| "the built-in font is not a valid font")?;
    Ok(())
}

/// One panel of the paper's Figure 2: the volume error in % over `0..t_max` s of each curve
/// (red, blue, green in order), the y range covering `lo..hi` with a margin, a legend.
pub fn volume_panel(
    panel: &DrawingArea<BitMapBackend<'_>, Shift>,
    caption: &str,
    t_max: f64,
    (lo, hi): (f64, f64),
    curves: Vec<Curve<'_>>,
) -> Result<(), Box<dyn std::error::Error>> {
    let pad = 0.05 * (hi - lo);
    let mut chart = ChartBuilder::on(panel)
        .caption(caption, ("sans-serif", 22))
        .margin(12)
        .x_label_area_size(36)
        .y_label_area_size(60)
        .build_cartesian_2d(0.0..t_max, (lo - pad)..(hi + pad))?;
    chart
        .configure_mesh()
        .x_desc("time (s)")
        .y_desc("volume error (%)")
        .label_style(("sans-serif", 15))
        .draw()?;
    for (curve, colour) in curves.into_iter().zip([RED, BLUE, RGBColor(20, 150, 60)]) {
        chart
            .draw_series(LineSeries::new(curve.points, colour.stroke_width(2)))?
            .label(curve.label)
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2))
            });
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::LowerLeft)
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .label_font(("sans-serif", 16))
        .draw()?;
    Ok(())
}
