//! Experiment files (TOML): what to optimise, how, and with which constants.
//!
//! A file is parsed strictly (unknown keys are errors) and then validated as a
//! whole; every error names the field (and the line when the TOML parser knows
//! it). Defaults are the paper's (Table III) and the CLOP reference's.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::params::Shown;
use crate::{keys, params};

/// Why an experiment file was refused.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum ExperimentError {
    /// The TOML could not be parsed into an experiment (syntax, unknown key, wrong type).
    #[error("experiment file: {0}")]
    Parse(String),
    /// A field has a value that makes no sense.
    #[error("experiment file: field `{field}`: {message}")]
    Invalid {
        /// Path of the offending field, e.g. `parameter[1].lower`.
        field: String,
        /// What is wrong with it.
        message: String,
    },
}

fn invalid(field: impl Into<String>, message: impl Into<String>) -> ExperimentError {
    ExperimentError::Invalid {
        field: field.into(),
        message: message.into(),
    }
}

/// How CLOP maps a parameter onto its internal `[-1, 1]` coordinate (`docs/spec/clop.md` §2).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ParamKind {
    /// Real, linear mapping.
    Linear,
    /// Integer, one cell per integer.
    Integer,
    /// Real, logarithmic mapping (`lower > 0`).
    Gamma,
    /// Integer, logarithmic mapping (`lower >= 1`).
    IntegerGamma,
}

/// One optimised parameter: a dimension of the space L.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ParamSpec {
    /// Identifier, one of [`params::KNOWN`].
    pub name: String,
    /// Mapping kind (default linear).
    #[serde(default = "default_kind")]
    pub kind: ParamKind,
    /// Lower bound (external units).
    pub lower: f64,
    /// Upper bound (external units).
    pub upper: f64,
    /// The expert value; absent means the registry's default.
    #[serde(default)]
    pub expert: Option<f64>,
}

fn default_kind() -> ParamKind {
    ParamKind::Linear
}

impl ParamSpec {
    /// The expert value, or the registry's default when the file gives none.
    #[must_use]
    pub fn expert_value(&self) -> f64 {
        self.expert
            .or_else(|| params::find(&self.name).map(|p| p.default))
            .unwrap_or((self.lower + self.upper) / 2.0)
    }
}

/// Which trial model the workers run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum TrialModel {
    /// The rebuilt NAO in rapier3d, walking (the real thing).
    #[default]
    Nao,
    /// A cheap deterministic noisy stand-in with the same parameter names.
    Synthetic,
}

impl TrialModel {
    /// Parses `nao` or `synthetic`.
    pub fn parse(s: &str) -> Result<Self, String> {
        match s {
            "nao" => Ok(Self::Nao),
            "synthetic" => Ok(Self::Synthetic),
            other => Err(format!(
                "unknown trial model `{other}` (expected `nao` or `synthetic`)"
            )),
        }
    }
}

/// Which walk engine the NAO's trials use (`walk = "…"`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum WalkEngine {
    /// The first engine: a LIP-3D plan played open loop at 0.40 s steps
    /// (the default, so experiments and journals from before the field keep
    /// their bits).
    #[default]
    OpenLoop,
    /// A LIP-3D plan at the league's pace, balanced at 50 Hz from the robot's
    /// own noisy sensors (`worker::nao::balance`).
    ClosedLoop,
}

/// A feedback gain (`hip_pitch_gain`, `ankle_pitch_gain`, `turn_place`, `step_aim`,
/// `lean_place`, `hip_roll_rate_gain`, `step_aim_heading`, `tilt_vector`,
/// `pitch_hold_gain`, `pitch_hold_rad`, `pitch_hold_ankle`, `step_aim_before`) needs a walk with
/// feedback: the open loop has none to give it to, so a parameter set for it
/// that names one is refused (by an experiment file and by `naofarm trial`).
pub fn gain_has_feedback(walk: WalkEngine, name: &str) -> Result<(), String> {
    let gain = params::find(name).is_some_and(|k| {
        matches!(
            k.param,
            params::Param::HipPitchGain
                | params::Param::AnklePitchGain
                | params::Param::TurnPlace
                | params::Param::StepAim
                | params::Param::LeanPlace
                | params::Param::HipRollRateGain
                | params::Param::StepAimHeading
                | params::Param::TiltVector
                | params::Param::PitchHoldGain
                | params::Param::PitchHold
                | params::Param::PitchHoldAnkle
                | params::Param::StepAimBefore
        )
    });
    if gain && walk == WalkEngine::OpenLoop {
        return Err(format!(
            "`{name}` is a gain of the closed-loop walk's feedback, and the open-loop walk has none"
        ));
    }
    Ok(())
}

impl WalkEngine {
    /// Every engine, by its name in experiment files.
    pub const ALL: [(&'static str, Self); 2] = [
        ("open-loop", Self::OpenLoop),
        ("closed-loop", Self::ClosedLoop),
    ];

    /// Parses an engine's name.
    pub fn parse(s: &str) -> Result<Self, String> {
        Self::ALL
            .iter()
            .find(|(n, _)| *n == s)
            .map(|(_, w)| *w)
            .ok_or_else(|| format!("unknown walk `{s}` (expected `open-loop` or `closed-loop`)"))
    }

    /// The engine's name in experiment files.
    #[must_use]
    pub fn name(self) -> &'static str {
        Self::ALL
            .iter()
            .find(|(_, w)| *w == self)
            .map_or("?", |(n, _)| n)
    }
}

/// Where the evolving process starts (`docs/spec/evolve.md`, Algorithm 1).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Start {
    /// ν′ undefined, H empty.
    #[default]
    Scratch,
    /// The expert set is evaluated first and becomes ν′.
    Expert,
}

/// The constants of pickOut (Algorithm 2); defaults from the paper's Table III.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PickOutConstants {
    /// Minimum success rate (default 0.75).
    pub success_rate: f64,
    /// Maximum my/mx (default 0.25).
    pub xy_ratio: f64,
    /// REJECT below m′x − α·e′x (default 3.0).
    pub alpha: f64,
    /// EQUIVALENT below m′x − β·e′x (default 1.0); β < α.
    pub beta: f64,
    /// ACCEPT when ex < γ·e′x (default 0.7).
    pub gamma: f64,
}

impl Default for PickOutConstants {
    fn default() -> Self {
        Self {
            success_rate: 0.75,
            xy_ratio: 0.25,
            alpha: 3.0,
            beta: 1.0,
            gamma: 0.7,
        }
    }
}

/// CLOP's settings (`docs/spec/clop.md` §10); defaults are the reference's for real runs.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ClopSettings {
    /// Confidence H (default 3).
    pub h: f64,
    /// Draw model strength in Elo (default 0 = binary).
    pub draw_elo: f64,
    /// Full quadratic (true, default) or diagonal only.
    pub correlations: bool,
    /// Gaussian prior precision λ (default 0.01).
    pub prior_strength: f64,
    /// Refresh schedule (default 0.1; 0 = after every outcome).
    pub refresh_rate: f64,
    /// Weight iterations per refresh (default 7; 0 = to convergence).
    pub max_weight_iterations: u32,
    /// Sampler steps per dimension (default 1000).
    pub n_mcmc: u32,
    /// Radius growth with n, ρ (default 0).
    pub localization_power: f64,
}

impl Default for ClopSettings {
    fn default() -> Self {
        Self {
            h: 3.0,
            draw_elo: 0.0,
            correlations: true,
            prior_strength: 0.01,
            refresh_rate: 0.1,
            max_weight_iterations: 7,
            n_mcmc: 1000,
            localization_power: 0.0,
        }
    }
}

/// How the workers' rapier3d integrates each 20 ms agent cycle of a NAO trial
/// (`[physics]`; ignored by the synthetic model). The default is the measured
/// balance of speed and fidelity to the league (`naofarm bench sim`); finer
/// steps, or a rotor inertia the league's robot does not have, keep joints
/// closer to their stops when a gait leans on them.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Physics {
    /// Physics steps per 20 ms cycle (1..=50).
    pub substeps: u32,
    /// Rapier solver iterations per step (1..=16).
    pub solver_iterations: u32,
    /// Inner PGS iterations per solver iteration (1..=200).
    pub pgs_iterations: u32,
    /// Reflected rotor inertia added to every motorised hinge, kg·m² (0..=0.1;
    /// MuJoCo's `armature`). The league's robot has none (0, the default).
    pub armature_kg_m2: f64,
    /// Natural frequency of the feet's contact with the ground, Hz (10..=10000;
    /// damping ratio 10). The default 500 is stiffer than rapier's own 60 Hz
    /// for contacts with a fixed body; `firm_stops` walks on the softer one.
    pub contact_hz: f64,
    /// Joint stops that hold within a physics step (the patch of the
    /// vendored rapier3d, `vendor/rapier3d/NAOFARM.md`): a joint within 3° of a
    /// stop gets a speculative limit row, which lets it reach the stop within
    /// the step and no further, and the limit rows are solved again after the
    /// contacts, so that a landing cannot push a joint through its stop.
    /// Off (the default): rapier's stops, engaged only past the stop.
    pub firm_stops: bool,
    /// With `firm_stops`, how near a stop a joint gets its speculative limit
    /// row, degrees (1..=20; default 3). A joint that comes at a stop faster
    /// than this per physics step passes it before its row is in place: the
    /// arms file's faster walk needs 8 (`docs/walk.md`, "The stop window").
    pub firm_stop_window_deg: f64,
    /// With `firm_stops`, a joint also gets its speculative limit row when
    /// its speed would carry it into the window within this many physics
    /// steps (0..=10; 0, the default: the window alone). A light link flung
    /// by a staggering walk crosses the whole window in one step and passes
    /// its stop before its row is in place: the capped lean file's corner
    /// `10011` so flings an elbow yaw 7.23° past its stop, and 1 step of
    /// look-ahead keeps it within 0.01° (`docs/walk.md`, "A stop row ahead
    /// of a flung joint").
    pub firm_stop_lookahead: u32,
    /// Weld the elbow yaws (`lae3`, `rae3`) at 0°, where the walk holds
    /// them (default false). With the arms swinging, at 5 ms steps those
    /// light links swing out against their servos, as they do not at 1 ms,
    /// and the fast walks lean on it (`docs/walk.md`, "What the look-ahead
    /// does not mend"); welded, a walk cannot.
    pub weld_elbow_yaws: bool,
    /// With it (`substeps`..=50), each trial draws its physics steps per
    /// cycle uniformly from `substeps..=substeps_max` by its seed, so that
    /// CLOP maximises the mean over a band of steps and cannot fit an
    /// optimum to one of them (`docs/walk.md`, "CLOP optimises into the
    /// time step"). 0 (the default): every trial takes `substeps`.
    pub substeps_max: u32,
}

impl std::fmt::Display for Physics {
    /// `10 x 2.000 ms steps per 20 ms cycle, 1 solver x 12 PGS iterations, armature 0 kg m^2`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} x {:.3} ms steps per 20 ms cycle, {} solver x {} PGS iterations, armature {} kg m^2",
            self.substeps,
            self.step_ms(),
            self.solver_iterations,
            self.pgs_iterations,
            self.armature_kg_m2
        )?;
        // The two later keys only when set, so a default run reads as before.
        if self.contact_hz != Self::default().contact_hz {
            write!(f, ", ground contact {} Hz", self.contact_hz)?;
        }
        if self.substeps_max != 0 {
            write!(
                f,
                ", drawn per trial from {}-{} steps per cycle",
                self.substeps, self.substeps_max
            )?;
        }
        if self.weld_elbow_yaws {
            write!(f, ", elbow yaws welded")?;
        }
        if self.firm_stops {
            write!(f, ", firm stops")?;
            if self.firm_stop_window_deg != Self::default().firm_stop_window_deg {
                write!(f, " within {} deg", self.firm_stop_window_deg)?;
            }
            match self.firm_stop_lookahead {
                0 => {}
                1 => write!(f, " or 1 step ahead")?,
                k => write!(f, " or {k} steps ahead")?,
            }
        }
        Ok(())
    }
}

impl Default for Physics {
    fn default() -> Self {
        Self {
            substeps: 2,
            solver_iterations: 1,
            pgs_iterations: 12,
            armature_kg_m2: 0.0,
            contact_hz: 500.0,
            firm_stops: false,
            firm_stop_window_deg: 3.0,
            firm_stop_lookahead: 0,
            weld_elbow_yaws: false,
            substeps_max: 0,
        }
    }
}

impl Physics {
    /// One physics step, ms: the 20 ms cycle over `substeps` (the coarsest
    /// step of a band).
    #[must_use]
    pub fn step_ms(&self) -> f64 {
        20.0 / f64::from(self.substeps.max(1))
    }

    /// The firm file's physics (`experiments/physical-technical-firm.toml`):
    /// firm stops, 28 PGS iterations and a 60 Hz ground at the farm's
    /// 2 × 10 ms steps (docs/walk.md, "Firm stops").
    #[must_use]
    pub fn firm() -> Self {
        Self {
            pgs_iterations: 28,
            contact_hz: 60.0,
            firm_stops: true,
            ..Self::default()
        }
    }

    /// Checks each count against its range; names the first one outside.
    pub fn validate(&self) -> Result<(), (&'static str, String)> {
        for (field, v, hi) in [
            ("substeps", self.substeps, 50),
            ("solver_iterations", self.solver_iterations, 16),
            ("pgs_iterations", self.pgs_iterations, 200),
        ] {
            if v == 0 || v > hi {
                return Err((field, format!("{v} is not in 1..={hi}")));
            }
        }
        let m = self.substeps_max;
        if m != 0 && !(self.substeps..=50).contains(&m) {
            return Err((
                "substeps_max",
                format!("{m} is not 0 or in {}..=50 (substeps..=50)", self.substeps),
            ));
        }
        let a = self.armature_kg_m2;
        if !(a.is_finite() && (0.0..=0.1).contains(&a)) {
            return Err(("armature_kg_m2", format!("{} is not in [0, 0.1]", Shown(a))));
        }
        let c = self.contact_hz;
        if !(c.is_finite() && (10.0..=10_000.0).contains(&c)) {
            return Err(("contact_hz", format!("{} is not in [10, 10000]", Shown(c))));
        }
        let k = self.firm_stop_lookahead;
        if k > 10 {
            return Err(("firm_stop_lookahead", format!("{k} is not in 0..=10")));
        }
        let w = self.firm_stop_window_deg;
        if !(w.is_finite() && (1.0..=20.0).contains(&w)) {
            return Err((
                "firm_stop_window_deg",
                format!("{} is not in [1, 20]", Shown(w)),
            ));
        }
        Ok(())
    }
}

/// A parsed, validated experiment.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Experiment {
    /// Run name; one key-expression chunk (letters, digits, `-`, `_`, `.`).
    pub name: String,
    /// Seed of every random stream of the run.
    pub seed: u64,
    /// Number of CLOP iterations (Algorithm 1's n).
    pub iterations: u64,
    /// Trials per iteration (default 10).
    #[serde(default = "default_trials")]
    pub trials_per_iteration: u32,
    /// Simulated duration of one trial, s (default 10).
    #[serde(default = "default_duration")]
    pub trial_duration_s: f64,
    /// Iterations in flight at once, D (default 4).
    #[serde(default = "default_depth")]
    pub pipeline_depth: u32,
    /// Trial model (default `nao`).
    #[serde(default)]
    pub model: TrialModel,
    /// League robot type 0–4 (default 0).
    #[serde(default)]
    pub robot_type: u8,
    /// Start from scratch (default) or from the expert set.
    #[serde(default)]
    pub start: Start,
    /// The optimised parameters, in CLOP's coordinate order.
    pub parameter: Vec<ParamSpec>,
    /// Values for known parameters that are not optimised (default: registry defaults).
    #[serde(default)]
    pub fixed: BTreeMap<String, f64>,
    /// pickOut constants.
    #[serde(default)]
    pub pickout: PickOutConstants,
    /// CLOP settings.
    #[serde(default)]
    pub clop: ClopSettings,
    /// Physics of the NAO trials.
    #[serde(default)]
    pub physics: Physics,
    /// The NAO's walk engine (default `open-loop`).
    #[serde(default)]
    pub walk: WalkEngine,
}

fn default_trials() -> u32 {
    10
}
fn default_duration() -> f64 {
    10.0
}
fn default_depth() -> u32 {
    4
}

impl Experiment {
    /// Parses and validates the text of an experiment file.
    pub fn from_toml(text: &str) -> Result<Self, ExperimentError> {
        let e: Experiment = toml::from_str(text)
            .map_err(|e| ExperimentError::Parse(e.to_string().trim().into()))?;
        e.validate()?;
        Ok(e)
    }

    /// Checks every field; the first problem found is returned.
    pub fn validate(&self) -> Result<(), ExperimentError> {
        keys::check_chunk("run name", &self.name).map_err(|m| invalid("name", m))?;
        if self.iterations == 0 || self.iterations > 10_000_000 {
            return Err(invalid("iterations", "must be in 1..=10000000"));
        }
        if self.trials_per_iteration == 0 {
            return Err(invalid("trials_per_iteration", "must be at least 1"));
        }
        if self.trials_per_iteration > 10_000 {
            return Err(invalid("trials_per_iteration", "must be at most 10000"));
        }
        finite_positive("trial_duration_s", self.trial_duration_s)?;
        if self.trial_duration_s > 3600.0 {
            return Err(invalid("trial_duration_s", "must be at most 3600 s"));
        }
        if self.pipeline_depth == 0 || self.pipeline_depth > 1000 {
            return Err(invalid("pipeline_depth", "must be in 1..=1000"));
        }
        if self.robot_type > 4 {
            return Err(invalid("robot_type", "must be 0, 1, 2, 3 or 4"));
        }
        if self.parameter.is_empty() {
            return Err(invalid("parameter", "at least one [[parameter]] is needed"));
        }
        for (i, p) in self.parameter.iter().enumerate() {
            let f = |s: &str| format!("parameter[{i}].{s}");
            params::find(&p.name).ok_or_else(|| {
                invalid(
                    f("name"),
                    format!(
                        "unknown parameter `{}` (known: {})",
                        p.name,
                        params::KNOWN
                            .iter()
                            .map(|k| k.name)
                            .collect::<Vec<_>>()
                            .join(", ")
                    ),
                )
            })?;
            if self.parameter[..i].iter().any(|q| q.name == p.name) {
                return Err(invalid(f("name"), format!("`{}` is listed twice", p.name)));
            }
            for (field, v) in [("lower", p.lower), ("upper", p.upper)] {
                params::check_value(&p.name, v).map_err(|m| invalid(f(field), m))?;
            }
            if p.lower >= p.upper {
                return Err(invalid(
                    f("lower"),
                    format!(
                        "lower ({}) must be below upper ({})",
                        Shown(p.lower),
                        Shown(p.upper)
                    ),
                ));
            }
            if let Some(x) = p.expert {
                if !x.is_finite() || x < p.lower || x > p.upper {
                    return Err(invalid(
                        f("expert"),
                        format!("{} is outside [{}, {}]", Shown(x), p.lower, p.upper),
                    ));
                }
            }
            let engine_constant = params::find(&p.name).is_some_and(|k| {
                matches!(
                    k.param,
                    params::Param::StepPeriod
                        | params::Param::DoubleSupport
                        | params::Param::ComAboveHip
                        | params::Param::HipRollComp
                )
            });
            gain_has_feedback(self.walk, &p.name).map_err(|m| invalid(f("name"), m))?;
            if engine_constant && p.expert.is_none() && self.walk == WalkEngine::OpenLoop {
                return Err(invalid(
                    f("expert"),
                    format!(
                        "`{}` needs an expert value with walk = \"open-loop\": the registry's \
                         default is the closed-loop engine's",
                        p.name
                    ),
                ));
            }
            match p.kind {
                ParamKind::Gamma if p.lower <= 0.0 => {
                    return Err(invalid(f("lower"), "a gamma parameter needs lower > 0"))
                }
                ParamKind::IntegerGamma if p.lower < 1.0 => {
                    return Err(invalid(
                        f("lower"),
                        "an integer_gamma parameter needs lower >= 1",
                    ))
                }
                ParamKind::Integer | ParamKind::IntegerGamma
                    if p.lower.fract() != 0.0 || p.upper.fract() != 0.0 =>
                {
                    return Err(invalid(
                        f("lower"),
                        "integer parameters need integer bounds",
                    ))
                }
                _ => {}
            }
        }
        for (name, v) in &self.fixed {
            let field = format!("fixed.{name}");
            params::check_value(name, *v).map_err(|m| invalid(&field, m))?;
            gain_has_feedback(self.walk, name).map_err(|m| invalid(&field, m))?;
            if self.parameter.iter().any(|p| &p.name == name) {
                return Err(invalid(field, "is also an optimised [[parameter]]"));
            }
        }
        let k = &self.pickout;
        for (field, v) in [
            ("pickout.success_rate", k.success_rate),
            ("pickout.xy_ratio", k.xy_ratio),
            ("pickout.alpha", k.alpha),
            ("pickout.beta", k.beta),
            ("pickout.gamma", k.gamma),
        ] {
            if !v.is_finite() || v < 0.0 {
                return Err(invalid(
                    field,
                    format!("{} is not a finite number >= 0", Shown(v)),
                ));
            }
        }
        if k.success_rate > 1.0 {
            return Err(invalid("pickout.success_rate", "must be at most 1"));
        }
        if k.beta >= k.alpha {
            return Err(invalid(
                "pickout.beta",
                format!(
                    "beta ({}) must be below alpha ({})",
                    Shown(k.beta),
                    Shown(k.alpha)
                ),
            ));
        }
        for (field, v) in [
            ("pickout.xy_ratio", k.xy_ratio),
            ("pickout.alpha", k.alpha),
            ("pickout.beta", k.beta),
            ("pickout.gamma", k.gamma),
        ] {
            if v > 1000.0 {
                return Err(invalid(field, format!("{} is above 1000", Shown(v))));
            }
        }
        let c = &self.clop;
        for (field, v, hi) in [
            ("clop.h", c.h, 100.0),
            ("clop.draw_elo", c.draw_elo, 10_000.0),
            ("clop.refresh_rate", c.refresh_rate, 1.0),
            ("clop.localization_power", c.localization_power, 10.0),
            ("clop.prior_strength", c.prior_strength, 1e6),
        ] {
            if !v.is_finite() || v < 0.0 || v > hi {
                return Err(invalid(field, format!("{} is not in [0, {hi}]", Shown(v))));
            }
        }
        if c.max_weight_iterations > 100 {
            return Err(invalid(
                "clop.max_weight_iterations",
                "must be in 0..=100 (0: to convergence, at most 100)",
            ));
        }
        finite_positive("clop.prior_strength", c.prior_strength)?;
        // Bounds on the cost of one CLOP decision (a refresh and an ask, inside
        // the coordinator's event loop); measured by clop's ignored test
        // `one_decision_at_the_bounds`.
        if c.n_mcmc == 0 || c.n_mcmc > 10_000 {
            return Err(invalid("clop.n_mcmc", "must be in 1..=10000"));
        }
        self.physics
            .validate()
            .map_err(|(field, m)| invalid(format!("physics.{field}"), m))?;
        Ok(())
    }

    /// Names of the optimised parameters, in CLOP order.
    #[must_use]
    pub fn param_names(&self) -> Vec<String> {
        self.parameter.iter().map(|p| p.name.clone()).collect()
    }

    /// The expert set: each optimised parameter at its expert value.
    #[must_use]
    pub fn expert_values(&self) -> Vec<f64> {
        self.parameter.iter().map(ParamSpec::expert_value).collect()
    }

    /// Every value a worker needs: the optimised `values` (CLOP order) plus the fixed ones.
    #[must_use]
    pub fn full_params(&self, values: &[f64]) -> Vec<(String, f64)> {
        let mut out: Vec<(String, f64)> = self
            .parameter
            .iter()
            .zip(values)
            .map(|(p, v)| (p.name.clone(), *v))
            .collect();
        out.extend(self.fixed.iter().map(|(k, v)| (k.clone(), *v)));
        out
    }

    /// Whether `values` lie inside L (finite, within each parameter's bounds).
    pub fn check_in_space(&self, values: &[f64]) -> Result<(), String> {
        if values.len() != self.parameter.len() {
            return Err(format!(
                "{} values for {} parameters",
                values.len(),
                self.parameter.len()
            ));
        }
        for (p, v) in self.parameter.iter().zip(values) {
            if !v.is_finite() || *v < p.lower || *v > p.upper {
                return Err(format!(
                    "`{}` = {} is outside [{}, {}]",
                    p.name,
                    Shown(*v),
                    p.lower,
                    p.upper
                ));
            }
        }
        Ok(())
    }
}

fn finite_positive(field: &str, v: f64) -> Result<(), ExperimentError> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(invalid(
            field,
            format!("{} is not a finite number > 0", Shown(v)),
        ))
    }
}

/// A stable 64-bit hash (FNV-1a) of an experiment file's text, for the journal header.
#[must_use]
pub fn text_hash(text: &str) -> u64 {
    text.bytes().fold(0xcbf2_9ce4_8422_2325_u64, |h, b| {
        (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = r#"
name = "t"
seed = 1
iterations = 5

[[parameter]]
name = "ThighRelHip2_Z"
lower = -0.08
upper = -0.03
expert = -0.04
"#;

    fn err(text: &str) -> String {
        Experiment::from_toml(text).unwrap_err().to_string()
    }

    #[test]
    fn parses_with_defaults() {
        let e = Experiment::from_toml(GOOD).unwrap();
        assert_eq!(e.trials_per_iteration, 10);
        assert_eq!(e.pickout, PickOutConstants::default());
        assert_eq!(e.clop.h, 3.0);
        assert_eq!(e.model, TrialModel::Nao);
        assert_eq!(e.expert_values(), vec![-0.04]);
        assert_eq!(e.physics, Physics::default());
    }

    #[test]
    fn each_malformed_variant_names_its_problem() {
        let cases: &[(&str, &str, &str)] = &[
            ("seed = 1", "seed = 1\nbogus = 3", "bogus"),
            ("upper = -0.03", "upper = -0.09", "parameter[0].lower"),
            ("expert = -0.04", "expert = -0.02", "parameter[0].expert"),
            (
                "iterations = 5",
                "iterations = 5\ntrials_per_iteration = 0",
                "trials_per_iteration",
            ),
            (
                "\"ThighRelHip2_Z\"",
                "\"ThighLength\"",
                "unknown parameter `ThighLength`",
            ),
            ("lower = -0.08", "lower = nan", "parameter[0].lower"),
            (
                "iterations = 5",
                "iterations = 5\n[pickout]\nbeta = 3.0",
                "pickout.beta",
            ),
            (
                "iterations = 5",
                "iterations = 5\ntrial_duration_s = inf",
                "trial_duration_s",
            ),
            ("name = \"t\"", "name = \"a/b\"", "name"),
            ("lower = -0.08", "lower = -0.5", "admissible range"),
            (
                "iterations = 5",
                "iterations = 5\n[physics]\nsubsteps = 0",
                "physics.substeps",
            ),
            (
                "iterations = 5",
                "iterations = 5\n[physics]\npgs_iterations = 500",
                "physics.pgs_iterations",
            ),
            (
                "iterations = 5",
                "iterations = 5\n[physics]\ntimestep = 0.001",
                "timestep",
            ),
            (
                "iterations = 5",
                "iterations = 5\n[physics]\narmature_kg_m2 = nan",
                "physics.armature_kg_m2",
            ),
            (
                "iterations = 5",
                "iterations = 5\n[physics]\ncontact_hz = 5.0",
                "physics.contact_hz",
            ),
            (
                "iterations = 5",
                "iterations = 5\n[physics]\nfirm_stop_window_deg = 45.0",
                "physics.firm_stop_window_deg",
            ),
            (
                "iterations = 5",
                "iterations = 5\n[physics]\nfirm_stop_window_deg = nan",
                "physics.firm_stop_window_deg",
            ),
            (
                "iterations = 5",
                "iterations = 5\n[physics]\nfirm_stop_lookahead = 11",
                "physics.firm_stop_lookahead",
            ),
            (
                "iterations = 5",
                "iterations = 5\n[physics]\nfirm_stop_lookahead = -1",
                "firm_stop_lookahead",
            ),
            (
                "iterations = 5",
                "iterations = 5\n[physics]\nweld_elbow_yaws = 1",
                "weld_elbow_yaws",
            ),
            (
                "iterations = 5",
                "iterations = 5\n[physics]\nsubsteps = 16\nsubsteps_max = 12",
                "physics.substeps_max",
            ),
            (
                "iterations = 5",
                "iterations = 5\n[physics]\nsubsteps_max = 51",
                "physics.substeps_max",
            ),
            (
                "iterations = 5",
                "iterations = 5\n[physics]\ncontact_hz = inf",
                "physics.contact_hz",
            ),
            (
                "iterations = 5",
                "iterations = 5\n[physics]\nfirm_stops = 1",
                "firm_stops",
            ),
        ];
        for (from, to, needle) in cases {
            let text = GOOD.replacen(from, to, 1);
            assert_ne!(text, GOOD, "{from}");
            let msg = err(&text);
            assert!(msg.contains(needle), "{to}: {msg}");
        }
    }

    #[test]
    fn syntax_errors_carry_a_line() {
        let msg = err("name = \"t\"\nseed = \n");
        assert!(msg.contains("line 2"), "{msg}");
    }

    /// Experiment 1 on the band walks with experiment 2's expert there: its
    /// one parameter's bounds aside, the two files give a worker the same
    /// values and physics.
    #[test]
    fn the_band_files_share_their_expert_and_physics() {
        let read = |f: &str| {
            let path = format!("{}/../experiments/{f}", env!("CARGO_MANIFEST_DIR"));
            Experiment::from_toml(&std::fs::read_to_string(path).unwrap()).unwrap()
        };
        let one = read("physical-converged-band.toml");
        let two = read("physical-technical-converged-period-band.toml");
        let values = |e: &Experiment| -> BTreeMap<String, f64> {
            e.full_params(&e.expert_values()).into_iter().collect()
        };
        assert_eq!(values(&one), values(&two));
        assert_eq!(one.physics, two.physics);
        assert_eq!(
            (one.walk, one.pickout, one.clop),
            (two.walk, two.pickout, two.clop)
        );
    }

    #[test]
    fn shipped_experiments_parse() {
        for f in [
            "physical.toml",
            "physical-technical.toml",
            "physical-converged.toml",
            "physical-technical-converged.toml",
            "physical-technical-converged-period.toml",
            "physical-technical-converged-period-1ms.toml",
            "physical-technical-converged-period-band.toml",
            "physical-converged-band.toml",
            "physical-converged-band-aim.toml",
            "physical-technical-converged-period-band-reach.toml",
            "physical-technical-converged-period-band-reach-aim.toml",
            "physical-technical-converged-period-band-reach11-aim.toml",
            "physical-stiff.toml",
            "physical-firm.toml",
            "physical-technical-stiff.toml",
            "physical-technical-firm.toml",
            "physical-technical-arms.toml",
            "physical-arms.toml",
            "physical-technical-arms-5ms.toml",
            "physical-arms-5ms.toml",
            "physical-technical-arms-5ms-roll.toml",
            "physical-arms-5ms-roll.toml",
            "physical-technical-arms-5ms-roll-aim.toml",
            "physical-arms-5ms-roll-aim.toml",
        ] {
            let path = format!("{}/../experiments/{f}", env!("CARGO_MANIFEST_DIR"));
            let text = std::fs::read_to_string(&path).unwrap();
            let e = Experiment::from_toml(&text).unwrap_or_else(|e| panic!("{f}: {e}"));
            if f.ends_with("converged.toml") {
                assert_eq!(e.physics.substeps, 10, "{f}");
                assert_eq!(e.fixed.get("double_support"), Some(&0.0), "{f}");
            }
            // The step-period file at 1 ms, and with each trial's step drawn
            // from 1.25 to 0.67 ms; every other file at one step.
            let band = match f {
                "physical-technical-converged-period-1ms.toml" => (20, 0),
                "physical-technical-converged-period-band.toml"
                | "physical-converged-band.toml"
                | "physical-converged-band-aim.toml"
                | "physical-technical-converged-period-band-reach.toml"
                | "physical-technical-converged-period-band-reach-aim.toml"
                | "physical-technical-converged-period-band-reach11-aim.toml" => (16, 30),
                _ => (e.physics.substeps, 0),
            };
            assert_eq!((e.physics.substeps, e.physics.substeps_max), band, "{f}");
            // Only the reach files cap the plan's steps (the reach11 file
            // 10 % wider), and only the aim files aim them short by the
            // legs' overreach.
            let reach = if f.contains("band-reach11") {
                Some(&1.1)
            } else {
                f.contains("band-reach").then_some(&1.0)
            };
            assert_eq!(e.fixed.get("step_reach"), reach, "{f}");
            let aim = f.ends_with("-aim.toml").then_some(&0.3);
            assert_eq!(e.fixed.get("step_aim"), aim, "{f}");
            if f.contains("band") {
                assert!(e
                    .physics
                    .to_string()
                    .ends_with("drawn per trial from 16-30 steps per cycle"));
            }
            if f.ends_with("-firm.toml") {
                assert_eq!(e.physics, Physics::firm(), "{f}");
            }
            if f.ends_with("stiff.toml") {
                assert_eq!(e.physics.substeps, Physics::default().substeps, "{f}");
                assert_eq!(e.physics.pgs_iterations, 32, "{f}");
                assert_eq!(e.fixed.get("hip_pitch_gain"), Some(&-0.75), "{f}");
            }
            if f.contains("arms") {
                assert_eq!(e.fixed.get("arm_swing"), Some(&0.4), "{f}");
                // Only the roll files widen the stance hip's roll.
                let roll = if f.contains("-roll") { 0.09 } else { 0.07 };
                assert_eq!(e.fixed.get("hip_roll_comp"), Some(&roll), "{f}");
                assert_eq!(e.physics.firm_stop_window_deg, 8.0, "{f}");
                assert!(e
                    .physics
                    .to_string()
                    .ends_with("ground contact 60 Hz, firm stops within 8 deg"));
            } else {
                assert_eq!(e.physics.firm_stop_window_deg, 3.0, "{f}");
            }
            if f.ends_with("firm.toml") || f.contains("arms") {
                let substeps = if f.contains("5ms") {
                    4
                } else {
                    Physics::default().substeps
                };
                assert_eq!(e.physics.substeps, substeps, "{f}");
                assert!(e.physics.firm_stops && e.physics.contact_hz == 60.0, "{f}");
                assert!(e
                    .physics
                    .to_string()
                    .contains("ground contact 60 Hz, firm stops"));
            } else {
                assert!(!e.physics.firm_stops, "{f}");
                assert_eq!(e.physics.contact_hz, Physics::default().contact_hz, "{f}");
            }
        }
    }

    /// The walk engine's constants are parameters too (fixed or optimised);
    /// their registry defaults are the closed-loop engine's, so an open-loop
    /// experiment that optimises one must say where it starts.
    #[test]
    fn the_walk_engines_constants_are_parameters() {
        let period = GOOD.replace("ThighRelHip2_Z", "step_period").replace(
            "lower = -0.08\nupper = -0.03\nexpert = -0.04",
            "lower = 0.15\nupper = 0.26\nexpert = 0.18",
        );
        let e = Experiment::from_toml(&format!("walk = \"closed-loop\"\n{period}")).unwrap();
        assert_eq!(e.expert_values(), vec![0.18]);
        let no_expert = period.replace("expert = 0.18\n", "");
        let e = Experiment::from_toml(&format!("walk = \"closed-loop\"\n{no_expert}")).unwrap();
        assert_eq!(e.expert_values(), vec![0.18]);
        let msg = err(&format!("walk = \"open-loop\"\n{no_expert}"));
        assert!(
            msg.contains("parameter[0].expert") && msg.contains("step_period"),
            "{msg}"
        );
        Experiment::from_toml(&format!("walk = \"open-loop\"\n{period}")).unwrap();
        let fixed = format!("{GOOD}\n[fixed]\ndouble_support = 0.6\n");
        assert!(
            err(&fixed).contains("fixed.double_support"),
            "{}",
            err(&fixed)
        );
        let fixed = format!("{GOOD}\n[fixed]\nstep_period = nan\n");
        assert!(err(&fixed).contains("fixed.step_period"), "{}", err(&fixed));
    }

    /// The feedback's gains are parameters of the closed-loop walk; the open
    /// loop, which has no feedback, refuses them by name, fixed or optimised.
    #[test]
    fn feedback_gains_are_closed_loop_parameters() {
        let fixed = format!("{GOOD}\n[fixed]\nhip_pitch_gain = -0.75\nankle_pitch_gain = 0.3\n");
        let e = Experiment::from_toml(&format!("walk = \"closed-loop\"\n{fixed}")).unwrap();
        assert_eq!(e.fixed.get("hip_pitch_gain"), Some(&-0.75));
        let msg = err(&format!("walk = \"open-loop\"\n{fixed}"));
        assert!(
            msg.contains("fixed.ankle_pitch_gain") && msg.contains("open-loop"),
            "{msg}"
        );
        let gain = GOOD.replace("ThighRelHip2_Z", "hip_pitch_gain").replace(
            "lower = -0.08\nupper = -0.03\nexpert = -0.04",
            "lower = -2.0\nupper = 0.0\nexpert = -1.0",
        );
        Experiment::from_toml(&format!("walk = \"closed-loop\"\n{gain}")).unwrap();
        let msg = err(&format!("walk = \"open-loop\"\n{gain}"));
        assert!(
            msg.contains("parameter[0].name") && msg.contains("hip_pitch_gain"),
            "{msg}"
        );
        let far = format!("{GOOD}\n[fixed]\nhip_pitch_gain = 9.0\n");
        assert!(err(&format!("walk = \"closed-loop\"\n{far}")).contains("fixed.hip_pitch_gain"));
    }
}
