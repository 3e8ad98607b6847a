//! End-to-end tests: the `naofarm` binary as a real process.
#![allow(clippy::unwrap_used)]

mod util;

use util::{naofarm, root, scratch, succeed};

#[test]
fn check_prints_the_five_parameters_with_the_papers_bounds() {
    let out = naofarm()
        .arg("check")
        .arg(root().join("experiments/physical-technical.toml"))
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{text}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    for (name, lo, hi) in [
        ("ThighRelHip2_Z", "-0.08", "-0.03"),
        ("ratio_flexion", "0.6", "0.95"),
        ("long_offset_MidAnkles_2_Torso_Init", "0.001", "0.03"),
        ("height_lift", "0.025", "0.07"),
        ("xlength_step_max", "0.02", "0.15"),
    ] {
        let line = text
            .lines()
            .find(|l| l.contains(name))
            .unwrap_or_else(|| panic!("{name} missing:\n{text}"));
        assert!(line.contains(&format!("[{lo}, {hi}]")), "{line}");
    }
}

#[test]
fn check_json_is_machine_readable() {
    let out = naofarm()
        .args(["check", "--json"])
        .arg(root().join("experiments/physical.toml"))
        .output()
        .unwrap();
    assert!(out.status.success());
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["parameter"][0]["name"], "ThighRelHip2_Z");
    assert_eq!(v["parameter"][0]["lower"], -0.10);
}

#[test]
fn malformed_experiments_exit_2_naming_the_problem() {
    let good = std::fs::read_to_string(root().join("experiments/physical-technical.toml")).unwrap();
    let dir = scratch("check");
    let cases = [
        ("seed = 1", "seed = 1\nspeed = 3", "speed"),
        ("lower = -0.08", "lower = -0.02", "parameter[0].lower"),
        ("expert = 0.730", "expert = 0.99", "parameter[1].expert"),
        ("beta = 1.0", "beta = 3.5", "pickout.beta"),
        (
            "trials_per_iteration = 10",
            "trials_per_iteration = 0",
            "trials_per_iteration",
        ),
        (
            "name = \"height_lift\"",
            "name = \"lift_height\"",
            "unknown parameter `lift_height`",
        ),
        ("lower = 0.60", "lower = nan", "parameter[1].lower"),
        ("seed = 1", "seed = ", "line"),
    ];
    for (i, (from, to, needle)) in cases.iter().enumerate() {
        let text = good.replacen(from, to, 1);
        assert_ne!(text, good, "{from}");
        let path = dir.join(format!("bad{i}.toml"));
        std::fs::write(&path, text).unwrap();
        let out = naofarm().arg("check").arg(&path).output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{to}: {err}");
        assert!(err.contains(needle), "{to}: {err}");
    }
    let out = naofarm()
        .arg("check")
        .arg(dir.join("missing.toml"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
}

mod farm {
    //! The farm as real processes over 127.0.0.1: a coordinator, workers, kills.

    use std::{
        io::{BufRead, BufReader},
        path::{Path, PathBuf},
        process::{Child, Stdio},
        sync::mpsc,
        time::{Duration, Instant},
    };

    use coordinator::{
        evolve::DecidedIteration,
        journal::{Journal, Record},
    };

    use super::{naofarm, scratch, succeed, util::Proc};
    // `events` parses the JSON lines of run, coordinator and watch.

    const TIMEOUT: Duration = Duration::from_secs(120);

    fn experiment(dir: &Path, iterations: u64) -> PathBuf {
        let text =
            std::fs::read_to_string(super::root().join("experiments/test/two-parameters.toml"))
                .unwrap()
                .replace("name = \"syn\"", "name = \"farm\"")
                .replace("seed = 42", "seed = 5")
                .replace("iterations = 40", &format!("iterations = {iterations}"))
                .replace("n_mcmc = 200", "n_mcmc = 100");
        let p = dir.join("exp.toml");
        std::fs::write(&p, text).unwrap();
        p
    }

    fn free_port() -> u16 {
        std::net::TcpListener::bind("127.0.0.1:0")
            .unwrap()
            .local_addr()
            .unwrap()
            .port()
    }

    struct Coordinator {
        child: Child,
        stderr: PathBuf,
        lines: mpsc::Receiver<String>,
        seen: Vec<String>,
    }

    impl Coordinator {
        fn start(exp: &Path, out: &Path, port: u16, lease_s: f64) -> Self {
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
            Self {
                child,
                stderr,
                lines,
                seen: Vec::new(),
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
            while !plain(&std::fs::read_to_string(&self.stderr).unwrap_or_default())
                .contains(needle)
            {
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
        Proc::spawn(
            naofarm()
                .args(["worker", "--connect", &format!("tcp/127.0.0.1:{port}")])
                .args([
                    "--slots",
                    &slots.to_string(),
                    "--min-trial-ms",
                    &pace_ms.to_string(),
                ])
                .env("RUST_LOG", "warn,naofarm_worker::service=info")
                .stdout(Stdio::null()),
            &std::env::temp_dir(),
            "worker",
        )
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

    /// The index of a worker of `ws` that the run in `out` has journaled an
    /// outcome of (so it is connected and being given work), waiting for one.
    fn a_busy_worker(out: &Path, ws: &[Proc]) -> usize {
        let ids: Vec<String> = ws.iter().map(worker_id).collect();
        let deadline = Instant::now() + TIMEOUT;
        loop {
            let records = Journal::read(out).map(|s| s.records()).unwrap_or_default();
            if let Some(i) = ids.iter().position(|id| {
                records
                    .iter()
                    .any(|r| matches!(r, Record::Outcome { worker, .. } if worker == id))
            }) {
                return i;
            }
            assert!(Instant::now() < deadline, "no worker ran a trial");
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    fn journal(dir: &Path) -> Vec<Record> {
        Journal::read(dir).unwrap().records()
    }

    fn decided(records: &[Record]) -> Vec<DecidedIteration> {
        records
            .iter()
            .filter_map(|r| {
                if let Record::Decided(d) = r {
                    Some(d.clone())
                } else {
                    None
                }
            })
            .collect()
    }

    fn bits(h: &[DecidedIteration]) -> Vec<u64> {
        let mut v = Vec::new();
        for d in h {
            v.push(d.iteration);
            v.extend(d.params.iter().map(|x| x.to_bits()));
            v.push(d.decision as u64);
            v.extend(
                [d.stats.mx, d.stats.my, d.stats.ex]
                    .iter()
                    .map(|x| x.map_or(u64::MAX, f64::to_bits)),
            );
        }
        v
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

    /// Runs a whole farm run with `n` workers; returns the run directory.
    fn farm_run(name: &str, n: usize, iterations: u64) -> PathBuf {
        let dir = scratch(name);
        let exp = experiment(&dir, iterations);
        let port = free_port();
        let out = dir.join("run");
        // Workers first: they keep trying to connect until the coordinator listens.
        let mut ws: Vec<Proc> = (0..n).map(|_| worker(port, 2, 15)).collect();
        let mut c = Coordinator::start(&exp, &out, port, 30.0);
        let status = c.wait_exit();
        kill_all(&mut ws);
        assert!(status.success(), "coordinator: {status}; {:?}", c.seen);
        out
    }

    #[test]
    fn three_workers_complete_a_run_with_every_trial_journaled_once() {
        let out = farm_run("three", 3, 20);
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
        let one = decided(&journal(&farm_run("det1", 1, 15)));
        let three = decided(&journal(&farm_run("det3", 3, 15)));
        assert_eq!(one.len(), 15);
        assert_eq!(bits(&one), bits(&three));
    }

    #[test]
    fn a_killed_worker_loses_no_trial() {
        let dir = scratch("sigkill");
        let exp = experiment(&dir, 20);
        let port = free_port();
        let out = dir.join("run");
        let mut c = Coordinator::start(&exp, &out, port, 30.0);
        let mut ws: Vec<Proc> = (0..3).map(|_| worker(port, 2, 20)).collect();
        c.wait_decided(3);
        let victim = a_busy_worker(&out, &ws);
        ws[victim].kill();
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
        let port = free_port();
        let out = dir.join("run");
        let mut c = Coordinator::start(&exp, &out, port, 1.0);
        let mut ws: Vec<Proc> = (0..3).map(|_| worker(port, 2, 20)).collect();
        c.wait_decided(2);
        let frozen = a_busy_worker(&out, &ws);
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
        let reference = decided(&journal(&farm_run("resume-ref", 2, 20)));
        let dir = scratch("resume");
        let exp = experiment(&dir, 20);
        let port = free_port();
        let out = dir.join("run");
        let mut ws: Vec<Proc> = (0..2).map(|_| worker(port, 2, 10)).collect();
        // SIGKILL at several points: after 3 new decisions, 6 more, 5 more.
        for n in [3, 6, 5] {
            let mut c = Coordinator::start(&exp, &out, port, 30.0);
            c.wait_decided(n);
            c.child.kill().unwrap();
            let _ = c.child.wait();
        }
        let mut c = Coordinator::start(&exp, &out, port, 30.0);
        let status = c.wait_exit();
        kill_all(&mut ws);
        assert!(status.success(), "{:?}", c.seen);
        let records = journal(&out);
        assert_every_trial_once(&records, 20);
        assert_eq!(bits(&decided(&records)), bits(&reference));
    }

    #[test]
    fn a_worker_that_fails_every_trial_is_set_aside_and_the_history_is_the_runs() {
        let dir = scratch("set-aside");
        let exp = experiment(&dir, 20);
        let local = dir.join("local");
        succeed(
            naofarm()
                .args(["run", "--json", "--workers", "2"])
                .arg(&exp)
                .arg("--out")
                .arg(&local),
        );
        let port = free_port();
        let out = dir.join("run");
        let mut bad = Proc::spawn(
            naofarm()
                .args(["worker", "--connect", &format!("tcp/127.0.0.1:{port}")])
                .args(["--slots", "2", "--min-trial-ms", "5"])
                .env("NAOFARM_FAULT_TRIAL", "fail")
                .stdout(Stdio::null()),
            &dir,
            "failing-worker",
        );
        // All workers first (they retry until the coordinator listens); the bad
        // one has the most free slots, so it is offered work first.
        let mut ws = vec![worker(port, 1, 20), worker(port, 1, 20)];
        let mut c = Coordinator::start(&exp, &out, port, 30.0);
        let status = c.wait_exit();
        kill_all(&mut ws);
        bad.kill();
        assert!(status.success(), "{:?}", c.seen);
        let finished: serde_json::Value = c
            .seen
            .iter()
            .find(|l| l.starts_with("{\"accepted\"") || l.contains("\"event\":\"finished\""))
            .map(|l| serde_json::from_str(l).unwrap())
            .expect("a finished line");
        let set_aside = finished["set_aside"].as_array().expect("set_aside");
        assert_eq!(set_aside.len(), 1, "{finished}");
        assert!(finished["failures"].as_u64().unwrap() >= 3, "{finished}");
        let records = journal(&out);
        assert_every_trial_once(&records, 20);
        let failed: Vec<&Record> = records
            .iter()
            .filter(|r| matches!(r, Record::Failed { worker, .. } if serde_json::json!(worker) == set_aside[0]))
            .collect();
        assert!(
            failed.len() >= 3,
            "the failures are journaled with their worker"
        );
        assert_eq!(
            bits(&decided(&records)),
            bits(&decided(&journal(&local))),
            "the same history as the run alone"
        );
    }

    #[test]
    fn a_second_coordinator_on_a_run_directory_exits_2_while_the_first_finishes() {
        let dir = scratch("two-coordinators");
        let exp = experiment(&dir, 8);
        let port = free_port();
        let out = dir.join("run");
        let mut c = Coordinator::start(&exp, &out, port, 30.0);
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
            .args(["--listen", &format!("tcp/127.0.0.1:{}", free_port())])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&second.stderr);
        assert_eq!(second.status.code(), Some(2), "{err}");
        assert!(err.contains(&holder) && err.contains("in use"), "{err}");
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
        let port = free_port();
        let out = dir.join("run");
        let mut c = Coordinator::start(&exp, &out, port, 30.0);
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

    fn outcome_worker(r: &Record) -> Option<String> {
        if let Record::Outcome { worker, .. } = r {
            Some(worker.clone())
        } else {
            None
        }
    }

    /// The README's field tables: schema name → (field, type) rows.
    fn readme_schemas() -> std::collections::BTreeMap<String, Vec<(String, String)>> {
        let text = std::fs::read_to_string(super::root().join("README.md")).unwrap();
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
    /// type, and no field the README does not document.
    fn conforms(
        schemas: &std::collections::BTreeMap<String, Vec<(String, String)>>,
        name: &str,
        v: &serde_json::Value,
    ) -> Result<(), String> {
        let rows = schemas
            .get(name)
            .ok_or_else(|| format!("no schema {name} in the README"))?;
        let obj = v
            .as_object()
            .ok_or_else(|| format!("{name}: not an object: {v}"))?;
        for key in obj.keys() {
            if !rows.iter().any(|(f, _)| f == key) {
                return Err(format!("{name}.{key} is not documented in the README"));
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
        ] {
            assert!(schemas.contains_key(s), "README lacks the {s} table");
        }
        let dir = scratch("schema");
        let exp = experiment(&dir, 8);
        let port = free_port();
        let out = dir.join("run");
        let mut c = Coordinator::start(&exp, &out, port, 30.0);
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
        let status = ask(protocol::keys::status("naofarm", "farm"));
        conforms(&schemas, "RunStatus", &status).unwrap();
        let mut ws = vec![worker(port, 2, 5)];
        c.wait_decided(4);
        let history = ask(protocol::keys::history("naofarm", "farm"));
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
            let schema = match key.split('/').nth(2) {
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

    #[test]
    fn a_late_watcher_gets_the_history_then_every_later_iteration_once() {
        let dir = scratch("watch");
        let exp = experiment(&dir, 14);
        let port = free_port();
        let out = dir.join("run");
        let mut c = Coordinator::start(&exp, &out, port, 30.0);
        let mut ws = vec![worker(port, 2, 40)];
        c.wait_decided(4);
        let watcher = naofarm()
            .args(["watch", "farm", "--json", "--connect"])
            .arg(format!("tcp/127.0.0.1:{port}"))
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let status = c.wait_exit();
        kill_all(&mut ws);
        assert!(status.success());
        let w = watcher.wait_with_output().unwrap();
        assert!(
            w.status.success(),
            "watch: {}",
            String::from_utf8_lossy(&w.stderr)
        );
        let ev = super::events(&w.stdout);
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
        let port = free_port();
        let out = dir.join("run");
        let mut c = Coordinator::start(&exp, &out, port, 30.0);
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
        let port = free_port();
        let out = dir.join("run");
        // No worker yet: the coordinator cannot finish before the garbage is in.
        let mut c = Coordinator::start(&exp, &out, port, 30.0);
        let session = session_to(port);
        // Wait until the coordinator is reachable (its status answers): by then
        // its subscriptions are known to this session and puts are routed.
        let deadline = Instant::now() + TIMEOUT;
        loop {
            let replies = session
                .get(protocol::keys::status("naofarm", "farm"))
                .timeout(Duration::from_secs(2))
                .wait()
                .unwrap();
            if replies.recv().is_ok() {
                break;
            }
            assert!(
                Instant::now() < deadline,
                "coordinator never answered its status query"
            );
        }
        let key = protocol::keys::outcomes("naofarm");
        let good = TrialOutcome {
            run: "farm".into(),
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
}

/// The JSON lines of `run --json` / `coordinator --json` / `watch --json`:
/// the decided iterations' results (history first), the last status, and
/// the final `finished` line.
struct Events {
    history: Vec<serde_json::Value>,
    decided: Vec<serde_json::Value>,
    status: Option<serde_json::Value>,
    finished: Option<serde_json::Value>,
}

fn events(stdout: &[u8]) -> Events {
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

#[test]
fn run_completes_a_synthetic_experiment_in_one_process() {
    let dir = scratch("run");
    let out = succeed(
        naofarm()
            .args(["run", "--json", "--workers", "2", "--iterations", "8"])
            .arg(root().join("experiments/synthetic.toml"))
            .arg("--out")
            .arg(dir.join("run")),
    );
    let ev = events(&out.stdout);
    let lines = ev.decided;
    assert_eq!(lines.len(), 8);
    let status = ev.status.expect("status lines");
    assert_eq!(status["decided"], 8);
    assert_eq!(status["finished"], true);
    let finished = ev.finished.expect("a finished line with the optima");
    let best = &finished["status"]["best"];
    assert!(best["iteration"].is_u64(), "Optim.1: {finished}");
    assert_eq!(
        finished["status"]["optim2"].as_array().map(Vec::len),
        Some(5)
    );

    // `history` exports the same H, with ν′ flagged once.
    let h = succeed(naofarm().arg("history").arg(dir.join("run")).arg("--json"));
    let rows: Vec<serde_json::Value> = serde_json::from_slice(&h.stdout).unwrap();
    assert_eq!(rows.len(), 8);
    for (row, line) in rows.iter().zip(&lines) {
        assert_eq!(row["iteration"], line["iteration"]);
        assert_eq!(row["mx"], line["stats"]["mx"]);
        assert!(["ACCEPT", "EQUIVALENT", "REJECT"].contains(&row["decision"].as_str().unwrap()));
        assert_eq!(row["params"].as_object().map(|o| o.len()), Some(5));
    }
    let flagged: Vec<&serde_json::Value> = rows.iter().filter(|r| r["best"] == true).collect();
    assert_eq!(flagged.len(), 1);
    assert_eq!(flagged[0]["iteration"], best["iteration"]);
    let csv = succeed(naofarm().arg("history").arg(dir.join("run")).arg("--csv"));
    let csv = String::from_utf8_lossy(&csv.stdout);
    assert_eq!(csv.lines().count(), 9, "a header and 8 rows");
    assert!(csv.starts_with("iteration,ThighRelHip2_Z,"));
    let missing = naofarm()
        .arg("history")
        .arg(dir.join("nowhere"))
        .output()
        .unwrap();
    assert_eq!(missing.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&missing.stderr).contains("journal"));
}

#[test]
fn a_torn_journal_resumes_and_a_corrupt_one_is_refused_with_its_offset() {
    let dir = scratch("journal-damage");
    let exp = root().join("experiments/synthetic.toml");
    let run = |out: &std::path::Path| {
        naofarm()
            .args(["run", "--json", "--workers", "1", "--iterations", "6"])
            .arg(&exp)
            .arg("--out")
            .arg(out)
            .output()
            .unwrap()
    };
    let reference = dir.join("reference");
    assert!(run(&reference).status.success());
    let want = succeed(naofarm().arg("history").arg(&reference).arg("--csv")).stdout;
    let journal = reference.join("journal.nfj");
    let bytes = std::fs::read(&journal).unwrap();

    // A torn tail (a crash mid-write): dropped with a warning, the run resumes.
    let torn = dir.join("torn");
    std::fs::create_dir_all(&torn).unwrap();
    std::fs::write(torn.join("journal.nfj"), &bytes[..bytes.len() * 2 / 3 - 3]).unwrap();
    let out = run(&torn);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let got = succeed(naofarm().arg("history").arg(&torn).arg("--csv")).stdout;
    assert_eq!(
        got, want,
        "the resumed history equals the uninterrupted one"
    );

    // A damaged byte in the middle: refused, naming the offset; the file is kept as it was.
    let corrupt = dir.join("corrupt");
    std::fs::create_dir_all(&corrupt).unwrap();
    let mut damaged = bytes.clone();
    let middle = damaged.len() / 2;
    damaged[middle] ^= 0x5a;
    std::fs::write(corrupt.join("journal.nfj"), &damaged).unwrap();
    let out = run(&corrupt);
    assert_eq!(out.status.code(), Some(1), "{out:?}");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("damaged frame at byte offset") && err.contains("journal salvage"),
        "{err}"
    );
    assert_eq!(std::fs::read(corrupt.join("journal.nfj")).unwrap(), damaged);
}

#[test]
fn the_main_job_runs_five_nao_iterations() {
    let dir = scratch("main-job");
    let out = succeed(
        naofarm()
            .args(["run", "--json", "--iterations", "5"])
            .arg(root().join("experiments/physical-technical.toml"))
            .arg("--out")
            .arg(dir.join("run")),
    );
    let ev = events(&out.stdout);
    let lines = ev.decided;
    assert_eq!(lines.len(), 5);
    assert_eq!(
        lines[0]["params"][0],
        serde_json::json!(["ThighRelHip2_Z", -0.04]),
        "the expert set first"
    );
    let finished = ev.finished.expect("finished line");
    assert_eq!(finished["status"]["decided"], 5);
    assert_eq!(finished["status"]["finished"], true);

    // A farm trial replayed locally gives the journaled x, y and fall time bit for bit.
    let run_dir = dir.join("run");
    let journaled = coordinator::journal::Journal::read(&run_dir)
        .unwrap()
        .records()
        .into_iter()
        .find_map(|r| match r {
            coordinator::journal::Record::Outcome {
                iteration: 4,
                trial: 7,
                measurement,
                ..
            } => Some(measurement),
            _ => None,
        })
        .expect("trial 4/7 journaled");
    let record = dir.join("replay.jsonl");
    let out = succeed(
        naofarm()
            .args([
                "trial",
                "--json",
                "--iteration",
                "4",
                "--trial",
                "7",
                "--run",
            ])
            .arg(&run_dir)
            .arg("--record")
            .arg(&record),
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["identical"], true, "{v}");
    let bits = |x: &serde_json::Value| x.as_f64().map(f64::to_bits);
    assert_eq!(bits(&v["replayed"]["x_m"]), Some(journaled.x_m.to_bits()));
    assert_eq!(bits(&v["replayed"]["y_m"]), Some(journaled.y_m.to_bits()));
    assert_eq!(
        v["replayed"]["fall_time_s"].as_f64().map(f64::to_bits),
        journaled.fall_time_s.map(f64::to_bits)
    );
    let header: serde_json::Value = serde_json::from_str(
        std::fs::read_to_string(&record)
            .unwrap()
            .lines()
            .next()
            .unwrap(),
    )
    .unwrap();
    assert_eq!(
        header["seed"], v["seed"],
        "the replay records the farm trial's seed"
    );
    let err = String::from_utf8_lossy(
        &naofarm()
            .args(["trial", "--iteration", "99", "--trial", "0", "--run"])
            .arg(&run_dir)
            .output()
            .unwrap()
            .stderr,
    )
    .to_string();
    assert!(err.contains("iteration 99 is not open"), "{err}");
}

#[test]
fn a_closed_pipe_ends_output_quietly() {
    // `naofarm model | head -1`, and a run whose JSON events (over 100 kB,
    // more than a pipe holds) lose their reader after one line: each ends
    // with 0 and no panic, and the run goes on to its end.
    let dir = scratch("pipe");
    let run_dir = dir.join("run").display().to_string();
    let exp = root()
        .join("experiments/synthetic.toml")
        .display()
        .to_string();
    for args in [
        vec!["model".to_string()],
        vec!["model".into(), "--json".into()],
        vec![
            "run".into(),
            "--json".into(),
            exp,
            "--out".into(),
            run_dir.clone(),
        ],
    ] {
        use std::io::BufRead;
        let mut child = naofarm()
            .args(&args)
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        let mut first = String::new();
        std::io::BufReader::new(child.stdout.take().unwrap())
            .read_line(&mut first)
            .unwrap();
        assert!(!first.is_empty());
        let out = child.wait_with_output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(0), "{args:?}: {err}");
        assert!(!err.contains("panicked"), "{err}");
    }
    let h = succeed(naofarm().args(["history", "--csv", &run_dir]));
    assert_eq!(
        String::from_utf8_lossy(&h.stdout).lines().count(),
        61,
        "the run went on"
    );
}

#[test]
fn model_prints_the_robot_and_refuses_an_impossible_thigh() {
    let out = naofarm()
        .args(["model", "--json", "--param", "ThighRelHip2_Z=-0.079"])
        .output()
        .unwrap();
    assert!(out.status.success());
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!((v["total_mass_kg"].as_f64().unwrap() - 4.6071).abs() < 1e-9);
    assert!((v["hip_to_sole_m"].as_f64().unwrap() - 0.309).abs() < 1e-9);
    let joints = v["joints"].as_array().unwrap();
    assert_eq!(joints.len(), 22);
    for f in ["name", "lower_rad", "upper_rad", "max_speed_rad_s"] {
        assert!(joints.iter().all(|j| !j[f].is_null()), "{f}");
    }
    let out = naofarm()
        .args(["model", "--param", "ThighRelHip2_Z=0.2"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("ThighRelHip2_Z") && err.contains("[-0.12, -0.005]"),
        "{err}"
    );
    let out = naofarm()
        .args(["model", "--param", "Bogus=1"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let out = naofarm().args(["model", "--type", "7"]).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
}

#[test]
fn stand_holds_and_reports_its_fields() {
    let out = succeed(naofarm().args(["stand", "--json", "--seconds", "3"]));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["fell"], false);
    let lo = v["torso_height_min_m"].as_f64().unwrap();
    let hi = v["torso_height_max_m"].as_f64().unwrap();
    assert!(lo > 0.3 && hi - lo < 0.01, "{lo} {hi}");
    let out = naofarm()
        .args(["stand", "--param", "ThighRelHip2_Z=-0.3"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
}

#[test]
fn trial_prints_the_table_iv_row_and_refuses_bad_parameters() {
    let run = |seed: &str| {
        let out = succeed(naofarm().args([
            "trial",
            "--json",
            "--trials",
            "3",
            "--duration",
            "3",
            "--seed",
            seed,
        ]));
        serde_json::from_slice::<serde_json::Value>(&out.stdout).unwrap()
    };
    let a = run("5");
    for f in ["s", "mx", "my", "ex", "ey"] {
        assert!(a[f].is_number(), "{f}: {a}");
    }
    let trials = a["trials"].as_array().unwrap();
    assert_eq!(trials.len(), 3);
    for f in ["seed", "fell", "x", "y", "fall_time_s"] {
        assert!(trials.iter().all(|t| t.get(f).is_some()), "{f}");
    }
    let b = run("5");
    assert_eq!(a["mx"], b["mx"]);
    assert_eq!(a["trials"], b["trials"]);
    for bad in ["ratio_flexion=7", "Bogus=1", "height_lift=nan"] {
        let out = naofarm()
            .args(["trial", "--trials", "1", "--param", bad])
            .output()
            .unwrap();
        assert_eq!(out.status.code(), Some(2), "{bad}");
        assert!(!out.stderr.is_empty());
    }
    let out = naofarm()
        .args(["trial", "--trials", "1", "--pgs-iterations", "500"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--pgs-iterations"));
}

#[test]
fn trial_records_a_replay_of_its_first_trial() {
    let f = scratch("record").join("replay.jsonl");
    let out = succeed(
        naofarm()
            .args([
                "trial",
                "--json",
                "--trials",
                "2",
                "--duration",
                "1",
                "--seed",
                "4",
            ])
            .arg("--record")
            .arg(&f),
    );
    let row: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let text = std::fs::read_to_string(&f).unwrap();
    let lines: Vec<serde_json::Value> = text
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let bodies = lines[0]["bodies"].as_array().unwrap().len();
    assert_eq!(lines[0]["seed"], 4);
    assert_eq!(bodies, 23, "type 0 has 23 bodies");
    // One line per 20 ms cycle of the 1 s trial, every body's pose in each.
    assert_eq!(lines.len(), 1 + 50);
    for l in &lines[1..] {
        let poses = l["poses"].as_array().unwrap();
        assert_eq!(poses.len(), bodies);
        assert!(poses
            .iter()
            .flat_map(|p| p.as_array().unwrap())
            .all(|x| x.as_f64().unwrap().is_finite()));
    }
    // The recorded trial is the first of the row: same end of the torso.
    let last = &lines[50]["poses"][0];
    let first = &lines[1]["poses"][0];
    let dx = last[0].as_f64().unwrap() - first[0].as_f64().unwrap();
    let x = row["trials"][0]["x"].as_f64().unwrap();
    assert!((dx - x).abs() < 0.05, "{dx} vs {x}");
    let z = last[2].as_f64().unwrap();
    assert!(z > 0.25 && z < 0.45, "torso at {z} m");
    let out = naofarm()
        .args([
            "trial",
            "--trials",
            "1",
            "--record",
            "/nonexistent-dir/x.jsonl",
        ])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
}

#[test]
fn the_nao_farm_gives_the_same_history_with_one_or_two_workers() {
    let dir = scratch("nao-farm");
    let exp = dir.join("nao.toml");
    std::fs::write(
        &exp,
        "name = \"nao-small\"\nseed = 3\niterations = 3\ntrials_per_iteration = 3\n\
         trial_duration_s = 2.0\npipeline_depth = 2\nmodel = \"nao\"\nstart = \"expert\"\n\n\
         [[parameter]]\nname = \"ratio_flexion\"\nkind = \"linear\"\nlower = 0.6\nupper = 0.95\nexpert = 0.73\n\n\
         [[parameter]]\nname = \"xlength_step_max\"\nkind = \"linear\"\nlower = 0.02\nupper = 0.15\nexpert = 0.08\n",
    )
    .unwrap();
    let run = |workers: &str| {
        let out_dir = dir.join(format!("run-{workers}"));
        let out = succeed(
            naofarm()
                .args(["run", "--json", "--workers", workers])
                .arg(&exp)
                .arg("--out")
                .arg(&out_dir),
        );
        events(&out.stdout)
            .decided
            .into_iter()
            .map(|v| {
                (
                    v["iteration"].clone(),
                    v["decision"].clone(),
                    v["stats"]["mx"].clone(),
                    v["params"].clone(),
                )
            })
            .collect::<Vec<_>>()
    };
    let one = run("1");
    assert_eq!(one.len(), 3);
    assert_eq!(one, run("2"));
}

#[test]
fn deploy_configs_are_valid_zenoh_configs() {
    for f in ["router", "coordinator", "worker"] {
        let path = root().join(format!("deploy/{f}.json5"));
        if let Err(e) = zenoh::Config::from_file(&path) {
            panic!("{}: {e}", path.display());
        }
    }
}

mod tune {
    //! `naofarm clop`: CLOP tuning a real noisy program, its log and resume.

    use std::path::{Path, PathBuf};

    use super::{naofarm, scratch, succeed};

    /// A noisy evaluator speaking lines: wins most often near x = 0.3.
    const EVALUATOR: &str = r#"#!/bin/sh
while read g s x; do
  awk -v s="$s" -v x="$x" 'BEGIN { srand(s % 1000003); p = 1 / (1 + exp(30 * (x - 0.3)^2 - 1)); if (rand() < p) print "W"; else print "L" }'
done
"#;

    fn script(dir: &Path, name: &str, text: &str) -> PathBuf {
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        let ok = std::process::Command::new("chmod")
            .arg("+x")
            .arg(&p)
            .status()
            .unwrap();
        assert!(ok.success());
        p
    }

    fn tune(evaluator: &Path, budget: u64, log: Option<&Path>) -> std::process::Output {
        let mut c = clop_cmd(evaluator, budget);
        if let Some(l) = log {
            c.arg("--log").arg(l);
        }
        c.output().unwrap()
    }

    #[test]
    fn clop_tunes_a_noisy_program_and_resumes_from_its_log() {
        let dir = scratch("clop-tune");
        let ev = script(&dir, "ev.sh", EVALUATOR);
        let straight = succeed(&mut clop_cmd(&ev, 300)).stdout;
        let v: serde_json::Value = serde_json::from_slice(&straight).unwrap();
        let x = v["mean"]["x"].as_f64().unwrap();
        assert!((0.15..0.45).contains(&x), "mean {x} far from 0.3: {v}");
        assert!(v["max"]["x"].as_f64().is_some());
        let games = v["wins"].as_u64().unwrap()
            + v["draws"].as_u64().unwrap()
            + v["losses"].as_u64().unwrap();
        assert_eq!(games, 300);

        // Stopped at 120 games, resumed to 300 from the log: the same answer, bit for bit.
        let log = dir.join("games.log");
        assert!(tune(&ev, 120, Some(&log)).status.success());
        let resumed = tune(&ev, 300, Some(&log));
        assert!(resumed.status.success());
        assert_eq!(resumed.stdout, straight);
        let lines = std::fs::read_to_string(&log).unwrap().lines().count();
        assert_eq!(lines, 301, "a header and one line per game");

        // A log of other parameters is refused.
        let other = naofarm()
            .args([
                "clop",
                "--param",
                "y:linear:0:2",
                "--budget",
                "10",
                "--evaluator",
            ])
            .arg(&ev)
            .arg("--log")
            .arg(&log)
            .output()
            .unwrap();
        assert_eq!(other.status.code(), Some(2));
        assert!(String::from_utf8_lossy(&other.stderr).contains("other parameters"));
    }

    fn clop_cmd(ev: &Path, budget: u64) -> std::process::Command {
        let mut c = naofarm();
        c.args(["clop", "--param", "x:linear:0:1", "--seed", "3", "--json"])
            .args(["--budget", &budget.to_string()])
            .arg("--evaluator")
            .arg(ev);
        c
    }

    #[test]
    fn clop_runs_a_classic_script_per_game() {
        let dir = scratch("clop-script");
        // CLOP's contract: <processor> <seed> <name> <value> …; the last line decides.
        let sc = script(
            &dir,
            "game.sh",
            "#!/bin/sh\necho \"processor $1 seed $2\"\n[ \"$3\" = x ] && [ \"$5\" = n ] || { echo bad-arguments; exit 1; }\n\
             awk -v v=\"$4\" 'BEGIN { print (v < 0.5) ? \"W\" : \"L\" }'\n",
        );
        let out = succeed(
            naofarm()
                .args([
                    "clop",
                    "--param",
                    "x:linear:0:1",
                    "--param",
                    "n:integer:1:4",
                ])
                .args(["--budget", "40", "--json", "--script"])
                .arg(&sc),
        );
        let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        assert_eq!(
            v["wins"].as_u64().unwrap() + v["losses"].as_u64().unwrap(),
            40
        );
        let n = v["mean"]["n"].as_f64().unwrap();
        assert!(n.fract() == 0.0 && (1.0..=4.0).contains(&n), "{v}");
    }

    #[test]
    fn a_failing_evaluator_is_a_clear_error_and_its_games_stay_in_the_log() {
        let dir = scratch("clop-bad");
        let cases = [
            (
                "wrong.sh",
                "#!/bin/sh\ni=0\nwhile read l; do i=$((i+1)); if [ $i -le 5 ]; then echo W; else echo maybe; fi; done\n",
                "answered `maybe` to game 5",
                5,
            ),
            (
                "dies.sh",
                "#!/bin/sh\nread l; echo L; read l; echo W; read l; exit 3\n",
                "exited",
                2,
            ),
            ("hangs.sh", "#!/bin/sh\nread l; echo W; read l; sleep 60\n", "within 1 s", 1),
        ];
        for (name, text, message, kept) in cases {
            let ev = script(&dir, name, text);
            let log = dir.join(format!("{name}.log"));
            let out = naofarm()
                .args([
                    "clop",
                    "--param",
                    "x:linear:0:1",
                    "--budget",
                    "50",
                    "--timeout-s",
                    "1",
                ])
                .arg("--evaluator")
                .arg(&ev)
                .arg("--log")
                .arg(&log)
                .output()
                .unwrap();
            assert_eq!(out.status.code(), Some(1), "{name}");
            let err = String::from_utf8_lossy(&out.stderr);
            assert!(err.contains(message), "{name}: {err}");
            let lines = std::fs::read_to_string(&log).unwrap().lines().count();
            assert_eq!(lines, 1 + kept, "{name}: the games played are kept");
        }
        let bad = naofarm()
            .args([
                "clop",
                "--param",
                "x:cubic:0:1",
                "--budget",
                "5",
                "--evaluator",
                "true",
            ])
            .output()
            .unwrap();
        assert_eq!(bad.status.code(), Some(2));
        assert!(String::from_utf8_lossy(&bad.stderr).contains("unknown kind `cubic`"));
    }
}
