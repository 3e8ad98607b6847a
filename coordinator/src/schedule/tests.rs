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

#[tokio::test(start_paused = true)]
async fn a_passed_lease_sends_the_trial_back_and_it_is_dispatched_again() {
    let mut s = sched();
    s.worker_seen("a", Some(1), Instant::now());
    s.enqueue((0, 0));
    assert_eq!(
        s.dispatch(Instant::now(), &none),
        [((0, 0), "a".to_string())]
    );
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
    let again = s.dispatch(Instant::now(), &none);
    assert_eq!(again, [((0, 0), "a".to_string())], "re-dispatched");
    assert!(!s.answered((0, 0), "b", Instant::now()), "b never held it");
    assert!(s.answered((0, 0), "a", Instant::now()));
}

#[tokio::test(start_paused = true)]
async fn a_silent_worker_gets_no_work_and_is_swept_after_four_silences() {
    let mut s = sched();
    s.worker_seen("a", Some(2), Instant::now());
    s.enqueue((1, 0));
    s.enqueue((1, 1));
    assert_eq!(s.dispatch(Instant::now(), &none).len(), 2);
    advance(SILENCE + Duration::from_millis(1)).await;
    s.enqueue((1, 2));
    assert!(
        s.dispatch(Instant::now(), &none).is_empty(),
        "silent: no new work"
    );
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
    let d = s.dispatch(Instant::now(), &none);
    assert_eq!(d.len(), 5);
    assert_eq!(s.held_by("a"), 2);
    assert_eq!(s.held_by("b"), 3);
    assert!(s.answered(d[0].0, &d[0].1, Instant::now()));
    assert_eq!(
        s.dispatch(Instant::now(), &none).len(),
        1,
        "one slot came free"
    );
}

#[tokio::test(start_paused = true)]
async fn a_failed_trial_waits_for_another_worker_while_one_lives() {
    let mut s = sched();
    s.worker_seen("a", Some(1), Instant::now());
    s.worker_seen("b", Some(1), Instant::now());
    s.enqueue((0, 1));
    let d = s.dispatch(Instant::now(), &none);
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
    assert!(s.answered((0, 1), "a", Instant::now()));
    s.enqueue((0, 1));
    let d = s.dispatch(Instant::now(), &failed_on_b);
    assert!(d.contains(&((0, 0), "a".to_string())), "{d:?}");
    // With "a" gone, "b" is the only live worker: it gets the trial again,
    // but only one silence period after its failure (a joining worker first).
    let mut s2 = sched();
    s2.worker_seen("b", Some(1), Instant::now());
    s2.failed((0, 0), Instant::now());
    assert!(s2.dispatch(Instant::now(), &failed_on_b).is_empty(), "held");
    advance(SILENCE).await;
    s2.worker_seen("b", Some(1), Instant::now());
    assert_eq!(
        s2.dispatch(Instant::now(), &failed_on_b),
        [((0, 0), "b".to_string())]
    );
}

#[tokio::test(start_paused = true)]
async fn a_set_aside_worker_gets_nothing() {
    let mut s = sched();
    s.worker_seen("a", Some(4), Instant::now());
    s.set_aside("a");
    s.enqueue((0, 0));
    assert!(s.dispatch(Instant::now(), &none).is_empty());
    assert!(s.is_queued((0, 0)));
    s.worker_seen("b", Some(1), Instant::now());
    assert_eq!(
        s.dispatch(Instant::now(), &none),
        [((0, 0), "b".to_string())]
    );
    s.forget((0, 0));
    assert_eq!(s.held_by("b"), 0);
}
