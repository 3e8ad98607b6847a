//! What a trial's feet did with the distance it walked: the torso's advance
//! `x_m` split, exactly, into the feet's travel between plants (stepping),
//! their travel while planted (sliding) and the torso's advance over the
//! feet (lean). A walk that covers its distance by stepping walks; sliding
//! or a lean passed off as walking shows in the other two terms.
//!
//! A foot is *planted* while the ground carries at least [`PLANTED_N`] of
//! it, whatever its tilt: a foot rolling over its heel or toe moves its
//! centre by about a millimetre (the centre sits a centimetre above the
//! sole's edge, so a roll of θ rad moves it by about θ cm), so what a
//! planted foot's centre travels is its sliding. Read from
//! the simulation's ground truth at the end of each 20 ms cycle; the terms
//! sum to the torso's advance over the cycles read. Reads only: it must not
//! change a trial's bits.
//!
//! Stepping further than planned has a cause of its own: legs that land
//! spread wider (or narrower) than their targets put them. At each
//! touchdown the tracker compares the feet's distance along the torso's x
//! axis from the forward kinematics of the true joint angles with that of
//! the angles the servos were steered to (`overreach_m`). In the world it
//! records the step each touchdown takes (`spacing_m`) and how far the
//! foot that landed before has moved on since (`settle_m`): a foot that
//! skids on after it lands carries the torso further than its step.
//!
//! How the torso is carried shows in `torso_pitch_deg`, its mean pitch over
//! the cycles read: a fast walk that leans far back stands on its heels, and
//! its distance swings with the physics step. The balance's own reading of
//! that pitch shows beside it in `tilt_error_deg`, its estimate's mean error.

use super::kinematics::{self, Iso};
use super::model::NaoModel;
use super::sim::{Perception, Sim};

/// Vertical load from which a foot counts as planted, N (a fifth of the
/// robot's weight).
pub const PLANTED_N: f64 = 10.0;

/// Cycles a foot must have been in the air for its landing to count as a
/// touchdown for `overreach_m` (60 ms: a bounce does not count).
pub const AIR_CYCLES: u32 = 3;

/// The torso's forward advance split by what the feet did, m. `stepping_m +
/// sliding_m + lean_m` is the torso's advance along x over the trial.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize)]
pub struct Footwork {
    /// The feet's mean forward travel while not planted (swing, roll-over), m.
    pub stepping_m: f64,
    /// The feet's mean forward travel while planted (negative: sliding back), m.
    pub sliding_m: f64,
    /// The torso's advance over the feet's midpoint, m.
    pub lean_m: f64,
    /// Times a foot came to be planted after it was not (a foot that
    /// bounces on landing counts again).
    pub plants: u32,
    /// Mean over touchdowns: how much further ahead of the other foot the
    /// landing foot is, along the torso's x axis, than the joint targets of
    /// that cycle put it (forward kinematics of the true angles less that of
    /// the targets), m. Positive: the legs land spread wider than aimed.
    pub overreach_m: f64,
    /// Touchdowns `overreach_m` averages (a landing after at least
    /// [`AIR_CYCLES`] in the air).
    pub touchdowns: u32,
    /// The torso's mean forward pitch over the cycles read (its x axis
    /// below the horizon), degrees; negative: leaning back.
    pub torso_pitch_deg: f64,
    /// Mean over touchdowns: how far the landing foot's centre is ahead of
    /// the other's along the world's x axis as it lands, m (the step it
    /// took, to compare with the plan's).
    pub spacing_m: f64,
    /// Mean over touchdowns after the first: how far the other foot has moved
    /// forward since its own touchdown, m. A foot that lands and stays put
    /// moves 0; what a landed foot skids on before it holds shows here, and
    /// the torso is carried on by it.
    pub settle_m: f64,
    /// The balance's pitch estimate less the torso's true pitch, mean
    /// over the cycles it estimated, degrees (negative: it reads more lean
    /// back than there is; 0 for a walk that estimates none).
    pub tilt_error_deg: f64,
}

impl Footwork {
    /// The mean split of `trials` (`plants` rounded down); none if empty.
    #[must_use]
    pub fn mean<'a>(trials: impl IntoIterator<Item = &'a Footwork>) -> Option<Footwork> {
        let mut sum = Footwork::default();
        let mut plants = 0u64;
        let mut touchdowns = 0u64;
        let mut reach = 0.0;
        let (mut spacing, mut settle) = (0.0, 0.0);
        let mut pitch = 0.0;
        let mut tilt_error = 0.0;
        let mut n = 0u32;
        for w in trials {
            sum.stepping_m += w.stepping_m;
            sum.sliding_m += w.sliding_m;
            sum.lean_m += w.lean_m;
            plants += u64::from(w.plants);
            // Weighted by touchdowns: the mean over every touchdown.
            reach += w.overreach_m * f64::from(w.touchdowns);
            spacing += w.spacing_m * f64::from(w.touchdowns);
            settle += w.settle_m * f64::from(w.touchdowns);
            touchdowns += u64::from(w.touchdowns);
            pitch += w.torso_pitch_deg;
            tilt_error += w.tilt_error_deg;
            n += 1;
        }
        (n > 0).then(|| {
            let k = f64::from(n);
            let per_touchdown = |sum: f64| {
                if touchdowns > 0 {
                    sum / touchdowns as f64
                } else {
                    0.0
                }
            };
            Footwork {
                stepping_m: sum.stepping_m / k,
                sliding_m: sum.sliding_m / k,
                lean_m: sum.lean_m / k,
                plants: u32::try_from(plants / u64::from(n)).unwrap_or(u32::MAX),
                overreach_m: per_touchdown(reach),
                touchdowns: u32::try_from(touchdowns / u64::from(n)).unwrap_or(u32::MAX),
                torso_pitch_deg: pitch / k,
                spacing_m: per_touchdown(spacing),
                settle_m: per_touchdown(settle),
                tilt_error_deg: tilt_error / k,
            }
        })
    }
}

/// Folds a trial's cycles into its [`Footwork`].
#[derive(Debug, Clone)]
pub struct Tracker {
    work: Footwork,
    feet: [[f64; 3]; 2],
    planted: [bool; 2],
    offset0: f64,
    offset: f64,
    /// Cycles each foot has been in the air.
    air: [u32; 2],
    reach_sum: f64,
    spacing_sum: f64,
    settle_sum: f64,
    /// Where each foot's centre was along x at its last touchdown, m.
    landed_at: [Option<f64>; 2],
    pitch_sum: f64,
    cycles: u32,
    tilt_error_sum: f64,
    estimates: u32,
}

impl Tracker {
    /// Starts from the robot as it stands before its first cycle.
    #[must_use]
    pub fn new(sim: &Sim, p: &Perception) -> Self {
        let feet = sim.feet_centres();
        let offset = p.torso_position_m[0] - (feet[0][0] + feet[1][0]) / 2.0;
        Self {
            work: Footwork::default(),
            feet,
            planted: [planted(p, 0), planted(p, 1)],
            offset0: offset,
            offset,
            air: [0, 0],
            reach_sum: 0.0,
            spacing_sum: 0.0,
            settle_sum: 0.0,
            landed_at: [None, None],
            pitch_sum: 0.0,
            cycles: 0,
            tilt_error_sum: 0.0,
            estimates: 0,
        }
    }

    /// Adds one cycle, read after it; `targets` are the joint angles the
    /// servos were steered to in it (model order).
    pub fn fold(&mut self, sim: &Sim, p: &Perception, targets: &[f64]) {
        let centres = sim.feet_centres();
        for (side, centre) in centres.iter().enumerate() {
            let now = planted(p, side);
            let was = self.planted[side];
            let dx = centre[0] - self.feet[side][0];
            if was && now {
                self.work.sliding_m += dx / 2.0;
            } else {
                self.work.stepping_m += dx / 2.0;
            }
            if now && !was {
                self.work.plants += 1;
                if self.air[side] >= AIR_CYCLES {
                    let (model, feet) = (sim.model(), sim.foot_bodies());
                    let landed = ahead(model, feet, side, &p.joint_angles_rad);
                    let aimed = ahead(model, feet, side, targets);
                    if (landed - aimed).is_finite() {
                        let other = centres[1 - side][0];
                        self.reach_sum += landed - aimed;
                        self.spacing_sum += centre[0] - other;
                        // The first touchdown has no earlier one to settle
                        // from: the foot stood there, which is 0.
                        self.settle_sum += self.landed_at[1 - side].map_or(0.0, |x| other - x);
                        self.landed_at[side] = Some(centre[0]);
                        self.work.touchdowns += 1;
                    }
                }
            }
            self.air[side] = if now {
                0
            } else {
                self.air[side].saturating_add(1)
            };
            self.planted[side] = now;
            self.feet[side] = *centre;
        }
        self.offset = p.torso_position_m[0] - (self.feet[0][0] + self.feet[1][0]) / 2.0;
        self.pitch_sum += forward_pitch_deg(p.torso_rotation);
        self.cycles += 1;
    }

    /// Adds the balance's pitch estimate `estimate_rad` of the cycle
    /// whose (true) perception is `p`.
    pub fn fold_tilt(&mut self, estimate_rad: f64, p: &Perception) {
        self.tilt_error_sum += estimate_rad.to_degrees() - forward_pitch_deg(p.torso_rotation);
        self.estimates += 1;
    }

    /// The split so far.
    #[must_use]
    pub fn footwork(&self) -> Footwork {
        // A sum's mean over `n` readings; 0 when there were none.
        let mean = |sum: f64, n: u32| if n > 0 { sum / f64::from(n) } else { 0.0 };
        let per_touchdown = |sum: f64| mean(sum, self.work.touchdowns);
        Footwork {
            lean_m: self.offset - self.offset0,
            overreach_m: per_touchdown(self.reach_sum),
            spacing_m: per_touchdown(self.spacing_sum),
            settle_m: per_touchdown(self.settle_sum),
            torso_pitch_deg: mean(self.pitch_sum, self.cycles),
            tilt_error_deg: mean(self.tilt_error_sum, self.estimates),
            ..self.work
        }
    }
}

/// How far the x axis of a body turned by unit quaternion `[x, y, z, w]`
/// points below the horizon, degrees (negative: above it, leaning back).
#[must_use]
pub fn forward_pitch_deg([x, y, z, w]: [f64; 4]) -> f64 {
    // The x axis's z component in the world is 2(xz − wy).
    libm::asin((2.0 * (w * y - x * z)).clamp(-1.0, 1.0)).to_degrees()
}

/// How far foot `side`'s centre is ahead of the other's along the torso's
/// x axis with joint angles `q` (forward kinematics from the torso), m.
#[must_use]
pub fn ahead(model: &NaoModel, feet: [usize; 2], side: usize, q: &[f64]) -> f64 {
    apart(model, feet, side, q).map_or(f64::NAN, |[x, _]| x)
}

/// How far foot `side`'s centre is ahead of the other's along the torso's x
/// axis turned back by `turn` rad about the torso's z axis, with joint angles
/// `q` (m): with the torso's sensed turn, the spacing along the walk's
/// heading. At `turn` 0 it is [`ahead`], bit for bit.
#[must_use]
pub fn ahead_turned(model: &NaoModel, feet: [usize; 2], side: usize, q: &[f64], turn: f64) -> f64 {
    if turn == 0.0 {
        return ahead(model, feet, side, q);
    }
    // The torso's axes turned by `turn` in the walk's frame: x_walk =
    // x cos(turn) − y sin(turn).
    apart(model, feet, side, q).map_or(f64::NAN, |[x, y]| x * libm::cos(turn) - y * libm::sin(turn))
}

/// Foot `side`'s centre less the other's along the torso's x and y axes
/// with joint angles `q`; none for angles of another model.
fn apart(model: &NaoModel, feet: [usize; 2], side: usize, q: &[f64]) -> Option<[f64; 2]> {
    if q.len() != model.joints.len() {
        return None;
    }
    let g = kinematics::body_motions(model, q, &Iso::identity());
    let at = |i: usize| kinematics::moved(&g[i], model.bodies[i].centre);
    let (a, b) = (at(feet[side]), at(feet[1 - side]));
    Some([a[0] - b[0], a[1] - b[1]])
}

fn planted(p: &Perception, side: usize) -> bool {
    p.foot_force_n[side][2] >= PLANTED_N
}
