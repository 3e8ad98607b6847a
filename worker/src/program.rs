//! Trial programs: simulators of the worker owner's choosing, registered by
//! name when the worker starts (`naofarm worker --program NAME=PATH`), run
//! once per trial. The contract (docs/programs.md): the trial goes to the
//! program's standard input as one JSON document ([`ProgramTrial`]); the
//! program prints its measurement as the last line of its standard output
//! ([`ProgramMeasurement`]) and exits 0. Anything else — a non-zero exit,
//! no answer within the worker's time-out (the program and everything it
//! started are killed), junk, a NaN, an implausible value — is a failed
//! trial whose reason carries the last lines of the program's standard
//! error.
//!
//! A coordinator names a program, never a path: only what the worker's
//! owner registered runs. The program's identity (a hash of its file and of
//! its `--version` line) joins the worker's fingerprint for the program's
//! runs, so a run never mixes two builds of a program; a file that changes
//! under a running worker is a new identity before its next trial
//! ([`Program::refreshed`]).
//!
//! Each trial runs as a [`crate::job::Job`]: contained, in a clean
//! environment ([`Settings::env_for`]), under the owner's limits, and
//! stopped whole when it ends, times out or the worker stops. A program
//! whose `--version` says [`SERVE_LINE`] is kept running in its slot
//! between the trials of a run instead ([`crate::served`]): one job then
//! runs the run's trials in that slot one after another.

use std::{
    collections::BTreeMap,
    io::Read,
    path::{Path, PathBuf},
    time::{Duration, SystemTime},
};

use protocol::{measurement::Measurement, TrialRequest};
use serde::{Deserialize, Serialize};
use sha3::{Digest, Sha3_256};
use tokio::io::{AsyncReadExt, AsyncWriteExt};

use crate::job::{Job, Limits};

/// How long `PROGRAM --version` may take when the worker registers it.
const VERSION_WITHIN: Duration = Duration::from_secs(10);
/// Bytes of a program's standard output kept (the measurement is its last line).
const STDOUT_TAIL: usize = 64 << 10;
/// Bytes of a program's standard error kept for a failure's reason.
pub(crate) const STDERR_TAIL: usize = 600;
/// How long the pipes may stay open once the job is killed (on a host
/// without a cgroup or a PID namespace, a process that left the job's group
/// may hold them).
const PIPES_WITHIN: Duration = Duration::from_secs(2);
/// Bytes of `PROGRAM --version` read for its first line.
const VERSION_BYTES: u64 = 4096;
/// A line of `PROGRAM --version` saying the program serves trials one after
/// another when started as `PROGRAM --serve` (docs/programs.md).
pub const SERVE_LINE: &str = "naofarm serve 1";

/// Why a program could not be registered.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum ProgramError {
    /// The `NAME=PATH` text is not one.
    #[error("--program {0}: expected NAME=PATH")]
    Syntax(String),
    /// The name is not a program name.
    #[error("--program {name}: {message}")]
    Name {
        /// The name given.
        name: String,
        /// What is wrong with it.
        message: String,
    },
    /// The path is not an executable file.
    #[error("--program {name}={path}: {message}")]
    Path {
        /// The program's name.
        name: String,
        /// The path given.
        path: String,
        /// What is wrong with it.
        message: String,
    },
    /// The same name twice.
    #[error("--program {0} is registered twice")]
    Twice(String),
}

/// One registered program.
#[derive(Debug, Clone, PartialEq)]
pub struct Program {
    /// The name experiments use.
    pub name: String,
    /// The executable, as an absolute path.
    pub path: PathBuf,
    /// The first line of `PROGRAM --version`, when it answers with exit 0.
    pub version: Option<String>,
    /// Hash of the file's bytes and of `version`: the program's build.
    pub identity: u64,
    /// Whether `--version` said [`SERVE_LINE`]: the program answers trials
    /// one after another as `PROGRAM --serve`.
    pub serves: bool,
    /// The file as registered: (size, modification time, inode).
    stamp: Option<(u64, SystemTime, u64)>,
}

/// How a worker runs its programs' trials.
#[derive(Debug, Clone)]
pub struct Settings {
    /// Longest wall time of one trial before the program is killed.
    pub timeout: Duration,
    /// How long a program asked to stop (SIGTERM) has before it is killed.
    pub grace: Duration,
    /// Variables the owner passes to every program (`--program-env`).
    pub env: Vec<(String, String)>,
    /// What a program may use.
    pub limits: Limits,
}

impl Default for Settings {
    fn default() -> Self {
        Self {
            timeout: Duration::from_secs(600),
            grace: Duration::from_secs(5),
            env: Vec::new(),
            limits: Limits::default(),
        }
    }
}

/// Variables a program always gets, set by the worker: the owner's
/// `--program-env` cannot name them.
pub const SET_BY_THE_WORKER: [&str; 2] = ["HOME", "TMPDIR"];

impl Settings {
    /// A program's whole environment in `scratch`: PATH and LANG (the
    /// worker's, or a plain default), HOME and TMPDIR inside the scratch,
    /// then what the owner passes. Nothing else of the worker's.
    #[must_use]
    pub fn env_for(&self, scratch: &Path) -> Vec<(String, String)> {
        let path = std::env::var("PATH").unwrap_or_else(|_| "/usr/local/bin:/usr/bin:/bin".into());
        let lang = std::env::var("LANG").unwrap_or_else(|_| "C.UTF-8".into());
        let mut env: BTreeMap<String, String> = BTreeMap::from([
            ("PATH".into(), path),
            ("LANG".into(), lang),
            ("HOME".into(), scratch.join("home").display().to_string()),
            ("TMPDIR".into(), scratch.join("tmp").display().to_string()),
        ]);
        for (k, v) in &self.env {
            if !SET_BY_THE_WORKER.contains(&k.as_str()) {
                env.insert(k.clone(), v.clone());
            }
        }
        env.into_iter().collect()
    }

    /// Reads `--program-env` texts: `NAME=VALUE`, or `NAME` for the
    /// worker's own value (absent when the worker has none).
    pub fn parse_env(specs: &[String]) -> Result<Vec<(String, String)>, String> {
        let mut out = Vec::new();
        for spec in specs {
            let (name, value) = match spec.split_once('=') {
                Some((n, v)) => (n, Some(v.to_string())),
                None => (spec.as_str(), None),
            };
            let ok = !name.is_empty()
                && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
                && !name.starts_with(|c: char| c.is_ascii_digit());
            if !ok {
                return Err(format!(
                    "--program-env {spec}: `{name}` is not a variable name"
                ));
            }
            if SET_BY_THE_WORKER.contains(&name) {
                return Err(format!(
                    "--program-env {spec}: {name} is the program's own, inside its scratch"
                ));
            }
            if let Some(v) = value.or_else(|| std::env::var(name).ok()) {
                out.push((name.to_string(), v));
            }
        }
        Ok(out)
    }
}

/// The programs a worker serves, with how it runs them.
#[derive(Debug, Clone, Default)]
pub struct Programs {
    /// The programs by name.
    pub by_name: BTreeMap<String, Program>,
    /// How their trials run.
    pub settings: Settings,
}

impl Programs {
    /// The program registered as `name`, if any.
    #[must_use]
    pub fn get(&self, name: &str) -> Option<&Program> {
        self.by_name.get(name)
    }

    /// Registers `NAME=PATH` texts (from the command line); a name twice is an error.
    pub async fn register(specs: &[String], settings: Settings) -> Result<Self, ProgramError> {
        let mut by_name = BTreeMap::new();
        for spec in specs {
            let (name, path) = spec
                .split_once('=')
                .ok_or_else(|| ProgramError::Syntax(spec.clone()))?;
            let p = Program::register(name, Path::new(path)).await?;
            if by_name.insert(name.to_string(), p).is_some() {
                return Err(ProgramError::Twice(name.to_string()));
            }
        }
        Ok(Self { by_name, settings })
    }
}

impl Program {
    /// Registers the executable at `path` as `name`: checks both, hashes the
    /// file and asks it `--version` (10 s at most; no answer is no version).
    pub async fn register(name: &str, path: &Path) -> Result<Self, ProgramError> {
        protocol::experiment::check_program_name(name).map_err(|message| ProgramError::Name {
            name: name.to_string(),
            message,
        })?;
        let bad = |message: String| ProgramError::Path {
            name: name.to_string(),
            path: path.display().to_string(),
            message,
        };
        let path = std::fs::canonicalize(path).map_err(|e| bad(e.to_string()))?;
        let meta = std::fs::metadata(&path).map_err(|e| bad(e.to_string()))?;
        if !meta.is_file() {
            return Err(bad("not a file".into()));
        }
        if std::os::unix::fs::PermissionsExt::mode(&meta.permissions()) & 0o111 == 0 {
            return Err(bad("not executable".into()));
        }
        let stamp = stamp(&meta);
        let mut h = Sha3_256::new();
        let mut file = std::fs::File::open(&path).map_err(|e| bad(e.to_string()))?;
        let mut chunk = vec![0u8; 1 << 16];
        loop {
            match file.read(&mut chunk) {
                Ok(0) => break,
                Ok(n) => h.update(&chunk[..n]),
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => return Err(bad(e.to_string())),
            }
        }
        let (version, serves) = version_line(&path).await.unzip();
        h.update(version.as_deref().unwrap_or("").as_bytes());
        let d = h.finalize();
        let mut b = [0u8; 8];
        b.copy_from_slice(&d[..8]);
        Ok(Self {
            name: name.to_string(),
            path,
            version,
            identity: u64::from_le_bytes(b),
            serves: serves.unwrap_or(false),
            stamp: Some(stamp),
        })
    }

    /// This program registered anew when its file changed since it was
    /// registered (size, modification time or inode), else `None`.
    pub async fn refreshed(&self) -> Option<Result<Self, ProgramError>> {
        let now = std::fs::metadata(&self.path).ok().map(|m| stamp(&m));
        if now.is_some() && now == self.stamp {
            return None;
        }
        Some(Self::register(&self.name, &self.path).await)
    }

    /// Whether the worker keeps this program in its slot between a run's
    /// trials: it serves, and no CPU-time limit (which bounds one trial)
    /// asks for a process per trial.
    #[must_use]
    pub fn kept(&self, settings: &Settings) -> bool {
        self.serves && settings.limits.cpu_s.is_none()
    }

    /// The worker's fingerprint for this program's runs: its own, mixed with
    /// the program's identity.
    #[must_use]
    pub fn fingerprint(&self, worker: u64) -> u64 {
        let mut h = Sha3_256::new();
        h.update(worker.to_le_bytes());
        h.update(self.name.as_bytes());
        h.update(self.identity.to_le_bytes());
        let d = h.finalize();
        let mut b = [0u8; 8];
        b.copy_from_slice(&d[..8]);
        u64::from_le_bytes(b)
    }
}

/// A file's size, modification time and inode.
fn stamp(meta: &std::fs::Metadata) -> (u64, SystemTime, u64) {
    use std::os::unix::fs::MetadataExt;
    (
        meta.len(),
        meta.modified().unwrap_or(SystemTime::UNIX_EPOCH),
        meta.ino(),
    )
}

/// The first line of `path --version`, if it says one with exit 0 in time,
/// and whether a later line is [`SERVE_LINE`]: run as a job (a clean
/// environment, killed whole), its output read up to a few KiB.
async fn version_line(path: &Path) -> Option<(String, bool)> {
    let dir = std::env::temp_dir();
    let env = Settings::default().env_for(&dir);
    let mut job =
        Job::start_with_args(path, &["--version"], &dir, &env, &Limits::default()).ok()?;
    drop(job.child.stdin.take());
    let mut stdout = job.child.stdout.take()?;
    drop(job.child.stderr.take());
    let read = async {
        let mut out = Vec::new();
        let _ = (&mut stdout)
            .take(VERSION_BYTES)
            .read_to_end(&mut out)
            .await;
        let status = job.child.wait().await.ok()?;
        Some((status, out))
    };
    let got = tokio::time::timeout(VERSION_WITHIN, read).await;
    job.end().await;
    let (status, out) = got.ok()??;
    if !status.success() {
        return None;
    }
    let text = String::from_utf8_lossy(&out);
    let mut lines = text.lines();
    let line = lines.next()?.trim();
    let serves = lines.any(|l| l.trim() == SERVE_LINE);
    (!line.is_empty()).then(|| (line.chars().take(200).collect(), serves))
}

/// What a program reads on its standard input: one trial.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ProgramTrial {
    /// Run id.
    pub run: String,
    /// CLOP iteration.
    pub iteration: u64,
    /// Trial index within the iteration.
    pub trial: u32,
    /// The trial's seed.
    pub seed: u64,
    /// Simulated duration, s.
    pub duration_s: f64,
    /// League robot type 0–4 (the experiment's `robot_type`).
    pub robot_type: u8,
    /// Every parameter by name, in the program's own units.
    pub params: BTreeMap<String, f64>,
    /// The worker's slot the trial runs in (0 ..< slots): no two trials of
    /// this worker run in one slot at once.
    pub slot: u32,
    /// A directory of the slot's own (kept across its trials, removed when
    /// the worker stops): scratch space, nobody else's.
    pub scratch: PathBuf,
}

/// What a program prints as the last line of its standard output.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ProgramMeasurement {
    /// Forward travel, m.
    pub x_m: f64,
    /// Sideways travel (left), m.
    pub y_m: f64,
    /// Whether the robot fell.
    pub fell: bool,
    /// When it fell, simulated s (present exactly when it fell).
    #[serde(default)]
    pub fall_time_s: Option<f64>,
    /// Simulated time run, s.
    pub sim_time_s: f64,
}

/// Reads a pipe to its end, keeping its last `keep` bytes or a little more
/// (a program may write as much as it likes: it is never left blocked on a
/// full pipe).
async fn read_tail(pipe: &mut (impl tokio::io::AsyncRead + Unpin), keep: usize) -> Vec<u8> {
    let mut buf = Vec::new();
    let mut chunk = [0u8; 8192];
    while let Ok(n) = pipe.read(&mut chunk).await {
        if n == 0 {
            break;
        }
        buf.extend_from_slice(&chunk[..n]);
        if buf.len() > 2 * keep {
            buf.drain(..buf.len() - keep);
        }
    }
    buf
}

/// The last `STDERR_TAIL` bytes of `err`, as text on one line.
pub(crate) fn tail(err: &[u8]) -> String {
    let text = String::from_utf8_lossy(err);
    let lines: Vec<&str> = text.lines().filter(|l| !l.trim().is_empty()).collect();
    let mut out = lines[lines.len().saturating_sub(5)..].join(" | ");
    if out.len() > STDERR_TAIL {
        let mut cut = out.len() - STDERR_TAIL;
        while !out.is_char_boundary(cut) {
            cut += 1;
        }
        out = format!("…{}", &out[cut..]);
    }
    if out.is_empty() {
        "(nothing on standard error)".into()
    } else {
        format!("standard error: {out}")
    }
}

/// Reads a program's answer: its last non-empty line of standard output,
/// checked for sense against the trial asked.
pub fn read_answer(stdout: &[u8], req: &TrialRequest) -> Result<Measurement, String> {
    let text = String::from_utf8_lossy(stdout);
    let Some(line) = text.lines().rev().find(|l| !l.trim().is_empty()) else {
        return Err("printed no measurement".into());
    };
    let shown: String = line.chars().take(120).collect();
    let m: ProgramMeasurement = serde_json::from_str(line.trim()).map_err(|e| {
        // serde's message may repeat the whole line.
        let e: String = e.to_string().chars().take(200).collect();
        format!("printed `{shown}`, not a measurement: {e}")
    })?;
    let m = Measurement {
        fell: m.fell,
        x_m: m.x_m,
        y_m: m.y_m,
        fall_time_s: m.fall_time_s,
        sim_time_s: m.sim_time_s,
    };
    m.check().map_err(|e| format!("printed `{shown}`: {e}"))?;
    m.plausible(req.duration_s)
        .map_err(|e| format!("printed `{shown}`, implausible: {e}"))?;
    Ok(m)
}

/// What `program` reads for `req` in `slot`.
fn trial_input(req: &TrialRequest, slot: u32, scratch: &Path) -> ProgramTrial {
    ProgramTrial {
        run: req.run.clone(),
        iteration: req.iteration,
        trial: req.trial,
        seed: req.seed,
        duration_s: req.duration_s,
        robot_type: req.robot_type,
        params: req.params.iter().cloned().collect(),
        slot,
        scratch: scratch.to_path_buf(),
    }
}

/// Makes the slot's scratch with its HOME and TMPDIR.
pub(crate) fn make_scratch(who: &str, scratch: &Path) -> Result<(), String> {
    for d in [
        scratch.to_path_buf(),
        scratch.join("home"),
        scratch.join("tmp"),
    ] {
        std::fs::create_dir_all(&d).map_err(|e| format!("{who}: scratch {}: {e}", d.display()))?;
    }
    Ok(())
}

/// Why a program that ended with `status` (not success) failed its trial.
pub(crate) fn exit_failure(
    who: &str,
    status: std::process::ExitStatus,
    err: &[u8],
    settings: &Settings,
) -> String {
    let how = status.code().map_or_else(
        || "was killed by a signal".to_string(),
        |c| format!("exited with status {c}"),
    );
    let limit = settings
        .limits
        .hit(status, &String::from_utf8_lossy(err))
        .map(|l| format!(": {l}"))
        .unwrap_or_default();
    format!("{who} {how}{limit}; {}", tail(err))
}

/// Why a trial that got no answer within the settings' time-out failed.
pub(crate) fn timeout_failure(who: &str, err: &[u8], settings: &Settings) -> String {
    format!(
        "{who} did not answer within {} s; it and every process it started were killed; {}",
        settings.timeout.as_secs_f64(),
        tail(err)
    )
}

/// Runs one trial of `program` in `slot`: the trial on its standard input,
/// its measurement from its standard output; any failure, with why. A
/// program that serves trials answers it in the process kept for the run in
/// this slot, from `pool` ([`crate::served`]), unless a CPU-time limit is
/// set (it bounds one trial, so each trial is a process of its own); any
/// other runs as a job of its own. When `stop` is cancelled the program is
/// asked to stop (SIGTERM, then SIGKILL after the settings' grace) and the
/// trial fails with "the worker is stopping".
pub async fn run(
    program: &Program,
    req: &TrialRequest,
    slot: u32,
    scratch: &Path,
    settings: &Settings,
    stop: &tokio_util::sync::CancellationToken,
    pool: &crate::served::Pool,
) -> Result<Measurement, String> {
    let who = format!("program `{}`", program.name);
    if stop.is_cancelled() {
        return Err(format!("the worker is stopping; {who} was not started"));
    }
    let input = serde_json::to_vec(&trial_input(req, slot, scratch))
        .map_err(|e| format!("{who}: the trial: {e}"))?;
    make_scratch(&who, scratch)?;
    if program.kept(settings) {
        return pool
            .run(program, req, &input, slot, scratch, settings, stop)
            .await;
    }
    run_once(&who, req, input, program, scratch, settings, stop).await
}

/// Runs one trial as a job of its own.
async fn run_once(
    who: &str,
    req: &TrialRequest,
    input: Vec<u8>,
    program: &Program,
    scratch: &Path,
    settings: &Settings,
    stop: &tokio_util::sync::CancellationToken,
) -> Result<Measurement, String> {
    let env = settings.env_for(scratch);
    let mut job = Job::start(&program.path, scratch, &env, &settings.limits)
        .map_err(|e| format!("{who} did not start: {e}"))?;
    let (Some(mut stdin), Some(mut stdout), Some(mut stderr)) = (
        job.child.stdin.take(),
        job.child.stdout.take(),
        job.child.stderr.take(),
    ) else {
        return Err(format!("{who}: its pipes could not be opened"));
    };
    tokio::spawn(async move {
        // A program that does not read its input is its own business.
        let _ = stdin.write_all(&input).await;
        let _ = stdin.shutdown().await;
    });
    let read_out = tokio::spawn(async move { read_tail(&mut stdout, STDOUT_TAIL).await });
    let read_err = tokio::spawn(async move { read_tail(&mut stderr, 2 * STDERR_TAIL).await });
    enum End {
        Exited(std::io::Result<std::process::ExitStatus>),
        TimedOut,
        Stopped,
    }
    let end = tokio::select! {
        s = job.child.wait() => End::Exited(s),
        () = tokio::time::sleep(settings.timeout) => End::TimedOut,
        () = stop.cancelled() => End::Stopped,
    };
    // Whatever it started and left running goes with it (and with them
    // the last ends of its pipes).
    match end {
        End::Stopped => job.stop(settings.grace).await,
        End::Exited(_) | End::TimedOut => job.end().await,
    }
    let drained = |h: tokio::task::JoinHandle<Vec<u8>>| async move {
        match tokio::time::timeout(PIPES_WITHIN, h).await {
            Ok(Ok(b)) => b,
            _ => Vec::new(),
        }
    };
    let (out, err) = (drained(read_out).await, drained(read_err).await);
    let status = match end {
        End::Stopped => {
            return Err(format!(
                "the worker is stopping; {who} was stopped; {}",
                tail(&err)
            ));
        }
        End::TimedOut => return Err(timeout_failure(who, &err, settings)),
        End::Exited(s) => s.map_err(|e| format!("{who}: {e}"))?,
    };
    if !status.success() {
        return Err(exit_failure(who, status, &err, settings));
    }
    read_answer(&out, req).map_err(|e| format!("{who} {e}; {}", tail(&err)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use protocol::{Physics, TrialModel};

    fn req() -> TrialRequest {
        TrialRequest {
            run: "r".into(),
            iteration: 1,
            trial: 2,
            seed: 3,
            model: TrialModel::Program,
            program: Some("p".into()),
            robot_type: 0,
            duration_s: 10.0,
            params: vec![("a".into(), 1.5)],
            dispatch: 0,
            physics: Physics::default(),
        }
    }

    #[test]
    fn an_answer_is_the_last_line_and_must_make_sense() {
        let good = b"log line\n{\"x_m\":1.5,\"y_m\":-0.2,\"fell\":false,\"sim_time_s\":10.0}\n\n";
        let m = read_answer(good, &req()).expect("a good answer");
        assert_eq!(
            (m.x_m, m.y_m, m.fell, m.sim_time_s),
            (1.5, -0.2, false, 10.0)
        );
        for (out, why) in [
            (&b""[..], "printed no measurement"),
            (b"hello", "not a measurement"),
            (
                b"{\"x_m\":NaN,\"y_m\":0,\"fell\":false,\"sim_time_s\":10}",
                "not a measurement",
            ),
            (
                b"{\"x_m\":1e9,\"y_m\":0,\"fell\":false,\"sim_time_s\":10}",
                "beyond 100 m",
            ),
            (
                b"{\"x_m\":1,\"y_m\":0,\"fell\":true,\"sim_time_s\":10}",
                "fall_time_s",
            ),
            (
                b"{\"x_m\":1,\"y_m\":0,\"fell\":false,\"sim_time_s\":10.02}",
                "outside [0, 10] s",
            ),
            (
                b"{\"x_m\":1,\"y_m\":0,\"fell\":true,\"fall_time_s\":9,\"sim_time_s\":8}",
                "fall time after",
            ),
            (
                b"{\"x_m\":1,\"y_m\":0,\"fell\":false,\"sim_time_s\":10,\"z\":1}",
                "unknown field",
            ),
        ] {
            let e = read_answer(out, &req()).expect_err(why);
            assert!(e.contains(why), "{e} should say {why}");
        }
    }

    #[test]
    fn a_stderr_tail_keeps_the_last_lines() {
        let err = (0..20).map(|i| format!("line {i}\n")).collect::<String>();
        let t = tail(err.as_bytes());
        assert_eq!(
            t,
            "standard error: line 15 | line 16 | line 17 | line 18 | line 19"
        );
        assert_eq!(tail(b""), "(nothing on standard error)");
        let long = "é".repeat(1000);
        assert!(tail(long.as_bytes()).len() <= STDERR_TAIL + 40);
    }

    #[tokio::test]
    async fn registration_refuses_what_is_not_a_program() {
        let t = Settings::default();
        let plain = std::env::temp_dir().join(format!("naofarm-plain-{}", std::process::id()));
        std::fs::write(&plain, "#!/bin/sh\n").expect("a temporary file");
        let not_executable = format!("x={}", plain.display());
        for (spec, why) in [
            ("league", "expected NAME=PATH"),
            ("a/b=/bin/true", "never given as a path"),
            ("x=/nonexistent/prog", "No such file"),
            ("x=/tmp", "not a file"),
            (not_executable.as_str(), "not executable"),
        ] {
            let e = Programs::register(&[spec.to_string()], t.clone())
                .await
                .expect_err(spec);
            assert!(e.to_string().contains(why), "{e} should say {why}");
        }
        let _ = std::fs::remove_file(&plain);
        let twice = ["x=/bin/true".to_string(), "x=/bin/false".to_string()];
        assert_eq!(
            Programs::register(&twice, t.clone())
                .await
                .expect_err("twice"),
            ProgramError::Twice("x".into())
        );
        let ok = Programs::register(&["t=/bin/true".to_string()], t.clone())
            .await
            .expect("/bin/true is a program");
        let p = ok.get("t").expect("registered");
        assert_ne!(p.fingerprint(1), p.fingerprint(2));
        // Another build under the same name is another fingerprint: a run
        // never mixes them.
        let other = Programs::register(&["t=/bin/false".to_string()], t.clone())
            .await
            .expect("/bin/false is a program");
        let q = other.get("t").expect("registered");
        assert_ne!(p.identity, q.identity);
        assert_ne!(p.fingerprint(1), q.fingerprint(1));
    }
}
