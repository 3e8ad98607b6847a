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

/// `who` (with `slots`) asks for as many trials as it has slots; ids 1, 2, ….
fn take(
    s: &mut Scheduler,
    who: &str,
    slots: u32,
    failed: &dyn Fn(TrialId) -> BTreeSet<String>,
) -> Vec<TrialId> {
    let mut n = 0;
    s.take(who, slots, slots, Instant::now(), failed, &mut || {
        n += 1;
        n
    })
    .into_iter()
    .map(|(t, _)| t)
    .collect()
}

/// Whether `who` answering `t` with the id in flight answers that dispatch.
fn answer(s: &mut Scheduler, t: TrialId, who: &str) -> bool {
    let id = s.dispatch_of(t).unwrap_or(0);
    s.answered(t, who, id, Instant::now()) == Answer::Held
}

#[tokio::test(start_paused = true)]
async fn a_passed_lease_sends_the_trial_back_and_it_is_taken_again() {
    let mut s = sched();
    s.enqueue((0, 0), Instant::now());
    assert_eq!(take(&mut s, "a", 1, &none), [(0, 0)]);
    advance(LEASE - Duration::from_millis(1)).await;
    s.worker_seen("a", Some(1), Instant::now());
    s.worker_seen("b", Some(1), Instant::now());
    assert_eq!(s.tick(Instant::now()), Tick::default(), "not yet");
    advance(Duration::from_millis(1)).await;
    let t = s.tick(Instant::now());
    assert_eq!(t.expired, [((0, 0), "a".to_string())]);
    assert!(t.silent.is_empty());
    assert_eq!(s.holder((0, 0)), None);
    s.enqueue((0, 0), Instant::now());
    assert!(
        take(&mut s, "a", 1, &none).is_empty(),
        "not to the worker it expired on while another lives"
    );
    assert_eq!(take(&mut s, "b", 1, &none), [(0, 0)]);
    assert!(!answer(&mut s, (0, 0), "a"), "a no longer holds it");
    assert!(answer(&mut s, (0, 0), "b"));
}

#[tokio::test(start_paused = true)]
async fn a_silent_worker_is_swept_after_four_silences_with_its_trials() {
    let mut s = sched();
    s.enqueue((1, 0), Instant::now());
    s.enqueue((1, 1), Instant::now());
    s.enqueue((1, 2), Instant::now());
    assert_eq!(take(&mut s, "a", 2, &none).len(), 2);
    advance(SILENCE * 4).await;
    assert!(s.tick(Instant::now()).silent.is_empty(), "not swept yet");
    s.worker_seen("a", None, Instant::now());
    advance(SILENCE * 4).await;
    assert!(
        s.tick(Instant::now()).silent.is_empty(),
        "a heartbeat keeps it"
    );
    advance(Duration::from_millis(1)).await;
    let t = s.tick(Instant::now());
    assert_eq!(t.silent, ["a".to_string()]);
    let held = s.worker_gone("a");
    assert_eq!(held, [(1, 0), (1, 1)]);
    assert_eq!(s.workers(), 0);
    assert_eq!(
        s.ready(),
        1,
        "(1, 2) still queued; the caller re-queues the rest"
    );
}

#[tokio::test(start_paused = true)]
async fn a_worker_never_holds_more_than_its_slots() {
    let mut s = sched();
    for k in 0..10 {
        s.enqueue((0, k), Instant::now());
    }
    assert_eq!(take(&mut s, "a", 2, &none).len(), 2);
    assert_eq!(take(&mut s, "a", 2, &none).len(), 0, "full");
    assert_eq!(take(&mut s, "b", 3, &none).len(), 3);
    assert_eq!(s.held_by("a"), 2);
    assert_eq!(s.held_by("b"), 3);
    assert_eq!(s.serving(), 2);
    let mut n = 100;
    let more = s.take("b", 3, 1, Instant::now(), &none, &mut || {
        n += 1;
        n
    });
    assert!(more.is_empty(), "b's slots are full whatever it wants");
    let first = s.holder((0, 0)).map(str::to_string).unwrap_or_default();
    assert!(answer(&mut s, (0, 0), &first));
    assert_eq!(
        take(&mut s, &first, if first == "a" { 2 } else { 3 }, &none).len(),
        1,
        "one slot came free"
    );
    assert_eq!(s.ready(), 4);
}

#[tokio::test(start_paused = true)]
async fn a_failed_trial_waits_for_another_worker_while_one_lives() {
    let failed_on_b = |t: TrialId| -> BTreeSet<String> {
        if t == (0, 0) {
            BTreeSet::from(["b".to_string()])
        } else {
            BTreeSet::new()
        }
    };
    let mut s = sched();
    s.worker_seen("a", Some(1), Instant::now());
    s.enqueue((0, 0), Instant::now());
    s.enqueue((0, 1), Instant::now());
    assert_eq!(
        take(&mut s, "b", 1, &failed_on_b),
        [(0, 1)],
        "b skips what it failed"
    );
    assert_eq!(take(&mut s, "a", 1, &failed_on_b), [(0, 0)]);
    // With only "b" alive, it gets the trial again, but only one silence
    // period after its failure (a joining worker first).
    let mut s2 = sched();
    s2.worker_seen("b", Some(1), Instant::now());
    s2.failed((0, 0), Instant::now());
    assert!(take(&mut s2, "b", 1, &failed_on_b).is_empty(), "held");
    advance(SILENCE).await;
    assert_eq!(take(&mut s2, "b", 1, &failed_on_b), [(0, 0)]);
}

#[tokio::test(start_paused = true)]
async fn a_set_aside_worker_gets_nothing() {
    let mut s = sched();
    s.set_aside("a");
    s.enqueue((0, 0), Instant::now());
    assert!(take(&mut s, "a", 4, &none).is_empty());
    assert!(s.is_queued((0, 0)));
    assert_eq!(take(&mut s, "b", 1, &none), [(0, 0)]);
    s.forget((0, 0));
    assert_eq!(s.held_by("b"), 0);
}

#[tokio::test(start_paused = true)]
async fn only_the_dispatch_in_flight_from_its_worker_answers() {
    let mut s = sched();
    s.worker_seen("b", Some(1), Instant::now());
    s.enqueue((0, 0), Instant::now());
    let d = s.take("a", 1, 1, Instant::now(), &none, &mut || 0xfeed);
    assert_eq!(d, [((0, 0), 0xfeed)]);
    for (t, who, dispatch, answer) in [
        ((0, 0), "b", 0xfeed, Answer::OtherWorker),
        ((0, 0), "a", 0xbeef, Answer::WrongDispatch),
        ((0, 1), "a", 0xfeed, Answer::NotInFlight),
        ((0, 0), "z", 0xfeed, Answer::UnknownWorker),
    ] {
        assert_eq!(s.answered(t, who, dispatch, Instant::now()), answer);
    }
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

/// A worker that keeps naming a dispatch keeps its trial past any number of
/// leases; one it stops naming comes back when its lease passes.
#[tokio::test(start_paused = true)]
async fn a_running_trial_named_by_its_worker_keeps_its_lease() {
    let mut s = sched();
    s.enqueue((0, 0), Instant::now());
    s.enqueue((0, 1), Instant::now());
    assert_eq!(take(&mut s, "a", 2, &none), [(0, 0), (0, 1)]);
    let kept = s.dispatch_of((0, 0)).unwrap();
    for _ in 0..3 {
        advance(LEASE / 2).await;
        s.worker_seen("a", Some(2), Instant::now());
        s.renew("a", &[kept], Instant::now());
        let t = s.tick(Instant::now());
        assert!(t.expired.iter().all(|(t, _)| *t != (0, 0)), "{t:?}");
    }
    assert_eq!(s.holder((0, 0)), Some("a"), "renewed past three leases");
    assert_eq!(s.holder((0, 1)), None, "not named: its lease passed");
    // Another worker naming the dispatch renews nothing.
    s.worker_seen("b", Some(1), Instant::now());
    s.renew("b", &[kept], Instant::now());
    advance(LEASE).await;
    s.worker_seen("a", Some(2), Instant::now());
    assert_eq!(s.tick(Instant::now()).expired, [((0, 0), "a".to_string())]);
}
