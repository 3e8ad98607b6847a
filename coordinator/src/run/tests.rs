use super::*;
use rand::{Rng, SeedableRng};

const EXP: &str = include_str!("../../../experiments/test/two-parameters.toml");

fn exp() -> Experiment {
    Experiment::from_toml(EXP).unwrap()
}

fn synthetic(req: &TrialRequest) -> Measurement {
    worker::run_trial(req).unwrap()
}

fn tmp(name: &str) -> crate::test_dir::TestDir {
    crate::test_dir::test_dir(&format!("run-{name}"))
}

fn bits(h: &[DecidedIteration]) -> Vec<u64> {
    crate::evolve::history_bits(h)
}

fn full_run(name: &str, shuffle_seed: Option<u64>) -> Vec<DecidedIteration> {
    let dir = tmp(name);
    let (mut run, effects) = Run::open(&dir, exp(), EXP, None).unwrap();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(shuffle_seed.unwrap_or(0));
    let mut order = |q: &mut Vec<TrialRequest>| {
        if shuffle_seed.is_some() {
            let n = q.len();
            q.swap(0, rng.random_range(0..n));
        }
    };
    drive_local(&mut run, effects, &synthetic, &mut order).unwrap();
    assert!(run.evolve().finished());
    run.evolve().history().to_vec()
}

#[test]
fn a_refusal_names_the_first_three_files_and_says_when_there_are_more() {
    assert_eq!(first_names::<&str>(&[]), "");
    assert_eq!(first_names(&["a", "b", "c"]), "a, b, c");
    assert_eq!(first_names(&["a", "b", "c", "d"]), "a, b, c, …");
}

#[test]
fn a_run_completes_and_the_order_of_outcomes_does_not_matter() {
    let a = full_run("order-a", None);
    let b = full_run("order-b", Some(7));
    assert_eq!(a.len(), 40);
    assert_eq!(bits(&a), bits(&b));
    assert!(
        a[0].params == vec![-0.04, 0.08],
        "the expert set is iteration 0"
    );
    let accepts = a
        .iter()
        .filter(|d| d.decision == protocol::Decision::Accept)
        .count();
    assert!(accepts >= 2, "{accepts}");
}

#[test]
fn the_status_refits_optim2_every_ten_decisions_and_at_the_end() {
    use crate::decider::{Snapshot, OPTIM2_EVERY};
    let dir = tmp("optim2-cadence");
    let (mut run, effects) = Run::open(&dir, exp(), EXP, None).unwrap();
    let mut queue: std::collections::VecDeque<TrialRequest> = Default::default();
    let enqueue = |run: &Run, effects: &[Effect], q: &mut std::collections::VecDeque<_>| {
        for e in effects {
            if let Effect::Dispatch(o, ks) = e {
                q.extend(ks.iter().map(|k| run.request(o, *k, 0).unwrap()));
            }
        }
    };
    enqueue(&run, &effects, &mut queue);
    let mut last: Option<Snapshot> = None;
    let mut refits = Vec::new();
    while let Some(req) = queue.pop_front() {
        let (_, fx) = run
            .on_outcome(req.iteration, req.trial, req.seed, synthetic(&req), "w")
            .unwrap();
        enqueue(&run, &fx, &mut queue);
        if !fx.iter().any(|e| matches!(e, Effect::Decided(_))) {
            continue;
        }
        let s = Snapshot::after(&run, last.as_ref());
        let fresh = Snapshot::of(&run);
        assert!(s.decided - s.optim2_decided < OPTIM2_EVERY, "{s:?}");
        if s.optim2_decided == s.decided {
            refits.push(s.decided);
            assert_eq!(s.optim2, fresh.optim2);
        } else {
            let l = last.as_ref().unwrap();
            assert_eq!((&s.optim2, s.optim2_decided), (&l.optim2, l.optim2_decided));
        }
        assert_eq!(
            Snapshot {
                optim2: fresh.optim2.clone(),
                optim2_decided: fresh.optim2_decided,
                ..s.clone()
            },
            fresh,
            "all but CLOP's mean is current"
        );
        last = Some(s);
    }
    assert!(run.evolve().finished());
    assert_eq!(
        refits,
        [1, 11, 21, 31, 40],
        "and the finished run's is current"
    );
}

#[test]
fn duplicates_count_once_and_bad_outcomes_change_nothing() {
    let dir = tmp("dup");
    let (mut run, effects) = Run::open(&dir, exp(), EXP, None).unwrap();
    let Effect::Dispatch(o, _) = &effects[0] else {
        panic!()
    };
    let req = run.request(o, 0, 0).unwrap();
    let r = synthetic(&req);
    let (c, _) = run.on_outcome(0, 0, req.seed, r, "w").unwrap();
    assert_eq!(c, Counted::New);
    let (c, _) = run.on_outcome(0, 0, req.seed, r, "w").unwrap();
    assert_eq!(c, Counted::Duplicate);
    let mut nan = r;
    nan.x_m = f64::NAN;
    assert!(matches!(
        run.on_outcome(0, 1, run.request(o, 1, 0).unwrap().seed, nan, "w"),
        Err(RunError::Refused(_))
    ));
    assert!(matches!(
        run.on_outcome(99, 0, 0, r, "w"),
        Err(RunError::Refused(OutcomeError::UnknownIteration(99)))
    ));
    assert!(matches!(
        run.on_outcome(0, 77, 0, r, "w"),
        Err(RunError::Refused(OutcomeError::UnknownTrial { .. }))
    ));
    assert!(matches!(
        run.on_outcome(0, 1, 12345, r, "w"),
        Err(RunError::Refused(OutcomeError::WrongSeed { .. }))
    ));
    drop(run);
    let outcomes = Journal::read(&dir)
        .unwrap()
        .records()
        .iter()
        .filter(|r| matches!(r, Record::Outcome { .. }))
        .count();
    assert_eq!(outcomes, 1, "only the one good outcome reached the journal");
}

#[test]
fn resume_after_a_crash_gives_the_same_history_bit_for_bit() {
    let reference = full_run("resume-ref", None);
    for stop_after in [1usize, 17, 60, 150] {
        let dir = tmp(&format!("resume-{stop_after}"));
        let (mut run, effects) = Run::open(&dir, exp(), EXP, None).unwrap();
        // Run part of it, then "crash" (drop everything in memory).
        let mut queue: Vec<TrialRequest> = Vec::new();
        let enqueue = |run: &Run, effects: Vec<Effect>, q: &mut Vec<TrialRequest>| {
            for e in effects {
                if let Effect::Dispatch(o, ks) = e {
                    q.extend(ks.into_iter().map(|k| run.request(&o, k, 0).unwrap()));
                }
            }
        };
        enqueue(&run, effects, &mut queue);
        for _ in 0..stop_after {
            let req = queue.remove(0);
            let (_, effects) = run
                .on_outcome(req.iteration, req.trial, req.seed, synthetic(&req), "w")
                .unwrap();
            enqueue(&run, effects, &mut queue);
        }
        drop(run);
        let (mut run, effects) = Run::open(&dir, exp(), EXP, None).unwrap();
        assert!(run.resumed());
        drive_local(&mut run, effects, &synthetic, &mut |_| {}).unwrap();
        let decided: Vec<DecidedIteration> = Journal::read(&dir)
            .unwrap()
            .records()
            .into_iter()
            .filter_map(|r| {
                if let Record::Decided(d) = r {
                    Some(d)
                } else {
                    None
                }
            })
            .collect();
        assert_eq!(
            bits(&decided),
            bits(&reference),
            "stopped after {stop_after}"
        );
    }
}

/// Experiment 2's file with the synthetic model and `iterations`, `depth`.
fn physical_technical(iterations: u64, depth: u32) -> (Experiment, String) {
    let text = include_str!("../../../experiments/physical-technical.toml")
        .replace("model = \"nao\"", "model = \"synthetic\"")
        .replace("iterations = 500", &format!("iterations = {iterations}"))
        .replace("pipeline_depth = 4", &format!("pipeline_depth = {depth}"));
    (Experiment::from_toml(&text).unwrap(), text)
}

fn run_to_end(name: &str, exp: Experiment, text: &str) -> Run {
    let dir = tmp(name);
    let (mut run, effects) = Run::open(&dir, exp, text, None).unwrap();
    drive_local(&mut run, effects, &synthetic, &mut |_| {}).unwrap();
    assert!(run.evolve().finished());
    run
}

#[test]
fn two_hundred_synthetic_iterations_converge() {
    let (exp, text) = physical_technical(200, 4);
    let run = run_to_end("converge", exp, &text);
    let ev = run.evolve();
    let h = ev.history();
    assert_eq!(h.len(), 200);
    let kept = |part: &[DecidedIteration]| {
        part.iter()
            .filter(|d| d.decision != protocol::Decision::Reject)
            .count()
    };
    let (first, last) = (kept(&h[..50]), kept(&h[150..]));
    assert!(
        last > first,
        "ACCEPT+EQUIVALENT share must grow: {first}/50 in the first quarter, {last}/50 in the last"
    );
    // The synthetic optimum, read from the model itself, in the experiment's order.
    let optimum: Vec<f64> = ev
        .experiment()
        .parameter
        .iter()
        .map(|p| {
            let id = protocol::params::find(&p.name)
                .expect("a known parameter")
                .param;
            worker::synthetic::SHAPE
                .iter()
                .find(|(q, _, _)| *q == id)
                .map_or(worker::synthetic::STEP_OPTIMUM, |(_, o, _)| *o)
        })
        .collect();
    let ranges = [0.05, 0.35, 0.029, 0.045, 0.13];
    let off = |p: &[f64]| -> f64 {
        p.iter()
            .zip(optimum.iter().zip(ranges))
            .map(|(v, (o, r))| ((v - o) / r).powi(2))
            .sum::<f64>()
            .sqrt()
    };
    let expert = off(&h[0].params);
    let nu_p = &ev.best().expect("a best exists").params;
    let optim1 = off(nu_p);
    let optim2 = off(&ev.optim2());
    eprintln!(
        "kept {first}/50 then {last}/50; distance expert {expert:.3}, Optim.1 {optim1:.3}, Optim.2 {optim2:.3}"
    );
    assert!(
        optim1 < 0.6 * expert && optim2 < 0.6 * expert,
        "distance to the optimum in range units: expert {expert:.3}, Optim.1 {optim1:.3}, Optim.2 {optim2:.3}"
    );
}

#[test]
fn pipeline_depths_one_and_four_are_each_reproducible() {
    for depth in [1, 4] {
        let (exp, text) = physical_technical(30, depth);
        let a = run_to_end(&format!("depth{depth}-a"), exp.clone(), &text);
        let b = run_to_end(&format!("depth{depth}-b"), exp, &text);
        assert_eq!(a.evolve().history().len(), 30);
        assert_eq!(
            bits(a.evolve().history()),
            bits(b.evolve().history()),
            "D = {depth}"
        );
    }
}

#[test]
fn a_journal_of_another_experiment_is_refused() {
    let dir = tmp("other");
    let (run, _) = Run::open(&dir, exp(), EXP, None).unwrap();
    drop(run);
    let other = EXP.replace("seed = 42", "seed = 43");
    let e = Run::open(&dir, Experiment::from_toml(&other).unwrap(), &other, None).unwrap_err();
    assert!(e.to_string().contains("another experiment"), "{e}");
    let finer = format!("{EXP}\n[physics]\nsubsteps = 8\n");
    let e = Run::open(&dir, Experiment::from_toml(&finer).unwrap(), &finer, None).unwrap_err();
    assert!(e.to_string().contains("physics"), "{e}");
}

/// A journal header written before `[physics]` existed resumes at the
/// default physics; the run's trial requests carry the experiment's.
#[test]
fn physics_reach_the_requests_and_old_headers_read_the_default() {
    let dir = tmp("physics");
    let (run, _) = Run::open(&dir, exp(), EXP, None).unwrap();
    drop(run);
    let records = Journal::read(&dir).unwrap().records();
    let Some(crate::journal::Record::Header {
        experiment_json, ..
    }) = records.first()
    else {
        panic!("no header");
    };
    let mut v: serde_json::Value = serde_json::from_str(experiment_json).unwrap();
    assert!(v.as_object_mut().unwrap().remove("physics").is_some());
    let old: Experiment = serde_json::from_value(v).unwrap();
    assert_eq!(old, exp());
    let finer = format!("{EXP}\n[physics]\nsubsteps = 8\npgs_iterations = 6\n");
    let fe = Experiment::from_toml(&finer).unwrap();
    let (run, effects) = Run::open(&tmp("physics-b"), fe, &finer, None).unwrap();
    let req = effects
        .iter()
        .find_map(|e| match e {
            Effect::Dispatch(o, _) => Some(run.request(o, 0, 0).unwrap()),
            _ => None,
        })
        .unwrap();
    assert_eq!(req.physics.substeps, 8);
    assert_eq!(req.physics.pgs_iterations, 6);
    assert_eq!(req.physics.solver_iterations, 1);
}

#[test]
fn starting_from_an_earlier_history_uses_it() {
    let dir = tmp("from-a");
    let (mut run, effects) = Run::open(&dir, exp(), EXP, None).unwrap();
    drive_local(&mut run, effects, &synthetic, &mut |_| {}).unwrap();
    let text = EXP.replace("start = \"expert\"", "start = \"scratch\"");
    let imported = load_history(&dir, &Experiment::from_toml(&text).unwrap())
        .unwrap()
        .imported;
    assert_eq!(imported.history.len(), 40);
    assert!(imported.best.is_some());
    let dir2 = tmp("from-b");
    let (mut run2, effects) = Run::open(
        &dir2,
        Experiment::from_toml(&text).unwrap(),
        &text,
        Some(imported.clone()),
    )
    .unwrap();
    assert_eq!(run2.evolve().imported_len(), 40);
    assert_eq!(
        run2.evolve().best(),
        imported.best.as_ref(),
        "ν′ carries over"
    );
    drive_local(&mut run2, effects, &synthetic, &mut |_| {}).unwrap();
    drop(run2);
    let again = load_history(&dir2, &exp()).unwrap();
    assert_eq!(again.imported.history.len(), 80, "H accumulates");
}
