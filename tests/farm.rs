//! The farm as real processes over 127.0.0.1: a coordinator, workers, kills,
//! watchers, the topics' documented fields.
#![allow(clippy::unwrap_used)]

mod util;

use std::{
    io::{BufRead, BufReader},
    path::{Path, PathBuf},
    process::{Child, Stdio},
    sync::mpsc,
    time::{Duration, Instant},
};

use coordinator::journal::{Journal, Record};

use util::{bits, decided, events, naofarm, root, scratch, succeed, Proc, Scratch};

const TIMEOUT: Duration = Duration::from_secs(120);

fn experiment(dir: &Path, iterations: u64) -> PathBuf {
    let text = std::fs::read_to_string(root().join("experiments/test/two-parameters.toml"))
        .unwrap()
        .replace("name = \"syn\"", "name = \"farm\"")
        .replace("seed = 42", "seed = 5")
        .replace("iterations = 40", &format!("iterations = {iterations}"))
        .replace("n_mcmc = 200", "n_mcmc = 100");
    let p = dir.join("exp.toml");
    std::fs::write(&p, text).unwrap();
    p
}

/// The port a coordinator listens on, in its own words on stderr
/// ("coordinator listening on tcp/127.0.0.1:PORT"), waiting for them.
fn listening_port(stderr: &Path) -> u16 {
    let deadline = Instant::now() + TIMEOUT;
    loop {
        let text = std::fs::read_to_string(stderr).unwrap_or_default();
        if let Some(p) = text
            .lines()
            .find_map(|l| l.strip_prefix("coordinator listening on tcp/127.0.0.1:"))
            .and_then(|p| p.trim().parse().ok())
        {
            return p;
        }
        assert!(
            Instant::now() < deadline,
            "the coordinator never said where it listens: {text}"
        );
        std::thread::sleep(Duration::from_millis(10));
    }
}

struct Coordinator {
    child: Child,
    stderr: PathBuf,
    lines: mpsc::Receiver<String>,
    seen: Vec<String>,
    /// The port it listens on, as it says itself.
    port: u16,
}

impl Coordinator {
    /// A coordinator listening on a port the OS picks (read from its own report).
    fn start(exp: &Path, out: &Path, lease_s: f64) -> Self {
        Self::start_on(exp, out, 0, lease_s)
    }

    /// A coordinator listening on `port` (0: the OS picks).
    fn start_on(exp: &Path, out: &Path, port: u16, lease_s: f64) -> Self {
        let stderr = out.with_extension("stderr");
        let mut child = naofarm()
            .args(["coordinator", "--json", "--lease-s", &lease_s.to_string()])
            .arg(exp)
            .arg("--out")
            .arg(out)
            .args(["--listen", &format!("tcp/127.0.0.1:{port}")])
            .env("RUST_LOG", "warn,naofarm_coordinator::service=info")
            .stdout(Stdio::piped())
            .stderr(std::fs::File::create(&stderr).unwrap())
            .spawn()
            .unwrap();
        let stdout = child.stdout.take().unwrap();
        let (tx, lines) = mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines().map_while(Result::ok) {
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
        let port = listening_port(&stderr);
        Self {
            child,
            stderr,
            lines,
            seen: Vec::new(),
            port,
        }
    }

    /// Waits until `n` iterations have been decided (by its JSON lines).
    fn wait_decided(&mut self, n: usize) {
        let deadline = Instant::now() + TIMEOUT;
        let decided = |seen: &[String]| {
            seen.iter()
                .filter(|l| l.starts_with("{\"event\":\"decided\""))
                .count()
        };
        while decided(&self.seen) < n {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.lines.recv_timeout(left) {
                Ok(l) => self.seen.push(l),
                Err(e) => panic!("waiting for {n} decisions: {e}; saw {:?}", self.seen),
            }
        }
    }

    /// Its final counters (the `finished` JSON line), once it has exited.
    fn finished(&self) -> serde_json::Value {
        self.seen
            .iter()
            .find(|l| l.contains("\"event\":\"finished\""))
            .map(|l| serde_json::from_str(l).unwrap())
            .unwrap_or_else(|| panic!("no finished line in {:?}", self.seen))
    }

    /// Waits until its log (info level for the service) says `needle`.
    fn wait_log(&self, needle: &str) {
        let deadline = Instant::now() + TIMEOUT;
        while !plain(&std::fs::read_to_string(&self.stderr).unwrap_or_default()).contains(needle) {
            assert!(
                Instant::now() < deadline,
                "the coordinator never logged `{needle}`"
            );
            std::thread::sleep(Duration::from_millis(10));
        }
    }

    fn wait_exit(&mut self) -> std::process::ExitStatus {
        let deadline = Instant::now() + TIMEOUT;
        loop {
            if let Some(s) = self.child.try_wait().unwrap() {
                while let Ok(l) = self.lines.recv_timeout(Duration::from_millis(200)) {
                    self.seen.push(l);
                }
                return s;
            }
            assert!(
                Instant::now() < deadline,
                "coordinator did not finish; saw {:?}",
                self.seen
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}

impl Drop for Coordinator {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
        if std::thread::panicking() {
            eprintln!(
                "--- coordinator stderr ---\n{}",
                std::fs::read_to_string(&self.stderr).unwrap_or_default()
            );
        }
    }
}

fn worker(port: u16, slots: u32, pace_ms: u64) -> Proc {
    worker_with(port, slots, pace_ms, None)
}

/// A worker process, with a fault hook (`VAR`, `VALUE`) switched on when given.
fn worker_with(port: u16, slots: u32, pace_ms: u64, fault: Option<(&str, &str)>) -> Proc {
    let mut cmd = naofarm();
    cmd.args(["worker", "--connect", &format!("tcp/127.0.0.1:{port}")])
        .args([
            "--slots",
            &slots.to_string(),
            "--min-trial-ms",
            &pace_ms.to_string(),
        ])
        .env("RUST_LOG", "warn,naofarm_worker::service=debug")
        .stdout(Stdio::null());
    if let Some((var, value)) = fault {
        cmd.env(var, value);
    }
    Proc::spawn_logged(&mut cmd, "worker")
}

/// Log text without the terminal colours tracing may add.
fn plain(log: &str) -> String {
    let mut text = String::new();
    let mut in_escape = false;
    for ch in log.chars() {
        match (in_escape, ch) {
            (false, '\u{1b}') => in_escape = true,
            (true, 'm') => in_escape = false,
            (true, _) => {}
            (false, c) => text.push(c),
        }
    }
    text
}

/// The id of a worker (from its "worker ready" log line), waiting for it.
fn worker_id(p: &Proc) -> String {
    let deadline = Instant::now() + TIMEOUT;
    loop {
        let text = plain(&p.stderr());
        if let Some(id) = text
            .lines()
            .find(|l| l.contains("worker ready"))
            .and_then(|l| l.split("worker=").nth(1))
            .and_then(|r| r.split_whitespace().next())
        {
            return id.to_string();
        }
        assert!(
            Instant::now() < deadline,
            "the worker never got ready: {text}"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Waits until worker `p` has started a trial (its debug log says so).
fn holding_a_trial(p: &Proc) {
    let deadline = Instant::now() + TIMEOUT;
    while !plain(&p.stderr()).contains("trial started") {
        assert!(
            Instant::now() < deadline,
            "the worker never started a trial"
        );
        std::thread::sleep(Duration::from_millis(10));
    }
}

fn journal(dir: &Path) -> Vec<Record> {
    Journal::read(dir).unwrap().records()
}

fn assert_every_trial_once(records: &[Record], iterations: u64) {
    let mut seen = std::collections::BTreeSet::new();
    for r in records {
        if let Record::Outcome {
            iteration, trial, ..
        } = r
        {
            assert!(
                seen.insert((*iteration, *trial)),
                "trial {iteration}/{trial} journaled twice"
            );
        }
    }
    assert_eq!(seen.len() as u64, iterations * 6, "every trial journaled");
}

fn kill_all(children: &mut [Proc]) {
    for c in children.iter_mut() {
        c.kill();
    }
}

fn signal(child: &Child, sig: &str) {
    let ok = std::process::Command::new("kill")
        .args([sig, &child.id().to_string()])
        .status()
        .unwrap();
    assert!(ok.success());
}

/// Runs a whole farm run with `n` workers; returns the scratch directory
/// (the run lives while it is held) and the run directory in it.
fn farm_run(name: &str, n: usize, iterations: u64) -> (Scratch, PathBuf) {
    let dir = scratch(name);
    let exp = experiment(&dir, iterations);
    let out = dir.join("run");
    let mut c = Coordinator::start(&exp, &out, 30.0);
    let mut ws: Vec<Proc> = (0..n).map(|_| worker(c.port, 2, 15)).collect();
    let status = c.wait_exit();
    kill_all(&mut ws);
    assert!(status.success(), "coordinator: {status}; {:?}", c.seen);
    (dir, out)
}

#[test]
fn three_workers_complete_a_run_with_every_trial_journaled_once() {
    let (_dir, out) = farm_run("three", 3, 20);
    let records = journal(&out);
    assert_every_trial_once(&records, 20);
    let workers: std::collections::BTreeSet<String> =
        records.iter().filter_map(outcome_worker).collect();
    assert!(
        workers.len() >= 2,
        "trials spread over workers: {workers:?}"
    );
}

#[test]
fn one_worker_and_three_workers_give_bit_identical_histories() {
    let one = decided(&journal(&farm_run("det1", 1, 15).1));
    let three = decided(&journal(&farm_run("det3", 3, 15).1));
    assert_eq!(one.len(), 15);
    assert_eq!(bits(&one), bits(&three));
}

#[test]
fn a_killed_worker_loses_no_trial() {
    let dir = scratch("sigkill");
    let exp = experiment(&dir, 20);
    let out = dir.join("run");
    let mut c = Coordinator::start(&exp, &out, 30.0);
    let port = c.port;
    // Two quick workers and a slow one, killed while it holds a trial.
    let mut ws: Vec<Proc> = (0..2).map(|_| worker(port, 2, 20)).collect();
    c.wait_decided(3);
    ws.push(worker(port, 1, 60_000));
    holding_a_trial(&ws[2]);
    ws[2].kill();
    let status = c.wait_exit();
    kill_all(&mut ws);
    assert!(status.success(), "{:?}", c.seen);
    let records = journal(&out);
    assert_every_trial_once(&records, 20);
    // Every worker is kept busy, so the killed one held trials: the
    // coordinator journaled their loss and gave them to others.
    let finished = c.finished();
    assert!(finished["redispatched"].as_u64() >= Some(1), "{finished}");
    let lost: Vec<&Record> = records
        .iter()
        .filter(|r| matches!(r, Record::Failed { reason, .. } if reason.contains("went away")))
        .collect();
    assert!(
        !lost.is_empty(),
        "the killed worker's trials are journaled as lost"
    );
    for r in lost {
        let Record::Failed {
            iteration,
            trial,
            worker,
            ..
        } = r
        else {
            unreachable!()
        };
        let ran = records.iter().find_map(|o| match o {
            Record::Outcome {
                iteration: i,
                trial: k,
                worker: w,
                ..
            } if i == iteration && k == trial => Some(w.clone()),
            _ => None,
        });
        assert!(
            ran.is_some_and(|w| &w != worker),
            "trial {iteration}/{trial} re-dispatched to another worker"
        );
    }
}

#[test]
fn a_frozen_worker_is_replaced_and_its_late_outcomes_ignored() {
    let dir = scratch("sigstop");
    let exp = experiment(&dir, 24);
    let out = dir.join("run");
    let mut c = Coordinator::start(&exp, &out, 1.0);
    let port = c.port;
    // Two quick workers and a slower one, frozen while it holds a trial.
    let mut ws: Vec<Proc> = (0..2).map(|_| worker(port, 2, 20)).collect();
    c.wait_decided(2);
    ws.push(worker(port, 1, 500));
    holding_a_trial(&ws[2]);
    let frozen = 2;
    signal(&ws[frozen].child, "-STOP");
    // Frozen past its trials' 1 s lease but not its 3 s transport lease:
    // the trials go elsewhere, and the frozen worker's answers still arrive.
    c.wait_log("lease expired");
    signal(&ws[frozen].child, "-CONT");
    let status = c.wait_exit();
    kill_all(&mut ws);
    assert!(status.success(), "{:?}", c.seen);
    assert_every_trial_once(&journal(&out), 24);
    // The frozen worker's trials went to others when their lease passed;
    // its late outcomes, sent on SIGCONT, were counted once: as duplicates
    // (or refused, when their iteration was already decided), never journaled.
    let f = c.finished();
    assert_eq!(f["accepted"], 24 * 6, "{f}");
    assert!(f["redispatched"].as_u64() >= Some(1), "{f}");
    let late = f["duplicates"].as_u64().unwrap_or(0) + f["refused"].as_u64().unwrap_or(0);
    assert!(
        late >= 1,
        "the late outcomes arrived and were not journaled: {f}"
    );
}

#[test]
fn a_killed_coordinator_resumes_to_the_same_history() {
    let reference = decided(&journal(&farm_run("resume-ref", 2, 20).1));
    let dir = scratch("resume");
    let exp = experiment(&dir, 20);
    let out = dir.join("run");
    // The first coordinator picks the port; the restarts take the same one,
    // which the workers keep connecting to.
    let mut port = 0;
    let mut ws: Vec<Proc> = Vec::new();
    // SIGKILL at several points: after 3 new decisions, 6 more, 5 more.
    for n in [3, 6, 5] {
        let mut c = Coordinator::start_on(&exp, &out, port, 30.0);
        if port == 0 {
            port = c.port;
            ws = (0..2).map(|_| worker(port, 2, 10)).collect();
        }
        c.wait_decided(n);
        c.child.kill().unwrap();
        let _ = c.child.wait();
    }
    let mut c = Coordinator::start_on(&exp, &out, port, 30.0);
    let status = c.wait_exit();
    kill_all(&mut ws);
    assert!(status.success(), "{:?}", c.seen);
    let records = journal(&out);
    assert_every_trial_once(&records, 20);
    assert_eq!(bits(&decided(&records)), bits(&reference));
}

#[test]
fn failing_forging_and_misaddressing_workers_never_reach_the_journal() {
    let dir = scratch("tamper");
    let exp = experiment(&dir, 12);
    let local = dir.join("local");
    succeed(
        naofarm()
            .args(["run", "--json", "--workers", "2"])
            .arg(&exp)
            .arg("--out")
            .arg(&local),
    );
    let want = bits(&decided(&journal(&local)));
    // (hook, mode, what the coordinator logs when it first answers the bad
    // worker, the refusal reason it counts — none: a failure of the trial).
    for (var, mode, seen, reason) in [
        ("NAOFARM_FAULT_TRIAL", "fail", "could not run a trial", None),
        ("NAOFARM_FAULT_TRIAL", "forge", "implausible outcome", None),
        (
            "NAOFARM_FAULT_OUTCOME",
            "wrong-dispatch",
            "refused",
            Some("wrong dispatch id"),
        ),
        (
            "NAOFARM_FAULT_OUTCOME",
            "other-run",
            "refused",
            Some("outcome for another run"),
        ),
        (
            "NAOFARM_FAULT_OUTCOME",
            "unsent",
            "refused",
            Some("trial not in flight"),
        ),
    ] {
        let out = dir.join(mode);
        // The bad worker alone first, until the coordinator has answered it;
        // then the good ones.
        let mut c = Coordinator::start(&exp, &out, 1.0);
        let port = c.port;
        let mut bad = worker_with(port, 2, 5, Some((var, mode)));
        c.wait_log(seen);
        let mut ws = vec![worker(port, 1, 20), worker(port, 1, 20)];
        let status = c.wait_exit();
        let bad_id = worker_id(&bad);
        bad.kill();
        kill_all(&mut ws);
        assert!(status.success(), "{mode}: {:?}", c.seen);
        let records = journal(&out);
        assert_every_trial_once(&records, 12);
        assert!(
            !records
                .iter()
                .any(|r| matches!(r, Record::Outcome { worker, .. } if *worker == bad_id)),
            "{mode}: nothing of the bad worker is journaled"
        );
        assert_eq!(
            bits(&decided(&records)),
            want,
            "{mode}: the run's history as alone"
        );
        let f = c.finished();
        match reason {
            Some(r) => assert!(
                f["refused_reasons"][r].as_u64() >= Some(1),
                "{mode}: counted as `{r}`: {f}"
            ),
            None => {
                // Each failure is journaled with its worker; after three trials
                // that others then ran, the worker is set aside and named.
                let failed: Vec<&str> = records
                    .iter()
                    .filter_map(|r| match r {
                        Record::Failed { worker, reason, .. } if *worker == bad_id => {
                            Some(reason.as_str())
                        }
                        _ => None,
                    })
                    .collect();
                assert!(
                    failed.len() >= 3,
                    "{mode}: failures journaled {failed:?}: {f}"
                );
                assert!(
                    failed.iter().all(|r| r.contains(seen) || mode == "fail"),
                    "{failed:?}"
                );
                assert_eq!(f["set_aside"], serde_json::json!([bad_id]), "{mode}: {f}");
            }
        }
    }
}

#[test]
fn a_second_coordinator_on_a_run_directory_exits_2_while_the_first_finishes() {
    let dir = scratch("two-coordinators");
    let exp = experiment(&dir, 8);
    let out = dir.join("run");
    let mut c = Coordinator::start(&exp, &out, 30.0);
    let port = c.port;
    // No worker yet: the first coordinator holds the run and waits for one.
    let deadline = Instant::now() + TIMEOUT;
    let holder = format!("pid {}", c.child.id());
    while !std::fs::read_to_string(out.join("lock")).is_ok_and(|t| t.contains(&holder)) {
        assert!(
            Instant::now() < deadline,
            "the first coordinator never took the lock"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    let second = naofarm()
        .args(["coordinator", "--json"])
        .arg(&exp)
        .arg("--out")
        .arg(&out)
        .args(["--listen", "tcp/127.0.0.1:0"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&second.stderr);
    assert_eq!(second.status.code(), Some(2), "{err}");
    assert!(err.contains(&holder) && err.contains("in use"), "{err}");
    // Started again as the first was, on its port too: the run's lock is
    // named, not the port (the run is opened before the network).
    let third = naofarm()
        .args(["coordinator", "--json"])
        .arg(&exp)
        .arg("--out")
        .arg(&out)
        .args(["--listen", &format!("tcp/127.0.0.1:{port}")])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&third.stderr);
    assert_eq!(third.status.code(), Some(2), "{err}");
    assert!(err.contains(&holder) && !err.contains("zenoh"), "{err}");
    let mut ws = vec![worker(port, 2, 5)];
    let status = c.wait_exit();
    kill_all(&mut ws);
    assert!(status.success(), "{:?}", c.seen);
    assert_every_trial_once(&journal(&out), 8);
}

#[test]
fn a_worker_that_joins_mid_run_gets_work() {
    let dir = scratch("join");
    let exp = experiment(&dir, 16);
    let out = dir.join("run");
    let mut c = Coordinator::start(&exp, &out, 30.0);
    let port = c.port;
    let mut ws = vec![worker(port, 1, 25)];
    c.wait_decided(3);
    // Read only: the coordinator holds the run and may be writing its tail.
    let before = Journal::read(&out).unwrap().records.len();
    ws.push(worker(port, 1, 25));
    let status = c.wait_exit();
    kill_all(&mut ws);
    assert!(status.success(), "{:?}", c.seen);
    let records = journal(&out);
    assert_every_trial_once(&records, 16);
    let early: std::collections::BTreeSet<String> = records[..before]
        .iter()
        .filter_map(outcome_worker)
        .collect();
    let late: std::collections::BTreeSet<String> = records[before..]
        .iter()
        .filter_map(outcome_worker)
        .collect();
    assert_eq!(early.len(), 1, "one worker before the join: {early:?}");
    assert!(
        late.difference(&early).count() == 1,
        "the joiner ran trials after it joined: before {early:?}, after {late:?}"
    );
}

/// `naofarm watch NAME --json` of the coordinator on `port`, its output piped.
fn watch(name: &str, port: u16) -> Child {
    naofarm()
        .args(["watch", name, "--json", "--connect"])
        .arg(format!("tcp/127.0.0.1:{port}"))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

/// A worker process serving the programs `NAME=PATH` (under tests/programs).
fn program_worker(port: u16, programs: &[(&str, &str)]) -> Proc {
    program_worker_with(port, programs, &[])
}

/// [`program_worker`] passing variables to its programs (`--program-env`).
fn program_worker_with(port: u16, programs: &[(&str, &str)], vars: &[(&str, &Path)]) -> Proc {
    let mut cmd = naofarm();
    cmd.args(["worker", "--connect", &format!("tcp/127.0.0.1:{port}")])
        .args(["--slots", "2"]);
    for (name, value) in vars {
        cmd.arg("--program-env")
            .arg(format!("{name}={}", value.display()));
    }
    cmd.env("RUST_LOG", "warn,naofarm_worker::service=debug")
        .stdout(Stdio::null());
    for (name, file) in programs {
        let path = root().join("tests/programs").join(file);
        cmd.args(["--program", &format!("{name}={}", path.display())]);
    }
    Proc::spawn_logged(&mut cmd, "worker")
}

/// A coordinator of experiments/test/program.toml (the `toy` program) in a
/// new scratch directory; the directory, the run's and the coordinator.
fn program_run(name: &str) -> (Scratch, PathBuf, Coordinator) {
    let dir = scratch(name);
    let exp = root().join("experiments/test/program.toml");
    let out = dir.join("run");
    let c = Coordinator::start(&exp, &out, 30.0);
    (dir, out, c)
}

#[test]
fn a_program_run_goes_only_to_workers_that_registered_its_program() {
    let (_dir, out, mut c) = program_run("program-farm");
    let watcher = watch("toy", c.port);
    // One worker serves only another program; one serves the run's.
    let other = program_worker(c.port, &[("other", "toy")]);
    let other_id = worker_id(&other);
    let mut ws = vec![other, program_worker(c.port, &[("toy", "toy")])];
    let status = c.wait_exit();
    assert!(status.success(), "{:?}", c.seen);
    // A watcher reads the program's run, its own parameter names and all.
    let w = watcher.wait_with_output().unwrap();
    let ev = events(&w.stdout);
    let mut seen: Vec<u64> = ev
        .history
        .iter()
        .chain(&ev.decided)
        .map(|r| r["iteration"].as_u64().unwrap())
        .collect();
    seen.sort_unstable();
    seen.dedup();
    assert_eq!(
        seen,
        (0..6).collect::<Vec<u64>>(),
        "{}",
        String::from_utf8_lossy(&w.stderr)
    );
    assert!(ev
        .decided
        .iter()
        .chain(&ev.history)
        .all(|r| r["params"][0][0] == "a"));
    let log = plain(&ws[0].stderr());
    kill_all(&mut ws);
    assert!(
        log.contains("this worker has not registered a program named `toy`")
            && !log.contains("trial started"),
        "the worker without the run's program never asked for its trials: {log}"
    );
    let records = journal(&out);
    let workers: std::collections::BTreeSet<String> =
        records.iter().filter_map(outcome_worker).collect();
    assert_eq!(workers.len(), 1, "{workers:?}");
    assert!(!workers.contains(&other_id));
    assert_eq!(
        records
            .iter()
            .filter(|r| matches!(r, Record::Outcome { .. }))
            .count(),
        6 * 6,
        "every trial of the 6 iterations journaled"
    );
}

#[test]
fn a_failing_program_s_trials_fail_with_its_reason_and_end_the_run() {
    let (_dir, _out, mut c) = program_run("program-crash");
    // Registered as `toy`, but it crashes on every trial.
    let mut ws = vec![program_worker(c.port, &[("toy", "crash")])];
    let status = c.wait_exit();
    kill_all(&mut ws);
    assert!(
        !status.success(),
        "a run whose every trial fails does not succeed"
    );
    let text = plain(&std::fs::read_to_string(&c.stderr).unwrap());
    assert!(
        text.contains("program `toy` exited with status 3; standard error: crash: the simulator lost its licence server | crash: giving up"),
        "{text}"
    );
}

#[test]
fn a_stopping_worker_stops_its_programs_and_what_they_started() {
    let (dir, _out, _c) = program_run("program-stop");
    let pid_file = dir.join("child.pid");
    let mut w = program_worker_with(
        _c.port,
        &[("toy", "hang")],
        &[("NAOFARM_TEST_PID_FILE", &pid_file)],
    );
    // The program has started its child and hangs (the time-out is 600 s).
    let deadline = Instant::now() + TIMEOUT;
    let child = loop {
        if let Some(pid) = std::fs::read_to_string(&pid_file)
            .ok()
            .filter(|p| p.ends_with('\n'))
        {
            break pid.trim().to_string();
        }
        assert!(Instant::now() < deadline, "the program never started");
        std::thread::sleep(Duration::from_millis(20));
    };
    signal(&w.child, "-TERM");
    let status = w.child.wait().unwrap();
    assert!(status.success(), "{status}: {}", w.stderr());
    // The child is killed with the program's group: gone, or a zombie
    // waiting for init.
    let stat = Path::new("/proc").join(&child).join("stat");
    let deadline = Instant::now() + Duration::from_secs(10);
    while std::fs::read_to_string(&stat).is_ok_and(|s| s.split_whitespace().nth(2) != Some("Z")) {
        assert!(
            Instant::now() < deadline,
            "the program's child {child} outlived the stopped worker"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    let log = plain(&w.stderr());
    assert!(log.contains("worker stopped"), "{log}");
}

/// SIGTERM to a worker whose program traps it: the program is asked
/// (SIGTERM) and stops within its grace, what it started goes with it, and
/// the worker removes its scratch space before it exits.
#[test]
fn a_worker_asked_to_stop_asks_its_program_and_leaves_nothing_behind() {
    let (dir, _out, c) = program_run("program-term");
    let (tmp, records) = (dir.join("tmp"), dir.join("records"));
    for d in [&tmp, &records] {
        std::fs::create_dir_all(d).unwrap();
    }
    let marker = format!("naofarm-test-marker-{}", uuid::Uuid::new_v4());
    let mut cmd = naofarm();
    cmd.args(["worker", "--connect", &format!("tcp/127.0.0.1:{}", c.port)])
        .args(["--slots", "1", "--program-grace-s", "30"])
        .arg("--program")
        .arg(format!(
            "toy={}",
            root().join("tests/programs/job").display()
        ))
        .args(["--program-env", "NAOFARM_TEST_JOB=trap"])
        .arg("--program-env")
        .arg(format!("NAOFARM_TEST_DIR={}", records.display()))
        .arg("--program-env")
        .arg(format!("NAOFARM_TEST_MARKER={marker}"))
        .env("TMPDIR", &tmp)
        .stdout(Stdio::null());
    let mut w = Proc::spawn_logged(&mut cmd, "worker");
    let alive = || {
        std::fs::read_dir("/proc")
            .unwrap()
            .flatten()
            .filter(|e| {
                std::fs::read(e.path().join("cmdline"))
                    .is_ok_and(|c| String::from_utf8_lossy(&c).contains(&marker))
            })
            .count()
    };
    util::wait_for("the program to start", TIMEOUT, || {
        records.join("started").exists().then_some(())
    });
    assert!(alive() >= 3, "the program and its two children run");
    signal(&w.child, "-TERM");
    let status = w.child.wait().unwrap();
    assert!(status.success(), "{status}: {}", w.stderr());
    let terminated = std::fs::read_to_string(records.join("terminated")).unwrap_or_default();
    assert_eq!(
        terminated.lines().count(),
        1,
        "the program was asked, not killed"
    );
    util::wait_for(
        "the program's processes to be gone",
        Duration::from_secs(10),
        || (alive() == 0).then_some(()),
    );
    let left: Vec<_> = std::fs::read_dir(&tmp)
        .unwrap()
        .flatten()
        .map(|e| e.file_name())
        .collect();
    assert!(left.is_empty(), "left in the worker's TMPDIR: {left:?}");
}

fn outcome_worker(r: &Record) -> Option<String> {
    if let Record::Outcome { worker, .. } = r {
        Some(worker.clone())
    } else {
        None
    }
}

/// The field tables of docs/topics.md: schema name → (field, type) rows.
fn readme_schemas() -> std::collections::BTreeMap<String, Vec<(String, String)>> {
    let text = std::fs::read_to_string(root().join("docs/topics.md")).unwrap();
    let mut out = std::collections::BTreeMap::new();
    let mut current: Option<(String, Vec<(String, String)>)> = None;
    for line in text.lines() {
        if let Some(name) = line
            .strip_prefix("<!-- schema:")
            .and_then(|l| l.strip_suffix(" -->"))
        {
            current = Some((name.to_string(), Vec::new()));
        } else if line == "<!-- /schema -->" {
            let (name, rows) = current.take().expect("a /schema without a schema");
            out.insert(name, rows);
        } else if let Some((_, rows)) = current.as_mut() {
            let cells: Vec<&str> = line.split('|').map(str::trim).collect();
            if cells.len() >= 4 && cells[1].starts_with('`') {
                rows.push((cells[1].trim_matches('`').to_string(), cells[2].to_string()));
            }
        }
    }
    assert!(current.is_none(), "an unclosed schema table");
    out
}

/// Checks `v` against schema `name`: every documented field with its
/// type, and no field docs/topics.md does not document.
fn conforms(
    schemas: &std::collections::BTreeMap<String, Vec<(String, String)>>,
    name: &str,
    v: &serde_json::Value,
) -> Result<(), String> {
    let rows = schemas
        .get(name)
        .ok_or_else(|| format!("no schema {name} in docs/topics.md"))?;
    let obj = v
        .as_object()
        .ok_or_else(|| format!("{name}: not an object: {v}"))?;
    for key in obj.keys() {
        if !rows.iter().any(|(f, _)| f == key) {
            return Err(format!("{name}.{key} is not documented in docs/topics.md"));
        }
    }
    for (field, ty) in rows {
        let value = obj
            .get(field)
            .ok_or_else(|| format!("{name}.{field} is documented but missing"))?;
        let (ty, nullable) = match ty.strip_suffix(" or null") {
            Some(t) => (t, true),
            None => (ty.as_str(), false),
        };
        if value.is_null() && nullable {
            continue;
        }
        let ok = match ty {
            "string" => value.is_string(),
            "integer" => value.is_u64(),
            "number" => value.is_number(),
            "boolean" => value.is_boolean(),
            "strings" => value
                .as_array()
                .is_some_and(|a| a.iter().all(serde_json::Value::is_string)),
            "reasons" => value.as_array().is_some_and(|a| {
                a.iter().all(|p| {
                    p.as_array()
                        .is_some_and(|p| p.len() == 2 && p[0].is_string() && p[1].is_u64())
                })
            }),
            "pairs" => value.as_array().is_some_and(|a| {
                a.iter().all(|p| {
                    p.as_array()
                        .is_some_and(|p| p.len() == 2 && p[0].is_string() && p[1].is_number())
                })
            }),
            other => {
                conforms(schemas, other, value)?;
                true
            }
        };
        if !ok {
            return Err(format!("{name}.{field} should be {ty}: {value}"));
        }
    }
    Ok(())
}

fn session_to(port: u16) -> zenoh::Session {
    use zenoh::Wait;
    let mut cfg = zenoh::Config::default();
    cfg.insert_json5("scouting/multicast/enabled", "false")
        .unwrap();
    cfg.insert_json5("listen/endpoints", "[]").unwrap();
    cfg.insert_json5("connect/endpoints", &format!("[\"tcp/127.0.0.1:{port}\"]"))
        .unwrap();
    zenoh::open(cfg).wait().unwrap()
}

#[test]
fn every_topic_matches_the_readme_field_tables() {
    use zenoh::Wait;
    let schemas = readme_schemas();
    for s in [
        "Params",
        "TrialOutcome",
        "IterationResult",
        "RunStatus",
        "Stats",
        "Best",
        "WorkerStatus",
    ] {
        assert!(
            schemas.contains_key(s),
            "docs/topics.md lacks the {s} table"
        );
    }
    let dir = scratch("schema");
    let exp = experiment(&dir, 8);
    let out = dir.join("run");
    let mut c = Coordinator::start(&exp, &out, 30.0);
    let port = c.port;
    let session = session_to(port);
    let (tx, rx) = mpsc::channel();
    let _sub = session
        .declare_subscriber("naofarm/farm/**")
        .callback(move |s| {
            let _ = tx.send((
                s.key_expr().as_str().to_string(),
                s.encoding().clone(),
                String::from_utf8_lossy(&s.payload().to_bytes()).into_owned(),
            ));
        })
        .wait()
        .unwrap();
    let (wtx, wrx) = mpsc::channel();
    let _workers = session
        .declare_subscriber("naofarm/@workers/*/status")
        .callback(move |s| {
            let _ = wtx.send(String::from_utf8_lossy(&s.payload().to_bytes()).into_owned());
        })
        .wait()
        .unwrap();
    // The coordinator answers its status query once the session is up;
    // only then start the worker, so that no message is published unseen.
    let ask_deadline = Instant::now() + TIMEOUT;
    let ask = |key: String| loop {
        assert!(Instant::now() < ask_deadline, "no answer to {key}");
        let replies = session
            .get(key.as_str())
            .timeout(Duration::from_secs(2))
            .wait()
            .unwrap();
        if let Ok(r) = replies.recv() {
            let s = r.result().unwrap();
            assert_eq!(s.encoding(), &zenoh::bytes::Encoding::APPLICATION_JSON);
            let text = String::from_utf8_lossy(&s.payload().to_bytes()).into_owned();
            break serde_json::from_str::<serde_json::Value>(&text).unwrap();
        }
    };
    let status = ask("naofarm/farm/*/status".to_string());
    conforms(&schemas, "RunStatus", &status).unwrap();
    let mut ws = vec![worker(port, 2, 5)];
    c.wait_decided(4);
    // A worker says every second how it stands.
    let w: serde_json::Value = serde_json::from_str(&wrx.recv_timeout(TIMEOUT).unwrap()).unwrap();
    conforms(&schemas, "WorkerStatus", &w).unwrap();
    assert_eq!(w["slots"], 2, "{w}");
    let history = ask("naofarm/farm/*/history".to_string());
    let rows = history.as_array().expect("the history is an array");
    assert!(rows.len() >= 4);
    for r in rows {
        conforms(&schemas, "IterationResult", r).unwrap();
    }
    let status = c.wait_exit();
    kill_all(&mut ws);
    assert!(status.success());
    let mut kinds = std::collections::BTreeMap::new();
    // The coordinator's last message is a finished status; one session's
    // messages arrive in order, so everything before it has arrived then.
    let deadline = Instant::now() + TIMEOUT;
    let mut finished = false;
    let next = |finished: bool| {
        if finished {
            return rx.try_recv().ok();
        }
        let left = deadline.saturating_duration_since(Instant::now());
        Some(
            rx.recv_timeout(left)
                .expect("the finished status before the deadline"),
        )
    };
    while let Some((key, encoding, text)) = next(finished) {
        assert_eq!(encoding, zenoh::bytes::Encoding::APPLICATION_JSON, "{key}");
        let v: serde_json::Value = serde_json::from_str(&text).unwrap();
        let schema = match key.split('/').nth(3) {
            Some("params") => "Params",
            Some("trials") => "TrialOutcome",
            Some("results") => "IterationResult",
            Some("status") => "RunStatus",
            other => panic!("an unexpected topic {other:?}: {key}"),
        };
        conforms(&schemas, schema, &v).unwrap_or_else(|e| panic!("{key}: {e}"));
        *kinds.entry(schema).or_insert(0) += 1;
        finished |= schema == "RunStatus" && v["finished"] == true;
    }
    assert_eq!(kinds.get("TrialOutcome"), Some(&48), "{kinds:?}");
    assert_eq!(kinds.get("IterationResult"), Some(&8), "{kinds:?}");
    // The first D = 3 iterations open before this session subscribes.
    assert!(kinds.get("Params").is_some_and(|&n| n >= 5), "{kinds:?}");
    assert!(kinds.get("RunStatus").is_some_and(|&n| n >= 8), "{kinds:?}");
    // A broken document fails the check (the check can fail).
    let mut bad = history[0].clone();
    bad["stats"]["undocumented"] = serde_json::json!(1);
    assert!(conforms(&schemas, "IterationResult", &bad).is_err());
}

/// A history far longer than one reply may carry (the coordinator answers
/// in parts of 25): a late watcher gets all of it, and the coordinator's
/// link holds. One reply of the whole history once outgrew the link's queue
/// and zenoh closed the coordinator's link instead.
#[test]
fn a_long_history_reaches_a_late_watcher_whole() {
    let dir = scratch("long-history");
    let exp = experiment(&dir, 400);
    let out = dir.join("run");
    succeed(
        naofarm()
            .args(["run", "--workers", "2", "--iterations", "300"])
            .arg(&exp)
            .arg("--out")
            .arg(&out),
    );
    // Extended to 400 iterations and served with no worker: it stays up.
    let c = Coordinator::start(&exp, &out, 30.0);
    let mut watcher = watch("farm", c.port);
    let (tx, rx) = mpsc::channel();
    let stdout = watcher.stdout.take().unwrap();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines().map_while(Result::ok) {
            if tx.send(line).is_err() {
                break;
            }
        }
    });
    let deadline = Instant::now() + TIMEOUT;
    let mut iterations = std::collections::BTreeSet::new();
    while iterations.len() < 300 {
        let left = deadline.saturating_duration_since(Instant::now());
        let line = rx
            .recv_timeout(left)
            .unwrap_or_else(|_| panic!("only {} of 300 iterations arrived", iterations.len()));
        let v: serde_json::Value = serde_json::from_str(&line).unwrap();
        if v["event"] == "history" {
            assert!(iterations.insert(v["result"]["iteration"].as_u64().unwrap()));
        }
    }
    let _ = watcher.kill();
    let _ = watcher.wait();
    assert_eq!(iterations.last(), Some(&299));
    let log = std::fs::read_to_string(&c.stderr).unwrap();
    assert!(!log.contains("Closing transport"), "{log}");
}

#[test]
fn a_late_watcher_gets_the_history_then_every_later_iteration_once() {
    let dir = scratch("watch");
    let exp = experiment(&dir, 14);
    let out = dir.join("run");
    let mut c = Coordinator::start(&exp, &out, 30.0);
    let port = c.port;
    let mut ws = vec![worker(port, 2, 40)];
    c.wait_decided(4);
    let watcher = watch("farm", port);
    let status = c.wait_exit();
    kill_all(&mut ws);
    assert!(status.success());
    let w = watcher.wait_with_output().unwrap();
    assert!(
        w.status.success(),
        "watch: {}",
        String::from_utf8_lossy(&w.stderr)
    );
    let ev = events(&w.stdout);
    assert!(ev.history.len() >= 4, "the status query's history");
    assert!(!ev.decided.is_empty(), "followed live");
    let mut seen: Vec<u64> = ev
        .history
        .iter()
        .chain(&ev.decided)
        .map(|r| r["iteration"].as_u64().unwrap())
        .collect();
    let reported = seen.len();
    seen.sort_unstable();
    seen.dedup();
    assert_eq!(reported, seen.len(), "an iteration reported twice");
    assert_eq!(seen, (0..14).collect::<Vec<u64>>(), "every iteration");
    let journaled = decided(&journal(&out));
    for r in ev.history.iter().chain(&ev.decided) {
        let i = r["iteration"].as_u64().unwrap() as usize;
        assert_eq!(r["stats"]["mx"].as_f64(), journaled[i].stats.mx);
    }
    let fin = ev.finished.expect("a finished line");
    assert_eq!(fin["status"]["finished"], true);

    // The run is over: watching it now says so and exits non-zero.
    let after = naofarm()
        .args(["watch", "farm", "--timeout-s", "1", "--connect"])
        .arg(format!("tcp/127.0.0.1:{port}"))
        .output()
        .unwrap();
    assert_eq!(after.status.code(), Some(1));
    let err = String::from_utf8_lossy(&after.stderr);
    assert!(err.contains("finished or unknown"), "{err}");
}

#[test]
fn watching_an_unknown_run_says_so() {
    let dir = scratch("watch-unknown");
    let exp = experiment(&dir, 3);
    let out = dir.join("run");
    let mut c = Coordinator::start(&exp, &out, 30.0);
    let port = c.port;
    let unknown = naofarm()
        .args(["watch", "nosuchrun", "--timeout-s", "3", "--connect"])
        .arg(format!("tcp/127.0.0.1:{port}"))
        .output()
        .unwrap();
    let listed = naofarm()
        .args(["watch", "--json", "--timeout-s", "5", "--connect"])
        .arg(format!("tcp/127.0.0.1:{port}"))
        .output()
        .unwrap();
    let mut ws = vec![worker(port, 2, 0)];
    assert!(c.wait_exit().success());
    kill_all(&mut ws);
    assert_eq!(unknown.status.code(), Some(1));
    let err = String::from_utf8_lossy(&unknown.stderr);
    assert!(
        err.contains("nosuchrun") && err.contains("unknown"),
        "{err}"
    );
    assert!(listed.status.success());
    let runs: Vec<serde_json::Value> = String::from_utf8_lossy(&listed.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(runs.len(), 1, "{runs:?}");
    assert_eq!(runs[0]["run"], "farm");
    let bad = naofarm().args(["watch", "a/b"]).output().unwrap();
    assert_eq!(bad.status.code(), Some(2));
}

#[test]
fn bad_messages_are_counted_and_change_nothing() {
    use protocol::wire::{TrialOutcome, WireMessage};
    use zenoh::Wait;
    let dir = scratch("garbage");
    let exp = experiment(&dir, 10);
    let out = dir.join("run");
    // No worker yet: the coordinator cannot finish before the garbage is in.
    let mut c = Coordinator::start(&exp, &out, 30.0);
    let port = c.port;
    let session = session_to(port);
    // Wait until the coordinator is reachable (its status answers): by then
    // its subscriptions are known to this session and puts are routed.
    let deadline = Instant::now() + TIMEOUT;
    let id = loop {
        let replies = session
            .get("naofarm/farm/*/status")
            .timeout(Duration::from_secs(2))
            .wait()
            .unwrap();
        if let Ok(r) = replies.recv() {
            let s = r.result().expect("a status");
            let v: serde_json::Value =
                serde_json::from_slice(&s.payload().to_bytes()).expect("JSON status");
            break v["id"].as_str().expect("the run id").to_string();
        }
        assert!(
            Instant::now() < deadline,
            "coordinator never answered its status query"
        );
    };
    let key = protocol::keys::FleetKeys::new("naofarm", &id).outcomes();
    let good = TrialOutcome {
        run: id.clone(),
        iteration: 1,
        trial: 0,
        seed: 0,
        dispatch: 0,
        worker: "intruder".into(),
        fell: false,
        x_m: 1.0,
        y_m: 0.0,
        fall_time_s: None,
        sim_time_s: 10.0,
        wall_time_s: 0.0,
        fingerprint: 0,
    };
    let mut nan = good.encode().unwrap();
    // Same layout with x_m's bytes replaced by NaN: find 1.0f64 and swap it.
    let one = 1.0f64.to_le_bytes();
    if let Some(i) = nan.windows(8).position(|w| w == one) {
        nan[i..i + 8].copy_from_slice(&f64::NAN.to_le_bytes());
    }
    let bad: Vec<Vec<u8>> = vec![
        b"garbage".to_vec(),
        vec![b'N', b'F', 99, 2, 1, 2, 3],
        nan,
        TrialOutcome {
            run: "otherrun".into(),
            ..good.clone()
        }
        .encode()
        .unwrap(),
        TrialOutcome {
            iteration: 999_999,
            ..good.clone()
        }
        .encode()
        .unwrap(),
        TrialOutcome {
            trial: 77,
            ..good.clone()
        }
        .encode()
        .unwrap(),
        TrialOutcome {
            seed: 12345,
            ..good.clone()
        }
        .encode()
        .unwrap(),
    ];
    for b in &bad {
        session.put(&key, b.clone()).wait().unwrap();
    }
    let mut ws: Vec<Proc> = (0..2).map(|_| worker(port, 2, 5)).collect();
    let status = c.wait_exit();
    kill_all(&mut ws);
    session.close().wait().unwrap();
    assert!(status.success(), "{:?}", c.seen);
    let records = journal(&out);
    assert_every_trial_once(&records, 10);
    let intruder = records
        .iter()
        .any(|r| matches!(r, Record::Outcome { worker, .. } if worker == "intruder"));
    assert!(
        !intruder,
        "nothing from the bad messages reached the journal"
    );
    let log = std::fs::read_to_string(out.with_extension("stderr")).unwrap();
    let refused: u64 = log
        .lines()
        .find(|l| l.starts_with("run complete:"))
        .and_then(|l| l.split(" refused").next())
        .and_then(|s| s.rsplit(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no summary in {log}"));
    assert!(refused >= bad.len() as u64, "{log}");
}

#[test]
fn a_held_run_thread_never_holds_up_work_requests() {
    // The run's thread (journal, pickOut, CLOP) is held for a long while
    // after its first outcome, as a slow fit would: meanwhile the service
    // keeps handing the ready trials to workers and answering queries.
    let dir = scratch("held");
    let exp = experiment(&dir, 6);
    let out = dir.join("run");
    let stderr = out.with_extension("stderr");
    let mut child = naofarm()
        .args(["coordinator", "--json", "--listen", "tcp/127.0.0.1:0"])
        .arg(&exp)
        .arg("--out")
        .arg(&out)
        .env("NAOFARM_FAULT_DECIDE_HOLD", "8000@1")
        .env("RUST_LOG", "warn")
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(&stderr).unwrap())
        .spawn()
        .unwrap();
    let deadline = Instant::now() + TIMEOUT;
    let port = listening_port(&stderr);
    let ws: Vec<Proc> = (0..2).map(|_| worker(port, 2, 20)).collect();
    while !plain(&std::fs::read_to_string(&stderr).unwrap_or_default()).contains("thread holds") {
        assert!(
            Instant::now() < deadline,
            "the hook never held the run's thread"
        );
        std::thread::sleep(Duration::from_millis(10));
    }
    // 3 iterations of 6 trials are open: all 18 get handed out and run
    // while the journal still holds one outcome.
    let started = || {
        ws.iter()
            .map(|w| w.stderr().matches("trial started").count())
            .sum::<usize>()
    };
    while started() < 18 {
        assert!(
            Instant::now() < deadline,
            "work stopped with the run's thread: {} started",
            started()
        );
        std::thread::sleep(Duration::from_millis(10));
    }
    let text = plain(&std::fs::read_to_string(&stderr).unwrap_or_default());
    let outcomes = journal(&out)
        .iter()
        .filter(|r| matches!(r, Record::Outcome { .. }))
        .count();
    assert!(
        !text.contains("thread goes on") && outcomes <= 1,
        "the trials were handed out while the run's thread was held ({outcomes} journaled)"
    );
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        assert!(Instant::now() < deadline, "the run never finished");
        std::thread::sleep(Duration::from_millis(20));
    };
    assert!(status.success());
    assert_every_trial_once(&journal(&out), 6);
}
