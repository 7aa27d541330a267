//! A body's settings as components, in the style of avian's (`SleepThreshold`,
//! `SleepingDisabled`): insert, change or remove them at any time and the plugin applies them
//! before the next step (`SoftBodySystems::Prepare`); they show in an inspector. A body without
//! them has the defaults each documents.

use bevy::prelude::*;

use crate::core::{RunawayLimits, SleepSettings, SoftContactSettings, TearSettings};

/// How this soft body meets other soft bodies and itself. Without it (or
/// [`SoftBodyContactsDisabled`]) a body meets the other soft bodies with a gap of a tenth of its
/// shortest rest edge, and not itself.
#[derive(Component, Reflect, Clone, Copy, Debug, Default, PartialEq)]
#[reflect(Component, Default, Debug, PartialEq)]
pub struct SoftBodyContacts {
    /// The gap kept between a particle and another body's surface, in metres (a pair keeps
    /// the larger of its two bodies'); zero or less: a tenth of the body's shortest rest edge.
    pub thickness: f32,
    /// Whether the body also meets itself (a long body that folds, a tail that touches).
    pub self_contacts: bool,
}

impl SoftBodyContacts {
    /// The core's settings for a body whose shortest rest edge is `shortest_edge`.
    pub(crate) fn settings(&self, shortest_edge: f32) -> SoftContactSettings {
        let mut settings = SoftContactSettings::for_edge(shortest_edge);
        if self.thickness > 0.0 {
            settings.thickness = self.thickness;
        }
        settings.self_contacts = self.self_contacts;
        settings
    }
}

/// Marks a soft body that passes through the other soft bodies (and itself).
#[derive(Component, Reflect, Clone, Copy, Debug, Default, PartialEq)]
#[reflect(Component, Default, Debug, PartialEq)]
pub struct SoftBodyContactsDisabled;

/// When this soft body falls asleep: every particle within `speed * time` of where it stood
/// for `time` seconds (a body in substeps, as every preset is; the paper's explicit springs
/// never sleep). Without it, the defaults below.
#[derive(Component, Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Component, Default, Debug, PartialEq)]
pub struct SoftBodySleepThreshold {
    /// The mean speed, m/s, under which every particle must stay. Default: 0.01 (5 mm in half
    /// a second, so a visible wobble is not frozen).
    pub speed: f32,
    /// How long, s, every particle must stay that still. Default: 0.5 (Jolt's
    /// `mTimeBeforeSleep`).
    pub time: f32,
}

impl Default for SoftBodySleepThreshold {
    fn default() -> Self {
        let SleepSettings { speed, time } = SleepSettings::default();
        SoftBodySleepThreshold { speed, time }
    }
}

/// Marks a soft body that never falls asleep (it wakes if asleep).
#[derive(Component, Reflect, Clone, Copy, Debug, Default, PartialEq)]
#[reflect(Component, Default, Debug, PartialEq)]
pub struct SoftBodySleepingDisabled;

/// When this soft body counts as running away: it is then put back at rest where it last was
/// sane and reported (`SoftBodyErrorKind::Runaway`). Without it, the defaults below.
#[derive(Component, Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Component, Default, Debug, PartialEq)]
pub struct SoftBodyRunawayLimits {
    /// Fastest particle speed, m/s. Default: 500 (faster than anything a soft body does in a
    /// game; an exploding body passes it within a few steps).
    pub max_speed: f32,
    /// Largest extent (the diagonal of the particles' bounding box) as a multiple of the rest
    /// shape's. Default: 10.
    pub max_stretch: f32,
}

impl Default for SoftBodyRunawayLimits {
    fn default() -> Self {
        let RunawayLimits {
            max_speed,
            max_stretch,
        } = RunawayLimits::default();
        SoftBodyRunawayLimits {
            max_speed,
            max_stretch,
        }
    }
}

/// Makes this soft body tear: where its material is stretched past `max_strain` it cracks
/// along its tets' faces and comes apart (`core/tearing.rs`), and a
/// [`SoftBodyTorn`](super::SoftBodyTorn) message says where. The body stays one entity however
/// many pieces it has (each keeps its volume); a game that wants an entity a piece splits it
/// itself. Without it a body never tears.
#[derive(Component, Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Component, Default, Debug, PartialEq)]
pub struct SoftBodyTearing {
    /// The strain `l / l0 - 1` of an edge past which the material cracks.
    pub max_strain: f32,
    /// The most faces cracked in one step.
    pub max_faces_per_step: u32,
    /// How long, s, a body that has just come apart waits before it starts another crack.
    pub min_interval: f32,
}

impl Default for SoftBodyTearing {
    /// The core's defaults (`TearSettings::default`).
    fn default() -> Self {
        let t = TearSettings::default();
        SoftBodyTearing {
            max_strain: t.max_strain,
            max_faces_per_step: t.max_faces_per_step,
            min_interval: t.min_interval,
        }
    }
}

impl SoftBodyTearing {
    /// The core's settings.
    pub(crate) fn settings(&self) -> TearSettings {
        TearSettings {
            max_strain: self.max_strain,
            max_faces_per_step: self.max_faces_per_step,
            min_interval: self.min_interval,
        }
    }
}

/// A body's settings components, as the plugin reads them.
pub(crate) type SettingsQuery = (
    Option<&'static SoftBodyContacts>,
    Has<SoftBodyContactsDisabled>,
    Option<&'static SoftBodySleepThreshold>,
    Has<SoftBodySleepingDisabled>,
    Option<&'static SoftBodyRunawayLimits>,
);

/// The core's settings the components (or their absence) ask for, for a body whose shortest
/// rest edge is `shortest_edge`.
pub(crate) fn core_settings(
    (contacts, no_contacts, sleep, no_sleep, runaway): <SettingsQuery as bevy::ecs::query::QueryData>::Item<'_, '_>,
    shortest_edge: f32,
) -> (
    Option<SoftContactSettings>,
    Option<SleepSettings>,
    RunawayLimits,
) {
    let contacts = (!no_contacts).then(|| {
        contacts
            .copied()
            .unwrap_or_default()
            .settings(shortest_edge)
    });
    let sleep = (!no_sleep).then(|| {
        let s = sleep.copied().unwrap_or_default();
        SleepSettings {
            speed: s.speed,
            time: s.time,
        }
    });
    let r = runaway.copied().unwrap_or_default();
    let runaway = RunawayLimits {
        max_speed: r.max_speed,
        max_stretch: r.max_stretch,
    };
    (contacts, sleep, runaway)
}
