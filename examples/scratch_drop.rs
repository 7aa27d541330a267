use bevy_soft_body::core::*;
use glam::{UVec3, Vec3};
use parry3d::math::Pose;
use parry3d::shape::SharedShape;
use std::sync::Arc;
fn main() {
    let args: Vec<String> = std::env::args().collect();
    let g: f32 = args.get(1).map(|s| s.parse().unwrap()).unwrap_or(0.1);
    let mass: f32 = args.get(2).map(|s| s.parse().unwrap()).unwrap_or(300.0);
    let mesh = Arc::new(box_grid(UVec3::splat(12), Vec3::splat(0.1), Vec3::ZERO).unwrap());
    let mat = SoftBodyMaterial {
        distance_stiffness: 0.2,
        method: VolumeMethod::PAPER_BASELINE,
        ..Default::default()
    };
    let mut b = SoftBodyState::new(mesh, mat).unwrap();
    let ground = vec![ColliderInstance::new(
        SharedShape::halfspace(Vec3::Y),
        Pose::IDENTITY,
        0.8,
    )];
    let mut spheres = vec![RigidSphereState {
        position: Vec3::new(0.6, 1.7, 0.6),
        velocity: Vec3::new(0.0, -0.3, 0.0),
        radius: 0.4,
        inv_mass: 1.0 / mass,
        friction: 0.5,
    }];
    let h = 0.01;
    let gv = Vec3::new(0.0, -g, 0.0);
    for step in 1..=800 {
        b.begin_step();
        b.apply_forces(h, gv);
        spheres[0].apply_forces(h, gv);
        let after_forces: f32 = b
            .velocities()
            .iter()
            .map(|v| v.length())
            .fold(0.0, f32::max);
        spheres[0].resolve_static_contacts(h, &ground);
        b.resolve_sphere_contacts(h, &mut spheres);
        b.resolve_static_contacts(h, &ground);
        let after_contacts: f32 = b
            .velocities()
            .iter()
            .map(|v| v.length())
            .fold(0.0, f32::max);
        spheres[0].resolve_static_contacts(h, &ground);
        b.resolve_sphere_contacts(h, &mut spheres);
        b.resolve_static_contacts(h, &ground);
        b.integrate_positions(h);
        spheres[0].integrate_position(h);
        let (imax, vmax) = b
            .velocities()
            .iter()
            .enumerate()
            .map(|(i, v)| (i, v.length()))
            .fold((0, 0.0), |a, x| if x.1 > a.1 { x } else { a });
        if step % 10 == 0 || vmax > 2.0 {
            let m = b.volume_metrics();
            println!(
                "t={:.2} err={:+.3}% inv={} sphere_y={:.3} vmax={vmax:.2} (particle {imax} mass {:.3} at {:?}) after_forces={after_forces:.2} after_contacts={after_contacts:.2}",
                step as f32 * h,
                m.volume_error_pct,
                m.inverted_tets,
                spheres[0].position.y,
                b.masses()[imax],
                b.positions()[imax]
            );
            if vmax > 50.0 || !vmax.is_finite() {
                break;
            }
        }
    }
}
