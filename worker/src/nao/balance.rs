//! The walk's balance: the LIP-3D plan of [`super::walk`] at the league's
//! pace, corrected every 20 ms agent cycle from the robot's own noisy
//! sensors.
//!
//! It must stay a controller: joint targets from the plan and what the robot
//! senses, no access to the simulation's true state and no randomness (the
//! trial adds the sensors' noise before they reach it).
//!
//! # What it senses and what it does with it
//! - **Torso tilt**: gravity kept as a vector in the torso's axes, turned
//!   by the gyro and pulled linearly towards each accelerometer reading
//!   with time constant [`TILT_FILTER_S`]. The heel strikes of a fast walk
//!   shake the accelerometer; a linear pull averages that out where a
//!   filter of per-cycle angles reads the torso 5–11° further back than it
//!   leans.
//! - **Ankles**: each stance ankle's pitch turns against the torso's pitch
//!   ([`ANKLE_PITCH_GAIN`]), in the leg's share of the sensed load.
//! - **Pitch hold**: both legs carry the integral of the pitch's excess over
//!   [`PITCH_HOLD_RAD`] ([`PITCH_HOLD_GAIN`], capped at [`PITCH_HOLD_MAX`]),
//!   half on the hips and half on the ankles: a slow bias, the same on both
//!   legs, that stops the fast walk leaning further back every second.
//! - **Sideways rock**: the stance hip's roll turns against the gyro's roll
//!   rate ([`HIP_ROLL_RATE_GAIN`]), in the leg's share of the load: a damper.
//! - **Forward lean**: a foot is placed against the torso's forward pitch in
//!   the share of the load it does not carry ([`LEAN_PLACE`]), so a torso
//!   pitched forward does not carry the swinging foot back with the hips.
//! - **Touchdowns**: a [`StepGauge`] reads each landing's feet spacing from
//!   the sensed joint angles of the cycle before the touchdown (while the
//!   other foot still carries), along the walk's heading (the torso's x
//!   axis turned back by the gyro's integrated turn), against the spacing
//!   aimed at; the plan is walked at the pace that aims the steps short by
//!   what the legs overreach ([`super::walk::Paced`]).
//!
//! Each foot's share of the load comes from the foot force sensors, so a
//! foot in the air gets no stance correction. docs/walk.md gives each
//! constant's measurement.

use super::footwork::{AIR_CYCLES, PLANTED_N};
use super::sim::Perception;

/// Time constant of the tilt estimate's pull towards the accelerometer, s.
pub const TILT_FILTER_S: f64 = 0.5;

/// Time constant of the turn estimate's leak towards 0, s: the walk's heading
/// drifts slowly, the turn of each step comes and goes within it.
pub const TURN_FILTER_S: f64 = 1.0;

/// Stance ankle pitch per rad of sensed torso pitch.
pub const ANKLE_PITCH_GAIN: f64 = 1.0;

/// Stance hip roll per rad/s of sensed torso roll rate.
pub const HIP_ROLL_RATE_GAIN: f64 = 0.05;

/// Each foot placed against this share of the torso's forward lean, in the
/// share of the load it does not carry.
pub const LEAN_PLACE: f64 = 0.5;

/// Both legs' pitch per rad·s of the integrated excess of the sensed pitch
/// over [`PITCH_HOLD_RAD`] (negative: a torso leaning back further is
/// pitched forward).
pub const PITCH_HOLD_GAIN: f64 = -0.5;

/// The torso pitch the hold keeps, rad (negative: leaning back).
pub const PITCH_HOLD_RAD: f64 = -0.2;

/// The hold's share on both ankles' pitch, the rest on the hips'.
pub const PITCH_HOLD_ANKLE: f64 = 0.5;

/// The largest pitch the hold puts on both legs, rad (hips and ankles
/// together): the expert stands through a minute with 0.2 and 0.4 alike,
/// and walks further with 0.2.
pub const PITCH_HOLD_MAX: f64 = 0.2;

/// Each step's share in [`StepGauge`]'s overreach estimate (about the last
/// three steps).
pub const STEP_AIM_SHARE: f64 = 0.3;

/// Gravity, m/s²: the tilt filter's start (the torso upright).
const GRAVITY_M_S2: f64 = 9.81;

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
/// after [`AIR_CYCLES`] in the air), the feet's spacing along the walk's
/// heading by forward kinematics of the sensed joint angles is divided by
/// the spacing the paced plan aims at for that step's end; the estimate
/// follows those readings by [`STEP_AIM_SHARE`] per step. The plan is then
/// walked at the pace 1 / estimate: legs that land 10 % past their aim are
/// aimed 10 % short, so the feet land the plan's steps.
#[derive(Debug, Clone)]
pub struct StepGauge {
    share: f64,
    ratio: f64,
    readings: u32,
    /// Cycles each foot's sensed load has been under [`PLANTED_N`].
    air: [u32; 2],
}

impl Default for StepGauge {
    fn default() -> Self {
        Self::new(STEP_AIM_SHARE)
    }
}

impl StepGauge {
    /// A gauge following each step's reading by `share` (0–1), no overreach
    /// yet.
    #[must_use]
    pub fn new(share: f64) -> Self {
        Self {
            share: share.clamp(0.0, 1.0),
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

    /// Steps read so far.
    #[must_use]
    pub fn readings(&self) -> u32 {
        self.readings
    }
}

/// The controller's state: the tilt, hold and turn estimates.
#[derive(Debug, Clone)]
pub struct Balance {
    /// Torso (roll, pitch) estimate, rad.
    tilt: [f64; 2],
    /// Gravity in the torso's axes, m/s²: turned by the gyro, pulled
    /// linearly towards each accelerometer reading.
    gravity: [f64; 3],
    /// The estimated pitch's excess over [`PITCH_HOLD_RAD`], integrated, rad·s.
    held: f64,
    /// Torso turn about the vertical, rad: the gyro integrated, leaking
    /// towards 0 with time constant [`TURN_FILTER_S`].
    turn: f64,
}

impl Default for Balance {
    fn default() -> Self {
        Self::new()
    }
}

/// What the controller adds to the plan for the next cycle.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Correction {
    /// Added to each leg's six angles (le1..le6), left then right.
    pub legs: [[f64; 6]; 2],
    /// The torso's forward lean each foot (left, right) is placed against,
    /// rad (0: none).
    pub lean: [f64; 2],
}

impl Balance {
    /// A controller with the torso upright.
    #[must_use]
    pub fn new() -> Self {
        Self {
            tilt: [0.0, 0.0],
            gravity: [0.0, 0.0, GRAVITY_M_S2],
            held: 0.0,
            turn: 0.0,
        }
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
        let k = dt / (TILT_FILTER_S + dt);
        // A vector fixed in the world turns in the torso's axes by −ω × v;
        // the pull is linear in the reading, so the heel strikes' shaking
        // averages out instead of biasing an angle.
        let v = self.gravity;
        let turned = [
            v[0] - (gy * v[2] - gz * v[1]) * dt,
            v[1] - (gz * v[0] - gx * v[2]) * dt,
            v[2] - (gx * v[1] - gy * v[0]) * dt,
        ];
        let a = [ax, ay, az];
        self.gravity = std::array::from_fn(|i| turned[i] + k * (a[i] - turned[i]));
        // Gravity seen from a torso rolled by r and pitched by p reads
        // (−g sin p, g sin r cos p, g cos r cos p) in the torso's axes.
        let [vx, vy, vz] = self.gravity;
        self.tilt = [libm::atan2(vy, vz), libm::atan2(-vx, libm::hypot(vy, vz))];
        let [_, pitch] = self.tilt;
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
            leg[4] = w * (ANKLE_PITCH_GAIN * pitch);
            leg[1] = w * (HIP_ROLL_RATE_GAIN * gx);
        }
        let cap = PITCH_HOLD_MAX / PITCH_HOLD_GAIN.abs();
        self.held = (self.held + (pitch - PITCH_HOLD_RAD) * dt).clamp(-cap, cap);
        let hold = PITCH_HOLD_GAIN * self.held;
        for leg in &mut c.legs {
            leg[2] += (1.0 - PITCH_HOLD_ANKLE) * hold;
            leg[4] += PITCH_HOLD_ANKLE * hold;
        }
        // A foot in the air (or both, in flight: no share) placed in full; a
        // torso leaning back (the walk's own posture) moves no foot.
        c.lean = share.map(|w| LEAN_PLACE * (1.0 - w) * pitch.max(0.0));
        c
    }
}

#[cfg(test)]
mod tests {
    use super::{Balance, Correction, StepGauge, PACE_MIN, PITCH_HOLD_MAX};
    use crate::nao::sim::Perception;

    /// What a torso at rest senses: the accelerometer reading `accel`, the
    /// feet's vertical loads `loads` (left, right), nothing turning.
    fn still(accel: [f64; 3], loads: [f64; 2]) -> Perception {
        Perception {
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

    /// The correction after `cycles` cycles of a torso held at `pitch` with
    /// the feet's loads `loads`.
    fn held(pitch: f64, loads: [f64; 2], cycles: u32) -> Correction {
        let mut b = Balance::new();
        let p = still([-9.81 * pitch.sin(), 0.0, 9.81 * pitch.cos()], loads);
        let mut c = Correction::default();
        for _ in 0..cycles {
            c = b.update(&p, 0.02);
        }
        c
    }

    /// A foot is placed against the sensed forward lean in the share of the
    /// load it does not carry (both in full in the air); a torso leaning
    /// back moves no foot.
    #[test]
    fn a_forward_lean_places_the_unloaded_foot() {
        let near = |a: [f64; 2], b: [f64; 2]| (0..2).all(|i| (a[i] - b[i]).abs() < 1e-6);
        // Leaning forward 0.2 rad, the left foot carrying three quarters.
        let c = held(0.2, [45.0, 15.0], 500);
        assert!(near(c.lean, [0.5 * 0.25 * 0.2, 0.5 * 0.75 * 0.2]), "{c:?}");
        // In flight both feet are placed in full.
        let c = held(0.2, [0.0, 0.0], 500);
        assert!(near(c.lean, [0.1, 0.1]), "{c:?}");
        // Leaning back: nothing, exactly.
        assert_eq!(held(-0.15, [0.0, 60.0], 500).lean, [0.0; 2]);
    }

    /// The hold integrates the estimated pitch's excess over its pitch on
    /// both legs alike, half on the hips and half on the ankles, up to its
    /// cap; held at its own pitch it stops growing.
    #[test]
    fn the_pitch_hold_integrates_to_its_cap_on_both_legs() {
        // Settled 0.2 rad further back than the held −0.2 rad for 20 s: the
        // cap, half of it on each hip (−0.5 × −0.2 × 20 s = 2 rad would be
        // far past it).
        let c = held(-0.4, [30.0, 30.0], 1000);
        for leg in &c.legs {
            assert!((leg[2] - PITCH_HOLD_MAX / 2.0).abs() < 1e-9, "{c:?}");
        }
        // Within the cap it is the integral: 0.4 s more of 0.2 rad past the
        // held pitch adds 0.5 × 0.2 × 0.4 / 2 = 0.02 rad on each hip (from
        // 1.8 s, once the estimate has settled, to 2.2 s, before the cap).
        let (a, b) = (held(-0.4, [0.0; 2], 90), held(-0.4, [0.0; 2], 110));
        let grown = b.legs[0][2] - a.legs[0][2];
        assert!((grown - 0.02).abs() < 2e-3, "{grown}");
        assert!(b.legs[0][2] < PITCH_HOLD_MAX / 2.0, "{b:?}");
        assert_eq!(a.legs[0][2], a.legs[1][2]);
        assert_eq!(a.legs[0][4], a.legs[0][2], "in the air: the hold alone");
        // Held at its own pitch, the hold stops growing once the estimate
        // has settled on it.
        let (a, b) = (
            held(-0.2, [30.0, 30.0], 500),
            held(-0.2, [30.0, 30.0], 1000),
        );
        assert!((a.legs[0][2] - b.legs[0][2]).abs() < 1e-6, "{a:?} {b:?}");
    }

    /// The stance ankle turns against the sensed pitch in the leg's share of
    /// the load: a leg in the air gets the hold alone.
    #[test]
    fn the_stance_ankle_turns_against_the_pitch_by_its_load() {
        let loaded = held(0.1, [60.0, 0.0], 500);
        let hold = loaded.legs[1][4];
        assert!((loaded.legs[0][4] - hold - 0.1).abs() < 5e-3, "{loaded:?}");
        assert_eq!(loaded.legs[1][2], loaded.legs[0][2]);
    }

    /// The gauge follows each step's landed-over-aimed reading by its share,
    /// skips readings outside its range (a foot landing behind, a stumble),
    /// never aims longer than the plan nor shorter than 70 % of it, and
    /// counts a touchdown only after a foot has been off the ground for
    /// three cycles.
    #[test]
    fn the_step_gauge_aims_short_by_the_overreach_it_reads() {
        let mut g = StepGauge::default();
        assert_eq!(g.pace(), 1.0);
        for _ in 0..40 {
            g.fold(0.088, 0.080);
        }
        assert!((g.pace() - 1.0 / 1.1).abs() < 1e-4, "{}", g.pace());
        assert_eq!(g.readings(), 40);
        let before = g.pace();
        for (landed, aimed) in [(-0.01, 0.08), (0.2, 0.08), (0.08, 0.0), (f64::NAN, 0.08)] {
            g.fold(landed, aimed);
        }
        assert_eq!((g.pace(), g.readings()), (before, 40));
        for _ in 0..40 {
            g.fold(0.06, 0.08);
        }
        assert_eq!(g.pace(), 1.0);
        for _ in 0..40 {
            g.fold(0.15, 0.08);
        }
        assert_eq!(g.pace(), PACE_MIN);
        let mut g = StepGauge::default();
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
}
