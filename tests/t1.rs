//! The league's 2026 robot on the farm: programs/t1/setup.sh installs the
//! league's MuJoCo server (rcssservermj, pinned) and the example T1 policy
//! (from the third-party sources; cached per machine), naofarm's own client
//! runs the policy in numpy, the stock T1 walks, and a farm run of the `t1`
//! program on the real server is journaled, killed mid-run and resumed.
#![allow(clippy::unwrap_used)]

mod util;

use std::{
    io::Write,
    path::{Path, PathBuf},
    process::{Command, Stdio},
    time::Duration,
};

use util::{root, scratch, succeed};

/// The T1 set-up's trial program (set up if the cache lacks it, from
/// `$NAOFARM_T1_SOURCE` or ../shared/third-party) and the set-up's
/// directory (the program is in its `bin`).
fn t1_program() -> (PathBuf, PathBuf) {
    let program = util::set_up_program("t1/setup.sh", "NAOFARM_T1_SOURCE");
    let prefix = program.parent().unwrap().parent().unwrap().to_path_buf();
    (program, prefix)
}

/// A trial as a worker gives it, in `dir`.
fn input(dir: &Path, seed: u64, duration_s: f64, params: &serde_json::Value) -> serde_json::Value {
    serde_json::json!({
        "run": "r", "iteration": 0, "trial": 0, "seed": seed, "duration_s": duration_s,
        "robot_type": 0, "params": params, "slot": 0, "scratch": dir.to_path_buf(),
    })
}

/// Trials answered one after another by one process (`t1-trial --serve`,
/// as a worker keeps it): their measurements.
fn served(program: &Path, trials: &[(u64, serde_json::Value)]) -> Vec<serde_json::Value> {
    let dir = scratch("t1-served");
    let lines: String = trials
        .iter()
        .map(|(seed, params)| format!("{}\n", input(&dir, *seed, 10.0, params)))
        .collect();
    let out = fed(Command::new(program).arg("--serve"), &dir, &lines);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

/// One trial of the program, as a worker gives it: how it ended.
fn answer(
    program: &Path,
    seed: u64,
    duration_s: f64,
    params: &serde_json::Value,
) -> std::process::Output {
    let dir = scratch("t1-trial");
    let input = input(&dir, seed, duration_s, params);
    fed(&mut Command::new(program), &dir, &input.to_string())
}

/// `cmd` run in `dir` with `stdin` on its standard input, to its end.
fn fed(cmd: &mut Command, dir: &Path, stdin: &str) -> std::process::Output {
    let mut child = cmd
        .current_dir(dir)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    child
        .stdin
        .take()
        .unwrap()
        .write_all(stdin.as_bytes())
        .unwrap();
    child.wait_with_output().unwrap()
}

/// One trial that must succeed: its measurement.
fn trial(
    program: &Path,
    seed: u64,
    duration_s: f64,
    params: &serde_json::Value,
) -> serde_json::Value {
    let out = answer(program, seed, duration_s, params);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    let stdout = String::from_utf8_lossy(&out.stdout);
    serde_json::from_str(stdout.lines().last().unwrap()).unwrap()
}

#[test]
fn the_t1_policy_in_numpy_is_its_equations() {
    let (_, p) = t1_program();
    let out = succeed(
        Command::new(p.join("venv/bin/python"))
            .arg(root().join("tests/programs/t1_policy_check.py"))
            .arg(&p),
    );
    let said = String::from_utf8_lossy(&out.stdout);
    assert!(said.contains("largest difference"), "{said}");
}

#[test]
fn the_stock_t1_walks_on_the_leagues_2026_server() {
    let (program, _) = t1_program();
    let m = trial(&program, 1, 10.0, &serde_json::json!({}));
    assert_eq!(m["fell"], false, "{m}");
    assert_eq!(m["sim_time_s"], 10.0, "{m}");
    let x = m["x_m"].as_f64().unwrap();
    assert!(x >= 7.0, "the stock T1 walked {x} m in 10 s: {m}");
    // The trial's noise comes from its seed: the same seed, the same walk
    // to the bit; another seed, another walk.
    assert_eq!(trial(&program, 1, 10.0, &serde_json::json!({})), m);
    let other = trial(&program, 2, 10.0, &serde_json::json!({}));
    assert_ne!(other["x_m"], m["x_m"], "{other} {m}");
    // The body is the trial's: a longer thigh walks another walk.
    let longer = trial(&program, 1, 10.0, &serde_json::json!({"t1_thigh": 1.2}));
    assert_eq!(longer["fell"], false, "{longer}");
    assert_ne!(longer["x_m"], m["x_m"], "{longer} {m}");
    // One process kept between trials, as a worker keeps it, answers each
    // as a fresh one does, to the bit, whatever it ran before.
    let stock = serde_json::json!({});
    let warm = served(
        &program,
        &[
            (1, serde_json::json!({"t1_thigh": 1.2})),
            (1, stock.clone()),
            (2, stock.clone()),
            (1, stock),
        ],
    );
    assert_eq!(warm, [longer, m.clone(), other, m]);
    // A parameter the program does not know is refused by name.
    let out = answer(
        &program,
        1,
        1.0,
        &serde_json::json!({"ThighRelHip2_Z": -0.04}),
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("ThighRelHip2_Z"), "{err}");
}

/// experiments/t1.toml cut to a test's size: 3 iterations of 4 walks of 4 s.
fn small_t1(dir: &Path) -> PathBuf {
    util::small_experiment("t1.toml", "iterations = 300", dir)
}

fn run(exp: &Path, out: &Path, program: &Path) -> Command {
    util::program_run(exp, out, "t1", program)
}

/// The processes working in a directory under `dir` (a trial's program and
/// its server work in the trial's scratch directory), by command line.
fn running(dir: &str) -> Vec<String> {
    std::fs::read_dir("/proc")
        .unwrap()
        .flatten()
        .filter_map(|e| {
            let cwd = std::fs::read_link(e.path().join("cwd")).ok()?;
            let cmd = std::fs::read(e.path().join("cmdline")).ok()?;
            cwd.starts_with(dir)
                .then(|| String::from_utf8_lossy(&cmd).replace('\0', " "))
        })
        .collect()
}

#[test]
fn a_t1_run_on_the_real_server_is_journaled_killed_and_resumed() {
    let (program, _) = t1_program();
    let dir = scratch("t1-run");
    let exp = small_t1(&dir);
    let out = dir.join("run");
    let tmp = dir.join("tmp");
    std::fs::create_dir_all(&tmp).unwrap();
    // The run's programs and servers work in its workers' scratch, under
    // this TMPDIR.
    let needle = tmp.display().to_string();

    let (mut first, stats) =
        util::until_first_decision(run(&exp, &out, &program).env("TMPDIR", &tmp));
    // Killed while its trials run (the pipeline keeps two iterations going):
    // a kept program with a trial's server forked from it.
    let in_flight = util::wait_for("a trial's server", Duration::from_secs(60), || {
        let r = running(&needle);
        (r.iter().filter(|c| c.contains("t1-trial --serve")).count() >= 2).then_some(r)
    });
    first.kill().unwrap();
    first.wait().unwrap();
    // The expert stood in every walk of the first iteration.
    assert!(
        stats["s"] == 1.0 && stats["mx"].as_f64().unwrap() > 2.0,
        "{stats}"
    );
    util::wait_for(
        &format!("the killed run's servers and programs {in_flight:?} to end"),
        Duration::from_secs(20),
        || running(&needle).is_empty().then_some(()),
    );

    succeed(run(&exp, &out, &program).env("TMPDIR", &tmp));
    let trials = util::journaled_once(&out);
    assert_eq!(trials.len(), 3 * 4, "every trial of the 3 iterations once");
    assert!(running(&needle).is_empty(), "{:?}", running(&needle));
}
