//! Which run a worker asks for work: its slots shared among the runs by
//! priority, as a pure part (the caller passes `now`; nothing here sends a
//! message or reads a clock).
//!
//! Each worker keeps, per run, the trial-seconds it gave that run divided by
//! the run's priority (its *virtual time*), and fills a free slot from the
//! run with trials ready whose virtual time, counting the trials it holds or
//! is asking for at the run's mean trial cost, is lowest (start-time fair
//! queueing). Because every worker does so, the fleet's trial-seconds split
//! among the runs with work ready in proportion to their priorities. A run
//! that becomes ready again after its adverts said it had nothing ready
//! starts at the fleet's current virtual time, so it gets its share from then
//! on, not a burst for the time it was idle; one this worker skipped only
//! because its grant came back short (others took the trials) keeps its place.
//! A run with nothing ready, paused, beyond the worker's limits, or not
//! heard from for [`FORGET_AFTER`] is skipped, so its share goes to the
//! others. Must not: talk to zenoh, block, or decide anything about a trial's
//! result.

use std::{collections::BTreeMap, time::Duration};

use protocol::wire::{RunAdvert, RunState};
use tokio::time::Instant;

/// A run whose adverts stop for this long is forgotten (its coordinator went).
pub const FORGET_AFTER: Duration = Duration::from_millis(3500);

#[derive(Debug, Clone)]
struct RunInfo {
    priority: f64,
    /// Trials ready, as last advertised, less those granted since.
    ready: u32,
    state: RunState,
    duration_s: f64,
    seq: u64,
    heard: Instant,
    /// Trial-seconds run for it ÷ priority.
    vt: f64,
    /// Mean wall seconds of its trials here (`None`: none finished yet).
    cost: Option<f64>,
    held: u32,
    asking: u32,
    /// A grant came back short: skip until an advert newer than this.
    empty_until: Option<u64>,
    /// Whether its last advert said it had trials ready (and ran). A short
    /// grant does not clear it: other workers took the trials, the run was
    /// not idle.
    advertised_ready: bool,
    /// Why this worker will not serve it (a limit), if so.
    unservable: Option<String>,
}

/// The fair-share state of one worker.
#[derive(Debug, Clone, Default)]
pub struct Share {
    runs: BTreeMap<String, RunInfo>,
    /// The fleet's virtual time as this worker sees it: the key of the last pick.
    vnow: f64,
    /// Mean wall seconds of any trial here (the cost of a run not yet measured).
    mean_cost: Option<f64>,
}

/// The cost assumed for a trial before any was measured, s.
const FIRST_COST_S: f64 = 1.0;

impl Share {
    /// An empty share (no runs known).
    #[must_use]
    pub fn new() -> Self {
        Self::default()
    }

    fn cost(&self, r: &RunInfo) -> f64 {
        r.cost.or(self.mean_cost).unwrap_or(FIRST_COST_S)
    }

    fn key(&self, r: &RunInfo, extra: u32) -> f64 {
        r.vt + f64::from(r.held + r.asking + extra) * self.cost(r) / r.priority
    }

    fn eligible(r: &RunInfo, max_duration_s: f64) -> bool {
        r.state == RunState::Running
            && r.ready > 0
            && r.asking == 0
            && r.empty_until.is_none()
            && r.unservable.is_none()
            && r.duration_s <= max_duration_s
    }

    /// A run's advert arrived.
    pub fn advert(&mut self, ad: &RunAdvert, now: Instant) {
        let vnow = self.vnow;
        let r = self.runs.entry(ad.id.clone()).or_insert_with(|| RunInfo {
            priority: 1.0,
            ready: 0,
            state: RunState::Running,
            duration_s: 0.0,
            seq: 0,
            heard: now,
            vt: vnow,
            cost: None,
            held: 0,
            asking: 0,
            empty_until: None,
            advertised_ready: true,
            unservable: None,
        });
        let was_ready = r.advertised_ready;
        if ad.seq < r.seq {
            // A restarted coordinator counts from 1 again; take it as new.
            r.empty_until = None;
        }
        r.priority = f64::from(ad.priority.max(1));
        r.ready = ad.ready;
        r.state = ad.state;
        r.duration_s = ad.duration_s;
        r.seq = ad.seq;
        r.heard = now;
        if r.empty_until.is_some_and(|s| ad.seq > s) {
            r.empty_until = None;
        }
        r.advertised_ready = r.ready > 0 && r.state == RunState::Running;
        if r.advertised_ready && !was_ready {
            // Back to work after being idle: from the fleet's present, not its
            // own past. (A run this worker skipped only because others took
            // its trials first keeps its place: it was never idle, and
            // restarting it would cost it its share whenever it is raced.)
            r.vt = r.vt.max(vnow);
        }
    }

    /// Chooses runs for `free` slots: `(run id, trials to ask for)`, at most one
    /// request per run, runs with the lowest virtual time first. The trials asked
    /// for count as held until [`Share::granted`].
    pub fn pick(&mut self, free: u32, max_duration_s: f64) -> Vec<(String, u32)> {
        let mut asks: BTreeMap<String, u32> = BTreeMap::new();
        for _ in 0..free {
            let best = self
                .runs
                .iter()
                .filter(|(id, r)| {
                    let n = asks.get(*id).copied().unwrap_or(0);
                    (n > 0 || Self::eligible(r, max_duration_s)) && r.ready > n
                })
                .map(|(id, r)| {
                    let n = asks.get(id).copied().unwrap_or(0);
                    (self.key(r, n), id)
                })
                .min_by(|a, b| a.0.total_cmp(&b.0).then_with(|| a.1.cmp(b.1)));
            let Some((key, id)) = best else { break };
            self.vnow = self.vnow.max(key);
            *asks.entry(id.clone()).or_default() += 1;
        }
        for (id, n) in &asks {
            if let Some(r) = self.runs.get_mut(id) {
                r.asking = *n;
            }
        }
        asks.into_iter().collect()
    }

    /// The run answered a request for `asked` trials with `got` (0 when the
    /// request failed), saying `ready` more are ready as of its advert `seq`
    /// (`answer`; `None`: no answer). A short answer means it has no more
    /// ready for now: the run is skipped until an advert newer than `seq`.
    /// A grant older than an advert already heard (the advert overtook the
    /// reply) says nothing new about readiness: the advert stands.
    pub fn granted(&mut self, run: &str, asked: u32, got: u32, answer: Option<(u32, u64)>) {
        if let Some(r) = self.runs.get_mut(run) {
            r.asking = r.asking.saturating_sub(asked);
            r.held += got;
            match answer {
                Some((_, seq)) if seq < r.seq => r.ready = r.ready.saturating_sub(got),
                Some((ready, seq)) => {
                    r.ready = ready;
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

    /// A trial of `run` ended here after `wall_s` seconds (run, failed or given back).
    pub fn done(&mut self, run: &str, wall_s: f64) {
        let wall_s = if wall_s.is_finite() {
            wall_s.max(0.0)
        } else {
            0.0
        };
        self.mean_cost = Some(self.mean_cost.map_or(wall_s, |c| 0.9 * c + 0.1 * wall_s));
        if let Some(r) = self.runs.get_mut(run) {
            r.held = r.held.saturating_sub(1);
            r.vt += wall_s / r.priority;
            r.cost = Some(r.cost.map_or(wall_s, |c| 0.8 * c + 0.2 * wall_s));
        }
    }

    /// This worker will not serve `run` (its trials are beyond a limit).
    pub fn unservable(&mut self, run: &str, why: &str) {
        if let Some(r) = self.runs.get_mut(run) {
            r.unservable = Some(why.to_string());
        }
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
            state: RunState::Running,
            duration_s: 10.0,
            seq,
        }
    }

    /// Runs `rounds` of: pick for every free slot, grant all, finish all after `cost`.
    fn serve(share: &mut Share, slots: u32, rounds: u32, cost: f64) -> BTreeMap<String, f64> {
        let mut got: BTreeMap<String, f64> = BTreeMap::new();
        for _ in 0..rounds {
            let asks = share.pick(slots, 3600.0);
            for (id, n) in &asks {
                share.granted(id, *n, *n, Some((1_000_000, 0)));
            }
            for (id, n) in asks {
                for _ in 0..n {
                    share.done(&id, cost);
                    *got.entry(id.clone()).or_default() += cost;
                }
            }
        }
        got
    }

    #[tokio::test(start_paused = true)]
    async fn slots_split_by_priority_while_every_run_has_work() {
        let mut s = Share::new();
        let now = Instant::now();
        for (i, p) in [(0, 1), (1, 2), (2, 3)] {
            s.advert(&ad(&format!("r{i}"), p, 1_000_000, 1), now);
        }
        let got = serve(&mut s, 6, 1000, 1.0);
        let total: f64 = got.values().sum();
        for (i, p) in [(0, 1.0), (1, 2.0), (2, 3.0)] {
            let share = got[&format!("r{i}")] / total;
            assert!(
                (share - p / 6.0).abs() < 0.01,
                "run {i}: {share} of the slot-seconds, priority share {}",
                p / 6.0
            );
        }
    }

    #[tokio::test(start_paused = true)]
    async fn a_run_with_nothing_ready_leaves_its_share_and_returns_without_a_burst() {
        let mut s = Share::new();
        let now = Instant::now();
        s.advert(&ad("a", 1, 1_000_000, 1), now);
        s.advert(&ad("b", 1, 0, 1), now);
        let got = serve(&mut s, 4, 100, 1.0);
        assert_eq!(got.get("b"), None, "b had nothing ready");
        assert_eq!(got["a"], 400.0, "a took every slot");
        // b has work again: from now on half each, not 400 s of catch-up for b.
        s.advert(&ad("b", 1, 1_000_000, 2), now);
        let got = serve(&mut s, 4, 100, 1.0);
        assert!((got["a"] - got["b"]).abs() <= 4.0, "{got:?}");
    }

    #[tokio::test(start_paused = true)]
    async fn a_short_grant_marks_the_run_empty_until_its_next_advert() {
        let mut s = Share::new();
        let now = Instant::now();
        s.advert(&ad("a", 1, 5, 7), now);
        let asks = s.pick(4, 3600.0);
        assert_eq!(asks, [("a".to_string(), 4)]);
        assert!(
            s.pick(4, 3600.0).is_empty(),
            "one request per run at a time"
        );
        s.granted("a", 4, 1, Some((0, 7)));
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
    async fn a_run_raced_by_other_workers_keeps_its_share() {
        // Run a (priority 3) is raced: every other request of this worker to
        // it comes back empty (others took its trials) and its next advert
        // says it has trials again. It was never idle, so it keeps its
        // place and gets its share of what this worker runs in the rounds it
        // can be served.
        let mut s = Share::new();
        let now = Instant::now();
        s.advert(&ad("a", 3, 1_000_000, 1), now);
        s.advert(&ad("b", 1, 1_000_000, 1), now);
        let (mut seq, mut got) = (1, BTreeMap::<String, f64>::new());
        for round in 0..2000 {
            let asks = s.pick(4, 3600.0);
            for (id, n) in &asks {
                if id == "a" && round % 2 == 0 {
                    s.granted(id, *n, 0, Some((0, 0)));
                    seq += 1;
                    s.advert(&ad("a", 3, 1_000_000, seq), now);
                } else {
                    s.granted(id, *n, *n, Some((1_000_000, 0)));
                    for _ in 0..*n {
                        s.done(id, 1.0);
                        *got.entry(id.clone()).or_default() += 1.0;
                    }
                }
            }
        }
        let a = got["a"] / (got["a"] + got["b"]);
        assert!(
            a > 0.7,
            "a ran {a} of the trial-seconds; its priority's share is 0.75"
        );
    }

    #[tokio::test(start_paused = true)]
    async fn paused_long_unservable_and_silent_runs_are_skipped() {
        let mut s = Share::new();
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
        let mut s = Share::new();
        let now = Instant::now();
        s.advert(&ad("a", 1, 1, 7), now);
        assert_eq!(s.pick(1, 3600.0), [("a".to_string(), 1)]);
        // The coordinator ran out (grant at advert 7), then opened an
        // iteration and advertised 8; the worker hears 8 first.
        s.advert(&ad("a", 1, 6, 8), now);
        s.granted("a", 1, 1, Some((0, 7)));
        s.done("a", 0.0);
        assert_eq!(s.pick(1, 3600.0), [("a".to_string(), 1)]);
        // A short grant as of the newest advert idles it until a newer one.
        s.granted("a", 1, 0, Some((0, 8)));
        assert!(s.pick(1, 3600.0).is_empty());
        s.advert(&ad("a", 1, 6, 9), now);
        assert_eq!(s.pick(1, 3600.0), [("a".to_string(), 1)]);
    }

    #[tokio::test(start_paused = true)]
    async fn a_never_asks_beyond_a_runs_ready_count() {
        let mut s = Share::new();
        s.advert(&ad("a", 1, 2, 1), Instant::now());
        s.advert(&ad("b", 5, 1, 1), Instant::now());
        let asks = s.pick(10, 3600.0);
        assert_eq!(asks, [("a".to_string(), 2), ("b".to_string(), 1)]);
    }
}
