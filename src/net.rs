//! The zenoh configuration of every networked subcommand: a file in zenoh's
//! own json5 format first, then flags.

use crate::args::NetArgs;
use anyhow::Context;

fn json_list(v: &[String]) -> String {
    serde_json::to_string(v).unwrap_or_else(|_| "[]".into())
}

impl NetArgs {
    /// Builds the zenoh config. Without a file, multicast scouting is off:
    /// naofarm finds its peers through explicit endpoints only, and a
    /// process that only connects (no endpoint to listen on) is a zenoh
    /// client: a peer without listeners behind a router is not routed to.
    pub fn zenoh_config(
        &self,
        role: &str,
        default_listen: &[&str],
    ) -> anyhow::Result<zenoh::Config> {
        let tls_listen: Vec<String>;
        let default_listen: Vec<&str> = if self.tls.is_some() {
            tls_listen = default_listen
                .iter()
                .map(|e| e.replacen("tcp/", "tls/", 1))
                .collect();
            tls_listen.iter().map(String::as_str).collect()
        } else {
            default_listen.to_vec()
        };
        let default_listen = default_listen.as_slice();
        protocol::keys::check_chunk("prefix", &self.prefix).map_err(anyhow::Error::msg)?;
        let mut cfg = match &self.config {
            Some(p) => zenoh::Config::from_file(p)
                .map_err(|e| anyhow::anyhow!("{}", zenoh_error(&e)))
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
        for e in &self.listen {
            check_endpoint("--listen", e, true)?;
        }
        for e in &self.connect {
            check_endpoint("--connect", e, false)?;
        }
        if !self.listen.is_empty() {
            cfg.insert_json5("listen/endpoints", &json_list(&self.listen))
                .map_err(|e| anyhow::anyhow!("--listen: {e}"))?;
        }
        if !self.connect.is_empty() {
            cfg.insert_json5("connect/endpoints", &json_list(&self.connect))
                .map_err(|e| anyhow::anyhow!("--connect: {e}"))?;
        }
        if self.config.is_none()
            && self.listen.is_empty()
            && default_listen.is_empty()
            && !self.connect.is_empty()
        {
            // Only connecting (to a router, or to a coordinator that listens):
            // a client, so that everything it says is routed, not lost
            // on a peer nobody can reach.
            cfg.insert_json5("mode", "\"client\"")
                .map_err(|e| anyhow::anyhow!("mode: {e}"))?;
            // Wait for the router (or coordinator) to come up, as peers do.
            cfg.insert_json5("connect/timeout_ms", "-1")
                .map_err(|e| anyhow::anyhow!("connect: {e}"))?;
            cfg.insert_json5("connect/exit_on_failure", "false")
                .map_err(|e| anyhow::anyhow!("connect: {e}"))?;
        }
        if let Some(dir) = &self.tls {
            tls(&mut cfg, dir, role)?;
            for e in self.listen.iter().chain(&self.connect) {
                if !e.starts_with("tls/") {
                    anyhow::bail!("`{e}`: with --tls every endpoint is tls/HOST:PORT");
                }
            }
            // The roles by certificate common name, enforced by the router
            // and by a coordinator that workers and watchers reach directly
            // (no router between); a configuration file may bring its own.
            let listens = !self.listen.is_empty() || !default_listen.is_empty();
            let enforces = match role {
                "router" => true,
                "coordinator" => listens && self.connect.is_empty() && self.config.is_none(),
                _ => false,
            };
            let own_acl = cfg
                .get_json("access_control/enabled")
                .is_ok_and(|v| v.trim() == "true");
            if enforces && !own_acl {
                cfg.insert_json5("access_control", &acl(&self.prefix))
                    .map_err(|e| anyhow::anyhow!("access control: {e}"))?;
            }
        }
        Ok(cfg)
    }

    /// As [`NetArgs::zenoh_config`], for a command that gives up: connecting
    /// fails after `timeout_s` instead of waiting for the other end.
    pub fn zenoh_config_within(&self, role: &str, timeout_s: f64) -> anyhow::Result<zenoh::Config> {
        let mut cfg = self.zenoh_config(role, &[])?;
        if self.config.is_none() {
            #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
            let ms = (timeout_s * 1000.0).ceil() as u64;
            cfg.insert_json5("connect/timeout_ms", &ms.to_string())
                .map_err(|e| anyhow::anyhow!("connect: {e}"))?;
            cfg.insert_json5("connect/exit_on_failure", "true")
                .map_err(|e| anyhow::anyhow!("connect: {e}"))?;
        }
        Ok(cfg)
    }
}

/// The link protocols this build of zenoh has (Cargo.toml's features).
const PROTOCOLS: [&str; 3] = ["tcp", "tls", "udp"];

/// Checks one endpoint of `flag` before zenoh sees it, so that a typo is a
/// usage error naming it, not a session that waits for ever on an address
/// nothing can answer: zenoh's syntax, a protocol this build has, and
/// HOST:PORT with an IPv4 address, a bracketed IPv6 one or a host name, and
/// a port in 1..=65535 (0 too when listening: the system picks one).
fn check_endpoint(flag: &str, e: &str, listening: bool) -> anyhow::Result<()> {
    let bad = |why: &str| {
        anyhow::anyhow!(
            "{flag} `{e}`: {why}; an endpoint is PROTOCOL/HOST:PORT, e.g. tcp/10.0.0.5:7447"
        )
    };
    let endpoint: zenoh::config::EndPoint = e.parse().map_err(|_| bad("not a zenoh endpoint"))?;
    let protocol = endpoint.protocol();
    if !PROTOCOLS.contains(&protocol.as_str()) {
        return Err(bad(&format!(
            "`{}` is not a protocol naofarm speaks ({})",
            protocol.as_str(),
            PROTOCOLS.join(", ")
        )));
    }
    let address = endpoint.address();
    let (host, port) = address
        .as_str()
        .rsplit_once(':')
        .ok_or_else(|| bad("no port"))?;
    match port.parse::<u16>() {
        Ok(0) if !listening => return Err(bad("port 0 cannot be connected to")),
        Ok(_) => {}
        Err(_) => return Err(bad(&format!("port `{port}` is not in 0..=65535"))),
    }
    let host_ok = if let Some(inner) = host.strip_prefix('[') {
        inner
            .strip_suffix(']')
            .is_some_and(|ip| ip.parse::<std::net::Ipv6Addr>().is_ok())
    } else if host.chars().all(|c| c.is_ascii_digit() || c == '.') {
        host.parse::<std::net::Ipv4Addr>().is_ok()
    } else {
        host.split('.').all(|label| {
            !label.is_empty() && label.chars().all(|c| c.is_ascii_alphanumeric() || c == '-')
        })
    };
    if host_ok {
        Ok(())
    } else {
        Err(bad(&format!("`{host}` is no IP address or host name")))
    }
}

/// Where `watch` and `ctl` connect when no endpoint or file is given: a
/// coordinator's default listener on this host (over TLS with `--tls`).
#[must_use]
pub fn default_connect(tls: bool) -> String {
    let scheme = if tls { "tls" } else { "tcp" };
    format!("{scheme}/127.0.0.1:7447")
}

/// How long a connecting session may go without reaching the other end
/// before its command says what it waits for.
const WAIT_NOTICE: std::time::Duration = std::time::Duration::from_secs(3);

/// Opens a zenoh session (the one place every command does). A session
/// that connects waits in zenoh's open for the other end to come up (a
/// router or coordinator started later); when that takes longer than
/// [`WAIT_NOTICE`], `ROLE: waiting for ENDPOINTS …` on stderr says so, and
/// `ROLE: connected to ENDPOINTS` once it is there, instead of a silent
/// wait.
pub async fn open_session(
    cfg: zenoh::Config,
    role: &str,
    connect: &[String],
) -> Result<zenoh::Session, crate::common::Failure> {
    // A thread of its own: zenoh's open may hold the runtime's threads.
    let (opened, notice) = std::sync::mpsc::channel::<()>();
    if !connect.is_empty() {
        let (role, connect) = (role.to_string(), connect.join(", "));
        std::thread::spawn(move || {
            if let Err(std::sync::mpsc::RecvTimeoutError::Timeout) =
                notice.recv_timeout(WAIT_NOTICE)
            {
                eprintln!(
                    "{role}: waiting for {connect}: nothing answers there yet (start a router or coordinator there, or check the endpoint); still trying"
                );
                if notice.recv().is_ok() {
                    eprintln!("{role}: connected to {connect}");
                }
            }
        });
    }
    let session = zenoh::open(cfg)
        .await
        .map_err(|e| crate::common::Failure::Job(anyhow::anyhow!("zenoh: {}", zenoh_error(&e))))?;
    // The notice thread may have ended already (no notice to give).
    let _ = opened.send(());
    Ok(session)
}

/// Prints the endpoints a session really listens on (a `:0` port resolved):
/// `ROLE listening on ENDPOINT`, one line each, for scripts and tests.
pub async fn say_endpoints(session: &zenoh::Session, role: &str) {
    for l in session.info().locators().await {
        eprintln!("{role} listening on {l}");
    }
}

/// Opens a session for a command that only asks (watch, ctl): a connection
/// that cannot be made says that nothing answers there.
pub async fn open_asking(
    cfg: zenoh::Config,
    connect: &[String],
) -> Result<zenoh::Session, crate::common::Failure> {
    zenoh::open(cfg).await.map_err(|e| {
        crate::common::Failure::Job(anyhow::anyhow!(
            "nothing answers at {}: no coordinator or router listens there, so the run is finished or unknown ({})",
            connect.join(", "),
            zenoh_error(&e)
        ))
    })
}

/// A zenoh error as a user reads it: without the places in zenoh's own
/// source that its messages carry (` at /…/src/unicast.rs:338.`).
fn zenoh_error(e: &dyn std::fmt::Display) -> String {
    let text = e.to_string();
    let mut out = String::with_capacity(text.len());
    let mut rest = text.as_str();
    while let Some(i) = rest.find(" at /") {
        out.push_str(&rest[..i]);
        let after = &rest[i + 4..];
        let end = after.find(char::is_whitespace).unwrap_or(after.len());
        let place = after[..end].trim_end_matches(['.', ']', ')']);
        let is_source = place
            .rsplit_once(".rs:")
            .is_some_and(|(_, line)| !line.is_empty() && line.bytes().all(|b| b.is_ascii_digit()));
        if is_source {
            // Keep what closed around the place (`]`, `)`), not its full stop.
            let tail = &after[place.len()..end];
            out.push_str(tail.trim_start_matches('.'));
        } else {
            out.push_str(&rest[i..i + 4 + end]);
        }
        rest = &after[end..];
    }
    out.push_str(rest);
    serde_message(&out)
}

/// serde's debug form of a config error (`JSON error: Message { msg: "…",
/// location: Some(Location { line: 1, column: 8 }) }`) as a sentence:
/// `JSON error: … (line 1, column 8)`. Any other text is kept as it is.
fn serde_message(text: &str) -> String {
    const OPEN: &str = "Message { msg: \"";
    let Some(start) = text.find(OPEN) else {
        return text.to_string();
    };
    let body = &text[start + OPEN.len()..];
    // The message ends at the first unescaped quote.
    let mut msg = String::new();
    let mut chars = body.char_indices();
    let mut end = None;
    while let Some((i, c)) = chars.next() {
        match c {
            '\\' => match chars.next() {
                Some((_, 'n')) => msg.push(' '),
                Some((_, e)) => msg.push(e),
                None => break,
            },
            '"' => {
                end = Some(i + 1);
                break;
            }
            c => msg.push(c),
        }
    }
    let Some(end) = end else {
        return text.to_string();
    };
    let after = &body[end..];
    let number = |key: &str| -> Option<u64> {
        let from = after.find(key)? + key.len();
        let digits: String = after[from..]
            .chars()
            .take_while(char::is_ascii_digit)
            .collect();
        digits.parse().ok()
    };
    let place = match (number("line: "), number("column: ")) {
        (Some(l), Some(c)) => format!(" (line {l}, column {c})"),
        _ => String::new(),
    };
    // What follows the `}` that closes `Message {`, if anything.
    let mut depth = 1;
    let close = after.char_indices().find_map(|(i, c)| {
        match c {
            '{' => depth += 1,
            '}' => depth -= 1,
            _ => {}
        }
        (depth == 0).then_some(i + 1)
    });
    let tail = close.map_or("", |i| &after[i..]);
    format!("{}{msg}{place}{tail}", &text[..start])
}

/// Mutual TLS for a session of `role` with the certificates in `dir`
/// (`naofarm certs`): the CA, and the role's certificate and key for both
/// the links it accepts and the links it opens.
pub fn tls(cfg: &mut zenoh::Config, dir: &std::path::Path, role: &str) -> anyhow::Result<()> {
    let file = |name: &str| -> anyhow::Result<String> {
        let p = dir.join(name);
        if !p.is_file() {
            anyhow::bail!(
                "--tls {}: no {name} (create the certificates with `naofarm certs {}`)",
                dir.display(),
                dir.display()
            );
        }
        serde_json::to_string(&p.display().to_string()).map_err(anyhow::Error::from)
    };
    let ca = file("ca.pem")?;
    let cert = file(&format!("{role}.pem"))?;
    let key = file(&format!("{role}.key"))?;
    for (k, v) in [
        ("transport/link/tls/root_ca_certificate", ca.as_str()),
        ("transport/link/tls/enable_mtls", "true"),
        ("transport/link/tls/listen_certificate", cert.as_str()),
        ("transport/link/tls/listen_private_key", key.as_str()),
        ("transport/link/tls/connect_certificate", cert.as_str()),
        ("transport/link/tls/connect_private_key", key.as_str()),
    ] {
        cfg.insert_json5(k, v)
            .map_err(|e| anyhow::anyhow!("--tls: {k}: {e}"))?;
    }
    Ok(())
}

/// The router's access control by role (a certificate's common name): each
/// role may send and receive only what its part of the fleet design needs.
/// Work reaches only the worker that asked (a query's reply goes only to its
/// querier), so workers need no per-worker rules. One rule per line: role,
/// flow, messages, keys (`runs/K` is `<prefix>/@runs/*/K`, `pub/K` is
/// `<prefix>/*/*/K`, `@…` is `<prefix>/@…`).
const ACL_RULES: &str = "\
worker      ingress put                                runs/outcomes runs/failures runs/presence
worker      ingress query                              runs/work
worker      egress  reply                              runs/work
worker      ingress liveliness_token                   @workers/*
worker      ingress put                                @workers/*/status
worker      ingress declare_subscriber                 runs/ad
worker      egress  put                                runs/ad
coordinator ingress declare_subscriber                 runs/outcomes runs/failures runs/presence
coordinator egress  put                                runs/outcomes runs/failures runs/presence
coordinator ingress declare_queryable,reply            runs/work runs/ctl pub/status pub/history pub/experiment
coordinator egress  query                              runs/work runs/ctl pub/status pub/history pub/experiment
coordinator ingress put                                runs/ad pub/params/* pub/trials/** pub/results/* pub/status
coordinator ingress liveliness_token,liveliness_query  @coordinators/*
coordinator egress  liveliness_token                   @coordinators/* @workers/*
coordinator ingress declare_liveliness_subscriber      @workers/*
coordinator ingress query                              runs/ctl pub/status
coordinator egress  reply                              runs/ctl pub/status
watcher     ingress declare_subscriber                 pub/params/* pub/trials/** pub/results/* pub/status @workers/*/status
watcher     egress  put                                pub/params/* pub/trials/** pub/results/* pub/status @workers/*/status
watcher     ingress query                              pub/status pub/history pub/experiment
watcher     egress  reply                              pub/status pub/history pub/experiment
watcher     ingress declare_liveliness_subscriber      @coordinators/* @workers/*
watcher     egress  liveliness_token                   @coordinators/* @workers/*
";

/// [`ACL_RULES`] as zenoh's `access_control` configuration (JSON), under `prefix`.
#[must_use]
pub fn acl(prefix: &str) -> String {
    let key = |k: &str| {
        if let Some(rest) = k.strip_prefix("runs/") {
            format!("{prefix}/@runs/*/{rest}")
        } else if let Some(rest) = k.strip_prefix("pub/") {
            format!("{prefix}/*/*/{rest}")
        } else {
            format!("{prefix}/{k}")
        }
    };
    let rules: Vec<(&str, &str, Vec<&str>, Vec<String>)> = ACL_RULES
        .lines()
        .filter_map(|l| {
            let mut w = l.split_whitespace();
            let (role, flow, messages) = (w.next()?, w.next()?, w.next()?);
            Some((
                role,
                flow,
                messages.split(',').collect(),
                w.map(key).collect(),
            ))
        })
        .collect();
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

#[cfg(test)]
mod tests {
    use super::zenoh_error;

    #[test]
    fn zenohs_source_places_are_left_out_of_its_messages() {
        let e = "Can not create a new TCP listener bound to tcp/8.8.8.8:7447: [8.8.8.8:7447: Cannot assign requested address (os error 99) at /root/.cargo/registry/src/index.crates.io-1949cf8c6b5b557f/zenoh-link-commons-1.10.2/src/tcp.rs:61.] at /root/.cargo/registry/src/zenoh-link-tcp-1.10.2/src/unicast.rs:338.";
        assert_eq!(
            zenoh_error(&e),
            "Can not create a new TCP listener bound to tcp/8.8.8.8:7447: [8.8.8.8:7447: Cannot assign requested address (os error 99)]"
        );
        // A path that is no source place stays.
        let e = "cannot read the file at /etc/zenoh.json5: denied";
        assert_eq!(zenoh_error(&e), e);
    }

    #[test]
    fn serdes_debug_form_is_a_sentence() {
        let e = r#"JSON error: Message { msg: "invalid type: integer `3`, expected either 'router', 'peer' or 'client'", location: Some(Location { line: 1, column: 8 }) }"#;
        assert_eq!(
            zenoh_error(&e),
            "JSON error: invalid type: integer `3`, expected either 'router', 'peer' or 'client' (line 1, column 8)"
        );
        let e =
            r#"JSON error: Message { msg: "unknown field `moed`, say \"mode\"", location: None }"#;
        assert_eq!(
            zenoh_error(&e),
            r#"JSON error: unknown field `moed`, say "mode""#
        );
        let e = "JSON error: a Message { without its form";
        assert_eq!(zenoh_error(&e), e);
    }
}
