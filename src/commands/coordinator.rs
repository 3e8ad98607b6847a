//! `naofarm coordinator`: the coordinator alone (cluster use).

use crate::{
    args::{JobArgs, NetArgs},
    common::Failure,
    net::open_session,
    serve::{prepare_run, runtime_with, serve_with_view, signals, summary},
};

/// `naofarm coordinator`.
pub fn coordinator(job: &JobArgs, net: &NetArgs, json: bool) -> Result<(), Failure> {
    // Listening on 7447 by default, unless it connects to a router (many
    // coordinators then share one host).
    let default_listen: &[&str] = if net.connect.is_empty() {
        &["tcp/127.0.0.1:7447"]
    } else {
        &[]
    };
    let cfg = net
        .zenoh_config("coordinator", default_listen)
        .map_err(Failure::Usage)?;
    let prepared = prepare_run(job)?;
    // The service runs on zenoh's application thread, which also does all of
    // the coordinator's zenoh work: a message reaches the service without
    // waking another thread (docs/fleet.md, measured). This thread only
    // waits; one tokio worker for what the runtime needs beside it.
    // `NAOFARM_COORD_OWN_THREAD=1` serves on this thread instead, to measure.
    let rt = runtime_with(1)?;
    let (job, prefix, connect) = (job.clone(), net.prefix.clone(), net.connect.clone());
    let serve = async move {
        let session = open_session(cfg, "coordinator", &connect).await?;
        let (run, effects) = prepared.open_beside(&session).await?;
        crate::net::say_endpoints(&session, "coordinator").await;
        let shutdown = signals();
        let served = serve_with_view(&session, (run, effects), &job, &prefix, shutdown, json).await;
        let _ = session.close().await;
        let (ended, view) = served;
        summary(
            &job.out,
            &ended.map_err(crate::common::service_failure)?,
            view,
        )
    };
    rt.block_on(async {
        if std::env::var_os("NAOFARM_COORD_OWN_THREAD").is_some() {
            return serve.await;
        }
        zenoh_runtime::ZRuntime::Application
            .spawn(serve)
            .await
            .map_err(|e| Failure::Job(anyhow::anyhow!("the coordinator's task ended: {e}")))?
    })
}
