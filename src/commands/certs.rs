//! `naofarm certs DIR`: a certificate authority and one certificate per role
//! (`coordinator`, `worker`, `watcher`, `router`; the role is the
//! certificate's common name) for mutual TLS on every link. Private keys are
//! written with mode 0600 and never overwritten without `--force`; a CA
//! already in DIR signs the new certificates.

use std::{io::Write, os::unix::fs::OpenOptionsExt, path::Path};

use anyhow::anyhow;
use rcgen::{
    BasicConstraints, CertificateParams, DistinguishedName, DnType, ExtendedKeyUsagePurpose, IsCa,
    Issuer, KeyPair, KeyUsagePurpose, SanType,
};

use crate::common::{usage_unless, Failure};

/// The roles, each a certificate's common name.
pub const ROLES: [&str; 4] = ["coordinator", "worker", "watcher", "router"];

/// The CA's common name.
const CA_NAME: &str = "naofarm CA";

fn write(path: &Path, text: &str, private: bool, force: bool) -> Result<(), Failure> {
    let mut o = std::fs::OpenOptions::new();
    o.write(true);
    if force {
        o.create(true).truncate(true);
    } else {
        o.create_new(true);
    }
    if private {
        o.mode(0o600);
    }
    let mut f = o.open(path).map_err(|e| {
        if e.kind() == std::io::ErrorKind::AlreadyExists {
            Failure::Usage(anyhow!(
                "{} exists; it is kept (use --force to replace it)",
                path.display()
            ))
        } else {
            Failure::Job(anyhow!("{}: {e}", path.display()))
        }
    })?;
    f.write_all(text.as_bytes())
        .and_then(|()| f.sync_all())
        .map_err(|e| Failure::Job(anyhow!("{}: {e}", path.display())))
}

fn ca_params() -> CertificateParams {
    let mut p = CertificateParams::default();
    let mut dn = DistinguishedName::new();
    dn.push(DnType::CommonName, CA_NAME);
    p.distinguished_name = dn;
    p.is_ca = IsCa::Ca(BasicConstraints::Unconstrained);
    p.key_usages = vec![KeyUsagePurpose::KeyCertSign, KeyUsagePurpose::CrlSign];
    p
}

fn validity(p: &mut CertificateParams, days: u32) {
    let now = time::OffsetDateTime::now_utc();
    p.not_before = now - time::Duration::minutes(5);
    p.not_after = now + time::Duration::days(i64::from(days));
}

fn rc(e: rcgen::Error) -> Failure {
    Failure::Job(anyhow!("certificate: {e}"))
}

/// `naofarm certs`.
pub fn certs(
    dir: &Path,
    names: &[String],
    hosts: &[String],
    days: u32,
    force: bool,
    expired: bool,
) -> Result<(), Failure> {
    let days_ok = (1..=3650).contains(&days);
    usage_unless(days_ok, || format!("--days {days}: must be in 1..=3650"))?;
    // Which certificates: every role, plus ROLE:NAME for each --name.
    let mut wanted: Vec<(String, String)> = ROLES
        .iter()
        .map(|r| ((*r).to_string(), (*r).to_string()))
        .collect();
    for n in names {
        let (role, name) = n.split_once(':').ok_or_else(|| {
            Failure::Usage(anyhow!("--name `{n}`: give ROLE:NAME, e.g. worker:node7"))
        })?;
        if !ROLES.contains(&role) {
            return Err(Failure::Usage(anyhow!(
                "--name `{n}`: unknown role `{role}` (roles: {})",
                ROLES.join(", ")
            )));
        }
        protocol::keys::check_chunk("name", name).map_err(|e| Failure::Usage(anyhow!(e)))?;
        if ROLES.contains(&name) || name == "ca" {
            return Err(Failure::Usage(anyhow!(
                "--name `{n}`: `{name}` is reserved"
            )));
        }
        wanted.push((role.to_string(), name.to_string()));
    }
    crate::common::make_dir(dir, "certificate directory")?;
    let (ca_pem, ca_key) = (dir.join("ca.pem"), dir.join("ca.key"));
    // The CA: reused when it is there (it signs the new certificates), made otherwise.
    let ca_key_pair = if ca_key.exists() && !force {
        let text = std::fs::read_to_string(&ca_key)
            .map_err(|e| Failure::Job(anyhow!("{}: {e}", ca_key.display())))?;
        KeyPair::from_pem(&text).map_err(|e| Failure::Job(anyhow!("{}: {e}", ca_key.display())))?
    } else {
        let key = KeyPair::generate().map_err(rc)?;
        let mut p = ca_params();
        validity(&mut p, days.max(365));
        let cert = p.self_signed(&key).map_err(rc)?;
        write(&ca_key, &key.serialize_pem(), true, force)?;
        write(&ca_pem, &cert.pem(), false, force)?;
        eprintln!("wrote {} and {}", ca_pem.display(), ca_key.display());
        key
    };
    let issuer = Issuer::new(ca_params(), ca_key_pair);
    let mut sans = vec![
        SanType::IpAddress(std::net::IpAddr::from([127, 0, 0, 1])),
        SanType::DnsName("localhost".try_into().map_err(rc)?),
    ];
    for h in hosts {
        sans.push(match h.parse::<std::net::IpAddr>() {
            Ok(ip) => SanType::IpAddress(ip),
            Err(_) => SanType::DnsName(
                h.clone()
                    .try_into()
                    .map_err(|e| Failure::Usage(anyhow!("--host `{h}`: {e}")))?,
            ),
        });
    }
    for (role, name) in wanted {
        let (pem, key) = (
            dir.join(format!("{name}.pem")),
            dir.join(format!("{name}.key")),
        );
        if !force && (pem.exists() || key.exists()) {
            eprintln!("kept {} (exists; --force replaces it)", pem.display());
            continue;
        }
        let k = KeyPair::generate().map_err(rc)?;
        let mut p = CertificateParams::default();
        let mut dn = DistinguishedName::new();
        dn.push(DnType::CommonName, role.as_str());
        p.distinguished_name = dn;
        // Servers (a router, a coordinator that listens) are named by their hosts.
        p.subject_alt_names.clone_from(&sans);
        p.extended_key_usages = vec![
            ExtendedKeyUsagePurpose::ServerAuth,
            ExtendedKeyUsagePurpose::ClientAuth,
        ];
        p.key_usages = vec![KeyUsagePurpose::DigitalSignature];
        validity(&mut p, days);
        if expired {
            let now = time::OffsetDateTime::now_utc();
            p.not_before = now - time::Duration::days(2);
            p.not_after = now - time::Duration::days(1);
        }
        let cert = p.signed_by(&k, &issuer).map_err(rc)?;
        write(&key, &k.serialize_pem(), true, force)?;
        write(&pem, &cert.pem(), false, force)?;
        eprintln!(
            "wrote {} (common name `{role}`, {days} days)",
            pem.display()
        );
    }
    Ok(())
}
