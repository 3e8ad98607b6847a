//! One walking trial of the NAO: build the robot for p, stand it at the
//! origin facing +x in the walk's posture, walk for the trial's duration, stop
//! early on a fall. A pure function of (p, seed, duration, settings).
//!
//! # Per-trial noise (all from the trial's seed)
//! Sized, as the first LIP-3D feasibility study of this NAO found, at 3–5× "tiny" so that success rates
//! between 0 and 1 appear near the limits of stability while the expert set
//! keeps walking:
//! - initial pose jitter: every joint uniform ±[`INIT_JITTER_DEG`]°;
//! - joint sensor noise: N(0, [`SENSOR_NOISE_DEG`]°) per joint per cycle;
//! - actuator noise: N(0, [`ACTUATOR_NOISE_RAD_S`]) rad/s added to each command;
//! - ground friction: uniform in [`FRICTION_RANGE`].

use protocol::measurement::Measurement;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::balance::{Balance, StepGauge};
use super::footwork::{ahead_turned, Footwork, Tracker};
use super::model::{ModelError, NaoModel};
use super::sim::{fallen, standing_angles, Perception, Sim, SimError, SimSettings, Start, CYCLE_S};
use super::walk::{Gait, GaitConfig, Paced, WalkParams};
use crate::noise::gauss;
use protocol::params::ParamValues;

/// The walk a trial runs: the engine's plan ([`GaitConfig::ENGINE`]),
/// balanced from the robot's sensors ([`super::balance`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Engine {
    /// Whether the balance and the step gauge correct the plan (off: the
    /// plan played as it is, to measure what the feedback carries).
    pub feedback: bool,
}

impl Default for Engine {
    fn default() -> Self {
        Self::WALK
    }
}

impl Engine {
    /// The walk naofarm ships.
    pub const WALK: Self = Self { feedback: true };

    /// The same plan with the feedback switched off.
    #[must_use]
    pub fn without_feedback(self) -> Self {
        Self { feedback: false }
    }
}

/// Initial joint jitter, ± degrees.
pub const INIT_JITTER_DEG: f64 = 2.0;
/// Joint sensor noise σ, degrees.
pub const SENSOR_NOISE_DEG: f64 = 1.0;
/// Actuator noise σ, rad/s.
pub const ACTUATOR_NOISE_RAD_S: f64 = 0.1;
/// Ground friction spread.
pub const FRICTION_RANGE: (f64, f64) = (0.7, 1.1);
/// Gyro noise σ, rad/s.
pub const GYRO_NOISE_RAD_S: f64 = 0.05;
/// Accelerometer noise σ, m/s².
pub const ACCEL_NOISE_M_S2: f64 = 0.2;
/// Foot force sensor noise σ, N.
pub const FORCE_NOISE_N: f64 = 1.0;

/// What one trial did: its measurement, and how it was made.
#[derive(Debug, Clone, PartialEq)]
pub struct NaoTrial {
    /// The trial's seed.
    pub seed: u64,
    /// What it measured.
    pub measurement: Measurement,
    /// Whether the fall was the physics diverging ([`SimError::Diverged`]),
    /// counted as a fall with no distance.
    pub diverged: bool,
    /// Every joint that went past one of its stops (read at the end of each
    /// cycle), at its worst, in model order.
    pub stop_excess: Vec<StopExcess>,
    /// Every joint whose command the servo clamped to its speed cap in some
    /// cycle, with how many cycles, in model order.
    pub speed_capped: Vec<SpeedCapped>,
    /// Cycles run (the trial's end or fall).
    pub cycles: u64,
    /// The distance walked split by what the feet did (over the cycles run;
    /// a diverged trial's up to its last sane cycle).
    pub footwork: Footwork,
    /// Physics steps per cycle it ran at.
    pub substeps: u32,
}

/// How often a joint's commanded speed was beyond its cap during a trial:
/// the servo then turned at the cap and the joint lagged its target.
#[derive(Debug, Clone, PartialEq)]
pub struct SpeedCapped {
    /// The joint's name.
    pub joint: String,
    /// Cycles whose command the servo clamped.
    pub cycles: u64,
}

/// How far a joint went past one of its stops during a trial, at its worst.
#[derive(Debug, Clone, PartialEq)]
pub struct StopExcess {
    /// The joint's name.
    pub joint: String,
    /// The excess, rad (> 0).
    pub rad: f64,
    /// When, simulated s.
    pub time_s: f64,
}

/// Each joint's worst excess over its stops so far, rad, and when.
struct Overruns(Vec<Option<(f64, f64)>>);

impl Overruns {
    fn new(model: &NaoModel) -> Self {
        Self(vec![None; model.joints.len()])
    }

    fn fold(&mut self, model: &NaoModel, angles: &[f64], t: f64) {
        for ((j, a), w) in model.joints.iter().zip(angles).zip(&mut self.0) {
            let e = (j.limits_rad.0 - a).max(a - j.limits_rad.1);
            if e > w.map_or(0.0, |w| w.0) {
                *w = Some((e, t));
            }
        }
    }

    fn list(&self, model: &NaoModel) -> Vec<StopExcess> {
        model
            .joints
            .iter()
            .zip(&self.0)
            .filter_map(|(j, w)| {
                w.map(|(rad, time_s)| StopExcess {
                    joint: j.name.clone(),
                    rad,
                    time_s,
                })
            })
            .collect()
    }
}

/// Counts, per joint, the cycles whose command is beyond the joint's speed cap.
struct Capped {
    caps: Vec<Option<f32>>,
    cycles: Vec<u64>,
}

impl Capped {
    fn new(sim: &Sim) -> Self {
        let caps = sim.speed_caps();
        let cycles = vec![0; caps.len()];
        Self { caps, cycles }
    }

    /// The same test as [`Sim::step`]'s clamp, in its precision.
    fn fold(&mut self, commands: &[f64]) {
        for ((cap, n), c) in self.caps.iter().zip(&mut self.cycles).zip(commands) {
            if cap.is_some_and(|cap| (*c as f32).abs() > cap) {
                *n += 1;
            }
        }
    }

    fn list(&self, model: &NaoModel) -> Vec<SpeedCapped> {
        model
            .joints
            .iter()
            .zip(&self.cycles)
            .filter(|(_, n)| **n > 0)
            .map(|(j, n)| SpeedCapped {
                joint: j.name.clone(),
                cycles: *n,
            })
            .collect()
    }
}

/// Why a trial could not run.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum NaoTrialError {
    /// The morphology cannot be built.
    #[error(transparent)]
    Model(#[from] ModelError),
    /// The simulation could not start.
    #[error(transparent)]
    Sim(#[from] SimError),
    /// A trial's thread panicked (a bug): the panic's message.
    #[error("a trial thread panicked: {0}")]
    Panicked(String),
}

/// The walk's plan of `walk` over `duration_s` with the constants `cfg`, on
/// the body `params` builds: what [`planned_travel_m`], [`planned_step_m`]
/// and [`reach_step_m`] read.
fn plan(
    robot_type: u8,
    params: &ParamValues,
    walk: WalkParams,
    duration_s: f64,
    cfg: GaitConfig,
) -> Result<Gait, NaoTrialError> {
    let model = NaoModel::with_params(robot_type, params)?;
    Ok(Gait::with_config(&model, walk, duration_s, cfg))
}

/// How far the walk's plan carries the hip forward over a trial of
/// `duration_s`, m: what a trial walks if it walks as planned (no sliding
/// or lunging passed off as walking).
pub fn planned_travel_m(
    robot_type: u8,
    params: &ParamValues,
    duration_s: f64,
) -> Result<f64, NaoTrialError> {
    let cfg = GaitConfig::ENGINE.with_params(params);
    let gait = plan(robot_type, params, params.walk(), duration_s, cfg)?;
    Ok(gait.state(duration_s).hip[0] - gait.state(0.0).hip[0])
}

/// The full step the walk's plan takes, m: `xlength_step_max`, or shorter
/// where the legs cannot swing it in time ([`super::walk::reachable_step`]).
pub fn planned_step_m(robot_type: u8, params: &ParamValues) -> Result<f64, NaoTrialError> {
    let cfg = GaitConfig::ENGINE.with_params(params);
    Ok(plan(robot_type, params, params.walk(), 0.0, cfg)?.step_length())
}

/// The longest step the legs swing in time under the hip pitch's speed cap,
/// m: the step the engine plans for an unbounded ask
/// ([`super::walk::reachable_step`]).
pub fn reach_step_m(robot_type: u8, params: &ParamValues) -> Result<f64, NaoTrialError> {
    let cfg = GaitConfig::ENGINE.with_params(params);
    let unbounded = WalkParams {
        step_length: f64::INFINITY,
        ..params.walk()
    };
    Ok(plan(robot_type, params, unbounded, 0.0, cfg)?.step_length())
}

/// Runs one trial of parameter set `params` (named; unset ones at expert).
pub fn run(
    robot_type: u8,
    params: &ParamValues,
    seed: u64,
    duration_s: f64,
    settings: SimSettings,
    engine: Engine,
) -> Result<NaoTrial, NaoTrialError> {
    run_observed(
        robot_type,
        params,
        seed,
        duration_s,
        settings,
        engine,
        &mut |_, _, _| {},
    )
}

/// [`run`], calling `observe` after every cycle with the simulation, what it
/// perceives and the joint targets the cycle's commands steered to (model
/// order: the plan's, with the balance's correction), to
/// record every body's pose with [`Sim::body_poses`] for a replay, to trace
/// how the joints track, or to check the robot.
pub fn run_observed(
    robot_type: u8,
    params: &ParamValues,
    seed: u64,
    duration_s: f64,
    mut settings: SimSettings,
    engine: Engine,
    observe: &mut dyn FnMut(&Sim, &Perception, &[f64]),
) -> Result<NaoTrial, NaoTrialError> {
    let model = NaoModel::with_params(robot_type, params)?;
    let walk: WalkParams = params.walk();
    let cfg = GaitConfig::ENGINE.with_params(params);
    let gait = Gait::with_config(&model, walk, duration_s, cfg);
    let mut balance = engine.feedback.then(Balance::new);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let rest = standing_angles(&model);
    let q0 = gait.targets(&rest, 0.0);
    let jitter = INIT_JITTER_DEG.to_radians();
    let start: Vec<f64> = q0
        .iter()
        .map(|q| q + rng.random_range(-jitter..=jitter))
        .collect();
    settings.friction = rng.random_range(FRICTION_RANGE.0..=FRICTION_RANGE.1);
    let mut sim = Sim::new(&model, settings, &Start::upright(start))?;
    let p0 = sim.perceive().torso_position_m;
    let cycles = (duration_s / CYCLE_S).round() as u64;
    let sensor = SENSOR_NOISE_DEG.to_radians();
    let mut q_now = q0;
    let mut perception = sim.perceive();
    let mut fall_time_s = None;
    let mut overruns = Overruns::new(&model);
    let mut capped = Capped::new(&sim);
    let mut footwork = Tracker::new(&sim, &perception);
    // With the feedback, the plan walked at the pace its sensed steps call for.
    let mut paced = engine.feedback.then(|| Pacing {
        gauge: StepGauge::default(),
        plan: Paced::new(),
        last_aim: None,
        prior_q: Vec::new(),
    });
    // A cycle's sensed joint angles, kept for the next cycle's touchdown in
    // `Pacing::prior_q` (the two buffers swapped).
    let mut sensed_q = Vec::new();
    let mut run = 0;
    // An exploded simulation is a fall, never a distance.
    let mut diverged_at = None;
    for k in 0..cycles {
        let t = k as f64 * CYCLE_S;
        // Where the swing foot of the step now under way is aimed to land,
        // and that of the step before, as aimed at its last cycle.
        let mut aim_now = None;
        let next = match paced.as_mut() {
            None => gait.state(t + CYCLE_S),
            Some(pacing) => {
                let pace = pacing.gauge.pace();
                if let Some(step) = gait.step_at(t) {
                    let planned = gait.foothold(step + 1) - gait.foothold(step);
                    aim_now = Some((step, pace * planned));
                    if gait.step_at(t + CYCLE_S) != Some(step) {
                        pacing.last_aim = aim_now;
                    }
                }
                pacing.plan.state(&gait, t + CYCLE_S, pace)
            }
        };
        let q_next = gait.targets_of(&rest, &next, [0.0; 2]);
        let mut landing = None;
        let aim = match balance.as_mut() {
            None => None,
            Some(b) => {
                let sensed = noisy(&perception, &mut rng);
                let c = b.update(&sensed, CYCLE_S);
                footwork.fold_tilt(b.tilt()[1], &perception);
                if let Some(pacing) = paced.as_mut() {
                    landing = pacing.gauge.touchdown(&sensed);
                }
                // The plan's targets, or with the feet placed against the
                // forward lean.
                let leaned;
                let planned = if c.lean == [0.0; 2] {
                    &q_next
                } else {
                    leaned = gait.targets_of(&rest, &next, c.lean);
                    &leaned
                };
                Some(gait.corrected(planned, &c.legs))
            }
        };
        let keep = paced.is_some();
        sensed_q.clear();
        let cmd: Vec<f64> = perception
            .joint_angles_rad
            .iter()
            .zip(&q_now)
            .zip(&q_next)
            .enumerate()
            .map(|(j, ((m, a), b))| {
                let measured = m + sensor * gauss(&mut rng);
                if keep {
                    sensed_q.push(measured);
                }
                let target = aim.as_ref().map_or(*b, |q| q[j]);
                (b - a) / CYCLE_S
                    + super::sim::SERVO_GAIN * (target - measured)
                    + ACTUATOR_NOISE_RAD_S * gauss(&mut rng)
            })
            .collect();
        if let (Some(side), Some(pacing)) = (landing, paced.as_mut()) {
            // The landing foot's step: the one under way, or (landing just
            // after its end) the one before. The first two, half steps from
            // standing, are not read.
            let swung = |a: &Option<(usize, f64)>| a.filter(|(k, _)| *k >= 2 && 1 - k % 2 == side);
            if let Some((_, aimed)) = swung(&aim_now).or(swung(&pacing.last_aim)) {
                // Along the walk's heading (the torso's sensed turn turned
                // back), from the cycle before the touchdown, while the other
                // foot still carried.
                let turn = balance.as_ref().map_or(0.0, Balance::turn);
                let landed = ahead_turned(&model, sim.foot_bodies(), side, &pacing.prior_q, turn);
                pacing.gauge.fold(landed, aimed);
            }
        }
        if let (true, Some(pacing)) = (keep, paced.as_mut()) {
            std::mem::swap(&mut pacing.prior_q, &mut sensed_q);
        }
        capped.fold(&cmd);
        run = k + 1;
        perception = match sim.step(&cmd) {
            Ok(p) => p,
            Err(SimError::Diverged(t)) => {
                diverged_at = Some(t);
                break;
            }
            Err(e) => return Err(e.into()),
        };
        overruns.fold(&model, &perception.joint_angles_rad, perception.time_s);
        let steered = aim.as_deref().unwrap_or(&q_next);
        footwork.fold(&sim, &perception, steered);
        observe(&sim, &perception, steered);
        q_now = q_next;
        if fallen(&perception) {
            fall_time_s = Some(perception.time_s);
            break;
        }
    }
    let p = perception.torso_position_m;
    let measurement = match diverged_at {
        Some(t) => Measurement {
            fell: true,
            x_m: 0.0,
            y_m: 0.0,
            fall_time_s: Some(t),
            sim_time_s: t,
        },
        None => Measurement {
            fell: fall_time_s.is_some(),
            x_m: p[0] - p0[0],
            y_m: p[1] - p0[1],
            fall_time_s,
            sim_time_s: perception.time_s,
        },
    };
    Ok(NaoTrial {
        seed,
        measurement,
        diverged: diverged_at.is_some(),
        stop_excess: overruns.list(&model),
        speed_capped: capped.list(&model),
        cycles: run,
        footwork: footwork.footwork(),
        substeps: settings.substeps,
    })
}

/// The step gauge in a trial: the plan at its pace, and the gauge that sets
/// the pace from the landings.
struct Pacing {
    gauge: StepGauge,
    plan: Paced,
    /// The last finished step and where its swing foot was aimed to land, m.
    last_aim: Option<(usize, f64)>,
    /// The last cycle's sensed joint angles (empty before the first cycle,
    /// which then reads as no reading).
    prior_q: Vec<f64>,
}

/// The sensors of `p` as the balance reads them: gyro, accelerometer
/// and foot forces each with their noise.
fn noisy(p: &Perception, rng: &mut ChaCha8Rng) -> Perception {
    let mut s = p.clone();
    for g in &mut s.gyro_rad_s {
        *g += GYRO_NOISE_RAD_S * gauss(rng);
    }
    for a in &mut s.accel_m_s2 {
        *a += ACCEL_NOISE_M_S2 * gauss(rng);
    }
    for f in s.foot_force_n.iter_mut().flatten() {
        *f += FORCE_NOISE_N * gauss(rng);
    }
    s
}

/// How many trials [`run_many`] runs, from which seed, on how many threads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Batch {
    /// The first trial's seed (then +1 per trial, wrapping).
    pub seed0: u64,
    /// Number of trials.
    pub n: u64,
    /// Threads (clamped to 1..=64).
    pub threads: usize,
}

/// Runs a [`Batch`] of trials of one parameter set with physics `settings`;
/// results in seed order whatever the threads.
pub fn run_many(
    robot_type: u8,
    params: &ParamValues,
    batch: Batch,
    duration_s: f64,
    settings: SimSettings,
    engine: Engine,
) -> Result<Vec<NaoTrial>, NaoTrialError> {
    let Batch { seed0, n, threads } = batch;
    in_parallel(n, threads, |i| {
        run(
            robot_type,
            params,
            seed0.wrapping_add(i),
            duration_s,
            settings,
            engine,
        )
    })
    .map_err(NaoTrialError::Panicked)?
    .into_iter()
    .collect()
}

/// `f(0), f(1), …, f(n − 1)` on up to `threads` threads (clamped to 1..=64),
/// in index order whatever the threads; a panic in `f` is an error with its
/// message.
pub fn in_parallel<T: Send>(
    n: u64,
    threads: usize,
    f: impl Fn(u64) -> T + Sync,
) -> Result<Vec<T>, String> {
    let next = std::sync::atomic::AtomicU64::new(0);
    let mut out: Vec<(u64, T)> = Vec::new();
    std::thread::scope(|s| {
        let handles: Vec<_> = (0..threads.clamp(1, 64))
            .map(|_| {
                s.spawn(|| {
                    let mut mine = Vec::new();
                    loop {
                        let i = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                        if i >= n {
                            break mine;
                        }
                        mine.push((i, f(i)));
                    }
                })
            })
            .collect();
        for h in handles {
            match h.join() {
                Ok(mine) => out.extend(mine),
                Err(p) => {
                    return Err(p
                        .downcast_ref::<&str>()
                        .map(|s| (*s).to_string())
                        .or_else(|| p.downcast_ref::<String>().cloned())
                        .unwrap_or_else(|| "(no message)".into()))
                }
            }
        }
        Ok(())
    })?;
    out.sort_by_key(|(i, _)| *i);
    if out.len() as u64 != n {
        return Err(format!("{} of {n} came back", out.len()));
    }
    Ok(out.into_iter().map(|(_, t)| t).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(seed: u64, duration_s: f64) -> NaoTrial {
        let p = ParamValues::default();
        run(
            0,
            &p,
            seed,
            duration_s,
            SimSettings::default(),
            Engine::WALK,
        )
        .unwrap()
    }

    #[test]
    fn same_seed_same_bits_other_seed_other_numbers() {
        let (a, b, c) = (at(11, 3.0), at(11, 3.0), at(12, 3.0));
        assert_eq!(a.measurement.x_m.to_bits(), b.measurement.x_m.to_bits());
        assert_eq!(a.measurement.y_m.to_bits(), b.measurement.y_m.to_bits());
        assert_ne!(a.measurement.x_m.to_bits(), c.measurement.x_m.to_bits());
        // Seed order whatever the threads.
        let batch = |threads| Batch {
            seed0: 11,
            n: 3,
            threads,
        };
        let many = |threads| {
            let p = ParamValues::default();
            run_many(
                0,
                &p,
                batch(threads),
                3.0,
                SimSettings::default(),
                Engine::WALK,
            )
            .unwrap()
        };
        let one = many(1);
        assert_eq!(one, many(2));
        assert_eq!(one[0], a);
    }

    /// The first seconds of a longer trial are the shorter trial, bit for
    /// bit: nothing in the plan or the controller looks ahead to the trial's
    /// end (the step gauge, the lean placing, the pitch hold, the swinging
    /// arms), so how long a walk lasts is read by running it for longer.
    #[test]
    fn a_longer_trial_begins_as_the_shorter_one_bit_for_bit() {
        let torso = |duration_s: f64| {
            let mut poses = Vec::new();
            let t = run_observed(
                0,
                &ParamValues::default(),
                3,
                duration_s,
                SimSettings::default(),
                Engine::WALK,
                &mut |_, p, _| {
                    poses.push((
                        p.torso_position_m.map(f64::to_bits),
                        p.torso_rotation.map(f64::to_bits),
                    ));
                },
            )
            .unwrap();
            assert!(!t.measurement.fell, "{duration_s} s: fell");
            poses
        };
        let (short, long) = (torso(4.0), torso(6.0));
        assert_eq!(short.len(), 200);
        assert_eq!(long.len(), 300);
        assert!(
            short[..] == long[..short.len()],
            "the 6 s trial parts from the 4 s one"
        );
    }

    /// Type 4's toes rest 1° from their stop and the walk drags them along
    /// the ground: their stops hold (within 1° over 10 trials of 10 s).
    #[test]
    fn type_4s_toes_hold_their_stops() {
        let batch = Batch {
            seed0: 777,
            n: 10,
            threads: 2,
        };
        let p = ParamValues::default();
        let ts = run_many(4, &p, batch, 10.0, SimSettings::default(), Engine::WALK).unwrap();
        let toes = ts
            .iter()
            .flat_map(|t| &t.stop_excess)
            .filter(|e| e.joint.ends_with("le7"))
            .map(|e| e.rad.to_degrees())
            .fold(0.0, f64::max);
        let s = ts.iter().filter(|t| !t.measurement.fell).count();
        println!("type 4: {s} of 10 stand, toes at worst {toes:.3}° past a stop");
        assert!(toes < 1.0, "a toe {toes:.2}° past its stop");
    }

    /// Falls happen because of physics: a deep crouch (the legs at 40 % of
    /// their length) with long steps falls in some trials, nothing in the
    /// trial decides it.
    #[test]
    fn a_walk_the_legs_cannot_carry_falls() {
        let named = [
            ("ratio_flexion".to_string(), 0.4),
            ("xlength_step_max".to_string(), 0.25),
        ];
        let p = ParamValues::from_named(&named).unwrap();
        let batch = Batch {
            seed0: 0,
            n: 4,
            threads: 2,
        };
        let ts = run_many(0, &p, batch, 10.0, SimSettings::default(), Engine::WALK).unwrap();
        let falls = ts.iter().filter(|t| t.measurement.fell).count();
        assert!(falls > 0, "none of 4 fell");
        assert!(
            ts.iter().all(|t| !t.diverged),
            "a fall is the physics', not a divergence"
        );
    }
}
