//! What a soft body is made of and which volume method keeps its volume.

/// How a body keeps its volume.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serialize", derive(serde::Serialize, serde::Deserialize))]
pub enum VolumeMethod {
    /// The existing method the paper compares against (its section 3, Teschner et al. 2004):
    /// a penalty force per tet from `E_V = 1/2 k_V ((V - V0) / V0)^2`.
    Baseline {
        /// `k_V`, the volume stiffness (the paper uses 1.4 in every scene).
        volume_stiffness: f32,
    },
    /// The paper's method (sections 4 and 5): velocity impulses sized by the smallest positive
    /// root of a cubic, in each vertex's one-ring and per tet.
    Impulses(ImpulseSettings),
    /// Extended position-based dynamics (Macklin et al. 2016, with the substeps of "Small Steps
    /// in Physics Simulation", 2019): the method most games use, as a peer to measure against.
    /// Springs become edge constraints of compliance `1 / k_D` (the same energy), each tet a
    /// volume constraint of zero compliance; one iteration per substep. With
    /// [`XpbdSettings::clusters`], the body's volume is then put back region by region at the
    /// end of each step ([`VolumeMethod::XPBD_CLUSTERS`]).
    Xpbd(XpbdSettings),
}

/// The settings of [`VolumeMethod::Xpbd`].
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serialize", derive(serde::Serialize, serde::Deserialize))]
pub struct XpbdSettings {
    /// Substeps per step (with [`XpbdSettings::clusters`], per 1/60 s of step), each with one
    /// pass over every constraint and its own contacts.
    pub substeps: u32,
    /// About how many regions (clusters of tets, cells of a grid over the rest shape) get their
    /// volume back exactly at the end of each step, all together (`core/clusters.rs`); 0 for
    /// none (plain XPBD). XPBD's sweeps hold each tet but leave the body's smooth loss, which a
    /// few large regions see: 8 puts it back (PERFORMANCE.md, "Cluster volume correction").
    /// With clusters, `substeps` counts per 1/60 s of step (20 a step at 30 Hz, 5 at 120 Hz),
    /// so that a game gets the same body at any rate; plain XPBD, the peer measured against,
    /// takes `substeps` a step whatever its length.
    pub clusters: u32,
}

impl XpbdSettings {
    /// 10 substeps and 8 clusters ([`VolumeMethod::XPBD_CLUSTERS`]).
    pub const CLUSTERS: XpbdSettings = XpbdSettings {
        substeps: 10,
        clusters: 8,
    };

    /// The substeps of a step of `h` seconds: `substeps`, or with clusters `substeps` per
    /// 1/60 s (see [`XpbdSettings::clusters`]).
    pub fn substeps_for(&self, h: f32) -> u32 {
        if self.clusters == 0 {
            return self.substeps.max(1);
        }
        // A hair of slack, so that 1/60 s is `substeps`, not one more.
        ((self.substeps as f32 * h * 60.0) * (1.0 - 1e-4))
            .ceil()
            .clamp(1.0, 10_000.0) as u32
    }
}

impl VolumeMethod {
    /// The baseline with the paper's `k_V = 1.4`.
    pub const PAPER_BASELINE: VolumeMethod = VolumeMethod::Baseline {
        volume_stiffness: 1.4,
    };
    /// The paper's method with every part switched on.
    pub const PAPER_IMPULSES: VolumeMethod = VolumeMethod::Impulses(ImpulseSettings::PAPER);
    /// XPBD with 10 substeps.
    pub const XPBD: VolumeMethod = VolumeMethod::Xpbd(XpbdSettings {
        substeps: 10,
        clusters: 0,
    });
    /// XPBD with 10 substeps and the volume of 8 clusters put back at the end of each step.
    pub const XPBD_CLUSTERS: VolumeMethod = VolumeMethod::Xpbd(XpbdSettings::CLUSTERS);

    /// A short name for tables and logs: `baseline`, `paper`, `xpbd` or `clusters` (XPBD with
    /// its cluster volume correction).
    pub fn name(&self) -> &'static str {
        match self {
            VolumeMethod::Baseline { .. } => "baseline",
            VolumeMethod::Impulses(_) => "paper",
            VolumeMethod::Xpbd(s) if s.clusters > 0 => "clusters",
            VolumeMethod::Xpbd(_) => "xpbd",
        }
    }

    /// Whether this is [`VolumeMethod::Xpbd`], which projects the tets' volumes in its shape
    /// solve instead of the impulses (`substep.rs`).
    pub fn is_xpbd(&self) -> bool {
        matches!(self, VolumeMethod::Xpbd(_))
    }
}

/// The presets' method: [`VolumeMethod::XPBD_CLUSTERS`] (README, "Two ways to keep the
/// volume").
impl Default for VolumeMethod {
    fn default() -> Self {
        Self::XPBD_CLUSTERS
    }
}

/// The switches of the paper's method.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serialize", derive(serde::Serialize, serde::Deserialize))]
pub struct ImpulseSettings {
    /// Restore the volume of each vertex's one-ring (section 5), once per step.
    pub one_ring: bool,
    /// Also correct every tet on its own, scaled by `gamma` (end of section 5), so that volume
    /// cannot drift from one tet of a ring into another.
    pub per_tet: bool,
    /// The fraction of the per-tet correction applied (the paper's `gamma = 1/8`). A tet whose
    /// predicted volume is inverted gets its whole correction instead: a fold to repair, not a
    /// deformation to leave to the rings.
    pub gamma: f32,
    /// Shorten an impulse so that no tet it touches falls below half its rest volume
    /// (section 4's clamp with `eps = V0 / 2`).
    pub neighbour_clamp: bool,
    /// Relative volume error `|V - V0| / V0` below which a tet needs no impulse; a ring is
    /// left alone when its own volume is within it and none of its tets is off by more than
    /// `ring_tet_tolerance`. The paper corrects every tet and ring every step, however small
    /// its error; once a body has settled most are within a hundredth of a percent, and their
    /// impulses would only cost time. Not a limit on the total error: a tet this close adds at
    /// most this fraction of its volume to it. The per-tet pass skips a tet when `gamma` times
    /// its error is within the tolerance (its impulse restores only that share).
    ///
    /// Default: 0.003 (0.3 %, a third of the 1 % the method is held to). Lower it where single
    /// tets must stay closer to their volume, at more cost per step; the figures behind the
    /// default are in PERFORMANCE.md ("The tolerances").
    pub tolerance: f32,
    /// Relative volume error of a single tet above which its ring is corrected even though the
    /// ring's volume is within `tolerance`. A ring impulse restores the ring's volume; how the
    /// error is spread among its tets is the per-tet pass's to even out, and a ring whose tets
    /// are off in opposite directions gets a root that the ring step limit cuts short (little
    /// motion at a ring impulse's full cost). Equal to `tolerance`, a ring is corrected whenever
    /// any of its tets is off by more than that. Slivers do not count (see
    /// [`TetMesh::is_sliver`](crate::core::TetMesh::is_sliver)): no ring impulse holds them,
    /// and retrying their rings every substep was much of an irregular mesh's cost at rest.
    ///
    /// Default: 0.01 (1 %, the error the method is held to; PERFORMANCE.md, "The tolerances").
    pub ring_tet_tolerance: f32,
}

impl ImpulseSettings {
    /// Everything on, `gamma = 1/8`, as in the paper.
    pub const PAPER: ImpulseSettings = ImpulseSettings {
        one_ring: true,
        per_tet: true,
        gamma: 0.125,
        neighbour_clamp: true,
        tolerance: 3e-3,
        ring_tet_tolerance: 1e-2,
    };
}

impl Default for ImpulseSettings {
    fn default() -> Self {
        Self::PAPER
    }
}

/// Plastic springs (paper section 6, last scene): a spring stretched or compressed past
/// `yield_strain` creeps towards its current length, up to `max_strain` from the original one.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serialize", derive(serde::Serialize, serde::Deserialize))]
pub struct Plasticity {
    /// Elastic strain `|e - e_p|` above which the spring starts to flow (`c_yield`).
    pub yield_strain: f32,
    /// Flow rate per second (`c_creep`): the fraction of the excess strain absorbed per second.
    pub creep: f32,
    /// Largest plastic strain `|e_p|` (`c_max`).
    pub max_strain: f32,
}

/// How stiff a body's edges are: what keeps its shape, while the [`VolumeMethod`] keeps its
/// volume.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serialize", derive(serde::Serialize, serde::Deserialize))]
pub enum Elasticity {
    /// The paper's springs: `E_D = 1/2 k_D ((L - D0) / D0)^2` on every edge, with a damper of
    /// `damping` (N s/m) along each, integrated explicitly (its scenes are reproduced with
    /// these). Stable only while `k_D` is weak for the particles' masses and the step: a game
    /// material at Earth gravity is not, so games use [`Elasticity::Elastic`].
    Springs {
        /// `k_D`, in joules (the energy of an edge at 100 % strain).
        distance_stiffness: f32,
        /// Damping along each spring, in force per unit of relative velocity (N s/m), applied
        /// implicitly so that any value is stable.
        damping: f32,
    },
    /// A physical material: stable at any stiffness and any step (see [`ElasticSettings`]).
    Elastic(ElasticSettings),
}

/// A material in physical units, the same whatever the mesh's resolution and the step.
///
/// Each tet carries Saint Venant-Kirchhoff's deviatoric energy of shear modulus
/// `mu = E / (2 (1 + nu))` and a hydrostatic energy `K/2 (det F - 1)^2` of bulk modulus
/// `K = E / (3 (1 - 2 nu))` (`E` the Young's modulus, `nu` the Poisson's ratio), solved as XPBD
/// constraints (Macklin et al. 2016) in substeps of at most `max_substep` seconds, each with
/// gravity, contacts and the paper's volume impulses (the "Small Steps" scheme, Macklin et al.
/// 2019; see `substep.rs` and `deviatoric.rs`). The shape solve holds the shape
/// and resists volume change as the material does; the impulses keep the volume within their
/// tolerance of the rest volume. Too stiff for the substep, a tet becomes as stiff as the
/// substep allows: it never explodes.
///
/// With [`Plasticity`], the shape is kept by springs on the edges instead (the plastic springs
/// are edges): each edge `e` gets `1/2 k_e ((L - D0) / D0)^2` with
/// `k_e = E * (sum of the volumes of the tets around e)`, the strain energy of an isotropic
/// solid of Young's modulus `E` and Poisson's ratio 1/4 (what a network of edges has), as XPBD
/// constraints of compliance `1 / k_e`. [`VolumeMethod::Xpbd`] uses the same edges.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serialize", derive(serde::Serialize, serde::Deserialize))]
pub struct ElasticSettings {
    /// Young's modulus `E`, in pascals. Jelly 10-50 kPa, flesh 50-300 kPa, soft rubber about
    /// 1 MPa, hard rubber 10 MPa and more.
    pub youngs_modulus: f32,
    /// Poisson's ratio `nu`, from 0 to 0.5: how much the shape solve itself resists a change
    /// of volume (at 0.5 it allows none, as a hard constraint). Jelly, flesh and rubber are
    /// 0.49 to 0.5; the default is 0.499. With one projection per substep the shape solve
    /// alone still loses a few percent on a landing, which the volume impulses take under
    /// their tolerance; the lower the value, the more of a landing's crush is left to them
    /// (PERFORMANCE.md).
    pub poisson_ratio: f32,
    /// Stiffness-proportional damping `beta`, in seconds: the damping is `beta` times the
    /// stiffness, so a mode of angular frequency `w` has the damping ratio `beta w / 2` (fast,
    /// small wobbles die first, a slow swing of the whole body is hardly touched;
    /// `SoftBodyMaterial::linear_damping` settles those). Solved with the shape constraints,
    /// in their projection, so that a damper too strong for the substep saturates as the
    /// stiffness does.
    pub damping: f32,
    /// The longest substep of the shape solve, in seconds: a step of `h` is cut into
    /// `ceil(h / max_substep)` substeps, so the body behaves the same at 30 and at 240 Hz.
    /// Shorter substeps make stiff bodies stiffer (closer to `youngs_modulus`) and cost
    /// more, in proportion. Default: 1/240 s (four substeps at 60 Hz).
    pub max_substep: f32,
    /// The farthest a particle may move in one substep, as a fraction of the mesh's shortest
    /// edge, relative to the body's mean motion, or in the world when it is about to meet a
    /// collider: a body deforming fast or landing gets more substeps, up to
    /// [`ElasticSettings::MAX_SUBSTEPS`], so that an impact is met a fraction of a cell at a
    /// time; a body falling or flying as a whole does not. Default: 0.03.
    ///
    /// `max_substep` and `max_motion` are the paper's method's; [`VolumeMethod::Xpbd`] takes
    /// the fixed number of substeps of its own settings.
    pub max_motion: f32,
}

impl ElasticSettings {
    /// The default substep, 1/240 s.
    pub const DEFAULT_MAX_SUBSTEP: f32 = 1.0 / 240.0;
    /// The most substeps a step of 1/60 s or less takes for the motion (see
    /// [`ElasticSettings::max_motion`]). A longer step may take as many more as keep its
    /// substeps as short as a 60 Hz step's can be (`MAX_SUBSTEPS` per 1/60 s), so that a game
    /// at 30 Hz meets a landing as finely as one at 60 Hz.
    pub const MAX_SUBSTEPS: u32 = 64;

    /// The default Poisson's ratio, 0.499.
    pub const DEFAULT_POISSON_RATIO: f32 = 0.499;

    /// A material of Young's modulus `youngs_modulus` (Pa) and stiffness-proportional
    /// damping `damping` (s), with the default Poisson's ratio and substep.
    pub const fn new(youngs_modulus: f32, damping: f32) -> Self {
        ElasticSettings {
            youngs_modulus,
            poisson_ratio: Self::DEFAULT_POISSON_RATIO,
            damping,
            max_substep: Self::DEFAULT_MAX_SUBSTEP,
            max_motion: 0.03,
        }
    }

    /// The compliances per unit volume of the tet shape model's constraints (see
    /// `deviatoric.rs`): `[1 / (2 mu), 1 / K]`, in 1/Pa. Divided by a tet's rest volume, each
    /// is that tet's constraint's compliance. Zero stiffness gives an infinite compliance
    /// (the constraint does nothing); `nu` = 0.5 a zero hydrostatic one (a hard constraint).
    pub fn tet_compliance(&self) -> [f32; 2] {
        let (e, nu) = (self.youngs_modulus, self.poisson_ratio);
        if e == 0.0 {
            return [f32::INFINITY; 2];
        }
        [(1.0 + nu) / e, 3.0 * (1.0 - 2.0 * nu) / e]
    }

    /// How many substeps a step of `h` seconds takes, for a body whose fastest particle moves
    /// at `speed` and whose shortest edge is `shortest_edge` long.
    pub fn substeps(&self, h: f32, speed: f32, shortest_edge: f32) -> u32 {
        // A hair of slack, so that 1/60 s in substeps of 1/240 s is four, not five.
        let for_step = ((h / self.max_substep) * (1.0 - 1e-4))
            .ceil()
            .clamp(1.0, 1000.0);
        let most = Self::MAX_SUBSTEPS as f32;
        let most = most.max((h * 60.0 * most * (1.0 - 1e-4)).ceil());
        let for_motion = (h * speed / (self.max_motion * shortest_edge)).ceil();
        let for_motion = if for_motion.is_finite() {
            for_motion.min(most)
        } else {
            most
        };
        for_step.max(for_motion) as u32
    }
}

/// Everything about a soft body's material.
///
/// Start from a preset ([`SoftBodyMaterial::JELLY`], [`FLESH`](SoftBodyMaterial::FLESH),
/// [`RUBBER`](SoftBodyMaterial::RUBBER), [`HARD_RUBBER`](SoftBodyMaterial::HARD_RUBBER)) or
/// [`SoftBodyMaterial::elastic`] with a Young's modulus; [`SoftBodyMaterial::paper`] gives the
/// paper's normalised springs. A material is checked when a body is made of it: a bad value
/// is a named [`MaterialError`], never a panic.
///
/// ```
/// use bevy_soft_body::core::{ElasticSettings, Elasticity, MaterialError, SoftBodyMaterial};
///
/// // A firm gel: 60 kPa, a little more damping than the jelly preset.
/// let gel = SoftBodyMaterial::elastic(1030.0, 60_000.0, 0.02);
/// assert!(gel.validate().is_ok());
/// // A heavier rubber, everything else as the preset.
/// let heavy_rubber = SoftBodyMaterial { density: 1500.0, ..SoftBodyMaterial::RUBBER };
/// assert!(heavy_rubber.validate().is_ok());
/// // A Poisson's ratio past 0.5 is not a material.
/// let bad = SoftBodyMaterial {
///     elasticity: Elasticity::Elastic(ElasticSettings {
///         poisson_ratio: 0.7,
///         ..ElasticSettings::new(20_000.0, 0.01)
///     }),
///     ..SoftBodyMaterial::JELLY
/// };
/// assert!(matches!(
///     bad.validate(),
///     Err(MaterialError::BadParameter { name: "poisson_ratio", .. })
/// ));
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serialize", derive(serde::Serialize, serde::Deserialize))]
pub struct SoftBodyMaterial {
    /// Mass per unit volume, kg/m^3; each tet gives a quarter of its mass to each vertex.
    pub density: f32,
    /// What keeps the shape.
    pub elasticity: Elasticity,
    /// Drag on every particle's velocity, per second (like a rigid body's linear damping in
    /// avian or rapier): each step keeps `1 / (1 + h c)` of it. Spring damping only acts on
    /// how fast springs change length, so it barely touches slow, large motions of a soft
    /// body (a long bar's torsion swings with a period of seconds); this settles them. It
    /// also slows a falling body, so keep it small (0 is a body in vacuum, and conserves
    /// momentum).
    pub linear_damping: f32,
    /// Deformation damping, per second (the mass-proportional half of Rayleigh damping, `alpha`):
    /// every step keeps `exp(-alpha h)` of each particle's velocity relative to the body's rigid
    /// motion. A mode of angular frequency `w` gets the damping ratio `alpha / (2 w)` on top of
    /// the shape solve's `beta w / 2` ([`ElasticSettings::damping`]): the slow wobbles of long,
    /// thin parts, which `beta` hardly touches, die, while the body's flight and spin, its
    /// momentum and angular momentum, are left alone (unlike `linear_damping`). Acts on a body
    /// stepped in substeps (a physical material, or XPBD). 0 keeps every wobble (and is what a
    /// saved material without it loads with).
    #[cfg_attr(feature = "serialize", serde(default))]
    pub deformation_damping: f32,
    /// Coulomb friction coefficient against colliders and spheres.
    pub friction: f32,
    /// Rolling resistance coefficient against static colliders (as a wheel's: the torque
    /// against rolling is this times the weight times the lever): what stops a body rocking on a
    /// curved underside or rolling on its side, which friction cannot (the contact does not
    /// slip) and a stiff body's internal damping does not (it rocks as a rigid body). Stands for
    /// the hysteresis of the contact patch, finer than the tets. Acts on a body stepped in
    /// substeps; 0 lets a ball roll for ever (and is what a saved material without it loads
    /// with).
    #[cfg_attr(feature = "serialize", serde(default))]
    pub rolling_resistance: f32,
    /// How volume is kept.
    pub method: VolumeMethod,
    /// Plastic springs, if any.
    pub plasticity: Option<Plasticity>,
}

impl SoftBodyMaterial {
    /// A physical material of `density` (kg/m^3) and Young's modulus `youngs_modulus` (Pa),
    /// with stiffness-proportional damping `damping` (s), deformation damping
    /// [`SoftBodyMaterial::DEFAULT_DEFORMATION_DAMPING`], friction 0.5, rolling resistance
    /// [`SoftBodyMaterial::DEFAULT_ROLLING_RESISTANCE`] and XPBD with its cluster volume
    /// correction ([`VolumeMethod::XPBD_CLUSTERS`], the default method: a step costs what its
    /// tets cost on any mesh; the paper's impulses, `with_method(VolumeMethod::PAPER_IMPULSES)`,
    /// keep each tet's volume better at many times the cost on meshes other tools made).
    pub const fn elastic(density: f32, youngs_modulus: f32, damping: f32) -> Self {
        SoftBodyMaterial {
            density,
            elasticity: Elasticity::Elastic(ElasticSettings::new(youngs_modulus, damping)),
            linear_damping: 0.0,
            deformation_damping: Self::DEFAULT_DEFORMATION_DAMPING,
            friction: 0.5,
            rolling_resistance: Self::DEFAULT_ROLLING_RESISTANCE,
            method: VolumeMethod::XPBD_CLUSTERS,
            plasticity: None,
        }
    }

    /// The paper's normalised springs of stiffness `k_D` (J) and damping `damping` (N s/m).
    pub const fn paper(density: f32, distance_stiffness: f32, damping: f32) -> Self {
        SoftBodyMaterial {
            density,
            elasticity: Elasticity::Springs {
                distance_stiffness,
                damping,
            },
            linear_damping: 0.0,
            deformation_damping: 0.0,
            friction: 0.5,
            rolling_resistance: 0.0,
            method: VolumeMethod::PAPER_IMPULSES,
            plasticity: None,
        }
    }

    /// The deformation damping of [`SoftBodyMaterial::elastic`], per second.
    pub const DEFAULT_DEFORMATION_DAMPING: f32 = 10.0;
    /// The rolling resistance of [`SoftBodyMaterial::elastic`].
    pub const DEFAULT_ROLLING_RESISTANCE: f32 = 0.1;

    /// A jelly: 1 050 kg/m^3, 20 kPa, wobbles after a landing: no deformation damping, so a
    /// long jelly's slow wobble goes on for seconds (give it some to settle it sooner).
    pub const JELLY: SoftBodyMaterial = SoftBodyMaterial {
        deformation_damping: 0.0,
        ..SoftBodyMaterial::elastic(1050.0, 2e4, 0.01)
    };
    /// Soft flesh: 1 050 kg/m^3, 150 kPa.
    pub const FLESH: SoftBodyMaterial = SoftBodyMaterial::elastic(1050.0, 1.5e5, 0.005);
    /// Soft rubber (a toy, a ball): 1 100 kg/m^3, 1 MPa.
    pub const RUBBER: SoftBodyMaterial = SoftBodyMaterial::elastic(1100.0, 1e6, 0.002);
    /// Hard rubber (a tyre, a bumper): 1 200 kg/m^3, 10 MPa: as stiff as the substeps allow.
    pub const HARD_RUBBER: SoftBodyMaterial = SoftBodyMaterial::elastic(1200.0, 1e7, 0.001);

    /// The presets by name (`jelly`, `flesh`, `rubber`, `hard_rubber`), for tables and tools.
    pub const PRESETS: [(&'static str, SoftBodyMaterial); 4] = [
        ("jelly", Self::JELLY),
        ("flesh", Self::FLESH),
        ("rubber", Self::RUBBER),
        ("hard_rubber", Self::HARD_RUBBER),
    ];

    /// Whether any spring has a damper.
    pub(crate) fn any_damping(&self) -> bool {
        match self.elasticity {
            Elasticity::Springs { damping, .. } => damping > 0.0,
            Elasticity::Elastic(e) => e.damping > 0.0,
        }
    }

    /// Whether a step is cut into substeps: XPBD's own, or a physical material's under the
    /// paper's impulses (`substep.rs`), with gravity and the shape solve in each. The paper's
    /// springs, and the baseline, are integrated explicitly: their forces act once a step and
    /// the step is one substep.
    pub fn is_substepped(&self) -> bool {
        matches!(
            (self.method, self.elasticity),
            (VolumeMethod::Xpbd(_), _) | (VolumeMethod::Impulses(_), Elasticity::Elastic(_))
        )
    }

    /// This material with volume method `method`.
    pub const fn with_method(mut self, method: VolumeMethod) -> Self {
        self.method = method;
        self
    }
}

impl Default for SoftBodyMaterial {
    /// [`SoftBodyMaterial::JELLY`].
    fn default() -> Self {
        Self::JELLY
    }
}

/// What is wrong with a material.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MaterialError {
    /// A parameter is negative, zero where it must be positive, or not finite.
    #[error("material parameter `{name}` must be {requirement}, got {value}")]
    BadParameter {
        /// The parameter.
        name: &'static str,
        /// What it must be.
        requirement: &'static str,
        /// What it was.
        value: f32,
    },
}

impl SoftBodyMaterial {
    /// Checks every parameter: positive density, non-negative finite stiffness, damping and
    /// friction, `gamma` in `[0, 1]`, sensible plasticity.
    pub fn validate(&self) -> Result<(), MaterialError> {
        fn positive(name: &'static str, value: f32) -> Result<(), MaterialError> {
            if value.is_finite() && value > 0.0 {
                Ok(())
            } else {
                Err(MaterialError::BadParameter {
                    name,
                    requirement: "positive and finite",
                    value,
                })
            }
        }
        fn non_negative(name: &'static str, value: f32) -> Result<(), MaterialError> {
            if value.is_finite() && value >= 0.0 {
                Ok(())
            } else {
                Err(MaterialError::BadParameter {
                    name,
                    requirement: "zero or positive and finite",
                    value,
                })
            }
        }
        positive("density", self.density)?;
        match self.elasticity {
            Elasticity::Springs {
                distance_stiffness,
                damping,
            } => {
                non_negative("distance_stiffness", distance_stiffness)?;
                non_negative("damping", damping)?;
            }
            Elasticity::Elastic(e) => {
                non_negative("youngs_modulus", e.youngs_modulus)?;
                if !(0.0..=0.5).contains(&e.poisson_ratio) {
                    return Err(MaterialError::BadParameter {
                        name: "poisson_ratio",
                        requirement: "between 0 and 0.5",
                        value: e.poisson_ratio,
                    });
                }
                non_negative("damping", e.damping)?;
                positive("max_substep", e.max_substep)?;
                positive("max_motion", e.max_motion)?;
            }
        }
        non_negative("linear_damping", self.linear_damping)?;
        non_negative("deformation_damping", self.deformation_damping)?;
        non_negative("friction", self.friction)?;
        non_negative("rolling_resistance", self.rolling_resistance)?;
        match self.method {
            VolumeMethod::Baseline { volume_stiffness } => {
                non_negative("volume_stiffness", volume_stiffness)?
            }
            VolumeMethod::Xpbd(s) => {
                if !(1..=1000).contains(&s.substeps) {
                    return Err(MaterialError::BadParameter {
                        name: "substeps",
                        requirement: "between 1 and 1000",
                        value: s.substeps as f32,
                    });
                }
            }
            VolumeMethod::Impulses(s) => {
                if !(s.tolerance.is_finite() && (0.0..0.1).contains(&s.tolerance)) {
                    return Err(MaterialError::BadParameter {
                        name: "tolerance",
                        requirement: "at least 0 and below 0.1",
                        value: s.tolerance,
                    });
                }
                if !(s.ring_tet_tolerance.is_finite() && (0.0..0.5).contains(&s.ring_tet_tolerance))
                {
                    return Err(MaterialError::BadParameter {
                        name: "ring_tet_tolerance",
                        requirement: "at least 0 and below 0.5",
                        value: s.ring_tet_tolerance,
                    });
                }
                if !(0.0..=1.0).contains(&s.gamma) {
                    return Err(MaterialError::BadParameter {
                        name: "gamma",
                        requirement: "between 0 and 1",
                        value: s.gamma,
                    });
                }
            }
        }
        if let Some(p) = self.plasticity {
            non_negative("yield_strain", p.yield_strain)?;
            non_negative("creep", p.creep)?;
            non_negative("max_strain", p.max_strain)?;
            if p.max_strain >= 1.0 {
                return Err(MaterialError::BadParameter {
                    name: "max_strain",
                    requirement: "below 1 (a spring cannot shrink to nothing)",
                    value: p.max_strain,
                });
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The elastic settings of a preset, changed by `change`.
    fn elastic(change: impl Fn(&mut ElasticSettings)) -> SoftBodyMaterial {
        let mut m = SoftBodyMaterial::RUBBER;
        if let Elasticity::Elastic(e) = &mut m.elasticity {
            change(e);
        }
        m
    }

    #[test]
    fn the_presets_are_valid_and_bad_elastic_parameters_are_named_errors() {
        for (name, preset) in SoftBodyMaterial::PRESETS {
            assert_eq!(preset.validate(), Ok(()), "{name}");
        }
        let bad: [(&str, SoftBodyMaterial); 7] = [
            ("poisson_ratio", elastic(|e| e.poisson_ratio = 0.6)),
            ("poisson_ratio", elastic(|e| e.poisson_ratio = -0.1)),
            ("poisson_ratio", elastic(|e| e.poisson_ratio = f32::NAN)),
            ("youngs_modulus", elastic(|e| e.youngs_modulus = -1.0)),
            (
                "youngs_modulus",
                elastic(|e| e.youngs_modulus = f32::INFINITY),
            ),
            ("damping", elastic(|e| e.damping = f32::NAN)),
            ("max_substep", elastic(|e| e.max_substep = 0.0)),
        ];
        for (expected, material) in bad {
            match material.validate() {
                Err(MaterialError::BadParameter { name, .. }) => assert_eq!(name, expected),
                other => panic!("{expected}: {other:?}"),
            }
        }
        // The ends of the Poisson's ratio's range are materials: 0.5 is a hard hydrostatic
        // constraint (zero compliance), 0 none.
        for nu in [0.0, 0.5] {
            let m = elastic(|e| e.poisson_ratio = nu);
            assert_eq!(m.validate(), Ok(()));
            if let Elasticity::Elastic(e) = m.elasticity {
                let [deviatoric, hydrostatic] = e.tet_compliance();
                assert!(deviatoric > 0.0 && deviatoric.is_finite());
                assert!(hydrostatic >= 0.0 && hydrostatic.is_finite());
                assert_eq!(hydrostatic == 0.0, nu == 0.5);
            }
            let limp = elastic(|e| (e.poisson_ratio, e.youngs_modulus) = (nu, 0.0));
            if let Elasticity::Elastic(e) = limp.elasticity {
                assert_eq!(e.tet_compliance(), [f32::INFINITY; 2]);
            }
        }
    }

    /// A landing asks for as many substeps as the cap allows: the same 64 at 60 Hz and above,
    /// twice as many at 30 Hz, so that no rate meets it with longer substeps than 60 Hz.
    #[test]
    fn the_substep_cap_keeps_substeps_as_short_as_at_60_hz() {
        let elastic = ElasticSettings::new(1e6, 0.0);
        let landing = |hz: f32| elastic.substeps(1.0 / hz, f32::INFINITY, 0.01);
        assert_eq!(landing(60.0), ElasticSettings::MAX_SUBSTEPS);
        assert_eq!(landing(120.0), ElasticSettings::MAX_SUBSTEPS);
        assert_eq!(landing(240.0), ElasticSettings::MAX_SUBSTEPS);
        assert_eq!(landing(30.0), 2 * ElasticSettings::MAX_SUBSTEPS);
    }
}
