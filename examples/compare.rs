//! The baseline (explicit volume forces, left, blue) and the paper's volume impulses (right,
//! red) side by side in one scene, as in the paper's figures; both volume errors are on screen
//! and plotted in the panel. `--scene NAME` picks the scene (default: soft_cube).

mod common;

use bevy::prelude::*;
use bevy_soft_body::scenes::PaperScene;

fn main() -> AppExit {
    let scene = common::ExampleOptions::from_args()
        .scene
        .unwrap_or(PaperScene::SoftCube);
    common::example_app(
        "bevy_soft_body: baseline vs volume impulses",
        Some(common::Layout::Compare(scene)),
    )
    .run()
}
