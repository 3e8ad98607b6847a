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
    /// A trial program that workers' owners registered by name (the
    /// experiment's `program`): a simulator of its own, run once per trial
    /// with the trial as JSON (docs/programs.md).
    Program,
}

impl TrialModel {
    /// Parses `nao` or `synthetic`.
    pub fn parse(s: &str) -> Result<Self, String> {
        match s {
            "nao" => Ok(Self::Nao),
            "synthetic" => Ok(Self::Synthetic),
            "program" => Ok(Self::Program),
            other => Err(format!(
                "unknown trial model `{other}` (expected `nao`, `synthetic` or `program`)"
            )),
        }
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

/// How finely the workers' rapier3d integrates each 20 ms agent cycle of a
/// NAO trial (`[physics]`, optional; ignored by the synthetic model). The
/// defaults are the one physics naofarm ships (docs/walk.md, "The physics"):
/// an experiment needs no `[physics]` section, and a change to these counts
/// is a measurement of the physics, not another walk.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Physics {
    /// Physics steps per 20 ms cycle (1..=50; default 4, 5 ms steps).
    pub substeps: u32,
    /// Rapier solver iterations per step (1..=16; default 1).
    pub solver_iterations: u32,
    /// Inner PGS iterations per solver iteration (1..=200; default 28).
    pub pgs_iterations: u32,
}

impl std::fmt::Display for Physics {
    /// `4 x 5.000 ms steps per 20 ms cycle, 1 solver x 28 PGS iterations`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} x {:.3} ms steps per 20 ms cycle, {} solver x {} PGS iterations",
            self.substeps,
            self.step_ms(),
            self.solver_iterations,
            self.pgs_iterations,
        )
    }
}

impl Default for Physics {
    fn default() -> Self {
        Self {
            substeps: 4,
            solver_iterations: 1,
            pgs_iterations: 28,
        }
    }
}

impl Physics {
    /// One physics step, ms: the 20 ms cycle over `substeps`.
    #[must_use]
    pub fn step_ms(&self) -> f64 {
        20.0 / f64::from(self.substeps.max(1))
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
    /// The trial program's name, with `model = "program"`: a name workers'
    /// owners register (`naofarm worker --program NAME=PATH`), never a path.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub program: Option<String>,
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
}

/// Checks a trial program's name: one word of letters, digits, `-` and `_`,
/// at most 64 bytes (a name, never a path or a command).
pub fn check_program_name(name: &str) -> Result<(), String> {
    if name.is_empty() || name.len() > 64 {
        return Err(format!(
            "a program's name must be 1 to 64 bytes, not {}",
            name.len()
        ));
    }
    match name
        .chars()
        .find(|c| !(c.is_ascii_alphanumeric() || matches!(c, '-' | '_')))
    {
        Some(c) => Err(format!(
            "program name `{name}` contains `{c}`; a program is named (letters, digits, `-`, `_`), never given as a path or a command"
        )),
        None => Ok(()),
    }
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
    /// Whether `name` is in the parameter registry; the error lists the known ones.
    fn known(name: &str) -> Result<(), String> {
        match params::find(name) {
            Some(_) => Ok(()),
            None => Err(format!(
                "unknown parameter `{name}` (known: {})",
                params::KNOWN
                    .iter()
                    .map(|k| k.name)
                    .collect::<Vec<_>>()
                    .join(", ")
            )),
        }
    }

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
        let program = self.model == TrialModel::Program;
        match &self.program {
            None if program => {
                return Err(invalid(
                    "program",
                    "model = \"program\" needs the program's name (`program = \"NAME\"`)",
                ))
            }
            Some(_) if !program => {
                return Err(invalid(
                    "program",
                    format!(
                        "only model = \"program\" runs a program; this model is `{}`",
                        format!("{:?}", self.model).to_lowercase()
                    ),
                ))
            }
            Some(name) => check_program_name(name).map_err(|m| invalid("program", m))?,
            None => {}
        }
        if self.parameter.is_empty() {
            return Err(invalid("parameter", "at least one [[parameter]] is needed"));
        }
        // A program's parameters are its own: any word, bounds as given.
        let check_value = |name: &str, v: f64| {
            if program {
                params::check_program_value(name, v)
            } else {
                params::check_value(name, v)
            }
        };
        for (i, p) in self.parameter.iter().enumerate() {
            let f = |s: &str| format!("parameter[{i}].{s}");
            if program {
                if p.expert.is_none() {
                    return Err(invalid(
                        f("expert"),
                        "a program's parameter needs its expert value (there is no registry default)",
                    ));
                }
            } else {
                Self::known(&p.name).map_err(|m| invalid(f("name"), m))?;
            }
            if self.parameter[..i].iter().any(|q| q.name == p.name) {
                return Err(invalid(f("name"), format!("`{}` is listed twice", p.name)));
            }
            for (field, v) in [("lower", p.lower), ("upper", p.upper)] {
                check_value(&p.name, v).map_err(|m| invalid(f(field), m))?;
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
            check_value(name, *v).map_err(|m| invalid(&field, m))?;
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
        let mut cases: Vec<(&str, String, &str)> = vec![
            ("seed = 1", "seed = 1\nbogus = 3".into(), "bogus"),
            (
                "upper = -0.03",
                "upper = -0.09".into(),
                "parameter[0].lower",
            ),
            (
                "expert = -0.04",
                "expert = -0.02".into(),
                "parameter[0].expert",
            ),
            (
                "\"ThighRelHip2_Z\"",
                "\"ThighLength\"".into(),
                "unknown parameter",
            ),
            ("lower = -0.08", "lower = nan".into(), "parameter[0].lower"),
            ("name = \"t\"", "name = \"a/b\"".into(), "name"),
            ("lower = -0.08", "lower = -0.5".into(), "admissible range"),
        ];
        // Keys added after `iterations`; the physics' variants are gone, so a
        // file that still asks for one is told which key is unknown.
        for (added, needle) in [
            ("trials_per_iteration = 0", "trials_per_iteration"),
            ("[pickout]\nbeta = 3.0", "pickout.beta"),
            ("trial_duration_s = inf", "trial_duration_s"),
            ("[physics]\nsubsteps = 0", "physics.substeps"),
            ("[physics]\npgs_iterations = 500", "physics.pgs_iterations"),
            ("[physics]\ntimestep = 0.001", "timestep"),
            ("[physics]\nfirm_stops = true", "firm_stops"),
            ("walk = \"closed-loop\"", "walk"),
        ] {
            cases.push(("iterations = 5", format!("iterations = 5\n{added}"), needle));
        }
        for (from, to, needle) in &cases {
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

    /// Every shipped experiment parses; the paper's two run the one
    /// physics (no `[physics]` section) and the one engine's constants (no
    /// `[fixed]` walk settings), and experiment 1 shares experiment 2's
    /// expert.
    #[test]
    fn shipped_experiments_parse() {
        let read = |f: &str| {
            let path = format!("{}/../experiments/{f}", env!("CARGO_MANIFEST_DIR"));
            let text = std::fs::read_to_string(&path).unwrap();
            Experiment::from_toml(&text).unwrap_or_else(|e| panic!("{f}: {e}"))
        };
        let dir = format!("{}/../experiments", env!("CARGO_MANIFEST_DIR"));
        let mut n = 0;
        for entry in std::fs::read_dir(dir).unwrap() {
            let path = entry.unwrap().path();
            if path.extension().is_some_and(|e| e == "toml") {
                let f = path.file_name().unwrap().to_string_lossy().into_owned();
                read(&f);
                n += 1;
            }
        }
        assert!(n >= 3, "{n} files");
        let one = read("physical.toml");
        let two = read("physical-technical.toml");
        for e in [&one, &two] {
            assert_eq!(e.physics, Physics::default(), "{}", e.name);
            assert!(e.fixed.is_empty(), "{}: {:?}", e.name, e.fixed);
            assert_eq!(e.trial_duration_s, 10.0);
        }
        assert_eq!(one.param_names(), ["ThighRelHip2_Z"]);
        assert_eq!(two.param_names().len(), 5);
        assert_eq!(one.expert_values()[0], two.expert_values()[0]);
        assert_eq!((one.pickout, one.clop), (two.pickout, two.clop));
        assert_eq!(
            Physics::default().to_string(),
            "4 x 5.000 ms steps per 20 ms cycle, 1 solver x 28 PGS iterations"
        );
    }

    /// The walk engine's plan constants a user may tune are parameters
    /// (fixed or optimised), within their admissible ranges.
    #[test]
    fn the_walk_engines_constants_are_parameters() {
        let period = GOOD.replace("ThighRelHip2_Z", "step_period").replace(
            "lower = -0.08\nupper = -0.03\nexpert = -0.04",
            "lower = 0.15\nupper = 0.26\nexpert = 0.18",
        );
        let e = Experiment::from_toml(&period).unwrap();
        assert_eq!(e.expert_values(), vec![0.18]);
        let no_expert = period.replace("expert = 0.18\n", "");
        let e = Experiment::from_toml(&no_expert).unwrap();
        assert_eq!(e.expert_values(), vec![0.16]);
        let fixed = format!("{GOOD}\n[fixed]\ndouble_support = 0.6\n");
        assert!(
            err(&fixed).contains("fixed.double_support"),
            "{}",
            err(&fixed)
        );
        let fixed = format!("{GOOD}\n[fixed]\nstep_period = nan\n");
        assert!(err(&fixed).contains("fixed.step_period"), "{}", err(&fixed));
        // A feedback gain is the engine's own, no parameter.
        let gain = format!("{GOOD}\n[fixed]\nhip_pitch_gain = -0.75\n");
        assert!(
            err(&gain).contains("unknown parameter `hip_pitch_gain`"),
            "{}",
            err(&gain)
        );
    }
}
