//! `naofarm ctl RUN ACTION`: pauses, resumes or stops a run, or changes its
//! priority, from any machine that reaches its router. The coordinator
//! journals the action (a resume keeps it) and answers with the run's status.

use std::time::{Duration, Instant};

use anyhow::anyhow;
use protocol::{
    keys::FleetKeys,
    wire::{Control, ControlRequest, RunStatus, WireMessage},
};

use crate::{args::NetArgs, common::Failure, serve::runtime};

/// Parses `pause | resume | stop | priority N`.
pub fn parse_action(words: &[String]) -> Result<Control, String> {
    let words: Vec<&str> = words.iter().map(String::as_str).collect();
    let action = match words.as_slice() {
        ["pause"] => Control::Pause,
        ["resume"] => Control::Resume,
        ["stop"] => Control::Stop,
        ["priority", n] => Control::Priority(
            n.parse()
                .map_err(|_| format!("priority `{n}` is not a whole number"))?,
        ),
        _ => {
            return Err(format!(
                "unknown action `{}`: use pause, resume, stop or priority N",
                words.join(" ")
            ))
        }
    };
    action.check()?;
    Ok(action)
}

fn who() -> String {
    let user = std::env::var("USER").unwrap_or_else(|_| "someone".into());
    let host = std::fs::read_to_string("/proc/sys/kernel/hostname")
        .map(|h| h.trim().to_string())
        .unwrap_or_else(|_| "somewhere".into());
    format!("{user}@{host}")
}

/// `naofarm ctl`.
pub fn ctl(run: &str, words: &[String], net: &NetArgs, timeout_s: f64) -> Result<(), Failure> {
    let action = parse_action(words).map_err(|e| Failure::Usage(anyhow!(e)))?;
    protocol::keys::check_chunk("run", run).map_err(|e| Failure::Usage(anyhow!(e)))?;
    if !(timeout_s.is_finite() && timeout_s > 0.0 && timeout_s <= 3600.0) {
        return Err(Failure::Usage(anyhow!("--timeout-s must be in (0, 3600]")));
    }
    let mut net = net.clone();
    if net.connect.is_empty() && net.config.is_none() {
        net.connect
            .push(crate::net::default_connect(net.tls.is_some()));
    }
    let cfg = net
        .zenoh_config_within("coordinator", timeout_s)
        .map_err(Failure::Usage)?;
    let rt = runtime()?;
    rt.block_on(async {
        let session = crate::net::open_asking(cfg, &net.connect).await?;
        let deadline = Instant::now() + Duration::from_secs_f64(timeout_s);
        let status = crate::commands::watch::resolve(
            &session,
            &net.prefix,
            run,
            deadline,
            &net.connect.join(", "),
        )
        .await?;
        let req = ControlRequest { action, by: who() };
        let bytes = req.encode().map_err(|e| Failure::Job(e.into()))?;
        let replies = session
            .get(FleetKeys::new(&net.prefix, &status.id).ctl())
            .payload(bytes)
            .timeout(Duration::from_secs_f64(timeout_s))
            .await
            .map_err(|e| Failure::Job(anyhow!("zenoh: {e}")))?;
        let answer = match replies.recv_async().await {
            Ok(reply) => match reply.result() {
                Ok(sample) => {
                    let text = String::from_utf8_lossy(&sample.payload().to_bytes()).into_owned();
                    RunStatus::from_json(&text)
                        .map_err(|e| Failure::Job(anyhow!("the coordinator's answer: {e}")))
                }
                Err(e) => Err(Failure::Job(anyhow!(
                    "run {} refused: {}",
                    status.id,
                    String::from_utf8_lossy(&e.payload().to_bytes())
                ))),
            },
            Err(_) => Err(Failure::Job(anyhow!(
                "run {} did not answer within {timeout_s} s",
                status.id
            ))),
        };
        let _ = session.close().await;
        let s = answer?;
        outln!(
            "{} {}: {}, priority {}, {}/{} decided",
            s.run,
            s.id,
            format!("{:?}", s.state).to_lowercase(),
            s.priority,
            s.decided,
            s.planned
        );
        Ok(())
    })
}
