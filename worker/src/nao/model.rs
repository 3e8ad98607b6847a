//! The league's NAO as plain data: bodies and hinge joints of
//! `docs/spec/nao-model.md` §2–§4, for types 0–4 and a variable morphology.
//!
//! **World frame (decided once for the whole project):** x forward (walking
//! direction), y left, z up, metres. The spec's torso frame (x right,
//! y forward, z up) is converted here and only here: x′ = y, y′ = −x, z′ = z
//! (a proper rotation, so hinge signs keep their meaning). Everything is given
//! at the zero pose, relative to the torso centre.

use protocol::params::{Param, ParamValues, Role, KNOWN};
use serde::Serialize;

/// A body's collision/inertia shape (sizes in metres, our frame).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub enum Shape {
    /// Box with these half extents.
    Box {
        /// Half extents (x, y, z), m.
        half: [f64; 3],
    },
    /// Sphere.
    Sphere {
        /// Radius, m.
        radius: f64,
    },
    /// Capsule along z: cylinder half length plus hemispherical caps.
    Capsule {
        /// Radius, m.
        radius: f64,
        /// Half length of the cylinder part, m.
        half_length: f64,
    },
}

/// One rigid body.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Body {
    /// Name (`torso`, `lthigh`, …).
    pub name: String,
    /// Index of the parent body (None for the torso).
    pub parent: Option<usize>,
    /// Shape (collision when `collider`, always the inertia shape).
    pub shape: Shape,
    /// Mass, kg.
    pub mass_kg: f64,
    /// Principal moments of inertia about the centre, kg·m² (our axes).
    pub inertia: [f64; 3],
    /// Centre at the zero pose, torso frame, m.
    pub centre: [f64; 3],
    /// Whether it has a collision shape (mass-only bodies do not).
    pub collider: bool,
}

/// One hinge joint.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Joint {
    /// Effector name (`lle3`, `rae1`, `he2`…).
    pub name: String,
    /// Parent body index.
    pub parent: usize,
    /// Child body index.
    pub child: usize,
    /// Anchor at the zero pose, torso frame, m.
    pub anchor: [f64; 3],
    /// Unit axis at the zero pose, torso frame (angle sign: right-hand rule).
    pub axis: [f64; 3],
    /// Limits (lower, upper), rad.
    pub limits_rad: (f64, f64),
    /// Max speed, rad/s.
    pub max_speed_rad_s: f64,
}

/// The heterogeneous-type quantities (`docs/spec/nao-model.md` §4), spec units.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Morphology {
    /// League type 0–4 this started from.
    pub robot_type: u8,
    /// Lateral hip offset, m (|x| in the spec frame).
    pub hip1_rel_torso_x: f64,
    /// Hip height below the torso centre, m (negative).
    pub hip1_rel_torso_z: f64,
    /// Thigh centre below hip2, m (negative); thigh length = 0.08 − value.
    pub thigh_rel_hip2_z: f64,
    /// Ankle below the shank centre, m (negative); tibia = 0.045 − value.
    pub ankle_rel_shank_z: f64,
    /// Elbow forward of the upper arm, m.
    pub elbow_rel_upper_arm_y: f64,
    /// Ankle pitch max speed, rad/s.
    pub lj5_max_speed: f64,
    /// Ankle roll max speed, rad/s.
    pub lj6_max_speed: f64,
    /// Whether the feet have toes (type 4).
    pub use_toe: bool,
}

/// Max speed of every joint unless a type overrides it, rad/s.
pub const MAX_SPEED: f64 = 6.1395;
/// Type 4's toe length, m.
pub const TOE_LENGTH: f64 = 0.035_517_656;

fn morphology_names() -> String {
    KNOWN
        .iter()
        .filter(|k| k.role == Role::Morphology)
        .map(|k| k.name)
        .collect::<Vec<_>>()
        .join(", ")
}

/// Why a model was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ModelError {
    /// Unknown robot type.
    #[error("robot type {0} does not exist (0..=4)")]
    Type(u8),
    /// A morphology quantity outside its range.
    #[error("{name} = {} is outside its admissible range [{lo}, {hi}] m", protocol::params::Shown(*.value))]
    Range {
        /// Parameter.
        name: String,
        /// Value given.
        value: f64,
        /// Lower bound.
        lo: f64,
        /// Upper bound.
        hi: f64,
    },
    /// A parameter that is not a morphology quantity.
    #[error("`{0}` is not a morphology parameter (those are: {known})", known = morphology_names())]
    Unknown(String),
    /// The structure is inconsistent (names, parents, ranges).
    #[error("invalid model: {0}")]
    Invalid(String),
}

impl Morphology {
    /// The league's type `t` (§4).
    pub fn of_type(t: u8) -> Result<Self, ModelError> {
        let base = Self {
            robot_type: t,
            hip1_rel_torso_x: 0.055,
            hip1_rel_torso_z: -0.115,
            thigh_rel_hip2_z: -0.04,
            ankle_rel_shank_z: -0.055,
            elbow_rel_upper_arm_y: 0.07,
            lj5_max_speed: MAX_SPEED,
            lj6_max_speed: MAX_SPEED,
            use_toe: false,
        };
        Ok(match t {
            0 => base,
            1 => Self {
                thigh_rel_hip2_z: -0.05832,
                ankle_rel_shank_z: -0.07332,
                elbow_rel_upper_arm_y: 0.10664,
                ..base
            },
            2 => Self {
                lj5_max_speed: 8.80667,
                lj6_max_speed: 3.47234,
                ..base
            },
            3 => Self {
                hip1_rel_torso_x: 0.072_954_143,
                thigh_rel_hip2_z: -0.067_868_424,
                ankle_rel_shank_z: -0.082_868_424,
                elbow_rel_upper_arm_y: 0.125_736_848,
                ..base
            },
            4 => Self {
                use_toe: true,
                ..base
            },
            t => return Err(ModelError::Type(t)),
        })
    }

    /// The field holding morphology parameter `p` (None for a walk parameter).
    fn field_mut(&mut self, p: Param) -> Option<&mut f64> {
        match p {
            Param::ThighRelHip2Z => Some(&mut self.thigh_rel_hip2_z),
            Param::Hip1RelTorsoX => Some(&mut self.hip1_rel_torso_x),
            Param::Hip1RelTorsoZ => Some(&mut self.hip1_rel_torso_z),
            Param::AnkleRelShankZ => Some(&mut self.ankle_rel_shank_z),
            Param::ElbowRelUpperArmY => Some(&mut self.elbow_rel_upper_arm_y),
            Param::RatioFlexion
            | Param::LongOffset
            | Param::HeightLift
            | Param::StepLength
            | Param::StepPeriod
            | Param::DoubleSupport
            | Param::ComAboveHip => None,
        }
    }

    /// The value of morphology parameter `p` in this body (None for a walk
    /// parameter).
    #[must_use]
    pub fn get(&self, p: Param) -> Option<f64> {
        let mut copy = *self;
        copy.field_mut(p).map(|f| *f)
    }

    /// Sets one morphology quantity (checked by [`Morphology::validate`]).
    pub fn set(&mut self, p: Param, value: f64) -> Result<(), ModelError> {
        let f = self
            .field_mut(p)
            .ok_or_else(|| ModelError::Unknown(p.name().to_string()))?;
        *f = value;
        self.validate()
    }

    /// Applies every morphology value given in a decoded set (walk values are not its concern).
    pub fn apply(&mut self, values: &ParamValues) -> Result<(), ModelError> {
        for k in KNOWN.iter().filter(|k| k.role == Role::Morphology) {
            if let (Some(v), Some(f)) = (values.given(k.param), self.field_mut(k.param)) {
                *f = v;
            }
        }
        self.validate()
    }

    /// Checks every quantity against the registry's admissible range.
    pub fn validate(&self) -> Result<(), ModelError> {
        let mut copy = *self;
        for k in KNOWN.iter().filter(|k| k.role == Role::Morphology) {
            let value = copy.field_mut(k.param).map_or(f64::NAN, |f| *f);
            if !value.is_finite() || value < k.min || value > k.max {
                return Err(ModelError::Range {
                    name: k.name.to_string(),
                    value,
                    lo: k.min,
                    hi: k.max,
                });
            }
        }
        Ok(())
    }

    /// Thigh length (hip → knee, vertical), m.
    #[must_use]
    pub fn thigh_m(&self) -> f64 {
        0.08 - self.thigh_rel_hip2_z
    }

    /// Tibia length (knee → ankle pitch axis), m.
    #[must_use]
    pub fn tibia_m(&self) -> f64 {
        0.045 - self.ankle_rel_shank_z
    }

    /// Hip centre → sole with straight legs, m.
    #[must_use]
    pub fn hip_to_sole_m(&self) -> f64 {
        self.thigh_m() + self.tibia_m() + 0.05
    }

    /// Torso centre → sole with straight legs, m.
    #[must_use]
    pub fn torso_to_sole_m(&self) -> f64 {
        -self.hip1_rel_torso_z + self.hip_to_sole_m()
    }

    /// Lateral distance between the hip centres, m.
    #[must_use]
    pub fn hip_width_m(&self) -> f64 {
        2.0 * self.hip1_rel_torso_x
    }

    /// This body as an entry of SimSpark's `naorobottypes.rb`, the `NaoType`
    /// array rcssserver3d reads its robot types from (the keys, order and units
    /// of release 0.6.8 on, `docs/spec/nao-model.md` §4), so that a body a run
    /// found can be tried on the league's own server. Each number is printed
    /// in the shortest form that reads back to the same `f64`.
    #[must_use]
    pub fn simspark_type(&self) -> String {
        let mut lines = vec![
            format!("    'Hip1RelTorso_X' => {}", self.hip1_rel_torso_x),
            format!("    'Hip1RelTorso_Z' => {}", self.hip1_rel_torso_z),
            format!("    'ThighRelHip2_Z' => {}", self.thigh_rel_hip2_z),
            format!("    'AnkleRelShank_Z' => {}", self.ankle_rel_shank_z),
            format!("    'lj5_max_abs_speed' => {}", self.lj5_max_speed),
            format!("    'lj6_max_abs_speed' => {}", self.lj6_max_speed),
            format!("    'ElbowRelUpperArm_Y' => {}", self.elbow_rel_upper_arm_y),
            format!("    'UseToe' => '{}'", self.use_toe),
        ];
        if self.use_toe {
            lines.push(format!("    'ToeLength' => {TOE_LENGTH}"));
        }
        format!("{{\n{}\n}}", lines.join(",\n"))
    }
}

/// The robot: bodies (torso first) and joints.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct NaoModel {
    /// The morphology it was built from.
    pub morphology: Morphology,
    /// Bodies; index 0 is the torso.
    pub bodies: Vec<Body>,
    /// Hinge joints.
    pub joints: Vec<Joint>,
}

/// Spec frame (x right, y forward, z up) → ours (x forward, y left, z up).
fn conv(v: [f64; 3]) -> [f64; 3] {
    [v[1], -v[0], v[2]]
}

fn add(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

fn boxed(size_spec: [f64; 3], mass: f64) -> (Shape, [f64; 3]) {
    let s = conv(size_spec).map(f64::abs);
    let i = [
        mass / 12.0 * (s[1] * s[1] + s[2] * s[2]),
        mass / 12.0 * (s[0] * s[0] + s[2] * s[2]),
        mass / 12.0 * (s[0] * s[0] + s[1] * s[1]),
    ];
    (
        Shape::Box {
            half: s.map(|x| x / 2.0),
        },
        i,
    )
}

fn sphere(r: f64, mass: f64) -> (Shape, [f64; 3]) {
    let i = 0.4 * mass * r * r;
    (Shape::Sphere { radius: r }, [i; 3])
}

/// ODE's capsule inertia (cylinder plus two hemispheres), along z.
fn capsule(r: f64, len: f64, mass: f64) -> (Shape, [f64; 3]) {
    let pi = std::f64::consts::PI;
    let vc = pi * r * r * len;
    let vs = 4.0 / 3.0 * pi * r * r * r;
    let mc = mass * vc / (vc + vs);
    let ms = mass - mc;
    let izz = mc * r * r / 2.0 + ms * 2.0 * r * r / 5.0;
    let ixx = mc * (r * r / 4.0 + len * len / 12.0)
        + ms * (2.0 * r * r / 5.0 + len * len / 4.0 + 3.0 * len * r / 8.0);
    (
        Shape::Capsule {
            radius: r,
            half_length: len / 2.0,
        },
        [ixx, ixx, izz],
    )
}

struct Builder {
    bodies: Vec<Body>,
    joints: Vec<Joint>,
}

impl Builder {
    /// Adds a body whose centre is given in the spec frame; returns its index.
    fn body(
        &mut self,
        name: &str,
        parent: Option<usize>,
        centre_spec: [f64; 3],
        si: (Shape, [f64; 3]),
        mass: f64,
        collider: bool,
    ) -> usize {
        self.bodies.push(Body {
            name: name.to_string(),
            parent,
            shape: si.0,
            mass_kg: mass,
            inertia: si.1,
            centre: conv(centre_spec),
            collider,
        });
        self.bodies.len() - 1
    }

    #[allow(clippy::too_many_arguments)]
    fn joint(
        &mut self,
        name: &str,
        parent: usize,
        child: usize,
        anchor_spec: [f64; 3],
        axis_spec: [f64; 3],
        deg: (f64, f64),
        speed: f64,
    ) {
        let n = axis_spec.iter().map(|a| a * a).sum::<f64>().sqrt();
        self.joints.push(Joint {
            name: name.to_string(),
            parent,
            child,
            anchor: conv(anchor_spec),
            axis: conv(axis_spec.map(|a| a / n)),
            limits_rad: (deg.0.to_radians(), deg.1.to_radians()),
            max_speed_rad_s: speed,
        });
    }
}

impl NaoModel {
    /// Builds the robot of a morphology (validated first).
    pub fn new(m: Morphology) -> Result<Self, ModelError> {
        m.validate()?;
        let mut b = Builder {
            bodies: Vec::new(),
            joints: Vec::new(),
        };
        let torso = b.body(
            "torso",
            None,
            [0.0; 3],
            boxed([0.10, 0.10, 0.18], 1.2171),
            1.2171,
            true,
        );
        let neck = b.body(
            "neck",
            Some(torso),
            [0.0, 0.0, 0.09],
            capsule(0.015, 0.08, 0.05),
            0.05,
            true,
        );
        let head = b.body(
            "head",
            Some(neck),
            [0.0, 0.0, 0.155],
            sphere(0.065, 0.35),
            0.35,
            true,
        );
        b.joint(
            "he1",
            torso,
            neck,
            [0.0, 0.0, 0.09],
            [0.0, 0.0, 1.0],
            (-120.0, 120.0),
            MAX_SPEED,
        );
        b.joint(
            "he2",
            neck,
            head,
            [0.0, 0.0, 0.15],
            [1.0, 0.0, 0.0],
            (-45.0, 45.0),
            MAX_SPEED,
        );
        // side: (letter, LR) with LR = +1 right, −1 left (spec x sign).
        for (s, lr) in [("l", -1.0), ("r", 1.0)] {
            let mirror = |lo: f64, hi: f64| if lr > 0.0 { (lo, hi) } else { (-hi, -lo) };
            // Arm.
            let sh_c = [lr * 0.098, 0.0, 0.075];
            let shoulder = b.body(
                &format!("{s}shoulder"),
                Some(torso),
                sh_c,
                sphere(0.01, 0.07),
                0.07,
                false,
            );
            let ua_c = add(sh_c, [lr * 0.01, 0.02, 0.0]);
            let upperarm = b.body(
                &format!("{s}upperarm"),
                Some(shoulder),
                ua_c,
                boxed([0.07, 0.08, 0.06], 0.15),
                0.15,
                true,
            );
            let el_c = add(ua_c, [-lr * 0.01, m.elbow_rel_upper_arm_y, 0.009]);
            let elbow = b.body(
                &format!("{s}elbow"),
                Some(upperarm),
                el_c,
                sphere(0.01, 0.035),
                0.035,
                false,
            );
            let la_c = add(el_c, [0.0, 0.05, 0.0]);
            let lowerarm = b.body(
                &format!("{s}lowerarm"),
                Some(elbow),
                la_c,
                boxed([0.05, 0.11, 0.05], 0.2),
                0.2,
                true,
            );
            b.joint(
                &format!("{s}ae1"),
                torso,
                shoulder,
                sh_c,
                [1.0, 0.0, 0.0],
                (-120.0, 120.0),
                MAX_SPEED,
            );
            b.joint(
                &format!("{s}ae2"),
                shoulder,
                upperarm,
                sh_c,
                [0.0, 0.0, 1.0],
                mirror(-95.0, 1.0),
                MAX_SPEED,
            );
            b.joint(
                &format!("{s}ae3"),
                upperarm,
                elbow,
                el_c,
                [0.0, 1.0, 0.0],
                (-120.0, 120.0),
                MAX_SPEED,
            );
            b.joint(
                &format!("{s}ae4"),
                elbow,
                lowerarm,
                el_c,
                [0.0, 0.0, 1.0],
                mirror(-1.0, 90.0),
                MAX_SPEED,
            );
            // Leg.
            let hip = [lr * m.hip1_rel_torso_x, -0.01, m.hip1_rel_torso_z];
            let hip1 = b.body(
                &format!("{s}hip1"),
                Some(torso),
                hip,
                sphere(0.01, 0.09),
                0.09,
                false,
            );
            let hip2 = b.body(
                &format!("{s}hip2"),
                Some(hip1),
                hip,
                sphere(0.01, 0.125),
                0.125,
                false,
            );
            let th_c = add(hip, [0.0, 0.01, m.thigh_rel_hip2_z]);
            let thigh = b.body(
                &format!("{s}thigh"),
                Some(hip2),
                th_c,
                boxed([0.07, 0.07, 0.14], 0.275),
                0.275,
                true,
            );
            let sk_c = add(th_c, [0.0, 0.005, -0.125]);
            let shank = b.body(
                &format!("{s}shank"),
                Some(thigh),
                sk_c,
                boxed([0.08, 0.07, 0.11], 0.225),
                0.225,
                true,
            );
            let an_c = add(sk_c, [0.0, -0.01, m.ankle_rel_shank_z]);
            let ankle = b.body(
                &format!("{s}ankle"),
                Some(shank),
                an_c,
                sphere(0.01, 0.125),
                0.125,
                false,
            );
            let knee = add(hip, [0.0, 0.005, m.thigh_rel_hip2_z - 0.08]);
            b.joint(
                &format!("{s}le1"),
                torso,
                hip1,
                hip,
                [-1.0, 0.0, lr], /* (−0.7071, 0, ±0.7071), normalised below */
                (-90.0, 1.0),
                MAX_SPEED,
            );
            b.joint(
                &format!("{s}le2"),
                hip1,
                hip2,
                hip,
                [0.0, 1.0, 0.0],
                mirror(-45.0, 25.0),
                MAX_SPEED,
            );
            b.joint(
                &format!("{s}le3"),
                hip2,
                thigh,
                hip,
                [1.0, 0.0, 0.0],
                (-25.0, 100.0),
                MAX_SPEED,
            );
            b.joint(
                &format!("{s}le4"),
                thigh,
                shank,
                knee,
                [1.0, 0.0, 0.0],
                (-130.0, 1.0),
                MAX_SPEED,
            );
            b.joint(
                &format!("{s}le5"),
                shank,
                ankle,
                an_c,
                [1.0, 0.0, 0.0],
                (-45.0, 75.0),
                m.lj5_max_speed,
            );
            let roll = add(an_c, [0.0, 0.0, -0.005]);
            if m.use_toe {
                let foot_len = 0.16 - TOE_LENGTH;
                let ft_c = add(an_c, [0.0, foot_len / 2.0 - 0.05, -0.04]);
                let foot_mass = 0.2 * (1.0 - TOE_LENGTH / 0.16 * 0.5);
                let foot = b.body(
                    &format!("{s}foot"),
                    Some(ankle),
                    ft_c,
                    boxed([0.08, foot_len, 0.02], foot_mass),
                    foot_mass,
                    true,
                );
                let toe_c = add(ft_c, [0.0, 0.08, -0.005]);
                let toe_mass = 0.2 - foot_mass;
                let toe = b.body(
                    &format!("{s}toe"),
                    Some(foot),
                    toe_c,
                    boxed([0.08, TOE_LENGTH, 0.01], toe_mass),
                    toe_mass,
                    true,
                );
                b.joint(
                    &format!("{s}le6"),
                    ankle,
                    foot,
                    roll,
                    [0.0, 1.0, 0.0],
                    mirror(-25.0, 45.0),
                    m.lj6_max_speed,
                );
                b.joint(
                    &format!("{s}le7"),
                    foot,
                    toe,
                    add(toe_c, [0.0, -TOE_LENGTH / 2.0, -0.005]),
                    [1.0, 0.0, 0.0],
                    (-1.0, 70.0),
                    MAX_SPEED,
                );
            } else {
                let ft_c = add(an_c, [0.0, 0.03, -0.04]);
                let foot = b.body(
                    &format!("{s}foot"),
                    Some(ankle),
                    ft_c,
                    boxed([0.08, 0.16, 0.02], 0.2),
                    0.2,
                    true,
                );
                b.joint(
                    &format!("{s}le6"),
                    ankle,
                    foot,
                    roll,
                    [0.0, 1.0, 0.0],
                    mirror(-25.0, 45.0),
                    m.lj6_max_speed,
                );
            }
        }
        let model = Self {
            morphology: m,
            bodies: b.bodies,
            joints: b.joints,
        };
        model.validate()?;
        Ok(model)
    }

    /// The league's type `t` with the morphology values of a decoded set.
    pub fn with_params(t: u8, values: &ParamValues) -> Result<Self, ModelError> {
        let mut m = Morphology::of_type(t)?;
        m.apply(values)?;
        Self::new(m)
    }

    /// Checks names, parents and ranges.
    pub fn validate(&self) -> Result<(), ModelError> {
        let bad = |s: String| Err(ModelError::Invalid(s));
        if self.bodies.first().map(|b| b.name.as_str()) != Some("torso") {
            return bad("body 0 must be the torso".into());
        }
        for (i, b) in self.bodies.iter().enumerate() {
            if self.bodies[..i].iter().any(|o| o.name == b.name) {
                return bad(format!("body name `{}` repeats", b.name));
            }
            if i > 0 && b.parent.is_none_or(|p| p >= i) {
                return bad(format!("body `{}` needs an earlier parent", b.name));
            }
            if !(b.mass_kg > 0.0 && b.inertia.iter().all(|x| *x > 0.0)) {
                return bad(format!("body `{}` needs positive mass and inertia", b.name));
            }
        }
        for j in &self.joints {
            if j.parent >= self.bodies.len()
                || j.child >= self.bodies.len()
                || self.bodies[j.child].parent != Some(j.parent)
            {
                return bad(format!(
                    "joint `{}` does not join a child to its parent",
                    j.name
                ));
            }
            if !(j.limits_rad.0 < j.limits_rad.1 && j.max_speed_rad_s > 0.0) {
                return bad(format!("joint `{}` has bad limits or speed", j.name));
            }
        }
        if self.joints.len() != self.bodies.len() - 1 {
            return bad("every body but the torso needs exactly one joint".into());
        }
        Ok(())
    }

    /// Total mass, kg.
    #[must_use]
    pub fn total_mass_kg(&self) -> f64 {
        self.bodies.iter().map(|b| b.mass_kg).sum()
    }

    /// Centre of mass at the zero pose, torso frame, m.
    #[must_use]
    pub fn centre_of_mass(&self) -> [f64; 3] {
        let m = self.total_mass_kg();
        let mut c = [0.0; 3];
        for b in &self.bodies {
            for (k, ck) in c.iter_mut().enumerate() {
                *ck += b.mass_kg * b.centre[k] / m;
            }
        }
        c
    }

    /// Index of a body by name.
    #[must_use]
    pub fn body_index(&self, name: &str) -> Option<usize> {
        self.bodies.iter().position(|b| b.name == name)
    }

    /// Index of a joint by effector name.
    #[must_use]
    pub fn joint_index(&self, name: &str) -> Option<usize> {
        self.joints.iter().position(|j| j.name == name)
    }

    /// Lowest point of the soles below the torso centre at the zero pose, m (positive).
    #[must_use]
    pub fn torso_height_standing(&self) -> f64 {
        self.bodies
            .iter()
            .filter(|b| b.collider)
            .map(|b| match b.shape {
                Shape::Box { half } => -(b.centre[2] - half[2]),
                Shape::Sphere { radius } => -(b.centre[2] - radius),
                Shape::Capsule {
                    radius,
                    half_length,
                } => -(b.centre[2] - radius - half_length),
            })
            .fold(f64::NEG_INFINITY, f64::max)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f64, b: f64, tol: f64) -> bool {
        (a - b).abs() < tol
    }

    #[test]
    fn type0_mass_and_heights() {
        let m = NaoModel::new(Morphology::of_type(0).unwrap()).unwrap();
        assert!(
            close(m.total_mass_kg(), 4.6071, 1e-9),
            "{}",
            m.total_mass_kg()
        );
        assert!(close(m.morphology.hip_to_sole_m(), 0.270, 1e-9));
        assert!(close(m.torso_height_standing(), 0.385, 1e-9));
        let c = m.centre_of_mass();
        // Spec: (0, +0.016, −0.079) in its frame = (+0.016, 0, −0.079) in ours.
        assert!(
            close(c[0], 0.016, 1e-3) && close(c[1], 0.0, 1e-9) && close(c[2], -0.079, 1e-3),
            "{c:?}"
        );
    }

    /// The entries of types 0–4 in rcssserver3d's `naorobottypes.rb` (release
    /// 0.6.8 on, `docs/spec/nao-model.md` §4), without its comments.
    const LEAGUE_TYPES: &str = "\
{
    'Hip1RelTorso_X' => 0.055,
    'Hip1RelTorso_Z' => -0.115,
    'ThighRelHip2_Z' => -0.04,
    'AnkleRelShank_Z' => -0.055,
    'lj5_max_abs_speed' => 6.1395,
    'lj6_max_abs_speed' => 6.1395,
    'ElbowRelUpperArm_Y' => 0.07,
    'UseToe' => 'false'
},
{
    'Hip1RelTorso_X' => 0.055,
    'Hip1RelTorso_Z' => -0.115,
    'ThighRelHip2_Z' => -0.05832,
    'AnkleRelShank_Z' => -0.07332,
    'lj5_max_abs_speed' => 6.1395,
    'lj6_max_abs_speed' => 6.1395,
    'ElbowRelUpperArm_Y' => 0.10664,
    'UseToe' => 'false'
},
{
    'Hip1RelTorso_X' => 0.055,
    'Hip1RelTorso_Z' => -0.115,
    'ThighRelHip2_Z' => -0.04,
    'AnkleRelShank_Z' => -0.055,
    'lj5_max_abs_speed' => 8.80667,
    'lj6_max_abs_speed' => 3.47234,
    'ElbowRelUpperArm_Y' => 0.07,
    'UseToe' => 'false'
},
{
    'Hip1RelTorso_X' => 0.072954143,
    'Hip1RelTorso_Z' => -0.115,
    'ThighRelHip2_Z' => -0.067868424,
    'AnkleRelShank_Z' => -0.082868424,
    'lj5_max_abs_speed' => 6.1395,
    'lj6_max_abs_speed' => 6.1395,
    'ElbowRelUpperArm_Y' => 0.125736848,
    'UseToe' => 'false'
},
{
    'Hip1RelTorso_X' => 0.055,
    'Hip1RelTorso_Z' => -0.115,
    'ThighRelHip2_Z' => -0.04,
    'AnkleRelShank_Z' => -0.055,
    'lj5_max_abs_speed' => 6.1395,
    'lj6_max_abs_speed' => 6.1395,
    'ElbowRelUpperArm_Y' => 0.07,
    'UseToe' => 'true',
    'ToeLength' => 0.035517656
}";

    #[test]
    fn simspark_types_read_as_the_league_file_writes_them() {
        let ours: Vec<String> = (0..=4)
            .map(|t| Morphology::of_type(t).unwrap().simspark_type())
            .collect();
        assert_eq!(ours.join(",\n"), LEAGUE_TYPES);
        // A found thigh reads back to the same bits.
        let mut mo = Morphology::of_type(0).unwrap();
        let thigh = -0.073_915_842_615_004_61;
        mo.set(Param::ThighRelHip2Z, thigh).unwrap();
        let text = mo.simspark_type();
        let read: f64 = text
            .lines()
            .find_map(|l| l.trim().strip_prefix("'ThighRelHip2_Z' => "))
            .and_then(|v| v.trim_end_matches(',').parse().ok())
            .unwrap();
        assert_eq!(read.to_bits(), thigh.to_bits(), "{text}");
    }

    #[test]
    fn hip_to_sole_follows_the_thigh() {
        let mut mo = Morphology::of_type(0).unwrap();
        mo.set(Param::ThighRelHip2Z, -0.079).unwrap();
        assert!(close(mo.hip_to_sole_m(), 0.309, 1e-9));
        for v in [-0.10, -0.01] {
            assert!(
                mo.set(Param::ThighRelHip2Z, v).is_ok(),
                "the paper's range is accepted"
            );
        }
        let e = mo.set(Param::ThighRelHip2Z, 0.02).unwrap_err().to_string();
        assert!(
            e.contains("ThighRelHip2_Z") && e.contains("[-0.12, -0.005]"),
            "{e}"
        );
    }

    #[test]
    fn five_types_derived_lengths() {
        let want = [
            (0.110, 0.120, 0.100, 0.270, 0.385),
            (0.110, 0.13832, 0.11832, 0.30664, 0.42164),
            (0.110, 0.120, 0.100, 0.270, 0.385),
            (0.145_908, 0.147_868, 0.127_868, 0.325_737, 0.440_737),
            (0.110, 0.120, 0.100, 0.270, 0.385),
        ];
        for (t, w) in want.iter().enumerate() {
            let m = NaoModel::new(Morphology::of_type(t as u8).unwrap()).unwrap();
            let mo = m.morphology;
            assert!(close(mo.hip_width_m(), w.0, 1e-6), "t{t}");
            assert!(close(mo.thigh_m(), w.1, 1e-6), "t{t}");
            assert!(close(mo.tibia_m(), w.2, 1e-6), "t{t}");
            assert!(close(mo.hip_to_sole_m(), w.3, 1e-6), "t{t}");
            assert!(close(mo.torso_to_sole_m(), w.4, 1e-6), "t{t}");
            assert!(close(m.total_mass_kg(), 4.6071, 1e-9), "t{t}");
            assert!(close(m.torso_height_standing(), w.4, 1e-6), "t{t}");
        }
        let t4 = NaoModel::new(Morphology::of_type(4).unwrap()).unwrap();
        assert_eq!(t4.joints.len(), 24, "type 4 has toes");
        let t0 = NaoModel::new(Morphology::of_type(0).unwrap()).unwrap();
        assert_eq!(t0.joints.len(), 22);
        // Type 2's ankles: their own speeds; every other type's are the default.
        for t in 0..5u8 {
            let m = NaoModel::new(Morphology::of_type(t).unwrap()).unwrap();
            for j in &m.joints {
                let want = match (t, &j.name[1..]) {
                    (2, "le5") => 8.80667,
                    (2, "le6") => 3.47234,
                    _ => MAX_SPEED,
                };
                assert_eq!(j.max_speed_rad_s, want, "type {t} {}", j.name);
            }
        }
        assert!(matches!(Morphology::of_type(5), Err(ModelError::Type(5))));
    }

    #[test]
    fn every_anchor_where_the_spec_puts_it() {
        let m = NaoModel::new(Morphology::of_type(0).unwrap()).unwrap();
        // Spec table 3, column (b), right side, spec frame.
        let spec: &[(&str, [f64; 3])] = &[
            ("he1", [0.0, 0.0, 0.09]),
            ("he2", [0.0, 0.0, 0.15]),
            ("rae1", [0.098, 0.0, 0.075]),
            ("rae2", [0.098, 0.0, 0.075]),
            ("rae3", [0.098, 0.09, 0.084]),
            ("rae4", [0.098, 0.09, 0.084]),
            ("rle1", [0.055, -0.01, -0.115]),
            ("rle2", [0.055, -0.01, -0.115]),
            ("rle3", [0.055, -0.01, -0.115]),
            ("rle4", [0.055, -0.005, -0.235]),
            ("rle5", [0.055, -0.005, -0.335]),
            ("rle6", [0.055, -0.005, -0.34]),
        ];
        for (name, a) in spec {
            for (side, lr) in [("r", 1.0), ("l", -1.0)] {
                let n = name.replacen('r', side, 1);
                let n = if name.starts_with('h') {
                    name.to_string()
                } else {
                    n
                };
                let j = &m.joints[m.joint_index(&n).unwrap()];
                let want = conv([lr * a[0], a[1], a[2]]);
                for k in 0..3 {
                    assert!(
                        close(j.anchor[k], want[k], 1e-9),
                        "{n}: {:?} vs {want:?}",
                        j.anchor
                    );
                }
            }
        }
        let t4 = NaoModel::new(Morphology::of_type(4).unwrap()).unwrap();
        let toe = &t4.joints[t4.joint_index("rle7").unwrap()];
        let want = conv([0.055, 0.069_482, -0.385]);
        for (a, w) in toe.anchor.iter().zip(want) {
            assert!(close(*a, w, 1e-6), "{:?}", toe.anchor);
        }
    }
}
