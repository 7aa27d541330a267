//! The paper's "Bar twist" scene in a window, with the paper's method and the detailed surface.
//! Controls are listed on screen; `--screenshot PATH --frames N` saves a picture and exits.

mod common;

use bevy::prelude::*;
use bevy_soft_body::scenes::PaperScene;

fn main() -> AppExit {
    common::example_app(
        "bevy_soft_body: Bar twist",
        Some(common::Layout::Single(PaperScene::BarTwist)),
    )
    .run()
}
