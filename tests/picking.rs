//! Picking without a window (feature `picking`): a pointer ray from a camera through a soft
//! body hits its deformed surface, and dragging with the pointer pulls the body toward it.
//! The pointer's ray is put in `RayMap` by hand, where Bevy's picking would put the mouse's.

use std::time::Duration;

use bevy::camera::NormalizedRenderTarget;
use bevy::picking::backend::ray::{RayId, RayMap};
use bevy::picking::backend::{HitData, PointerHits};
use bevy::picking::events::{Drag, DragEnd, DragStart, Pointer};
use bevy::picking::pointer::{Location, PointerButton, PointerId};
use bevy::prelude::*;
use bevy::time::TimeUpdateStrategy;
use bevy_soft_body::core::box_grid;
use bevy_soft_body::picking::{SoftBodyDraggable, SoftBodyHit, SoftBodyPickingPlugin};
use bevy_soft_body::prelude::*;

/// A 0.3 m jelly cube dropped 0.1 m onto the ground, a camera, and the picking backend.
fn jelly_on_ground() -> (App, Entity, Entity) {
    let mut app = App::new();
    app.add_plugins((
        MinimalPlugins,
        SoftBodyPlugin::default(),
        SoftBodyPickingPlugin,
    ))
    .insert_resource(TimeUpdateStrategy::ManualDuration(Duration::from_millis(
        10,
    )))
    .init_resource::<RayMap>()
    .add_message::<PointerHits>();
    let mesh = box_grid(UVec3::splat(6), Vec3::splat(0.05), Vec3::splat(-0.15)).unwrap();
    let jelly = SoftBody::new(mesh.into(), SoftBodyMaterial::JELLY).unwrap();
    let world = app.world_mut();
    let body = world
        .spawn((
            jelly,
            SoftBodyDraggable::default(),
            Transform::from_xyz(0.0, 0.25, 0.0),
        ))
        .id();
    world.spawn((StaticCollider::ground(0.8), Transform::default()));
    let camera = world.spawn(Camera::default()).id();
    (app, body, camera)
}

/// An update in which no time passes (no step): the hits are on the particles as they are.
fn update_without_step(app: &mut App) {
    app.insert_resource(TimeUpdateStrategy::ManualDuration(Duration::ZERO));
    app.update();
    app.insert_resource(TimeUpdateStrategy::ManualDuration(Duration::from_millis(
        10,
    )));
}

/// Points the mouse's ray of `camera` from `origin` toward `through`.
fn aim(app: &mut App, camera: Entity, origin: Vec3, through: Vec3) {
    let ray = Ray3d::new(origin, Dir3::new(through - origin).unwrap());
    // Only this update's hits.
    app.world_mut()
        .resource_mut::<Messages<PointerHits>>()
        .clear();
    let mut rays = app.world_mut().resource_mut::<RayMap>();
    rays.map.clear();
    rays.map.insert(RayId::new(camera, PointerId::Mouse), ray);
}

/// The hits the backend wrote in the last update.
fn hits(app: &App) -> Vec<(Entity, HitData)> {
    let messages = app.world().resource::<Messages<PointerHits>>();
    let mut cursor = messages.get_cursor();
    cursor
        .read(messages)
        .flat_map(|h| h.picks.iter().cloned())
        .collect()
}

/// The mouse's `event` on `body`.
fn pointer<E: std::fmt::Debug + Clone + Reflect>(body: Entity, event: E) -> Pointer<E> {
    let location = Location {
        target: NormalizedRenderTarget::None {
            width: 100,
            height: 100,
        },
        position: Vec2::ZERO,
    };
    Pointer::new(PointerId::Mouse, location, event, body)
}

#[test]
fn a_pointer_ray_hits_the_deformed_surface() {
    let (mut app, body, camera) = jelly_on_ground();
    // Landed and squashed: its top is no longer where the rest shape's is.
    for _ in 0..60 {
        app.update();
    }
    let (x, z) = (0.04, -0.03);
    aim(&mut app, camera, Vec3::new(x, 2.0, z), Vec3::new(x, 0.0, z));
    update_without_step(&mut app);
    let found = hits(&app);
    assert_eq!(found.len(), 1, "{found:?}");
    let (entity, hit) = &found[0];
    assert_eq!(*entity, body);
    let point = hit.position.unwrap();
    let state = app.world().get::<SoftBody>(body).unwrap().state();
    // On the top surface where the particles are now: within a millimetre of the top
    // particles' height around the ray (the surface between them is flat to that).
    let top = state
        .positions()
        .iter()
        .filter(|p| Vec2::new(p.x - x, p.z - z).length() < 0.06)
        .map(|p| p.y)
        .fold(f32::NEG_INFINITY, f32::max);
    assert!((point.y - top).abs() < 1e-3, "hit at {point}, top at {top}");
    assert!(top < 0.3 - 2e-3, "the jelly sags: top {top}");
    assert!((hit.depth - (2.0 - point.y)).abs() < 1e-4);
    assert!(hit.normal.unwrap().y > 0.9);
    let extra = hit.extra_as::<SoftBodyHit>().unwrap();
    let [a, b, c] = extra.triangle.map(|i| state.positions()[i as usize]);
    let on_triangle = a * extra.weights.x + b * extra.weights.y + c * extra.weights.z;
    assert!(on_triangle.distance(point) < 1e-4);
    assert!(state.positions()[extra.particle as usize].distance(point) < 0.05);
    // A ray beside the body hits nothing.
    aim(
        &mut app,
        camera,
        Vec3::new(1.0, 2.0, 0.0),
        Vec3::new(1.0, 0.0, 0.0),
    );
    app.update();
    assert!(hits(&app).is_empty());
}

#[test]
fn dragging_pulls_the_body_toward_the_pointer() {
    let (mut app, body, camera) = jelly_on_ground();
    for _ in 0..60 {
        app.update();
    }
    let eye = Vec3::new(0.0, 1.0, 2.0);
    aim(&mut app, camera, eye, Vec3::new(0.0, 0.2, 0.0));
    update_without_step(&mut app);
    let (_, hit) = hits(&app)
        .into_iter()
        .next()
        .expect("the body is under the pointer");
    app.world_mut().trigger(pointer(
        body,
        DragStart {
            button: PointerButton::Primary,
            hit: hit.clone(),
        },
    ));
    app.world_mut().flush();
    assert!(app.world().get::<SoftBodyGrab>(body).is_some());
    let centre = |app: &App| {
        app.world()
            .get::<SoftBody>(body)
            .unwrap()
            .state()
            .centre_of_mass()
    };
    let start = centre(&app);
    // The pointer moves up and to the side: at the grab's depth its ray reaches `target`.
    let target = eye + (Vec3::new(0.6, 0.8, 0.0) - eye).normalize() * hit.depth;
    aim(&mut app, camera, eye, target);
    for _ in 0..100 {
        app.world_mut().trigger(pointer(
            body,
            Drag {
                button: PointerButton::Primary,
                distance: Vec2::new(50.0, -30.0),
                delta: Vec2::ZERO,
            },
        ));
        app.update();
    }
    let grab = app.world().get::<SoftBodyGrab>(body).unwrap();
    assert!(grab.target.distance(target) < 1e-4);
    let end = centre(&app);
    let pulled = (end - start).dot((target - start).normalize());
    assert!(
        pulled > 0.3 * start.distance(target),
        "the centre moved {pulled} m toward the pointer, {} m away",
        start.distance(target)
    );
    // Pulled by one point, lifted off the ground, it keeps its volume.
    let stats = app.world().get::<SoftBodyStats>(body).unwrap();
    assert!(stats.peak_volume_error_pct.abs() < 1.0, "{stats:?}");
    assert!(end.y > start.y, "pulled up: {start} -> {end}");
    app.world_mut().trigger(pointer(
        body,
        DragEnd {
            button: PointerButton::Primary,
            distance: Vec2::new(50.0, -30.0),
        },
    ));
    app.update();
    assert!(app.world().get::<SoftBodyGrab>(body).is_none());
}
