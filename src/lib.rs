//! Almost incompressible soft bodies for Bevy, after "Simulating Almost Incompressible
//! Deformable Objects" (Diziol, Bayer, Bender 2009).
#![warn(missing_docs)]

pub mod core;
