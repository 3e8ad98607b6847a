//! `naofarm run`: a coordinator and local workers in one process, over zenoh
//! on loopback.

use anyhow::anyhow;

use crate::{
    args::{JobArgs, NetArgs, ProgramArgs},
    common::Failure,
    net::open_session,
    serve::{prepare_run, runtime, serve_with_view, signals, summary},
};

/// `naofarm run`: coordinator and local workers in one process, over zenoh on loopback.
pub fn run(
    job: &JobArgs,
    workers: Option<u32>,
    json: bool,
    listen: Option<&str>,
    tls: Option<std::path::PathBuf>,
    programs: &ProgramArgs,
) -> Result<(), Failure> {
    let n = workers.unwrap_or_else(|| {
        std::thread::available_parallelism()
            .ok()
            .and_then(|n| u32::try_from(n.get()).ok())
            .unwrap_or(1)
    });
    if n == 0 || n > 1024 {
        return Err(Failure::Usage(anyhow!(
            "--workers {n}: must be in 1..=1024"
        )));
    }
    let scheme = if tls.is_some() { "tls" } else { "tcp" };
    let endpoint = match listen {
        Some(e)
            if e.starts_with(&format!("{scheme}/127."))
                || e.starts_with(&format!("{scheme}/[::1]")) =>
        {
            e.to_string()
        }
        Some(e) => {
            return Err(Failure::Usage(anyhow!(
                "--listen `{e}`: `run` serves on loopback only ({scheme}/127.0.0.1:PORT); use `coordinator` and `worker` for a cluster"
            )))
        }
        // A port the OS picks, read back from the session.
        None => format!("{scheme}/127.0.0.1:0"),
    };
    let coord_net = NetArgs {
        listen: vec![endpoint],
        prefix: protocol::keys::DEFAULT_PREFIX.to_string(),
        tls: tls.clone(),
        ..NetArgs::default()
    };
    let ccfg = coord_net
        .zenoh_config("coordinator", &[])
        .map_err(Failure::Usage)?;
    // Local workers run only what they are given: without the program, a
    // program's run would wait for workers that never come.
    let (exp, _) = crate::common::load_experiment(&job.experiment)?;
    if let Some(p) = &exp.program {
        let given = programs
            .programs
            .iter()
            .any(|s| s.split_once('=').is_some_and(|(n, _)| n == p));
        if !given {
            return Err(Failure::Usage(anyhow!(
                "{}: its trials run the program `{p}`; give the local workers it with --program {p}=PATH",
                job.experiment.display()
            )));
        }
    }
    let prepared = prepare_run(job)?;
    let rt = runtime()?;
    rt.block_on(async {
        let programs = crate::common::register_programs(programs, n).await?;
        let session = open_session(ccfg, "coordinator", &coord_net.connect).await?;
        let (run, effects) = prepared.open_beside(&session).await?;
        let endpoint = session
            .info()
            .locators()
            .await
            .into_iter()
            .map(|l| l.to_string())
            .find(|l| l.starts_with(&format!("{scheme}/127.")))
            .ok_or_else(|| Failure::Job(anyhow!("the session listens on no loopback endpoint")))?;
        let tls_flag = tls
            .as_ref()
            .map(|d| format!(" --tls {}", d.display()))
            .unwrap_or_default();
        let name = &run.evolve().experiment().name;
        eprintln!(
            "zenoh on {endpoint}; watch from another terminal with `naofarm watch {name} --connect \
             {endpoint}{tls_flag}`, or in a browser with `naofarm web --connect {endpoint}{tls_flag}`"
        );
        let worker_net = NetArgs {
            connect: vec![endpoint],
            listen: vec![],
            prefix: protocol::keys::DEFAULT_PREFIX.to_string(),
            config: None,
            tls,
        };
        let shutdown = signals();
        // The workers stop when the run ends or on a signal, and are waited
        // for: each stops its programs and removes its scratch space.
        let (stop_workers, workers_stop) = tokio::sync::watch::channel(false);
        let mut on_signal = shutdown.clone();
        let forward = stop_workers.clone();
        tokio::spawn(async move {
            if on_signal.wait_for(|s| *s).await.is_ok() {
                let _ = forward.send(true);
            }
        });
        let mut handles = Vec::new();
        let mut worker_sessions = Vec::new();
        for _ in 0..n {
            let wcfg = worker_net.zenoh_config("worker", &[]).map_err(Failure::Job)?;
            let ws = open_session(wcfg, "worker", &worker_net.connect).await?;
            worker_sessions.push(ws.clone());
            let cfg = worker::service::WorkerConfig {
                slots: 1,
                programs: programs.clone(),
                ..worker::service::WorkerConfig::default()
            };
            handles.push(tokio::spawn(worker::service::serve(
                ws,
                cfg,
                workers_stop.clone(),
            )));
        }
        let (ended, view) = serve_with_view(
            &session,
            (run, effects),
            job,
            protocol::keys::DEFAULT_PREFIX,
            shutdown,
            json,
        )
        .await;
        let _ = stop_workers.send(true);
        for h in handles {
            match h.await {
                Ok(Ok(_)) => {}
                Ok(Err(e)) => tracing::warn!(error = %e, "a local worker failed"),
                Err(e) => tracing::warn!(error = %e, "a local worker's task ended"),
            }
        }
        for ws in &worker_sessions {
            let _ = ws.close().await;
        }
        let _ = session.close().await;
        let ended = ended.map_err(crate::common::service_failure)?;
        summary(&job.out, &ended, view)
    })
}
