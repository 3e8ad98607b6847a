//! What every end-to-end test file shares: the binary, the repository root,
//! a scratch directory, a command that must succeed.
#![allow(dead_code, clippy::unwrap_used)]

use std::{
    path::{Path, PathBuf},
    process::Command,
};

/// The `naofarm` binary under test.
pub fn naofarm() -> Command {
    Command::new(env!("CARGO_BIN_EXE_naofarm"))
}

/// Runs a command that must succeed; on failure the message shows both streams.
pub fn succeed(cmd: &mut Command) -> std::process::Output {
    let out = cmd.output().unwrap();
    assert!(
        out.status.success(),
        "{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// Runs a command that must exit with `code`; returns its stderr.
pub fn fails(cmd: &mut Command, code: i32) -> String {
    let out = cmd.output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr).to_string();
    let stdout = String::from_utf8_lossy(&out.stdout);
    let tail: String = stdout
        .chars()
        .rev()
        .take(2000)
        .collect::<Vec<_>>()
        .into_iter()
        .rev()
        .collect();
    assert_eq!(
        out.status.code(),
        Some(code),
        "{cmd:?}\nstdout (its end): {tail}\nstderr: {err}"
    );
    err
}

/// The repository root.
pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// A fresh scratch directory for one test (`naofarm-e2e-NAME-…` in the
/// system's temporary directory): removed when the test lets go of it, kept
/// (and its path printed) when the test is failing.
pub fn scratch(name: &str) -> Scratch {
    let dir = tempfile::Builder::new()
        .prefix(&format!("naofarm-e2e-{name}-"))
        .tempdir()
        .unwrap();
    Scratch(dir)
}

/// A test's scratch directory; see [`scratch`].
pub struct Scratch(tempfile::TempDir);

impl std::ops::Deref for Scratch {
    type Target = Path;
    fn deref(&self) -> &Path {
        self.0.path()
    }
}

impl AsRef<Path> for Scratch {
    fn as_ref(&self) -> &Path {
        self.0.path()
    }
}

impl AsRef<std::ffi::OsStr> for Scratch {
    fn as_ref(&self) -> &std::ffi::OsStr {
        self.0.path().as_os_str()
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        if std::thread::panicking() {
            self.0.disable_cleanup(true);
            eprintln!(
                "kept the failing test's directory {}",
                self.0.path().display()
            );
        }
    }
}

/// A child process that is killed when the test lets go of it (an assert
/// that fails included), with its stderr kept in a file and printed when the
/// test is failing.
pub struct Proc {
    /// The process.
    pub child: std::process::Child,
    name: String,
    stderr: PathBuf,
    /// The stderr file when the process owns it ([`Proc::spawn_logged`]):
    /// removed after the process.
    _log: Option<tempfile::TempPath>,
}

impl Proc {
    /// Starts `cmd` with stderr to a file named after `name` in `dir`.
    pub fn spawn(cmd: &mut Command, dir: &std::path::Path, name: &str) -> Self {
        use std::sync::atomic::{AtomicU32, Ordering};
        static N: AtomicU32 = AtomicU32::new(0);
        let stderr = dir.join(format!(
            "{name}-{}.stderr",
            N.fetch_add(1, Ordering::Relaxed)
        ));
        let child = cmd
            .stderr(std::fs::File::create(&stderr).unwrap())
            .spawn()
            .unwrap();
        Self {
            child,
            name: name.to_string(),
            stderr,
            _log: None,
        }
    }

    /// Starts `cmd` with stderr to a temporary file of its own, removed
    /// when the process is (printed first if the test is failing).
    pub fn spawn_logged(cmd: &mut Command, name: &str) -> Self {
        let (file, path) = tempfile::Builder::new()
            .prefix(&format!("naofarm-e2e-{name}-"))
            .suffix(".stderr")
            .tempfile()
            .unwrap()
            .into_parts();
        let child = cmd.stderr(file).spawn().unwrap();
        Self {
            child,
            name: name.to_string(),
            stderr: path.to_path_buf(),
            _log: Some(path),
        }
    }

    /// Kills it (SIGKILL) and reaps it.
    pub fn kill(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }

    /// What it wrote to stderr so far.
    pub fn stderr(&self) -> String {
        std::fs::read_to_string(&self.stderr).unwrap_or_default()
    }
}

impl Drop for Proc {
    fn drop(&mut self) {
        self.kill();
        if std::thread::panicking() {
            eprintln!("--- stderr of {} ---\n{}", self.name, self.stderr());
        }
    }
}

impl Proc {
    /// Waits until it wrote a line containing `needle` to stderr, for at
    /// most `within`; that line.
    pub fn wait_line(&self, needle: &str, within: std::time::Duration) -> String {
        let deadline = std::time::Instant::now() + within;
        loop {
            if let Some(l) = self.stderr().lines().find(|l| l.contains(needle)) {
                return l.to_string();
            }
            assert!(
                std::time::Instant::now() < deadline,
                "{} never logged `{needle}`",
                self.name
            );
            std::thread::sleep(std::time::Duration::from_millis(10));
        }
    }
}

/// The JSON lines of `run --json` / `coordinator --json` / `watch --json`:
/// the decided iterations' results (history first), the last status, and
/// the final `finished` line.
pub struct Events {
    pub history: Vec<serde_json::Value>,
    pub decided: Vec<serde_json::Value>,
    pub status: Option<serde_json::Value>,
    pub finished: Option<serde_json::Value>,
}

/// `naofarm run --json --iterations N` of experiment file `file` (a path, or
/// a name in `experiments/`) with `workers` local workers, journaled in
/// `out`; it must succeed. Its events.
pub fn run_events(file: &Path, workers: u32, iterations: u64, out: &Path) -> Events {
    let run = succeed(
        naofarm()
            .args(["run", "--json", "--workers", &workers.to_string()])
            .args(["--iterations", &iterations.to_string()])
            .arg(root().join("experiments").join(file))
            .arg("--out")
            .arg(out),
    );
    events(&run.stdout)
}

pub fn events(stdout: &[u8]) -> Events {
    let mut e = Events {
        history: Vec::new(),
        decided: Vec::new(),
        status: None,
        finished: None,
    };
    for l in String::from_utf8_lossy(stdout).lines() {
        let v: serde_json::Value =
            serde_json::from_str(l).unwrap_or_else(|err| panic!("{err}: {l}"));
        match v["event"].as_str() {
            Some("history") => e.history.push(v["result"].clone()),
            Some("decided") => e.decided.push(v["result"].clone()),
            Some("status") => e.status = Some(v["status"].clone()),
            Some("finished") => e.finished = Some(v),
            Some("trial") => {}
            other => panic!("unknown event {other:?}: {l}"),
        }
    }
    e
}

/// The decided iterations among a journal's records.
pub fn decided(
    records: &[coordinator::journal::Record],
) -> Vec<coordinator::evolve::DecidedIteration> {
    records
        .iter()
        .filter_map(|r| match r {
            coordinator::journal::Record::Decided(d) => Some(d.clone()),
            _ => None,
        })
        .collect()
}

/// A history as bits: iterations, parameters, decisions and statistics.
pub fn bits(h: &[coordinator::evolve::DecidedIteration]) -> Vec<u64> {
    coordinator::evolve::history_bits(h)
}

/// Waits until `cond` gives a value (polled every 10 ms, the one polling
/// interval of the tests' event waits), failing with `what` after `within`.
#[allow(dead_code)]
pub fn wait_for<T>(
    what: &str,
    within: std::time::Duration,
    mut cond: impl FnMut() -> Option<T>,
) -> T {
    let deadline = std::time::Instant::now() + within;
    loop {
        if let Some(v) = cond() {
            return v;
        }
        assert!(
            std::time::Instant::now() < deadline,
            "waited {within:?} for {what}"
        );
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
}

/// A trial program the project sets up outside the clone:
/// `programs/NAME/SCRIPT SOURCE` must succeed, and the program is the last
/// line it prints. The sources: `$VAR`, else ../shared/third-party.
pub fn set_up_program(script: &str, var: &str) -> PathBuf {
    let source = third_party(var);
    assert!(
        source.is_dir(),
        "the sources for {script} are not at {} (set {var} to their directory)",
        source.display()
    );
    let out = succeed(Command::new(root().join("programs").join(script)).arg(&source));
    let stdout = String::from_utf8_lossy(&out.stdout);
    let program = PathBuf::from(stdout.lines().last().unwrap().trim());
    assert!(program.is_file(), "{}", program.display());
    program
}

/// The third-party sources: `$VAR`, else ../shared/third-party.
pub fn third_party(var: &str) -> PathBuf {
    std::env::var_os(var).map_or_else(|| root().join("../shared/third-party"), PathBuf::from)
}

/// `naofarm run --json --workers 2 EXP --out OUT --program NAME=PROGRAM`.
pub fn program_run(exp: &Path, out: &Path, name: &str, program: &Path) -> Command {
    let mut cmd = naofarm();
    cmd.args(["run", "--json", "--workers", "2"])
        .arg(exp)
        .arg("--out")
        .arg(out)
        .arg("--program")
        .arg(format!("{name}={}", program.display()));
    cmd
}

/// The trials (iteration, index) a run's journal holds outcomes of, each
/// journaled once (asserted).
pub fn journaled_once(out: &Path) -> std::collections::BTreeSet<(u64, u32)> {
    let mut trials = std::collections::BTreeSet::new();
    for r in coordinator::journal::Journal::read(out).unwrap().records() {
        if let coordinator::journal::Record::Outcome {
            iteration, trial, ..
        } = r
        {
            assert!(trials.insert((iteration, trial)), "journaled twice");
        }
    }
    trials
}

/// Starts `cmd` (a `run --json`; its stderr discarded) and reads its events
/// up to its first decided iteration: the process, still running, and that
/// iteration's statistics (`Stats`).
pub fn until_first_decision(cmd: &mut Command) -> (std::process::Child, serde_json::Value) {
    use std::io::BufRead;
    let mut child = cmd
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let lines = std::io::BufReader::new(child.stdout.take().unwrap()).lines();
    for line in lines.map_while(Result::ok) {
        if line.starts_with("{\"event\":\"decided\"") {
            let v: serde_json::Value = serde_json::from_str(&line).unwrap();
            return (child, v["result"]["stats"].clone());
        }
    }
    let status = child.wait().unwrap();
    panic!("the run ended ({status}) before it decided an iteration");
}

/// experiments/FILE cut to a test's size in `dir`: 3 iterations of 4 walks
/// of 4 s, two in flight, a light CLOP (the file's own `iterations` line
/// given, since it differs per experiment).
pub fn small_experiment(file: &str, iterations: &str, dir: &Path) -> PathBuf {
    let text = std::fs::read_to_string(root().join("experiments").join(file))
        .unwrap()
        .replace(iterations, "iterations = 3")
        .replace("trials_per_iteration = 10", "trials_per_iteration = 4")
        .replace("trial_duration_s = 10.0", "trial_duration_s = 4.0")
        .replace("pipeline_depth = 4", "pipeline_depth = 2")
        .replace("n_mcmc = 1000", "n_mcmc = 100");
    assert!(text.contains("iterations = 3\n"), "{text}");
    let p = dir.join(file);
    std::fs::write(&p, text).unwrap();
    p
}
