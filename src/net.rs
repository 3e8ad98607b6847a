//! The zenoh configuration of every networked subcommand: a file in zenoh's
//! own json5 format first, then flags.

use crate::args::NetArgs;
use anyhow::Context;

fn json_list(v: &[String]) -> String {
    serde_json::to_string(v).unwrap_or_else(|_| "[]".into())
}

impl NetArgs {
    /// Builds the zenoh config. Without a file, multicast scouting is off:
    /// naofarm finds its peers through explicit endpoints only.
    pub fn zenoh_config(&self, default_listen: &[&str]) -> anyhow::Result<zenoh::Config> {
        protocol::keys::check_chunk("prefix", &self.prefix).map_err(anyhow::Error::msg)?;
        let mut cfg = match &self.config {
            Some(p) => zenoh::Config::from_file(p)
                .map_err(|e| anyhow::anyhow!("{e}"))
                .with_context(|| format!("zenoh config {}", p.display()))?,
            None => {
                let mut c = zenoh::Config::default();
                c.insert_json5("scouting/multicast/enabled", "false")
                    .map_err(|e| anyhow::anyhow!("{e}"))?;
                c.insert_json5("transport/link/tx/lease", "3000")
                    .map_err(|e| anyhow::anyhow!("{e}"))?;
                let listen: Vec<String> = default_listen.iter().map(|s| (*s).to_string()).collect();
                c.insert_json5("listen/endpoints", &json_list(&listen))
                    .map_err(|e| anyhow::anyhow!("{e}"))?;
                c
            }
        };
        if !self.listen.is_empty() {
            cfg.insert_json5("listen/endpoints", &json_list(&self.listen))
                .map_err(|e| anyhow::anyhow!("--listen: {e}"))?;
        }
        if !self.connect.is_empty() {
            cfg.insert_json5("connect/endpoints", &json_list(&self.connect))
                .map_err(|e| anyhow::anyhow!("--connect: {e}"))?;
        }
        Ok(cfg)
    }
}

/// A free TCP port on 127.0.0.1 (for the embedded run's loopback endpoint).
pub fn free_loopback_port() -> anyhow::Result<u16> {
    let l = std::net::TcpListener::bind("127.0.0.1:0").context("bind 127.0.0.1:0")?;
    Ok(l.local_addr()?.port())
}

/// Opens a zenoh session (the one place every command does).
pub async fn open_session(cfg: zenoh::Config) -> Result<zenoh::Session, crate::common::Failure> {
    zenoh::open(cfg)
        .await
        .map_err(|e| crate::common::Failure::Job(anyhow::anyhow!("zenoh: {e}")))
}
