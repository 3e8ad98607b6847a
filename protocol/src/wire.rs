//! Wire messages and their codec.
//!
//! Every message travels as `b"NF"`, a version byte, a kind byte, then the
//! message body in bincode 2 (serde mode, standard config). [`WireMessage`]
//! gives each message exactly one `encode` and one `decode`; decoding caps the
//! size before allocating, rejects trailing bytes, and checks every field
//! ([`WireMessage::validate`]), so a decoded message is always a sane one.
//! Watched topics (results, status) also have a JSON form (`to_json`).

use serde::{de::DeserializeOwned, Deserialize, Serialize};

use crate::{
    experiment::{Physics, TrialModel},
    measurement::Measurement,
};

/// Version of the envelope and message layout, and of what a message may
/// carry (the parameter registry's names and a trial request's physics):
/// a decoder of another version refuses the message by its envelope, so
/// workers of two builds never serve one run with different walks.
pub const WIRE_VERSION: u8 = 24;
/// Largest message accepted, in bytes (checked before any allocation).
pub const MAX_MESSAGE_BYTES: usize = 1 << 20;
const MAGIC: [u8; 2] = *b"NF";
const HEADER: usize = 4;

/// A message that could not be encoded (never silently sent empty).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("cannot encode a {message}: {why}")]
pub struct EncodeError {
    /// The message.
    pub message: &'static str,
    /// The encoder's reason.
    pub why: String,
}

/// Why bytes could not be decoded into a message.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum DecodeError {
    /// The buffer exceeds [`MAX_MESSAGE_BYTES`].
    #[error("{message}: {len} bytes exceeds the limit of {MAX_MESSAGE_BYTES}")]
    TooLarge {
        /// Expected message.
        message: &'static str,
        /// Size received.
        len: usize,
    },
    /// No envelope: too short or wrong magic.
    #[error("{message}: not a naofarm envelope")]
    NotAnEnvelope {
        /// Expected message.
        message: &'static str,
    },
    /// The envelope's version is not ours.
    #[error("{message}: envelope version {found}, this build speaks {WIRE_VERSION}")]
    Version {
        /// Expected message.
        message: &'static str,
        /// Version found.
        found: u8,
    },
    /// The envelope carries another kind of message.
    #[error("{message}: envelope holds message kind {found}, expected {expected}")]
    WrongKind {
        /// Expected message.
        message: &'static str,
        /// Kind byte expected.
        expected: u8,
        /// Kind byte found.
        found: u8,
    },
    /// The body is not valid bincode for the message.
    #[error("{message}: malformed body: {detail}")]
    Body {
        /// Expected message.
        message: &'static str,
        /// The codec's explanation.
        detail: String,
    },
    /// Bytes remain after the body.
    #[error("{message}: {extra} trailing bytes after the body")]
    Trailing {
        /// Expected message.
        message: &'static str,
        /// Number of bytes left over.
        extra: usize,
    },
    /// The body decoded but a field is out of range.
    #[error("{message}: field `{field}`: {problem}")]
    Field {
        /// Expected message.
        message: &'static str,
        /// The offending field.
        field: &'static str,
        /// What is wrong.
        problem: String,
    },
}

/// A message with a fixed kind byte, one encoding and one checked decoding.
pub trait WireMessage: Serialize + DeserializeOwned + Sized {
    /// Human name used in errors.
    const NAME: &'static str;
    /// Kind byte in the envelope.
    const KIND: u8;

    /// Field-level checks run after decoding (and before encoding in tests).
    fn validate(&self) -> Result<(), (&'static str, String)>;

    /// Encodes the message inside the envelope.
    fn encode(&self) -> Result<Vec<u8>, EncodeError> {
        let mut out = Vec::with_capacity(64);
        out.extend_from_slice(&MAGIC);
        out.push(WIRE_VERSION);
        out.push(Self::KIND);
        let body =
            bincode::serde::encode_to_vec(self, bincode::config::standard()).map_err(|e| {
                EncodeError {
                    message: Self::NAME,
                    why: e.to_string(),
                }
            })?;
        out.extend_from_slice(&body);
        Ok(out)
    }

    /// Decodes and checks a message.
    fn decode(bytes: &[u8]) -> Result<Self, DecodeError> {
        Self::decode_unchecked(bytes)?.checked()
    }

    /// This message if its fields pass [`WireMessage::validate`], else
    /// the field and the problem.
    fn checked(self) -> Result<Self, DecodeError> {
        self.validate()
            .map_err(|(field, problem)| DecodeError::Field {
                message: Self::NAME,
                field,
                problem,
            })?;
        Ok(self)
    }

    /// Decodes the envelope and body without the field checks of
    /// [`WireMessage::validate`]: only to give back what a message that
    /// failed them holds (a worker returning the trials of a grant it cannot
    /// run), never to act on it.
    fn decode_unchecked(bytes: &[u8]) -> Result<Self, DecodeError> {
        let message = Self::NAME;
        if bytes.len() > MAX_MESSAGE_BYTES {
            return Err(DecodeError::TooLarge {
                message,
                len: bytes.len(),
            });
        }
        if bytes.len() < HEADER || bytes[..2] != MAGIC {
            return Err(DecodeError::NotAnEnvelope { message });
        }
        if bytes[2] != WIRE_VERSION {
            return Err(DecodeError::Version {
                message,
                found: bytes[2],
            });
        }
        if bytes[3] != Self::KIND {
            return Err(DecodeError::WrongKind {
                message,
                expected: Self::KIND,
                found: bytes[3],
            });
        }
        let body = &bytes[HEADER..];
        let cfg = bincode::config::standard().with_limit::<MAX_MESSAGE_BYTES>();
        let (value, used): (Self, usize) =
            bincode::serde::decode_from_slice(body, cfg).map_err(|e| DecodeError::Body {
                message,
                detail: e.to_string(),
            })?;
        if used != body.len() {
            return Err(DecodeError::Trailing {
                message,
                extra: body.len() - used,
            });
        }
        Ok(value)
    }

    /// The documented JSON form (for watched topics and `--json` output).
    fn to_json(&self) -> Result<String, EncodeError> {
        serde_json::to_string(self).map_err(|e| EncodeError {
            message: Self::NAME,
            why: e.to_string(),
        })
    }

    /// Parses and checks the JSON form.
    fn from_json(text: &str) -> Result<Self, DecodeError> {
        let value: Self = serde_json::from_str(text).map_err(|e| DecodeError::Body {
            message: Self::NAME,
            detail: e.to_string(),
        })?;
        value.checked()
    }
}

type Check = Result<(), (&'static str, String)>;

fn finite(field: &'static str, v: f64) -> Check {
    if v.is_finite() {
        Ok(())
    } else {
        Err((field, format!("{v} is not a finite number")))
    }
}

fn finite_opt(field: &'static str, v: Option<f64>) -> Check {
    v.map_or(Ok(()), |v| finite(field, v))
}

fn chunk(field: &'static str, s: &str) -> Check {
    crate::keys::check_chunk(field, s).map_err(|m| (field, m))
}

/// A parameter of a run's result, of the registry (checked against its
/// range) or of a program (any word, finite).
fn any_value(name: &str, v: f64) -> Result<(), String> {
    if crate::params::find(name).is_some() {
        crate::params::check_value(name, v)
    } else {
        crate::params::check_program_value(name, v)
    }
}

/// At most 64 parameters, each checked by `check` (the registry's, or a
/// program's own names).
fn param_list(
    field: &'static str,
    ps: &[(String, f64)],
    check: fn(&str, f64) -> Result<(), String>,
) -> Check {
    if ps.len() > 64 {
        return Err((field, format!("{} parameters, at most 64", ps.len())));
    }
    for (name, v) in ps {
        check(name, *v).map_err(|m| (field, m))?;
    }
    Ok(())
}

/// A request to run one trial: everything a stateless worker needs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrialRequest {
    /// Run id (a UUID: the run's identity; its name is only a label).
    pub run: String,
    /// CLOP iteration index i.
    pub iteration: u64,
    /// Trial index k within the iteration.
    pub trial: u32,
    /// The trial's seed, derived only from (run seed, i, k).
    pub seed: u64,
    /// Which trial model to run.
    pub model: TrialModel,
    /// The trial program's name, exactly when `model` is a program.
    pub program: Option<String>,
    /// League robot type 0–4.
    pub robot_type: u8,
    /// Simulated duration, s.
    pub duration_s: f64,
    /// Every parameter of the robot and the walk, by name (external units).
    pub params: Vec<(String, f64)>,
    /// Dispatch number; a re-dispatched trial gets a new one.
    pub dispatch: u64,
    /// How finely the NAO's physics integrates (the experiment's `[physics]`).
    pub physics: Physics,
}

impl WireMessage for TrialRequest {
    const NAME: &'static str = "TrialRequest";
    const KIND: u8 = 1;
    fn validate(&self) -> Check {
        chunk("run", &self.run)?;
        match (&self.program, self.model) {
            (Some(p), TrialModel::Program) => {
                crate::experiment::check_program_name(p).map_err(|m| ("program", m))?
            }
            (None, TrialModel::Program) => {
                return Err(("program", "a program trial without a program name".into()))
            }
            (Some(_), _) => return Err(("program", "a program name on a model trial".into())),
            (None, _) => {}
        }
        if self.robot_type > 4 {
            return Err(("robot_type", format!("{} is not 0..=4", self.robot_type)));
        }
        finite("duration_s", self.duration_s)?;
        if self.duration_s <= 0.0 || self.duration_s > 3600.0 {
            return Err((
                "duration_s",
                format!("{} is not in (0, 3600]", self.duration_s),
            ));
        }
        self.physics.validate()?;
        if self.model == TrialModel::Program {
            param_list("params", &self.params, crate::params::check_program_value)
        } else {
            param_list("params", &self.params, crate::params::check_value)
        }
    }
}

/// One trial's outcome, as a worker reports it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrialOutcome {
    /// Run name.
    pub run: String,
    /// CLOP iteration index i.
    pub iteration: u64,
    /// Trial index k.
    pub trial: u32,
    /// The seed the trial ran with.
    pub seed: u64,
    /// Dispatch number of the request answered.
    pub dispatch: u64,
    /// Id of the worker that ran it.
    pub worker: String,
    /// Whether the robot fell.
    pub fell: bool,
    /// Final torso x (forward), m.
    pub x_m: f64,
    /// Final torso y (left), m.
    pub y_m: f64,
    /// Simulated time of the fall, s (absent when it did not fall).
    pub fall_time_s: Option<f64>,
    /// Simulated time actually run, s.
    pub sim_time_s: f64,
    /// Wall-clock time the trial took on the worker, s.
    pub wall_time_s: f64,
    /// The worker's fingerprint (its build and its host's maths: see
    /// `worker::fingerprint`); a run takes outcomes of one fingerprint only.
    pub fingerprint: u64,
}

impl TrialOutcome {
    /// The answer to `req`: what `worker` (of `fingerprint`) measured, in
    /// `wall_time_s` of wall time.
    #[must_use]
    pub fn answer(
        req: &TrialRequest,
        worker: String,
        fingerprint: u64,
        m: Measurement,
        wall_time_s: f64,
    ) -> Self {
        Self {
            run: req.run.clone(),
            iteration: req.iteration,
            trial: req.trial,
            seed: req.seed,
            dispatch: req.dispatch,
            worker,
            fell: m.fell,
            x_m: m.x_m,
            y_m: m.y_m,
            fall_time_s: m.fall_time_s,
            sim_time_s: m.sim_time_s,
            wall_time_s,
            fingerprint,
        }
    }

    /// What the trial measured.
    #[must_use]
    pub fn measurement(&self) -> Measurement {
        Measurement {
            fell: self.fell,
            x_m: self.x_m,
            y_m: self.y_m,
            fall_time_s: self.fall_time_s,
            sim_time_s: self.sim_time_s,
        }
    }
}

impl WireMessage for TrialOutcome {
    const NAME: &'static str = "TrialOutcome";
    const KIND: u8 = 2;
    fn validate(&self) -> Check {
        chunk("run", &self.run)?;
        if self.worker.len() > 128 {
            return Err(("worker", "longer than 128 bytes".into()));
        }
        finite("wall_time_s", self.wall_time_s)?;
        // One definition of a valid measurement, shared with the trial models.
        self.measurement().check().map_err(|m| ("measurement", m))
    }
}

/// A trial a worker could not run: an error, a panic, or a non-finite result.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrialFailure {
    /// Run id.
    pub run: String,
    /// CLOP iteration index i.
    pub iteration: u64,
    /// Trial index k.
    pub trial: u32,
    /// The seed of the request.
    pub seed: u64,
    /// Dispatch number of the request answered.
    pub dispatch: u64,
    /// Id of the worker that tried it.
    pub worker: String,
    /// What went wrong (error text, panic message, the non-finite value).
    pub reason: String,
    /// The worker would not run it (beyond its limits): not a failure of the
    /// trial; the coordinator offers it to other workers.
    pub refused: bool,
}

impl WireMessage for TrialFailure {
    const NAME: &'static str = "TrialFailure";
    const KIND: u8 = 6;
    fn validate(&self) -> Check {
        chunk("run", &self.run)?;
        if self.worker.len() > 128 {
            return Err(("worker", "longer than 128 bytes".into()));
        }
        if self.reason.len() > MAX_FAILURE_REASON {
            return Err(("reason", format!("longer than {MAX_FAILURE_REASON} bytes")));
        }
        Ok(())
    }
}

/// pickOut's decision (Algorithm 2).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "SCREAMING_SNAKE_CASE")]
pub enum Decision {
    /// Better: a CLOP win, and ν′ ← ν.
    Accept,
    /// About as good: a CLOP draw.
    Equivalent,
    /// Worse: a CLOP loss.
    Reject,
}

impl Decision {
    /// The documented spelling: `ACCEPT`, `EQUIVALENT` or `REJECT`.
    #[must_use]
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Accept => "ACCEPT",
            Self::Equivalent => "EQUIVALENT",
            Self::Reject => "REJECT",
        }
    }
}

/// An iteration's statistics (`docs/spec/evolve.md`: m and e over successful trials).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Stats {
    /// Number of trials.
    pub trials: u32,
    /// Trials that did not fall.
    pub successes: u32,
    /// Success rate s = successes / trials.
    pub s: f64,
    /// Mean forward distance over successful trials, m (absent with none).
    pub mx: Option<f64>,
    /// Mean |lateral distance| over successful trials, m.
    pub my: Option<f64>,
    /// Sample standard deviation of x over successful trials, m (absent with fewer than 2).
    pub ex: Option<f64>,
    /// Sample standard deviation of |y| over successful trials, m.
    pub ey: Option<f64>,
    /// Mean forward distance over all trials, m.
    pub mx_all: f64,
    /// Mean |lateral distance| over all trials, m.
    pub my_all: f64,
}

impl Stats {
    fn check(&self) -> Check {
        if self.successes > self.trials {
            return Err(("stats.successes", "more successes than trials".into()));
        }
        finite("stats.s", self.s)?;
        finite_opt("stats.mx", self.mx)?;
        finite_opt("stats.my", self.my)?;
        finite_opt("stats.ex", self.ex)?;
        finite_opt("stats.ey", self.ey)?;
        finite("stats.mx_all", self.mx_all)?;
        finite("stats.my_all", self.my_all)
    }
}

/// The best result so far, ν′ and its parameter set (Optim.1).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Best {
    /// Iteration where it was found.
    pub iteration: u64,
    /// Its parameter set (optimised parameters, external units).
    pub params: Vec<(String, f64)>,
    /// Its statistics.
    pub stats: Stats,
}

/// An iteration's decision, published on the results topic.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct IterationResult {
    /// Run name.
    pub run: String,
    /// Iteration index.
    pub iteration: u64,
    /// Its parameter set (optimised parameters, external units).
    pub params: Vec<(String, f64)>,
    /// Its statistics.
    pub stats: Stats,
    /// pickOut's decision.
    pub decision: Decision,
    /// ν′ after this decision.
    pub best: Option<Best>,
}

impl WireMessage for IterationResult {
    const NAME: &'static str = "IterationResult";
    const KIND: u8 = 3;
    fn validate(&self) -> Check {
        chunk("run", &self.run)?;
        param_list("params", &self.params, any_value)?;
        self.stats.check()?;
        if let Some(b) = &self.best {
            param_list("best.params", &b.params, any_value)?;
            b.stats.check()?;
        }
        Ok(())
    }
}

/// Where a run stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RunState {
    /// Trials are handed out.
    Running,
    /// No trials are handed out (`naofarm ctl RUN pause`).
    Paused,
    /// The coordinator is stopping (`naofarm ctl RUN stop`).
    Stopped,
    /// Every planned iteration is decided.
    Finished,
}

/// A run's advert on `<prefix>/@runs/<id>/ad`: what a worker needs to choose
/// which run to ask for work. Published when it changes and every heartbeat.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunAdvert {
    /// Run id.
    pub id: String,
    /// Run name (a label).
    pub name: String,
    /// Priority 1..=1000.
    pub priority: u32,
    /// Trials queued and ready to hand out.
    pub ready: u32,
    /// Trials in flight on the fleet (handed out, not yet answered): with
    /// the priority, where the run stands against its share.
    pub running: u32,
    /// Where the run stands.
    pub state: RunState,
    /// Longest trial of the run, simulated seconds (a worker beyond its limit does not ask).
    pub duration_s: f64,
    /// The trial program the run's trials need, if any: only workers that
    /// registered it ask.
    pub program: Option<String>,
    /// Increases with every advert of this coordinator (older ones are ignored).
    pub seq: u64,
}

impl WireMessage for RunAdvert {
    const NAME: &'static str = "RunAdvert";
    const KIND: u8 = 7;
    fn validate(&self) -> Check {
        chunk("id", &self.id)?;
        chunk("name", &self.name)?;
        if let Some(p) = &self.program {
            crate::experiment::check_program_name(p).map_err(|m| ("program", m))?;
        }
        Control::Priority(self.priority)
            .check()
            .map_err(|m| ("priority", m))?;
        finite("duration_s", self.duration_s)
    }
}

/// A worker fingerprint as it is shown, logged and named in errors: 16 hex digits.
#[must_use]
pub fn show_fingerprint(fp: u64) -> String {
    format!("{fp:016x}")
}

/// A worker asking a run for trials (the payload of a query on `<prefix>/@runs/<id>/work`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WorkRequest {
    /// Worker id (a UUID).
    pub worker: String,
    /// Trials wanted now (at most its free slots).
    pub want: u32,
    /// Slots of the worker.
    pub slots: u32,
    /// Trials it runs now (for all runs).
    pub busy: u32,
    /// Longest trial it accepts, simulated seconds.
    pub max_duration_s: f64,
    /// naofarm version of the worker.
    pub version: String,
    /// The worker's fingerprint: a run grants trials only to workers of its
    /// own. For a program's run it also hashes the program's identity.
    pub fingerprint: u64,
    /// The trial program this worker registered under the run's program's
    /// name, if the run names one: a run grants its trials to no other.
    pub program: Option<String>,
}

impl WireMessage for WorkRequest {
    const NAME: &'static str = "WorkRequest";
    const KIND: u8 = 8;
    fn validate(&self) -> Check {
        chunk("worker", &self.worker)?;
        if self.slots == 0 || self.slots > 4096 {
            return Err(("slots", format!("{} is not in 1..=4096", self.slots)));
        }
        if self.want == 0 || self.want > self.slots {
            return Err((
                "want",
                format!("{} is not in 1..={}", self.want, self.slots),
            ));
        }
        if self.busy > self.slots {
            return Err(("busy", "more busy slots than slots".into()));
        }
        finite("max_duration_s", self.max_duration_s)?;
        if self.version.len() > 64 {
            return Err(("version", "longer than 64 bytes".into()));
        }
        if let Some(p) = &self.program {
            crate::experiment::check_program_name(p).map_err(|m| ("program", m))?;
        }
        Ok(())
    }
}

/// A run's answer to a [`WorkRequest`]: the trials granted (possibly none) and why not more.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WorkGrant {
    /// The trials now in flight on the asking worker.
    pub trials: Vec<TrialRequest>,
    /// Trials still ready after this grant.
    pub ready: u32,
    /// Trials in flight on the fleet after this grant.
    pub running: u32,
    /// Sequence number of the run's last advert before this grant (a
    /// worker that heard a newer advert trusts that one on readiness).
    pub seq: u64,
    /// Where the run stands.
    pub state: RunState,
    /// Why fewer trials than wanted, when it is not just an empty queue.
    pub note: Option<String>,
}

impl WireMessage for WorkGrant {
    const NAME: &'static str = "WorkGrant";
    const KIND: u8 = 9;
    fn validate(&self) -> Check {
        if self.trials.len() > 4096 {
            return Err(("trials", "more than 4096".into()));
        }
        for t in &self.trials {
            t.validate()?;
        }
        if self.note.as_ref().is_some_and(|n| n.len() > 4096) {
            return Err(("note", "longer than 4096 bytes".into()));
        }
        Ok(())
    }
}

/// A `naofarm ctl` request (the payload of a query on `<prefix>/@runs/<id>/ctl`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ControlRequest {
    /// What to do.
    pub action: Control,
    /// Who asks (user@host), journaled with the action.
    pub by: String,
}

impl WireMessage for ControlRequest {
    const NAME: &'static str = "ControlRequest";
    const KIND: u8 = 10;
    fn validate(&self) -> Check {
        self.action.check().map_err(|m| ("action", m))?;
        if self.by.len() > 256 {
            return Err(("by", "longer than 256 bytes".into()));
        }
        Ok(())
    }
}

/// What `naofarm ctl` (or `--priority`) can do to a run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Control {
    /// Hand out no more trials (those in flight finish).
    Pause,
    /// Hand out trials again.
    Resume,
    /// The run's priority (1..=1000): its share of a shared fleet follows it.
    Priority(u32),
    /// The coordinator stops (the run can be resumed later).
    Stop,
}

/// The highest priority a run can have.
pub const MAX_PRIORITY: u32 = 1000;

impl Control {
    /// Checks the action's numbers.
    pub fn check(self) -> Result<(), String> {
        match self {
            Self::Priority(p) if p == 0 || p > MAX_PRIORITY => {
                Err(format!("priority {p} is not in 1..={MAX_PRIORITY}"))
            }
            _ => Ok(()),
        }
    }
}

/// A worker's announcement: who it is and how many trials it can take.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WorkerPresence {
    /// Worker id (a UUID).
    pub worker: String,
    /// Trials it runs at once.
    pub slots: u32,
    /// Trials it is running now.
    pub busy: u32,
    /// naofarm version of the worker.
    pub version: String,
    /// The dispatch ids of this run's trials the worker is running now: the
    /// run renews their leases, so a trial longer than its lease is never
    /// offered again while its worker speaks.
    pub running: Vec<u64>,
}

impl WireMessage for WorkerPresence {
    const NAME: &'static str = "WorkerPresence";
    const KIND: u8 = 4;
    fn validate(&self) -> Check {
        chunk("worker", &self.worker)?;
        if self.slots == 0 || self.slots > 4096 {
            return Err(("slots", format!("{} is not in 1..=4096", self.slots)));
        }
        if self.busy > self.slots {
            return Err(("busy", "more busy slots than slots".into()));
        }
        if self.version.len() > 64 {
            return Err(("version", "longer than 64 bytes".into()));
        }
        if self.running.len() > self.slots as usize {
            return Err(("running", "more trials running than slots".into()));
        }
        Ok(())
    }
}

/// A run's state, for late joiners and watchers.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunStatus {
    /// Run name (the experiment's; a label).
    pub run: String,
    /// Run id (a UUID, given when the run's directory was created).
    pub id: String,
    /// The run's priority: its share of a shared fleet.
    pub priority: u32,
    /// Running, paused, stopped or finished.
    pub state: RunState,
    /// Iterations planned.
    pub planned: u64,
    /// Iterations opened so far (the current iteration is `opened - 1`).
    pub opened: u64,
    /// Iterations decided so far.
    pub decided: u64,
    /// ACCEPT count.
    pub accepts: u64,
    /// EQUIVALENT count.
    pub equivalents: u64,
    /// REJECT count.
    pub rejects: u64,
    /// ν′ and its parameters (Optim.1).
    pub best: Option<Best>,
    /// CLOP's mean recommendation (Optim.2), external units.
    pub optim2: Vec<(String, f64)>,
    /// Iterations decided when `optim2` was computed: a running coordinator
    /// refits CLOP's mean every few decisions, not after each (its cost grows
    /// with the history); a finished, stopped or controlled run's is current.
    pub optim2_decided: u64,
    /// Workers currently alive.
    pub workers: u32,
    /// Trials completed per wall-clock second, recent average.
    pub trials_per_s: f64,
    /// Whether every planned iteration is decided.
    pub finished: bool,
    /// Trials that failed on a worker or that a worker gave back, by reason
    /// (at most [`MAX_REASONS`]; the rest counted under "other reasons").
    #[serde(default)]
    pub failures: Vec<(String, u64)>,
    /// Messages the coordinator refused (undecodable, for another run, not
    /// asked for, a forged or late answer), by reason, as `failures`.
    #[serde(default)]
    pub refused: Vec<(String, u64)>,
}

/// Most reasons a [`RunStatus`] lists in `failures` or `refused`.
pub const MAX_REASONS: usize = 16;
/// Longest reason a [`RunStatus`] lists, bytes.
pub const MAX_REASON_LEN: usize = 240;

/// Counts by reason as a status lists them: the most frequent
/// [`MAX_REASONS`] − 1 reasons, each cut to [`MAX_REASON_LEN`] bytes, and
/// the rest summed under "other reasons".
#[must_use]
pub fn reason_counts<'a>(
    counts: impl IntoIterator<Item = (&'a String, &'a u64)>,
) -> Vec<(String, u64)> {
    let mut all: Vec<(String, u64)> = counts
        .into_iter()
        .map(|(r, n)| (cut(r, MAX_REASON_LEN), *n))
        .collect();
    all.sort_by(|a, b| b.1.cmp(&a.1).then_with(|| a.0.cmp(&b.0)));
    if all.len() > MAX_REASONS {
        let rest: u64 = all[MAX_REASONS - 1..].iter().map(|(_, n)| n).sum();
        all.truncate(MAX_REASONS - 1);
        all.push(("other reasons".into(), rest));
    }
    all
}

/// `s` cut to at most `max` bytes on a character boundary.
/// The longest reason a [`TrialFailure`] carries, in bytes.
pub const MAX_FAILURE_REASON: usize = 4096;

/// A failure's reason as the wire takes it: control characters escaped (a
/// reason is one line), cut on a character boundary to at most
/// [`MAX_FAILURE_REASON`] bytes with `…` marking the cut. Never refused.
#[must_use]
pub fn fit_reason(reason: &str) -> String {
    let mut out = String::with_capacity(reason.len().min(MAX_FAILURE_REASON));
    for c in reason.chars() {
        if c.is_control() {
            out.extend(c.escape_default());
        } else {
            out.push(c);
        }
        if out.len() > MAX_FAILURE_REASON {
            break;
        }
    }
    if out.len() > MAX_FAILURE_REASON {
        let mut kept = cut(&out, MAX_FAILURE_REASON - '…'.len_utf8());
        kept.push('…');
        return kept;
    }
    out
}

fn cut(s: &str, max: usize) -> String {
    let mut end = s.len().min(max);
    while !s.is_char_boundary(end) {
        end -= 1;
    }
    s[..end].to_string()
}

fn reasons(field: &'static str, list: &[(String, u64)]) -> Check {
    if list.len() > MAX_REASONS {
        return Err((
            field,
            format!("{} reasons, at most {MAX_REASONS}", list.len()),
        ));
    }
    match list.iter().find(|(r, _)| r.len() > MAX_REASON_LEN) {
        Some(_) => Err((
            field,
            format!("a reason longer than {MAX_REASON_LEN} bytes"),
        )),
        None => Ok(()),
    }
}

impl WireMessage for RunStatus {
    const NAME: &'static str = "RunStatus";
    const KIND: u8 = 5;
    fn validate(&self) -> Check {
        chunk("run", &self.run)?;
        chunk("id", &self.id)?;
        Control::Priority(self.priority)
            .check()
            .map_err(|m| ("priority", m))?;
        if self.decided > self.opened {
            return Err(("decided", "more decided than opened".into()));
        }
        if self.accepts + self.equivalents + self.rejects != self.decided {
            return Err(("accepts", "decision counts do not add up to decided".into()));
        }
        param_list("optim2", &self.optim2, any_value)?;
        if self.optim2_decided > self.decided {
            return Err(("optim2_decided", "more than decided".into()));
        }
        if let Some(b) = &self.best {
            param_list("best.params", &b.params, any_value)?;
            b.stats.check()?;
        }
        reasons("failures", &self.failures)?;
        reasons("refused", &self.refused)?;
        finite("trials_per_s", self.trials_per_s)
    }
}

/// Iterations per reply of a run's `history` query: a long history is
/// answered in parts, so that no one reply outgrows the link's queue.
pub const HISTORY_PART: usize = 25;

/// A run's history from the replies to its `history` query (each a JSON
/// array of [`IterationResult`]s, in any order, possibly overlapping): every
/// iteration once, in order.
pub fn history_from_parts(parts: &[String]) -> Result<Vec<IterationResult>, DecodeError> {
    let mut all: std::collections::BTreeMap<u64, IterationResult> =
        std::collections::BTreeMap::new();
    for part in parts {
        let rows: Vec<IterationResult> =
            serde_json::from_str(part).map_err(|e| DecodeError::Body {
                message: "history",
                detail: e.to_string(),
            })?;
        for r in rows {
            let r = r.checked()?;
            all.insert(r.iteration, r);
        }
    }
    Ok(all.into_values().collect())
}

/// A worker's public status, for watchers (JSON on
/// `<prefix>/@workers/<id>/status`, published every second).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WorkerStatus {
    /// Worker id (a UUID).
    pub worker: String,
    /// The host it runs on (its hostname).
    pub host: String,
    /// Trials it runs at once.
    pub slots: u32,
    /// Trials it holds now.
    pub busy: u32,
    /// Its fingerprint (`naofarm fingerprint`), 16 hex digits.
    pub fingerprint: String,
    /// naofarm version of the worker.
    pub version: String,
    /// The runs whose trials it holds now: run id and trials held.
    pub runs: Vec<(String, u32)>,
    /// Trials it ran and reported since it started.
    pub trials: u64,
    /// Trials it failed or gave back since it started.
    pub refused: u64,
    /// The trial programs it registered, by name.
    #[serde(default)]
    pub programs: Vec<String>,
    /// How it contains its programs' processes (docs/programs.md), e.g.
    /// `cgroup v2 + PID namespace`.
    #[serde(default)]
    pub containment: String,
}

impl WireMessage for WorkerStatus {
    const NAME: &'static str = "WorkerStatus";
    const KIND: u8 = 11;
    fn validate(&self) -> Check {
        chunk("worker", &self.worker)?;
        if self.host.is_empty() || self.host.len() > 253 || self.host.chars().any(char::is_control)
        {
            return Err(("host", "not a host name of 1 to 253 printable bytes".into()));
        }
        if self.slots == 0 || self.slots > 4096 {
            return Err(("slots", format!("{} is not in 1..=4096", self.slots)));
        }
        if self.busy > self.slots {
            return Err(("busy", "more busy slots than slots".into()));
        }
        if self.fingerprint.len() != 16 || !self.fingerprint.chars().all(|c| c.is_ascii_hexdigit())
        {
            return Err(("fingerprint", "not 16 hex digits".into()));
        }
        if self.version.len() > 64 {
            return Err(("version", "longer than 64 bytes".into()));
        }
        if self.runs.len() > 4096 {
            return Err(("runs", "more than 4096 runs".into()));
        }
        for (run, _) in &self.runs {
            chunk("runs", run)?;
        }
        if self.runs.iter().map(|(_, n)| u64::from(*n)).sum::<u64>() > u64::from(self.busy) {
            return Err(("runs", "more trials held than busy slots".into()));
        }
        if self.programs.len() > 64 {
            return Err(("programs", "more than 64 programs".into()));
        }
        for p in &self.programs {
            crate::experiment::check_program_name(p).map_err(|m| ("programs", m))?;
        }
        if self.containment.len() > 128 || self.containment.chars().any(char::is_control) {
            return Err((
                "containment",
                "not a description of at most 128 printable bytes".into(),
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// A reason of any length or content fits the wire: escaped, cut on a
    /// character boundary, and a failure carrying it decodes.
    #[test]
    fn any_reason_fits_a_failure() {
        let junk = format!("{}\u{1b}[31m\n{}", "é".repeat(3000), "x".repeat(3000));
        let r = fit_reason(&junk);
        assert!(r.len() <= MAX_FAILURE_REASON, "{}", r.len());
        assert!(r.ends_with('…') && !r.chars().any(char::is_control));
        assert_eq!(fit_reason("a\tb\u{7}"), "a\\tb\\u{7}");
        assert_eq!(fit_reason("short"), "short");
        let f = TrialFailure {
            run: "r".into(),
            iteration: 0,
            trial: 0,
            seed: 1,
            dispatch: 2,
            worker: "w".into(),
            reason: r,
            refused: false,
        };
        assert_eq!(TrialFailure::decode(&f.encode().unwrap()), Ok(f));
    }

    fn stats() -> impl Strategy<Value = Stats> {
        (0u32..20, any::<bool>(), -5.0f64..5.0, 0.0f64..1.0).prop_map(|(n, some, x, e)| Stats {
            trials: n + 1,
            successes: n / 2,
            s: f64::from(n / 2) / f64::from(n + 1),
            mx: some.then_some(x),
            my: some.then_some(x.abs()),
            ex: some.then_some(e),
            ey: None,
            mx_all: x,
            my_all: x.abs(),
        })
    }

    fn params() -> impl Strategy<Value = Vec<(String, f64)>> {
        proptest::collection::vec((0usize..5, 0.0f64..1.0), 0..5).prop_map(|v| {
            v.into_iter()
                .map(|(i, t)| {
                    let p = &crate::params::KNOWN[i];
                    (p.name.to_string(), p.min + t * (p.max - p.min))
                })
                .collect()
        })
    }

    fn run() -> impl Strategy<Value = String> {
        "[a-z0-9_-]{1,20}"
    }

    proptest! {
        #[test]
        fn trial_request_round_trips(run in run(), i in any::<u64>(), k in any::<u32>(), seed in any::<u64>(),
                                     d in 0.1f64..100.0, ps in params(), t in 0u8..5, disp in any::<u64>(),
                                     sub in 1u32..=50, its in 1u32..=16, pgs in 1u32..=200) {
            let physics = Physics { substeps: sub, solver_iterations: its, pgs_iterations: pgs };
            let m = TrialRequest { run, iteration: i, trial: k, seed, model: TrialModel::Synthetic, program: None,
                                   robot_type: t, duration_s: d, params: ps, dispatch: disp, physics };
            prop_assert_eq!(TrialRequest::decode(&m.encode().unwrap()), Ok(m));
        }

        #[test]
        fn trial_outcome_round_trips(run in run(), i in any::<u64>(), k in any::<u32>(), fell in any::<bool>(),
                                     x in -100.0f64..100.0, y in -100.0f64..100.0, t in 0.0f64..10.0, f in any::<u64>()) {
            let m = TrialOutcome { run, iteration: i, trial: k, seed: 7, dispatch: 1, worker: "w".into(), fell,
                                   x_m: x, y_m: y, fall_time_s: fell.then_some(t), sim_time_s: t, wall_time_s: 0.5, fingerprint: f };
            prop_assert_eq!(TrialOutcome::decode(&m.encode().unwrap()), Ok(m));
        }

        #[test]
        fn iteration_result_round_trips(run in run(), i in any::<u64>(), ps in params(), st in stats(), best in any::<bool>()) {
            let m = IterationResult { run, iteration: i, params: ps.clone(), stats: st.clone(), decision: Decision::Equivalent,
                                      best: best.then_some(Best { iteration: i, params: ps, stats: st }) };
            prop_assert_eq!(IterationResult::decode(&m.encode().unwrap()), Ok(m.clone()));
            prop_assert_eq!(IterationResult::from_json(&m.to_json().unwrap()), Ok(m));
        }

        #[test]
        fn presence_and_status_round_trip(w in run(), slots in 1u32..64, a in 0u64..100, e in 0u64..100, r in 0u64..100, ps in params()) {
            let p = WorkerPresence { worker: w.clone(), slots, busy: slots / 2, version: "0.1.0".into(), running: (0..u64::from(slots / 2)).collect() };
            prop_assert_eq!(WorkerPresence::decode(&p.encode().unwrap()), Ok(p));
            let s = RunStatus { run: w.clone(), id: format!("{w}-id"), priority: 2, state: RunState::Running, planned: 500, opened: a + e + r + 2, decided: a + e + r, accepts: a,
                                equivalents: e, rejects: r, best: None, optim2: ps, optim2_decided: a + e + r, workers: 3, trials_per_s: 1.5, finished: false,
                                failures: vec![("panic: x".into(), a)], refused: Vec::new() };
            prop_assert_eq!(RunStatus::decode(&s.encode().unwrap()), Ok(s.clone()));
            prop_assert_eq!(RunStatus::from_json(&s.to_json().unwrap()), Ok(s));
        }

        #[test]
        fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..512)) {
            let _ = TrialRequest::decode(&bytes);
            let _ = TrialOutcome::decode(&bytes);
            let _ = IterationResult::decode(&bytes);
            let _ = WorkerPresence::decode(&bytes);
            let _ = RunStatus::decode(&bytes);
            let _ = RunAdvert::decode(&bytes);
            let _ = WorkRequest::decode(&bytes);
            let _ = WorkGrant::decode(&bytes);
            let _ = ControlRequest::decode(&bytes);
        }

        #[test]
        fn fleet_messages_round_trip(w in run(), slots in 1u32..64, p in 1u32..1000, ready in any::<u32>(), seq in any::<u64>()) {
            let ad = RunAdvert { id: format!("{w}-id"), name: w.clone(), priority: p, ready, running: ready, state: RunState::Paused, duration_s: 10.0, program: None, seq };
            prop_assert_eq!(RunAdvert::decode(&ad.encode().unwrap()), Ok(ad));
            let rq = WorkRequest { worker: w.clone(), want: slots, slots, busy: 0, max_duration_s: 60.0, version: "x".into(), fingerprint: seq, program: None };
            prop_assert_eq!(WorkRequest::decode(&rq.encode().unwrap()), Ok(rq));
            let c = ControlRequest { action: Control::Priority(p), by: w };
            prop_assert_eq!(ControlRequest::decode(&c.encode().unwrap()), Ok(c));
        }

        #[test]
        fn arbitrary_bodies_behind_a_valid_header_never_panic(kind in 1u8..11, body in proptest::collection::vec(any::<u8>(), 0..256)) {
            let mut bytes = vec![b'N', b'F', WIRE_VERSION, kind];
            bytes.extend(body);
            let _ = TrialRequest::decode(&bytes);
            let _ = TrialOutcome::decode(&bytes);
            let _ = IterationResult::decode(&bytes);
            let _ = WorkerPresence::decode(&bytes);
            let _ = RunStatus::decode(&bytes);
            let _ = RunAdvert::decode(&bytes);
            let _ = WorkRequest::decode(&bytes);
            let _ = WorkGrant::decode(&bytes);
            let _ = ControlRequest::decode(&bytes);
        }
    }

    #[test]
    fn fleet_messages_refuse_absurd_numbers() {
        let rq = WorkRequest {
            worker: "w".into(),
            want: 5,
            slots: 4,
            busy: 0,
            max_duration_s: 60.0,
            version: "x".into(),
            fingerprint: 1,
            program: None,
        };
        assert!(matches!(
            WorkRequest::decode(&rq.encode().unwrap()),
            Err(DecodeError::Field { field: "want", .. })
        ));
        let c = ControlRequest {
            action: Control::Priority(0),
            by: "me".into(),
        };
        assert!(matches!(
            ControlRequest::decode(&c.encode().unwrap()),
            Err(DecodeError::Field {
                field: "action",
                ..
            })
        ));
        let ad = RunAdvert {
            id: "i".into(),
            name: "n".into(),
            priority: 1001,
            ready: 1,
            running: 0,
            state: RunState::Running,
            duration_s: 1.0,
            program: None,
            seq: 1,
        };
        assert!(ad.encode().is_ok_and(|b| RunAdvert::decode(&b).is_err()));
    }

    fn outcome() -> TrialOutcome {
        TrialOutcome {
            run: "r".into(),
            iteration: 1,
            trial: 2,
            seed: 3,
            dispatch: 4,
            worker: "w".into(),
            fell: false,
            x_m: 1.0,
            y_m: 0.1,
            fall_time_s: None,
            sim_time_s: 10.0,
            wall_time_s: 0.1,
            fingerprint: 5,
        }
    }

    #[test]
    fn rejects_trailing_bytes_version_kind_and_nan() {
        let mut b = outcome().encode().unwrap();
        b.push(0);
        assert!(matches!(
            TrialOutcome::decode(&b),
            Err(DecodeError::Trailing { extra: 1, .. })
        ));
        let mut b = outcome().encode().unwrap();
        b[2] = WIRE_VERSION + 1;
        assert!(matches!(
            TrialOutcome::decode(&b),
            Err(DecodeError::Version { found, .. }) if found == WIRE_VERSION + 1
        ));
        let b = outcome().encode().unwrap();
        assert!(matches!(
            TrialRequest::decode(&b),
            Err(DecodeError::WrongKind { .. })
        ));
        let mut o = outcome();
        o.x_m = f64::NAN;
        let e = TrialOutcome::decode(&o.encode().unwrap())
            .unwrap_err()
            .to_string();
        assert!(e.contains("TrialOutcome") && e.contains("x_m"), "{e}");
        let huge = vec![0u8; MAX_MESSAGE_BYTES + 1];
        assert!(matches!(
            TrialOutcome::decode(&huge),
            Err(DecodeError::TooLarge { .. })
        ));
    }

    #[test]
    fn a_huge_length_prefix_does_not_allocate() {
        // A string length of u64::MAX must be refused by the limit, not attempted.
        let mut b = vec![b'N', b'F', WIRE_VERSION, TrialOutcome::KIND, 0xff];
        b.extend_from_slice(&u64::MAX.to_le_bytes());
        assert!(matches!(
            TrialOutcome::decode(&b),
            Err(DecodeError::Body { .. })
        ));
    }

    #[test]
    fn request_outside_admissible_range_is_refused() {
        let r = TrialRequest {
            run: "r".into(),
            iteration: 0,
            trial: 0,
            seed: 0,
            model: TrialModel::Nao,
            program: None,
            robot_type: 0,
            duration_s: 10.0,
            params: vec![("ThighRelHip2_Z".into(), 0.5)],
            dispatch: 0,
            physics: Physics::default(),
        };
        let e = TrialRequest::decode(&r.encode().unwrap())
            .unwrap_err()
            .to_string();
        assert!(e.contains("ThighRelHip2_Z"), "{e}");
        // Physics out of range, each refused naming its field.
        for (physics, field) in [((0, 28), "substeps"), ((4, 0), "pgs_iterations")] {
            let r = TrialRequest {
                params: vec![("ThighRelHip2_Z".into(), -0.04)],
                physics: Physics {
                    substeps: physics.0,
                    pgs_iterations: physics.1,
                    ..Physics::default()
                },
                ..r.clone()
            };
            let e = TrialRequest::decode(&r.encode().unwrap())
                .unwrap_err()
                .to_string();
            assert!(e.contains(field), "{e}");
        }
    }
}
