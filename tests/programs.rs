//! The trial-program contract (docs/programs.md), against real processes:
//! a good program, one that hangs (and leaves a child), one that crashes,
//! one that prints junk, a NaN or an implausible distance, and a trial of a
//! program the worker did not register; and the experiment side: a program
//! is named, never a path or a command.
#![allow(clippy::unwrap_used)]

mod util;

use std::time::Duration;

use protocol::{wire::WireMessage, Physics, TrialModel, TrialRequest};
use util::{naofarm, root, scratch};
use worker::program::{run, Program, Programs, Settings};

fn program(name: &str) -> Program {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    rt.block_on(Program::register(
        name,
        &root().join("tests/programs").join(name),
    ))
    .unwrap()
}

fn request(program: &str, params: &[(&str, f64)]) -> TrialRequest {
    TrialRequest {
        run: "r".into(),
        iteration: 4,
        trial: 2,
        seed: 11,
        model: TrialModel::Program,
        program: Some(program.into()),
        robot_type: 0,
        duration_s: 10.0,
        params: params.iter().map(|(k, v)| ((*k).to_string(), *v)).collect(),
        dispatch: 0,
        physics: Physics::default(),
    }
}

/// Runs one trial of tests/programs/NAME in a fresh scratch directory
/// (passing it NAOFARM_TEST_PID_FILE, as a worker's owner would with
/// `--program-env`).
fn trial(name: &str, timeout: Duration) -> Result<protocol::measurement::Measurement, String> {
    let dir = scratch(&format!("program-{name}"));
    let p = program(name);
    let req = request(name, &[("a", 0.3), ("b", -0.1)]);
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    let settings = Settings {
        timeout,
        env: Settings::parse_env(&["NAOFARM_TEST_PID_FILE".into()]).unwrap(),
        ..Settings::default()
    };
    let stop = tokio_util::sync::CancellationToken::new();
    let pool = worker::served::Pool::default();
    rt.block_on(run(
        &p,
        &req,
        1,
        &dir.join("slot-1"),
        &settings,
        &stop,
        &pool,
    ))
}

#[test]
fn a_good_program_answers_with_its_measurement_from_its_seed() {
    let a = trial("toy", Duration::from_secs(30)).unwrap();
    let b = trial("toy", Duration::from_secs(30)).unwrap();
    assert_eq!(a, b, "the same trial (seed) gives the same answer");
    assert_eq!(a.sim_time_s, 10.0);
    assert!(a.x_m > 2.0 && a.x_m < 4.0, "near the toy's best: {a:?}");
}

#[test]
fn a_program_may_log_as_much_as_it_likes_before_its_measurement() {
    let m = trial("chatty", Duration::from_secs(30)).unwrap();
    assert_eq!((m.x_m, m.fell), (1.25, false));
}

#[test]
fn a_hanging_program_is_killed_with_every_process_it_started() {
    let dir = scratch("program-hang-pid");
    let pid_file = dir.join("child.pid");
    std::env::set_var("NAOFARM_TEST_PID_FILE", &pid_file);
    let e = trial("hang", Duration::from_millis(1500)).unwrap_err();
    assert!(
        e.contains("program `hang` did not answer within 1.5 s")
            && e.contains("hang: waiting forever"),
        "{e}"
    );
    let pid = std::fs::read_to_string(&pid_file).unwrap();
    let proc = std::path::Path::new("/proc").join(pid.trim());
    // Killed by SIGKILL to its group before `run` returned; reaped by init.
    let gone = (0..500).any(|_| {
        let zombie_or_gone = std::fs::read_to_string(proc.join("stat"))
            .map_or(true, |s| s.split_whitespace().nth(2) == Some("Z"));
        if !zombie_or_gone {
            std::thread::sleep(Duration::from_millis(10));
        }
        zombie_or_gone
    });
    assert!(gone, "the program's child {} outlived it", pid.trim());
}

#[test]
fn a_crash_junk_a_nan_and_an_implausible_distance_are_failed_trials_with_why() {
    let t = Duration::from_secs(30);
    let e = trial("crash", t).unwrap_err();
    assert!(
        e.contains("program `crash` exited with status 3")
            && e.contains("crash: the simulator lost its licence server | crash: giving up"),
        "{e}"
    );
    let e = trial("junk", t).unwrap_err();
    assert!(
        e.contains("printed `the robot walked quite far`, not a measurement"),
        "{e}"
    );
    let e = trial("nan", t).unwrap_err();
    assert!(e.contains("not a measurement"), "{e}");
    let e = trial("far", t).unwrap_err();
    assert!(
        e.contains("implausible") && e.contains("beyond 100 m"),
        "{e}"
    );
}

#[test]
fn a_worker_refuses_a_trial_of_a_program_it_did_not_register() {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    let toy = root().join("tests/programs/toy");
    let programs = rt
        .block_on(Programs::register(
            &[format!("toy={}", toy.display())],
            Settings::default(),
        ))
        .unwrap();
    let cfg = worker::service::WorkerConfig {
        programs,
        ..worker::service::WorkerConfig::default()
    };
    assert_eq!(cfg.beyond_limits(&request("toy", &[("a", 0.1)])), None);
    assert_eq!(
        cfg.beyond_limits(&request("league", &[("a", 0.1)]))
            .unwrap(),
        "this worker has not registered a program named `league`"
    );
}

#[test]
fn a_program_is_named_never_given_as_a_path_or_a_command() {
    let dir = scratch("program-named");
    let text = std::fs::read_to_string(root().join("experiments/test/program.toml")).unwrap();
    for (program, why) in [
        ("/bin/sh", "contains `/`"),
        ("sh -c reboot", "contains ` `"),
        ("../toy", "contains `.`"),
        ("", "must be 1 to 64 bytes"),
    ] {
        let p = dir.join("exp.toml");
        std::fs::write(
            &p,
            text.replace("program = \"toy\"", &format!("program = \"{program}\"")),
        )
        .unwrap();
        let err = util::fails(naofarm().arg("check").arg(&p), 2);
        assert!(
            err.contains("field `program`") && err.contains(why),
            "{err}"
        );
    }
    // Nor on the wire: a forged trial naming a path does not decode.
    let mut req = request("toy", &[("a", 0.1)]);
    req.program = Some("/usr/bin/env".into());
    let bytes = req.encode().unwrap();
    let e = TrialRequest::decode(&bytes).unwrap_err().to_string();
    assert!(e.contains("program") && e.contains("contains `/`"), "{e}");
    // And a worker's owner registers names of the same kind only.
    let e = util::fails(
        naofarm().args([
            "worker",
            "--program",
            "a/b=/bin/true",
            "--connect",
            "tcp/127.0.0.1:9",
        ]),
        2,
    );
    assert!(e.contains("never given as a path"), "{e}");
}

#[test]
fn run_and_report_tune_a_program_on_one_machine() {
    let dir = scratch("program-run");
    let exp = root().join("experiments/test/program.toml");
    let toy = format!("toy={}", root().join("tests/programs/toy").display());
    let out = dir.join("run");
    // Without the program the local workers could never serve the run.
    let err = util::fails(naofarm().arg("run").arg(&exp).arg("--out").arg(&out), 2);
    assert!(err.contains("--program toy=PATH"), "{err}");
    assert!(!out.exists(), "nothing written");
    let ran = util::succeed(
        naofarm()
            .args(["run", "--json", "--workers", "2", "--program", &toy])
            .arg(&exp)
            .arg("--out")
            .arg(&out),
    );
    let events = util::events(&ran.stdout);
    assert_eq!(events.decided.len(), 6);
    // Table IV runs its trials through the program, as a worker does.
    let err = util::fails(naofarm().args(["report", "--trials", "4"]).arg(&out), 2);
    assert!(err.contains("--program toy=PATH"), "{err}");
    util::succeed(
        naofarm()
            .args(["report", "--trials", "4", "--program", &toy])
            .arg(&out),
    );
    let table: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report/table4.json")).unwrap())
            .unwrap();
    let text = table.to_string();
    assert!(
        text.contains("Expert") && text.contains("Optim.1"),
        "{text}"
    );
}
