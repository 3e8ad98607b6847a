//! Which run a worker asks for work: the fleet's slots shared among the runs
//! by priority, as a pure part (the caller passes `now`; nothing here sends a
//! message or reads a clock).
//!
//! Every run tells, in its adverts and in each grant, how many of its trials
//! are in flight on the fleet. A worker fills each free slot from a run with
//! trials ready that is below its share of the slots in use (the runs'
//! trials in flight water-filled by priority, none given more than it runs
//! or has ready) by at least one trial, drawn among those; when none is, it
//! draws among every run with trials ready. Both draws are lotteries with
//! odds of a run's priority over the wall time its trials take on this
//! worker: a run then starts trials at a rate proportional to that weight and
//! holds each slot for as long as its trials take, so it holds slots — the
//! fleet's trial-seconds — in proportion to its priority, whatever the other
//! runs' trial lengths. The first draw lets a run whose trials just became
//! ready take the slots that free next (a run whose window is close to its
//! share needs that); the second needs no count at all, so the runs' counts,
//! always somewhat stale, decide only the first: drawing the furthest below,
//! or the fewest in flight per priority when none is below, gave the runs
//! with small shares more than theirs (docs/fleet.md). A run with nothing
//! ready is skipped, so its share goes to the others by their priorities;
//! when it has trials again it takes its share, and nothing is owed for the
//! time it was idle. The draws come from the worker's own stream (ChaCha8),
//! so workers draw differently; the free slots of one request take evenly
//! spaced points of one draw, so a worker with many free slots splits them by
//! the odds to within one trial. A run paused, beyond the worker's limits,
//! or not heard from for [`FORGET_AFTER`] is skipped. Must not: talk to
//! zenoh, block, or decide anything about a trial's result.

use std::{collections::BTreeMap, time::Duration};

use protocol::wire::{RunAdvert, RunState};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use tokio::time::Instant;

/// A run whose adverts stop for this long is forgotten (its coordinator went).
pub const FORGET_AFTER: Duration = Duration::from_millis(3500);

/// How much of a run's mean wall time per trial one new trial moves (an
/// exponential mean over about the last 20 trials).
const WALL_GAIN: f64 = 0.05;

#[derive(Debug, Clone)]
struct RunInfo {
    priority: f64,
    /// Trials ready, as last heard, less those granted here since.
    ready: u32,
    /// Trials in flight on the fleet, as last heard (advert or grant), less
    /// those that ended here since.
    running: u32,
    state: RunState,
    /// The trials' simulated duration (seconds), as advertised.
    duration_s: f64,
    /// Mean wall time of its trials on this worker (seconds), once one ran.
    wall_s: Option<f64>,
    seq: u64,
    heard: Instant,
    held: u32,
    asking: u32,
    /// A grant came back short: skip until an advert newer than this.
    empty_until: Option<u64>,
    /// Why this worker will not serve it (a limit), if so.
    unservable: Option<String>,
}

/// The fair-share state of one worker.
#[derive(Debug, Clone)]
pub struct Share {
    runs: BTreeMap<String, RunInfo>,
    /// This worker's own draws.
    rng: ChaCha8Rng,
}

impl Share {
    /// An empty share (no runs known); `seed` (the worker's own, e.g. from
    /// its id) seeds its draws, so that workers draw differently.
    #[must_use]
    pub fn new(seed: u64) -> Self {
        Self {
            runs: BTreeMap::new(),
            rng: ChaCha8Rng::seed_from_u64(seed),
        }
    }

    fn eligible(r: &RunInfo, max_duration_s: f64) -> bool {
        r.state == RunState::Running
            && r.ready > 0
            && r.asking == 0
            && r.empty_until.is_none()
            && r.unservable.is_none()
            && r.duration_s <= max_duration_s
    }

    /// Each run's odds in the draws: its priority over the wall seconds a
    /// trial of it is expected to hold a slot here — its own mean once one
    /// ran; before, its simulated duration times the mean ratio of wall to
    /// simulated time of the runs that did (1 if none did).
    fn odds(&self) -> BTreeMap<&String, f64> {
        let (mut sum, mut n) = (0.0, 0.0);
        for o in self.runs.values() {
            if let Some(w) = o.wall_s {
                if o.duration_s > 0.0 {
                    sum += w / o.duration_s;
                    n += 1.0;
                }
            }
        }
        let ratio = if n > 0.0 { sum / n } else { 1.0 };
        self.runs
            .iter()
            .map(|(id, r)| {
                let wall = r.wall_s.unwrap_or(r.duration_s * ratio).max(1e-6);
                (id, r.priority / wall)
            })
            .collect()
    }

    /// A run's advert arrived.
    pub fn advert(&mut self, ad: &RunAdvert, now: Instant) {
        let r = self.runs.entry(ad.id.clone()).or_insert_with(|| RunInfo {
            priority: 1.0,
            ready: 0,
            running: 0,
            state: RunState::Running,
            duration_s: 0.0,
            wall_s: None,
            seq: 0,
            heard: now,
            held: 0,
            asking: 0,
            empty_until: None,
            unservable: None,
        });
        if ad.seq < r.seq {
            // A restarted coordinator counts from 1 again; take it as new.
            r.empty_until = None;
        }
        r.priority = f64::from(ad.priority.max(1));
        r.ready = ad.ready;
        r.running = ad.running;
        r.state = ad.state;
        r.duration_s = ad.duration_s;
        r.seq = ad.seq;
        r.heard = now;
        if r.empty_until.is_some_and(|s| ad.seq > s) {
            r.empty_until = None;
        }
    }

    /// Chooses runs for `free` slots: `(run id, trials to ask for)`, at most
    /// one request per run. Each slot goes to a run below its share by at
    /// least one trial, drawn among those; when none is, to any run with
    /// trials ready, drawn among all (the module's doc says why). The odds
    /// are a run's priority over its trials' wall time here; a run is asked
    /// for no more than it has ready. The trials asked for count as the run's
    /// in flight until [`Share::granted`].
    pub fn pick(&mut self, free: u32, max_duration_s: f64) -> Vec<(String, u32)> {
        let offset: f64 = self.rng.random();
        let targets = self.targets(max_duration_s);
        let odds = self.odds();
        let mut asks: BTreeMap<String, u32> = BTreeMap::new();
        for slot in 0..free {
            let n = |id: &String| asks.get(id).copied().unwrap_or(0);
            // (odds, run, below its share by a trial)
            let open: Vec<(f64, &String, bool)> = self
                .runs
                .iter()
                .filter(|(id, r)| {
                    (n(id) > 0 || Self::eligible(r, max_duration_s)) && r.ready > n(id)
                })
                .map(|(id, r)| {
                    let have = f64::from(r.running.saturating_add(r.asking).saturating_add(n(id)));
                    let below = targets.get(id).copied().unwrap_or(0.0) - have >= 1.0;
                    (odds.get(id).copied().unwrap_or(0.0), id, below)
                })
                .collect();
            let any_below = open.iter().any(|o| o.2);
            let drawn: Vec<(f64, &String)> = open
                .into_iter()
                .filter(|o| o.2 || !any_below)
                .map(|(odds, id, _)| (odds, id))
                .collect();
            let total: f64 = drawn.iter().map(|(odds, _)| odds).sum();
            if drawn.is_empty() || total <= 0.0 || !total.is_finite() {
                break;
            }
            // Stratified: the free slots of one request draw evenly spaced points.
            let mut x = (offset + f64::from(slot)) / f64::from(free) * total;
            let Some(id) = drawn
                .iter()
                .find(|(odds, _)| {
                    x -= odds;
                    x < 0.0
                })
                .or(drawn.last())
                .map(|(_, id)| (*id).clone())
            else {
                break;
            };
            *asks.entry(id).or_default() += 1;
        }
        drop((targets, odds));
        for (id, n) in &asks {
            if let Some(r) = self.runs.get_mut(id) {
                r.asking = *n;
            }
        }
        asks.into_iter().collect()
    }

    /// Each run's share of the fleet's slots as this worker sees them: the
    /// slots in use (the runs' trials in flight) split by priority among the
    /// runs, none given more than it runs or has ready (water-filling).
    fn targets(&self, max_duration_s: f64) -> BTreeMap<&String, f64> {
        let capacity: f64 = self.runs.values().map(|r| f64::from(r.running)).sum();
        let mut open: Vec<(&String, f64, f64)> = self
            .runs
            .iter()
            .map(|(id, r)| {
                let more = if Self::eligible(r, max_duration_s) || r.asking > 0 {
                    f64::from(r.ready)
                } else {
                    0.0
                };
                (id, r.priority, f64::from(r.running) + more)
            })
            .collect();
        // Fill the runs that want least (per priority) first.
        open.sort_by(|a, b| (a.2 / a.1).total_cmp(&(b.2 / b.1)));
        let (mut left, mut weight) = (capacity, open.iter().map(|o| o.1).sum::<f64>());
        let mut out = BTreeMap::new();
        for (id, p, demand) in open {
            let fair = if weight > 0.0 { left * p / weight } else { 0.0 };
            let got = fair.min(demand);
            out.insert(id, got);
            left -= got;
            weight -= p;
        }
        out
    }

    /// The run answered a request for `asked` trials with `got` (0 when the
    /// request failed), saying `ready` more are ready as of its advert `seq`
    /// (`answer`; `None`: no answer). A short answer means it has no more
    /// ready for now: the run is skipped until an advert newer than `seq`. A
    /// grant older than an advert already heard (the advert overtook the
    /// reply) says nothing new: the advert stands.
    pub fn granted(&mut self, run: &str, asked: u32, got: u32, answer: Option<(u32, u32, u64)>) {
        if let Some(r) = self.runs.get_mut(run) {
            r.asking = r.asking.saturating_sub(asked);
            r.held += got;
            match answer {
                // The newer advert's count of trials in flight already holds these.
                Some((_, _, seq)) if seq < r.seq => r.ready = r.ready.saturating_sub(got),
                Some((ready, running, seq)) => {
                    r.ready = ready;
                    r.running = running;
                    if got < asked || ready == 0 {
                        r.ready = 0;
                        r.empty_until = Some(seq.max(r.seq));
                    }
                }
                None => {
                    r.ready = 0;
                    r.empty_until = Some(r.seq);
                }
            }
        }
    }

    /// A trial of `run` ended here (run, failed or given back); `wall_s`:
    /// the wall seconds it held its slot, when it ran to its end.
    pub fn done(&mut self, run: &str, wall_s: Option<f64>) {
        if let Some(r) = self.runs.get_mut(run) {
            r.held = r.held.saturating_sub(1);
            r.running = r.running.saturating_sub(1);
            if let Some(w) = wall_s.filter(|w| w.is_finite() && *w >= 0.0) {
                r.wall_s = Some(r.wall_s.map_or(w, |m| m + WALL_GAIN * (w - m)));
            }
        }
    }

    /// This worker will not serve `run`: its trials are beyond a limit, or
    /// the run is pinned to another worker fingerprint. Whether this marked
    /// it (the run is known and was not marked yet).
    pub fn unservable(&mut self, run: &str, why: &str) -> bool {
        match self.runs.get_mut(run) {
            Some(r) if r.unservable.is_none() => {
                r.unservable = Some(why.to_string());
                true
            }
            _ => false,
        }
    }

    /// Whether `run` is known (heard from and not forgotten).
    #[must_use]
    pub fn knows(&self, run: &str) -> bool {
        self.runs.contains_key(run)
    }

    /// Forgets runs not heard from for [`FORGET_AFTER`] that it holds nothing of.
    pub fn expire(&mut self, now: Instant) {
        self.runs.retain(|_, r| {
            now.saturating_duration_since(r.heard) <= FORGET_AFTER || r.held > 0 || r.asking > 0
        });
    }

    /// Runs known.
    #[must_use]
    pub fn runs(&self) -> usize {
        self.runs.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ad(id: &str, priority: u32, ready: u32, seq: u64) -> RunAdvert {
        RunAdvert {
            id: id.into(),
            name: "x".into(),
            priority,
            ready,
            running: 0,
            state: RunState::Running,
            duration_s: 10.0,
            program: None,
            seq,
        }
    }

    /// A run of the fleet in miniature.
    #[derive(Clone, Copy)]
    struct Sim {
        priority: u32,
        /// Trials in flight at most (`u32::MAX`: always trials ready).
        window: u32,
        /// Ticks a trial takes (it takes up to 69 more).
        ticks: u32,
    }

    fn backlogged(priority: u32) -> Sim {
        Sim {
            priority,
            window: u32::MAX,
            ticks: 200,
        }
    }

    /// A fleet in miniature, on a clock of ticks (200 to a trial, as 5 ms
    /// to the bench's trials of 1 s): `workers` workers of `slots` slots
    /// serve the runs; a trial lasts its run's ticks plus 0 to 69. Each run
    /// advertises as a coordinator does: every 200 ticks; when its trials
    /// become ready or run out; when trials are ready while a worker that
    /// got a short grant waits; and when its trials in flight moved by a
    /// sixteenth (at least 2), at most every 5 ticks. Every grant tells its
    /// asker. Workers act in turn, each on what it last heard. Returns each
    /// run's slot-ticks after a warm-up of 10,000 ticks. (On a clock of 20
    /// ticks to a trial, where every worker acts on one tick's adverts, the
    /// views of the runs' trials in flight were off by 5 trials of 60, and
    /// runs of one priority could lock in at 0.31 : 0.31 : 0.38.)
    fn fleet(runs: &[Sim], workers: usize, slots: u32, seed: u64) -> Vec<f64> {
        let now = Instant::now();
        let mut running = vec![0u32; runs.len()];
        // Per run: its advert number, a worker waits, it advertised trials
        // ready, the trials in flight it advertised.
        let mut adv = vec![(0u64, true, false, 0u32); runs.len()];
        // Per worker: its share, and the trials it holds (run, start, end).
        type Held = Vec<(usize, u32, u32)>;
        let mut fleet: Vec<(Share, Held)> = (0..workers)
            .map(|w| (Share::new(seed * 1000 + w as u64), Vec::new()))
            .collect();
        let mut slot_ticks = vec![0.0; runs.len()];
        let ready = |i: usize, running: &[u32]| runs[i].window.saturating_sub(running[i]);
        let mut last_moved = vec![0u32; runs.len()];
        for tick in 0..40_000u32 {
            for (i, run) in runs.iter().enumerate() {
                let r = ready(i, &running);
                let moved = r > 0
                    && running[i].abs_diff(adv[i].3) >= (adv[i].3 / 16).max(2)
                    && tick - last_moved[i] >= 5;
                if moved {
                    last_moved[i] = tick;
                }
                if tick % 200 == 0 || (r > 0 && adv[i].1) || (r > 0) != adv[i].2 || moved {
                    adv[i] = (adv[i].0 + 1, false, r > 0, running[i]);
                    let mut a = ad(&format!("r{i}"), run.priority, r, adv[i].0);
                    a.running = running[i];
                    for (share, _) in &mut fleet {
                        share.advert(&a, now);
                    }
                }
            }
            let turn = tick as usize % workers;
            for k in 0..workers {
                let w = (turn + k) % workers;
                let (share, held) = &mut fleet[w];
                held.retain(|&(i, start, end)| {
                    if end > tick {
                        return true;
                    }
                    share.done(&format!("r{i}"), Some(f64::from(end - start)));
                    running[i] -= 1;
                    false
                });
                let free = slots - u32::try_from(held.len()).unwrap_or(slots);
                for (id, n) in share.pick(free, 3600.0) {
                    let i: usize = id[1..].parse().unwrap_or(0);
                    let got = n.min(ready(i, &running));
                    running[i] += got;
                    if got < n || ready(i, &running) == 0 {
                        adv[i].1 = true;
                    }
                    share.granted(
                        &id,
                        n,
                        got,
                        Some((ready(i, &running), running[i], adv[i].0)),
                    );
                    for k in 0..got {
                        let jitter = (u32::try_from(w).unwrap_or(0) * 7 + tick * 13 + k * 3) % 70;
                        held.push((i, tick, tick + runs[i].ticks + jitter));
                    }
                }
            }
            if tick >= 10_000 {
                for (t, r) in slot_ticks.iter_mut().zip(&running) {
                    *t += f64::from(*r);
                }
            }
        }
        slot_ticks
    }

    fn shares(slot_ticks: &[f64]) -> Vec<f64> {
        let total: f64 = slot_ticks.iter().sum();
        slot_ticks.iter().map(|t| t / total).collect()
    }

    #[tokio::test(start_paused = true)]
    async fn a_fleet_splits_its_slots_by_priority_while_every_run_has_work() {
        // 20 workers × 10 slots, runs of priorities 1, 2, 3, 1, 2, 3, each
        // with trials always ready.
        let runs = [1, 2, 3, 1, 2, 3].map(backlogged);
        for seed in 0..3 {
            let s = shares(&fleet(&runs, 20, 10, seed));
            for (run, share) in runs.iter().zip(&s) {
                let due = f64::from(run.priority) / 12.0;
                assert!(
                    (share / due - 1.0).abs() < 0.05,
                    "priority {}: {share:.4} of the slot-ticks, its share {due:.4} ({s:?})",
                    run.priority
                );
            }
        }
    }

    #[tokio::test(start_paused = true)]
    async fn a_run_that_cannot_use_its_share_leaves_it_to_the_others_by_priority() {
        // The priority-3 run never has more than 30 trials in flight (its
        // share of 200 slots would be 100): it keeps most of them in flight,
        // and the other two share the rest 2 : 1. (Taking the runs below
        // their share by the advertised counts gave 1.6–1.8 : 1 here, for
        // every seed: docs/fleet.md.)
        let runs = [
            backlogged(1),
            backlogged(2),
            Sim {
                priority: 3,
                window: 30,
                ticks: 200,
            },
        ];
        for seed in 0..4 {
            let s = fleet(&runs, 20, 10, seed);
            let total: f64 = s.iter().sum();
            let slots = |i: usize| 200.0 * s[i] / total;
            assert!(
                slots(2) > 20.0,
                "the window-bound run: {:.1} slots of 30",
                slots(2)
            );
            let ratio = slots(1) / slots(0);
            assert!(
                (ratio / 2.0 - 1.0).abs() < 0.05,
                "seed {seed}: priority 2 : priority 1 = {ratio:.3} ({s:?})"
            );
        }
    }

    #[tokio::test(start_paused = true)]
    async fn runs_share_trial_seconds_by_priority_whatever_their_trials_last() {
        // Two runs of one priority, one with trials three times as long: each
        // still holds half the slots (so half the fleet's trial-seconds),
        // not three quarters.
        let runs = [
            backlogged(1),
            Sim {
                priority: 1,
                window: u32::MAX,
                ticks: 600,
            },
            backlogged(2),
        ];
        let s = shares(&fleet(&runs, 20, 10, 0));
        for (run, share) in runs.iter().zip(&s) {
            let due = f64::from(run.priority) / 4.0;
            assert!((share / due - 1.0).abs() < 0.05, "{s:?}");
        }
    }

    #[tokio::test(start_paused = true)]
    async fn runs_of_one_priority_get_one_share_whatever_their_names() {
        // The lottery's draws are uniform: the first run by name is not
        // favoured (a biased hand-written generator gave 71 : 66 : 63 here).
        let runs = [2, 2, 2].map(backlogged);
        let s = shares(&fleet(&runs, 20, 10, 0));
        for share in &s {
            assert!((share * 3.0 - 1.0).abs() < 0.05, "{s:?}");
        }
    }

    #[tokio::test(start_paused = true)]
    async fn one_worker_alone_splits_its_slots_by_priority() {
        let mut s = Share::new(7);
        let now = Instant::now();
        for (i, p) in [(0, 1), (1, 2), (2, 3)] {
            s.advert(&ad(&format!("r{i}"), p, 1_000_000, 1), now);
        }
        let mut asks = s.pick(12, 3600.0);
        asks.sort();
        assert_eq!(
            asks,
            [
                ("r0".to_string(), 2),
                ("r1".to_string(), 4),
                ("r2".to_string(), 6)
            ]
        );
    }

    #[tokio::test(start_paused = true)]
    async fn a_run_with_nothing_ready_leaves_its_share_and_returns_without_a_burst() {
        let mut s = Share::new(1);
        let now = Instant::now();
        s.advert(&ad("a", 1, 1_000_000, 1), now);
        s.advert(&ad("b", 1, 0, 1), now);
        let asks = s.pick(4, 3600.0);
        assert_eq!(asks, [("a".to_string(), 4)], "b had nothing ready");
        s.granted("a", 4, 4, Some((1_000_000, 4, 1)));
        // b has work again: the slots that free go to a and b alike; nothing
        // is owed to b for the time it was idle.
        s.advert(&ad("b", 1, 1_000_000, 2), now);
        s.advert(&ad("a", 1, 1_000_000, 2), now);
        let mut held = vec!["a"; 4];
        let mut to_b = 0;
        for _ in 0..400 {
            let run = held.remove(0);
            s.done(run, Some(1.0));
            let asks = s.pick(1, 3600.0);
            let (id, n) = asks[0].clone();
            s.granted(&id, n, n, Some((1_000_000, 2, 2)));
            if id == "b" {
                to_b += 1;
                held.push("b");
            } else {
                held.push("a");
            }
        }
        assert!((180..=220).contains(&to_b), "{to_b} of 400 slots to b");
    }

    #[tokio::test(start_paused = true)]
    async fn a_short_grant_marks_the_run_empty_until_its_next_advert() {
        let mut s = Share::new(0);
        let now = Instant::now();
        s.advert(&ad("a", 1, 5, 7), now);
        let asks = s.pick(4, 3600.0);
        assert_eq!(asks, [("a".to_string(), 4)]);
        assert!(
            s.pick(4, 3600.0).is_empty(),
            "one request per run at a time"
        );
        s.granted("a", 4, 1, Some((0, 1, 7)));
        assert!(s.pick(3, 3600.0).is_empty(), "empty until its next advert");
        s.advert(&ad("a", 1, 5, 7), now);
        assert!(
            s.pick(3, 3600.0).is_empty(),
            "the same advert again changes nothing"
        );
        s.advert(&ad("a", 1, 5, 8), now);
        assert_eq!(s.pick(3, 3600.0), [("a".to_string(), 3)]);
    }

    #[tokio::test(start_paused = true)]
    async fn workers_that_tie_do_not_all_ask_the_same_run() {
        let now = Instant::now();
        let firsts: std::collections::BTreeSet<String> = (0..16u64)
            .map(|w| {
                let mut s = Share::new(w);
                for id in ["a", "b", "c", "d"] {
                    s.advert(&ad(id, 1, 9, 1), now);
                }
                s.pick(1, 3600.0)[0].0.clone()
            })
            .collect();
        assert!(firsts.len() >= 3, "16 workers asked only {firsts:?}");
    }

    #[tokio::test(start_paused = true)]
    async fn a_run_not_yet_run_here_is_weighed_by_its_duration() {
        // a's trials took 2 s of wall time per 10 s simulated here; b (20 s
        // simulated) has not run here yet, so it is expected to take 4 s:
        // of 12 slots, at one priority, a gets 8 and b 4.
        let mut s = Share::new(3);
        let now = Instant::now();
        s.advert(&ad("a", 1, 1_000, 1), now);
        let mut b = ad("b", 1, 1_000, 1);
        b.duration_s = 20.0;
        s.advert(&b, now);
        s.done("a", Some(2.0));
        let mut asks = s.pick(12, 3600.0);
        asks.sort();
        assert_eq!(asks, [("a".to_string(), 8), ("b".to_string(), 4)]);
    }

    #[tokio::test(start_paused = true)]
    async fn paused_long_unservable_and_silent_runs_are_skipped() {
        let mut s = Share::new(0);
        let now = Instant::now();
        let mut paused = ad("p", 1, 9, 1);
        paused.state = RunState::Paused;
        s.advert(&paused, now);
        let mut long = ad("l", 1, 9, 1);
        long.duration_s = 100.0;
        s.advert(&long, now);
        s.advert(&ad("u", 1, 9, 1), now);
        s.unservable("u", "model not served");
        assert!(s.pick(4, 60.0).is_empty());
        assert_eq!(
            s.pick(1, 600.0),
            [("l".to_string(), 1)],
            "within a larger limit"
        );
        s.granted("l", 1, 0, None);
        tokio::time::advance(FORGET_AFTER + Duration::from_millis(1)).await;
        s.expire(Instant::now());
        assert_eq!(s.runs(), 0, "none heard from lately, none held");
    }

    /// The advert that says trials are ready again can overtake the reply
    /// that said there were none (they travel apart): the run is asked again
    /// at once, not after the next periodic advert.
    #[tokio::test(start_paused = true)]
    async fn a_grant_older_than_the_last_advert_does_not_idle_the_run() {
        let mut s = Share::new(0);
        let now = Instant::now();
        s.advert(&ad("a", 1, 1, 7), now);
        assert_eq!(s.pick(1, 3600.0), [("a".to_string(), 1)]);
        // The coordinator ran out (grant at advert 7), then opened an
        // iteration and advertised 8; the worker hears 8 first.
        s.advert(&ad("a", 1, 6, 8), now);
        s.granted("a", 1, 1, Some((0, 1, 7)));
        assert_eq!(s.runs["a"].running, 0, "advert 8's count stands");
        s.done("a", Some(1.0));
        assert_eq!(s.pick(1, 3600.0), [("a".to_string(), 1)]);
        // A short grant as of the newest advert idles it until a newer one.
        s.granted("a", 1, 0, Some((0, 0, 8)));
        assert!(s.pick(1, 3600.0).is_empty());
        s.advert(&ad("a", 1, 6, 9), now);
        assert_eq!(s.pick(1, 3600.0), [("a".to_string(), 1)]);
    }

    #[tokio::test(start_paused = true)]
    async fn a_never_asks_beyond_a_runs_ready_count() {
        let mut s = Share::new(0);
        s.advert(&ad("a", 1, 2, 1), Instant::now());
        s.advert(&ad("b", 5, 1, 1), Instant::now());
        let mut asks = s.pick(10, 3600.0);
        asks.sort();
        assert_eq!(asks, [("a".to_string(), 2), ("b".to_string(), 1)]);
    }
}
