//! When a followed run has ended, for watchers: a pure state machine over
//! what a watcher sees (statuses, the coordinator's liveliness, the results
//! reported), with `now` from the caller.
//!
//! The run ends when its coordinator says it finished or its token goes; its
//! last results may still be on the way (other keys, other queues), so the
//! watcher waits up to a grace period for every planned iteration before it
//! calls the report incomplete. Must not: read a clock or do I/O.

use std::time::Duration;

use tokio::time::Instant;

/// What a watcher should do now.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    /// Keep following.
    Going,
    /// Every planned iteration was reported; `finished` when the coordinator
    /// said so (otherwise it went away after its last decision).
    Complete {
        /// The coordinator's status said finished.
        finished: bool,
    },
    /// The grace period passed with iterations missing.
    Incomplete {
        /// The coordinator's status said finished (else it went away).
        finished: bool,
    },
}

/// The end-of-run state of one followed run.
#[derive(Debug, Clone)]
pub struct Ending {
    planned: u64,
    grace: Duration,
    ending: Option<(Instant, bool)>,
}

impl Ending {
    /// Follows a run of `planned` iterations, waiting `grace` for the last results.
    #[must_use]
    pub fn new(planned: u64, grace: Duration) -> Self {
        Self {
            planned,
            grace,
            ending: None,
        }
    }

    /// A status arrived.
    pub fn status(&mut self, planned: u64, finished: bool, now: Instant) {
        self.planned = planned;
        if finished && !self.ending.is_some_and(|(_, f)| f) {
            self.ending = Some((now + self.grace, true));
        }
    }

    /// The coordinator's liveliness token went away.
    pub fn coordinator_gone(&mut self, now: Instant) {
        if self.ending.is_none() {
            self.ending = Some((now + self.grace, false));
        }
    }

    /// The planned total.
    #[must_use]
    pub fn planned(&self) -> u64 {
        self.planned
    }

    /// When the watcher must give up waiting, if the run has ended.
    #[must_use]
    pub fn deadline(&self) -> Option<Instant> {
        self.ending.map(|(d, _)| d)
    }

    /// The verdict with `reported` iterations reported at `now`.
    #[must_use]
    pub fn verdict(&self, reported: u64, now: Instant) -> Verdict {
        match self.ending {
            None => Verdict::Going,
            Some((_, finished)) if reported >= self.planned => Verdict::Complete { finished },
            Some((deadline, finished)) if now >= deadline => Verdict::Incomplete { finished },
            Some(_) => Verdict::Going,
        }
    }
}

#[cfg(test)]
mod tests {
    use tokio::time::advance;

    use super::*;

    const GRACE: Duration = Duration::from_secs(3);

    /// The verdict now with `reported` iterations reported.
    fn at(e: &Ending, reported: u64) -> Verdict {
        e.verdict(reported, Instant::now())
    }

    const DONE: Verdict = Verdict::Complete { finished: true };
    const GONE: Verdict = Verdict::Complete { finished: false };
    const SHORT: Verdict = Verdict::Incomplete { finished: true };
    const LOST: Verdict = Verdict::Incomplete { finished: false };

    #[tokio::test(start_paused = true)]
    async fn a_finished_run_completes_when_its_last_results_arrive() {
        let mut e = Ending::new(10, GRACE);
        assert_eq!(at(&e, 10), Verdict::Going, "not ended yet");
        e.status(10, true, Instant::now());
        assert_eq!(at(&e, 8), Verdict::Going, "results on the way");
        advance(Duration::from_secs(1)).await;
        assert_eq!(at(&e, 10), DONE);
    }

    #[tokio::test(start_paused = true)]
    async fn missing_results_past_the_grace_are_an_incomplete_report() {
        let mut e = Ending::new(10, GRACE);
        e.status(10, true, Instant::now());
        advance(GRACE).await;
        assert_eq!(at(&e, 9), SHORT);
    }

    #[tokio::test(start_paused = true)]
    async fn a_coordinator_that_goes_away_ends_the_run_after_the_grace() {
        let mut e = Ending::new(20, GRACE);
        e.coordinator_gone(Instant::now());
        assert_eq!(at(&e, 5), Verdict::Going);
        // A finished status that arrives after the token went still counts.
        e.status(20, true, Instant::now());
        advance(GRACE).await;
        assert_eq!(at(&e, 5), SHORT);
        let mut gone = Ending::new(20, GRACE);
        gone.coordinator_gone(Instant::now());
        advance(GRACE).await;
        assert_eq!(at(&gone, 5), LOST);
        assert_eq!(at(&gone, 20), GONE);
    }
}
