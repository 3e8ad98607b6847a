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

use super::sim::{Perception, Sim};

/// Vertical load from which a foot counts as planted, N (a fifth of the
/// robot's weight).
pub const PLANTED_N: f64 = 10.0;

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
}

impl Footwork {
    /// The mean split of `trials` (`plants` rounded down); none if empty.
    #[must_use]
    pub fn mean<'a>(trials: impl IntoIterator<Item = &'a Footwork>) -> Option<Footwork> {
        let mut sum = Footwork::default();
        let mut plants = 0u64;
        let mut n = 0u32;
        for w in trials {
            sum.stepping_m += w.stepping_m;
            sum.sliding_m += w.sliding_m;
            sum.lean_m += w.lean_m;
            plants += u64::from(w.plants);
            n += 1;
        }
        (n > 0).then(|| {
            let k = f64::from(n);
            Footwork {
                stepping_m: sum.stepping_m / k,
                sliding_m: sum.sliding_m / k,
                lean_m: sum.lean_m / k,
                plants: u32::try_from(plants / u64::from(n)).unwrap_or(u32::MAX),
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
        }
    }

    /// Adds one cycle, read after it.
    pub fn fold(&mut self, sim: &Sim, p: &Perception) {
        for (side, centre) in sim.feet_centres().iter().enumerate() {
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
            }
            self.planted[side] = now;
            self.feet[side] = *centre;
        }
        self.offset = p.torso_position_m[0] - (self.feet[0][0] + self.feet[1][0]) / 2.0;
    }

    /// The split so far.
    #[must_use]
    pub fn footwork(&self) -> Footwork {
        Footwork {
            lean_m: self.offset - self.offset0,
            ..self.work
        }
    }
}

fn planted(p: &Perception, side: usize) -> bool {
    p.foot_force_n[side][2] >= PLANTED_N
}
