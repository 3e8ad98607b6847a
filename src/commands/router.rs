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
    if net.tls.is_some() && config.is_none() {
        // Roles by certificate common name: what the ACL denies never reaches naofarm.
        cfg.insert_json5("access_control", &acl(&net.prefix))
            .map_err(|e| Failure::Usage(anyhow!("access control: {e}")))?;
    }
    let rt = runtime()?;
    rt.block_on(async {
        let session = open_session(cfg).await?;
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

/// The router's access control by role (a certificate's common name): each
/// role may send and receive only what its part of the fleet design needs.
/// Work reaches only the worker that asked (a query's reply goes only to its
/// querier), so workers need no per-worker rules.
#[must_use]
pub fn acl(prefix: &str) -> String {
    let p = prefix;
    let runs = |k: &str| format!("{p}/@runs/*/{k}");
    let public = |k: &str| format!("{p}/*/*/{k}");
    // (role, flow, messages, keys)
    let rules: Vec<(&str, &str, &[&str], Vec<String>)> = vec![
        // A worker: puts outcomes, failures, heartbeats; asks for work; holds its token; hears adverts.
        (
            "worker",
            "ingress",
            &["put"],
            vec![runs("outcomes"), runs("failures"), runs("presence")],
        ),
        ("worker", "ingress", &["query"], vec![runs("work")]),
        ("worker", "egress", &["reply"], vec![runs("work")]),
        (
            "worker",
            "ingress",
            &["liveliness_token"],
            vec![format!("{p}/@workers/*")],
        ),
        (
            "worker",
            "ingress",
            &["declare_subscriber"],
            vec![runs("ad")],
        ),
        ("worker", "egress", &["put"], vec![runs("ad")]),
        // A coordinator: hears its fleet keys, answers work, ctl, status and history,
        // publishes the watched topics and its advert, holds its token, watches workers' tokens.
        (
            "coordinator",
            "ingress",
            &["declare_subscriber"],
            vec![runs("outcomes"), runs("failures"), runs("presence")],
        ),
        (
            "coordinator",
            "egress",
            &["put"],
            vec![runs("outcomes"), runs("failures"), runs("presence")],
        ),
        (
            "coordinator",
            "ingress",
            &["declare_queryable", "reply"],
            vec![
                runs("work"),
                runs("ctl"),
                public("status"),
                public("history"),
            ],
        ),
        (
            "coordinator",
            "egress",
            &["query"],
            vec![
                runs("work"),
                runs("ctl"),
                public("status"),
                public("history"),
            ],
        ),
        (
            "coordinator",
            "ingress",
            &["put"],
            vec![
                runs("ad"),
                public("params/*"),
                public("trials/**"),
                public("results/*"),
                public("status"),
            ],
        ),
        (
            "coordinator",
            "ingress",
            &["liveliness_token", "liveliness_query"],
            vec![format!("{p}/@coordinators/*")],
        ),
        (
            "coordinator",
            "egress",
            &["liveliness_token"],
            vec![format!("{p}/@coordinators/*"), format!("{p}/@workers/*")],
        ),
        (
            "coordinator",
            "ingress",
            &["declare_liveliness_subscriber"],
            vec![format!("{p}/@workers/*")],
        ),
        // `naofarm ctl` runs with the coordinator's certificate: it asks runs.
        (
            "coordinator",
            "ingress",
            &["query"],
            vec![runs("ctl"), public("status")],
        ),
        (
            "coordinator",
            "egress",
            &["reply"],
            vec![runs("ctl"), public("status")],
        ),
        // A watcher: subscribes to and queries the public topics, follows coordinators' tokens.
        (
            "watcher",
            "ingress",
            &["declare_subscriber"],
            vec![
                public("params/*"),
                public("trials/**"),
                public("results/*"),
                public("status"),
            ],
        ),
        (
            "watcher",
            "egress",
            &["put"],
            vec![
                public("params/*"),
                public("trials/**"),
                public("results/*"),
                public("status"),
            ],
        ),
        (
            "watcher",
            "ingress",
            &["query"],
            vec![public("status"), public("history")],
        ),
        (
            "watcher",
            "egress",
            &["reply"],
            vec![public("status"), public("history")],
        ),
        (
            "watcher",
            "ingress",
            &["declare_liveliness_subscriber"],
            vec![format!("{p}/@coordinators/*")],
        ),
        (
            "watcher",
            "egress",
            &["liveliness_token"],
            vec![format!("{p}/@coordinators/*")],
        ),
    ];
    let mut rule_json = Vec::new();
    let mut policies: std::collections::BTreeMap<&str, Vec<String>> =
        std::collections::BTreeMap::new();
    for (i, (role, flow, messages, keys)) in rules.iter().enumerate() {
        let id = format!("r{i}_{role}");
        rule_json.push(serde_json::json!({
            "id": id,
            "permission": "allow",
            "flows": [flow],
            "messages": messages,
            "key_exprs": keys,
        }));
        policies.entry(role).or_default().push(id);
    }
    let subjects: Vec<serde_json::Value> = policies
        .keys()
        .map(|r| serde_json::json!({"id": r, "cert_common_names": [r]}))
        .collect();
    let policy_json: Vec<serde_json::Value> = policies
        .iter()
        .map(|(r, ids)| serde_json::json!({"id": format!("p_{r}"), "subjects": [r], "rules": ids}))
        .collect();
    serde_json::json!({
        "enabled": true,
        "default_permission": "deny",
        "rules": rule_json,
        "subjects": subjects,
        "policies": policy_json,
    })
    .to_string()
}
