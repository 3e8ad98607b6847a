//! The scheduler under tokio's paused clock: leases, silence, re-dispatch,
//! slots, failed and set-aside workers. No wall-clock time passes.

use std::collections::BTreeSet;

use tokio::time::{advance, Instant};

use super::*;

const LEASE: Duration = Duration::from_secs(30);
const SILENCE: Duration = Duration::from_secs(3);

fn none(_: TrialId) -> BTreeSet<String> {
    BTreeSet::new()
}

fn sched() -> Scheduler {
    Scheduler::new(LEASE, SILENCE)
}

/// Dispatches with ids 1, 2, …; the (trial, worker) pairs.
fn give(s: &mut Scheduler, failed: &dyn Fn(TrialId) -> BTreeSet<String>) -> Vec<(TrialId, String)> {
    let mut n = 0;
    s.dispatch(Instant::now(), failed, &mut || {
        n += 1;
        n
    })
    .into_iter()
    .map(|(t, w, _)| (t, w))
    .collect()
}

/// Whether `who` answering `t` with the id in flight answers that dispatch.
fn answer(s: &mut Scheduler, t: TrialId, who: &str) -> bool {
    let id = s.dispatch_of(t).unwrap_or(0);
    s.answered(t, who, id, Instant::now()) == Answer::Held
}

#[tokio::test(start_paused = true)]
async fn a_passed_lease_sends_the_trial_back_and_it_is_dispatched_again() {
    let mut s = sched();
    s.worker_seen("a", Some(1), Instant::now());
    s.enqueue((0, 0));
    assert_eq!(give(&mut s, &none), [((0, 0), "a".to_string())]);
    advance(LEASE - Duration::from_millis(1)).await;
    s.worker_seen("a", Some(1), Instant::now());
    s.worker_seen("b", Some(1), Instant::now());
    assert_eq!(s.tick(Instant::now()), Tick::default(), "not yet");
    advance(Duration::from_millis(1)).await;
    let t = s.tick(Instant::now());
    assert_eq!(t.expired, [((0, 0), "a".to_string())]);
    assert!(t.silent.is_empty());
    assert_eq!(s.holder((0, 0)), None);
    s.enqueue((0, 0));
    let again = give(&mut s, &none);
    assert_eq!(
        again,
        [((0, 0), "b".to_string())],
        "re-dispatched, not to the worker it expired on"
    );
    assert!(!answer(&mut s, (0, 0), "a"), "a no longer holds it");
    assert!(answer(&mut s, (0, 0), "b"));
}

#[tokio::test(start_paused = true)]
async fn a_silent_worker_gets_no_work_and_is_swept_after_four_silences() {
    let mut s = sched();
    s.worker_seen("a", Some(2), Instant::now());
    s.enqueue((1, 0));
    s.enqueue((1, 1));
    assert_eq!(give(&mut s, &none).len(), 2);
    advance(SILENCE + Duration::from_millis(1)).await;
    s.enqueue((1, 2));
    assert!(give(&mut s, &none).is_empty(), "silent: no new work");
    assert!(s.tick(Instant::now()).silent.is_empty(), "not swept yet");
    advance(SILENCE * 3).await;
    let t = s.tick(Instant::now());
    assert_eq!(t.silent, ["a".to_string()]);
    let held = s.worker_gone("a");
    assert_eq!(held, [(1, 0), (1, 1)]);
    assert_eq!(s.workers(), 0);
}

#[tokio::test(start_paused = true)]
async fn a_worker_never_holds_more_than_its_slots() {
    let mut s = sched();
    s.worker_seen("a", Some(2), Instant::now());
    s.worker_seen("b", Some(3), Instant::now());
    for k in 0..10 {
        s.enqueue((0, k));
    }
    let d = give(&mut s, &none);
    assert_eq!(d.len(), 5);
    assert_eq!(s.held_by("a"), 2);
    assert_eq!(s.held_by("b"), 3);
    assert!(answer(&mut s, d[0].0, &d[0].1));
    assert_eq!(give(&mut s, &none).len(), 1, "one slot came free");
}

#[tokio::test(start_paused = true)]
async fn a_failed_trial_waits_for_another_worker_while_one_lives() {
    let mut s = sched();
    s.worker_seen("a", Some(1), Instant::now());
    s.worker_seen("b", Some(1), Instant::now());
    s.enqueue((0, 1));
    let d = give(&mut s, &none);
    let busy_b = d[0].1.clone();
    assert_eq!(busy_b, "a", "most free slots, then the smallest id");
    // Now (0, 0) failed on "b"; only "b" is free: it waits.
    let failed_on_b = |t: TrialId| -> BTreeSet<String> {
        if t == (0, 0) {
            BTreeSet::from(["b".to_string()])
        } else {
            BTreeSet::new()
        }
    };
    s.enqueue((0, 0));
    assert!(answer(&mut s, (0, 1), "a"));
    s.enqueue((0, 1));
    let d = give(&mut s, &failed_on_b);
    assert!(d.contains(&((0, 0), "a".to_string())), "{d:?}");
    // With "a" gone, "b" is the only live worker: it gets the trial again,
    // but only one silence period after its failure (a joining worker first).
    let mut s2 = sched();
    s2.worker_seen("b", Some(1), Instant::now());
    s2.failed((0, 0), Instant::now());
    assert!(give(&mut s2, &failed_on_b).is_empty(), "held");
    advance(SILENCE).await;
    s2.worker_seen("b", Some(1), Instant::now());
    assert_eq!(give(&mut s2, &failed_on_b), [((0, 0), "b".to_string())]);
}

#[tokio::test(start_paused = true)]
async fn a_set_aside_worker_gets_nothing() {
    let mut s = sched();
    s.worker_seen("a", Some(4), Instant::now());
    s.set_aside("a");
    s.enqueue((0, 0));
    assert!(give(&mut s, &none).is_empty());
    assert!(s.is_queued((0, 0)));
    s.worker_seen("b", Some(1), Instant::now());
    assert_eq!(give(&mut s, &none), [((0, 0), "b".to_string())]);
    s.forget((0, 0));
    assert_eq!(s.held_by("b"), 0);
}

#[tokio::test(start_paused = true)]
async fn only_the_dispatch_in_flight_from_its_worker_answers() {
    let mut s = sched();
    s.worker_seen("a", Some(1), Instant::now());
    s.worker_seen("b", Some(1), Instant::now());
    s.enqueue((0, 0));
    let d = s.dispatch(Instant::now(), &none, &mut || 0xfeed);
    assert_eq!(d, [((0, 0), "a".to_string(), 0xfeed)]);
    assert_eq!(
        s.answered((0, 0), "b", 0xfeed, Instant::now()),
        Answer::OtherWorker
    );
    assert_eq!(
        s.answered((0, 0), "a", 0xbeef, Instant::now()),
        Answer::WrongDispatch
    );
    assert_eq!(
        s.answered((0, 1), "a", 0xfeed, Instant::now()),
        Answer::NotInFlight
    );
    assert_eq!(
        s.answered((0, 0), "z", 0xfeed, Instant::now()),
        Answer::UnknownWorker
    );
    assert_eq!(
        s.holder((0, 0)),
        Some("a"),
        "refused answers change nothing"
    );
    assert_eq!(
        s.answered((0, 0), "a", 0xfeed, Instant::now()),
        Answer::Held
    );
    assert_eq!(s.holder((0, 0)), None);
    assert_eq!(
        s.answered((0, 0), "a", 0xfeed, Instant::now()),
        Answer::NotInFlight,
        "once"
    );
}
