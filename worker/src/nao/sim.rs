//! The NAO of [`NaoModel`] as a rapier3d rigid-body simulation with contacts,
//! driven like the league's server: a 20 ms agent cycle of joint velocity
//! commands in, perceptions out.
//!
//! It must stay a pure function of (model, settings, start, commands): no
//! clock, no global state, no randomness (noise belongs to the trial).
//!
//! The physics decisions (joint formulation, time step, motors, stops,
//! friction, contacts, sensors, fall) and their measurements are in
//! `docs/walk.md`, "The physics". [`SimSettings::default`] is the one
//! physics naofarm ships; its other fields exist to measure it.

use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use rapier3d::prelude::*;
use serde::Serialize;

use super::kinematics::{self, Iso};
use super::model::{NaoModel, Shape};

/// The agent cycle, s.
pub const CYCLE_S: f64 = 0.02;
/// Most torque a servo can apply, N·m.
pub const MAX_TORQUE_NM: f64 = 10.0;
/// Below this torso-centre height the robot has fallen, m.
pub const FALL_HEIGHT_M: f64 = 0.25;
/// Beyond this torso tilt the robot has fallen, rad (45°).
pub const FALL_TILT_RAD: f64 = std::f64::consts::FRAC_PI_4;
/// The league agents' position servo gain: 0.15 rad/s per degree, in rad/s per rad.
pub const SERVO_GAIN: f64 = 0.15 * 180.0 / std::f64::consts::PI;
/// Farther than this from the origin, a body has left any field: diverged, m.
pub const SANE_DISTANCE_M: f64 = 1000.0;
/// Faster than this, a body is no longer a falling robot: diverged, m/s.
pub const SANE_SPEED_M_S: f64 = 50.0;
/// Spinning faster than this, a body has diverged, rad/s.
pub const SANE_SPIN_RAD_S: f64 = 500.0;
/// A hinge that turns faster than this over one 20 ms cycle has diverged,
/// rad/s (3 rad a cycle). The servos are capped at 6.14 rad/s and the fastest
/// joint of any walk measured over a cycle, landings and falls included, was
/// 36 rad/s; an unstable solve of an arm turned a shoulder 4.5 rad in one
/// cycle (226 rad/s) while every body stayed below [`SANE_SPIN_RAD_S`].
pub const SANE_JOINT_SPEED_RAD_S: f64 = 150.0;
/// SimSpark's drag coefficient (force per velocity, torque per angular velocity).
/// rapier's multibody maps the torque on a link other than the torso
/// wrongly, and the walk leans on it: docs/walk.md, "Limits that remain".
pub const DRAG: f64 = 0.01;
const GRAVITY: f64 = 9.81;
/// With firm stops, limit rows are solved again after the contacts once a
/// joint is past this (negative: before the stop, so the speculative rows
/// are solved again too, and so is every servo row, which the vendored
/// rapier's filter reads as a limit row 0° past: vendor/rapier3d/NAOFARM.md).
const FIRM_STOP_RESOLVE_PAST_DEG: f64 = -0.5;
/// Type 4's toe hinges (`lle7`, `rle7`) rest at 0°, 1° from their stop at
/// −1°, so the walk meets that stop in every step, where other stops are
/// rarely met: without a stop that holds within a step, a toe dragged along
/// the ground ran up to 29° through it. So they have firm stops in every
/// world, with this window when the settings give the others none.
pub const TOE_STOP_WINDOW_DEG: f64 = 3.0;

/// Whether the model's joint `name` is a toe hinge (type 4).
fn is_toe(name: &str) -> bool {
    name.len() == 4 && name.ends_with("le7")
}

/// Physics settings of one simulation.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SimSettings {
    /// Physics steps per 20 ms cycle.
    pub substeps: u32,
    /// Solver iterations per physics step (each recomputes the multibody's mass matrix).
    pub solver_iterations: usize,
    /// Inner PGS iterations per solver iteration (cheap: no mass-matrix update).
    pub pgs_iterations: usize,
    /// Coulomb friction of feet and ground.
    pub friction: f64,
    /// Contact spring natural frequency, Hz (damping ratio 10; the
    /// experiment's `[physics] contact_hz`).
    pub contact_hz: f64,
    /// How near the ground a collider gets contact rows before it touches
    /// (rapier's speculative contacts), m.
    pub contact_prediction_m: f64,
    /// Weld head and arms to the torso at their start angles.
    pub weld_upper_body: bool,
    /// Weld the head even when the upper body is not welded (swinging arms:
    /// a multibody's cost grows faster than its degrees of freedom, and the
    /// walk holds the head still).
    pub weld_head: bool,
    /// With `weld_head`, weld the elbow yaws (`lae3`, `rae3`), which the
    /// walk holds at 0°, and so the elbow rolls (`lae4`, `rae4`) that hang
    /// from them: each forearm rigid with its upper arm.
    pub weld_elbow_yaws: bool,
    /// Motor damping (velocity constraint stiffness), N·m·s/rad.
    pub motor_damping: f64,
    /// Stops that hold within a step: a
    /// speculative limit row for every hinge within `firm_stop_window_deg` of
    /// a stop, and the limit rows solved again after the contacts (the vendored
    /// rapier3d's `speculative_joint_limits` and `joint_limits_after_contacts`).
    pub firm_stops: bool,
    /// With firm stops, a hinge this near a stop gets a speculative limit
    /// row, degrees.
    pub firm_stop_window_deg: f64,
    /// With firm stops, a hinge also gets its row when its speed would carry
    /// it into the window within this many physics steps (0: the window
    /// alone).
    pub firm_stop_lookahead: u32,
}

impl Default for SimSettings {
    /// The one physics naofarm ships (docs/walk.md, "The physics"): the
    /// experiment's default `[physics]` counts (defined once, in
    /// `protocol::Physics`), a 60 Hz ground, stops that hold within a step
    /// (within 8° of a stop or one step ahead of it), the arms free to
    /// swing at the shoulders and the elbows but for the elbow yaws, the
    /// head welded.
    fn default() -> Self {
        Self::with_physics(&protocol::Physics::default())
    }
}

impl SimSettings {
    /// Whether these settings weld the hinge named `name` at its start angle.
    #[must_use]
    pub fn welds(&self, name: &str) -> bool {
        is_upper_body_joint(name)
            && (self.weld_upper_body
                || self.weld_head
                    && (!is_arm_joint(name)
                        || self.weld_elbow_yaws
                            && (name.ends_with("ae3") || name.ends_with("ae4"))))
    }

    /// The shipped physics with an experiment's `[physics]` counts.
    #[must_use]
    pub fn with_physics(physics: &protocol::Physics) -> Self {
        Self {
            substeps: physics.substeps,
            solver_iterations: physics.solver_iterations as usize,
            pgs_iterations: physics.pgs_iterations as usize,
            friction: 1.0,
            contact_hz: 60.0,
            contact_prediction_m: 0.005,
            weld_upper_body: false,
            weld_head: true,
            weld_elbow_yaws: true,
            motor_damping: 1000.0,
            firm_stops: true,
            firm_stop_window_deg: 8.0,
            firm_stop_lookahead: 1,
        }
    }
}

/// Why a simulation could not be built or continued.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SimError {
    /// Wrong number of commands or angles.
    #[error("expected {expected} joint values, got {got}")]
    Arity {
        /// Joints of the model.
        expected: usize,
        /// Values given.
        got: usize,
    },
    /// A NaN or infinite command or start value.
    #[error("joint value for `{0}` is not finite")]
    NonFinite(String),
    /// A settings value that cannot work.
    #[error("bad simulation settings: {0}")]
    Settings(String),
    /// The physics went non-finite.
    #[error("the simulation diverged at t = {0:.2} s")]
    Diverged(f64),
}

/// How a simulation starts.
#[derive(Debug, Clone, PartialEq)]
pub struct Start {
    /// Joint angles, one per model joint, rad (clamped into the limits).
    pub angles: Vec<f64>,
    /// Torso pitch (about y, + leans forward), rad.
    pub pitch_rad: f64,
    /// Torso roll (about x, right-hand rule: + leans the top to the right), rad.
    pub roll_rad: f64,
}

impl Start {
    /// Upright with these joint angles.
    #[must_use]
    pub fn upright(angles: Vec<f64>) -> Self {
        Self {
            angles,
            pitch_rad: 0.0,
            roll_rad: 0.0,
        }
    }
}

/// What the agent perceives after a cycle, plus the ground truth for metrics.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Perception {
    /// Simulated time, s.
    pub time_s: f64,
    /// Hinge angles, one per model joint, rad.
    pub joint_angles_rad: Vec<f64>,
    /// Torso angular velocity in the torso frame, rad/s.
    pub gyro_rad_s: [f64; 3],
    /// Accelerometer in the torso frame, m/s² (+9.81 z at rest).
    pub accel_m_s2: [f64; 3],
    /// Contact force on the left and right foot (with toe), world frame, N.
    pub foot_force_n: [[f64; 3]; 2],
    /// Ground truth: torso centre, world frame, m.
    pub torso_position_m: [f64; 3],
    /// Ground truth: torso orientation quaternion (x, y, z, w).
    pub torso_rotation: [f64; 4],
    /// Ground truth: angle between the torso's z axis and the vertical, rad.
    pub torso_tilt_rad: f64,
}

/// The fall rule for every trial: torso centre below 0.25 m or tilt beyond 45°.
#[must_use]
pub fn fallen(p: &Perception) -> bool {
    p.torso_position_m[2] < FALL_HEIGHT_M || p.torso_tilt_rad > FALL_TILT_RAD
}

/// A motorised hinge: a multibody link.
#[derive(Debug, Clone, Copy)]
struct Hinge {
    handle: MultibodyJointHandle,
    link: usize,
    max_speed: f32,
    /// Within this of a stop the hinge gets a speculative limit row, rad
    /// (0: only once past it).
    stop_window: f32,
}

/// Where a model body lives in the world.
#[derive(Debug, Clone)]
enum Place {
    /// Its own rigid body.
    Own(RigidBodyHandle),
    /// Welded into its nearest ancestor with a body of its own (the host, a
    /// body index: the torso for the head and for arms welded whole) with
    /// this motion relative to the host's.
    Welded { host: usize, rel: Iso },
}

/// A running simulation of one robot.
pub struct Sim {
    world: PhysicsWorld,
    model: NaoModel,
    settings: SimSettings,
    places: Vec<Place>,
    hinges: Vec<Option<Hinge>>,
    welded_angles: Vec<f64>,
    torso: RigidBodyHandle,
    root_joint: MultibodyJointHandle,
    feet: [Vec<ColliderHandle>; 2],
    /// The feet's bodies in the model (left, right).
    foot_bodies: [usize; 2],
    ground: ColliderHandle,
    own_bodies: Vec<RigidBodyHandle>,
    cycle: u64,
    prev_linvel: Vector3<f64>,
    accel: Vector3<f64>,
    /// The hinge angles at the end of the last cycle, rad.
    prev_angles: Vec<f64>,
}

fn v3(a: [f64; 3]) -> Vec3 {
    Vec3::new(a[0] as f32, a[1] as f32, a[2] as f32)
}

fn to_pose(g: &Iso) -> Pose {
    let t = g.translation.vector;
    let q = g.rotation.quaternion();
    Pose::from_parts(
        Vec3::new(t.x as f32, t.y as f32, t.z as f32),
        Rotation::from_xyzw(q.i as f32, q.j as f32, q.k as f32, q.w as f32),
    )
}

fn from_pose(p: &Pose) -> Iso {
    let t = p.translation;
    let r = p.rotation;
    Iso::from_parts(
        nalgebra::Translation3::new(f64::from(t.x), f64::from(t.y), f64::from(t.z)),
        UnitQuaternion::new_normalize(Quaternion::new(
            f64::from(r.w),
            f64::from(r.x),
            f64::from(r.y),
            f64::from(r.z),
        )),
    )
}

fn shape_collider(shape: Shape) -> ColliderBuilder {
    match shape {
        Shape::Box { half } => {
            ColliderBuilder::cuboid(half[0] as f32, half[1] as f32, half[2] as f32)
        }
        Shape::Sphere { radius } => ColliderBuilder::ball(radius as f32),
        Shape::Capsule {
            radius,
            half_length,
        } => ColliderBuilder::capsule_z(half_length as f32, radius as f32),
    }
}

/// Pose, in its host body's frame, of a body welded with relative motion `rel`.
fn welded_offset(rel: &Iso, centre: [f64; 3], host_centre: [f64; 3]) -> Iso {
    let c = rel * nalgebra::Point3::from(centre);
    let t = nalgebra::Point3::from(host_centre);
    Iso::from_parts(nalgebra::Translation3::from(c - t), rel.rotation)
}

/// Whether a joint belongs to the head or the arms.
#[must_use]
pub fn is_upper_body_joint(name: &str) -> bool {
    name.starts_with("he") || is_arm_joint(name)
}

/// The left and right shoulder pitches: the joints a swinging arm swings.
pub const SHOULDER_PITCHES: [&str; 2] = ["lae1", "rae1"];

/// Whether a joint is one of the arms' (shoulders, elbows).
#[must_use]
pub fn is_arm_joint(name: &str) -> bool {
    name.starts_with("lae") || name.starts_with("rae")
}

impl Sim {
    /// Builds the world: ground, robot in the start posture with its soles just above
    /// the ground, torso over the origin.
    pub fn new(model: &NaoModel, settings: SimSettings, start: &Start) -> Result<Self, SimError> {
        let n = model.joints.len();
        if start.angles.len() != n {
            return Err(SimError::Arity {
                expected: n,
                got: start.angles.len(),
            });
        }
        for (j, a) in model.joints.iter().zip(&start.angles) {
            if !a.is_finite() {
                return Err(SimError::NonFinite(j.name.clone()));
            }
        }
        if settings.substeps == 0
            || settings.solver_iterations == 0
            || settings.pgs_iterations == 0
            || !(settings.friction.is_finite() && settings.friction >= 0.0)
            || !(settings.contact_hz.is_finite() && settings.contact_hz > 0.0)
            || !(settings.contact_prediction_m.is_finite() && settings.contact_prediction_m > 0.0)
            || !(settings.motor_damping.is_finite() && settings.motor_damping > 0.0)
            || !(start.pitch_rad.is_finite() && start.roll_rad.is_finite())
        {
            return Err(SimError::Settings(format!("{settings:?}")));
        }
        let angles: Vec<f64> = model
            .joints
            .iter()
            .zip(&start.angles)
            .map(|(j, a)| a.clamp(j.limits_rad.0, j.limits_rad.1))
            .collect();
        let tilt = UnitQuaternion::from_euler_angles(start.roll_rad, start.pitch_rad, 0.0);
        let mut root = Iso::from_parts(nalgebra::Translation3::identity(), tilt);
        let motions = kinematics::body_motions(model, &angles, &root);
        let low = kinematics::lowest_point(model, &motions);
        root.translation.vector.z = -low + 0.0005;
        let motions = kinematics::body_motions(model, &angles, &root);

        let mut world = PhysicsWorld::new();
        world.gravity = Vec3::new(0.0, 0.0, -GRAVITY as f32);
        world.integration_parameters.dt = (CYCLE_S / f64::from(settings.substeps)) as f32;
        world.integration_parameters.num_solver_iterations = settings.solver_iterations;
        world.integration_parameters.num_internal_pgs_iterations = settings.pgs_iterations;
        let contact = SpringCoefficients::new(settings.contact_hz as f32, 10.0);
        world.integration_parameters.contact_softness = contact;
        world.integration_parameters.normalized_prediction_distance =
            settings.contact_prediction_m as f32;
        world.integration_parameters.static_contact_softness = contact;
        let firm_toes = model.joints.iter().any(|j| is_toe(&j.name));
        let firm = settings.firm_stops || firm_toes;
        world.integration_parameters.speculative_joint_limits = firm;
        // No continuous collision detection: the ground is a metre thick and
        // no body comes near the speed that would cross it within a step.
        world.integration_parameters.max_ccd_substeps = 0;
        world.integration_parameters.joint_limits_after_contacts = if firm {
            FIRM_STOP_RESOLVE_PAST_DEG.to_radians() as f32
        } else {
            f32::MAX
        };

        let robot =
            InteractionGroups::new(Group::GROUP_1, Group::GROUP_2, InteractionTestMode::And);
        let ground_group =
            InteractionGroups::new(Group::GROUP_2, Group::GROUP_1, InteractionTestMode::And);
        let friction = settings.friction as f32;
        let gbody =
            world.insert_body(RigidBodyBuilder::fixed().translation(Vec3::new(0.0, 0.0, -0.5)));
        let ground = world.insert_collider(
            ColliderBuilder::cuboid(100.0, 100.0, 0.5)
                .friction(friction)
                .collision_groups(ground_group),
            Some(gbody),
        );

        // Each body's host: itself, or for a welded body its nearest
        // ancestor with a body of its own (parents come before children).
        let hosts: Vec<usize> = {
            let pj = kinematics::parent_joints(model);
            let mut hosts = Vec::with_capacity(model.bodies.len());
            for (i, j) in pj.iter().enumerate() {
                let host = match j {
                    Some(j) if settings.welds(&model.joints[*j].name) => {
                        hosts[model.joints[*j].parent]
                    }
                    _ => i,
                };
                hosts.push(host);
            }
            hosts
        };
        // Bodies, each host's mass gathered in body order (the torso's own
        // first, as before arms could be welded in part).
        let mut masses = vec![MassProperties::default(); model.bodies.len()];
        // Whether a body hosts others (the torso's mass is always set).
        let mut hosting = vec![false; model.bodies.len()];
        hosting[0] = true;
        let mut places = Vec::with_capacity(model.bodies.len());
        let mut own_bodies = Vec::new();
        for (i, b) in model.bodies.iter().enumerate() {
            let local = MassProperties::new(Vec3::ZERO, b.mass_kg as f32, v3(b.inertia));
            let host = hosts[i];
            if host != i {
                let rel = motions[host].inverse() * motions[i];
                let offset = welded_offset(&rel, b.centre, model.bodies[host].centre);
                masses[host] += local.transform_by(&to_pose(&offset));
                hosting[host] = true;
                places.push(Place::Welded { host, rel });
                continue;
            }
            masses[i] += local;
            let g = motions[i] * nalgebra::Translation3::from(Vector3::from(b.centre));
            let handle = world.insert_body(
                RigidBodyBuilder::dynamic()
                    .pose(to_pose(&g))
                    .can_sleep(false)
                    .additional_mass_properties(if i == 0 {
                        MassProperties::default()
                    } else {
                        local
                    }),
            );
            own_bodies.push(handle);
            places.push(Place::Own(handle));
        }
        let Place::Own(torso) = places[0] else {
            return Err(SimError::Settings("the torso cannot be welded".into()));
        };
        // A body that hosts none keeps the mass it was built with.
        for ((place, mass), hosts_some) in places.iter().zip(&masses).zip(&hosting) {
            if let (Place::Own(h), true) = (place, hosts_some) {
                world.bodies[*h].set_additional_mass_properties(*mass, false);
            }
        }
        // Colliders.
        let mut feet = [Vec::new(), Vec::new()];
        let mut foot_bodies = [None, None];
        for (i, b) in model.bodies.iter().enumerate() {
            if !b.collider {
                continue;
            }
            let (parent, offset) = match &places[i] {
                Place::Own(h) => (*h, Pose::IDENTITY),
                Place::Welded { host, rel } => {
                    let Place::Own(h) = places[*host] else {
                        return Err(SimError::Settings(format!(
                            "{} is welded to a body welded itself",
                            b.name
                        )));
                    };
                    (
                        h,
                        to_pose(&welded_offset(rel, b.centre, model.bodies[*host].centre)),
                    )
                }
            };
            let h = world.insert_collider(
                shape_collider(b.shape)
                    .position(offset)
                    .density(0.0)
                    .friction(friction)
                    .collision_groups(robot),
                Some(parent),
            );
            let side = if b.name.starts_with('l') { 0 } else { 1 };
            if b.name.ends_with("foot") || b.name.ends_with("toe") {
                feet[side].push(h);
            }
            if b.name.ends_with("foot") {
                foot_bodies[side] = Some(i);
            }
        }
        let (Some(left), Some(right), false) = (
            foot_bodies[0],
            foot_bodies[1],
            feet.iter().any(Vec::is_empty),
        ) else {
            return Err(SimError::Settings("a robot without both feet".into()));
        };
        let foot_bodies = [left, right];
        // Joints (bodies inserted at their posed places: anchors are given in each
        // body's own frame, which is the zero-pose frame carried along).
        let mut hinges = vec![None; n];
        let mut welded_angles = vec![0.0; n];
        for (j, joint) in model.joints.iter().enumerate() {
            welded_angles[j] = angles[j];
            let (p, c) = match (&places[joint.parent], &places[joint.child]) {
                (Place::Own(p), Place::Own(c)) => (p, c),
                (_, Place::Welded { .. }) => continue,
                // A hinge hanging from a welded body would leave its child
                // attached to nothing.
                (Place::Welded { .. }, Place::Own(_)) => {
                    return Err(SimError::Settings(format!(
                        "joint {} hangs from a welded body but is not welded itself",
                        joint.name
                    )))
                }
            };
            let pc = model.bodies[joint.parent].centre;
            let cc = model.bodies[joint.child].centre;
            let a = joint.anchor;
            let builder = RevoluteJointBuilder::new(v3(joint.axis))
                .local_anchor1(v3([a[0] - pc[0], a[1] - pc[1], a[2] - pc[2]]))
                .local_anchor2(v3([a[0] - cc[0], a[1] - cc[1], a[2] - cc[2]]))
                .limits([joint.limits_rad.0 as f32, joint.limits_rad.1 as f32])
                .motor_model(MotorModel::ForceBased)
                .motor_velocity(0.0, settings.motor_damping as f32)
                .motor_max_force(MAX_TORQUE_NM as f32)
                .contacts_enabled(false);
            let max_speed = joint.max_speed_rad_s as f32;
            let stop_window = match (settings.firm_stops, is_toe(&joint.name)) {
                (true, _) => settings.firm_stop_window_deg,
                (false, true) => TOE_STOP_WINDOW_DEG,
                (false, false) => 0.0,
            }
            .to_radians() as f32;
            let handle = world
                .multibody_joints
                .insert(*p, *c, builder, true)
                .ok_or_else(|| SimError::Settings(format!("joint {} closes a loop", joint.name)))?;
            hinges[j] = Some(Hinge {
                handle,
                link: 0,
                max_speed,
                stop_window,
            });
        }
        let Some(root_joint) = hinges.iter().flatten().next().map(|h: &Hinge| h.handle) else {
            return Err(SimError::Settings("a robot without hinges".into()));
        };
        let mut sim = Self {
            root_joint,
            world,
            model: model.clone(),
            settings,
            places,
            hinges,
            welded_angles,
            torso,
            feet,
            foot_bodies,
            ground,
            own_bodies,
            cycle: 0,
            prev_linvel: Vector3::zeros(),
            accel: Vector3::new(0.0, 0.0, GRAVITY),
            prev_angles: Vec::new(),
        };
        let torso_pose =
            motions[0] * nalgebra::Translation3::from(Vector3::from(model.bodies[0].centre));
        sim.pose_multibody(&angles, &torso_pose)?;
        sim.prev_angles = sim.joint_angles();
        Ok(sim)
    }

    /// Sets the multibody's generalised coordinates to the start pose and its
    /// damping to the settings.
    fn pose_multibody(&mut self, angles: &[f64], torso: &Iso) -> Result<(), SimError> {
        // Link ids are known only once every joint is in.
        for h in self.hinges.iter_mut().flatten() {
            let (_, link) = self
                .world
                .multibody_joints
                .get(h.handle)
                .ok_or_else(|| SimError::Settings("lost a joint".into()))?;
            h.link = link;
        }
        let (mb, _) = self
            .world
            .multibody_joints
            .get_mut(self.root_joint)
            .ok_or_else(|| SimError::Settings("lost a joint".into()))?;
        let ndofs = mb.ndofs();
        let mut disp = vec![0.0f32; ndofs];
        // The root's free joint starts at the identity and the hinges at zero:
        // displace both to the start pose.
        let t = torso.translation.vector;
        let r = torso.rotation.scaled_axis();
        for (k, x) in [t.x, t.y, t.z, r.x, r.y, r.z].into_iter().enumerate() {
            disp[k] = x as f32;
        }
        for (j, h) in self.hinges.iter().enumerate() {
            if let Some(h) = h {
                let Some(link) = mb.link(h.link) else {
                    return Err(SimError::Settings("lost a link".into()));
                };
                disp[link.assembly_id()] = angles[j] as f32;
            }
        }
        mb.apply_displacements(&disp);
        for d in mb.damping_mut().iter_mut() {
            *d = 0.0;
        }
        mb.forward_kinematics(&self.world.bodies, false);
        mb.update_rigid_bodies(&mut self.world.bodies, true);
        Ok(())
    }

    /// The model simulated.
    #[must_use]
    pub fn model(&self) -> &NaoModel {
        &self.model
    }

    /// The settings.
    #[must_use]
    pub fn settings(&self) -> &SimSettings {
        &self.settings
    }

    /// Simulated time, s.
    #[must_use]
    pub fn time_s(&self) -> f64 {
        self.cycle as f64 * CYCLE_S
    }

    /// Whether a joint is motorised (not welded).
    #[must_use]
    pub fn is_motorised(&self, joint: usize) -> bool {
        self.hinges.get(joint).is_some_and(Option::is_some)
    }

    /// Each model joint's speed cap in this world, rad/s; `None` for a
    /// welded joint. [`Sim::step`] clamps a command to it.
    #[must_use]
    pub fn speed_caps(&self) -> Vec<Option<f32>> {
        self.hinges.iter().map(|h| h.map(|h| h.max_speed)).collect()
    }

    /// Current hinge angles, one per model joint (welded ones at their weld), rad.
    #[must_use]
    pub fn joint_angles(&self) -> Vec<f64> {
        let mut out = self.welded_angles.clone();
        let Some((mb, _)) = self.world.multibody_joints.get(self.root_joint) else {
            return out;
        };
        for (j, h) in self.hinges.iter().enumerate() {
            if let Some(link) = h.and_then(|h| mb.link(h.link)) {
                out[j] = f64::from(link.joint().coords()[3]);
            }
        }
        out
    }

    /// Runs one 20 ms cycle with these joint velocity commands (rad/s, one per
    /// model joint; welded joints ignore theirs). Commands are clamped to the
    /// joint's max speed.
    pub fn step(&mut self, commands: &[f64]) -> Result<Perception, SimError> {
        if commands.len() != self.model.joints.len() {
            return Err(SimError::Arity {
                expected: self.model.joints.len(),
                got: commands.len(),
            });
        }
        for (j, c) in self.model.joints.iter().zip(commands) {
            if !c.is_finite() {
                return Err(SimError::NonFinite(j.name.clone()));
            }
        }
        let damping = self.settings.motor_damping as f32;
        let drag = DRAG as f32;
        for _ in 0..self.settings.substeps {
            self.set_motors_and_stops(commands, damping);
            for h in &self.own_bodies {
                let rb = &mut self.world.bodies[*h];
                let (lv, av) = (rb.linvel(), rb.angvel());
                rb.reset_forces(false);
                rb.add_force(-drag * lv, false);
                rb.add_torque(-drag * av, false);
            }
            self.world.step();
        }
        self.cycle += 1;
        if !self.sane() {
            return Err(SimError::Diverged(self.time_s()));
        }
        let rb = &self.world.bodies[self.torso];
        let lv = rb.linvel();
        let lv = Vector3::new(f64::from(lv.x), f64::from(lv.y), f64::from(lv.z));
        self.accel = (lv - self.prev_linvel) / CYCLE_S + Vector3::new(0.0, 0.0, GRAVITY);
        self.prev_linvel = lv;
        let p = self.perceive();
        if !self.hinges_sane(&p.joint_angles_rad) {
            return Err(SimError::Diverged(self.time_s()));
        }
        self.prev_angles.clone_from(&p.joint_angles_rad);
        Ok(p)
    }

    /// Whether the state is one a robot can be in: every body finite, within
    /// [`SANE_DISTANCE_M`] of the origin, slower than [`SANE_SPEED_M_S`] and
    /// [`SANE_SPIN_RAD_S`]. A multibody that lost stability (it happens in
    /// some violent falls) grows without bound in a few steps, finite at first:
    /// non-finite checks alone let a "fall" 10⁸ m away through. The hinges'
    /// angles are checked apart, once perceived ([`Sim::hinges_sane`]).
    fn sane(&self) -> bool {
        self.world.quarantine().is_empty()
            && self.own_bodies.iter().all(|h| {
                let rb = &self.world.bodies[*h];
                let (t, v, w) = (rb.translation(), rb.linvel(), rb.angvel());
                t.is_finite()
                    && v.is_finite()
                    && w.is_finite()
                    && f64::from(t.length()) < SANE_DISTANCE_M
                    && f64::from(v.length()) < SANE_SPEED_M_S
                    && f64::from(w.length()) < SANE_SPIN_RAD_S
            })
    }

    /// Whether every hinge turned at most [`SANE_JOINT_SPEED_RAD_S`] allows
    /// since the last cycle's `prev_angles`, to `angles`. A non-finite angle
    /// fails it too (the start pose is finite, and so then is every angle
    /// kept).
    fn hinges_sane(&self, angles: &[f64]) -> bool {
        let turn = SANE_JOINT_SPEED_RAD_S * CYCLE_S;
        angles
            .iter()
            .zip(&self.prev_angles)
            .all(|(a, b)| (a - b).abs() <= turn)
    }

    /// Sets each multibody hinge's motor for the next physics step, and its
    /// stop only where it may act: a hinge within its stop window of a stop
    /// (or, with the look-ahead, whose speed would carry it there) gets its
    /// limit row, speculative with firm stops. Any other hinge gets no row,
    /// which would cost a solve with the mass matrix per hinge and step, and
    /// its motor's target velocity is clamped so that the step ends on the
    /// stop at most, as rapier's own limit does.
    fn set_motors_and_stops(&mut self, commands: &[f64], damping: f32) {
        let inv_dt = self.world.integration_parameters.inv_dt();
        // Only firm stops look ahead (the toes' own window does not).
        let lookahead = if self.settings.firm_stops {
            self.settings.firm_stop_lookahead as f32
        } else {
            0.0
        };
        let Some((mb, _)) = self.world.multibody_joints.get_mut(self.root_joint) else {
            return;
        };
        for ((h, c), joint) in self.hinges.iter().zip(commands).zip(&self.model.joints) {
            let Some(h) = h else { continue };
            // How far the hinge's speed carries it in `firm_stop_lookahead` steps.
            let ahead = if lookahead > 0.0 {
                mb.link(h.link)
                    .map_or(0.0, |l| mb.joint_velocity(l)[0] * lookahead / inv_dt)
            } else {
                0.0
            };
            let Some(l) = mb.link_mut(h.link) else {
                continue;
            };
            let mut v = (*c as f32).clamp(-h.max_speed, h.max_speed);
            let q = l.joint.coords()[3];
            let (lo, hi) = (joint.limits_rad.0 as f32, joint.limits_rad.1 as f32);
            let data = &mut l.joint.data;
            let window = h.stop_window;
            let (reach_lo, reach_hi) = (q + ahead.min(0.0), q + ahead.max(0.0));
            if reach_lo < lo + window || hi - window < reach_hi {
                data.set_limits(JointAxis::AngX, [lo, hi]);
            } else {
                data.limit_axes.remove(JointAxesMask::ANG_X);
                v = v.clamp((lo - q) * inv_dt, (hi - q) * inv_dt);
            }
            data.set_motor_velocity(JointAxis::AngX, v, damping);
        }
    }

    /// The perception now (no noise).
    #[must_use]
    pub fn perceive(&self) -> Perception {
        let rb = &self.world.bodies[self.torso];
        let pose = from_pose(rb.position());
        let inv = pose.rotation.inverse();
        let av = rb.angvel();
        let gyro = inv * Vector3::new(f64::from(av.x), f64::from(av.y), f64::from(av.z));
        let accel = inv * self.accel;
        let up = pose.rotation * Vector3::z();
        let q = pose.rotation.quaternion();
        let t = pose.translation.vector;
        Perception {
            time_s: self.time_s(),
            joint_angles_rad: self.joint_angles(),
            gyro_rad_s: [gyro.x, gyro.y, gyro.z],
            accel_m_s2: [accel.x, accel.y, accel.z],
            foot_force_n: [self.foot_force(0), self.foot_force(1)],
            torso_position_m: [t.x, t.y, t.z],
            torso_rotation: [q.i, q.j, q.k, q.w],
            torso_tilt_rad: libm::acos(up.z.clamp(-1.0, 1.0)),
        }
    }

    /// The feet's bodies in the model (left, right).
    #[must_use]
    pub fn foot_bodies(&self) -> [usize; 2] {
        self.foot_bodies
    }

    /// Ground truth, for measurements: each foot's (left, right) centre in
    /// the world frame, m.
    #[must_use]
    pub fn feet_centres(&self) -> [[f64; 3]; 2] {
        std::array::from_fn(|side| {
            let t = self.world.colliders[self.feet[side][0]]
                .position()
                .translation;
            [f64::from(t.x), f64::from(t.y), f64::from(t.z)]
        })
    }

    /// Ground contact force on one foot (0 left, 1 right) over the last physics step, N.
    fn foot_force(&self, side: usize) -> [f64; 3] {
        let dt = f64::from(self.world.integration_parameters.dt);
        let mut f = Vector3::zeros();
        for c in &self.feet[side] {
            if let Some(pair) = self.world.narrow_phase.contact_pair(*c, self.ground) {
                let i = pair.total_impulse();
                let sign = if pair.collider1 == *c { -1.0 } else { 1.0 };
                f += sign * Vector3::new(f64::from(i.x), f64::from(i.y), f64::from(i.z)) / dt;
            }
        }
        [f.x, f.y, f.z]
    }

    /// Every body's motion from its zero pose (welded bodies follow the torso), for
    /// replays and checks.
    #[must_use]
    pub fn body_motions(&self) -> Vec<Iso> {
        let mut out: Vec<Iso> = Vec::with_capacity(self.places.len());
        for (i, p) in self.places.iter().enumerate() {
            let m = match p {
                Place::Own(h) => self.motion_of(*h, i),
                // Hosts come before the bodies welded to them.
                Place::Welded { host, rel } => out[*host] * rel,
            };
            out.push(m);
        }
        out
    }

    fn motion_of(&self, h: RigidBodyHandle, body: usize) -> Iso {
        let p = from_pose(self.world.bodies[h].position());
        p * nalgebra::Translation3::from(-Vector3::from(self.model.bodies[body].centre))
    }

    /// Every body's pose as (x, y, z, qx, qy, qz, qw) of its centre, for replays.
    #[must_use]
    pub fn body_poses(&self) -> Vec<[f64; 7]> {
        self.body_motions()
            .iter()
            .zip(&self.model.bodies)
            .map(|(g, b)| {
                let c = kinematics::moved(g, b.centre);
                let q = g.rotation.quaternion();
                [c[0], c[1], c[2], q.i, q.j, q.k, q.w]
            })
            .collect()
    }

    /// The exact bits of every body's position, rotation and velocities: equal
    /// vectors mean identical simulations.
    #[must_use]
    pub fn state_bits(&self) -> Vec<u32> {
        let mut out = Vec::with_capacity(self.own_bodies.len() * 13);
        for h in &self.own_bodies {
            let rb = &self.world.bodies[*h];
            let p = rb.position();
            let (lv, av) = (rb.linvel(), rb.angvel());
            for x in [
                p.translation.x,
                p.translation.y,
                p.translation.z,
                p.rotation.x,
                p.rotation.y,
                p.rotation.z,
                p.rotation.w,
                lv.x,
                lv.y,
                lv.z,
                av.x,
                av.y,
                av.z,
            ] {
                out.push(x.to_bits());
            }
        }
        out
    }

    /// One cycle of holding a posture: the league's P servo towards
    /// `targets` (rad) from the current angles, no feed-forward.
    pub fn hold(&mut self, targets: &[f64]) -> Result<Perception, SimError> {
        let zero = vec![0.0; targets.len()];
        let cmd = servo(&self.joint_angles(), targets, &zero);
        self.step(&cmd)
    }
}

/// Velocity commands of the league's P servo towards `targets` (rad), plus a
/// feed-forward velocity `ff` (rad/s) — what league agents send.
#[must_use]
pub fn servo(measured: &[f64], targets: &[f64], ff: &[f64]) -> Vec<f64> {
    measured
        .iter()
        .zip(targets)
        .zip(ff)
        .map(|((m, t), f)| f + SERVO_GAIN * (t - m))
        .collect()
}

/// A standing posture: arms down, knees slightly bent, feet flat.
#[must_use]
pub fn standing_angles(model: &NaoModel) -> Vec<f64> {
    let deg = std::f64::consts::PI / 180.0;
    model
        .joints
        .iter()
        .map(|j| match &j.name[1..] {
            "ae1" => -90.0 * deg,
            "ae2" if j.name.starts_with('l') => 8.0 * deg,
            "ae2" => -8.0 * deg,
            "le3" => 20.0 * deg,
            "le4" => -40.0 * deg,
            "le5" => 20.0 * deg,
            _ => 0.0,
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nao::model::Morphology;

    fn model(t: u8) -> NaoModel {
        NaoModel::new(Morphology::of_type(t).unwrap()).unwrap()
    }

    #[test]
    fn rapier_pose_matches_forward_kinematics() {
        for (weld, weld_head, weld_elbow_yaws) in [
            (false, false, false),
            (false, true, false),
            (false, true, true),
            (true, false, false),
        ] {
            let m = model(4);
            let q = standing_angles(&m);
            let settings = SimSettings {
                weld_upper_body: weld,
                weld_head,
                weld_elbow_yaws,
                ..SimSettings::default()
            };
            let mut sim = Sim::new(&m, settings, &Start::upright(q.clone())).unwrap();
            for (j, joint) in m.joints.iter().enumerate() {
                let elbow_yaw = joint.name.ends_with("ae3") || joint.name.ends_with("ae4");
                let welded = is_upper_body_joint(&joint.name)
                    && (weld
                        || weld_head
                            && (!is_arm_joint(&joint.name) || weld_elbow_yaws && elbow_yaw));
                assert_eq!(settings.welds(&joint.name), welded, "{}", joint.name);
                assert_eq!(sim.is_motorised(j), !welded, "{}", joint.name);
            }
            // Welding moves mass onto its host, never loses any.
            let robot: f64 = m.bodies.iter().map(|b| b.mass_kg).sum();
            let world = &mut sim.world;
            let simulated: f64 = sim
                .own_bodies
                .iter()
                .map(|h| {
                    let body = &mut world.bodies[*h];
                    body.recompute_mass_properties_from_colliders(&world.colliders);
                    f64::from(body.mass())
                })
                .sum();
            assert!((simulated - robot).abs() < 1e-4, "{simulated} {robot}");
            let ours = sim.body_motions();
            let angles = sim.joint_angles();
            for (a, b) in angles.iter().zip(&q) {
                assert!((a - b).abs() < 1e-6, "{a} {b}");
            }
            let root = ours[0];
            let fk = kinematics::body_motions(&m, &q, &root);
            for (i, (g, f)) in ours.iter().zip(&fk).enumerate() {
                let c = kinematics::moved(g, m.bodies[i].centre);
                let d = kinematics::moved(f, m.bodies[i].centre);
                for k in 0..3 {
                    assert!(
                        (c[k] - d[k]).abs() < 1e-5,
                        "{} {c:?} {d:?}",
                        m.bodies[i].name
                    );
                }
            }
        }
    }

    #[test]
    fn standing_holds_ten_seconds_within_a_centimetre() {
        for t in [0, 4] {
            let m = model(t);
            let q = standing_angles(&m);
            let mut sim = Sim::new(&m, SimSettings::default(), &Start::upright(q.clone())).unwrap();
            let z0 = sim.perceive().torso_position_m[2];
            for _ in 0..500 {
                let p = sim.hold(&q).unwrap();
                assert!(!fallen(&p));
                assert_within_a_degree_of_limits(&m, &p);
                assert!(
                    (p.torso_position_m[2] - z0).abs() < 0.01,
                    "type {t}: {:?}",
                    p.torso_position_m
                );
                // Weight on the feet (4.6 kg).
                let fz = p.foot_force_n[0][2] + p.foot_force_n[1][2];
                assert!(fz > 0.0);
            }
        }
    }

    #[test]
    fn a_robot_started_tilted_falls_and_is_detected() {
        let m = model(0);
        let q = standing_angles(&m);
        // Forward, backward and sideways.
        for (pitch, roll) in [(30.0, 0.0), (-30.0, 0.0), (0.0, 30.0)] {
            let start = Start {
                angles: q.clone(),
                pitch_rad: f64::to_radians(pitch),
                roll_rad: f64::to_radians(roll),
            };
            let mut sim = Sim::new(&m, SimSettings::default(), &start).unwrap();
            let mut fell_at = None;
            // On past the fall: the robot hits the ground and lies there, its
            // joints still within a degree of their stops.
            for _ in 0..250 {
                let p = sim.hold(&q).unwrap();
                assert_within_a_degree_of_limits(&m, &p);
                if fallen(&p) && fell_at.is_none() {
                    fell_at = Some(p.time_s);
                }
            }
            assert!(
                fell_at.is_some_and(|t| t < 5.0),
                "pitch {pitch}° roll {roll}°: {fell_at:?}"
            );
        }
    }

    fn assert_within_a_degree_of_limits(m: &NaoModel, p: &Perception) {
        let tol = 1f64.to_radians();
        for (j, a) in m.joints.iter().zip(&p.joint_angles_rad) {
            assert!(
                *a >= j.limits_rad.0 - tol && *a <= j.limits_rad.1 + tol,
                "t = {:.2} s: {} at {:.2}° outside [{:.2}°, {:.2}°]",
                p.time_s,
                j.name,
                a.to_degrees(),
                j.limits_rad.0.to_degrees(),
                j.limits_rad.1.to_degrees()
            );
        }
    }

    #[test]
    fn the_same_run_twice_gives_identical_bits() {
        let m = model(0);
        let q = standing_angles(&m);
        let run = || {
            let mut sim = Sim::new(&m, SimSettings::default(), &Start::upright(q.clone())).unwrap();
            for k in 0..150 {
                let p = sim.perceive();
                let t = f64::from(k) * CYCLE_S;
                let target: Vec<f64> = q.iter().map(|a| a + 0.2 * (5.0 * t).sin()).collect();
                let ff = vec![0.0; q.len()];
                let cmd = servo(&p.joint_angles_rad, &target, &ff);
                sim.step(&cmd).unwrap();
            }
            sim.state_bits()
        };
        let a = run();
        assert_eq!(a, run());
        assert!(!a.is_empty());
    }

    #[test]
    fn bad_commands_are_refused() {
        let m = model(0);
        let q = standing_angles(&m);
        let mut sim = Sim::new(&m, SimSettings::default(), &Start::upright(q.clone())).unwrap();
        assert!(matches!(sim.step(&[0.0; 3]), Err(SimError::Arity { .. })));
        let mut nan = vec![0.0; q.len()];
        nan[5] = f64::NAN;
        assert!(matches!(sim.step(&nan), Err(SimError::NonFinite(_))));
        let mut bad = Start::upright(q);
        bad.angles[0] = f64::INFINITY;
        assert!(Sim::new(&m, SimSettings::default(), &bad).is_err());
    }

    /// A state no robot can be in (here a knee spun at 10⁴ rad/s, as a lost
    /// multibody does before it goes non-finite) is reported as diverged,
    /// never returned as a pose far away.
    #[test]
    fn a_diverging_state_is_reported_not_returned() {
        let m = model(0);
        let q = standing_angles(&m);
        let mut sim = Sim::new(&m, SimSettings::default(), &Start::upright(q.clone())).unwrap();
        assert!(sim.hold(&q).is_ok());
        let knee = m.joints.iter().position(|j| j.name == "lle4").unwrap();
        let link = sim.hinges[knee].unwrap().link;
        let (mb, _) = sim.world.multibody_joints.get_mut(sim.root_joint).unwrap();
        let dof = mb.link(link).unwrap().assembly_id();
        mb.generalized_velocity_mut()[dof] = 1.0e4;
        assert!(matches!(sim.hold(&q), Err(SimError::Diverged(_))));
    }

    /// A hinge that turns more than [`SANE_JOINT_SPEED_RAD_S`] allows in one
    /// cycle is reported as diverged, even while every body moves slowly; a
    /// turn just within it is not. (The cycle's own turn while holding is
    /// far below 0.05 rad, so the last angles moved by 3 ± 0.05 rad give a
    /// turn on either side of the 3 rad bound.)
    #[test]
    fn a_hinge_that_turns_too_far_in_a_cycle_is_reported_as_diverged() {
        let m = model(0);
        let q = standing_angles(&m);
        let bound = SANE_JOINT_SPEED_RAD_S * CYCLE_S;
        let knee = m.joints.iter().position(|j| j.name == "lle4").unwrap();
        let mut sim = Sim::new(&m, SimSettings::default(), &Start::upright(q.clone())).unwrap();
        let mut within = Sim::new(&m, SimSettings::default(), &Start::upright(q.clone())).unwrap();
        for s in [&mut sim, &mut within] {
            assert!(s.hold(&q).is_ok());
        }
        sim.prev_angles[knee] += bound + 0.05;
        within.prev_angles[knee] += bound - 0.05;
        assert!(matches!(sim.hold(&q), Err(SimError::Diverged(_))));
        assert!(within.hold(&q).is_ok());
    }
}
