//! The evolving loop on its own: the pipeline rule, refusals, order independence.

use super::*;

const EXP: &str = include_str!("../../../experiments/test/two-parameters.toml");

fn exp() -> Experiment {
    let text = EXP
        .replace("seed = 42", "seed = 3")
        .replace("iterations = 40", "iterations = 12")
        .replace("trials_per_iteration = 6", "trials_per_iteration = 3")
        .replace("pipeline_depth = 3", "pipeline_depth = 2");
    Experiment::from_toml(&text).expect("the test experiment parses")
}

/// A measurement that depends on the parameter and the seed only.
fn measure(o: &OpenedIteration, k: usize) -> Measurement {
    let x = 1.0 + 10.0 * (o.params[0] + 0.08) + (o.seeds[k] % 97) as f64 / 970.0;
    Measurement {
        fell: false,
        x_m: x,
        y_m: 0.01,
        fall_time_s: None,
        sim_time_s: 10.0,
    }
}

fn opened(actions: &[Action]) -> Vec<OpenedIteration> {
    actions
        .iter()
        .filter_map(|a| match a {
            Action::Open(o) => Some(o.clone()),
            _ => None,
        })
        .collect()
}

#[test]
fn iteration_i_opens_exactly_when_i_minus_depth_is_decided() {
    let (mut ev, first) = Evolve::start(exp(), &Imported::default());
    let mut open = opened(&first);
    assert_eq!(open.iter().map(|o| o.iteration).collect::<Vec<_>>(), [0, 1]);
    assert!(open[0].expert && !open[1].expert);
    let mut all = open.clone();
    while let Some(o) = open.first().cloned() {
        open.remove(0);
        let mut actions = Vec::new();
        for k in 0..3 {
            actions.extend(
                ev.apply(o.iteration, k as u32, o.seeds[k], measure(&o, k))
                    .unwrap(),
            );
        }
        let newly = opened(&actions);
        let decided: Vec<u64> = actions
            .iter()
            .filter_map(|a| match a {
                Action::Decided(d) => Some(d.iteration),
                _ => None,
            })
            .collect();
        assert_eq!(decided, [o.iteration]);
        for n in &newly {
            assert_eq!(
                n.iteration,
                o.iteration + 2,
                "opened when i - D was decided"
            );
        }
        if o.iteration + 2 < 12 {
            assert_eq!(newly.len(), 1);
        } else {
            assert!(newly.is_empty(), "never beyond the planned total");
        }
        all.extend(newly.clone());
        open.extend(newly);
    }
    assert!(ev.finished());
    assert_eq!(ev.history().len(), 12);
    assert_eq!(all.len(), 12);
}

#[test]
fn refused_outcomes_change_nothing() {
    let (mut ev, first) = Evolve::start(exp(), &Imported::default());
    let o = opened(&first)[0].clone();
    let before = ev.clone();
    let m = measure(&o, 0);
    assert_eq!(
        ev.classify(9, 0, 0, &m),
        Err(OutcomeError::UnknownIteration(9))
    );
    assert!(matches!(
        ev.classify(0, 3, 0, &m),
        Err(OutcomeError::UnknownTrial { .. })
    ));
    assert!(matches!(
        ev.classify(0, 0, o.seeds[0] ^ 1, &m),
        Err(OutcomeError::WrongSeed { .. })
    ));
    let nan = Measurement { x_m: f64::NAN, ..m };
    assert!(matches!(
        ev.apply(0, 0, o.seeds[0], nan),
        Err(OutcomeError::Invalid { .. })
    ));
    assert_eq!(ev, before);
    assert!(ev.apply(0, 0, o.seeds[0], m).unwrap().is_empty());
    assert_eq!(ev.classify(0, 0, o.seeds[0], &m), Ok(Counted::Duplicate));
    assert!(
        ev.apply(0, 0, o.seeds[0], m).unwrap().is_empty(),
        "a duplicate does nothing"
    );
}

#[test]
fn seeds_are_the_seed_modules() {
    let (_, first) = Evolve::start(exp(), &Imported::default());
    for o in opened(&first) {
        for (k, s) in o.seeds.iter().enumerate() {
            assert_eq!(*s, protocol::seed::trial_seed(3, o.iteration, k as u32));
        }
    }
}

#[test]
fn table_iv_sets_are_the_expert_nu_prime_and_clops_mean() {
    let names =
        |ev: &Evolve| -> Vec<&'static str> { ev.table_sets().iter().map(|(n, _)| *n).collect() };
    // Before any decision: no ν′.
    let (mut ev, first) = Evolve::start(exp(), &Imported::default());
    assert_eq!(names(&ev), ["Expert", "Optim.2"]);
    let sets = ev.table_sets();
    assert_eq!(sets[0].1, ev.experiment().expert_values());
    assert_eq!(sets[1].1, ev.optim2());
    // Through the run: Optim.1 is ν′ as the history records it after each
    // decision, Optim.2 CLOP's mean.
    let mut open = opened(&first);
    while let Some(o) = open.first().cloned() {
        open.remove(0);
        for k in 0..3 {
            let actions = ev
                .apply(o.iteration, k as u32, o.seeds[k], measure(&o, k))
                .unwrap();
            open.extend(opened(&actions));
        }
        let last = ev.history().last().unwrap().best.clone();
        let sets = ev.table_sets();
        let optim1 = sets.iter().find(|(n, _)| *n == "Optim.1").map(|(_, v)| v);
        assert_eq!(optim1, last.as_ref().map(|b| &b.params));
        assert_eq!(sets.last().unwrap(), &("Optim.2", ev.optim2()));
    }
    assert!(ev.finished());
    let imported = ev.to_imported();
    assert!(imported.best.is_some(), "this run accepts");
    // A run started from that history has its ν′ before its own first decision.
    let (ev, _) = Evolve::start(exp(), &imported);
    assert_eq!(ev.history().len(), 0);
    assert_eq!(names(&ev), ["Expert", "Optim.1", "Optim.2"]);
    assert_eq!(ev.table_sets()[1].1, imported.best.unwrap().params);
}
