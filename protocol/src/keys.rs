//! Every zenoh key expression naofarm uses, built in one place.
//!
//! The prefix is configurable (default [`DEFAULT_PREFIX`]); run names are
//! checked by [`check_chunk`] so they can never inject `/`, `*` or `$`.
//! A run's watched keys ([`RunKeys`]) carry its name and its id; the keys
//! workers and `naofarm ctl` use ([`FleetKeys`]) carry only its id.

/// The default first chunk of every key.
pub const DEFAULT_PREFIX: &str = "naofarm";

/// Checks that `s` can stand as one chunk of a key expression.
pub fn check_chunk(what: &str, s: &str) -> Result<(), String> {
    if s.is_empty() {
        return Err(format!("{what} is empty"));
    }
    if s.len() > 128 {
        return Err(format!("{what} is longer than 128 bytes"));
    }
    if let Some(c) = s
        .chars()
        .find(|c| !(c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.')))
    {
        return Err(format!(
            "{what} `{s}` contains `{c}`; use letters, digits, `-`, `_` or `.`"
        ));
    }
    if s.starts_with('@') || s == "." || s == ".." {
        return Err(format!("{what} `{s}` is reserved"));
    }
    Ok(())
}

/// The watched keys of one run: `<prefix>/<name>/<id>/…`. The name (the
/// experiment's, a label) comes first so that `<prefix>/<name>/*/…` follows
/// every run of that name; the id (a UUID) tells two runs of one name apart.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RunKeys {
    base: String,
}

impl RunKeys {
    /// The keys of run `id` named `name` (both checked by [`check_chunk`] beforehand).
    #[must_use]
    pub fn new(prefix: &str, name: &str, id: &str) -> Self {
        Self {
            base: format!("{prefix}/{name}/{id}"),
        }
    }

    /// `…/params/<iter>`: an iteration's parameter set.
    #[must_use]
    pub fn params(&self, iter: u64) -> String {
        format!("{}/params/{iter}", self.base)
    }

    /// `…/trials/<iter>/<k>`: one trial's outcome.
    #[must_use]
    pub fn trial(&self, iter: u64, k: u32) -> String {
        format!("{}/trials/{iter}/{k}", self.base)
    }

    /// `…/trials/**`: every trial outcome of the run.
    #[must_use]
    pub fn trials_all(&self) -> String {
        format!("{}/trials/**", self.base)
    }

    /// `…/results/<iter>`: an iteration's decision.
    #[must_use]
    pub fn results(&self, iter: u64) -> String {
        format!("{}/results/{iter}", self.base)
    }

    /// `…/results/*`: every result of the run.
    #[must_use]
    pub fn results_all(&self) -> String {
        format!("{}/results/*", self.base)
    }

    /// `…/status`: the run's state (queryable and published).
    #[must_use]
    pub fn status(&self) -> String {
        format!("{}/status", self.base)
    }

    /// `…/history`: the decided iterations (queryable).
    #[must_use]
    pub fn history(&self) -> String {
        format!("{}/history", self.base)
    }

    /// `…/experiment`: the run's experiment as parsed (queryable).
    #[must_use]
    pub fn experiment(&self) -> String {
        format!("{}/experiment", self.base)
    }
}

/// `<prefix>/*/<id>/status`: the status of run `id`, whatever its name.
#[must_use]
pub fn status_of(prefix: &str, id: &str) -> String {
    format!("{prefix}/*/{id}/status")
}

/// The worker id of a key made by [`worker_status`].
#[must_use]
pub fn worker_of_status(key: &str) -> &str {
    last_chunk(key.strip_suffix("/status").unwrap_or(key))
}

/// `<prefix>/*/*/results/*`: every result of every run.
#[must_use]
pub fn results_all(prefix: &str) -> String {
    format!("{prefix}/*/*/results/*")
}

/// `<prefix>/*/*/status`: the status of every run.
#[must_use]
pub fn status_all(prefix: &str) -> String {
    format!("{prefix}/*/*/status")
}

/// The fleet's keys of one run, `<prefix>/@runs/<id>/…`: what workers and
/// `naofarm ctl` talk to. Only the run's coordinator subscribes to them.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FleetKeys {
    base: String,
}

impl FleetKeys {
    /// The fleet keys of run `id`.
    #[must_use]
    pub fn new(prefix: &str, id: &str) -> Self {
        Self {
            base: format!("{prefix}/@runs/{id}"),
        }
    }

    /// `…/work`: the coordinator's queryable; a worker asks it for trials.
    #[must_use]
    pub fn work(&self) -> String {
        format!("{}/work", self.base)
    }

    /// `…/outcomes`: workers put this run's trial outcomes here.
    #[must_use]
    pub fn outcomes(&self) -> String {
        format!("{}/outcomes", self.base)
    }

    /// `…/failures`: workers report this run's trials they could not (or would not) run.
    #[must_use]
    pub fn failures(&self) -> String {
        format!("{}/failures", self.base)
    }

    /// `…/presence`: heartbeats of workers holding this run's trials.
    #[must_use]
    pub fn presence(&self) -> String {
        format!("{}/presence", self.base)
    }

    /// `…/ad`: the run's advert (priority, trials ready, state), for workers.
    #[must_use]
    pub fn advert(&self) -> String {
        format!("{}/ad", self.base)
    }

    /// `…/ctl`: the coordinator's queryable for `naofarm ctl`.
    #[must_use]
    pub fn ctl(&self) -> String {
        format!("{}/ctl", self.base)
    }
}

/// `<prefix>/@runs/*/ad`: every run's advert.
#[must_use]
pub fn adverts_all(prefix: &str) -> String {
    format!("{prefix}/@runs/*/ad")
}

/// `<prefix>/@workers/<worker-id>`: a worker's liveliness token.
#[must_use]
pub fn worker(prefix: &str, worker_id: &str) -> String {
    format!("{prefix}/@workers/{worker_id}")
}

/// `<prefix>/@workers/*`: every worker's liveliness token.
#[must_use]
pub fn workers_all(prefix: &str) -> String {
    format!("{prefix}/@workers/*")
}

/// `<prefix>/@workers/<worker-id>/status`: a worker's public status (JSON).
#[must_use]
pub fn worker_status(prefix: &str, worker_id: &str) -> String {
    format!("{prefix}/@workers/{worker_id}/status")
}

/// `<prefix>/@workers/*/status`: every worker's public status.
#[must_use]
pub fn worker_statuses_all(prefix: &str) -> String {
    format!("{prefix}/@workers/*/status")
}

/// `<prefix>/@coordinators/*`: every coordinator's liveliness token.
#[must_use]
pub fn coordinators_all(prefix: &str) -> String {
    format!("{prefix}/@coordinators/*")
}

/// `<prefix>/@coordinators/<id>`: the liveliness token of a run's
/// coordinator (watchers notice a coordinator that stopped; a second
/// coordinator claiming the same run id is refused).
#[must_use]
pub fn coordinator(prefix: &str, id: &str) -> String {
    format!("{prefix}/@coordinators/{id}")
}

/// Extracts the last chunk of a key (a worker id from a liveliness key).
#[must_use]
pub fn last_chunk(key: &str) -> &str {
    key.rsplit('/').next().unwrap_or(key)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_have_the_documented_shape() {
        let k = RunKeys::new("naofarm", "r1", "u-1");
        assert_eq!(k.trial(3, 7), "naofarm/r1/u-1/trials/3/7");
        assert_eq!(k.results(3), "naofarm/r1/u-1/results/3");
        assert_eq!(k.status(), "naofarm/r1/u-1/status");
        assert_eq!(status_all("naofarm"), "naofarm/*/*/status");
        let f = FleetKeys::new("naofarm", "u-1");
        assert_eq!(f.work(), "naofarm/@runs/u-1/work");
        assert_eq!(f.outcomes(), "naofarm/@runs/u-1/outcomes");
        assert_eq!(adverts_all("naofarm"), "naofarm/@runs/*/ad");
        assert_eq!(worker("naofarm", "abc"), "naofarm/@workers/abc");
        assert_eq!(last_chunk("naofarm/@workers/abc"), "abc");
        assert_eq!(
            worker_status("naofarm", "abc"),
            "naofarm/@workers/abc/status"
        );
        assert_eq!(worker_of_status(&worker_status("naofarm", "abc")), "abc");
        assert_eq!(status_of("naofarm", "u-1"), "naofarm/*/u-1/status");
        assert_eq!(k.experiment(), "naofarm/r1/u-1/experiment");
        assert_eq!(results_all("naofarm"), "naofarm/*/*/results/*");
    }

    #[test]
    fn chunks_refuse_wildcards() {
        assert!(check_chunk("run", "a/b").is_err());
        assert!(check_chunk("run", "a*").is_err());
        assert!(check_chunk("run", "").is_err());
        assert!(check_chunk("run", "@x").is_err());
        assert!(check_chunk("run", "physical-technical_1.0").is_ok());
    }
}
