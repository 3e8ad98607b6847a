//! What every command shares: the exit-code failure, reading an experiment
//! file, parsing NAME=VALUE parameters. A leaf: it uses no command module.

use std::path::Path;

use anyhow::Context;
use protocol::Experiment;

/// Exit-code classes: 2 for usage or configuration errors, 1 for a failed job.
pub enum Failure {
    /// Bad arguments, a bad file: exit 2.
    Usage(anyhow::Error),
    /// The job itself failed: exit 1.
    Job(anyhow::Error),
}

/// A usage error (exit 2) saying `why`, unless `ok`.
pub fn usage_unless(ok: bool, why: impl FnOnce() -> String) -> Result<(), Failure> {
    if ok {
        Ok(())
    } else {
        Err(Failure::Usage(anyhow::anyhow!(why())))
    }
}

/// A coordinator service failure: serving a run twice is a usage error (exit 2), the rest job failures.
pub fn service_failure(e: coordinator::service::ServiceError) -> Failure {
    match e {
        coordinator::service::ServiceError::AlreadyServed { .. } => Failure::Usage(e.into()),
        e => Failure::Job(e.into()),
    }
}

/// Writes `text` to stdout; a closed pipe (`| head`) ends quietly.
pub fn emit(text: &str) -> Result<(), Failure> {
    crate::out::write(text);
    Ok(())
}

/// The most an experiment file may hold. The shipped files are 1–4 KiB; a
/// bound keeps `check /dev/zero` (or a mistyped path to a data file) from
/// reading without end.
const MAX_EXPERIMENT_BYTES: u64 = 1 << 20;

/// Reads and validates an experiment file (a usage error when it is bad).
pub fn load_experiment(path: &Path) -> Result<(Experiment, String), Failure> {
    let text = read_bounded(path, MAX_EXPERIMENT_BYTES)
        .with_context(|| format!("cannot read {}", path.display()))
        .map_err(Failure::Usage)?;
    let e = Experiment::from_toml(&text)
        .with_context(|| format!("{}", path.display()))
        .map_err(Failure::Usage)?;
    Ok((e, text))
}

/// Makes the output directory `dir` given by `what` (e.g. `--out`) unless
/// it is there: a file or a device already at that path is a usage error
/// that names it, and is left as it is.
pub fn make_dir(dir: &Path, what: &str) -> Result<(), Failure> {
    if dir.exists() && !dir.is_dir() {
        return Err(Failure::Usage(anyhow::anyhow!(
            "{what} {}: exists and is not a directory",
            dir.display()
        )));
    }
    std::fs::create_dir_all(dir)
        .map_err(|e| Failure::Job(anyhow::anyhow!("{what} {}: {e}", dir.display())))
}

/// A usage error (exit 2), `FLAG VALUE: must be in LO..=HI`, unless `value`
/// lies in `range`.
pub fn flag_in<T: PartialOrd + std::fmt::Display>(
    flag: &str,
    value: T,
    range: std::ops::RangeInclusive<T>,
) -> Result<(), Failure> {
    if range.contains(&value) {
        return Ok(());
    }
    Err(Failure::Usage(anyhow::anyhow!(
        "{flag} {value}: must be in {}..={}",
        range.start(),
        range.end()
    )))
}

/// Reads a UTF-8 text file of at most `max` bytes; a longer one is an error
/// that says so, read no further than `max + 1` bytes.
fn read_bounded(path: &Path, max: u64) -> anyhow::Result<String> {
    use std::io::Read;
    let file = std::fs::File::open(path)?;
    if file.metadata()?.is_dir() {
        anyhow::bail!("it is a directory");
    }
    let mut bytes = Vec::new();
    file.take(max + 1).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > max {
        anyhow::bail!("it holds more than {max} bytes; an experiment file is a few KiB");
    }
    String::from_utf8(bytes).map_err(|_| anyhow::anyhow!("it is not UTF-8 text"))
}

/// Where a NAO experiment's start replaces the body of robot type
/// `robot_type` (the experiment's, or `trial --type`'s): each morphology
/// parameter whose expert (in L) or fixed value differs from the type's,
/// with a line that says so; e.g. the paper's files' ThighRelHip2_Z −0.04
/// given type 3, whose own thigh is −0.067868424.
pub fn type_overrides(e: &Experiment, robot_type: u8) -> Vec<(String, String)> {
    use worker::nao::model::Morphology;
    let Ok(body) = Morphology::of_type(robot_type) else {
        return Vec::new();
    };
    let starts = e
        .parameter
        .iter()
        .map(|p| (p.name.as_str(), p.expert_value(), "expert"))
        .chain(e.fixed.iter().map(|(k, v)| (k.as_str(), *v, "fixed value")));
    starts
        .filter_map(|(name, value, what)| {
            let own = protocol::params::find(name).and_then(|k| body.get(k.param))?;
            (own != value).then(|| {
                let line = format!(
                    "{name}'s {what} {} replaces robot type {}'s own {}",
                    protocol::params::Shown(value),
                    robot_type,
                    protocol::params::Shown(own)
                );
                (name.to_string(), line)
            })
        })
        .collect()
}

pub fn parse_params(params: &[String]) -> Result<Vec<(String, f64)>, Failure> {
    params
        .iter()
        .map(|p| {
            let (name, value) = p.split_once('=').ok_or_else(|| {
                Failure::Usage(anyhow::anyhow!("--param `{p}`: expected NAME=VALUE"))
            })?;
            let v: f64 = value.trim().parse().map_err(|_| {
                Failure::Usage(anyhow::anyhow!("--param `{p}`: `{value}` is not a number"))
            })?;
            if !v.is_finite() {
                return Err(Failure::Usage(anyhow::anyhow!(
                    "--param `{p}`: not a finite number"
                )));
            }
            Ok((name.trim().to_string(), v))
        })
        .collect()
}

/// The league's type `robot_type` with morphology overrides NAME=VALUE (a
/// walk parameter or an unknown name is a usage error).
pub fn morphology(
    robot_type: u8,
    params: &[String],
) -> Result<worker::nao::model::Morphology, Failure> {
    use worker::nao::model::{ModelError, Morphology};
    let mut m = Morphology::of_type(robot_type).map_err(|e| Failure::Usage(e.into()))?;
    for (name, v) in parse_params(params)? {
        let p = protocol::params::find(&name).ok_or(ModelError::Unknown(name.clone()));
        p.and_then(|p| m.set(p.param, v))
            .map_err(|e| Failure::Usage(e.into()))?;
    }
    Ok(m)
}

/// Says on stderr what a torn tail means, unless the run is live (then it is in progress).
pub fn note_tail(dir: &Path, view: &coordinator::run::RunView) {
    if let (coordinator::journal::Tail::Torn { offset, len }, false) = (&view.tail, view.live) {
        eprintln!(
            "note: {}: the last {len} bytes (from offset {offset}) are an interrupted append; \
             resuming the run saves them to journal.nfj.torn-{offset} and cuts them",
            coordinator::journal::Journal::path_in(dir).display()
        );
    }
}

/// What is wrong with `dir` as a run directory, naming it, when it is none:
/// missing, a file, or a directory without a journal (a usage error).
pub fn not_a_run(dir: &Path) -> Option<String> {
    let journal = coordinator::journal::Journal::path_in(dir);
    let why = if !dir.exists() {
        "does not exist"
    } else if !dir.is_dir() {
        "is a file, not a run directory"
    } else if !journal.exists() {
        "is not a run directory: it holds no journal.nfj"
    } else {
        return None;
    };
    Some(format!("{}: {why}", dir.display()))
}

/// Reads the run in `dir` for a command that only reads it: a journal that
/// cannot be opened is a usage error (exit 2), a damaged one a failed job.
pub fn read_run(dir: &Path) -> Result<coordinator::run::RunView, Failure> {
    only_read(dir, coordinator::run::read_run)
}

/// The run in `dir` replayed from its journal as a resume replays it (its
/// CLOP state, hence its Table IV sets), for a command that only reads it:
/// errors as [`read_run`]'s.
pub fn replay_run(dir: &Path) -> Result<coordinator::evolve::Evolve, Failure> {
    only_read(dir, coordinator::run::replay)
}

/// `read` of the run in `dir`, its errors as a reading command gives them.
fn only_read<T>(
    dir: &Path,
    read: impl FnOnce(&Path) -> Result<T, coordinator::run::RunError>,
) -> Result<T, Failure> {
    if let Some(why) = not_a_run(dir) {
        return Err(Failure::Usage(anyhow::Error::msg(why)));
    }
    read(dir).map_err(|e| match e {
        coordinator::run::RunError::Journal(coordinator::journal::JournalError::Io { .. }) => {
            Failure::Usage(e.into())
        }
        e => Failure::Job(e.into()),
    })
}

/// A Table IV set's short name, as `naofarm trial --set` takes it and the
/// report names its replay files: `Optim.1` → `optim1`.
#[must_use]
pub fn set_key(name: &str) -> String {
    name.to_lowercase().replace('.', "")
}

/// Registers `--program NAME=PATH` (each checked, hashed and asked its
/// `--version`) with `--program-timeout-s`; a bad one is a usage error.
pub async fn register_programs(
    args: &crate::args::ProgramArgs,
    slots: u32,
) -> Result<worker::program::Programs, Failure> {
    let t = args.program_timeout_s;
    usage_unless(t.is_finite() && t > 0.0 && t <= 86_400.0, || {
        format!(
            "--program-timeout-s {}: must be in (0, 86400] seconds",
            protocol::params::Shown(t)
        )
    })?;
    let g = args.program_grace_s;
    usage_unless(g.is_finite() && (0.0..=600.0).contains(&g), || {
        format!(
            "--program-grace-s {}: must be in [0, 600] seconds",
            protocol::params::Shown(g)
        )
    })?;
    let env = worker::program::Settings::parse_env(&args.program_env)
        .map_err(|e| Failure::Usage(anyhow::anyhow!(e)))?;
    let d = worker::job::Limits::defaults(slots);
    let given = |v: Option<u64>, default: Option<u64>| match v {
        Some(0) => None,
        Some(v) => Some(v),
        None => default,
    };
    let limits = worker::job::Limits {
        memory_mib: given(args.program_memory_mib, d.memory_mib),
        processes: given(args.program_processes, d.processes),
        file_size_mib: given(args.program_file_size_mib, d.file_size_mib),
        cpu_s: given(args.program_cpu_s, d.cpu_s),
    };
    let settings = worker::program::Settings {
        timeout: std::time::Duration::from_secs_f64(t),
        grace: std::time::Duration::from_secs_f64(g),
        env,
        limits,
    };
    worker::program::Programs::register(&args.programs, settings)
        .await
        .map_err(|e| Failure::Usage(e.into()))
}
