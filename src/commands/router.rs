//! `naofarm router`: a zenoh router inside the naofarm binary, so a cluster
//! needs one binary. Runs, workers and watchers connect to it; it routes and
//! stores nothing of naofarm's own.

use anyhow::anyhow;

use crate::{args::NetArgs, common::Failure, net::open_session, serve::runtime};

/// `naofarm router`.
pub fn router(
    listen: &[String],
    config: Option<&std::path::Path>,
    tls: Option<std::path::PathBuf>,
) -> Result<(), Failure> {
    let net = NetArgs {
        listen: listen.to_vec(),
        config: config.map(std::path::Path::to_path_buf),
        prefix: protocol::keys::DEFAULT_PREFIX.to_string(),
        tls,
        ..NetArgs::default()
    };
    let mut cfg = net
        .zenoh_config("router", &["tcp/0.0.0.0:7447"])
        .map_err(Failure::Usage)?;
    cfg.insert_json5("mode", "\"router\"")
        .map_err(|e| Failure::Usage(anyhow!("mode: {e}")))?;
    let rt = runtime()?;
    rt.block_on(async {
        let session = open_session(cfg, "router", &net.connect).await?;
        // The endpoints really bound (a `:0` port resolved), for scripts and tests.
        crate::net::say_endpoints(&session, "router").await;
        eprintln!("router ready (zid {})", session.zid());
        let mut shutdown = crate::serve::signals();
        while !*shutdown.borrow() {
            if shutdown.changed().await.is_err() {
                break;
            }
        }
        let _ = session.close().await;
        eprintln!("router stopped");
        Ok(())
    })
}
