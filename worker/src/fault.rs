//! Fault hooks for tests, switched on at run time by an environment variable
//! (never by a second build): `NAOFARM_FAULT_TRIAL=MODE[@I/K]` makes every
//! trial (or only trial K of iteration I) misbehave, where MODE is `fail` (an
//! error), `panic`, `nan` (a non-finite result) or `forge` (x = 10⁶ m, a
//! result no robot walks); `NAOFARM_FAULT_GRANT` ([`grant_bytes`]) makes
//! every grant's trials unreadable. Without the variables,
//! [`run_trial`] is exactly [`crate::run_trial`].

use protocol::TrialRequest;

use crate::{Measurement, TrialError};

/// The environment variable that switches a fault on.
pub const TRIAL_FAULT_VAR: &str = "NAOFARM_FAULT_TRIAL";

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Mode {
    Fail,
    Panic,
    Nan,
    Forge,
}

fn fault_for(req: &TrialRequest) -> Option<Mode> {
    let spec = std::env::var(TRIAL_FAULT_VAR).ok()?;
    let (mode, target) = match spec.split_once('@') {
        Some((m, t)) => (m, Some(t)),
        None => (spec.as_str(), None),
    };
    let mode = match mode {
        "fail" => Mode::Fail,
        "panic" => Mode::Panic,
        "nan" => Mode::Nan,
        "forge" => Mode::Forge,
        _ => return None,
    };
    if let Some(t) = target {
        let (i, k) = t.split_once('/')?;
        if i.parse::<u64>().ok()? != req.iteration || k.parse::<u32>().ok()? != req.trial {
            return None;
        }
    }
    Some(mode)
}

/// `NAOFARM_FAULT_OUTCOME=wrong-dispatch|other-run|unsent`: the worker
/// tampers with every outcome it sends (another dispatch id, another run's
/// name, a trial it was never sent).
pub const OUTCOME_FAULT_VAR: &str = "NAOFARM_FAULT_OUTCOME";

/// Applies the outcome fault hook, if set.
pub fn tamper(o: &mut protocol::TrialOutcome) {
    match std::env::var(OUTCOME_FAULT_VAR).as_deref() {
        Ok("wrong-dispatch") => o.dispatch ^= 0x5a5a,
        Ok("other-run") => o.run = format!("{}-other", o.run),
        Ok("unsent") => o.trial += 1000,
        _ => {}
    }
}

/// `NAOFARM_FAULT_GRANT=unknown-param`: every trial of every grant the
/// worker gets names a parameter no build knows, as a grant from a build
/// with another parameter registry would.
pub const GRANT_FAULT_VAR: &str = "NAOFARM_FAULT_GRANT";

/// Applies the grant fault hook to a grant's bytes as received, if set.
#[must_use]
pub fn grant_bytes(bytes: Vec<u8>) -> Vec<u8> {
    use protocol::wire::{WireMessage, WorkGrant};
    if std::env::var(GRANT_FAULT_VAR).as_deref() != Ok("unknown-param") {
        return bytes;
    }
    let Ok(mut g) = WorkGrant::decode_unchecked(&bytes) else {
        return bytes;
    };
    for t in &mut g.trials {
        t.params.push(("no_such_parameter".into(), 1.0));
    }
    g.encode().unwrap_or(bytes)
}

/// Runs one trial, unless a fault hook says otherwise.
pub fn run_trial(req: &TrialRequest) -> Result<Measurement, TrialError> {
    match fault_for(req) {
        None => crate::run_trial(req),
        Some(Mode::Fail) => Err(TrialError::Model(format!(
            "fault hook {TRIAL_FAULT_VAR}: trial {}/{} fails",
            req.iteration, req.trial
        ))),
        Some(Mode::Panic) => panic!(
            "fault hook {TRIAL_FAULT_VAR}: trial {}/{} panics",
            req.iteration, req.trial
        ),
        Some(Mode::Nan) => crate::run_trial(req).map(|mut t| {
            t.x_m = f64::NAN;
            t
        }),
        Some(Mode::Forge) => crate::run_trial(req).map(|mut t| {
            t.x_m = 1e6;
            t
        }),
    }
}
