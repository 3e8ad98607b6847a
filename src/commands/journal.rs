//! `naofarm journal check DIR` and `naofarm journal salvage DIR --out NEW_DIR`.

use std::path::Path;

use coordinator::{
    journal::{Journal, Tail},
    run::{read_run, salvage, RunError},
};

use crate::{
    args::JournalCommand,
    common::{emit, not_a_run, Failure},
};

/// Runs a journal command.
pub fn journal(cmd: JournalCommand) -> Result<(), Failure> {
    match cmd {
        JournalCommand::Check { dir, json } => check(&dir, json),
        JournalCommand::Salvage { dir, out } => {
            if let Some(why) = not_a_run(&dir) {
                return Err(Failure::Usage(anyhow::Error::msg(why)));
            }
            let s = salvage(&dir, &out).map_err(|e| match e {
                RunError::OtherExperiment { .. }
                | RunError::SalvageOntoJournal(_)
                | RunError::NotARunDirectory { .. }
                | RunError::InsideARun { .. }
                | RunError::Locked(_) => Failure::Usage(e.into()),
                e => Failure::Job(e.into()),
            })?;
            let spans: Vec<String> = s
                .skipped
                .iter()
                .map(|(o, l)| format!("{l} bytes at offset {o}"))
                .collect();
            emit(&format!(
                "salvaged {} into {}: {} valid records read, skipped {}; {} outcomes carried over, {} left out \
                 (their iteration needs lost outcomes first; they will be run again), {} iterations decided. \
                 {} is unchanged; resume with `naofarm run EXPERIMENT --out {}`\n",
                dir.display(),
                out.display(),
                s.records,
                if spans.is_empty() { "nothing".into() } else { spans.join(", ") },
                s.outcomes,
                s.dropped,
                s.decided,
                dir.display(),
                out.display()
            ))
        }
    }
}

fn check(dir: &Path, json: bool) -> Result<(), Failure> {
    if let Some(why) = not_a_run(dir) {
        return Err(Failure::Usage(anyhow::Error::msg(why)));
    }
    let path = Journal::path_in(dir);
    let view = read_run(dir).map_err(|e| Failure::Job(e.into()))?;
    let tail = match (&view.tail, view.live) {
        (Tail::Clean, _) => "clean".to_string(),
        (Tail::Torn { offset, len }, true) => {
            format!("{len} bytes at offset {offset} being written (the run is live)")
        }
        (Tail::Torn { offset, len }, false) => format!(
            "torn: {len} bytes at offset {offset} are an interrupted append (a resume saves and cuts them)"
        ),
        (Tail::Damaged { .. }, _) => "damaged".into(),
    };
    if json {
        let v = serde_json::json!({
            "journal": path.display().to_string(),
            "format": view.format,
            "created_by": view.version,
            "run": view.experiment.name,
            "records": view.records,
            "decided": view.decided.len(),
            "planned": view.experiment.iterations,
            "extensions": view.extensions,
            "live": view.live,
            "tail": tail,
        });
        return emit(&format!("{v}\n"));
    }
    emit(&format!(
        "{}: format {}, created by naofarm {}, run `{}`; {} records, {} of {} iterations decided{}; tail {}\n",
        path.display(),
        view.format,
        view.version,
        view.experiment.name,
        view.records,
        view.decided.len(),
        view.experiment.iterations,
        if view.extensions.is_empty() {
            String::new()
        } else {
            format!(" (extended to {:?})", view.extensions)
        },
        tail
    ))
}
