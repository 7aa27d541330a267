//! An egui inspector for soft bodies (feature `egui`): per body the method and each of its
//! switches, the material's parameters (edits apply at once), the volume error, solver time and
//! inverted tets, and a live plot of every body's volume error over time like the paper's
//! Figure 2.

use bevy::platform::collections::HashMap;
use bevy::prelude::*;
use bevy_egui::{EguiContexts, EguiPlugin, EguiPrimaryContextPass, egui};
use egui_plot::{Legend, Line, Plot};

use crate::components::{SoftBody, SoftBodyStats};
use crate::core::{Elasticity, ImpulseSettings, Plasticity, SoftBodyMaterial, VolumeMethod};

/// Shows the inspector panel. Adds `EguiPlugin` if the app has none yet.
pub struct SoftBodyInspectorPlugin;

/// The plot's line colours: red first for the volume impulses (and XPBD), blue first for the
/// baseline, as the `compare` example paints its two bodies; the next body of the same kind
/// takes the next colour (red, green, blue, as games often tell bodies apart), so that every
/// line can be told apart.
const PLOT_COLOURS: [&[egui::Color32]; 2] = [
    &[
        egui::Color32::from_rgb(230, 70, 90),
        egui::Color32::from_rgb(60, 180, 90),
        egui::Color32::from_rgb(80, 120, 240),
        egui::Color32::from_rgb(240, 160, 40),
        egui::Color32::from_rgb(170, 90, 220),
        egui::Color32::from_rgb(40, 190, 200),
    ],
    &[
        egui::Color32::from_rgb(90, 130, 240),
        egui::Color32::from_rgb(130, 210, 255),
        egui::Color32::from_rgb(150, 110, 240),
    ],
];

/// Seconds of history the plot keeps.
const HISTORY_SECS: f64 = 30.0;

/// Each body's volume error over simulated time, sampled once per frame.
#[derive(Resource, Default)]
pub struct VolumeErrorHistory {
    series: HashMap<Entity, Vec<[f64; 2]>>,
}

/// Whether the panel is shown.
#[derive(Resource, Clone, Copy, Debug)]
pub struct SoftBodyInspector {
    /// Show the panel.
    pub visible: bool,
}

impl Default for SoftBodyInspector {
    fn default() -> Self {
        SoftBodyInspector { visible: true }
    }
}

impl Plugin for SoftBodyInspectorPlugin {
    fn build(&self, app: &mut App) {
        if !app.is_plugin_added::<EguiPlugin>() {
            app.add_plugins(EguiPlugin::default());
        }
        app.init_resource::<VolumeErrorHistory>()
            .init_resource::<SoftBodyInspector>()
            .add_systems(Update, record_history)
            .add_systems(EguiPrimaryContextPass, inspector_panel);
    }
}

fn record_history(
    time: Res<Time<Fixed>>,
    bodies: Query<(Entity, &SoftBody, &SoftBodyStats)>,
    mut history: ResMut<VolumeErrorHistory>,
) {
    let t = time.elapsed_secs_f64();
    history.series.retain(|e, _| bodies.contains(*e));
    for (entity, body, stats) in &bodies {
        if !body.is_placed() {
            continue;
        }
        let series = history.series.entry(entity).or_default();
        // A scene spawned again starts its own time axis.
        if series.last().is_some_and(|p| p[0] > t) {
            series.clear();
        }
        if series.last().is_none_or(|p| p[0] < t) {
            series.push([t, stats.volume_error_pct]);
        }
        let cut = series.partition_point(|p| p[0] < t - HISTORY_SECS);
        series.drain(..cut);
    }
}

fn inspector_panel(
    mut contexts: EguiContexts,
    inspector: Res<SoftBodyInspector>,
    mut bodies: Query<(Entity, Option<&Name>, &mut SoftBody, &SoftBodyStats)>,
    history: Res<VolumeErrorHistory>,
) -> Result {
    if !inspector.visible {
        return Ok(());
    }
    let ctx = contexts.ctx_mut()?;
    let mut root = egui::Ui::new(
        ctx.clone(),
        "soft_body_inspector_root".into(),
        egui::UiBuilder::new()
            .layer_id(egui::LayerId::background())
            .max_rect(ctx.viewport_rect()),
    );
    egui::Panel::right("soft_body_inspector")
        .default_size(330.0)
        .resizable(true)
        .show(&mut root, |ui| {
            ui.heading("Soft bodies");
            // (entity, label, baseline?)
            let mut names = Vec::new();
            egui::ScrollArea::vertical()
                .max_height(ui.available_height() - 250.0)
                .show(ui, |ui| {
                    for (entity, name, mut body, stats) in &mut bodies {
                        let label = name.map_or_else(|| format!("{entity}"), |n| n.to_string());
                        let baseline = matches!(
                            body.state().material().method,
                            VolumeMethod::Baseline { .. }
                        );
                        names.push((entity, label.clone(), baseline));
                        egui::CollapsingHeader::new(&label)
                            .id_salt(entity)
                            .default_open(true)
                            .show(ui, |ui| body_controls(ui, &mut body, stats));
                    }
                });
            ui.separator();
            ui.label("Volume error % over time");
            Plot::new("volume_error_plot")
                .height(200.0)
                .legend(Legend::default())
                .include_y(-1.0)
                .include_y(1.0)
                .x_axis_label("s")
                .show(ui, |plot| {
                    let mut drawn = [0usize; 2];
                    for (entity, label, baseline) in &names {
                        if let Some(series) = history.series.get(entity) {
                            let palette = PLOT_COLOURS[*baseline as usize];
                            let colour = palette[drawn[*baseline as usize] % palette.len()];
                            drawn[*baseline as usize] += 1;
                            plot.line(Line::new(label.clone(), series.clone()).color(colour));
                        }
                    }
                });
        });
    Ok(())
}

fn body_controls(ui: &mut egui::Ui, body: &mut SoftBody, stats: &SoftBodyStats) {
    ui.label(format!(
        "volume error {:+.3} % (peak {:.3} %)",
        stats.volume_error_pct, stats.peak_volume_error_pct
    ));
    ui.label(format!(
        "solver {:.2} ms/step, {} inverted tets, {} tets{}",
        stats.step_ms,
        stats.inverted_tets,
        body.state().mesh().tet_count(),
        if stats.sleeping { ", asleep" } else { "" }
    ));
    let mut m = *body.state().material();
    let mut chosen = m.method.name();
    ui.horizontal(|ui| {
        ui.label("method");
        ui.radio_value(&mut chosen, "baseline", "baseline");
        ui.radio_value(&mut chosen, "paper", "impulses");
        ui.radio_value(&mut chosen, "xpbd", "XPBD");
        ui.radio_value(&mut chosen, "clusters", "XPBD + clusters");
    });
    if chosen != m.method.name() {
        m.method = match chosen {
            "baseline" => VolumeMethod::PAPER_BASELINE,
            "xpbd" => VolumeMethod::XPBD,
            "clusters" => VolumeMethod::XPBD_CLUSTERS,
            _ => VolumeMethod::Impulses(ImpulseSettings::PAPER),
        };
    }
    match &mut m.method {
        VolumeMethod::Impulses(s) => {
            ui.checkbox(&mut s.one_ring, "one-ring impulses");
            ui.checkbox(&mut s.per_tet, "per-tet correction");
            ui.add(egui::Slider::new(&mut s.gamma, 0.0..=1.0).text("gamma"));
            ui.checkbox(&mut s.neighbour_clamp, "neighbour clamp");
        }
        VolumeMethod::Baseline { volume_stiffness } => {
            ui.add(
                egui::Slider::new(volume_stiffness, 0.0..=20.0)
                    .logarithmic(true)
                    .text("k_V"),
            );
        }
        VolumeMethod::Xpbd(s) => {
            ui.add(
                egui::Slider::new(&mut s.substeps, 1..=100)
                    .logarithmic(true)
                    .text("substeps"),
            );
            if s.clusters > 0 {
                ui.add(egui::Slider::new(&mut s.clusters, 1..=64).text("clusters"));
            }
        }
    }
    elasticity_controls(ui, &mut m);
    let mut plastic = m.plasticity.is_some();
    ui.checkbox(&mut plastic, "plastic springs");
    match (plastic, &mut m.plasticity) {
        (true, None) => {
            m.plasticity = Some(Plasticity {
                yield_strain: 0.03,
                creep: 4.0,
                max_strain: 0.5,
            })
        }
        (false, Some(_)) => m.plasticity = None,
        (true, Some(p)) => {
            ui.add(egui::Slider::new(&mut p.yield_strain, 0.0..=0.5).text("yield"));
            ui.add(egui::Slider::new(&mut p.creep, 0.0..=20.0).text("creep /s"));
            ui.add(egui::Slider::new(&mut p.max_strain, 0.0..=0.9).text("max"));
        }
        (false, None) => {}
    }
    if m != *body.state().material()
        && let Err(e) = body.set_material(m)
    {
        ui.colored_label(egui::Color32::LIGHT_RED, e.to_string());
    }
}

/// The sliders of a material's elasticity and damping.
fn elasticity_controls(ui: &mut egui::Ui, m: &mut SoftBodyMaterial) {
    match &mut m.elasticity {
        Elasticity::Springs {
            distance_stiffness,
            damping,
        } => {
            ui.add(
                egui::Slider::new(distance_stiffness, 0.0..=50.0)
                    .logarithmic(true)
                    .text("k_D"),
            );
            ui.add(
                egui::Slider::new(damping, 0.0..=200.0)
                    .logarithmic(true)
                    .text("damping"),
            );
        }
        Elasticity::Elastic(e) => {
            ui.add(
                egui::Slider::new(&mut e.youngs_modulus, 1e3..=1e8)
                    .logarithmic(true)
                    .text("Young's modulus (Pa)"),
            );
            ui.add(egui::Slider::new(&mut e.poisson_ratio, 0.0..=0.5).text("Poisson's ratio"));
            ui.add(
                egui::Slider::new(&mut e.damping, 0.0..=0.1)
                    .logarithmic(true)
                    .text("damping (s)"),
            );
        }
    }
    ui.add(
        egui::Slider::new(&mut m.linear_damping, 0.0..=5.0)
            .logarithmic(true)
            .text("drag"),
    );
    ui.add(
        egui::Slider::new(&mut m.deformation_damping, 0.0..=50.0)
            .logarithmic(true)
            .text("deformation damping /s"),
    );
    ui.add(
        egui::Slider::new(&mut m.rolling_resistance, 0.0..=1.0)
            .logarithmic(true)
            .text("rolling resistance"),
    );
}
