//! Debug gizmos (feature `render`): the tet mesh coloured by each tet's volume error, the
//! particles touching a collider or sphere, and the pinned and driven particles.

use bevy::prelude::*;

use crate::components::{DrivenParticles, PinnedParticles, SoftBody};

/// What [`SoftBodyDebugPlugin`] draws; flip `enabled` at run time.
#[derive(Resource, Clone, Copy, Debug, Reflect)]
#[reflect(Resource)]
pub struct SoftBodyDebugGizmos {
    /// Draw anything at all.
    pub enabled: bool,
    /// Every tet's edges: white at rest volume, blue when compressed, red when stretched, fully
    /// coloured at `error_scale` relative error.
    pub tets: bool,
    /// The relative volume error drawn at full colour.
    pub error_scale: f32,
    /// The particles in contact in the last step, with their contact normals.
    pub contacts: bool,
    /// Pinned (yellow) and driven (green) particles.
    pub constrained: bool,
}

impl Default for SoftBodyDebugGizmos {
    fn default() -> Self {
        SoftBodyDebugGizmos {
            enabled: false,
            tets: true,
            error_scale: 0.1,
            contacts: true,
            constrained: true,
        }
    }
}

/// Draws [`SoftBodyDebugGizmos`] with Bevy's gizmos (needs the gizmo plugins, part of
/// `DefaultPlugins`).
pub struct SoftBodyDebugPlugin;

impl Plugin for SoftBodyDebugPlugin {
    fn build(&self, app: &mut App) {
        app.init_resource::<SoftBodyDebugGizmos>()
            .register_type::<SoftBodyDebugGizmos>()
            .add_systems(PostUpdate, draw_soft_body_gizmos);
    }
}

/// The colour of a tet with relative volume error `error`, saturating at `scale`.
pub fn volume_error_colour(error: f32, scale: f32) -> Color {
    let t = (error / scale.max(f32::EPSILON)).clamp(-1.0, 1.0);
    let white = LinearRgba::WHITE;
    let towards = if t < 0.0 {
        LinearRgba::rgb(0.05, 0.25, 1.0)
    } else {
        LinearRgba::rgb(1.0, 0.1, 0.05)
    };
    Color::from(white.mix(&towards, t.abs()))
}

fn draw_soft_body_gizmos(
    settings: Res<SoftBodyDebugGizmos>,
    bodies: Query<(
        &SoftBody,
        Option<&PinnedParticles>,
        Option<&DrivenParticles>,
    )>,
    mut gizmos: Gizmos,
) {
    if !settings.enabled {
        return;
    }
    for (body, pinned, driven) in &bodies {
        if !body.is_placed() {
            continue;
        }
        let state = body.state();
        let mesh = state.mesh();
        let x = state.positions();
        if settings.tets {
            for (tet, &v0) in mesh.tets().iter().zip(mesh.rest_volumes()) {
                let p = tet.map(|i| x[i as usize]);
                let error = (crate::core::geometry::signed_volume(&p) - v0) / v0;
                let colour = volume_error_colour(error, settings.error_scale);
                for (a, b) in [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)] {
                    gizmos.line(p[a], p[b], colour);
                }
            }
        }
        if settings.contacts {
            for (i, normal) in state.contacts() {
                let at = x[i];
                gizmos.sphere(
                    Isometry3d::from_translation(at),
                    0.015,
                    Color::srgb(1.0, 0.5, 0.0),
                );
                gizmos.line(at, at + normal * 0.08, Color::srgb(1.0, 0.5, 0.0));
            }
        }
        if settings.constrained {
            let mut mark = |indices: &[u32], colour: Color| {
                for &i in indices {
                    if let Some(&at) = x.get(i as usize) {
                        gizmos.sphere(Isometry3d::from_translation(at), 0.02, colour);
                    }
                }
            };
            if let Some(p) = pinned {
                mark(&p.0, Color::srgb(1.0, 0.9, 0.0));
            }
            if let Some(d) = driven {
                mark(&d.particles, Color::srgb(0.1, 1.0, 0.2));
            }
        }
    }
}
