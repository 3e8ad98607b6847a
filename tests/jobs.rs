//! Trial programs as jobs (docs/programs.md, "What a program may rely
//! on"), against real processes and `naofarm run`: a detached child (holding
//! the answer's pipe and not), a run killed by SIGKILL, trials three times
//! their lease, a junk line longer than a wire message, the environment,
//! the slots of concurrent trials, a program rewritten mid-run, and a run
//! stopped by SIGINT. Every test's workers get a temporary directory of
//! their own, checked empty at the end, and every process a test's program
//! starts carries a marker on its command line, checked gone.
#![allow(clippy::unwrap_used)]

mod util;

use std::{
    path::{Path, PathBuf},
    process::{Command, Stdio},
    time::Duration,
};

use util::{naofarm, root, scratch, wait_for, Scratch};

/// How long a test waits for anything.
const WITHIN: Duration = Duration::from_secs(60);

/// One test's farm: its directory, its workers' temporary directory, its
/// records and its programs' marker.
struct Farm {
    dir: Scratch,
    marker: String,
}

impl Farm {
    fn new(name: &str) -> Self {
        let dir = scratch(&format!("jobs-{name}"));
        for d in ["tmp", "records"] {
            std::fs::create_dir_all(dir.join(d)).unwrap();
        }
        let marker = format!("naofarm-test-marker-{}", uuid::Uuid::new_v4());
        Self { dir, marker }
    }

    fn tmp(&self) -> PathBuf {
        self.dir.join("tmp")
    }

    fn records(&self) -> PathBuf {
        self.dir.join("records")
    }

    fn out(&self) -> PathBuf {
        self.dir.join("run")
    }

    /// experiments/test/program.toml for the `job` program, with
    /// `iterations` iterations of `trials` trials.
    fn experiment(&self, iterations: u64, trials: u32) -> PathBuf {
        let text = std::fs::read_to_string(root().join("experiments/test/program.toml")).unwrap();
        let text = text
            .replace("program = \"toy\"", "program = \"job\"")
            .replace("iterations = 6", &format!("iterations = {iterations}"))
            .replace(
                "trials_per_iteration = 6",
                &format!("trials_per_iteration = {trials}"),
            );
        let p = self.dir.join("exp.toml");
        std::fs::write(&p, text).unwrap();
        p
    }

    /// `naofarm run` of [`Farm::experiment`] on `workers` local workers,
    /// the program `job` at `program` doing `mode`.
    fn run(
        &self,
        program: &Path,
        mode: &str,
        workers: u32,
        iterations: u64,
        trials: u32,
    ) -> Command {
        let mut cmd = naofarm();
        cmd.args(["run", "--json", "--workers", &workers.to_string()])
            .arg(self.experiment(iterations, trials))
            .arg("--out")
            .arg(self.out())
            .arg("--program")
            .arg(format!("job={}", program.display()))
            .args(["--program-env", &format!("NAOFARM_TEST_JOB={mode}")])
            .arg("--program-env")
            .arg(format!("NAOFARM_TEST_DIR={}", self.records().display()))
            .args([
                "--program-env",
                &format!("NAOFARM_TEST_MARKER={}", self.marker),
            ])
            .env("TMPDIR", self.tmp())
            .stdout(Stdio::piped());
        cmd
    }

    /// The processes alive whose command line carries this farm's marker.
    fn alive(&self) -> Vec<String> {
        let mut found = Vec::new();
        for e in std::fs::read_dir("/proc").unwrap().flatten() {
            if let Ok(cmd) = std::fs::read(e.path().join("cmdline")) {
                let cmd = String::from_utf8_lossy(&cmd).replace('\0', " ");
                if cmd.contains(&self.marker) {
                    found.push(format!("{}: {cmd}", e.file_name().to_string_lossy()));
                }
            }
        }
        found
    }

    /// Nothing of the programs is alive, and the workers left nothing in
    /// their temporary directory.
    fn assert_clean(&self) {
        wait_for(
            "the programs' processes to be gone",
            Duration::from_secs(10),
            || self.alive().is_empty().then_some(()),
        );
        let left: Vec<_> = std::fs::read_dir(self.tmp())
            .unwrap()
            .flatten()
            .map(|e| e.file_name())
            .collect();
        assert!(left.is_empty(), "left in the workers' TMPDIR: {left:?}");
    }

    fn lines(&self, name: &str) -> Vec<String> {
        std::fs::read_to_string(self.records().join(name))
            .unwrap_or_default()
            .lines()
            .map(str::to_string)
            .collect()
    }
}

fn job_program() -> PathBuf {
    root().join("tests/programs/job")
}

/// Runs `cmd` to its end (killed, and the test failed, after five
/// minutes), which must be exit code `code`: its stdout and stderr.
fn finish(cmd: &mut Command, code: i32) -> (String, String) {
    let mut child = cmd.stderr(Stdio::piped()).spawn().unwrap();
    let read = |mut r: Box<dyn std::io::Read + Send>| {
        std::thread::spawn(move || {
            let mut s = String::new();
            let _ = r.read_to_string(&mut s);
            s
        })
    };
    let out = read(Box::new(child.stdout.take().unwrap()));
    let err = read(Box::new(child.stderr.take().unwrap()));
    let ended = wait_for_quietly(&mut child, Duration::from_secs(300));
    let (out, err) = (out.join().unwrap(), err.join().unwrap());
    let Some(status) = ended else {
        panic!("{cmd:?} did not end within 300 s\n{err}");
    };
    assert_eq!(status.code(), Some(code), "{cmd:?}\n{err}");
    (out, err)
}

/// Waits for `child` to exit within `within`; kills it past that.
fn wait_for_quietly(
    child: &mut std::process::Child,
    within: Duration,
) -> Option<std::process::ExitStatus> {
    let deadline = std::time::Instant::now() + within;
    loop {
        if let Some(s) = child.try_wait().unwrap() {
            return Some(s);
        }
        if std::time::Instant::now() >= deadline {
            let _ = child.kill();
            let _ = child.wait();
            return None;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
}

#[test]
fn a_detached_child_neither_outlives_its_trial_nor_holds_back_its_answer() {
    for mode in ["daemon-holding", "daemon-quiet"] {
        let farm = Farm::new(mode);
        let (stdout, err) = finish(&mut farm.run(&job_program(), mode, 1, 2, 3), 0);
        assert_eq!(
            util::events(stdout.as_bytes()).decided.len(),
            2,
            "{mode}: {err}"
        );
        assert!(!err.contains("printed no measurement"), "{mode}: {err}");
        farm.assert_clean();
    }
}

/// The weaker mechanisms of hosts without a cgroup (a PID namespace) or
/// without either (the worker as child subreaper) kill a detached child
/// with its trial too.
#[test]
fn every_mechanism_kills_a_detached_child_with_its_trial() {
    for mechanism in ["pidns", "group"] {
        let farm = Farm::new(&format!("daemon-{mechanism}"));
        let (stdout, err) = finish(
            farm.run(&job_program(), "daemon-holding", 1, 1, 2)
                .env("NAOFARM_JOB_CONTAINMENT", mechanism)
                .env("RUST_LOG", "info"),
            0,
        );
        let said = if mechanism == "pidns" {
            "PID namespace"
        } else {
            "child subreaper"
        };
        assert!(
            err.contains(said) && !err.contains("cgroup v2"),
            "{mechanism}: {err}"
        );
        assert_eq!(
            util::events(stdout.as_bytes()).decided.len(),
            1,
            "{mechanism}: {err}"
        );
        farm.assert_clean();
    }
}

#[test]
fn a_killed_run_leaves_no_program_running_and_the_next_start_sweeps_its_scratch() {
    let farm = Farm::new("killed");
    let mut run = farm
        .run(&job_program(), "hang", 2, 2, 2)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    wait_for("both programs to start", WITHIN, || {
        (farm.lines("started").len() >= 2).then_some(())
    });
    assert!(farm.alive().len() >= 6, "{:?}", farm.alive());
    run.kill().unwrap();
    run.wait().unwrap();
    wait_for(
        "the killed run's programs to be gone",
        Duration::from_secs(10),
        || farm.alive().is_empty().then_some(()),
    );
    // Its workers' scratch stays until a naofarm process starts on this host.
    assert!(std::fs::read_dir(farm.tmp()).unwrap().next().is_some());
    let again = Farm {
        dir: scratch("jobs-killed-again"),
        marker: farm.marker.clone(),
    };
    std::fs::create_dir_all(again.records()).unwrap();
    finish(
        again
            .run(&job_program(), "slow", 1, 1, 1)
            .env("TMPDIR", farm.tmp())
            .args(["--program-env", "NAOFARM_TEST_SLEEP=0"]),
        0,
    );
    farm.assert_clean();
}

#[test]
fn a_trial_three_times_its_lease_runs_exactly_once() {
    let farm = Farm::new("lease");
    let (stdout, _) = finish(
        farm.run(&job_program(), "slow", 2, 1, 2).args([
            "--lease-s",
            "3",
            "--program-env",
            "NAOFARM_TEST_SLEEP=9",
        ]),
        0,
    );
    assert_eq!(util::events(stdout.as_bytes()).decided.len(), 1);
    let mut started = farm.lines("count");
    let n = started.len();
    started.sort();
    started.dedup();
    assert_eq!(
        started.len(),
        n,
        "a trial ran twice: {:?}",
        farm.lines("count")
    );
    assert!(n >= 2, "{started:?}");
    let finished: serde_json::Value = serde_json::from_str(stdout.lines().last().unwrap()).unwrap();
    assert_eq!(finished["redispatched"], 0, "{finished}");
    farm.assert_clean();
}

#[test]
fn a_junk_line_longer_than_a_message_stops_the_run_naming_it() {
    let farm = Farm::new("junk");
    let (_, err) = finish(&mut farm.run(&job_program(), "junk", 1, 2, 2), 1);
    assert!(
        err.contains("printed `\"jjjj") && err.contains("not a measurement"),
        "{err}"
    );
    farm.assert_clean();
}

/// A program over its CPU-time or file-size limit is a failed trial that
/// names the limit; the run stops on it.
#[test]
fn a_program_over_a_limit_fails_naming_the_limit() {
    for (mode, flag, said) in [
        ("spin", "--program-cpu-s", "CPU-time limit of 1 s"),
        (
            "bigfile",
            "--program-file-size-mib",
            "file-size limit of 1 MiB",
        ),
    ] {
        let farm = Farm::new(mode);
        let (_, err) = finish(
            farm.run(&job_program(), mode, 1, 1, 1)
                .args([flag, "1", "--max-trial-failures", "1"]),
            1,
        );
        assert!(err.contains(said), "{mode}: {err}");
        farm.assert_clean();
    }
}

#[test]
fn a_program_sees_only_what_its_owner_gives_it() {
    let farm = Farm::new("env");
    let home = std::env::var("HOME").unwrap_or_default();
    finish(
        farm.run(&job_program(), "env", 1, 1, 2)
            .env("NAOFARM_TEST_WORKER_SECRET", "hunter2")
            .env(
                "CREDENTIALS_DIRECTORY",
                "/run/credentials/naofarm-worker.service",
            )
            .args(["--program-env", "PASSED=yes"]),
        0,
    );
    let dumps: Vec<PathBuf> = std::fs::read_dir(farm.records())
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.to_string_lossy().contains("env-"))
        .collect();
    assert!(!dumps.is_empty());
    for d in dumps {
        let v: serde_json::Value = serde_json::from_slice(&std::fs::read(&d).unwrap()).unwrap();
        let env = v["env"].as_object().unwrap();
        let scratch = v["scratch"].as_str().unwrap();
        assert!(env.get("NAOFARM_TEST_WORKER_SECRET").is_none(), "{v}");
        assert!(env.get("CREDENTIALS_DIRECTORY").is_none(), "{v}");
        assert_eq!(env["PASSED"], "yes");
        let (h, t) = (
            env["HOME"].as_str().unwrap(),
            env["TMPDIR"].as_str().unwrap(),
        );
        assert_ne!(h, home);
        assert!(h.starts_with(scratch) && t.starts_with(scratch), "{v}");
        assert!(
            scratch.starts_with(&farm.tmp().display().to_string()),
            "{v}"
        );
        let mut names: Vec<&str> = env.keys().map(String::as_str).collect();
        // NAOFARM_JOB marks a job's processes where the worker is their
        // child subreaper (a host with neither a cgroup nor a PID namespace).
        names.retain(|n| !n.starts_with("NAOFARM_TEST_") && !["PASSED", "NAOFARM_JOB"].contains(n));
        names.sort_unstable();
        // What the program's own launchers add aside: the shell's PWD and
        // SHLVL, Python's LC_CTYPE, a pyenv shim's PYENV_*.
        names.retain(|n| {
            !["PWD", "SHLVL", "_", "LC_CTYPE"].contains(n)
                && !n.starts_with("PYENV_")
                && !n.starts_with("_PYENV_")
        });
        assert_eq!(names, ["HOME", "LANG", "PATH", "TMPDIR"], "{v}");
    }
    farm.assert_clean();
}

#[test]
fn concurrent_trials_on_one_host_hold_distinct_slots() {
    let farm = Farm::new("slots");
    finish(&mut farm.run(&job_program(), "slots", 3, 2, 6), 0);
    let most = farm
        .lines("overlap")
        .iter()
        .map(|l| l.split_whitespace().count())
        .max()
        .unwrap();
    assert_eq!(most, 3, "three trials at once: {:?}", farm.lines("overlap"));
    farm.assert_clean();
}

#[test]
fn a_program_rewritten_mid_run_is_a_new_build_the_run_does_not_mix() {
    let farm = Farm::new("rewritten");
    let program = farm.dir.join("job");
    let text = std::fs::read_to_string(job_program()).unwrap();
    std::fs::write(&program, &text).unwrap();
    std::fs::set_permissions(
        &program,
        std::os::unix::fs::PermissionsExt::from_mode(0o755),
    )
    .unwrap();
    let mut cmd = farm.run(&program, "slow", 1, 6, 2);
    cmd.args(["--program-env", "NAOFARM_TEST_SLEEP=0.3"])
        .stdout(Stdio::null())
        .stderr(Stdio::piped());
    let child = cmd.spawn().unwrap();
    wait_for("a trial of the first build", WITHIN, || {
        (!farm.lines("count").is_empty()).then_some(())
    });
    std::fs::write(&program, text.replace("BUILD = \"1\"", "BUILD = \"2\"")).unwrap();
    let mut child = child;
    let status = wait_for_quietly(&mut child, Duration::from_secs(300)).expect("the run ended");
    let mut err = String::new();
    std::io::Read::read_to_string(&mut child.stderr.take().unwrap(), &mut err).unwrap();
    assert_eq!(status.code(), Some(1), "{err}");
    assert!(
        err.contains("changed on disk") || err.contains("fingerprint"),
        "{err}"
    );
    let builds: Vec<String> = farm.lines("count");
    assert!(
        builds.iter().all(|l| l.ends_with(" 1")),
        "the second build ran a trial: {builds:?}"
    );
    farm.assert_clean();
}

/// A program that serves (tests/programs/served) is started once for its
/// run in its slot and kept between the trials; a trial it botches ends
/// it and runs again in a fresh one; nothing of it outlives the run. With a
/// CPU-time limit, which bounds one trial, each trial is a process of its
/// own.
#[test]
fn a_program_that_serves_is_kept_between_trials_and_ends_with_its_run() {
    let program = root().join("tests/programs/served");
    let farm = Farm::new("served");
    let (stdout, err) = finish(&mut farm.run(&program, "served", 1, 3, 4), 0);
    assert_eq!(util::events(stdout.as_bytes()).decided.len(), 3, "{err}");
    assert_eq!(util::journaled_once(&farm.out()).len(), 3 * 4, "{err}");
    let starts = farm.lines("starts");
    assert!(starts.iter().all(|s| s.starts_with("serve ")), "{starts:?}");
    let trials: Vec<Vec<String>> = farm
        .lines("trials")
        .iter()
        .map(|l| l.split_whitespace().map(str::to_string).collect())
        .collect();
    assert_eq!(trials.len(), 3 * 4 + 1, "{trials:?}");
    // One process per slot the run's trials took (other tests' trials hold
    // slots too), and one more after the junk; each answers in one slot.
    let mut slot_of = std::collections::BTreeMap::new();
    for t in &trials {
        let slot = slot_of.entry(t[1].clone()).or_insert_with(|| t[2].clone());
        assert_eq!(
            *slot, t[2],
            "process {} answered in two slots: {trials:?}",
            t[1]
        );
    }
    let slots: std::collections::BTreeSet<&String> = trials.iter().map(|t| &t[2]).collect();
    assert_eq!(starts.len(), slot_of.len(), "{starts:?} {trials:?}");
    assert!(
        slot_of.len() <= slots.len() + 1 && slot_of.len() < trials.len(),
        "kept per slot: {starts:?} {trials:?}"
    );
    // The junked trial, asked again of a fresh process; the one that
    // printed junk answered nothing more.
    let junked: Vec<usize> = (0..trials.len())
        .filter(|&i| trials[i][0] == "1-0")
        .collect();
    assert_eq!(junked.len(), 2, "{trials:?}");
    let junker = &trials[junked[0]][1];
    assert_ne!(junker, &trials[junked[1]][1], "{trials:?}");
    assert!(
        trials[junked[0] + 1..].iter().all(|t| &t[1] != junker),
        "the process that printed junk answered again: {trials:?}"
    );
    assert!(err.contains("not a measurement"), "{err}");
    farm.assert_clean();

    let farm = Farm::new("served-cpu");
    let mut cmd = farm.run(&program, "served", 1, 2, 2);
    cmd.args(["--program-cpu-s", "100"]);
    finish(&mut cmd, 0);
    let starts = farm.lines("starts");
    assert_eq!(starts.len(), 2 * 2 + 1, "{starts:?}");
    assert!(starts.iter().all(|s| s.starts_with("once ")), "{starts:?}");
    farm.assert_clean();
}

#[test]
fn ctrl_c_on_run_stops_its_programs_and_their_children() {
    let farm = Farm::new("sigint");
    let run = farm.run(&job_program(), "trap", 1, 2, 2);
    interrupt_and_check(&farm, run);
}

#[test]
fn ctrl_c_on_report_stops_its_programs_and_their_children() {
    let farm = Farm::new("report-sigint");
    finish(
        farm.run(&job_program(), "slow", 1, 2, 2)
            .args(["--program-env", "NAOFARM_TEST_SLEEP=0"]),
        0,
    );
    let mut report = naofarm();
    report
        .args(["report", "--trials", "4"])
        .arg(farm.out())
        .arg("--program")
        .arg(format!("job={}", job_program().display()))
        .args(["--program-env", "NAOFARM_TEST_JOB=trap"])
        .arg("--program-env")
        .arg(format!("NAOFARM_TEST_DIR={}", farm.records().display()))
        .args([
            "--program-env",
            &format!("NAOFARM_TEST_MARKER={}", farm.marker),
        ])
        .env("TMPDIR", farm.tmp());
    interrupt_and_check(&farm, report);
}

/// Starts `cmd` (its programs trap SIGTERM), sends it SIGINT once a program
/// runs: it exits 1, each program was asked to stop (not killed), and
/// nothing of them is left.
fn interrupt_and_check(farm: &Farm, mut cmd: Command) {
    let mut child = cmd
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    wait_for("a program to start", WITHIN, || {
        (!farm.lines("started").is_empty()).then_some(())
    });
    let sent = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(sent.success());
    let status = wait_for_quietly(&mut child, WITHIN).expect("it stopped");
    assert_eq!(status.code(), Some(1));
    // Asked (SIGTERM, which they trap), not killed: every program that
    // started was asked (one may be asked before it says it started).
    let asked = farm.lines("terminated");
    let started = farm.lines("started");
    assert!(
        started.iter().all(|k| asked.contains(k)),
        "started {started:?}, asked {asked:?}"
    );
    farm.assert_clean();
}
