//! The paper's scenes.
