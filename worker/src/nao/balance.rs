//! The closed-loop walk: the LIP-3D plan of [`super::walk`] at the league's
//! pace, balanced every 20 ms agent cycle from the robot's own noisy sensors.
//!
//! It must stay a controller: joint targets from the plan and what the robot
//! senses, no access to the simulation's true state and no randomness (the
//! trial adds the sensors' noise before they reach it).
//!
//! # What it senses and what it does with it
//! - **Torso tilt**, estimated by a complementary filter: the gyro integrated,
//!   pulled towards the accelerometer's gravity direction with time constant
//!   [`TILT_FILTER_S`]. The plan keeps the torso upright, so the estimate is the
//!   error. By default the pull is towards each cycle's accelerometer angle;
//!   the heel strikes of a fast walk shake that reading (its vertical part's
//!   sd 9-11 m/s² against its 9.8 m/s² mean), and the mean of those angles
//!   reads the torso further back than it leans (by 5-11° on the held walks
//!   below, each trial's mean). With `tilt_vector` the filter keeps the
//!   gravity vector instead, turned by the gyro and pulled linearly towards
//!   each reading, whose mean is gravity's: its pitch keeps within 1° of
//!   the torso's (docs/walk.md, "The tilt estimate, read right, and the
//!   pitch held").
//! - **Pitch hold**: with `pitch_hold_gain` (0 by default) both hips' pitch
//!   carries the integral of the estimated pitch's excess over
//!   `pitch_hold_rad` (capped at [`PITCH_HOLD_MAX`]), or with
//!   `pitch_hold_ankle` a share of it both ankles' pitch: a slow bias the
//!   same on both legs, where the hip-pitch gain, switched from leg to leg
//!   with the load every step, costs the walk its pace. On the heading
//!   file's walk it leans against the walk's first lean, then grows to its
//!   cap within about 20 s and keeps the walk standing at a lean of 20-30°
//!   for a minute (docs/walk.md, "The tilt estimate, read right, and the
//!   pitch held").
//! - **Sagittal balance**: the stance hip pitch turns against the torso's
//!   pitch ([`Gains::hip_pitch`]). Without it the torso leans back a little
//!   more with every fast step (−2° on average at 0.22 s steps, −40° and a fall
//!   within 8 s on some seeds), and a leaning torso swings the feet further
//!   than the plan: distances that are not walking.
//! - The stance ankle pitch and hip roll can turn against the tilt and its
//!   rate too ([`Gains`]); measured on the first walks, they did not help
//!   this robot and are 0 by default.
//! - **Sideways rock**: with `hip_roll_rate_gain` (0 by default) the stance
//!   hip's roll turns against the gyro's roll rate, in the leg's share of
//!   the load: a damper. With the elbow yaws welded, the fast arms walks
//!   rock sideways as they lean back and fall late in a trial; the damper
//!   calms the rock and they stand (docs/walk.md, "The sideways rock,
//!   damped").
//! - **Foot force sensors** weigh the stance corrections: each leg's share is
//!   its share of the sensed vertical load, so a foot in the air gets none.
//! - **Torso turn** about the vertical, the gyro's yaw rate integrated and
//!   leaking over [`TURN_FILTER_S`]: with `turn_place` (0 by default) the
//!   feet are placed against it, so a turned torso lands them where the
//!   plan has them in the walk's frame (docs/walk.md, "Where the optima's
//!   distance beyond their plan comes from").
//! - **Forward lean**: with `lean_place` (0 by default) a foot is placed
//!   against the torso's sensed forward pitch in the share of the load it
//!   does not carry, so a torso pitched forward does not carry the swinging
//!   foot's target back with the hips (a torso leaning back, the walk's own
//!   posture, moves no foot): docs/walk.md, "A torso leaning forward steps
//!   ahead".
//! - **Touchdowns**: with `step_aim` (0 by default) a [`StepGauge`] reads
//!   each landing's feet spacing from the sensed joint angles, against the
//!   spacing aimed at, and the plan is walked at the pace that aims the
//!   steps short by what the legs overreach ([`super::walk::Paced`];
//!   docs/walk.md, "Steps aimed short by the legs' overreach"). With
//!   `step_aim_heading` (0 by default) the spacing is read along the walk's
//!   heading, the torso's x axis turned back by the gyro's integrated turn:
//!   a torso that yaws with each step otherwise reads the feet's sideways
//!   offset as spacing (docs/walk.md, "Steps read along the heading").
//!   With `step_aim_before` (0 by default) it is read from the angles of
//!   the cycle before the touchdown, while the other foot still carries
//!   (docs/walk.md, "Steps read before the other foot leaves").
//!
//! # Engine constants (values and why)
//! Each value was measured on the expert set (20 noisy trials, seed 3) against
//! its neighbours with `naofarm trial --walk closed-loop --engine KEY=VALUE`;
//! `docs/walk.md` has the tables.
//! - Step period 0.18 s (the open loop's 0.40 s): speed comes from the step
//!   rate. At 0.17 s s fell to 0.8–0.9, at 0.16 s every trial fell.
//! - Double support 5 % (10 % → 3.83 m, 5 % → 4.07 m, 15 % → s 0.8).
//! - Stance hip-roll compensation 0.10 rad (the open loop's 0.20 rad rolls the
//!   torso over at this pace: s 0.35 at 0.15, 1.00 at 0.10, 0.50 at 0.05).
//! - Trapezoidal swing travel: peak foot speed 1.33× the mean instead of the
//!   cosine's 1.57×, so the hip and knee stay nearer the 6.14 rad/s cap
//!   (0.22 s steps of 0.10 m: 4.73 m against 4.48 m).
//! - Hip-pitch gain −1.5 rad/rad: −1 → 4.07 m, −1.5 → 4.15 m, −2 → 4.16 m
//!   with s 0.98 over 100 trials; 0 → 3.81 m.
//!
//! The step period, double support, CoM height, the stance hip-roll
//! compensation, the arm swing, the hip- and ankle-pitch gains and the
//! turn's share are registry parameters too (`step_period`,
//! `double_support`, `com_above_hip`, `hip_roll_comp`, `arm_swing`,
//! `hip_pitch_gain`, `ankle_pitch_gain`, `turn_place`, `step_aim`,
//! `step_aim_heading`, `step_aim_before`, `lean_place`, `hip_roll_rate_gain`,
//! `tilt_vector`, `pitch_hold_gain`, `pitch_hold_rad`, `pitch_hold_ankle`):
//! a set that gives one replaces the constant here.
//! The arms configuration (`experiments/physical-technical-arms.toml`)
//! swings the arms: docs/walk.md, "Swinging arms at the league's pace"; at
//! 4 × 5 ms (`physical-technical-arms-5ms.toml`) its walks keep to their
//! plan ("The arms at 4 × 5 ms").
//! The stiff configuration
//! (`experiments/physical-technical-stiff.toml`, 32 PGS iterations) fixes
//! 0.19 s, 0, 0.05 m, −0.75 and 0.3: with these constants the expert set
//! falls there in 80 % of its trials (docs/walk.md, "A stiffer solve").

use protocol::params::{Param, ParamValues};

use super::footwork::{AIR_CYCLES, PLANTED_N};
use super::sim::Perception;
use super::walk::{GaitConfig, TravelProfile};

/// The closed-loop walk's plan constants.
pub const GAIT: GaitConfig = GaitConfig {
    period_s: 0.18,
    double_support: 0.05,
    com_above_hip_m: 0.03,
    hip_roll_comp_rad: 0.10,
    start_s: 0.5,
    travel: TravelProfile::Trapezoid,
    ramp_steps: 0.0,
    lift_peak: 0.5,
    lift_end: 1.0,
    yaw_pitch_rad: 0.0,
    arm_swing_rad: 0.0,
    step_reach: 0.0,
};

/// Time constant of the tilt estimate's pull towards the accelerometer, s.
pub const TILT_FILTER_S: f64 = 0.5;

/// The largest pitch the hold puts on both legs, rad (hips and ankles
/// together). On the split hold's expert (20 trials of 60 s from 777) 0.3
/// stands 75 % of the trials, 0.4 all of them, 0.6 and 0.8 45 and 40 %:
/// the larger the cap, the more upright and the shorter the walk.
pub const PITCH_HOLD_MAX: f64 = 0.4;

/// Gravity, m/s²: the gravity-vector filter's start (the torso upright).
const GRAVITY_M_S2: f64 = 9.81;

/// Time constant of the turn estimate's leak towards 0, s: the walk's heading
/// drifts slowly, the turn of each step comes and goes within it.
pub const TURN_FILTER_S: f64 = 1.0;

/// Feedback gains (rad per rad, rad per rad/s).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Gains {
    /// Stance ankle pitch per rad of torso pitch.
    pub ankle_pitch: f64,
    /// Stance ankle pitch per rad/s of pitch rate.
    pub ankle_pitch_rate: f64,
    /// Stance hip pitch per rad of torso pitch.
    pub hip_pitch: f64,
    /// Stance hip roll per rad of torso roll.
    pub hip_roll: f64,
    /// Stance hip roll per rad/s of roll rate.
    pub hip_roll_rate: f64,
    /// The feet placed against this share of the torso's sensed turn about
    /// the vertical (0: in the torso's frame, as planned; 1: in the walk's).
    pub turn_place: f64,
    /// Each step's share in the overreach estimate of [`StepGauge`]
    /// (0: off, the plan's steps aimed as they are; 0.1: about the last ten
    /// steps).
    pub step_aim: f64,
    /// The share of the torso's sensed turn by which [`StepGauge`]'s
    /// reading is turned back towards the walk's heading (0: along the
    /// torso's x axis; 1: along the heading).
    pub step_aim_heading: f64,
    /// The share of [`StepGauge`]'s reading taken from the cycle before the
    /// touchdown, while the other foot still carries (0: the touchdown's
    /// own cycle, when the other foot may already be on its way).
    pub step_aim_before: f64,
    /// Each foot placed against this share of the torso's sensed forward
    /// lean, in the share of the load it does not carry (0: in the torso's
    /// frame, as planned; 1: a foot in the air where the plan has it in the
    /// walk's frame). A torso leaning back moves no foot.
    pub lean_place: f64,
    /// The tilt estimate's share taken from the gravity-vector filter (0:
    /// the per-cycle angle filter; 1: the vector's alone).
    pub tilt_vector: f64,
    /// Both legs' pitch per rad·s of the estimated pitch's excess over
    /// `pitch_hold`, integrated (0: off), on the hips and the ankles by
    /// `pitch_hold_ankle`.
    pub pitch_hold_gain: f64,
    /// The torso pitch the hold keeps, rad (negative: leaning back).
    pub pitch_hold: f64,
    /// The hold's share on both ankles' pitch, the rest on the hips'.
    pub pitch_hold_ankle: f64,
}

impl Gains {
    /// These gains with the parameter set's `hip_pitch_gain`,
    /// `ankle_pitch_gain`, `turn_place`, `step_aim`, `step_aim_heading`,
    /// `step_aim_before`, `lean_place`, `hip_roll_rate_gain`, `tilt_vector`,
    /// `pitch_hold_gain`, `pitch_hold_rad` and `pitch_hold_ankle`, where it
    /// gives them (the registry's feedback parameters; an experiment may fix
    /// or optimise them).
    #[must_use]
    pub fn with_params(self, params: &ParamValues) -> Self {
        Self {
            hip_pitch: params.given(Param::HipPitchGain).unwrap_or(self.hip_pitch),
            ankle_pitch: params
                .given(Param::AnklePitchGain)
                .unwrap_or(self.ankle_pitch),
            turn_place: params.given(Param::TurnPlace).unwrap_or(self.turn_place),
            step_aim: params.given(Param::StepAim).unwrap_or(self.step_aim),
            step_aim_heading: params
                .given(Param::StepAimHeading)
                .unwrap_or(self.step_aim_heading),
            step_aim_before: params
                .given(Param::StepAimBefore)
                .unwrap_or(self.step_aim_before),
            lean_place: params.given(Param::LeanPlace).unwrap_or(self.lean_place),
            hip_roll_rate: params
                .given(Param::HipRollRateGain)
                .unwrap_or(self.hip_roll_rate),
            tilt_vector: params.given(Param::TiltVector).unwrap_or(self.tilt_vector),
            pitch_hold_gain: params
                .given(Param::PitchHoldGain)
                .unwrap_or(self.pitch_hold_gain),
            pitch_hold: params.given(Param::PitchHold).unwrap_or(self.pitch_hold),
            pitch_hold_ankle: params
                .given(Param::PitchHoldAnkle)
                .unwrap_or(self.pitch_hold_ankle),
            ..self
        }
    }

    /// Each gain by its field name: the registry parameter it is also given
    /// by, where it is one (which sets its range: [`Gains::range`]), and
    /// the field.
    pub const FIELDS: [GainField; 14] = [
        ("ankle_pitch", Some(Param::AnklePitchGain), |g| {
            &mut g.ankle_pitch
        }),
        ("ankle_pitch_rate", None, |g| &mut g.ankle_pitch_rate),
        ("hip_pitch", Some(Param::HipPitchGain), |g| &mut g.hip_pitch),
        ("hip_roll", None, |g| &mut g.hip_roll),
        ("hip_roll_rate", Some(Param::HipRollRateGain), |g| {
            &mut g.hip_roll_rate
        }),
        ("turn_place", Some(Param::TurnPlace), |g| &mut g.turn_place),
        ("step_aim", Some(Param::StepAim), |g| &mut g.step_aim),
        ("step_aim_heading", Some(Param::StepAimHeading), |g| {
            &mut g.step_aim_heading
        }),
        ("step_aim_before", Some(Param::StepAimBefore), |g| {
            &mut g.step_aim_before
        }),
        ("lean_place", Some(Param::LeanPlace), |g| &mut g.lean_place),
        ("tilt_vector", Some(Param::TiltVector), |g| {
            &mut g.tilt_vector
        }),
        ("pitch_hold_gain", Some(Param::PitchHoldGain), |g| {
            &mut g.pitch_hold_gain
        }),
        ("pitch_hold", Some(Param::PitchHold), |g| &mut g.pitch_hold),
        ("pitch_hold_ankle", Some(Param::PitchHoldAnkle), |g| {
            &mut g.pitch_hold_ankle
        }),
    ];

    /// The range a gain of [`Gains::FIELDS`] may be set in, by its
    /// parameter: the parameter's admissible range, or [`OTHER_GAIN_RANGE`]
    /// for a gain that is no parameter.
    #[must_use]
    pub fn range(param: Option<Param>) -> (f64, f64) {
        param.map_or(OTHER_GAIN_RANGE, |p| (p.spec().min, p.spec().max))
    }
}

/// A gain of [`Gains::FIELDS`]: its name, its parameter, its field.
pub type GainField = (&'static str, Option<Param>, fn(&mut Gains) -> &mut f64);

/// The range of the gains that are no parameter (rad per rad, rad per
/// rad/s): that of the pitch gains that are (`hip_pitch_gain`,
/// `ankle_pitch_gain`). Every gain measured is well inside it.
pub const OTHER_GAIN_RANGE: (f64, f64) = (-5.0, 5.0);

/// The closed-loop walk's gains.
pub const GAINS: Gains = Gains {
    ankle_pitch: 0.0,
    ankle_pitch_rate: 0.0,
    hip_pitch: -1.5,
    hip_roll: 0.0,
    hip_roll_rate: 0.0,
    turn_place: 0.0,
    step_aim: 0.0,
    step_aim_heading: 0.0,
    step_aim_before: 0.0,
    lean_place: 0.0,
    tilt_vector: 0.0,
    pitch_hold_gain: 0.0,
    pitch_hold: 0.0,
    pitch_hold_ankle: 0.0,
};

/// The readings [`StepGauge`] keeps: a step's landed spacing over its aim,
/// from half to twice (beyond: a stumble or a foot landing behind, skipped).
pub const OVERREACH_RANGE: (f64, f64) = (0.5, 2.0);

/// The shortest pace [`StepGauge`] aims at: 70 % of the plan's steps. It
/// never aims longer than the plan: legs that land short of their aim are
/// left short (aiming them further asks the swing for more speed than it
/// has, and a stumble would feed itself).
pub const PACE_MIN: f64 = 0.7;

/// What the legs overreach by, measured at each step's end from the robot's
/// own sensed joint angles, and the pace that aims the steps short by it.
///
/// At each touchdown (a foot's sensed load rising through [`PLANTED_N`]
/// after [`AIR_CYCLES`] in the air), the feet's spacing along the torso's x
/// axis by forward kinematics of the sensed joint angles is divided by the
/// spacing the paced plan aims at for that step's end; the
/// estimate follows those readings by `share` per step. The plan is then
/// walked at the pace 1 / estimate ([`super::walk::Paced`]): legs that land
/// 10 % past their aim are aimed 10 % short, so the feet land the plan's
/// steps. A controller like the rest: sensed angles, no ground truth.
#[derive(Debug, Clone)]
pub struct StepGauge {
    share: f64,
    heading: f64,
    before: f64,
    ratio: f64,
    readings: u32,
    /// Cycles each foot's sensed load has been under [`PLANTED_N`].
    air: [u32; 2],
}

impl StepGauge {
    /// A gauge following each step's reading by `share` (0–1), no overreach
    /// yet, its readings turned back by `heading` (0–1) of the torso's
    /// sensed turn ([`StepGauge::turn_back`]).
    #[must_use]
    pub fn new(share: f64, heading: f64) -> Self {
        Self {
            share: share.clamp(0.0, 1.0),
            heading: heading.clamp(0.0, 1.0),
            before: 0.0,
            ratio: 1.0,
            readings: 0,
            air: [0, 0],
        }
    }

    /// Folds one cycle's sensed foot loads; the side that touched down in it,
    /// if one did: its sensed load reached [`PLANTED_N`] after at least
    /// [`AIR_CYCLES`] cycles under it (a bounce does not count).
    pub fn touchdown(&mut self, sensed: &Perception) -> Option<usize> {
        let mut landed = None;
        for (side, air) in self.air.iter_mut().enumerate() {
            if sensed.foot_force_n[side][2] >= PLANTED_N {
                if *air >= AIR_CYCLES {
                    landed = Some(side);
                }
                *air = 0;
            } else {
                *air = air.saturating_add(1);
            }
        }
        landed
    }

    /// Folds one step's end: the feet `landed` this far apart (sensed), the
    /// paced plan `aimed` them this far apart, m. An aim under a centimetre,
    /// or a reading outside [`OVERREACH_RANGE`] (or not a number), is skipped.
    pub fn fold(&mut self, landed: f64, aimed: f64) {
        let r = landed / aimed;
        // A NaN aim or landing gives a NaN ratio, outside the range.
        if aimed < 0.01 || !(OVERREACH_RANGE.0..=OVERREACH_RANGE.1).contains(&r) {
            return;
        }
        self.ratio += self.share * (r - self.ratio);
        self.readings += 1;
    }

    /// The pace to walk the plan at: 1 / the overreach estimate, from
    /// [`PACE_MIN`] to 1.
    #[must_use]
    pub fn pace(&self) -> f64 {
        (1.0 / self.ratio).clamp(PACE_MIN, 1.0)
    }

    /// The angle a reading is turned back by, rad, for a torso's sensed
    /// turn about the vertical of `turn` rad: its `heading` share of it.
    /// The feet's spacing is then read along the walk's heading rather than
    /// the torso's x axis ([`super::footwork::ahead_turned`]): a torso that
    /// yaws with each step (by ±3–5° on the long thighs) otherwise reads its
    /// feet's sideways offset, 0.1 m × the yaw, as spacing or its lack.
    #[must_use]
    pub fn turn_back(&self, turn: f64) -> f64 {
        self.heading * turn
    }

    /// This gauge taking `before` (0–1) of each reading from the cycle
    /// before the touchdown ([`StepGauge::before`]).
    #[must_use]
    pub fn reading_before(self, before: f64) -> Self {
        Self {
            before: before.clamp(0.0, 1.0),
            ..self
        }
    }

    /// The share of each reading taken from the sensed angles of the cycle
    /// before the touchdown, the rest from the touchdown's own cycle. A
    /// foot's landing is sensed in the cycle its load rises, and by then
    /// the other foot has often begun its swing: read in that cycle, the
    /// spacing is short of the step by how far the other foot has gone
    /// (2–3 cm on the hold file's fast walks; docs/walk.md, "Steps read
    /// before the other foot leaves").
    #[must_use]
    pub fn before(&self) -> f64 {
        self.before
    }

    /// Steps read so far.
    #[must_use]
    pub fn readings(&self) -> u32 {
        self.readings
    }
}

/// The controller's state: the tilt estimate.
#[derive(Debug, Clone)]
pub struct Balance {
    gains: Gains,
    /// Torso (roll, pitch) estimate, rad: the angle filter's, the vector
    /// filter's, or their blend (`tilt_vector`).
    tilt: [f64; 2],
    /// The angle filter's (roll, pitch), rad: the gyro's rates integrated,
    /// pulled towards each cycle's accelerometer angles.
    angles: [f64; 2],
    /// The vector filter's gravity in the torso's axes, m/s²: turned by the
    /// gyro, pulled linearly towards each accelerometer reading.
    gravity: [f64; 3],
    /// The estimated pitch's excess over `pitch_hold`, integrated, rad·s.
    held: f64,
    /// Torso turn about the vertical, rad: the gyro integrated, leaking
    /// towards 0 with time constant [`TURN_FILTER_S`].
    turn: f64,
}

/// What the controller adds to the plan for the next cycle.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Correction {
    /// Added to each leg's six angles (le1..le6), left then right.
    pub legs: [[f64; 6]; 2],
    /// The torso's turn the feet are placed against, rad (0: none).
    pub turn: f64,
    /// The torso's forward lean each foot (left, right) is placed against,
    /// rad (0: none; `lean_place`).
    pub lean: [f64; 2],
}

impl Balance {
    /// A controller with these gains, the torso upright.
    #[must_use]
    pub fn new(gains: Gains) -> Self {
        Self {
            gains,
            tilt: [0.0, 0.0],
            angles: [0.0, 0.0],
            gravity: [0.0, 0.0, GRAVITY_M_S2],
            held: 0.0,
            turn: 0.0,
        }
    }

    /// A [`StepGauge`] for this controller's `step_aim`; none when it is 0.
    #[must_use]
    pub fn gauge(&self) -> Option<StepGauge> {
        (self.gains.step_aim > 0.0).then(|| {
            StepGauge::new(self.gains.step_aim, self.gains.step_aim_heading)
                .reading_before(self.gains.step_aim_before)
        })
    }

    /// The torso (roll, pitch) estimate, rad.
    #[must_use]
    pub fn tilt(&self) -> [f64; 2] {
        self.tilt
    }

    /// The torso's turn about the vertical, rad: the gyro integrated, leaking
    /// towards 0 over [`TURN_FILTER_S`] (its swing about the walk's heading).
    #[must_use]
    pub fn turn(&self) -> f64 {
        self.turn
    }

    /// Folds in one cycle's (noisy) perception and returns the correction.
    pub fn update(&mut self, sensed: &Perception, dt: f64) -> Correction {
        let [gx, gy, gz] = sensed.gyro_rad_s;
        self.turn += gz * dt;
        self.turn -= self.turn * dt / TURN_FILTER_S;
        let [ax, ay, az] = sensed.accel_m_s2;
        // Gravity seen from a torso rolled by r and pitched by p reads
        // (−g sin p, g sin r cos p, g cos r cos p) in the torso's axes.
        let acc_roll = libm::atan2(ay, az);
        let acc_pitch = libm::atan2(-ax, libm::hypot(ay, az));
        let k = dt / (TILT_FILTER_S + dt);
        let roll = self.angles[0] + gx * dt;
        let pitch = self.angles[1] + gy * dt;
        self.angles = [
            roll + k * (acc_roll - roll),
            pitch + k * (acc_pitch - pitch),
        ];
        let g = &self.gains;
        self.tilt = if g.tilt_vector == 0.0 {
            self.angles
        } else {
            // A vector fixed in the world turns in the torso's axes by
            // −ω × v; the pull is linear in the reading, so the heel
            // strikes' shaking averages out instead of biasing an angle.
            let v = self.gravity;
            let turned = [
                v[0] - (gy * v[2] - gz * v[1]) * dt,
                v[1] - (gz * v[0] - gx * v[2]) * dt,
                v[2] - (gx * v[1] - gy * v[0]) * dt,
            ];
            let a = [ax, ay, az];
            self.gravity = std::array::from_fn(|i| turned[i] + k * (a[i] - turned[i]));
            let [vx, vy, vz] = self.gravity;
            let vector = [libm::atan2(vy, vz), libm::atan2(-vx, libm::hypot(vy, vz))];
            let s = g.tilt_vector;
            std::array::from_fn(|i| (1.0 - s) * self.angles[i] + s * vector[i])
        };
        let [roll, pitch] = self.tilt;
        let load = |f: &[f64; 3]| f[2].max(0.0);
        let (l, r) = (load(&sensed.foot_force_n[0]), load(&sensed.foot_force_n[1]));
        let share = if l + r > 1.0 {
            [l / (l + r), r / (l + r)]
        } else {
            [0.0, 0.0]
        };
        let mut c = Correction::default();
        for (side, w) in share.iter().enumerate() {
            let leg = &mut c.legs[side];
            leg[4] = w * (g.ankle_pitch * pitch + g.ankle_pitch_rate * gy);
            leg[2] = w * g.hip_pitch * pitch;
            leg[1] = w * (g.hip_roll * roll + g.hip_roll_rate * gx);
        }
        if g.pitch_hold_gain != 0.0 {
            let cap = PITCH_HOLD_MAX / g.pitch_hold_gain.abs();
            self.held = (self.held + (pitch - g.pitch_hold) * dt).clamp(-cap, cap);
            let hold = g.pitch_hold_gain * self.held;
            let ankle = g.pitch_hold_ankle;
            for leg in &mut c.legs {
                leg[2] += (1.0 - ankle) * hold;
                if ankle != 0.0 {
                    leg[4] += ankle * hold;
                }
            }
        }
        // Off, exactly 0 whatever the estimate (never 0 × a non-finite turn).
        if g.turn_place != 0.0 {
            c.turn = g.turn_place * self.turn;
        }
        if g.lean_place != 0.0 {
            // A foot in the air (or both, in flight: no share) placed in
            // full; a torso leaning back (the walk's own posture) moves no foot.
            c.lean = share.map(|w| g.lean_place * (1.0 - w) * pitch.max(0.0));
        }
        c
    }
}

#[cfg(test)]
mod tests {
    use crate::nao::sim::SimSettings;
    use crate::nao::trial::{self, run, run_many, Batch, Engine, NaoTrial, WalkEngine};
    use protocol::params::{Param, ParamValues};

    fn closed() -> Engine {
        Engine::of(WalkEngine::ClosedLoop)
    }

    /// (s, mx, my) over the trials, mx and my over those that did not fall.
    fn summary(ts: &[NaoTrial]) -> (f64, f64, f64) {
        let ok: Vec<_> = ts.iter().filter(|t| !t.measurement.fell).collect();
        let n = ok.len().max(1) as f64;
        (
            ok.len() as f64 / ts.len() as f64,
            ok.iter().map(|t| t.measurement.x_m).sum::<f64>() / n,
            ok.iter().map(|t| t.measurement.y_m.abs()).sum::<f64>() / n,
        )
    }

    /// Done-when of the pace issue: the expert set walks ≥ 4.0 m in 10 s with
    /// s ≥ 0.7 over 100 trials, straight (my/mx ≤ 0.25), and as far as its
    /// planned steps within 10 % (no sliding or lunging passed off as walking).
    #[test]
    fn the_expert_set_walks_at_the_leagues_pace_as_far_as_planned() {
        walks_at_pace_as_planned(&ParamValues::default(), 100, SimSettings::default());
    }

    /// `n` noisy trials of `p` on the closed loop, 10 s each, seeds from 777
    /// (Table IV's), on 2 threads.
    fn from_777(p: &ParamValues, n: u64, physics: SimSettings) -> Vec<NaoTrial> {
        lasting(p, n, 10.0, physics)
    }

    /// `n` trials of `params` from seed 777 with `physics`, held to the pace
    /// issue's walk: s ≥ 0.7, mx ≥ 4.0 m, my/mx ≤ 0.25, and mx within 10 %
    /// of the plan's hip travel. Returns the trials, s, mx and the plan's.
    fn walks_at_pace_as_planned(
        params: &ParamValues,
        n: u64,
        physics: SimSettings,
    ) -> (Vec<NaoTrial>, f64, f64, f64) {
        let ts = from_777(params, n, physics);
        let (s, mx, my) = summary(&ts);
        assert!(s >= 0.7, "s = {s}");
        assert!(mx >= 4.0, "mx = {mx}");
        assert!(my / mx <= 0.25, "my/mx = {}", my / mx);
        let planned = trial::planned_travel_m(0, params, 10.0, closed()).unwrap();
        assert!(
            (mx - planned).abs() <= 0.1 * planned,
            "walked {mx} m, planned {planned} m"
        );
        (ts, s, mx, planned)
    }

    /// [`walks_at_pace_as_planned`], with every joint of every trial within
    /// 1° of its stops (the pace issue's bound on the expert set).
    fn walks_at_pace_within_the_stops(
        params: &ParamValues,
        n: u64,
        physics: SimSettings,
    ) -> (Vec<NaoTrial>, f64, f64, f64) {
        let walked = walks_at_pace_as_planned(params, n, physics);
        for t in &walked.0 {
            for e in &t.stop_excess {
                assert!(e.rad.to_degrees() <= 1.0, "seed {}: {e:?}", t.seed);
            }
        }
        walked
    }

    /// What a torso at rest senses: the accelerometer reading `accel`, the
    /// feet's vertical loads `loads` (left, right), nothing turning.
    fn still(accel: [f64; 3], loads: [f64; 2]) -> crate::nao::sim::Perception {
        crate::nao::sim::Perception {
            time_s: 0.0,
            joint_angles_rad: Vec::new(),
            gyro_rad_s: [0.0; 3],
            accel_m_s2: accel,
            foot_force_n: [[0.0, 0.0, loads[0]], [0.0, 0.0, loads[1]]],
            torso_position_m: [0.0; 3],
            torso_rotation: [0.0, 0.0, 0.0, 1.0],
            torso_tilt_rad: 0.0,
        }
    }

    /// `lean_place` places a foot against the sensed forward lean in the
    /// share of the load it does not carry (both in full in the air), a
    /// torso leaning back moves no foot, and off it is exactly nothing.
    #[test]
    fn a_forward_lean_places_the_unloaded_foot() {
        use super::{Balance, Correction, Gains, GAINS};
        let lean = |pitch: f64, loads: [f64; 2], gain: f64| -> Correction {
            let mut b = Balance::new(Gains {
                lean_place: gain,
                ..GAINS
            });
            // Gravity seen from a torso pitched by `pitch`, held until the
            // estimate has settled on it.
            let p = still([-9.81 * pitch.sin(), 0.0, 9.81 * pitch.cos()], loads);
            let mut c = Correction::default();
            for _ in 0..500 {
                c = b.update(&p, 0.02);
            }
            c
        };
        let near = |a: [f64; 2], b: [f64; 2]| (0..2).all(|i| (a[i] - b[i]).abs() < 1e-6);
        // Leaning forward 0.2 rad, the left foot carrying three quarters.
        let c = lean(0.2, [45.0, 15.0], 0.5);
        assert!(near(c.lean, [0.5 * 0.25 * 0.2, 0.5 * 0.75 * 0.2]), "{c:?}");
        // In flight both feet are placed in full.
        let c = lean(0.2, [0.0, 0.0], 0.5);
        assert!(near(c.lean, [0.1, 0.1]), "{c:?}");
        // Leaning back, or the gain off: nothing, exactly.
        assert_eq!(lean(-0.15, [0.0, 60.0], 0.5).lean, [0.0; 2]);
        assert_eq!(lean(0.2, [0.0, 60.0], 0.0).lean, [0.0; 2]);
    }

    /// The gauge follows each step's landed-over-aimed reading by its share,
    /// skips readings outside its range (a foot landing behind, a stumble),
    /// never aims longer than the plan nor shorter than 70 % of it, and
    /// counts a touchdown only after a foot has been off the ground for
    /// three cycles.
    #[test]
    fn the_step_gauge_aims_short_by_the_overreach_it_reads() {
        use super::{StepGauge, PACE_MIN};
        let mut g = StepGauge::new(0.3, 0.0);
        assert_eq!(g.pace(), 1.0);
        for _ in 0..40 {
            g.fold(0.088, 0.080);
        }
        assert!((g.pace() - 1.0 / 1.1).abs() < 1e-4, "{}", g.pace());
        assert_eq!(g.readings(), 40);
        // A foot behind the other, a reading past twice the aim, an aim of
        // nothing and a NaN: skipped.
        let before = g.pace();
        for (landed, aimed) in [(-0.01, 0.08), (0.2, 0.08), (0.08, 0.0), (f64::NAN, 0.08)] {
            g.fold(landed, aimed);
        }
        assert_eq!((g.pace(), g.readings()), (before, 40));
        // Short landings bring the pace back to the plan's, never past it.
        for _ in 0..40 {
            g.fold(0.06, 0.08);
        }
        assert_eq!(g.pace(), 1.0);
        // Far overreach is aimed at most 30 % short.
        for _ in 0..40 {
            g.fold(0.15, 0.08);
        }
        assert_eq!(g.pace(), PACE_MIN);
        // Touchdowns, from the sensed loads.
        let mut g = StepGauge::new(0.3, 0.0);
        let mut p = still([0.0, 0.0, 9.81], [0.0; 2]);
        let mut load = |g: &mut StepGauge, left: f64, right: f64| {
            p.foot_force_n[0][2] = left;
            p.foot_force_n[1][2] = right;
            g.touchdown(&p)
        };
        assert_eq!(load(&mut g, 30.0, 30.0), None);
        // The right foot lifts for two cycles (a bounce) and lands: none.
        assert_eq!(load(&mut g, 60.0, 2.0), None);
        assert_eq!(load(&mut g, 60.0, 2.0), None);
        assert_eq!(load(&mut g, 40.0, 20.0), None);
        // For three: a touchdown of the right foot.
        for _ in 0..3 {
            assert_eq!(load(&mut g, 60.0, 0.0), None);
        }
        assert_eq!(load(&mut g, 45.0, 15.0), Some(1));
        assert_eq!(load(&mut g, 45.0, 15.0), None);
    }

    /// The feedback is what keeps the fast walk going on the farm's default
    /// physics (2 × 10 ms): without it the expert set falls more or walks
    /// clearly shorter (0.15 m is five standard errors of 20 trials' mean).
    /// On the band of fine steps it is not (`scripts/feedback.py`;
    /// docs/walk.md, "Is the feedback load-bearing on the band?").
    #[test]
    fn the_feedback_is_used() {
        the_expert_falls_or_walks_shorter_without_feedback(
            &ParamValues::default(),
            SimSettings::default(),
            (3, 20),
        );
    }

    /// The arms file at 4 × 5 ms (docs/walk.md, "Where the walks keep each
    /// bound").
    const ARMS_5MS_FILE: &str =
        include_str!("../../../experiments/physical-technical-arms-5ms.toml");

    /// The converged file: 10 × 2 ms steps, no double support.
    const CONVERGED_FILE: &str =
        include_str!("../../../experiments/physical-technical-converged.toml");

    /// The converged file with the step period co-optimised.
    const PERIOD_FILE: &str =
        include_str!("../../../experiments/physical-technical-converged-period.toml");

    /// The step period file at 1 ms physics steps.
    const PERIOD_1MS_FILE: &str =
        include_str!("../../../experiments/physical-technical-converged-period-1ms.toml");

    /// The step period file with each trial's physics step drawn from a band.
    const PERIOD_BAND_FILE: &str =
        include_str!("../../../experiments/physical-technical-converged-period-band.toml");

    /// Experiment 1 on the band with the steps aimed short.
    const BAND_AIM_FILE: &str =
        include_str!("../../../experiments/physical-converged-band-aim.toml");

    /// Experiment 1 on the roll file with its steps aimed.
    const EXP1_ROLL_AIM_FILE: &str =
        include_str!("../../../experiments/physical-arms-5ms-roll-aim.toml");

    /// The feedback carries the arms walk at 4 × 5 ms, the file whose
    /// experiment 2 walks 6 m as planned (docs/walk.md, "Where the walks
    /// keep each bound"): without it the expert walks clearly shorter.
    /// Measured, 20 trials from seed 3: 4.23 m with it, 4.01 m without, s 1.00
    /// both (100 from 777: 4.254 and 4.05 m; seed 1's optima 5.914 → 5.57 m
    /// and 5.667 → 5.28 m).
    #[test]
    fn the_feedback_carries_the_arms_walk_at_5ms() {
        let (_, physics, expert) = shipped(ARMS_5MS_FILE);
        the_expert_falls_or_walks_shorter_without_feedback(&expert, physics, (3, 20));
    }

    /// The feedback carries the arms walk at 4 × 5 ms with the stance hip's
    /// roll at 0.09 rad too (docs/walk.md, "The engine's constants at 4 ×
    /// 5 ms"), by less: over the 100 trials of Table IV (seeds 777–876) the
    /// expert walks 4.276 m, s 1.00, with it and 4.089 m, s 0.96, without.
    /// 20 trials from seed 3 cannot tell (4.147 and 4.092 m), so this test
    /// takes the 100. Seed 1's Optim.1 of the file: 6.046 → 5.515 m (40
    /// trials).
    #[test]
    #[ignore = "long: a superseded 4 × 5 ms file's claim (`cargo test --workspace -- --ignored nao::balance`)"]
    fn the_feedback_carries_the_arms_walk_at_5ms_with_the_wider_hip_roll() {
        let (_, physics, expert) = shipped(ROLL_FILE);
        the_expert_falls_or_walks_shorter_without_feedback(&expert, physics, (777, 100));
    }

    /// The arms walk at 4 × 5 ms keeps its bits: the one walk whose every
    /// part of the vendored rapier is at work (26 degrees of freedom on four
    /// branches, the firm stops' rows, four substeps), so a change there
    /// that is meant to keep the bits is checked here as well as by the
    /// open loop's pins. The values were read off `naofarm trial
    /// --experiment experiments/physical-technical-arms-5ms.toml --seed 11
    /// --trials 2 --json` built at 247508b, before session 34's cuts of the
    /// multibody's work.
    #[test]
    fn the_arms_walk_at_5ms_keeps_its_bits() {
        let (_, physics, expert) = shipped(ARMS_5MS_FILE);
        for (seed, x, y) in [
            (11, 4.458_668_231_964_111, 0.021_067_418_158_054_352),
            (12, 3.977_905_511_856_079, -0.289_411_365_985_870_36),
        ] {
            let t = run(0, &expert, seed, 10.0, physics, closed()).unwrap();
            assert_eq!(t.measurement.x_m.to_bits(), f64::to_bits(x), "seed {seed}");
            assert_eq!(t.measurement.y_m.to_bits(), f64::to_bits(y), "seed {seed}");
        }
    }

    /// Asserts that `params` with `physics`, `n` trials from `seed0`, stands
    /// in more than a fifth fewer of them without the closed loop's
    /// feedback, or walks more than 0.15 m shorter.
    fn the_expert_falls_or_walks_shorter_without_feedback(
        params: &ParamValues,
        physics: SimSettings,
        (seed0, n): (u64, u64),
    ) {
        let go = |engine: Engine| {
            let ts = run_many(
                0,
                params,
                Batch {
                    seed0,
                    n,
                    threads: 2,
                },
                10.0,
                physics,
                engine,
            )
            .unwrap();
            summary(&ts)
        };
        let (s, mx, _) = go(closed());
        let off = Engine {
            feedback: None,
            ..closed()
        };
        let (s_off, mx_off, _) = go(off);
        println!("with feedback s {s} mx {mx:.3}, without s {s_off} mx {mx_off:.3}");
        assert!(
            s_off < s - 0.2 || mx_off < mx - 0.15,
            "with feedback s {s} mx {mx}, without s {s_off} mx {mx_off}"
        );
    }

    #[test]
    fn same_seed_same_bits_and_a_walk_of_its_own() {
        let p = ParamValues::default();
        let d = SimSettings::default();
        let a = run(0, &p, 11, 3.0, d, closed()).unwrap();
        let b = run(0, &p, 11, 3.0, d, closed()).unwrap();
        assert_eq!(a.measurement.x_m.to_bits(), b.measurement.x_m.to_bits());
        assert_eq!(a.measurement.y_m.to_bits(), b.measurement.y_m.to_bits());
        let c = run(0, &p, 12, 3.0, d, closed()).unwrap();
        assert_ne!(a.measurement.x_m.to_bits(), c.measurement.x_m.to_bits());
        let open = run(0, &p, 11, 3.0, d, Engine::of(WalkEngine::OpenLoop)).unwrap();
        assert_ne!(a.measurement.x_m.to_bits(), open.measurement.x_m.to_bits());
    }

    /// The worst excess over its stops during one trial with physics
    /// `settings`: of the hip yaw-pitch joints (`le1`) and of every other
    /// joint, in degrees, each with where.
    fn worst_excess(params: &ParamValues, seed: u64, settings: SimSettings) -> [(f64, String); 2] {
        let t = run(0, params, seed, 10.0, settings, closed()).unwrap();
        [true, false].map(|yaw_pitch| {
            t.stop_excess
                .iter()
                .filter(|e| e.joint.ends_with("le1") == yaw_pitch)
                .max_by(|a, b| a.rad.total_cmp(&b.rad))
                .map_or((0.0, String::new()), |e| {
                    (
                        e.rad.to_degrees(),
                        format!("{} at {:.2} s", e.joint, e.time_s),
                    )
                })
        })
    }

    /// An experiment file, parsed.
    fn experiment(toml: &str) -> protocol::Experiment {
        protocol::Experiment::from_toml(toml).unwrap()
    }

    /// A shipped experiment file: parsed, its physics and its expert set
    /// (with its fixed values).
    fn shipped(toml: &str) -> (protocol::Experiment, SimSettings, ParamValues) {
        let exp = experiment(toml);
        let physics = SimSettings::with_physics(&exp.physics);
        let expert = expert_of(&exp);
        (exp, physics, expert)
    }

    /// A set a run of `exp` found, `found` naming every parameter of the
    /// file in its order, checked inside L, with the file's fixed values: as
    /// a worker gets it.
    fn found_in(exp: &protocol::Experiment, found: &[(&str, f64)]) -> ParamValues {
        let names: Vec<&str> = exp.parameter.iter().map(|p| p.name.as_str()).collect();
        let given: Vec<&str> = found.iter().map(|(n, _)| *n).collect();
        assert_eq!(names, given, "the file's parameters, in order");
        let values: Vec<f64> = found.iter().map(|(_, v)| *v).collect();
        exp.check_in_space(&values).unwrap();
        ParamValues::from_named(&exp.full_params(&values)).unwrap()
    }

    /// `exp`'s expert set with its fixed values, as a worker gets it.
    fn expert_of(exp: &protocol::Experiment) -> ParamValues {
        ParamValues::from_named(&exp.full_params(&exp.expert_values())).unwrap()
    }

    /// `exp`'s L at its corners (those with the shortest steps only, or all
    /// 32) and its centre, each as every value a worker gets (fixed ones too).
    fn corners_of_l(exp: &protocol::Experiment, all: bool) -> Vec<Vec<(String, f64)>> {
        let l = &exp.parameter;
        let short = l.iter().position(|p| p.name == "xlength_step_max").unwrap();
        let mut sets: Vec<Vec<f64>> = (0..1u32 << l.len())
            .filter(|corner| all || corner >> short & 1 == 0)
            .map(|corner| {
                l.iter()
                    .enumerate()
                    .map(|(i, p)| {
                        if corner >> i & 1 == 1 {
                            p.upper
                        } else {
                            p.lower
                        }
                    })
                    .collect()
            })
            .collect();
        sets.push(l.iter().map(|p| (p.lower + p.upper) / 2.0).collect());
        sets.iter().map(|v| exp.full_params(v)).collect()
    }

    const EXPERIMENT_2: &str = include_str!("../../../experiments/physical-technical.toml");

    /// At the farm's physics (2 × 10 ms) every joint but the hip yaw-pitch
    /// stays within 1° of its stops on the expert set and within 2.5° over
    /// the 16 corners of experiment 2's L with its shortest steps and its
    /// centre; the hip yaw-pitch within 2° and 4°. The issue's bounds (1°,
    /// 2° over all of L) are not met at 10 ms: the deepest-crouch,
    /// highest-lift corner takes its left ankle roll 2.26° past its stop, the
    /// hip yaw-pitch of the landing leg yields into its stop by 1.2–1.7° at
    /// every step (1.2–1.4° with the feedback off), and L's corners with
    /// 0.15 m steps overrun by up to 8° as they fall. Rapier engages a limit
    /// row only once the joint is past the stop, and its PGS does not hold the
    /// row against a landing within a 10 ms step: with 2 ms steps every bound
    /// holds (the next test). `docs/walk.md` has the measurements.
    #[test]
    fn joints_stay_near_their_stops_on_the_expert_set_and_the_short_step_half_of_l() {
        let farm = SimSettings::default();
        let [yp, other] = worst_excess(&ParamValues::default(), 3, farm);
        assert!(other.0 <= 1.0, "expert: {:.2}° {}", other.0, other.1);
        assert!(yp.0 <= 2.0, "expert: {:.2}° {}", yp.0, yp.1);
        let sets = corners_of_l(&experiment(EXPERIMENT_2), false);
        assert_eq!(sets.len(), 17);
        let (mut worst_yp, mut worst_other) = (0.0f64, 0.0f64);
        for named in &sets {
            let p = ParamValues::from_named(named).unwrap();
            let [yp, other] = worst_excess(&p, 1, farm);
            worst_yp = worst_yp.max(yp.0);
            worst_other = worst_other.max(other.0);
            assert!(other.0 <= 2.5, "{named:?}: {:.2}° {}", other.0, other.1);
            assert!(
                yp.0 <= 4.0,
                "{named:?}: hip yaw-pitch {:.2}° {}",
                yp.0,
                yp.1
            );
        }
        println!("over L: hip yaw-pitch {worst_yp:.2}°, others {worst_other:.2}°");
    }

    /// The overruns are the 10 ms physics step's: with 2 ms steps (10 per
    /// cycle) every joint, the hip yaw-pitch too, keeps the issue's bounds —
    /// within 1° of its stops on the expert set (five seeds) and within 2°
    /// over all 32 corners of experiment 2's L and its centre, long steps
    /// and falls included (measured: 1.03° at worst; at 10 ms up to 7.9°).
    #[test]
    fn with_two_millisecond_steps_every_joint_keeps_the_bounds_over_all_of_l() {
        let fine = SimSettings {
            substeps: 10,
            ..SimSettings::default()
        };
        for seed in 1..=5 {
            for (deg, at) in worst_excess(&ParamValues::default(), seed, fine) {
                assert!(deg <= 1.0, "expert, seed {seed}: {deg:.2}° {at}");
            }
        }
        let sets = corners_of_l(&experiment(EXPERIMENT_2), true);
        assert_eq!(sets.len(), 33);
        for named in &sets {
            let p = ParamValues::from_named(named).unwrap();
            for (deg, at) in worst_excess(&p, 1, fine) {
                assert!(deg <= 2.0, "{named:?}: {deg:.2}° {at}");
            }
        }
    }

    /// The shipped converged configuration
    /// (`experiments/physical-technical-converged.toml`: 10 × 2 ms steps, no
    /// double support, set in the file) keeps every bound of the pace issue
    /// but its 6.0 m: the expert set walks ≥ 4.0 m with s ≥ 0.7, straight and
    /// within 10 % of its planned steps (measured over 100 trials: 4.236 m,
    /// s 1.00), every joint within 1° of its stops on it and within 2° over
    /// the file's L (its 32 corners and centre; measured: 0.95° at worst).
    #[test]
    #[ignore = "long: an older file's claim, pinned by the_older_files_claims_keep_their_bits (`cargo test --workspace -- --ignored nao::balance`)"]
    fn the_converged_experiment_walks_at_pace_within_the_stops() {
        let (exp, physics, expert) = shipped(CONVERGED_FILE);
        let (_, s, mx, planned) = walks_at_pace_within_the_stops(&expert, 30, physics);
        let sets = corners_of_l(&exp, true);
        assert_eq!(sets.len(), 33);
        let over_l = within_two_degrees_over(&sets, physics);
        println!("expert: s {s:.2}, mx {mx:.3} m (planned {planned:.3}); over L: {over_l:.2}°");
    }

    /// The shipped stiff configuration (`experiments/physical-technical-stiff.toml`:
    /// the farm's 2 × 10 ms steps with 32 PGS iterations, the engine retuned
    /// by its fixed values) keeps the expert set at the pace issue's walk
    /// (s ≥ 0.7, ≥ 4.0 m, straight, within 10 % of its plan) with every
    /// joint within 1° of its stops (measured over 100 trials: 4.194 m,
    /// s 0.95, 0.33° at worst). The solve is what holds them: the same walk
    /// with the default 12 iterations takes a joint past 1° in these trials.
    #[test]
    fn the_stiff_experiment_keeps_the_experts_stops_at_the_farms_step() {
        let (exp, physics, expert) = shipped(include_str!(
            "../../../experiments/physical-technical-stiff.toml"
        ));
        assert_eq!(exp.physics.substeps, protocol::Physics::default().substeps);
        let worst = |ts: &[NaoTrial]| {
            ts.iter()
                .flat_map(|t| t.stop_excess.iter().map(|e| e.rad.to_degrees()))
                .fold(0.0, f64::max)
        };
        let (ts, s, mx, planned) = walks_at_pace_as_planned(&expert, 30, physics);
        assert!(worst(&ts) <= 1.0, "expert: {:.2}°", worst(&ts));
        let loose = SimSettings {
            pgs_iterations: SimSettings::default().pgs_iterations,
            ..physics
        };
        let at_12 = from_777(&expert, 30, loose);
        assert!(worst(&at_12) > 1.0, "12 iterations: {:.2}°", worst(&at_12));
        println!(
            "expert: s {s:.2}, mx {mx:.3} m (planned {planned:.3}), {:.2}° (12 iterations: {:.2}°)",
            worst(&ts),
            worst(&at_12)
        );
    }

    /// The arms file (`experiments/physical-technical-arms.toml`: the firm
    /// physics with the arms swinging and the engine retuned for them) walks
    /// its expert set at pace as planned within 1° of every stop, and the
    /// arms are what hold it: with them still (`arm_swing` 0, welded) every
    /// trial falls (measured over seeds 777–806: s 1.00, 4.446 m of 4.631 m
    /// planned, 0.17° at worst; still, s 0).
    #[test]
    fn the_arms_experiment_walks_its_expert_at_pace_and_falls_with_its_arms_still() {
        let (_, physics, expert) = shipped(include_str!(
            "../../../experiments/physical-technical-arms.toml"
        ));
        walks_at_pace_within_the_stops(&expert, 30, physics);
        let mut still = expert;
        still.set(protocol::params::Param::ArmSwing, 0.0).unwrap();
        let ts = from_777(&still, 10, physics);
        assert!(ts.iter().all(|t| t.measurement.fell), "a trial stood");
    }

    /// Placing the feet against the torso's sensed turn (`turn_place`) keeps
    /// a fast walk to its plan: the arms file's experiment-2 Optim.2 body
    /// (seed 1, session 23) walks beyond its planned steps by more than 12 %
    /// with the feet placed in the torso's frame, as the turn lengthens each
    /// step, and within 10 % with them placed in the walk's (measured, seeds
    /// 777–796: s 1.00 and 6.033 m, 1.14 × the plan's 5.288 m; s 1.00 and
    /// 5.779 m, 1.09 ×).
    #[test]
    fn placing_the_feet_against_the_turn_keeps_a_fast_walk_to_its_plan() {
        let (_, physics, expert) = shipped(include_str!(
            "../../../experiments/physical-technical-arms.toml"
        ));
        let mut p = with_values(expert, &ARMS_OPTIM2);
        let (in_torso, planned) = twenty_from_777(&p, physics);
        p.set(protocol::params::Param::TurnPlace, 1.0).unwrap();
        let (in_walk, _) = twenty_from_777(&p, physics);
        println!("planned {planned:.3} m; torso's frame {in_torso:?}; walk's {in_walk:?}");
        assert!(in_torso.1 > 1.12 * planned, "torso's frame: {in_torso:?}");
        assert!(in_walk.0 >= 0.9, "walk's frame: {in_walk:?}");
        assert!(
            (in_walk.1 - planned).abs() <= 0.1 * planned,
            "walk's frame: {in_walk:?}"
        );
    }

    /// The arms file's experiment-2 Optim.2 at seed 1 (session 23's run).
    const ARMS_OPTIM2: [(&str, f64); 5] = [
        ("ThighRelHip2_Z", -0.0707),
        ("ratio_flexion", 0.7265),
        ("long_offset_MidAnkles_2_Torso_Init", 0.0120),
        ("height_lift", 0.0371),
        ("xlength_step_max", 0.0914),
    ];

    /// `p` with these values, by name.
    fn with_values(mut p: ParamValues, values: &[(&str, f64)]) -> ParamValues {
        for (name, v) in values {
            p.set(protocol::params::find(name).unwrap().param, *v)
                .unwrap();
        }
        p
    }

    /// 20 trials of `p` from seed 777 with `physics`: (s, mx, my) and the
    /// plan's travel, m.
    fn twenty_from_777(p: &ParamValues, physics: SimSettings) -> ((f64, f64, f64), f64) {
        let walked = summary(&from_777(p, 20, physics));
        let planned = trial::planned_travel_m(0, p, 10.0, closed()).unwrap();
        (walked, planned)
    }

    /// Arm swing steadies a fast walk that pivots about its stance foot
    /// (docs/walk.md, "The torso's yaw"): the firm file's experiment-2
    /// Optim.1 body at 0.15 s steps of 0.07 m falls in every trial with the
    /// arms still (welded, as trials keep them) and stands in at least 9 of
    /// 10 with the arms swinging 0.3 rad per step length (measured: s 0 and
    /// 1.0, seeds 3–12; 0.2 and 0.4 rad stand in 7 of 10, the head welded),
    /// its shoulders then moving against the legs.
    #[test]
    fn swinging_arms_steady_a_fast_walk_that_falls_without_them() {
        let (_, physics, expert) = shipped(include_str!(
            "../../../experiments/physical-technical-firm.toml"
        ));
        let p = with_values(
            expert,
            &[
                ("ThighRelHip2_Z", -0.0798),
                ("ratio_flexion", 0.8213),
                ("long_offset_MidAnkles_2_Torso_Init", 0.011),
                ("height_lift", 0.0525),
                ("step_period", 0.15),
                ("xlength_step_max", 0.07),
            ],
        );
        let batch = Batch {
            seed0: 3,
            n: 10,
            threads: 2,
        };
        let engine = closed().with("arm_swing_rad", "0.3").unwrap();
        let still = run_many(0, &p, batch, 10.0, physics, closed()).unwrap();
        let swung = run_many(0, &p, batch, 10.0, physics, engine).unwrap();
        let stood = |ts: &[NaoTrial]| ts.iter().filter(|t| !t.measurement.fell).count();
        assert_eq!(stood(&still), 0);
        assert!(stood(&swung) >= 9, "{} of 10 stood", stood(&swung));
        let model = crate::nao::model::NaoModel::with_params(0, &p).unwrap();
        let (l, r) = (
            model.joint_index("lae1").unwrap(),
            model.joint_index("rae1").unwrap(),
        );
        let rest = crate::nao::sim::standing_angles(&model);
        let mut opposed = 0;
        trial::run_observed(0, &p, 3, 2.0, physics, engine, &mut |_, s, _| {
            let (a, b) = (
                s.joint_angles_rad[l] - rest[l],
                s.joint_angles_rad[r] - rest[r],
            );
            if a * b < 0.0 && a.abs().min(b.abs()) > 0.05 {
                opposed += 1;
            }
        })
        .unwrap();
        assert!(opposed >= 30, "arms opposed in {opposed} of 100 cycles");
    }

    /// The shipped firm configuration (`experiments/physical-technical-firm.toml`:
    /// the farm's 2 × 10 ms steps, 28 PGS iterations, the ground at 60 Hz and
    /// `firm_stops`) keeps the pace issue's stop bounds at the farm's step:
    /// the expert set walks at pace as planned with every joint within 1° of
    /// its stops, and every joint stays within 2° over the file's L (its 32
    /// corners and centre, falls included; measured: 1.32° at worst over
    /// seeds 1–3, against 5.11° with the same file's stops left to rapier).
    /// The stops are what hold them: without them L passes 2° in these trials.
    #[test]
    fn the_firm_experiment_keeps_every_stop_bound_at_the_farms_step() {
        let (exp, physics, expert) = shipped(include_str!(
            "../../../experiments/physical-technical-firm.toml"
        ));
        assert_eq!(exp.physics.substeps, protocol::Physics::default().substeps);
        assert!(exp.physics.firm_stops);
        let (_, s, mx, planned) = walks_at_pace_within_the_stops(&expert, 30, physics);
        let sets = corners_of_l(&exp, true);
        assert_eq!(sets.len(), 33);
        let firm = within_two_degrees_over(&sets, physics);
        let rapiers = worst(&worst_over(
            &sets,
            SimSettings {
                firm_stops: false,
                ..physics
            },
        ));
        assert!(rapiers > 2.0, "rapier's stops: {rapiers:.2}°");
        println!(
            "expert: s {s:.2}, mx {mx:.3} m (planned {planned:.3}); over L: {firm:.2}° (rapier's stops: {rapiers:.2}°)"
        );
    }

    /// Each set's worst overrun of any stop, degrees, in one trial (seed 1).
    fn worst_over(
        sets: &[Vec<(String, f64)>],
        settings: SimSettings,
    ) -> Vec<(f64, Vec<(String, f64)>)> {
        trial::in_parallel(sets.len() as u64, 2, |i| {
            let named = &sets[i as usize];
            let p = ParamValues::from_named(named).unwrap();
            let t = run(0, &p, 1, 10.0, settings, closed()).unwrap();
            let worst = t
                .stop_excess
                .iter()
                .map(|e| e.rad.to_degrees())
                .fold(0.0, f64::max);
            (worst, named.clone())
        })
        .unwrap()
    }

    fn worst(r: &[(f64, Vec<(String, f64)>)]) -> f64 {
        r.iter().map(|(d, _)| *d).fold(0.0, f64::max)
    }

    /// [`worst_over`], with every set within 2° of its stops (the pace
    /// issue's bound over L); the worst, degrees.
    fn within_two_degrees_over(sets: &[Vec<(String, f64)>], settings: SimSettings) -> f64 {
        let over = worst_over(sets, settings);
        for (deg, named) in &over {
            assert!(*deg <= 2.0, "{named:?}: {deg:.2}°");
        }
        worst(&over)
    }

    /// The arms file's faster walk keeps L's stop bound with its 8° stop
    /// window (`firm_stop_window_deg`): every joint within 2° of its stops
    /// over the file's 32 corners and centre (measured: 1.22° at worst at
    /// seed 1, 1.28° over seeds 1–5), where the firm file's 3° window lets
    /// a corner pass 2° (2.51°, an ankle pitch in a fall): joints that come
    /// at a stop faster than 3° a step pass it before their row is in place.
    #[test]
    fn the_arms_experiment_keeps_l_within_its_stops_with_its_stop_window() {
        let (exp, physics, _) = shipped(include_str!(
            "../../../experiments/physical-technical-arms.toml"
        ));
        assert_eq!(physics.firm_stop_window_deg, 8.0);
        let sets = corners_of_l(&exp, true);
        assert_eq!(sets.len(), 33);
        let window = within_two_degrees_over(&sets, physics);
        let narrow = worst(&worst_over(
            &sets,
            SimSettings {
                firm_stop_window_deg: 3.0,
                ..physics
            },
        ));
        assert!(narrow > 2.0, "3° window: {narrow:.2}°");
        println!("over L: {window:.2}° (a 3° window: {narrow:.2}°)");
    }

    /// The arms file at 4 × 5 ms (`experiments/physical-technical-arms-5ms.toml`)
    /// walks its plan: its expert at pace as planned within 1° of every
    /// stop, L within 2° of its stops, and session 23's experiment-2 optimum
    /// (seed 1's Optim.2, which goes 1.14 × its plan at 2 × 10 ms:
    /// `placing_the_feet_against_the_turn_keeps_a_fast_walk_to_its_plan`)
    /// within 5 % of its plan. Measured: the expert s 1.00, 4.254 m of
    /// 4.631 m planned over 100 trials, within 0.02°; L 0.20° at worst;
    /// the optimum s 1.00, 5.358 m of 5.288 m planned (seeds 777–796).
    #[test]
    #[ignore = "long: an older file's claim, pinned by the_older_files_claims_keep_their_bits (`cargo test --workspace -- --ignored nao::balance`)"]
    fn the_arms_experiment_at_5ms_walks_its_plan_and_keeps_its_stops() {
        let (exp, physics, expert) = shipped(ARMS_5MS_FILE);
        assert_eq!(physics.substeps, 4);
        walks_at_pace_within_the_stops(&expert, 30, physics);
        let window = within_two_degrees_over(&corners_of_l(&exp, true), physics);
        let ((s, mx, _), planned) = twenty_from_777(&with_values(expert, &ARMS_OPTIM2), physics);
        println!("L {window:.2}°; optimum s {s}, {mx:.3} m of {planned:.3} m");
        assert!(s >= 0.9, "s {s}");
        assert!(
            (mx - planned).abs() <= 0.05 * planned,
            "{mx} m of {planned} m"
        );
    }

    /// `exp`'s expert at pace as planned within 1° of every stop (30 trials),
    /// L's corners and centre within 2° of theirs, and `optim1`, a set a run
    /// of `exp` found (every parameter, in the file's order), over the 100
    /// trials of Table IV at s ≥ 0.9 and ≥ 6.0 m, within 10 % of its plan
    /// and 1° of every stop.
    fn keeps_the_stops_and_walks_six_metres(
        exp: &protocol::Experiment,
        physics: SimSettings,
        expert: &ParamValues,
        optim1: &[(&str, f64)],
    ) {
        walks_at_pace_within_the_stops(expert, 30, physics);
        let window = within_two_degrees_over(&corners_of_l(exp, true), physics);
        let optim1 = found_in(exp, optim1);
        let (_, s, mx, planned) = walks_at_pace_within_the_stops(&optim1, 100, physics);
        println!("L {window:.2}°; Optim.1: s {s}, {mx:.3} m of {planned:.3} m");
        assert!(s >= 0.9 && mx >= 6.0, "s {s}, {mx} m");
    }

    /// The arms file at 4 × 5 ms with the stance hip's roll at 0.09 rad
    /// (`experiments/physical-technical-arms-5ms-roll.toml`; docs/walk.md,
    /// "The engine's constants at 4 × 5 ms") keeps the stops and finds the
    /// 6 m at seed 1, where the 0.07 rad file's best stopped at 5.914 m: the
    /// expert at pace as planned within 1° of every stop (30 trials), L's
    /// corners and centre within 2°, and seed 1's Optim.1 (session 35's run)
    /// over the 100 trials of Table IV at s ≥ 0.9 and ≥ 6.0 m, within 10 % of
    /// its plan and 1° of every stop. Measured: L 0.30° at worst over seeds
    /// 1–3 (`scripts/stops.py`); the optimum s 0.98, 6.034 m of 6.167 m
    /// planned, 0.05° at worst.
    #[test]
    #[ignore = "long: a superseded 4 × 5 ms file's claim (`cargo test --workspace -- --ignored nao::balance`)"]
    fn the_wider_hip_roll_at_5ms_keeps_the_stops_and_finds_six_metres_at_seed_1() {
        let (exp, physics, expert) = shipped(ROLL_FILE);
        assert_eq!(
            (physics.substeps, expert.given(Param::HipRollComp)),
            (4, Some(0.09))
        );
        keeps_the_stops_and_walks_six_metres(&exp, physics, &expert, &ROLL_SEED1_OPTIM1);
    }

    /// Seed 1's Optim.1 of experiment 1 on the roll file with its steps
    /// aimed (session 36's run).
    const EXP1_ROLL_AIM_OPTIM1: [(&str, f64); 1] = [("ThighRelHip2_Z", -0.09917141208691056)];

    /// The roll file with its steps aimed short by the legs' overreach
    /// (`experiments/physical-arms-5ms-roll-aim.toml`; docs/walk.md, "The
    /// roll file with its steps aimed") walks experiment 1's optimum as
    /// planned: seed 1's Optim.1 (session 36's run, a thigh longer than
    /// experiment 2's L allows) over 40 trials at s ≥ 0.9 within 10 % of its
    /// plan and 1° of every stop, where without the aim the same body walks
    /// more than 10 % beyond it. Measured: 4.873 m of 4.630 m planned (1.05
    /// ×) with the aim, 5.413 m (1.17 ×) without.
    #[test]
    #[ignore = "long: an older file's claim, pinned by the_older_files_claims_keep_their_bits (`cargo test --workspace -- --ignored nao::balance`)"]
    fn the_aimed_roll_file_walks_experiment_ones_optimum_as_planned() {
        let (exp, physics, expert) = shipped(EXP1_ROLL_AIM_FILE);
        assert_eq!(
            (
                expert.given(Param::StepAim),
                expert.given(Param::HipRollComp)
            ),
            (Some(0.3), Some(0.09))
        );
        let optim1 = found_in(&exp, &EXP1_ROLL_AIM_OPTIM1);
        let (_, s, mx, planned) = walks_at_pace_within_the_stops(&optim1, 40, physics);
        println!("aimed: s {s}, {mx:.3} m of {planned:.3} m");
        assert!(s >= 0.9, "s {s}");
        let mut unaimed = optim1;
        unaimed.set(Param::StepAim, 0.0).unwrap();
        let (s, mx, _) = summary(&from_777(&unaimed, 40, physics));
        println!("not aimed: s {s}, {mx:.3} m of {planned:.3} m");
        assert!(mx > 1.1 * planned, "{mx} m of {planned} m");
    }

    /// Experiment 2 of the roll file with its steps aimed
    /// (`experiments/physical-technical-arms-5ms-roll-aim.toml`) keeps the
    /// stops and finds the 6 m as planned at seed 1: the expert at pace as
    /// planned within 1° of every stop (30 trials), L's corners and centre
    /// within 2°, and seed 1's Optim.1 (session 36's run) over the 100 trials
    /// of Table IV at s ≥ 0.9 and ≥ 6.0 m, within 10 % of its plan and 1° of
    /// every stop. Measured: L 0.30° at worst over seeds 1–3
    /// (`scripts/stops.py`); the optimum s 0.99, 6.167 m of 6.235 m planned.
    #[test]
    #[ignore = "long: a superseded 4 × 5 ms file's claim (`cargo test --workspace -- --ignored nao::balance`)"]
    fn the_aimed_roll_file_keeps_the_stops_and_finds_six_metres_at_seed_1() {
        let (exp, physics, expert) = shipped(ROLL_AIM_FILE);
        assert_eq!(expert.given(Param::StepAim), Some(0.3));
        keeps_the_stops_and_walks_six_metres(&exp, physics, &expert, &ROLL_AIM_SEED1_OPTIM1);
    }

    /// A torso leaning forward steps ahead
    /// (`experiments/physical-technical-arms-5ms-roll-aim-lean.toml`): the
    /// roll-aim file's Optim.1 of experiment 2 at seed 4 (session 51's run)
    /// ended trials 832 and 837 a metre behind its start without a fall, its
    /// torso pitched forward; with the feet placed against the forward lean
    /// both walk beyond 4 m, and so does every trial from 832 to 837.
    /// Measured (100 trials from 777): 5.889 m, 0.88 × its plan, without
    /// the placing; 6.229 m, s 0.98, 0.93 × with it.
    #[test]
    fn a_torso_leaning_forward_steps_ahead_instead_of_back() {
        let (exp, physics, expert) = shipped(LEAN_FILE);
        assert_eq!(expert.given(Param::LeanPlace), Some(0.5));
        let placed = found_in(
            &exp,
            &[
                ("ThighRelHip2_Z", -0.07735889300734732),
                ("ratio_flexion", 0.8447150636006667),
                ("long_offset_MidAnkles_2_Torso_Init", 0.00816911809443738),
                ("height_lift", 0.027425239190586627),
                ("xlength_step_max", 0.11530087198994697),
            ],
        );
        let mut unplaced = placed;
        unplaced.set(Param::LeanPlace, 0.0).unwrap();
        let batch = Batch {
            seed0: 832,
            n: 6,
            threads: 2,
        };
        let walked = |p: &ParamValues| -> Vec<(u64, bool, f64)> {
            run_many(0, p, batch, 10.0, physics, closed())
                .unwrap()
                .iter()
                .map(|t| (t.seed, t.measurement.fell, t.measurement.x_m))
                .collect()
        };
        let before = walked(&unplaced);
        println!("without: {before:?}");
        for (seed, fell, x) in &before {
            if [832, 837].contains(seed) {
                assert!(!fell && *x < -0.5, "seed {seed}: fell {fell}, x {x}");
            }
        }
        let after = walked(&placed);
        println!("with: {after:?}");
        for (seed, fell, x) in &after {
            assert!(!fell && *x > 4.0, "seed {seed}: fell {fell}, x {x}");
        }
    }

    /// Steps beyond the legs' reach march backward (docs/walk.md, "The
    /// lean file's landscape"): the lean file's expert asked for 0.134 m
    /// steps, where its hip pitch swings 0.081 m in a step under its speed
    /// cap, falls out of phase with its plan and ends its trials behind
    /// its start on average, without falling in most; with each planned
    /// step capped at the legs' reach (`step_reach = 1`) every trial walks
    /// forward near its capped plan. Measured (20 trials, seed 3): −0.669
    /// m, s 0.90, without; 4.415 m, s 1.00, 0.94 × its plan, none below
    /// 4.03 m, with.
    #[test]
    fn steps_beyond_the_legs_reach_march_backward_and_the_cap_mends_them() {
        let (_, physics, expert) = shipped(LEAN_FILE);
        let mut long = expert;
        long.set(Param::StepLength, 0.1338).unwrap();
        let batch = Batch {
            seed0: 3,
            n: 8,
            threads: 2,
        };
        let uncapped = run_many(0, &long, batch, 10.0, physics, closed()).unwrap();
        let (s, mx, _) = summary(&uncapped);
        println!("uncapped: s {s}, mx {mx:.3} m");
        assert!(s >= 0.7 && mx < 0.0, "s {s}, mx {mx}");
        let mut capped = long;
        capped.set(Param::StepReach, 1.0).unwrap();
        let planned = trial::planned_travel_m(0, &capped, 10.0, closed()).unwrap();
        let walked = run_many(0, &capped, batch, 10.0, physics, closed()).unwrap();
        let (s, mx, _) = summary(&walked);
        let least = walked
            .iter()
            .map(|t| t.measurement.x_m)
            .fold(f64::INFINITY, f64::min);
        println!("capped: s {s}, mx {mx:.3} m of {planned:.3} m, least {least:.2} m");
        assert_eq!(s, 1.0);
        assert!(least > 3.5, "least {least}");
        assert!((mx / planned - 1.0).abs() <= 0.1, "{mx} of {planned}");
    }

    /// Seed 3's Optim.1 of experiment 2 on the capped lean file (session
    /// 55's run; `docs/results/exp2-arms-5ms-roll-aim-lean-reach-seed3/`).
    const CAPPED_SEED3_OPTIM1: [(&str, f64); 5] = [
        ("ThighRelHip2_Z", -0.07612060971177904),
        ("ratio_flexion", 0.8442214276072637),
        ("long_offset_MidAnkles_2_Torso_Init", 0.0064570387050410655),
        ("height_lift", 0.02511712484569534),
        ("xlength_step_max", 0.123665826694503),
    ];

    /// A stop row set ahead of a flung joint (`[physics]
    /// firm_stop_lookahead`; `experiments/physical-technical-arms-5ms-roll-aim-lean-reach.toml`):
    /// L's corner `10011` (the shortest thigh, the deepest crouch, the
    /// highest lift, 0.15 m steps asked and capped at the legs' reach)
    /// staggers through its trial at seed 3 and flings its right elbow yaw,
    /// a light link, through the file's 8° stop window in one physics step
    /// and past its stop; with one step of look-ahead its row is in place
    /// and every joint keeps within 1°, L's corners and centre within 2°.
    /// The expert's trials are the same to the bit either way. Measured:
    /// 7.23° past without, 0.01° with; L 0.22–0.29° at seeds 1–5; the
    /// expert's 100 trials from 777 hash the same.
    #[test]
    fn a_stop_row_ahead_of_a_flung_joint_keeps_it_at_its_stop() {
        let (exp, physics, expert) = shipped(CAPPED_FILE);
        assert_eq!(physics.firm_stop_lookahead, 1);
        assert_eq!(expert.given(Param::StepReach), Some(1.0));
        let window_alone = SimSettings {
            firm_stop_lookahead: 0,
            ..physics
        };
        let corner = found_in(
            &exp,
            &[
                ("ThighRelHip2_Z", -0.03),
                ("ratio_flexion", 0.60),
                ("long_offset_MidAnkles_2_Torso_Init", 0.001),
                ("height_lift", 0.070),
                ("xlength_step_max", 0.150),
            ],
        );
        let [_, flung] = worst_excess(&corner, 3, window_alone);
        println!("window alone: {:.2}° ({})", flung.0, flung.1);
        assert!(flung.0 > 5.0 && flung.1.starts_with("rae3"), "{flung:?}");
        let held = worst_excess(&corner, 3, physics);
        println!("one step ahead: {held:?}");
        assert!(held.iter().all(|(deg, _)| *deg <= 1.0), "{held:?}");
        let over_l = within_two_degrees_over(&corners_of_l(&exp, true), physics);
        println!("over L: {over_l:.2}°");
        let batch = Batch {
            seed0: 777,
            n: 10,
            threads: 2,
        };
        let ahead = run_many(0, &expert, batch, 10.0, physics, closed()).unwrap();
        let alone = run_many(0, &expert, batch, 10.0, window_alone, closed()).unwrap();
        for (a, b) in ahead.iter().zip(&alone) {
            let bits = |t: &NaoTrial| (t.measurement.x_m.to_bits(), t.measurement.y_m.to_bits());
            assert_eq!(bits(a), bits(b), "seed {}", a.seed);
        }
    }

    /// Experiment 2 of the lean file with its steps capped at the legs'
    /// reach and a stop row ahead of a flung joint
    /// (`experiments/physical-technical-arms-5ms-roll-aim-lean-reach.toml`)
    /// keeps the stops and finds the 6 m as planned at seed 3, the seed
    /// where a staggering corner of L flung an elbow yaw 7.23° past its
    /// stop without the look-ahead: the expert at pace as planned within 1°
    /// of every stop (30 trials), L's corners and centre within 2°, and
    /// seed 3's Optim.1 (session 55's run) over the 100 trials of Table IV
    /// at s ≥ 0.9 and ≥ 6.0 m, within 10 % of its plan and 1° of every
    /// stop. Measured: L 0.22–0.29° at seeds 1–5; the optimum s 0.99, 6.278
    /// m of 6.288 m planned, 0.07° at worst.
    #[test]
    #[ignore = "long: a superseded 4 × 5 ms file's claim (`cargo test --workspace -- --ignored nao::balance`)"]
    fn the_capped_lean_file_keeps_the_stops_and_finds_six_metres_at_seed_3() {
        let (exp, physics, expert) = shipped(CAPPED_FILE);
        keeps_the_stops_and_walks_six_metres(&exp, physics, &expert, &CAPPED_SEED3_OPTIM1);
    }

    /// The capped lean file's fast walk leans on its elbow yaws' swing
    /// (docs/walk.md, "What the look-ahead does not mend"): at 5 ms steps
    /// the elbow yaws the walk holds at 0° swing out against their servos
    /// (up to 57° in seed 3's Optim.1; at 1 ms within 7.4°), and with them
    /// welded (`[physics] weld_elbow_yaws`) that optimum falls where it
    /// stood. Measured over 100 trials from 777: s 0.99 free, 0.64 welded;
    /// here 30 trials: s 1.00 and 0.57.
    #[test]
    fn the_capped_lean_files_optimum_leans_on_its_elbow_yaws_swing() {
        let (exp, physics, _) = shipped(CAPPED_FILE);
        assert!(!physics.weld_elbow_yaws);
        let welded = SimSettings::with_physics(&protocol::Physics {
            weld_elbow_yaws: true,
            ..exp.physics
        });
        // As a walk that swings its arms runs them (`trial::walk_settings`).
        let swinging = |s: SimSettings| SimSettings {
            weld_upper_body: false,
            weld_head: true,
            ..s
        };
        for name in ["lae3", "rae3"] {
            assert!(swinging(welded).welds(name), "{name}");
            assert!(!swinging(physics).welds(name), "{name}");
        }
        for name in ["lae1", "lae2", "rae4"] {
            assert!(!swinging(welded).welds(name), "{name}");
        }
        let optim1 = found_in(&exp, &CAPPED_SEED3_OPTIM1);
        let batch = Batch {
            seed0: 777,
            n: 30,
            threads: 2,
        };
        let (free, _, _) = summary(&run_many(0, &optim1, batch, 10.0, physics, closed()).unwrap());
        let (held, _, _) = summary(&run_many(0, &optim1, batch, 10.0, welded, closed()).unwrap());
        println!("s free {free}, welded {held}");
        assert!(free >= 0.9, "free: s {free}");
        assert!(held <= 0.8, "welded: s {held}");
    }

    /// The roll file: the arms walk at 4 × 5 ms with the stance hip's roll at
    /// 0.09 rad (docs/walk.md, "The engine's constants at 4 × 5 ms").
    const ROLL_FILE: &str =
        include_str!("../../../experiments/physical-technical-arms-5ms-roll.toml");

    /// The roll file with its steps aimed short by the legs' overreach
    /// (docs/walk.md, "The roll file with its steps aimed").
    const ROLL_AIM_FILE: &str =
        include_str!("../../../experiments/physical-technical-arms-5ms-roll-aim.toml");

    /// The roll-aim file with the feet placed against the forward lean
    /// (docs/walk.md, "A torso leaning forward steps ahead").
    const LEAN_FILE: &str =
        include_str!("../../../experiments/physical-technical-arms-5ms-roll-aim-lean.toml");

    /// The lean file with its steps capped at the legs' reach and a stop row
    /// ahead of a flung joint (docs/walk.md, "A stop row ahead of a flung joint").
    const CAPPED_FILE: &str =
        include_str!("../../../experiments/physical-technical-arms-5ms-roll-aim-lean-reach.toml");

    /// The damp file: the capped lean file with the elbow yaws welded and
    /// the roll-rate damper (docs/walk.md, "The sideways rock, damped").
    const DAMP_FILE: &str = include_str!(
        "../../../experiments/physical-technical-arms-5ms-roll-aim-lean-reach-damp.toml"
    );

    /// Seed 1's Optim.1 of experiment 2 on the capped lean file with the
    /// elbow yaws welded (session 55's run;
    /// `docs/results/exp2-arms-5ms-roll-aim-lean-reach-elbows-seed1/`).
    const WELDED_SEED1_OPTIM1: [(&str, f64); 5] = [
        ("ThighRelHip2_Z", -0.07860563286501877),
        ("ratio_flexion", 0.7810806427087718),
        ("long_offset_MidAnkles_2_Torso_Init", 0.0054936534003132455),
        ("height_lift", 0.03215442306363837),
        ("xlength_step_max", 0.1412584678476766),
    ];

    /// The stance hip's roll turned against the gyro's roll rate
    /// (`hip_roll_rate_gain`) stands the fast walk that falls without the
    /// elbow yaws' swing (docs/walk.md, "The sideways rock, damped"): on the
    /// damp file (`experiments/physical-technical-arms-5ms-roll-aim-lean-reach-damp.toml`,
    /// the elbow yaws welded) the welded run's seed-1 optimum falls in more
    /// than a tenth of its trials with the gain at 0 and in at most one of
    /// twenty with the file's 0.05, and walks 6 m. Measured over 100 trials
    /// from 777: s 0.80 and 5.869 m without, 0.98 and 6.086 m with; here 40
    /// trials: 0.825 and 0.975, 6.117 m.
    #[test]
    fn damping_the_sideways_rock_stands_the_welded_fast_walk() {
        let (exp, physics, _) = shipped(DAMP_FILE);
        assert!(physics.weld_elbow_yaws);
        let damped = found_in(&exp, &WELDED_SEED1_OPTIM1);
        assert_eq!(damped.given(Param::HipRollRateGain), Some(0.05));
        let undamped = with_values(damped, &[("hip_roll_rate_gain", 0.0)]);
        let (s_off, mx_off, _) = summary(&from_777(&undamped, 40, physics));
        let (s_on, mx_on, _) = summary(&from_777(&damped, 40, physics));
        println!("without: s {s_off}, {mx_off:.3} m; with: s {s_on}, {mx_on:.3} m");
        assert!(s_off < 0.9, "without: s {s_off}");
        assert!(s_on >= 0.95 && mx_on >= 6.0, "with: s {s_on}, {mx_on} m");
    }

    /// Seed 1's Optim.1 of experiment 2 on the damp file (session 56's run;
    /// `docs/results/exp2-arms-5ms-roll-aim-lean-reach-damp-seed1/`).
    const DAMP_SEED1_OPTIM1: [(&str, f64); 5] = [
        ("ThighRelHip2_Z", -0.07781323544882683),
        ("ratio_flexion", 0.799843850026897),
        ("long_offset_MidAnkles_2_Torso_Init", 0.009787816724626374),
        ("height_lift", 0.028751529610296003),
        ("xlength_step_max", 0.13234894894302937),
    ];

    /// Experiment 2 of the damp file (the capped lean file with the elbow
    /// yaws welded and the roll-rate damper:
    /// `experiments/physical-technical-arms-5ms-roll-aim-lean-reach-damp.toml`)
    /// keeps the stops and finds the 6 m as planned with no walk standing
    /// on the elbow yaws' swing: the expert at pace as planned within 1° of
    /// every stop (30 trials), L's corners and centre within 2°, and seed
    /// 1's Optim.1 (session 56's run) over the 100 trials of Table IV at
    /// s ≥ 0.9 and ≥ 6.0 m, within 10 % of its plan and 1° of every stop.
    /// Measured: L 0.24–0.46° at seeds 1–5; the optimum s 0.91, 6.030 m of
    /// 6.005 m planned, 0.07° at worst.
    #[test]
    #[ignore = "long: a superseded 4 × 5 ms file's claim (`cargo test --workspace -- --ignored nao::balance`)"]
    fn the_damp_file_keeps_the_stops_and_finds_six_metres_with_the_elbow_yaws_welded() {
        let (exp, physics, expert) = shipped(DAMP_FILE);
        assert!(physics.weld_elbow_yaws);
        keeps_the_stops_and_walks_six_metres(&exp, physics, &expert, &DAMP_SEED1_OPTIM1);
    }

    /// The damp file's expert leans on its feedback: without it (every
    /// gain, the roll-rate damper too) it walks clearly shorter. Measured
    /// over 40 trials from 777: 4.502 m with, 4.073 m without.
    #[test]
    #[ignore = "long: a superseded 4 × 5 ms file's claim (`cargo test --workspace -- --ignored nao::balance`)"]
    fn the_damp_files_expert_walks_shorter_without_feedback() {
        let (_, physics, expert) = shipped(DAMP_FILE);
        the_expert_falls_or_walks_shorter_without_feedback(&expert, physics, (777, 40));
    }

    /// The roll-rate damper turns each stance hip's roll against the sensed
    /// roll rate in that leg's share of the load, a foot in the air not at
    /// all; off, it is exactly nothing.
    #[test]
    fn the_roll_rate_damper_turns_the_loaded_hip() {
        use super::{Balance, Gains, GAINS};
        let roll_of = |gain: f64, loads: [f64; 2]| {
            let mut b = Balance::new(Gains {
                hip_roll_rate: gain,
                ..GAINS
            });
            let mut sensed = still([0.0, 0.0, 9.81], loads);
            sensed.gyro_rad_s = [0.5, 0.0, 0.0];
            let c = b.update(&sensed, 0.02);
            [c.legs[0][1], c.legs[1][1]]
        };
        let [l, r] = roll_of(0.05, [300.0, 100.0]);
        assert!((l - 0.05 * 0.5 * 0.75).abs() < 1e-12, "{l}");
        assert!((r - 0.05 * 0.5 * 0.25).abs() < 1e-12, "{r}");
        assert_eq!(roll_of(0.05, [200.0, 0.0])[1], 0.0);
        assert_eq!(roll_of(0.0, [200.0, 200.0]), [0.0, 0.0]);
    }

    /// The gauge's reading along the walk's heading: the feet's spacing by
    /// forward kinematics, turned back by the share `step_aim_heading` of
    /// the torso's sensed turn. Feet standing side by side under a torso
    /// turned left by ψ stand, along the heading, with the left foot behind
    /// by their sideways offset × sin ψ; at no turn the reading is the torso
    /// axis's to the bit, and the share scales the turn.
    #[test]
    fn the_step_gauge_reads_along_the_heading() {
        use super::super::footwork::{ahead, ahead_turned};
        use super::StepGauge;
        let model = crate::nao::model::NaoModel::with_params(0, &ParamValues::default()).unwrap();
        let body = |name: &str| model.body_index(name).unwrap();
        let feet = [body("lfoot"), body("rfoot")];
        let q = vec![0.0; model.joints.len()];
        let g = crate::nao::kinematics::body_motions(
            &model,
            &q,
            &crate::nao::kinematics::Iso::identity(),
        );
        let y = |i: usize| crate::nao::kinematics::moved(&g[i], model.bodies[i].centre)[1];
        let offset = y(feet[0]) - y(feet[1]);
        assert!(offset > 0.05, "{offset}");
        assert!(ahead(&model, feet, 0, &q).abs() < 1e-12);
        let turn = 0.06;
        let left = ahead_turned(&model, feet, 0, &q, turn);
        let right = ahead_turned(&model, feet, 1, &q, turn);
        assert!((left + offset * turn.sin()).abs() < 1e-12, "{left}");
        assert!((right - offset * turn.sin()).abs() < 1e-12, "{right}");
        // A bent leg: the reading at no turn is the torso axis's.
        let mut bent = q.clone();
        let hip = model.joint_index("lle3").unwrap();
        bent[hip] = -0.4;
        assert_eq!(
            ahead_turned(&model, feet, 0, &bent, 0.0).to_bits(),
            ahead(&model, feet, 0, &bent).to_bits()
        );
        assert!(ahead(&model, feet, 0, &bent).abs() > 0.03);
        assert_eq!(StepGauge::new(0.3, 1.0).turn_back(0.05), 0.05);
        assert_eq!(StepGauge::new(0.3, 0.5).turn_back(0.05), 0.025);
        assert_eq!(StepGauge::new(0.3, 0.0).turn_back(0.05), 0.0);
        assert_eq!(StepGauge::new(0.3, 3.0).turn_back(0.05), 0.05);
    }

    /// Experiment 1's twin of the heading file: the damp file's with the
    /// steps read along the walk's heading (docs/walk.md, "Steps read along
    /// the heading").
    const HEADING_EXP1_FILE: &str = include_str!(
        "../../../experiments/physical-arms-5ms-roll-aim-lean-reach-damp-heading.toml"
    );

    /// Experiment 2 of the heading file
    /// (`experiments/physical-technical-arms-5ms-roll-aim-lean-reach-damp-heading.toml`,
    /// the steps read along the walk's heading) keeps the stops and finds
    /// the 6 m at seed 2 as planned: the expert at pace as planned within 1°
    /// of every stop (30 trials), L's corners and centre within 2°, and seed
    /// 2's Optim.1 (session 57's run) over Table IV's 100 trials at s ≥ 0.9
    /// and ≥ 6.0 m, within 10 % of its plan and 1° of every stop. Measured:
    /// L 0.24–0.46° at seeds 1–5; the optimum s 0.90, 6.153 m of 6.135 m
    /// planned, 0.06° at worst. Seeds 1 and 5 stop short (5.949 m at s 0.91,
    /// 5.966 m at s 0.86; docs/walk.md, "Steps read along the heading").
    #[test]
    fn the_heading_file_keeps_the_stops_and_finds_six_metres_at_seed_2() {
        let (exp, physics, expert) = shipped(include_str!(
            "../../../experiments/physical-technical-arms-5ms-roll-aim-lean-reach-damp-heading.toml"
        ));
        assert_eq!(expert.given(Param::StepAimHeading), Some(1.0));
        keeps_the_stops_and_walks_six_metres(
            &exp,
            physics,
            &expert,
            &[
                ("ThighRelHip2_Z", -0.07823385119438615),
                ("ratio_flexion", 0.8166708458192984),
                ("long_offset_MidAnkles_2_Torso_Init", 0.008741266198885343),
                ("height_lift", 0.026155225014924788),
                ("xlength_step_max", 0.12687414020548596),
            ],
        );
    }

    /// Read along the walk's heading, the step gauge keeps experiment 1's
    /// long thigh to its plan: seed 1's Optim.1 of experiment 1 on the damp
    /// file (ThighRelHip2_Z −0.0998) steps more than 8 % past its plan with
    /// the spacing read along the torso's x axis (its torso yaws 3–5° with
    /// each step and reads the feet's sideways offset as spacing short of
    /// the true one), and within 7 % of it read along the heading, standing.
    /// Measured over 100 trials from 777: 1.11 and 1.05 × (5.154 and 4.860 m
    /// of 4.631 m); here 40 trials: 1.106 and 1.052 × (5.119 and 4.870
    /// m), s 1.00 both.
    #[test]
    fn reading_the_steps_along_the_heading_keeps_the_long_thigh_to_its_plan() {
        let (_, physics, torso_axis) = shipped(include_str!(
            "../../../experiments/physical-arms-5ms-roll-aim-lean-reach-damp.toml"
        ));
        let (_, heading_physics, heading) = shipped(HEADING_EXP1_FILE);
        assert_eq!(physics, heading_physics);
        assert_eq!(heading.given(Param::StepAimHeading), Some(1.0));
        assert_eq!(torso_axis.given(Param::StepAimHeading), None);
        let thigh = [("ThighRelHip2_Z", -0.0998)];
        let ratio = |p: &ParamValues| against_plan(&with_values(*p, &thigh), 40, physics);
        let (s_torso, mx_torso, torso) = ratio(&torso_axis);
        let (s_heading, mx_heading, along) = ratio(&heading);
        println!(
            "torso axis: s {s_torso}, {mx_torso:.3} m, {torso:.3} x; \
             heading: s {s_heading}, {mx_heading:.3} m, {along:.3} x"
        );
        assert!(torso > 1.08, "torso axis: {torso}");
        assert!(
            along <= 1.07 && s_heading >= 0.9,
            "heading: {along}, s {s_heading}"
        );
    }

    /// s, mx and mx over the plan's distance of `n` trials of `p` from 777.
    fn against_plan(p: &ParamValues, n: u64, physics: SimSettings) -> (f64, f64, f64) {
        let (s, mx, _) = summary(&from_777(p, n, physics));
        let planned = trial::planned_travel_m(0, p, 10.0, closed()).unwrap();
        (s, mx, mx / planned)
    }

    /// Experiment 2 of the roll-aim file with the feet placed against the
    /// forward lean (`experiments/physical-technical-arms-5ms-roll-aim-lean.toml`)
    /// keeps the stops and finds the 6 m as planned at seed 4, where the
    /// roll-aim file's best walked 5.889 m, 0.88 × its plan: the expert at
    /// pace as planned within 1° of every stop (30 trials), L's corners and
    /// centre within 2°, and seed 4's Optim.1 (session 52's run) over the
    /// 100 trials of Table IV at s ≥ 0.9 and ≥ 6.0 m, within 10 % of its
    /// plan and 1° of every stop. Measured: L 0.28° at worst over seeds 1–3
    /// (`scripts/stops.py`); the optimum s 1.00, 6.270 m of 6.083 m planned,
    /// 0.04° at worst.
    #[test]
    #[ignore = "long: a superseded 4 × 5 ms file's claim (`cargo test --workspace -- --ignored nao::balance`)"]
    fn the_lean_file_keeps_the_stops_and_finds_six_metres_at_seed_4() {
        let (exp, physics, expert) = shipped(LEAN_FILE);
        keeps_the_stops_and_walks_six_metres(&exp, physics, &expert, &LEAN_SEED4_OPTIM1);
    }

    /// Seed 4's Optim.1 of experiment 2 on the arms file at 4 × 5 ms
    /// (session 33's run).
    const ARMS_5MS_SEED4_OPTIM1: [(&str, f64); 5] = [
        ("ThighRelHip2_Z", -0.0783477250442469),
        ("ratio_flexion", 0.7394565582757648),
        ("long_offset_MidAnkles_2_Torso_Init", 0.00518644248710892),
        ("height_lift", 0.025170063800778675),
        ("xlength_step_max", 0.10477865722243142),
    ];

    /// Experiment 2 on the arms file at 4 × 5 ms finds a set that walks the
    /// issue's 6 m as planned: seed 4's Optim.1 (session 33's run), 100
    /// trials from 777, s ≥ 0.9, ≥ 6.0 m, my/mx ≤ 0.25, within 10 % of its
    /// plan and 1° of every stop (measured: s 0.99, 6.028 m of 6.064 m
    /// planned, 0.09° at worst; docs/results.md).
    #[test]
    #[ignore = "long: an older file's claim, pinned by the_older_files_claims_keep_their_bits (`cargo test --workspace -- --ignored nao::balance`)"]
    fn the_arms_at_5ms_find_a_set_that_walks_six_metres_as_planned() {
        let (exp, physics, _) = shipped(ARMS_5MS_FILE);
        let optim1 = found_in(&exp, &ARMS_5MS_SEED4_OPTIM1);
        let (_, s, mx, planned) = walks_at_pace_within_the_stops(&optim1, 100, physics);
        println!("seed 4's Optim.1: s {s}, {mx:.3} m of {planned:.3} m planned");
        assert!(s >= 0.9 && mx >= 6.0, "s {s}, {mx} m");
    }

    /// The walk leans on the league's ankle speed cap: on converged physics
    /// the expert plan asks the ankle pitches for more than 6.14 rad/s, the
    /// servos clamp those commands in a tenth of the cycles or more, and
    /// every clamped joint is a leg joint (the arms and head are welded).
    /// With the ankle pitches' cap doubled the clamping nearly stops and the
    /// robot walks far less (measured: 1.41 m against 4.26 m over these 2
    /// trials; ankles clamped in 20 % of the cycles, and 0–0.1 %):
    /// its ankles lagging their flat-foot targets drive it (docs/walk.md, "The
    /// landscape").
    #[test]
    fn the_walk_leans_on_the_ankle_pitch_speed_cap() {
        let exp = experiment(CONVERGED_FILE);
        let capped = SimSettings::with_physics(&exp.physics);
        let expert = expert_of(&exp);
        let model = crate::nao::model::NaoModel::with_params(0, &expert).unwrap();
        let ankles = ["lle5", "rle5"].map(|n| model.joint_index(n).unwrap());
        let doubled = SimSettings {
            speed_cap_scale: 2.0,
            speed_cap_joints: ankles.iter().map(|j| 1u64 << j).sum(),
            ..capped
        };
        let walk = |physics: SimSettings| {
            let batch = Batch {
                seed0: 3,
                n: 2,
                threads: 2,
            };
            let ts = run_many(0, &expert, batch, 10.0, physics, closed()).unwrap();
            let mx = ts.iter().map(|t| t.measurement.x_m).sum::<f64>() / ts.len() as f64;
            let share = |name: &str| {
                let clamped: u64 = ts
                    .iter()
                    .flat_map(|t| &t.speed_capped)
                    .filter(|c| c.joint == name)
                    .map(|c| c.cycles)
                    .sum();
                clamped as f64 / ts.iter().map(|t| t.cycles).sum::<u64>() as f64
            };
            for t in &ts {
                assert!(!t.measurement.fell, "seed {} fell", t.seed);
                assert_eq!(t.cycles, 500, "seed {}", t.seed);
                for c in &t.speed_capped {
                    assert!(c.joint.contains("le"), "{c:?}: not a leg joint");
                    assert!(c.cycles <= t.cycles, "{c:?}");
                }
            }
            (mx, share("lle5"), share("rle5"))
        };
        let (mx, left, right) = walk(capped);
        assert!(
            left > 0.1 && right > 0.1,
            "ankles clamped in {left:.3}, {right:.3} of the cycles"
        );
        let (mx_doubled, left_d, right_d) = walk(doubled);
        assert!(
            left_d < 0.01 && right_d < 0.01,
            "doubled cap: ankles clamped in {left_d:.3}, {right_d:.3} of the cycles"
        );
        assert!(
            mx > 4.0 && mx_doubled < 0.6 * mx,
            "mx {mx:.3} m with the league's cap, {mx_doubled:.3} m with the ankles' doubled"
        );
    }

    /// A trial's distance split by its feet (`footwork`): the three terms
    /// sum to the distance, to the rounding.
    fn assert_split_sums(t: &crate::nao::trial::NaoTrial) {
        let w = t.footwork;
        let sum = w.stepping_m + w.sliding_m + w.lean_m;
        assert!(
            (sum - t.measurement.x_m).abs() < 1e-9,
            "seed {}: {w:?} sums to {sum}, x {}",
            t.seed,
            t.measurement.x_m
        );
    }

    /// On converged physics a deep crouch (ThighRelHip2_Z −0.08, others at
    /// expert) walks more than 1.15 × its plan (measured 1.23 ×), and the
    /// feet show the surplus is steps: at least 97 % of the distance is the
    /// feet's travel between plants, planted feet slide and the torso leans
    /// ahead of them by at most 2 % (measured: 0.8 % and −0.5 %). Longer
    /// strides than planned (the ankle pitch lagging at its speed cap, the
    /// test above), not sliding or lunging passed off as walking.
    #[test]
    fn a_deep_crouch_walks_past_its_plan_by_longer_steps_not_sliding() {
        let exp = experiment(CONVERGED_FILE);
        let mut crouch = expert_of(&exp);
        crouch
            .set(protocol::params::Param::ThighRelHip2Z, -0.08)
            .unwrap();
        let physics = SimSettings::with_physics(&exp.physics);
        let batch = Batch {
            seed0: 3,
            n: 2,
            threads: 2,
        };
        let ts = run_many(0, &crouch, batch, 10.0, physics, closed()).unwrap();
        let planned = crate::nao::trial::planned_travel_m(0, &crouch, 10.0, closed()).unwrap();
        for t in &ts {
            assert!(!t.measurement.fell, "seed {} fell", t.seed);
            assert_split_sums(t);
            let (x, w) = (t.measurement.x_m, t.footwork);
            assert!(
                x > 1.15 * planned,
                "seed {}: {x:.3} m, planned {planned:.3}",
                t.seed
            );
            assert!(w.stepping_m >= 0.97 * x, "seed {}: {w:?}, x {x:.3}", t.seed);
            assert!(w.sliding_m.abs() <= 0.02 * x, "seed {}: {w:?}", t.seed);
            assert!(w.lean_m.abs() <= 0.02 * x, "seed {}: {w:?}", t.seed);
        }
    }

    /// Where experiment 1's optima at 4 × 5 ms walk beyond their plan
    /// (docs/walk.md, "Why experiment 1's optima step beyond their plan"): their
    /// legs land spread wider than the servos were steered to. On the
    /// longest thighs its CLOP chose (ThighRelHip2_Z −0.0956, the arms file
    /// at 4 × 5 ms) each landing foot is more than 8 mm further ahead than
    /// its targets put it (measured +13.0 mm, 20 trials), and those landings
    /// account for the distance beyond the plan within a third (measured
    /// 59 × 13.0 mm = 0.77 m of 0.63 m); the expert's land within 5 mm of
    /// their aim (measured −2.6 mm) and it walks within 10 % of its plan.
    #[test]
    fn long_thighs_walk_past_their_plan_by_landing_wider_than_aimed() {
        let (_, physics, expert) =
            shipped(include_str!("../../../experiments/physical-arms-5ms.toml"));
        let long = with_values(expert, &[("ThighRelHip2_Z", -0.0956)]);
        for (p, wide) in [(&long, true), (&expert, false)] {
            let ts = from_777(p, 10, physics);
            let planned = trial::planned_travel_m(0, p, 10.0, closed()).unwrap();
            let (s, mx, _) = summary(&ts);
            let w = crate::nao::footwork::Footwork::mean(
                ts.iter()
                    .filter(|t| !t.measurement.fell)
                    .map(|t| &t.footwork),
            )
            .unwrap();
            let beyond = mx - planned;
            let landed = f64::from(w.touchdowns) * w.overreach_m;
            println!("wide {wide}: s {s}, {mx:.3} of {planned:.3} m, {w:?}");
            assert!(s >= 0.9, "s {s}");
            assert!(w.touchdowns >= 40, "{w:?}");
            if wide {
                assert!(w.overreach_m > 0.008, "{w:?}");
                assert!(beyond > 0.1 * planned, "{mx} of {planned}");
                assert!(
                    (landed - beyond).abs() < beyond / 3.0,
                    "landings {landed:.3} m, beyond the plan {beyond:.3} m"
                );
            } else {
                assert!(w.overreach_m.abs() < 0.005, "{w:?}");
                assert!(beyond.abs() < 0.1 * planned, "{mx} of {planned}");
            }
        }
    }

    /// The split tells sliding and lunging apart from steps. On the league's
    /// floor the expert walk (the farm's physics) slides and leans by under
    /// 5 cm (measured −0.001 m and −0.028 m over 10 trials); with the ground's
    /// friction a fifth of the trial's draw every trial falls, its planted
    /// feet slide back by more than 3 cm (measured 7–24 cm) and the fallen
    /// torso is more than 10 cm ahead of its feet (measured 20–26 cm).
    #[test]
    fn a_slippery_floor_shows_as_sliding_and_a_fall_as_lean() {
        let exp = experiment(include_str!("../../../experiments/physical-technical.toml"));
        let expert = expert_of(&exp);
        let league = SimSettings::with_physics(&exp.physics);
        let slippery = SimSettings {
            friction_scale: 0.2,
            ..league
        };
        let batch = Batch {
            seed0: 3,
            n: 2,
            threads: 2,
        };
        for t in run_many(0, &expert, batch, 10.0, league, closed()).unwrap() {
            assert!(!t.measurement.fell, "seed {} fell", t.seed);
            assert_split_sums(&t);
            let w = t.footwork;
            assert!(
                w.sliding_m.abs() < 0.05 && w.lean_m.abs() < 0.05,
                "seed {}: {w:?}",
                t.seed
            );
            assert!(w.plants >= 50, "seed {}: {w:?}", t.seed);
        }
        for t in run_many(0, &expert, batch, 10.0, slippery, closed()).unwrap() {
            assert!(
                t.measurement.fell,
                "seed {} walked on the slippery floor",
                t.seed
            );
            assert_split_sums(&t);
            let w = t.footwork;
            assert!(w.sliding_m < -0.03, "seed {}: {w:?}", t.seed);
            assert!(w.lean_m > 0.1, "seed {}: {w:?}", t.seed);
        }
    }

    /// Where the planted feet's creep at the farm's 10 ms step comes from
    /// (docs/walk.md, "Where the feet's creep at 10 ms comes from"): rapier
    /// solves friction in each step's unbiased pass only, after the biased
    /// pass has moved the bodies, so a foot held by friction still slides
    /// within each step. With friction solved in the biased pass as well
    /// the arms file's expert slides a fifth as far (measured over those of
    /// these 4 trials that stand: 0.206 m and 0.039 m), and falls a third
    /// short of its plan (its steps cover 2.98 m of 4.63 m), its feet
    /// touching down a third more often (79 and 105 plants): why that pass
    /// is measured, not kept.
    #[test]
    fn the_feet_creep_at_10ms_because_friction_waits_for_the_unbiased_pass() {
        let (_, physics, expert) = shipped(include_str!(
            "../../../experiments/physical-technical-arms.toml"
        ));
        assert_eq!(physics.substeps, 2);
        // Over the trials that stand, as `naofarm trial` prints it.
        let footwork = |physics: SimSettings| {
            let ts = from_777(&expert, 4, physics);
            let w = crate::nao::footwork::Footwork::mean(
                ts.iter()
                    .filter(|t| !t.measurement.fell)
                    .map(|t| &t.footwork),
            )
            .unwrap();
            (w.sliding_m, w.stepping_m, f64::from(w.plants))
        };
        let (slid, _, plants) = footwork(physics);
        let (held, stepped, caught) = footwork(SimSettings {
            friction_in_bias_pass: true,
            ..physics
        });
        let planned = trial::planned_travel_m(0, &expert, 10.0, closed()).unwrap();
        println!("sliding {slid:.3} m, {held:.3} m; stepping {stepped:.3} of {planned:.3} m; plants {plants}, {caught}");
        assert!(slid > 0.1, "{slid}");
        assert!(held < 0.4 * slid, "{held} against {slid}");
        assert!(stepped < 0.8 * planned, "{stepped} of {planned}");
        assert!(caught > 1.15 * plants, "{caught} against {plants}");
    }

    /// Seed 2's Optim.1 of the 4 × 5 ms arms file (experiment 2 on the farm,
    /// `docs/results.md`, to 4 digits).
    const ARMS_5MS_OPTIM1: [(&str, f64); 5] = [
        ("ThighRelHip2_Z", -0.0795),
        ("ratio_flexion", 0.7530),
        ("long_offset_MidAnkles_2_Torso_Init", 0.0069),
        ("height_lift", 0.0271),
        ("xlength_step_max", 0.1041),
    ];

    /// Where the walks part with the time step (docs/walk.md): seed 2's
    /// Optim.1 of the 4 × 5 ms arms file, the file as shipped with only the
    /// physics steps per cycle changed, carries its torso nearly upright at
    /// 5 ms and 1 ms but leans far back at 2 ms, stands on its heels, and
    /// walks clearly shorter. The footwork's `torso_pitch_deg` is the mean
    /// over the cycles of the torso's pitch, checked here against the
    /// torso's x axis computed apart. Measured (seeds 777–780): −3.2°,
    /// −15.6° and +0.2°; 5.52, 4.88 and 5.38 m.
    #[test]
    #[ignore = "long: an older file's claim, pinned by the_older_files_claims_keep_their_bits (`cargo test --workspace -- --ignored nao::balance`)"]
    fn the_fast_walk_leans_back_at_2ms_and_walks_shorter() {
        let (_, physics, expert) = shipped(ARMS_5MS_FILE);
        let optim = with_values(expert, &ARMS_5MS_OPTIM1);
        let at = |substeps: u32| {
            let physics = SimSettings {
                substeps,
                ..physics
            };
            let (mut pitch, mut mx) = (0.0, 0.0);
            for seed in 777..781 {
                let mut sum = 0.0;
                let mut cycles = 0.0;
                let t = trial::run_observed(
                    0,
                    &optim,
                    seed,
                    10.0,
                    physics,
                    closed(),
                    &mut |sim, _, _| {
                        let pose = sim.body_poses()[0];
                        let q = nalgebra::UnitQuaternion::from_quaternion(
                            nalgebra::Quaternion::new(pose[6], pose[3], pose[4], pose[5]),
                        );
                        let x = q * nalgebra::Vector3::x();
                        sum += (-x.z).asin().to_degrees();
                        cycles += 1.0;
                    },
                )
                .unwrap();
                assert!(!t.measurement.fell, "seed {seed} at {substeps} steps");
                let own = t.footwork.torso_pitch_deg;
                assert!(
                    (own - sum / cycles).abs() < 1e-6,
                    "{own} against {}",
                    sum / cycles
                );
                pitch += own / 4.0;
                mx += t.measurement.x_m / 4.0;
            }
            (pitch, mx)
        };
        let (five, two, one) = (at(4), at(10), at(20));
        println!("5 ms {five:.3?}, 2 ms {two:.3?}, 1 ms {one:.3?}");
        assert!(five.0 > -6.0 && one.0 > -6.0, "{five:?} {one:?}");
        assert!(two.0 < -10.0, "{two:?}");
        assert!(
            two.1 < five.1 - 0.5 && two.1 < one.1 - 0.3,
            "{five:?} {two:?} {one:?}"
        );
    }

    /// The 1 ms step period file's experiment 2 Optim.1 (iteration 455).
    const PERIOD_1MS_OPTIM1: [(&str, f64); 6] = [
        ("ThighRelHip2_Z", -0.079_283_857_342_304_61),
        ("ratio_flexion", 0.775_170_556_307_798_7),
        (
            "long_offset_MidAnkles_2_Torso_Init",
            0.010_299_657_659_159_53,
        ),
        ("height_lift", 0.036_489_608_738_238_64),
        ("xlength_step_max", 0.127_474_929_742_425_77),
        ("step_period", 0.152_911_190_106_561_3),
    ];

    /// CLOP optimises into the time step (docs/walk.md): the best set of
    /// experiment 2 with the step period at 1 ms physics steps
    /// (`experiments/physical-technical-converged-period-1ms.toml`, Optim.1
    /// of iteration 455 as `naofarm report` printed it) walks past the
    /// issue's 6.0 m at its own step, a third less at 1.25 ms and clearly
    /// less at 0.67 ms, all else as the file has it. Measured (20 trials
    /// from seed 777): 6.451, 4.331 and 5.786 m, s 1.00 at each.
    #[test]
    #[ignore = "long: an older file's claim, pinned by the_older_files_claims_keep_their_bits (`cargo test --workspace -- --ignored nao::balance`)"]
    fn the_one_millisecond_optimum_is_fitted_to_its_step() {
        let exp = experiment(PERIOD_1MS_FILE);
        let physics = SimSettings::with_physics(&exp.physics);
        assert_eq!(physics.substeps, 20);
        let optim = found_in(&exp, &PERIOD_1MS_OPTIM1);
        let at = |substeps: u32| {
            twenty_from_777(
                &optim,
                SimSettings {
                    substeps,
                    ..physics
                },
            )
            .0
        };
        let ((s, own, _), (s_coarse, coarse, _), (s_fine, fine, _)) = (at(20), at(16), at(30));
        println!("1 ms {own:.3} m, 1.25 ms {coarse:.3} m, 0.67 ms {fine:.3} m");
        assert!(
            s >= 0.9 && s_coarse >= 0.9 && s_fine >= 0.9,
            "{s} {s_coarse} {s_fine}"
        );
        assert!(own >= 6.0, "{own}");
        assert!(coarse < 0.8 * own, "{coarse} against {own}");
        assert!(fine < 0.95 * own, "{fine} against {own}");
    }

    /// The band file's experiment 2 Optim.1 (iteration 448 of its first run).
    const PERIOD_BAND_OPTIM1: [(&str, f64); 6] = [
        ("ThighRelHip2_Z", -0.078_718_203_732_988_52),
        ("ratio_flexion", 0.722_955_009_324_876),
        (
            "long_offset_MidAnkles_2_Torso_Init",
            0.009_011_403_136_531_496,
        ),
        ("height_lift", 0.030_823_244_004_163_065),
        ("xlength_step_max", 0.082_196_565_978_954_21),
        ("step_period", 0.132_082_156_487_145_4),
    ];

    /// A band of physics steps keeps CLOP from fitting its optimum to one:
    /// the best set experiment 2 with the step period found with each
    /// trial's step drawn from 1.25 to 0.67 ms
    /// (`experiments/physical-technical-converged-period-band.toml`, Optim.1
    /// of iteration 448 as `naofarm report` printed it, in its first run,
    /// with the file's expert period at 0.18 s) walks the issue's
    /// 6.0 m at the band's ends and middle, each step fixed, upright and
    /// by stepping. Measured (100 trials from seed 777): 6.235, 6.396 and
    /// 6.321 m at 1.25, 1 and 0.67 ms, s 1.00, torso −1.5° to −0.5°.
    #[test]
    #[ignore = "long: an older file's claim, pinned by the_older_files_claims_keep_their_bits (`cargo test --workspace -- --ignored nao::balance`)"]
    fn the_band_optimum_walks_six_metres_at_every_step_of_its_band() {
        let exp = experiment(PERIOD_BAND_FILE);
        let physics = SimSettings::with_physics(&exp.physics);
        assert_eq!((physics.substeps, physics.substeps_max), (16, 30));
        let optim = found_in(&exp, &PERIOD_BAND_OPTIM1);
        for substeps in [16, 20, 30] {
            let fixed = SimSettings {
                substeps,
                substeps_max: 0,
                ..physics
            };
            let ts = from_777(&optim, 20, fixed);
            let (s, mx, my) = summary(&ts);
            let w = crate::nao::footwork::Footwork::mean(
                ts.iter()
                    .filter(|t| !t.measurement.fell)
                    .map(|t| &t.footwork),
            )
            .unwrap();
            println!(
                "{substeps} steps: s {s}, {mx:.3} m, pitch {:.1}°, sliding {:.3} m",
                w.torso_pitch_deg, w.sliding_m
            );
            assert!(
                s >= 0.9 && mx >= 6.0 && my / mx <= 0.25,
                "{substeps}: {s} {mx} {my}"
            );
            assert!(w.torso_pitch_deg.abs() < 5.0, "{w:?}");
            assert!(w.sliding_m.abs() < 0.05 * mx, "{w:?}");
        }
    }

    /// The band file's experiment 2 optimum (session 28, seed 1, iteration 494).
    const BAND_OPTIM: [(&str, f64); 6] = [
        ("ThighRelHip2_Z", -0.07857499297181415),
        ("ratio_flexion", 0.7741895793878497),
        ("long_offset_MidAnkles_2_Torso_Init", 0.0038717354567943843),
        ("height_lift", 0.034488529928708454),
        ("xlength_step_max", 0.11309929787598152),
        ("step_period", 0.13837635796158732),
    ];

    /// The reach file's experiment 2 Optim.2 (session 29, seed 1).
    const REACH_OPTIM2: [(&str, f64); 6] = [
        ("ThighRelHip2_Z", -0.07706498953106387),
        ("ratio_flexion", 0.7398127868480532),
        ("long_offset_MidAnkles_2_Torso_Init", 0.01233662393993597),
        ("height_lift", 0.042057196189412276),
        ("xlength_step_max", 0.11405149474763805),
        ("step_period", 0.1314131670876751),
    ];

    /// The reach-aim file's experiment 2 Optim.1 (seed 1).
    const AIM_OPTIM1: [(&str, f64); 6] = [
        ("ThighRelHip2_Z", -0.0789056136060395),
        ("ratio_flexion", 0.7352045984338313),
        ("long_offset_MidAnkles_2_Torso_Init", 0.006757706130347866),
        ("height_lift", 0.0376129487842171),
        ("xlength_step_max", 0.10411027188597062),
        ("step_period", 0.12474491549712542),
    ];

    /// The wider reach file's experiment 2 Optim.1 (session 32, seed 1).
    const REACH11_OPTIM1: [(&str, f64); 6] = [
        ("ThighRelHip2_Z", -0.07900423429969812),
        ("ratio_flexion", 0.717971394503071),
        ("long_offset_MidAnkles_2_Torso_Init", 0.007978654172390104),
        ("height_lift", 0.03640426114690867),
        ("xlength_step_max", 0.08856005054477481),
        ("step_period", 0.12205118441994006),
    ];

    /// The band files keep their bits. Their claims (the seven tests below
    /// marked long: 100-trial samples at 1.25-0.67 ms steps and L's 65 sets,
    /// about 20 min of CPU in all) run only with `cargo test --workspace --
    /// --ignored nao::balance`; this pins trials of their samples, each set
    /// they walk at the step its seed draws, so a change to the engine or
    /// the vendored rapier that moves a band walk fails here. When a pin
    /// moves on purpose, run the long claims again before moving it (the
    /// test prints every pin's seed, drawn steps, x and y). Read off this
    /// test at 014eb9b, where the long claims passed in clean-clone CI.
    #[test]
    fn the_band_files_keep_their_bits() {
        let band = PERIOD_BAND_FILE;
        let reach = include_str!(
            "../../../experiments/physical-technical-converged-period-band-reach.toml"
        );
        let aim = include_str!(
            "../../../experiments/physical-technical-converged-period-band-reach-aim.toml"
        );
        let reach11 = include_str!(
            "../../../experiments/physical-technical-converged-period-band-reach11-aim.toml"
        );
        // (file, the set if not the expert, seed, drawn steps, x, y)
        type Pin<'a> = (&'a str, Option<&'a [(&'a str, f64)]>, u64, u32, f64, f64);
        let pins: [Pin; 7] = [
            (band, None, 777, 18, 4.402172088623047, 0.31303226947784424),
            (
                band,
                Some(&BAND_OPTIM),
                778,
                23,
                6.534740447998047,
                0.15793460607528687,
            ),
            (
                reach,
                Some(&REACH_OPTIM2),
                779,
                28,
                6.286581039428711,
                0.08406458795070648,
            ),
            (aim, None, 780, 24, 3.9125497341156006, -0.35846373438835144),
            (
                aim,
                Some(&AIM_OPTIM1),
                781,
                23,
                6.095880508422852,
                -0.1282893419265747,
            ),
            (
                reach11,
                None,
                782,
                23,
                3.8368489742279053,
                -0.16148316860198975,
            ),
            (
                reach11,
                Some(&REACH11_OPTIM1),
                783,
                16,
                6.463290691375732,
                -0.09876402467489243,
            ),
        ];
        // Every pin walked first, so that a failure prints them all.
        let walked: Vec<_> = pins
            .iter()
            .map(|&(file, found, seed, ..)| {
                let (exp, physics, expert) = shipped(file);
                let set = found.map_or(expert, |f| found_in(&exp, f));
                let t = run(0, &set, seed, 10.0, physics, closed()).unwrap();
                let m = &t.measurement;
                println!(
                    "{seed}, {}, {:?}, {:?}, fell {}",
                    t.substeps, m.x_m, m.y_m, m.fell
                );
                t
            })
            .collect();
        for (i, (t, &(.., substeps, x, y))) in walked.iter().zip(&pins).enumerate() {
            assert_eq!(t.substeps, substeps, "pin {i}");
            assert!(!t.measurement.fell, "pin {i}");
            assert_eq!(t.measurement.x_m.to_bits(), x.to_bits(), "pin {i}");
            assert_eq!(t.measurement.y_m.to_bits(), y.to_bits(), "pin {i}");
        }
    }

    /// On the band of steps the expert walks the pace issue's 4.0 m at the
    /// band file's step period of 0.17 s: 100 trials from seed 777, each at
    /// its drawn step from 1.25 to 0.67 ms, s ≥ 0.7, straight, within 10 %
    /// of its plan and 1° of every stop; L's 64 corners and centre within
    /// 2°. At the other step-period files' 0.18 s it walks 3.96 m there.
    #[test]
    #[ignore = "long: a band file's 100-trial claim (`cargo test --workspace -- --ignored nao::balance`)"]
    fn the_band_expert_walks_four_metres_within_its_stops() {
        let (exp, physics, expert) = shipped(PERIOD_BAND_FILE);
        assert_eq!((physics.substeps, physics.substeps_max), (16, 30));
        assert_eq!(
            expert.given(protocol::params::Param::StepPeriod),
            Some(0.17)
        );
        band_expert_and_l_within_their_stops(&exp, physics, &expert);
    }

    /// A band file's expert over 100 trials from 777, each at its drawn
    /// step (every step of the 15 drawn), at the pace issue's distance and
    /// within 1° of every stop; and its L's 64 corners and centre within 2°.
    fn band_expert_and_l_within_their_stops(
        exp: &protocol::Experiment,
        physics: SimSettings,
        expert: &ParamValues,
    ) {
        let (ts, s, mx, planned) = walks_at_pace_within_the_stops(expert, 100, physics);
        let drawn: std::collections::BTreeSet<u32> = ts.iter().map(|t| t.substeps).collect();
        assert_eq!(drawn.len(), 15, "every step of the band drawn: {drawn:?}");
        let sets = corners_of_l(exp, true);
        assert_eq!(sets.len(), 65);
        let window = within_two_degrees_over(&sets, physics);
        println!("expert s {s}, {mx:.3} m of {planned:.3} m; L {window:.2}°");
    }

    /// The reach-aim file (the band with its steps capped at the legs' reach
    /// and aimed short) keeps the pace issue's stop bounds: its expert
    /// walks ≥ 4.0 m over 100 trials from 777, within 10 % of its plan and
    /// 1° of every stop, and L's 64 corners and centre, each walked with
    /// the cap and the aim, stay within 2° of their stops.
    #[test]
    #[ignore = "long: a band file's 100-trial claim (`cargo test --workspace -- --ignored nao::balance`)"]
    fn the_reach_aim_file_keeps_the_expert_and_l_within_their_stops() {
        let (exp, physics, expert) = shipped(include_str!(
            "../../../experiments/physical-technical-converged-period-band-reach-aim.toml"
        ));
        assert_eq!(expert.given(Param::StepAim), Some(0.3));
        assert_eq!(expert.given(Param::StepReach), Some(1.0));
        band_expert_and_l_within_their_stops(&exp, physics, &expert);
    }

    /// The reach-aim file with the reach 10 % wider (`step_reach = 1.1`)
    /// keeps the same stop bounds: L's long-step corners, now planned
    /// longer, stay within 2° of their stops, and the expert (whose step the
    /// cap does not shorten) within 1°.
    #[test]
    #[ignore = "long: a band file's 100-trial claim (`cargo test --workspace -- --ignored nao::balance`)"]
    fn the_wider_reach_file_keeps_the_expert_and_l_within_their_stops() {
        let (exp, physics, expert) = shipped(include_str!(
            "../../../experiments/physical-technical-converged-period-band-reach11-aim.toml"
        ));
        assert_eq!(expert.given(Param::StepAim), Some(0.3));
        assert_eq!(expert.given(Param::StepReach), Some(1.1));
        band_expert_and_l_within_their_stops(&exp, physics, &expert);
    }

    /// Experiment 2 on the band with the expert at 0.17 s (session 28's run
    /// of `experiments/physical-technical-converged-period-band.toml`,
    /// Optim.1 of iteration 494 as `naofarm report` printed it) finds the
    /// pace issue's 6.0 m over the band's draw (measured: 6.101 m, s 1.00,
    /// my/mx 0.04, over 100 trials from seed 777), but 0.80 × its plan: its
    /// 0.113 m steps are beyond its legs' reach under the speed cap, and
    /// with 0.090 m steps the same set walks further and within 10 % of its
    /// plan (measured: 6.195 m of 6.043 m planned, 20 trials).
    #[test]
    #[ignore = "long: a band file's 100-trial claim (`cargo test --workspace -- --ignored nao::balance`)"]
    fn the_band_runs_optimum_walks_six_metres_but_steps_short_of_its_plan() {
        let (exp, physics, _) = shipped(PERIOD_BAND_FILE);
        let optim = found_in(&exp, &BAND_OPTIM);
        let (s, mx, my) = summary(&from_777(&optim, 100, physics));
        let planned = trial::planned_travel_m(0, &optim, 10.0, closed()).unwrap();
        println!("s {s}, {mx:.3} m of {planned:.3} m planned");
        assert!(s >= 0.9 && mx >= 6.0 && my / mx <= 0.25, "{s} {mx} {my}");
        assert!((0.75..0.85).contains(&(mx / planned)), "{mx} of {planned}");
        let reachable = with_values(optim, &[("xlength_step_max", 0.090)]);
        let ((s, mx, _), planned) = twenty_from_777(&reachable, physics);
        println!("0.090 m steps: s {s}, {mx:.3} m of {planned:.3} m planned");
        assert!(s >= 0.9 && mx >= 6.0, "{s} {mx}");
        assert!((mx - planned).abs() <= 0.1 * planned, "{mx} of {planned}");
    }

    /// Experiment 2 on the band with the plan capped at the legs' reach
    /// (session 29's run of
    /// `experiments/physical-technical-converged-period-band-reach.toml`,
    /// seed 1; Optim.1 and Optim.2 as `naofarm report` printed them). Both
    /// ask for steps the cap shortens, and both walk the issue's 6.0 m over
    /// the band's draw (measured, 100 trials from 777: 6.211 m and
    /// 6.100 m, s 1.00), straight and within 1° of every stop. Now they walk
    /// *beyond* their plan, by stepping: Optim.2 1.09 × (within the 10 %),
    /// Optim.1 1.11 × (just outside it), where the uncapped band run's
    /// optimum walked 0.80 ×.
    #[test]
    #[ignore = "long: a band file's 100-trial claim (`cargo test --workspace -- --ignored nao::balance`)"]
    fn the_reach_runs_optima_walk_six_metres_by_about_their_plan() {
        let (exp, physics, _) = shipped(include_str!(
            "../../../experiments/physical-technical-converged-period-band-reach.toml"
        ));
        let optim1 = found_in(
            &exp,
            &[
                ("ThighRelHip2_Z", -0.07936676058858248),
                ("ratio_flexion", 0.7391661615035853),
                ("long_offset_MidAnkles_2_Torso_Init", 0.006439725736962886),
                ("height_lift", 0.04338248345381031),
                ("xlength_step_max", 0.1326148376608648),
                ("step_period", 0.13522526092746529),
            ],
        );
        let optim2 = found_in(&exp, &REACH_OPTIM2);
        for optim in [&optim1, &optim2] {
            let step = trial::planned_step_m(0, optim, closed()).unwrap();
            assert!(step < optim.walk().step_length - 0.02, "{step}");
        }
        let (ts, s, mx, planned) = walks_at_pace_within_the_stops(&optim2, 100, physics);
        println!("Optim.2: s {s}, {mx:.3} m of {planned:.3} m planned");
        assert!(s >= 0.9 && mx >= 6.0 && mx > planned, "{s} {mx} {planned}");
        // Beyond the plan by stepping: the feet slide less than 2 % of it.
        let sliding = ts.iter().map(|t| t.footwork.sliding_m).sum::<f64>() / ts.len() as f64;
        assert!(sliding.abs() < 0.02 * mx, "{sliding}");
        let ts = from_777(&optim1, 100, physics);
        let (s, mx, my) = summary(&ts);
        let planned = trial::planned_travel_m(0, &optim1, 10.0, closed()).unwrap();
        println!("Optim.1: s {s}, {mx:.3} m of {planned:.3} m planned");
        assert!(s >= 0.9 && mx >= 6.0 && my / mx <= 0.25, "{s} {mx} {my}");
        assert!((1.10..1.12).contains(&(mx / planned)), "{mx} of {planned}");
        for t in &ts {
            assert!(t.stop_excess.iter().all(|e| e.rad.to_degrees() <= 1.0));
        }
    }

    /// Experiment 2 on the band with the plan capped at the legs' reach and
    /// the steps aimed short by what the legs overreach (session 30's run of
    /// `experiments/physical-technical-converged-period-band-reach-aim.toml`,
    /// seed 1; Optim.1 and Optim.2 as `naofarm report` printed them). Both
    /// walk the pace issue's whole distance bound over the band's draw:
    /// ≥ 6.0 m, s ≥ 0.9, my/mx ≤ 0.25, within 10 % of their plan and 1° of
    /// every stop (measured, 100 trials from 777: 6.093 m and 6.062 m, s 1.00,
    /// both 1.09 ×). The aim is what brings Optim.1 inside the 10 %: with
    /// `step_aim` 0 the same body walks further beyond its plan (measured,
    /// 20 trials: 6.257 m, 1.12 ×, against 6.119 m, 1.10 ×).
    #[test]
    #[ignore = "long: a band file's 100-trial claim (`cargo test --workspace -- --ignored nao::balance`)"]
    fn the_aim_runs_optima_walk_six_metres_within_a_tenth_of_their_plan() {
        let (exp, physics, _) = shipped(include_str!(
            "../../../experiments/physical-technical-converged-period-band-reach-aim.toml"
        ));
        let optim1 = found_in(&exp, &AIM_OPTIM1);
        let optim2 = found_in(
            &exp,
            &[
                ("ThighRelHip2_Z", -0.07789339311932564),
                ("ratio_flexion", 0.7391859533315959),
                ("long_offset_MidAnkles_2_Torso_Init", 0.011645302146291628),
                ("height_lift", 0.04815941812283232),
                ("xlength_step_max", 0.11310287696972185),
                ("step_period", 0.13270313979197532),
            ],
        );
        for (name, optim) in [("Optim.1", &optim1), ("Optim.2", &optim2)] {
            assert_eq!(optim.given(Param::StepAim), Some(0.3));
            let (_, s, mx, planned) = walks_at_pace_within_the_stops(optim, 100, physics);
            println!("{name}: s {s}, {mx:.3} m of {planned:.3} m planned");
            assert!(s >= 0.9 && mx >= 6.0 && mx > planned, "{s} {mx} {planned}");
        }
        // The same Optim.1 aimed as planned, against aimed short, 20 trials.
        let mut unaimed = optim1;
        unaimed.set(Param::StepAim, 0.0).unwrap();
        let planned = trial::planned_travel_m(0, &optim1, 10.0, closed()).unwrap();
        let ratio = |p: &ParamValues| summary(&from_777(p, 20, physics)).1 / planned;
        let (aimed, off) = (ratio(&optim1), ratio(&unaimed));
        println!("Optim.1 x plan: {aimed:.3} aimed short, {off:.3} as planned");
        assert!(off > 1.1 && off > aimed + 0.015, "{aimed} {off}");
    }

    /// Experiment 2 on the reach-aim file with the reach 10 % wider
    /// (session 32's run of
    /// `experiments/physical-technical-converged-period-band-reach11-aim.toml`,
    /// seed 1; Optim.1 and Optim.2 as `naofarm report` printed them). Both
    /// walk the pace issue's whole distance bound over the band's draw, now
    /// on a plan of 6.0 m or more rather than beyond a shorter one: ≥ 6.0 m,
    /// s ≥ 0.9, my/mx ≤ 0.25, within 10 % of their plan and 1° of every stop
    /// (measured, 100 trials from 777: 6.316 m of 6.006 m planned, 1.05 ×,
    /// and 6.088 m of 6.134 m, 0.99 ×; s 1.00).
    #[test]
    #[ignore = "long: a band file's 100-trial claim (`cargo test --workspace -- --ignored nao::balance`)"]
    fn the_wider_reach_runs_optima_walk_six_metres_on_a_six_metre_plan() {
        let (exp, physics, _) = shipped(include_str!(
            "../../../experiments/physical-technical-converged-period-band-reach11-aim.toml"
        ));
        let optim1 = found_in(&exp, &REACH11_OPTIM1);
        let optim2 = found_in(
            &exp,
            &[
                ("ThighRelHip2_Z", -0.07604692681097201),
                ("ratio_flexion", 0.7431630383966894),
                ("long_offset_MidAnkles_2_Torso_Init", 0.009487430656550472),
                ("height_lift", 0.03755894873760762),
                ("xlength_step_max", 0.10975664028581887),
                ("step_period", 0.13011434086645657),
            ],
        );
        for (name, optim) in [("Optim.1", &optim1), ("Optim.2", &optim2)] {
            assert_eq!(optim.given(Param::StepReach), Some(1.1));
            let (_, s, mx, planned) = walks_at_pace_within_the_stops(optim, 100, physics);
            println!("{name}: s {s}, {mx:.3} m of {planned:.3} m planned");
            assert!(
                s >= 0.9 && mx >= 6.0 && planned >= 6.0,
                "{s} {mx} {planned}"
            );
        }
    }

    /// Experiment 1 on the band with the steps aimed short
    /// (`experiments/physical-converged-band-aim.toml`): every thigh walks
    /// the same plan, and with the aim the distance has an interior optimum
    /// in ThighRelHip2_Z. Measured, 20 trials from 777 (s 1.00 at each):
    /// −0.10 walks 4.241 m, −0.075 4.593 m (1.06 × its plan), −0.04 (the
    /// expert) 4.076 m; without the aim −0.10 walks 4.541 m, past its plan,
    /// so there the deep crouch still wins over most of the range.
    #[test]
    #[ignore = "long: an older file's claim, pinned by the_older_files_claims_keep_their_bits (`cargo test --workspace -- --ignored nao::balance`)"]
    fn experiment_ones_thigh_has_an_interior_optimum_with_the_aim() {
        let (_, physics, expert) = shipped(BAND_AIM_FILE);
        assert_eq!(expert.given(Param::StepAim), Some(0.3));
        let thigh = |v: f64| with_values(expert, &[("ThighRelHip2_Z", v)]);
        let walk = |p: &ParamValues| {
            let ((s, mx, _), planned) = twenty_from_777(p, physics);
            assert!((s - 1.0).abs() < 1e-12, "{s}");
            (mx, planned)
        };
        let (deep, _) = walk(&thigh(-0.10));
        let (peak, planned) = walk(&thigh(-0.075));
        let (standard, _) = walk(&expert);
        println!("aimed: -0.10 {deep:.3} m, -0.075 {peak:.3} m, expert {standard:.3} m");
        assert!(
            peak > deep + 0.2 && peak > standard + 0.3,
            "{deep} {peak} {standard}"
        );
        assert!(
            (peak - planned).abs() <= 0.1 * planned,
            "{peak} of {planned}"
        );
        let mut unaimed = thigh(-0.10);
        unaimed.set(Param::StepAim, 0.0).unwrap();
        let (deep_off, planned) = walk(&unaimed);
        println!("as planned: -0.10 {deep_off:.3} m of {planned:.3} m");
        assert!(
            deep_off > planned && deep_off > deep + 0.2,
            "{deep_off} {deep}"
        );
    }

    /// The step period file's experiment 2 Optim.1 (iteration 369).
    const PERIOD_OPTIM1: [(&str, f64); 6] = [
        ("ThighRelHip2_Z", -0.078_619_611_717_998_87),
        ("ratio_flexion", 0.674_939_194_536_835),
        (
            "long_offset_MidAnkles_2_Torso_Init",
            0.027_151_363_412_487_813,
        ),
        ("height_lift", 0.063_689_905_311_591_98),
        ("xlength_step_max", 0.085_220_683_185_753_74),
        ("step_period", 0.122_157_409_483_154_03),
    ];

    /// The pace issue's 6.0 m, reached on converged physics with the step
    /// period co-optimised (`experiments/physical-technical-converged-period.toml`):
    /// the best set its 500 iterations found (Optim.1, iteration 369, as
    /// `naofarm report` printed it) walks ≥ 6.0 m with s ≥ 0.9 over 100
    /// trials (measured: 6.111 m, s 1.00), straight (my/mx ≤ 0.25) and within
    /// 10 % of its planned steps, every joint within 1° of its stops
    /// (measured: 0.80°). The file's expert set keeps the engine's own step
    /// period, so its walk is the five-parameter file's.
    #[test]
    #[ignore = "long: an older file's claim, pinned by the_older_files_claims_keep_their_bits (`cargo test --workspace -- --ignored nao::balance`)"]
    fn the_step_period_experiments_best_set_walks_six_metres_within_the_stops() {
        let exp = experiment(PERIOD_FILE);
        let physics = SimSettings::with_physics(&exp.physics);
        let optim = found_in(&exp, &PERIOD_OPTIM1);
        let (ts, s, mx, planned) = walks_at_pace_as_planned(&optim, 100, physics);
        assert!(s >= 0.9, "s = {s}");
        assert!(mx >= 6.0, "mx = {mx}");
        for t in &ts {
            for e in &t.stop_excess {
                assert!(e.rad.to_degrees() <= 1.0, "seed {}: {e:?}", t.seed);
            }
        }
        let expert = expert_of(&exp);
        let five = experiment(CONVERGED_FILE);
        let five = ParamValues::from_named(&five.full_params(&five.expert_values())).unwrap();
        let one = |p: &ParamValues| run(0, p, 777, 10.0, physics, closed()).unwrap();
        assert_eq!(one(&expert), one(&five), "the expert set's walk");
        println!("Optim.1: s {s:.2}, mx {mx:.3} m (planned {planned:.3})");
    }

    /// The heading file with the tilt estimate from the gravity vector and
    /// the torso's mean pitch held by both hips (docs/walk.md, "The tilt
    /// estimate, read right, and the pitch held").
    const HOLD_FILE: &str = include_str!(
        "../../../experiments/physical-technical-arms-5ms-roll-aim-lean-reach-damp-heading-hold.toml"
    );

    /// `n` trials of `p` from seed 777 lasting `duration_s`.
    fn lasting(p: &ParamValues, n: u64, duration_s: f64, physics: SimSettings) -> Vec<NaoTrial> {
        let batch = Batch {
            seed0: 777,
            n,
            threads: 2,
        };
        run_many(0, p, batch, duration_s, physics, closed()).unwrap()
    }

    /// Experiment 2 of the hold file keeps the stops and finds the 6 m at
    /// seed 1 as planned: the expert at pace as planned within 1° of every
    /// stop (30 trials), L's corners and centre within 2°, and seed 1's
    /// Optim.1 (session 59's run) over Table IV's 100 trials at s ≥ 0.9 and
    /// ≥ 6.0 m, within 10 % of its plan and 1° of every stop. Measured: the
    /// optimum s 1.00, 6.352 m of 6.244 m planned, 0.05° at worst (the
    /// heading file's seed 1: 5.949 m at s 0.91).
    #[test]
    #[ignore = "long: a superseded 4 × 5 ms file's claim (`cargo test --workspace -- --ignored nao::balance`)"]
    fn the_hold_file_keeps_the_stops_and_finds_six_metres_at_seed_1() {
        let (exp, physics, expert) = shipped(HOLD_FILE);
        keeps_the_stops_and_walks_six_metres(&exp, physics, &expert, &HOLD_SEED1_OPTIM1);
    }

    /// The hold file with each step read from the cycle before its
    /// touchdown (docs/walk.md, "Steps read before the other foot leaves").
    const BEFORE_FILE: &str = include_str!(
        "../../../experiments/physical-technical-arms-5ms-roll-aim-lean-reach-damp-heading-hold-before.toml"
    );

    /// Experiment 2 of the before file keeps the stops and finds the 6 m at
    /// seed 1 as planned: the expert at pace as planned within 1° of every
    /// stop (30 trials), L's corners and centre within 2°, and seed 1's
    /// Optim.1 (session 60's run) over Table IV's 100 trials at s ≥ 0.9 and
    /// ≥ 6.0 m, within 10 % of its plan and 1° of every stop. Measured: L
    /// 0.30° at worst over seeds 1–3 (`scripts/stops.py`); the optimum
    /// s 1.00, 6.042 m of 6.144 m planned (0.98 ×; the hold file's seed 1:
    /// 6.352 m at 1.02 ×, seed 3's 1.11 ×).
    #[test]
    fn the_before_file_keeps_the_stops_and_finds_six_metres_as_planned_at_seed_1() {
        let (exp, physics, expert) = shipped(BEFORE_FILE);
        keeps_the_stops_and_walks_six_metres(
            &exp,
            physics,
            &expert,
            &[
                ("ThighRelHip2_Z", -0.0748542340696662),
                ("ratio_flexion", 0.828656022368882),
                ("long_offset_MidAnkles_2_Torso_Init", 0.013182028207710503),
                ("height_lift", 0.026907390711135012),
                ("xlength_step_max", 0.14050995774255126),
            ],
        );
    }

    /// The before file's expert leans on its feedback: without it (every
    /// gain, the roll-rate damper, the pitch hold and the step gauge too) it
    /// walks clearly shorter. Measured over 40 trials from 777: 4.572 m with,
    /// 4.073 m without, s 1.00 both.
    #[test]
    fn the_before_files_expert_walks_shorter_without_feedback() {
        let (_, physics, expert) = shipped(BEFORE_FILE);
        the_expert_falls_or_walks_shorter_without_feedback(&expert, physics, (777, 40));
    }

    /// Seed 1's Optim.1 of experiment 2 on the roll file (session 35's run).
    const ROLL_SEED1_OPTIM1: [(&str, f64); 5] = [
        ("ThighRelHip2_Z", -0.07248014550316677),
        ("ratio_flexion", 0.7337248544360496),
        ("long_offset_MidAnkles_2_Torso_Init", 0.007568212834695239),
        ("height_lift", 0.027382255547773543),
        ("xlength_step_max", 0.10655390587942211),
    ];

    /// Seed 1's Optim.1 of experiment 2 on the roll-aim file (session 36's run).
    const ROLL_AIM_SEED1_OPTIM1: [(&str, f64); 5] = [
        ("ThighRelHip2_Z", -0.07723586923111701),
        ("ratio_flexion", 0.7913222324625083),
        ("long_offset_MidAnkles_2_Torso_Init", 0.008266306443202406),
        ("height_lift", 0.025000629956579354),
        ("xlength_step_max", 0.10772545353299341),
    ];

    /// Seed 4's Optim.1 of experiment 2 on the lean file (session 52's run).
    const LEAN_SEED4_OPTIM1: [(&str, f64); 5] = [
        ("ThighRelHip2_Z", -0.0795884250812909),
        ("ratio_flexion", 0.7915152326661048),
        ("long_offset_MidAnkles_2_Torso_Init", 0.007432642764605207),
        ("height_lift", 0.025574446778253247),
        ("xlength_step_max", 0.10511595834344509),
    ];

    /// Seed 1's Optim.1 of experiment 2 on the hold file (session 59's run).
    const HOLD_SEED1_OPTIM1: [(&str, f64); 5] = [
        ("ThighRelHip2_Z", -0.07810438860141834),
        ("ratio_flexion", 0.8316249731504421),
        ("long_offset_MidAnkles_2_Torso_Init", 0.014116291667796297),
        ("height_lift", 0.027920855880542546),
        ("xlength_step_max", 0.11600874473183519),
    ];

    /// A trial pinned to the bit: the file, the set's values over the
    /// file's expert (none: the expert), the physics steps per cycle, fixed
    /// (0: the file's own), the seed, and the trial's x and y.
    type BitPin<'a> = (&'a str, &'a [(&'a str, f64)], u32, u64, [f64; 2]);

    /// Runs every pinned trial on the closed loop and fails naming each one
    /// whose x or y moved by a bit. A set naming every parameter of its file
    /// is checked to be the one a worker gets.
    fn pins_hold(pins: &[BitPin]) {
        let mut moved = Vec::new();
        for &(file, values, substeps, seed, xy) in pins {
            let (exp, physics, expert) = shipped(file);
            let set = with_values(expert, values);
            let names = exp.parameter.iter().map(|p| p.name.as_str());
            if names.eq(values.iter().map(|(n, _)| *n)) {
                assert_eq!(
                    set,
                    found_in(&exp, values),
                    "{}: as a worker gets it",
                    exp.name
                );
            }
            let physics = match substeps {
                0 => physics,
                n => SimSettings {
                    substeps: n,
                    substeps_max: 0,
                    ..physics
                },
            };
            let t = run(0, &set, seed, 10.0, physics, closed()).unwrap();
            let (x, y) = (t.measurement.x_m, t.measurement.y_m);
            println!(
                "{}, {values:?} at {substeps}, seed {seed}: [{x:?}, {y:?}]",
                exp.name
            );
            if [x.to_bits(), y.to_bits()] != xy.map(f64::to_bits) {
                moved.push((exp.name, values, substeps, seed, x, y));
            }
        }
        assert!(moved.is_empty(), "moved: {moved:?}");
    }

    /// The superseded 4 × 5 ms files keep their bits: the roll, roll-aim,
    /// lean, capped lean, damp and hold files, each a step on the way to the
    /// before file. Their claims (six tests of the 6 m and the stops, 163
    /// trials each, and two of the feedback; about 8 min of CPU in all) are
    /// marked long and run only with `cargo test --workspace -- --ignored
    /// nao::balance`; this pins one trial of each file's expert (seed 11)
    /// and one of the Optim.1 its claim walks (seed 12), so a change to the
    /// engine or the vendored rapier that moves one of those walks fails
    /// here. When a pin moves on purpose, run the long claims again before
    /// moving it. Read off `naofarm trial --experiment FILE --seed S
    /// --trials 1 --json` at 6591aad, whose long claims passed in
    /// clean-clone CI (at f84c244, with the same bits) and again with
    /// `--ignored` at 177681b. The lean and capped
    /// files' experts walk the same bits: the cap at the legs' reach does
    /// not bind on the expert's 0.08 m steps.
    #[test]
    fn the_superseded_5ms_files_keep_their_bits() {
        // each file's expert at seed 11, its claim's Optim.1 at seed 12
        pins_hold(&[
            (
                ROLL_FILE,
                &[],
                0,
                11,
                [4.281322956085205, 0.20885001122951508],
            ),
            (
                ROLL_FILE,
                &ROLL_SEED1_OPTIM1,
                0,
                12,
                [5.703700065612793, -0.06071317568421364],
            ),
            (
                ROLL_AIM_FILE,
                &[],
                0,
                11,
                [4.559727191925049, 0.17019248008728027],
            ),
            (
                ROLL_AIM_FILE,
                &ROLL_AIM_SEED1_OPTIM1,
                0,
                12,
                [6.258851051330566, -0.45746731758117676],
            ),
            (
                LEAN_FILE,
                &[],
                0,
                11,
                [4.2903361320495605, 0.04639783129096031],
            ),
            (
                LEAN_FILE,
                &LEAN_SEED4_OPTIM1,
                0,
                12,
                [6.0312819480896, 0.35011887550354004],
            ),
            (
                CAPPED_FILE,
                &[],
                0,
                11,
                [4.2903361320495605, 0.04639783129096031],
            ),
            (
                CAPPED_FILE,
                &CAPPED_SEED3_OPTIM1,
                0,
                12,
                [6.201181888580322, -0.06047630310058594],
            ),
            (
                DAMP_FILE,
                &[],
                0,
                11,
                [4.469581604003906, 0.12153854966163635],
            ),
            (
                DAMP_FILE,
                &DAMP_SEED1_OPTIM1,
                0,
                12,
                [6.417342662811279, -0.3300636112689972],
            ),
            (
                HOLD_FILE,
                &[],
                0,
                11,
                [4.637856960296631, -0.17280606925487518],
            ),
            (
                HOLD_FILE,
                &HOLD_SEED1_OPTIM1,
                0,
                12,
                [6.426103591918945, -0.020636824890971184],
            ),
        ]);
    }

    /// The older files' claims, marked long, keep their bits: one trial of
    /// each set those claims walk, on the physics they walk it on, checked
    /// to the bit (the claims' own trials are the same function of the same
    /// inputs). The claims: experiment 1's interior optimum with the aim,
    /// the band, 1 ms and step period optima, the arms file's at 4 × 5 ms
    /// (seed 4's Optim.1, session 23's optimum, seed 2's Optim.1 at 2 ms)
    /// and experiment 1's optimum on the roll-aim file, aimed and not, and
    /// the converged file's expert. The values were read off this test's
    /// own print at 113c641, where every one of those claims passed
    /// (session 61's `--ignored` run and its CI).
    #[test]
    fn the_older_files_claims_keep_their_bits() {
        let deep_unaimed = [("ThighRelHip2_Z", -0.10), ("step_aim", 0.0)];
        let unaimed = [EXP1_ROLL_AIM_OPTIM1[0], ("step_aim", 0.0)];
        pins_hold(&[
            (
                BAND_AIM_FILE,
                &[],
                0,
                11,
                [4.219828128814697, 0.4014723598957062],
            ),
            (
                BAND_AIM_FILE,
                &[("ThighRelHip2_Z", -0.075)],
                0,
                12,
                [4.646162033081055, -0.1609996259212494],
            ),
            (
                BAND_AIM_FILE,
                &deep_unaimed,
                0,
                12,
                [3.729851484298706, -0.0012005593162029982],
            ),
            (
                PERIOD_BAND_FILE,
                &PERIOD_BAND_OPTIM1,
                16,
                12,
                [5.943450927734375, -0.6294988989830017],
            ),
            (
                PERIOD_BAND_FILE,
                &PERIOD_BAND_OPTIM1,
                30,
                12,
                [5.4790940284729, -0.4165811836719513],
            ),
            (
                PERIOD_1MS_FILE,
                &PERIOD_1MS_OPTIM1,
                0,
                12,
                [5.755347728729248, -0.7034714818000793],
            ),
            (
                PERIOD_1MS_FILE,
                &PERIOD_1MS_OPTIM1,
                16,
                12,
                [4.268350124359131, -0.7147274017333984],
            ),
            (
                PERIOD_FILE,
                &PERIOD_OPTIM1,
                0,
                12,
                [5.8168253898620605, -0.18462815880775452],
            ),
            (
                ARMS_5MS_FILE,
                &ARMS_5MS_SEED4_OPTIM1,
                0,
                12,
                [5.995064735412598, -0.27393221855163574],
            ),
            (
                ARMS_5MS_FILE,
                &ARMS_OPTIM2,
                0,
                12,
                [5.445354461669922, -0.1392078995704651],
            ),
            (
                ARMS_5MS_FILE,
                &ARMS_5MS_OPTIM1,
                10,
                12,
                [4.924708843231201, -0.1302572339773178],
            ),
            (
                EXP1_ROLL_AIM_FILE,
                &EXP1_ROLL_AIM_OPTIM1,
                0,
                12,
                [4.909170627593994, 0.31926780939102173],
            ),
            (
                EXP1_ROLL_AIM_FILE,
                &unaimed,
                0,
                12,
                [5.282294750213623, -0.00655552139505744],
            ),
            (
                CONVERGED_FILE,
                &[],
                0,
                11,
                [4.291441440582275, -0.02505970187485218],
            ),
        ]);
    }

    /// Read in the touchdown's own cycle, when the other foot has often
    /// begun its swing, a step reads short of the feet's true spacing, and
    /// the gauge never slows the hold file's fast walks: seed 3's Optim.1 of
    /// experiment 2 on the hold file (session 59's run) steps more than 8 %
    /// past its plan. Read from the cycle before, while the other foot still
    /// carries, it walks within 5 % of its plan, standing. Measured over 20
    /// trials from 777: 1.097 and 1.025 × (6.269 and 5.858 m of 5.716 m),
    /// s 1.00 both; over 40, 1.102 and 1.022 ×.
    #[test]
    fn reading_the_steps_before_the_other_foot_leaves_keeps_the_held_optimum_to_its_plan() {
        let (_, physics, touchdown) = shipped(HOLD_FILE);
        let (_, before_physics, before) = shipped(BEFORE_FILE);
        assert_eq!(physics, before_physics);
        assert_eq!(before.given(Param::StepAimBefore), Some(1.0));
        assert_eq!(touchdown.given(Param::StepAimBefore), None);
        let optimum = [
            ("ThighRelHip2_Z", -0.07966838599290399),
            ("ratio_flexion", 0.7554388002091614),
            ("long_offset_MidAnkles_2_Torso_Init", 0.0214667357803614),
            ("height_lift", 0.025775345455140035),
            ("xlength_step_max", 0.1064705891676588),
        ];
        let ratio = |p: &ParamValues| against_plan(&with_values(*p, &optimum), 20, physics);
        let (s_touchdown, mx_touchdown, at) = ratio(&touchdown);
        let (s_before, mx_before, read_before) = ratio(&before);
        println!(
            "touchdown: s {s_touchdown}, {mx_touchdown:.3} m, {at:.3} x; \
             before: s {s_before}, {mx_before:.3} m, {read_before:.3} x"
        );
        assert!(at > 1.08, "read at the touchdown: {at}");
        assert!(
            read_before <= 1.05 && s_before >= 0.9,
            "read before: {read_before}, s {s_before}"
        );
    }

    /// The hold integrates the estimated pitch's excess over its pitch:
    /// a torso held 0.2 rad further back than `pitch_hold_rad` gets,
    /// after t seconds, gain × (−0.2 t) on both legs (the same on each,
    /// whatever their loads), split between the hips and the ankles by
    /// `pitch_hold_ankle`, until it reaches [`super::PITCH_HOLD_MAX`];
    /// off, or held at its own pitch, it adds nothing.
    #[test]
    fn the_pitch_hold_integrates_to_its_cap_on_both_legs() {
        use super::{Balance, Correction, Gains, GAINS, PITCH_HOLD_MAX};
        let held = |pitch: f64, cycles: u32, gain: f64, ankle: f64| -> Correction {
            let mut b = Balance::new(Gains {
                tilt_vector: 1.0,
                pitch_hold_gain: gain,
                pitch_hold: -0.2,
                pitch_hold_ankle: ankle,
                // The stance hip's own pitch gain off: the hold alone.
                hip_pitch: 0.0,
                ..GAINS
            });
            let p = still([-9.81 * pitch.sin(), 0.0, 9.81 * pitch.cos()], [45.0, 15.0]);
            let mut c = Correction::default();
            for _ in 0..cycles {
                c = b.update(&p, 0.02);
            }
            c
        };
        // Settled on −0.4 rad (1000 cycles, 20 s): the cap, a quarter of
        // it on each hip and each ankle at the half split (−0.5 × −0.2 ×
        // 20 s = 2 rad would be far past it).
        let c = held(-0.4, 1000, -0.5, 0.5);
        for leg in &c.legs {
            assert!((leg[2] - PITCH_HOLD_MAX / 2.0).abs() < 1e-9, "{c:?}");
            assert!((leg[4] - PITCH_HOLD_MAX / 2.0).abs() < 1e-9, "{c:?}");
        }
        // Within the cap it is the integral: 1 s more of 0.2 rad past
        // the held pitch adds 0.5 × 0.2 = 0.1 rad (the estimate settles
        // within a few of the filter's 0.5 s, so compare 2.5 s with 3.5 s;
        // the cap, 0.4 / 0.5 = 0.8 rad·s, is not reached before 4 s).
        let (a, b) = (held(-0.4, 125, -0.5, 0.0), held(-0.4, 175, -0.5, 0.0));
        let grown = b.legs[0][2] - a.legs[0][2];
        assert!((grown - 0.1).abs() < 2e-3, "{grown}");
        assert!(b.legs[0][2] < PITCH_HOLD_MAX, "{b:?}");
        assert!(a.legs[0][2] > 0.0 && a.legs[0][2] < PITCH_HOLD_MAX);
        assert_eq!(a.legs[0][2], a.legs[1][2]);
        // The hips alone: the ankles get nothing, exactly.
        assert_eq!(a.legs[0][4], 0.0);
        // Off: nothing at all.
        assert_eq!(held(-0.4, 1000, 0.0, 0.5).legs, [[0.0; 6]; 2]);
    }

    /// The heel strikes of the held walk shake the accelerometer, and the
    /// per-cycle angle filter's pitch reads more lean back than the torso
    /// has (each trial's mean error, estimate less the truth, over 4
    /// trials of 30 s: −4.5 to −5.1°); the gravity-vector filter of the file
    /// (`tilt_vector = 1`) reads it within 1° (−0.08 to −0.21°).
    #[test]
    fn the_vector_filter_reads_the_pitch_the_shaken_angle_filter_misreads() {
        let (_, physics, held) = shipped(HOLD_FILE);
        assert_eq!(held.given(Param::TiltVector), Some(1.0));
        let angles = with_values(held, &[("tilt_vector", 0.0)]);
        let errors = |p: &ParamValues| {
            lasting(p, 4, 30.0, physics)
                .iter()
                .map(|t| t.footwork.tilt_error_deg)
                .collect::<Vec<_>>()
        };
        for e in errors(&angles) {
            assert!(e < -3.0, "the angle filter: {e}°");
        }
        for e in errors(&held) {
            assert!(e.abs() < 1.0, "the vector filter: {e}°");
        }
    }

    /// The hold file's expert walks the pace issue's 10 s as planned (s ≥
    /// 0.7, ≥ 4.0 m, within 10 % of its plan; measured over 20 trials: s 1.00, 4.644 m
    /// of 4.631 m planned)
    /// and stands through a minute (measured: s 1.00, 21.21 m); without the hold
    /// (`pitch_hold_gain = 0`, the estimate still the vector's) it leans
    /// back further every second and falls in every trial by 30 s
    /// (s 0.00).
    #[test]
    fn holding_the_pitch_stands_the_heading_expert_through_a_minute() {
        let (_, physics, held) = shipped(HOLD_FILE);
        assert_eq!(held.given(Param::PitchHoldGain), Some(-0.5));
        assert_eq!(held.given(Param::PitchHoldAnkle), Some(0.5));
        walks_at_pace_as_planned(&held, 20, physics);
        let (s, ..) = summary(&lasting(&held, 20, 60.0, physics));
        assert!(s >= 0.85, "held, 60 s: s {s}");
        let unheld = with_values(held, &[("pitch_hold_gain", 0.0)]);
        let (s, ..) = summary(&lasting(&unheld, 20, 30.0, physics));
        assert!(s <= 0.1, "unheld, 30 s: s {s}");
    }
}
