//! The walk's plan: a 3D linear-inverted-pendulum (LIP-3D) gait with
//! analytic leg inverse kinematics derived from the morphology it drives, at
//! the league's pace. `nao::balance` keeps it upright from the sensors.
//!
//! It must stay a pure planner: joint targets as a function of time and
//! parameters, no physics and no randomness (noise belongs to the trial).
//!
//! # The five parameters (experiment 2 of `docs/spec/evolve.md`)
//! - `ThighRelHip2_Z` changes the thigh, hence the robot *and* the IK.
//! - `ratio_flexion`: hip-centre height above the ankle-pitch axis over the
//!   stretched leg (thigh + tibia); it sets the CoM height of the pendulum.
//! - `long_offset_MidAnkles_2_Torso_Init`: the hip midpoint rides this far
//!   ahead of the pendulum's CoM/ZMP plan, m.
//! - `height_lift`: peak lift of the swing ankle, profile (1 − cos 2πs)/2, m.
//! - `xlength_step_max`: how far the swing foot lands ahead of the support
//!   foot, m; the first two steps are half as long.
//!
//! # The plan ([`GaitConfig::ENGINE`]; docs/walk.md says why each value)
//! - The ZMP sits on the support-foot centre; the CoM follows the bounded
//!   LIPM solution (the ZMP plan convolved with exp(−|t|/Tc)/(2Tc)), which
//!   starts from rest with no special case. Feet under the hips.
//! - The swing foot travels with a trapezoidal speed profile: peak 1.33× the
//!   mean instead of a cosine's 1.57×, so the hip and knee stay nearer the
//!   6.14 rad/s cap.
//! - A step is shortened until the thighs part, on average, no faster than
//!   the hip pitch's speed cap: a plan the legs cannot swing is walked short
//!   of itself.
//! - The shoulders swing against the opposite leg, carrying angular
//!   momentum about the vertical against the legs'.
//! - The servos get the target plus a velocity feed-forward (without it the
//!   P servo lags about 0.12 s and motions shrink).

use nalgebra::{Unit, UnitQuaternion, Vector3};

use super::model::NaoModel;
use protocol::params::{Param, ParamValues};

/// Ankle-roll anchor above the sole, m.
pub const ANKLE_H: f64 = 0.045;
/// Knee and ankle-pitch axis forward of the hip, m.
pub const KNEE_FORWARD: f64 = 0.005;
/// Ankle-pitch axis above the ankle-roll anchor, m.
pub const PITCH_ABOVE_ROLL: f64 = 0.005;
const G: f64 = 9.81;
const GRID_S: f64 = 0.005;

/// The plan's constants. The engine's are [`GaitConfig::ENGINE`]; an
/// experiment may tune the step period, the double support and the CoM
/// height ([`GaitConfig::with_params`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GaitConfig {
    /// Step period, s.
    pub period_s: f64,
    /// Double-support share of a step.
    pub double_support: f64,
    /// CoM above the hip centre, m.
    pub com_above_hip_m: f64,
    /// Stance hip-roll compensation during single support, rad.
    pub hip_roll_comp_rad: f64,
    /// Stepping starts at, s.
    pub start_s: f64,
    /// Arm swing: each shoulder pitch (`lae1`, `rae1`) turns this far from
    /// its rest angle per step length the opposite foot leads, rad (the
    /// right arm forward as the left foot is, as people walk).
    pub arm_swing_rad: f64,
    /// Cap on the planned step: shortened until the mean rate at which the
    /// thighs part in a swing, 2 × step ÷ (hip height × swing time), is at
    /// most this many times the hip pitch's speed cap ([`reachable_step`]).
    pub step_reach: f64,
}

/// Share of the swing over which the swing foot speeds up (and slows down):
/// constant acceleration over the first and last quarter, constant speed
/// between, peak 1/(1 − ramp) × the mean.
pub const TRAVEL_RAMP: f64 = 0.25;

/// The share of the way the swing foot has travelled at swing phase s (0..1).
#[must_use]
pub fn travel(s: f64) -> f64 {
    let r = TRAVEL_RAMP;
    let v = 1.0 / (1.0 - r);
    let s = s.clamp(0.0, 1.0);
    if s < r {
        v * s * s / (2.0 * r)
    } else if s > 1.0 - r {
        1.0 - v * (1.0 - s) * (1.0 - s) / (2.0 * r)
    } else {
        v * (s - r / 2.0)
    }
}

impl GaitConfig {
    /// The engine's plan (docs/walk.md, "The plan"): 0.16 s steps with no
    /// double support, the pendulum's CoM 0.025 m above the hips, 0.09 rad
    /// of stance hip roll, stepping from 0.5 s, the arms swinging 0.15 rad
    /// per step, steps capped at the hip pitch's speed cap.
    pub const ENGINE: Self = Self {
        period_s: 0.16,
        double_support: 0.0,
        com_above_hip_m: 0.025,
        hip_roll_comp_rad: 0.09,
        start_s: 0.5,
        arm_swing_rad: 0.15,
        step_reach: 1.0,
    };

    /// These constants with the parameter set's `step_period`,
    /// `double_support` and `com_above_hip`, where it gives them.
    #[must_use]
    pub fn with_params(self, params: &ParamValues) -> Self {
        Self {
            period_s: params.given(Param::StepPeriod).unwrap_or(self.period_s),
            double_support: params
                .given(Param::DoubleSupport)
                .unwrap_or(self.double_support),
            com_above_hip_m: params
                .given(Param::ComAboveHip)
                .unwrap_or(self.com_above_hip_m),
            ..self
        }
    }
}

pub use protocol::params::WalkParams;

/// The step the plan takes for an asked `step_length`: the asked one when
/// `cfg.step_reach` is 0, else at most
/// the step whose swing parts the thighs, on average, at `step_reach` × the
/// hip pitch's speed cap: in a swing of `period × (1 − double_support)`
/// the swing foot goes from half a step behind the hip to half a step
/// ahead, and the stance foot from half a step ahead to half behind, so
/// the angle between the thighs, about legs of the hip's height, opens by
/// 2 × step ÷ hip height.
#[must_use]
pub fn reachable_step(
    model: &NaoModel,
    step_length: f64,
    hip_height: f64,
    cfg: &GaitConfig,
) -> f64 {
    if cfg.step_reach <= 0.0 {
        return step_length;
    }
    let cap = model
        .joint_index("lle3")
        .map_or(super::model::MAX_SPEED, |i| model.joints[i].max_speed_rad_s);
    let swing_s = cfg.period_s * (1.0 - cfg.double_support);
    step_length.min(cfg.step_reach * cap * hip_height * swing_s / 2.0)
}

/// Leg geometry for the IK, from the morphology.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Leg {
    /// Hip → knee, vertical, m.
    pub thigh: f64,
    /// Knee → ankle pitch, m.
    pub tibia: f64,
    /// Hip centre (x, |y|, z) relative to the torso centre, m.
    pub hip: [f64; 3],
}

impl Leg {
    /// The legs of a model.
    #[must_use]
    pub fn of(model: &NaoModel) -> Self {
        let m = &model.morphology;
        Self {
            thigh: m.thigh_m(),
            tibia: m.tibia_m(),
            hip: [-0.01, m.hip1_rel_torso_x, m.hip1_rel_torso_z],
        }
    }
}

fn wrap(a: f64) -> f64 {
    let t = std::f64::consts::TAU;
    (a + std::f64::consts::PI).rem_euclid(t) - std::f64::consts::PI
}

/// Leg angles (yaw-pitch, roll, hip pitch, knee, ankle pitch, ankle roll) that
/// put the ankle-pitch point at `p` (relative to that side's hip centre, torso
/// axes) with the foot parallel to the torso; yaw-pitch stays 0.
#[must_use]
pub fn leg_ik_pitch_point(p: [f64; 3], leg: &Leg) -> [f64; 6] {
    let (px, py, pz) = (p[0], p[1], p[2]);
    let q2 = libm::atan2(py, -pz);
    let zr = -libm::sin(q2) * py + libm::cos(q2) * pz;
    let (l1, l2, d) = (leg.thigh, leg.tibia, KNEE_FORWARD);
    let a = libm::hypot(l1, d);
    let phi0 = libm::atan2(d, l1);
    let r2 = px * px + zr * zr;
    let c = ((r2 - d * d - l1 * l1 - l2 * l2) / (2.0 * l2 * a)).clamp(-1.0, 1.0);
    let beta4 = libm::acos(c) - phi0;
    let q4 = -beta4;
    let (vx, vz) = (d - l2 * libm::sin(beta4), -l1 - l2 * libm::cos(beta4));
    let q3 = wrap(libm::atan2(zr, px) - libm::atan2(vz, vx));
    [0.0, q2, q3, q4, -(q3 + q4), -q2]
}

/// Leg angles that put the ankle-roll anchor (45 mm above the sole) at `p`
/// relative to that side's hip centre, foot parallel to the torso.
#[must_use]
pub fn leg_ik(p: [f64; 3], leg: &Leg) -> [f64; 6] {
    // The roll anchor sits 5 mm below the pitch point along the ankle body's
    // z axis, which the roll angle tilts: a fixed point converges in a few steps.
    let mut q = [0.0; 6];
    for _ in 0..12 {
        let up = UnitQuaternion::from_axis_angle(&Unit::new_unchecked(Vector3::x()), q[1])
            * Vector3::new(0.0, 0.0, PITCH_ABOVE_ROLL);
        q = leg_ik_pitch_point([p[0] + up.x, p[1] + up.y, p[2] + up.z], leg);
    }
    q
}

/// Where the gait puts the hip midpoint and the two ankle-roll anchors, world frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GaitState {
    /// Hip midpoint, m.
    pub hip: [f64; 3],
    /// Left and right ankle-roll anchors, m.
    pub feet: [[f64; 3]; 2],
    /// Support side (0 left, 1 right) and single-support weight, when stepping.
    pub support: Option<(usize, f64)>,
}

/// A planned walk for one robot and parameter set.
#[derive(Debug, Clone)]
pub struct Gait {
    p: WalkParams,
    cfg: GaitConfig,
    leg: Leg,
    /// Hip centre above the ankle-roll anchor, m.
    hip_height: f64,
    foot_y: f64,
    steps: Vec<f64>,
    grid_start: f64,
    com: Vec<[f64; 2]>,
    /// For each model joint, the (side, le index 0..6) it takes from the IK.
    leg_slots: Vec<Option<(usize, usize)>>,
    /// Each joint's stops (model order): targets are clamped into them.
    limits: Vec<(f64, f64)>,
    /// The left and right shoulder pitch (`lae1`, `rae1`), if the model has them.
    shoulders: [Option<usize>; 2],
}

/// Which IK output drives each model joint: `lle1`..`lle6` → (0, 0..6),
/// `rle1`..`rle6` → (1, 0..6), anything else (arms, head, toes) none.
fn leg_slots(model: &NaoModel) -> Vec<Option<(usize, usize)>> {
    model
        .joints
        .iter()
        .map(|joint| {
            let side = match joint.name.as_bytes().first() {
                Some(b'l') => 0,
                Some(b'r') => 1,
                _ => return None,
            };
            let i: usize = joint.name.get(1..)?.strip_prefix("le")?.parse().ok()?;
            (1..=6).contains(&i).then_some((side, i - 1))
        })
        .collect()
}

impl Gait {
    /// Plans `duration_s` seconds of the engine's walk.
    #[must_use]
    pub fn new(model: &NaoModel, p: WalkParams, duration_s: f64) -> Self {
        Self::with_config(model, p, duration_s, GaitConfig::ENGINE)
    }

    /// Plans `duration_s` seconds of walking with the constants `cfg`.
    #[must_use]
    pub fn with_config(model: &NaoModel, p: WalkParams, duration_s: f64, cfg: GaitConfig) -> Self {
        let leg = Leg::of(model);
        let hip_height = p.ratio_flexion * (leg.thigh + leg.tibia) + PITCH_ABOVE_ROLL;
        let p = WalkParams {
            step_length: reachable_step(model, p.step_length, hip_height, &cfg),
            ..p
        };
        let zc = hip_height + ANKLE_H + cfg.com_above_hip_m;
        let tc = (zc / G).sqrt();
        let foot_y = leg.hip[1];
        let nsteps = ((duration_s + 10.0 * tc) / cfg.period_s) as usize + 4;
        let mut steps = vec![0.0; nsteps + 1];
        for k in 0..nsteps {
            let len = if k < 2 {
                p.step_length / 2.0
            } else {
                p.step_length
            };
            steps[k + 1] = steps[k] + len;
        }
        let mut g = Self {
            p,
            cfg,
            leg,
            hip_height,
            foot_y,
            steps,
            grid_start: 0.0,
            com: Vec::new(),
            leg_slots: leg_slots(model),
            limits: model.joints.iter().map(|j| j.limits_rad).collect(),
            shoulders: super::sim::SHOULDER_PITCHES.map(|name| model.joint_index(name)),
        };
        g.plan_com(duration_s, tc);
        g
    }

    /// The full step this plan takes, m (the asked one, or its reach).
    #[must_use]
    pub fn step_length(&self) -> f64 {
        self.p.step_length
    }

    /// The ZMP plan at time t: support-foot centre, handed over linearly during
    /// double support.
    fn zmp(&self, t: f64) -> [f64; 2] {
        if t < self.cfg.start_s {
            return [0.0, 0.0];
        }
        let x = (t - self.cfg.start_s) / self.cfg.period_s;
        let k = x.floor() as usize;
        let u = x - k as f64;
        let sgn = if k.is_multiple_of(2) { 1.0 } else { -1.0 };
        let step = |i: usize| self.steps[i.min(self.steps.len() - 1)];
        let cur = [step(k), sgn * self.foot_y];
        let prev = if k == 0 {
            [0.0, 0.0]
        } else {
            [step(k - 1), -sgn * self.foot_y]
        };
        let a = if self.cfg.double_support > 0.0 {
            (u / self.cfg.double_support).min(1.0)
        } else {
            1.0
        };
        [
            prev[0] + (cur[0] - prev[0]) * a,
            prev[1] + (cur[1] - prev[1]) * a,
        ]
    }

    /// The bounded LIPM solution: the ZMP plan convolved with exp(−|t|/Tc)/(2Tc).
    fn plan_com(&mut self, duration_s: f64, tc: f64) {
        let pad = 8.0 * tc;
        let n = (pad / GRID_S).round() as usize;
        let total = ((duration_s + 2.0 * pad) / GRID_S).ceil() as usize + 2;
        self.grid_start = -pad;
        let zmp: Vec<[f64; 2]> = (0..total + 2 * n)
            .map(|i| self.zmp(-pad + (i as f64 - n as f64) * GRID_S))
            .collect();
        let ker: Vec<f64> = (0..=2 * n)
            .map(|i| libm::exp(-((i as f64 - n as f64).abs() * GRID_S) / tc))
            .collect();
        let sum: f64 = ker.iter().sum();
        self.com = (0..total)
            .map(|i| {
                let mut c = [0.0, 0.0];
                for (j, k) in ker.iter().enumerate() {
                    let z = zmp[i + j];
                    c[0] += k * z[0];
                    c[1] += k * z[1];
                }
                [c[0] / sum, c[1] / sum]
            })
            .collect();
    }

    fn com_at(&self, t: f64) -> [f64; 2] {
        let x = (t - self.grid_start) / GRID_S;
        let i = (x.floor().max(0.0) as usize).min(self.com.len().saturating_sub(2));
        let f = (x - i as f64).clamp(0.0, 1.0);
        let (a, b) = (self.com[i], self.com[i + 1]);
        [a[0] + (b[0] - a[0]) * f, a[1] + (b[1] - a[1]) * f]
    }

    /// The swing foot's lift at swing phase s, a share of `height_lift`.
    fn lift_profile(s: f64) -> f64 {
        (1.0 - libm::cos(std::f64::consts::TAU * s)) / 2.0
    }

    /// The hip midpoint and feet at time t.
    #[must_use]
    pub fn state(&self, t: f64) -> GaitState {
        let w = self.foot_y;
        let mut feet = [[0.0, w, ANKLE_H], [0.0, -w, ANKLE_H]];
        let mut support = None;
        if t >= self.cfg.start_s {
            let x = (t - self.cfg.start_s) / self.cfg.period_s;
            let k = x.floor() as usize;
            let u = x - k as f64;
            let sup = k % 2; // 0 left, 1 right
            let sw = 1 - sup;
            let step = |i: usize| self.steps[i.min(self.steps.len() - 1)];
            let ds = self.cfg.double_support;
            let s = if u <= ds { 0.0 } else { (u - ds) / (1.0 - ds) };
            let sx = travel(s);
            let x0 = if k >= 1 { step(k - 1) } else { 0.0 };
            let x1 = step(k + 1);
            let lift = self.p.height_lift * Self::lift_profile(s);
            let side_y = |side: usize| if side == 0 { w } else { -w };
            feet[sup] = [step(k), side_y(sup), ANKLE_H];
            feet[sw] = [x0 + (x1 - x0) * sx, side_y(sw), ANKLE_H + lift];
            let wgt = if s > 0.0 {
                (5.0 * s).min(5.0 * (1.0 - s)).min(1.0)
            } else {
                0.0
            };
            support = Some((sup, wgt));
        }
        let c = self.com_at(t);
        GaitState {
            hip: [c[0] + self.p.long_offset, c[1], ANKLE_H + self.hip_height],
            feet,
            support,
        }
    }

    /// Leg joint targets at time t: `[left six, right six]` in the order
    /// le1..le6, with the stance hip-roll compensation.
    #[must_use]
    pub fn leg_targets(&self, t: f64) -> [[f64; 6]; 2] {
        self.legs_at(&self.state(t), [0.0; 2])
    }

    /// [`Gait::leg_targets`] for the gait's state `st` at some time, each
    /// foot's place about its hip turned by `pitch[side]` (rad) about the
    /// lateral axis: a torso pitched forward by `pitch` then puts that foot
    /// where the plan has it (0: the plan's own, exactly).
    fn legs_at(&self, st: &GaitState, pitch: [f64; 2]) -> [[f64; 6]; 2] {
        let mut out = [[0.0; 6]; 2];
        for (side, o) in out.iter_mut().enumerate() {
            let y = if side == 0 {
                self.leg.hip[1]
            } else {
                -self.leg.hip[1]
            };
            let f = st.feet[side];
            let (dx, dy) = (f[0] - st.hip[0], f[1] - st.hip[1]);
            let dz = f[2] - st.hip[2];
            let (dx, dz) = if pitch[side] == 0.0 {
                (dx, dz)
            } else {
                // The plan's (dx, dz) seen from a torso pitched forward
                // (about +y) by pitch: turned back by it.
                let (s, c) = libm::sincos(pitch[side]);
                (c * dx - s * dz, s * dx + c * dz)
            };
            *o = leg_ik([dx, dy - y, dz], &self.leg);
        }
        if let Some((sup, wgt)) = st.support {
            let sgn = if sup == 0 { 1.0 } else { -1.0 };
            out[sup][1] += sgn * self.cfg.hip_roll_comp_rad * wgt;
        }
        out
    }

    /// Targets for every model joint at time t (arms and head at their rest
    /// posture `rest`, one angle per joint of the model the gait was planned for).
    #[must_use]
    ///
    /// A target beyond a joint's stop is clamped to the stop, as a league
    /// agent clamps its servo targets: commanding a hinge into its stop only
    /// loads the limit constraint, which then yields a few degrees.
    pub fn targets(&self, rest: &[f64], t: f64) -> Vec<f64> {
        self.targets_of(rest, &self.state(t), [0.0; 2])
    }

    /// [`Gait::targets`] for a state `st` of this gait (the plan's own at
    /// some time, or one [`Paced`] from it), each foot placed against a
    /// torso pitched by `pitch[side]` (rad; 0: the plan's own, exactly).
    #[must_use]
    pub fn targets_of(&self, rest: &[f64], st: &GaitState, pitch: [f64; 2]) -> Vec<f64> {
        let legs = self.legs_at(st, pitch);
        let mut q = rest.to_vec();
        // How far the left foot leads the right, in step lengths.
        let feet = st.feet;
        let lead = ((feet[0][0] - feet[1][0]) / self.p.step_length.max(1e-3)).clamp(-1.5, 1.5);
        for (side, joint) in self.shoulders.iter().enumerate() {
            let sign = if side == 0 { -1.0 } else { 1.0 };
            if let Some(qj) = joint.and_then(|j| q.get_mut(j)) {
                *qj += sign * self.cfg.arm_swing_rad * lead;
            }
        }
        for ((qj, slot), (lo, hi)) in q.iter_mut().zip(&self.leg_slots).zip(&self.limits) {
            if let Some((side, i)) = slot {
                *qj = legs[*side][*i];
            }
            *qj = qj.clamp(*lo, *hi);
        }
        q
    }

    /// The step the plan is in at time t (0 the first), none before stepping
    /// starts. In step k the support foot is side `k % 2` (0 left) and the
    /// other foot swings; it lands at the step's end.
    #[must_use]
    pub fn step_at(&self, t: f64) -> Option<usize> {
        (t >= self.cfg.start_s)
            .then(|| ((t - self.cfg.start_s) / self.cfg.period_s).floor() as usize)
    }

    /// Where the plan puts the k-th foothold forward, m: the support foot of
    /// step k stands on foothold k, its swing foot lands on foothold k + 1.
    #[must_use]
    pub fn foothold(&self, k: usize) -> f64 {
        self.steps[k.min(self.steps.len() - 1)]
    }
}

/// A gait's plan walked at a pace of its own: each step the plan takes is
/// taken `pace` times as long, the hip's advance over its support foot with
/// it, so at a constant pace the walk is the plan with every step `pace`
/// times as long. A pace that changes moves a target by at most the change
/// times a step (the swing foot by its share of the way, the hip by its
/// lead), and the feet stay one paced step apart: no foot keeps a lead an
/// earlier pace left.
/// Sideways and vertical motion stay the plan's. The balance's step gauge
/// uses it to aim the steps short by what the legs overreach
/// (`nao::balance`).
#[derive(Debug, Clone)]
pub struct Paced {
    /// The step the footholds are held for.
    step: usize,
    /// Where the step's swing foot lifted off and its support foot stands, m.
    held: [f64; 2],
    /// The pace of the last call.
    pace: f64,
}

impl Default for Paced {
    fn default() -> Self {
        Self::new()
    }
}

impl Paced {
    /// The plan before its first step, at pace 1.
    #[must_use]
    pub fn new() -> Self {
        Self {
            step: 0,
            held: [0.0, 0.0],
            pace: 1.0,
        }
    }

    /// The gait's state at time `t` (not before the last call's) walked at
    /// `pace`.
    pub fn state(&mut self, gait: &Gait, t: f64, pace: f64) -> GaitState {
        let mut st = gait.state(t);
        let Some(k) = gait.step_at(t) else {
            return st;
        };
        // Each finished step's foot landed where its last pace aimed it.
        while self.step < k {
            let j = self.step;
            let landed = self.held[1] + self.pace * (gait.foothold(j + 1) - gait.foothold(j));
            self.held = [self.held[1], landed];
            self.step = j + 1;
        }
        self.pace = pace;
        let (sup, sw) = (k % 2, 1 - k % 2);
        let (from, to) = (gait.foothold(k.saturating_sub(1)), gait.foothold(k + 1));
        let (lifted, stands) = (self.held[0], self.held[1]);
        let lands = stands + pace * (to - gait.foothold(k));
        let share = if to > from {
            (st.feet[sw][0] - from) / (to - from)
        } else {
            0.0
        };
        st.feet[sup][0] = stands;
        st.feet[sw][0] = lifted + (lands - lifted) * share;
        let offset = gait.p.long_offset;
        st.hip[0] = stands + offset + pace * (st.hip[0] - offset - gait.foothold(k));
        st
    }
}

impl Gait {
    /// Targets `q` (from [`Gait::targets`]) with `legs` added to each leg's
    /// six angles (le1..le6, left then right), clamped to the stops again.
    #[must_use]
    pub fn corrected(&self, q: &[f64], legs: &[[f64; 6]; 2]) -> Vec<f64> {
        q.iter()
            .zip(&self.leg_slots)
            .zip(&self.limits)
            .map(|((qj, slot), (lo, hi))| match slot {
                Some((side, i)) => (qj + legs[*side][*i]).clamp(*lo, *hi),
                None => *qj,
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nao::kinematics::{body_motions, moved, Iso};
    use crate::nao::model::Morphology;
    use rand::{Rng, SeedableRng};

    /// Forward kinematics of leg angles `q` (le1..le6) on `side` (0 left):
    /// the ankle-roll anchor relative to that side's hip centre and the
    /// foot's rotation, or None when an angle is past its joint's stops.
    fn foot_of(
        model: &NaoModel,
        leg: &Leg,
        side: usize,
        q: &[f64; 6],
    ) -> Option<([f64; 3], UnitQuaternion<f64>)> {
        let pre = if side == 0 { "lle" } else { "rle" };
        let mut angles = vec![0.0; model.joints.len()];
        for (i, qi) in q.iter().enumerate() {
            let j = model.joint_index(&format!("{pre}{}", i + 1)).unwrap();
            let (lo, hi) = model.joints[j].limits_rad;
            if !(lo..=hi).contains(qi) {
                return None;
            }
            angles[j] = *qi;
        }
        let g = body_motions(model, &angles, &Iso::identity());
        let six = &model.joints[model.joint_index(&format!("{pre}6")).unwrap()];
        let at = moved(&g[six.child], six.anchor);
        let y = if side == 0 { leg.hip[1] } else { -leg.hip[1] };
        Some((
            [at[0] - leg.hip[0], at[1] - y, at[2] - leg.hip[2]],
            g[six.child].rotation,
        ))
    }

    /// Forward kinematics of the IK solution reaches the asked point with a
    /// flat foot, across the workspace and for several thighs.
    #[test]
    fn ik_reaches_the_asked_foot_pose() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        for tz in [-0.10, -0.08, -0.06, -0.04, -0.03, -0.01] {
            let mut morph = Morphology::of_type(0).unwrap();
            morph
                .set(protocol::params::Param::ThighRelHip2Z, tz)
                .unwrap();
            let model = NaoModel::new(morph).unwrap();
            let leg = Leg::of(&model);
            let mut checked = 0;
            while checked < 300 {
                let side = rng.random_range(0..2usize);
                let reach = leg.thigh + leg.tibia;
                let p = [
                    rng.random_range(-0.4..0.4) * reach,
                    rng.random_range(-0.25..0.25) * reach,
                    -rng.random_range(0.55..0.97) * reach - PITCH_ABOVE_ROLL,
                ];
                let q = leg_ik(p, &leg);
                let Some((at, foot)) = foot_of(&model, &leg, side, &q) else {
                    continue;
                };
                for k in 0..3 {
                    assert!((at[k] - p[k]).abs() < 1e-6, "tz {tz} p {p:?} got {at:?}");
                }
                assert!(foot.angle() < 1e-9, "foot not flat: {}", foot.angle());
                checked += 1;
            }
        }
    }

    /// The engine's expert plan without its stance hip-roll
    /// compensation (which turns a leg away from its IK), for the placing
    /// tests: the model, the gait, the rest posture.
    fn placing_gait() -> (NaoModel, Gait, Vec<f64>) {
        let model = NaoModel::new(Morphology::of_type(0).unwrap()).unwrap();
        let cfg = GaitConfig {
            hip_roll_comp_rad: 0.0,
            ..GaitConfig::ENGINE
        };
        let g = Gait::with_config(&model, WalkParams::EXPERT, 3.0, cfg);
        let rest = crate::nao::sim::standing_angles(&model);
        (model, g, rest)
    }

    /// Where `side`'s leg angles `leg` put its foot about the hip midpoint
    /// once the torso is turned by `torso` (forward kinematics, then the
    /// torso's turn), and where the plan's state `st` has it; None when an
    /// angle is past its stops.
    fn placed_foot(
        model: &NaoModel,
        g: &Gait,
        st: &GaitState,
        side: usize,
        leg: &[f64; 6],
        torso: UnitQuaternion<f64>,
    ) -> Option<(Vector3<f64>, [f64; 3])> {
        let (at, _) = foot_of(model, &g.leg, side, leg)?;
        let y = if side == 0 {
            g.leg.hip[1]
        } else {
            -g.leg.hip[1]
        };
        let f = st.feet[side];
        Some((
            torso * Vector3::new(at[0], at[1] + y, at[2]),
            [f[0] - st.hip[0], f[1] - st.hip[1], f[2] - st.hip[2]],
        ))
    }

    /// Asserts a placed foot (`walk`, from [`placed_foot`]) lands on the
    /// plan's (`plan`) within 1 µm on every axis; `what` names the case.
    fn assert_lands(walk: &Vector3<f64>, plan: &[f64; 3], what: &str) {
        for k in 0..3 {
            assert!(
                (walk[k] - plan[k]).abs() < 1e-6,
                "{what}: {walk:?} against {plan:?}"
            );
        }
    }

    /// Legs placed against a pitched torso (the balance's lean placing) put each foot
    /// where the plan has it in the walk's frame: forward kinematics of the
    /// pitched legs, pitched with the torso, lands on the plan's foot (about
    /// its hip); each side is placed by its own angle, and 0 is the plan's
    /// own targets, bit for bit.
    #[test]
    fn pitched_legs_put_the_feet_where_the_plan_has_them() {
        let (model, g, rest) = placing_gait();
        let mut checked = 0;
        for i in 0..40 {
            let t = 0.6 + 0.037 * f64::from(i);
            let st = g.state(t);
            assert_eq!(g.targets_of(&rest, &st, [0.0; 2]), g.targets(&rest, t));
            for pitch in [0.05, 0.12, 0.25] {
                for placed in 0..2 {
                    let mut by = [0.0; 2];
                    by[placed] = pitch;
                    let legs = g.legs_at(&st, by);
                    let plain = g.legs_at(&st, [0.0; 2]);
                    // The other side is the plan's, exactly.
                    assert_eq!(legs[1 - placed], plain[1 - placed]);
                    let tilt = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), pitch);
                    let Some((walk, plan)) =
                        placed_foot(&model, &g, &st, placed, &legs[placed], tilt)
                    else {
                        continue;
                    };
                    assert_lands(&walk, &plan, &format!("t {t} pitch {pitch} side {placed}"));
                    // Pitched forward, the foot's target moves ahead of the plan's.
                    let at = tilt.inverse() * walk;
                    assert!(at[0] > plan[0], "t {t} pitch {pitch}: {at:?}");
                    checked += 1;
                }
            }
        }
        assert!(checked >= 200, "only {checked} of 240 reachable");
    }

    /// `step_period`, `double_support` and `com_above_hip`, where a set
    /// gives them, replace the engine's own constants and nothing else; not
    /// given, the engine keeps its own.
    #[test]
    fn the_walk_engine_parameters_replace_the_engines_constants() {
        let none = ParamValues::default();
        assert_eq!(GaitConfig::ENGINE.with_params(&none), GaitConfig::ENGINE);
        let mut p = ParamValues::default();
        p.set(Param::StepPeriod, 0.22).unwrap();
        p.set(Param::DoubleSupport, 0.0).unwrap();
        p.set(Param::ComAboveHip, 0.03).unwrap();
        let cfg = GaitConfig::ENGINE.with_params(&p);
        assert_eq!(
            cfg,
            GaitConfig {
                period_s: 0.22,
                double_support: 0.0,
                com_above_hip_m: 0.03,
                ..GaitConfig::ENGINE
            }
        );
        // No double support: the support hands over at once, each step.
        let model = NaoModel::new(Morphology::of_type(0).unwrap()).unwrap();
        let g = Gait::with_config(&model, WalkParams::EXPERT, 3.0, cfg);
        let at = |t: f64| g.zmp(t);
        let k = GaitConfig::ENGINE.start_s + 3.0 * 0.22;
        assert!(at(k).iter().all(|v| v.is_finite()));
        assert_eq!(at(k + 1e-9), at(k + 0.1));
    }

    /// `step_reach` shortens a step whose swing would part the thighs, on
    /// average, faster than `step_reach` x the hip's speed cap, to exactly
    /// that step, and leaves shorter steps and every step without it (0) as
    /// asked; the first two steps stay half the (capped) step.
    #[test]
    fn step_reach_caps_the_planned_step_at_the_hips_speed_cap() {
        let model = NaoModel::new(Morphology::of_type(0).unwrap()).unwrap();
        let capped = GaitConfig {
            period_s: 0.14,
            double_support: 0.0,
            ..GaitConfig::ENGINE
        };
        assert_eq!(capped.step_reach, 1.0);
        let free = GaitConfig {
            step_reach: 0.0,
            ..capped
        };
        let full_step = |g: &Gait| (g.steps[1], g.steps[4] - g.steps[3]);
        let hip_rate = |g: &Gait, step: f64| 2.0 * step / (g.hip_height * g.cfg.period_s);
        let cap = model.joints[model.joint_index("lle3").unwrap()].max_speed_rad_s;
        for asked in [0.05, 0.12, 0.15] {
            let walk = WalkParams {
                step_length: asked,
                ..WalkParams::EXPERT
            };
            let g = Gait::with_config(&model, walk, 3.0, capped);
            let (first, full) = full_step(&g);
            assert!((first - full / 2.0).abs() < 1e-12, "{first} {full}");
            let rate = hip_rate(&g, asked);
            if rate <= cap {
                assert!(
                    (full - asked).abs() < 1e-12,
                    "{asked}: {full} at {rate} rad/s"
                );
            } else {
                assert!(full < asked);
                assert!((hip_rate(&g, full) - cap).abs() < 1e-9, "{asked}: {full}");
            }
            let free_full = full_step(&Gait::with_config(&model, walk, 3.0, free)).1;
            assert!((free_full - asked).abs() < 1e-12, "{asked}: {free_full}");
        }
        // The two longer steps are beyond the cap at this period: the test
        // covers both branches.
        let g = Gait::with_config(&model, WalkParams::EXPERT, 3.0, capped);
        assert!(hip_rate(&g, 0.05) < cap && hip_rate(&g, 0.12) > cap);
    }

    /// A plan walked at pace 1 is the plan; at a pace p each step lands p
    /// times the plan's step ahead of the support foot and the hip keeps p
    /// times the plan's lead over it; each cycle the targets move by the
    /// plan's motion at the pace, and by at most the pace's change times a
    /// step besides; the feet stay one paced step apart.
    #[test]
    fn a_paced_plan_takes_each_step_at_its_pace() {
        let model = NaoModel::new(Morphology::of_type(0).unwrap()).unwrap();
        let cfg = GaitConfig::ENGINE;
        let g = Gait::with_config(&model, WalkParams::EXPERT, 6.0, cfg);
        let cycle = 0.02;
        // Off the step boundaries (0.5 s + k x 0.16 s), which fall on cycles.
        let times = || (0..300).map(|i| f64::from(i) * cycle + 0.005);
        let mut at_one = Paced::new();
        for t in times() {
            let (plan, paced) = (g.state(t), at_one.state(&g, t, 1.0));
            for (a, b) in [plan.hip, plan.feet[0], plan.feet[1]].iter().zip([
                paced.hip,
                paced.feet[0],
                paced.feet[1],
            ]) {
                for (x, y) in a.iter().zip(b) {
                    assert!((x - y).abs() < 1e-12, "{t}: {a:?} {b:?}");
                }
            }
        }
        // The pace drops from 1 to 0.8 at 2 s, then rises to 0.9 at 4 s.
        let pace_at = |t: f64| {
            if t < 2.0 {
                1.0
            } else if t < 4.0 {
                0.8
            } else {
                0.9
            }
        };
        let mut paced = Paced::new();
        let (mut was, mut plan_was) = (paced.state(&g, 0.005, 1.0), g.state(0.005));
        let mut checked = 0;
        for t in times().skip(1) {
            let (st, plan) = (paced.state(&g, t, pace_at(t)), g.state(t));
            let moved = |a: &GaitState, b: &GaitState| {
                [
                    a.hip[0] - b.hip[0],
                    a.feet[0][0] - b.feet[0][0],
                    a.feet[1][0] - b.feet[1][0],
                ]
            };
            let (ours, theirs) = (moved(&st, &was), moved(&plan, &plan_was));
            // The pace's change over the last two steps (a swing foot lifted
            // from where an earlier pace put it).
            let change = (0..=25)
                .map(|i| (pace_at(t) - pace_at(t - f64::from(i) * cycle)).abs())
                .fold(0.0, f64::max);
            for (o, p) in ours.iter().zip(theirs) {
                // The plan's motion at the pace, and a pace change moves a
                // target by at most the change times a step.
                let bound = change * g.p.step_length + 1e-9;
                assert!(
                    (o - pace_at(t) * p).abs() <= bound,
                    "{t}: {ours:?} against {theirs:?}"
                );
            }
            // At a step's last cycle: the swing foot is where the pace lands
            // it, and the hip's lead over the support foot is the pace's.
            if let (Some(k), Some(next)) = (g.step_at(t), g.step_at(t + cycle)) {
                if next != k && k >= 2 {
                    let (sup, sw) = (k % 2, 1 - k % 2);
                    let step = g.foothold(k + 1) - g.foothold(k);
                    let end = cfg.start_s + (k + 1) as f64 * cfg.period_s - 1e-9;
                    let mut ahead = paced.clone();
                    let st_end = ahead.state(&g, end, pace_at(t));
                    let spacing = st_end.feet[sw][0] - st_end.feet[sup][0];
                    assert!((spacing - pace_at(t) * step).abs() < 1e-6, "{t}: {spacing}");
                    let lead = st.hip[0] - st.feet[sup][0] - g.p.long_offset;
                    let plan_lead = plan.hip[0] - plan.feet[sup][0] - g.p.long_offset;
                    assert!((lead - pace_at(t) * plan_lead).abs() < 1e-9, "{t}: {lead}");
                    checked += 1;
                }
            }
            (was, plan_was) = (st, plan);
        }
        assert_eq!(checked, 32, "steps 2 to 33 end within the 6 s");
        // Walked at 0.8 and 0.9 for most of it, the feet ended well short of
        // the plan's.
        assert!(
            was.hip[0] < 0.92 * plan_was.hip[0],
            "{} {}",
            was.hip[0],
            plan_was.hip[0]
        );
    }

    /// The legs' targets, clamped into the stops as the servos get them,
    /// put the feet one planned step apart at every touchdown, on a
    /// long-thighed body with the engine's constants: forward kinematics
    /// of [`Gait::leg_targets`] against [`Gait::state`]. Where a trial's
    /// feet land further apart than planned, the excess is not in the plan
    /// or the IK.
    #[test]
    fn the_legs_targets_land_the_feet_one_planned_step_apart() {
        let mut p = ParamValues::default();
        for (k, v) in [
            (Param::ThighRelHip2Z, -0.0794),
            (Param::RatioFlexion, 0.739),
            (Param::LongOffset, 0.0064),
            (Param::HeightLift, 0.0434),
            (Param::StepLength, 0.1326),
            (Param::StepPeriod, 0.1352),
            (Param::DoubleSupport, 0.0),
        ] {
            p.set(k, v).unwrap();
        }
        let model = NaoModel::with_params(0, &p).unwrap();
        let cfg = GaitConfig::ENGINE.with_params(&p);
        let g = Gait::with_config(&model, p.walk(), 10.0, cfg);
        let leg = Leg::of(&model);
        let rest = crate::nao::sim::standing_angles(&model);
        let step = g.step_length();
        assert!(step < 0.1326 - 0.02, "capped: {step}");
        for k in 4..60 {
            let t = cfg.start_s + (k as f64 + 0.999) * cfg.period_s;
            // The targets the servos get, clamped by the gait itself.
            let mut q = [[0.0; 6]; 2];
            for (j, target) in g.targets(&rest, t).into_iter().enumerate() {
                if let Some((side, i)) = g.leg_slots[j] {
                    q[side][i] = target;
                }
            }
            let l = foot_of(&model, &leg, 0, &q[0]).unwrap().0;
            let r = foot_of(&model, &leg, 1, &q[1]).unwrap().0;
            let feet = g.state(t).feet;
            let planned = feet[0][0] - feet[1][0];
            assert!((planned.abs() - step).abs() < 1e-3, "{t}: {planned}");
            assert!(((l[0] - r[0]) - planned).abs() < 1e-3, "{t}: {l:?} {r:?}");
        }
    }

    /// Arm swing turns each shoulder pitch against its opposite leg, by the
    /// constant times the left foot's lead in step lengths (the right arm
    /// forward, its angle up, as the left foot leads), and touches nothing
    /// else; without it the arms keep their rest angles exactly.
    #[test]
    fn arm_swing_turns_the_shoulders_against_the_legs() {
        let model = NaoModel::new(Morphology::of_type(0).unwrap()).unwrap();
        let rest = crate::nao::sim::standing_angles(&model);
        let held = GaitConfig {
            arm_swing_rad: 0.0,
            ..GaitConfig::ENGINE
        };
        let still = Gait::with_config(&model, WalkParams::EXPERT, 5.0, held);
        let cfg = GaitConfig {
            arm_swing_rad: 0.3,
            ..GaitConfig::ENGINE
        };
        let swung = Gait::with_config(&model, WalkParams::EXPERT, 5.0, cfg);
        let (l, r) = (
            model.joint_index("lae1").unwrap(),
            model.joint_index("rae1").unwrap(),
        );
        let mut seen = [false; 2];
        for i in 0..500 {
            let t = f64::from(i) * 0.01;
            let (a, b) = (still.targets(&rest, t), swung.targets(&rest, t));
            assert_eq!((a[l], a[r]), (rest[l], rest[r]));
            let feet = swung.state(t).feet;
            let lead = (feet[0][0] - feet[1][0]) / WalkParams::EXPERT.step_length;
            assert!((b[l] - (rest[l] - 0.3 * lead)).abs() < 1e-12, "t {t}");
            assert!((b[r] - (rest[r] + 0.3 * lead)).abs() < 1e-12, "t {t}");
            for j in (0..a.len()).filter(|j| *j != l && *j != r) {
                assert_eq!(a[j].to_bits(), b[j].to_bits(), "joint {j} at {t}");
            }
            seen[usize::from(lead > 0.5)] |= lead.abs() > 0.5;
        }
        assert_eq!(seen, [true, true], "both feet lead by over half a step");
    }

    #[test]
    fn gait_starts_still_and_walks_forward() {
        let model = NaoModel::new(Morphology::of_type(0).unwrap()).unwrap();
        let g = Gait::new(&model, WalkParams::EXPERT, 10.0);
        let s0 = g.state(0.0);
        assert!(
            (s0.hip[0] - WalkParams::EXPERT.long_offset).abs() < 1e-3 && s0.hip[1].abs() < 1e-3
        );
        let s = g.state(9.9);
        // Steps: half, half, then full: about (9.4 / 0.16 − 1) × 0.08 m.
        assert!(s.hip[0] > 4.3 && s.hip[0] < 4.8, "{:?}", s.hip);
    }
}
