//! `naofarm fingerprint`: this host's worker fingerprint and the version.

use crate::common::{emit, Failure};

/// `naofarm fingerprint`.
pub fn fingerprint() -> Result<(), Failure> {
    let fp = worker::fingerprint::of_this_worker();
    emit(&format!(
        "{} naofarm {}\n",
        protocol::wire::show_fingerprint(fp),
        env!("CARGO_PKG_VERSION")
    ))
}
