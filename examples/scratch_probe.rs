use bevy_soft_body::core::VolumeMethod;
use bevy_soft_body::prelude::*;
use bevy_soft_body::scenes::{PaperScene, headless_scene_app};
fn main() {
    let scene = PaperScene::from_name(&std::env::args().nth(1).unwrap()).unwrap();
    let secs: f32 = std::env::args()
        .nth(2)
        .map(|s| s.parse().unwrap())
        .unwrap_or(scene.duration_secs());
    for method in [VolumeMethod::PAPER_BASELINE, VolumeMethod::PAPER_IMPULSES] {
        let (mut app, body) = headless_scene_app(scene, method);
        for step in 1..=(secs / 0.01) as usize {
            app.update();
            if step % 50 == 0 {
                let b = app.world().get::<SoftBody>(body).unwrap();
                let rest = b.state().mesh().positions();
                let rms = (b
                    .state()
                    .positions()
                    .iter()
                    .zip(rest)
                    .map(|(p, r)| p.distance_squared(*r))
                    .sum::<f32>()
                    / rest.len() as f32)
                    .sqrt();
                let st = app.world().get::<SoftBodyStats>(body).unwrap();
                println!(
                    "{} t={:.1} rms={rms:.3} com_y={:.3} err={:+.3}",
                    method.name(),
                    step as f32 * 0.01,
                    b.state().centre_of_mass().y,
                    st.volume_error_pct
                );
            }
        }
    }
}
