//! Every zenoh key expression naofarm uses, built in one place.
//!
//! The prefix is configurable (default [`DEFAULT_PREFIX`]); run names are
//! checked by [`check_chunk`] so they can never inject `/`, `*` or `$`.

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

/// `<prefix>/<run>/params/<iter>`: an iteration's parameter set.
#[must_use]
pub fn params(prefix: &str, run: &str, iter: u64) -> String {
    format!("{prefix}/{run}/params/{iter}")
}

/// `<prefix>/<run>/trials/<iter>/<k>`: one trial's outcome.
#[must_use]
pub fn trial(prefix: &str, run: &str, iter: u64, k: u32) -> String {
    format!("{prefix}/{run}/trials/{iter}/{k}")
}

/// `<prefix>/<run>/trials/**`: every trial outcome of a run.
#[must_use]
pub fn trials_all(prefix: &str, run: &str) -> String {
    format!("{prefix}/{run}/trials/**")
}

/// `<prefix>/<run>/results/<iter>`: an iteration's decision.
#[must_use]
pub fn results(prefix: &str, run: &str, iter: u64) -> String {
    format!("{prefix}/{run}/results/{iter}")
}

/// `<prefix>/<run>/results/*`: every result of a run.
#[must_use]
pub fn results_all(prefix: &str, run: &str) -> String {
    format!("{prefix}/{run}/results/*")
}

/// `<prefix>/<run>/status`: the run's state (queryable and published).
#[must_use]
pub fn status(prefix: &str, run: &str) -> String {
    format!("{prefix}/{run}/status")
}

/// `<prefix>/*/status`: the status of every run.
#[must_use]
pub fn status_all(prefix: &str) -> String {
    format!("{prefix}/*/status")
}

/// `<prefix>/<run>/history`: the decided iterations (queryable).
#[must_use]
pub fn history(prefix: &str, run: &str) -> String {
    format!("{prefix}/{run}/history")
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

/// `<prefix>/@work/<worker-id>`: trial requests addressed to one worker.
#[must_use]
pub fn work(prefix: &str, worker_id: &str) -> String {
    format!("{prefix}/@work/{worker_id}")
}

/// `<prefix>/@presence`: workers announce themselves and their free slots here.
#[must_use]
pub fn presence(prefix: &str) -> String {
    format!("{prefix}/@presence")
}

/// `<prefix>/@outcomes`: workers publish trial outcomes here for the coordinator.
#[must_use]
pub fn outcomes(prefix: &str) -> String {
    format!("{prefix}/@outcomes")
}

/// `<prefix>/@failures`: workers report trials they could not run here.
#[must_use]
pub fn failures(prefix: &str) -> String {
    format!("{prefix}/@failures")
}

/// `<prefix>/@coordinators/<run>`: the liveliness token of a run's coordinator
/// (watchers notice a coordinator that stopped).
#[must_use]
pub fn coordinator(prefix: &str, run: &str) -> String {
    format!("{prefix}/@coordinators/{run}")
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
        assert_eq!(trial("naofarm", "r1", 3, 7), "naofarm/r1/trials/3/7");
        assert_eq!(results("naofarm", "r1", 3), "naofarm/r1/results/3");
        assert_eq!(status("naofarm", "r1"), "naofarm/r1/status");
        assert_eq!(worker("naofarm", "abc"), "naofarm/@workers/abc");
        assert_eq!(last_chunk("naofarm/@workers/abc"), "abc");
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
