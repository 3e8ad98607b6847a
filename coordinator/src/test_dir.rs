//! Scratch directories for this crate's tests: a fresh, not yet existing
//! path under a temporary directory, removed when the test lets go of it
//! and kept (its path printed) when the test is failing.

use std::path::{Path, PathBuf};

/// A test's scratch path; see the module.
pub struct TestDir {
    root: tempfile::TempDir,
    path: PathBuf,
}

/// A fresh path `naofarm-PREFIX-…/PREFIX` that does not exist yet.
pub fn test_dir(prefix: &str) -> TestDir {
    let root = tempfile::Builder::new()
        .prefix(&format!("naofarm-{prefix}-"))
        .tempdir()
        .unwrap();
    let path = root.path().join(prefix);
    TestDir { root, path }
}

impl std::ops::Deref for TestDir {
    type Target = Path;
    fn deref(&self) -> &Path {
        &self.path
    }
}

impl AsRef<Path> for TestDir {
    fn as_ref(&self) -> &Path {
        &self.path
    }
}

impl Drop for TestDir {
    fn drop(&mut self) {
        if std::thread::panicking() {
            self.root.disable_cleanup(true);
            eprintln!("kept the failing test's directory {}", self.path.display());
        }
    }
}
