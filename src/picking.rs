//! Soft bodies in Bevy's picking (feature `picking`): [`SoftBodyPickingPlugin`] is a
//! `bevy_picking` backend whose pointer rays hit a body's deformed surface (its boundary
//! triangles where the particles are now), and [`SoftBodyDraggable`] lets the pointer drag a
//! body by the point it pressed, through a [`SoftBodyGrab`] spring. Hovering, clicking and
//! dragging a soft body then work as they do for meshes and sprites: observers of
//! `Pointer<Click>`, `Pointer<Over>`, ... on the body's entity.
//!
//! Each hit carries a [`SoftBodyHit`] in its `extra` data: the triangle, the point's weights
//! in it and the nearest particle.

use bevy::picking::Pickable;
use bevy::picking::PickingSystems;
use bevy::picking::backend::ray::{RayId, RayMap};
use bevy::picking::backend::{HitData, PointerHits};
use bevy::picking::events::{Drag, DragEnd, DragStart, Pointer};
use bevy::prelude::*;

use crate::components::{SoftBody, SoftBodyGrab};

/// The picking backend for soft bodies, in [`SoftBodyPlugins`](crate::SoftBodyPlugins) with
/// feature `picking`. Needs Bevy's picking plugins (in `DefaultPlugins`); in an app without
/// them (`MinimalPlugins`) its backend does not run.
#[derive(Default)]
pub struct SoftBodyPickingPlugin;

impl Plugin for SoftBodyPickingPlugin {
    fn build(&self, app: &mut App) {
        app.register_type::<SoftBodyDraggable>()
            .add_systems(
                PreUpdate,
                soft_body_hits
                    .in_set(PickingSystems::Backend)
                    .run_if(resource_exists::<RayMap>)
                    .run_if(resource_exists::<Messages<PointerHits>>),
            )
            .add_observer(start_drag)
            .add_observer(drag)
            .add_observer(end_drag);
    }
}

/// What a pointer hit on a soft body carries in [`HitData::extra`] (read it with
/// `hit.extra_as::<SoftBodyHit>()`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SoftBodyHit {
    /// The boundary triangle's particles.
    pub triangle: [u32; 3],
    /// The hit point's barycentric weights in it.
    pub weights: Vec3,
    /// The triangle's particle nearest the hit.
    pub particle: u32,
}

/// Lets the pointer drag the [`SoftBody`] on the same entity: pressing it and moving grabs the
/// material around the point pressed with a [`SoftBodyGrab`] spring, pulled toward the pointer
/// at the depth it was grabbed at; releasing lets go. The spring is given as Box2D's mouse
/// joint gives it, for the body's mass when the drag starts: a frequency and a damping ratio
/// (`k = M (2 pi f)^2`, `c = 2 zeta M 2 pi f`) and a largest acceleration (`M a`), so that a
/// light and a heavy body follow the pointer alike.
#[derive(Component, Clone, Copy, Debug, Reflect)]
#[reflect(Component)]
pub struct SoftBodyDraggable {
    /// How fast the body follows, Hz.
    pub frequency: f32,
    /// The damping ratio: 1 follows without swinging past the pointer.
    pub damping_ratio: f32,
    /// The largest acceleration the pull gives the body, m/s^2.
    pub max_acceleration: f32,
    /// How far around the pressed point the grab holds the material, m (`None`: a tenth of
    /// the body's size).
    pub radius: Option<f32>,
}

impl Default for SoftBodyDraggable {
    /// 2 Hz, damping ratio 1, at most 3 g (30 m/s^2), the default radius.
    fn default() -> Self {
        SoftBodyDraggable {
            frequency: 2.0,
            damping_ratio: 1.0,
            max_acceleration: 30.0,
            radius: None,
        }
    }
}

/// A drag in progress: the ray it follows and the grabbed point's distance along it.
#[derive(Component, Clone, Copy, Debug)]
struct Dragging {
    ray: RayId,
    depth: f32,
}

/// The backend: every pointer ray against every placed soft body's surface.
fn soft_body_hits(
    rays: Res<RayMap>,
    cameras: Query<&Camera>,
    bodies: Query<(Entity, &SoftBody, Option<&Pickable>)>,
    mut hits: MessageWriter<PointerHits>,
) {
    for (&id, &ray) in rays.iter() {
        let Ok(camera) = cameras.get(id.camera) else {
            continue;
        };
        let mut picks = Vec::new();
        for (entity, body, pickable) in &bodies {
            if !body.is_placed() || pickable.is_some_and(|p| !p.is_hoverable) {
                continue;
            }
            let Some(hit) = body.state().ray_cast(ray.origin, *ray.direction, f32::MAX) else {
                continue;
            };
            let extra = SoftBodyHit {
                triangle: hit.triangle,
                weights: hit.weights,
                particle: hit.particle,
            };
            let data = HitData::new_with_extra(
                id.camera,
                hit.distance,
                Some(hit.point),
                Some(hit.normal),
                extra,
            );
            picks.push((entity, data));
        }
        if !picks.is_empty() {
            hits.write(PointerHits::new(id.pointer, picks, camera.order as f32));
        }
    }
}

fn start_drag(
    event: On<Pointer<DragStart>>,
    draggable: Query<(&SoftBodyDraggable, &SoftBody)>,
    mut commands: Commands,
) {
    let (entity, hit) = (event.entity, &event.event.hit);
    let (Ok((draggable, body)), Some(point)) = (draggable.get(entity), hit.position) else {
        return;
    };
    let mass: f32 = body.state().masses().iter().sum();
    let omega = std::f32::consts::TAU * draggable.frequency;
    let mut grab = SoftBodyGrab::new(point, mass * omega * omega);
    grab.damping = 2.0 * draggable.damping_ratio * mass * omega;
    grab.max_force = mass * draggable.max_acceleration;
    grab.radius = draggable.radius;
    let ray = RayId::new(hit.camera, event.pointer_id);
    commands.entity(entity).insert((
        grab,
        Dragging {
            ray,
            depth: hit.depth,
        },
    ));
}

fn drag(
    event: On<Pointer<Drag>>,
    rays: Option<Res<RayMap>>,
    mut grabs: Query<(&mut SoftBodyGrab, &Dragging)>,
) {
    let (Ok((mut grab, dragging)), Some(rays)) = (grabs.get_mut(event.entity), rays) else {
        return;
    };
    if let Some(ray) = rays.map.get(&dragging.ray) {
        grab.target = ray.origin + *ray.direction * dragging.depth;
    }
}

fn end_drag(
    event: On<Pointer<DragEnd>>,
    dragging: Query<(), With<Dragging>>,
    mut commands: Commands,
) {
    if dragging.contains(event.entity) {
        commands
            .entity(event.entity)
            .remove::<(SoftBodyGrab, Dragging)>();
    }
}
