//! The progress view of a run, shared by `run`, `coordinator` and `watch`:
//! a terminal view (a progress bar on stderr, one line per decided iteration
//! on stdout) or one JSON line per event (`--json`).
//!
//! JSON events: `{"event": "history", "result": IterationResult}` for each
//! iteration decided before the view started, `{"event": "decided", "result":
//! IterationResult}`, `{"event": "status", "status": RunStatus}`, `{"event":
//! "trial", "outcome": TrialOutcome}` (watch only) and a last `{"event":
//! "finished", "status": RunStatus, …}`. Each iteration is reported once.

use std::{collections::BTreeSet, time::Instant};

use indicatif::{ProgressBar, ProgressStyle};
use protocol::wire::{Best, IterationResult, RunStatus, TrialOutcome};

/// A view of one run.
pub struct View {
    json: bool,
    bar: ProgressBar,
    seen: BTreeSet<u64>,
    started: Instant,
    decided_at_start: Option<u64>,
}

fn metres(v: Option<f64>) -> String {
    v.map_or("-".to_string(), |v| format!("{v:.3}"))
}

fn params(p: &[(String, f64)]) -> String {
    p.iter()
        .map(|(n, v)| format!("{n} = {v:.4}"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// ν′ in one line: its iteration, statistics (m) and, after `sep`, its parameters.
fn best_line(b: &Best, sep: &str) -> String {
    format!(
        "iteration {} s {:.2} mx {} my {} ex {}{sep}{}",
        b.iteration,
        b.stats.s,
        metres(b.stats.mx),
        metres(b.stats.my),
        metres(b.stats.ex),
        params(&b.params)
    )
}

/// A message as a JSON value (one that cannot be encoded says so, never null).
fn json_of<T: serde::Serialize>(m: &T) -> serde_json::Value {
    serde_json::to_value(m).unwrap_or_else(|e| serde_json::json!({ "unencodable": e.to_string() }))
}

impl View {
    /// A view printing JSON lines (`json`) or drawing the terminal view.
    pub fn new(json: bool) -> Self {
        let bar = if json {
            ProgressBar::hidden()
        } else {
            let bar = ProgressBar::new(0);
            if let Ok(style) = ProgressStyle::with_template(
                "{bar:40.cyan/blue} {pos}/{len} iterations  {msg}\n{prefix}",
            ) {
                bar.set_style(style);
            }
            bar
        };
        Self {
            json,
            bar,
            seen: BTreeSet::new(),
            started: Instant::now(),
            decided_at_start: None,
        }
    }

    fn line(&self, text: &str) {
        if self.bar.is_hidden() {
            outln!("{text}");
        } else {
            self.bar.println(text);
        }
    }

    fn event(&self, value: &serde_json::Value) {
        outln!("{value}");
    }

    /// Iterations decided before the view started (a status query's history).
    pub fn history(&mut self, results: &[IterationResult]) {
        for r in results {
            if !self.seen.insert(r.iteration) {
                continue;
            }
            if self.json {
                self.event(&serde_json::json!({"event": "history", "result": json_of(r)}));
            }
        }
        if !self.json && !results.is_empty() {
            self.line(&format!(
                "{} iterations decided before this view started",
                results.len()
            ));
        }
    }

    /// A newly decided iteration; false (and nothing shown) if already reported.
    pub fn decided(&mut self, r: &IterationResult) -> bool {
        if !self.seen.insert(r.iteration) {
            return false;
        }
        if self.json {
            self.event(&serde_json::json!({"event": "decided", "result": json_of(r)}));
        } else {
            self.line(&format!(
                "iteration {:>4} {:<10} s {:.2} mx {} my {} ex {}",
                r.iteration,
                r.decision.as_str(),
                r.stats.s,
                metres(r.stats.mx),
                metres(r.stats.my),
                metres(r.stats.ex),
            ));
        }
        true
    }

    /// The iterations reported so far (history and decided).
    pub fn reported(&self) -> usize {
        self.seen.len()
    }

    /// A trial outcome (JSON view only; the terminal view shows rates instead).
    pub fn trial(&self, o: &TrialOutcome) {
        if self.json {
            self.event(&serde_json::json!({"event": "trial", "outcome": json_of(o)}));
        }
    }

    /// The run's status after an event.
    pub fn status(&mut self, s: &RunStatus) {
        if self.json {
            self.event(&serde_json::json!({"event": "status", "status": json_of(s)}));
            return;
        }
        let first = *self.decided_at_start.get_or_insert(s.decided);
        let done = s.decided.saturating_sub(first);
        #[allow(clippy::cast_precision_loss)]
        let eta = if done > 0 {
            let per = self.started.elapsed().as_secs_f64() / done as f64;
            let left = per * s.planned.saturating_sub(s.decided) as f64;
            format!("ETA {:.0}m{:02.0}s", (left / 60.0).floor(), left % 60.0)
        } else {
            "ETA -".to_string()
        };
        self.bar.set_length(s.planned);
        self.bar.set_position(s.decided);
        self.bar.set_message(format!(
            "A {} E {} R {} | {:.1} trials/s | {eta} | {} workers",
            s.accepts, s.equivalents, s.rejects, s.trials_per_s, s.workers
        ));
        self.bar.set_prefix(match &s.best {
            Some(b) => format!("best: {}", best_line(b, " | ")),
            None => "best: none accepted yet".to_string(),
        });
    }

    /// The end of a finished run: Optim.1 (ν′, the best-first agent) and
    /// Optim.2 (CLOP's mean, the best-average agent); `extra` joins the JSON line.
    pub fn finish(&mut self, s: &RunStatus, extra: serde_json::Value) {
        if self.json {
            let mut line = serde_json::json!({"event": "finished", "status": json_of(s)});
            if let (Some(obj), serde_json::Value::Object(more)) = (line.as_object_mut(), extra) {
                obj.extend(more);
            }
            self.event(&line);
            return;
        }
        self.bar.finish_and_clear();
        match &s.best {
            Some(b) => outln!("Optim.1 (nu'): {}", best_line(b, "\n  ")),
            None => outln!("Optim.1: no parameter set was accepted"),
        }
        outln!("Optim.2 (CLOP's mean):\n  {}", params(&s.optim2));
    }

    /// Clears the terminal view without a summary (interrupted, failed).
    pub fn abandon(&self) {
        self.bar.finish_and_clear();
    }
}
