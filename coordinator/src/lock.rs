//! One coordinator per run directory: an exclusive advisory lock on
//! `DIR/lock`, held for the run's life and released by the kernel when the
//! process ends (however it ends). The file records the holder's pid and host
//! for the message a second coordinator prints. Readers (`history`,
//! `journal check`) never take it; they only ask whether it is held.
//! Must not: delete or truncate anything but the lock file's own text.

use std::{
    fs::{File, OpenOptions},
    io::{Read, Seek, Write},
    path::{Path, PathBuf},
};

/// Name of the lock file inside a run directory.
pub const LOCK_FILE: &str = "lock";

/// A held run lock; dropping it releases the lock.
#[derive(Debug)]
pub struct RunLock {
    _file: File,
}

/// Why the lock was not taken.
#[derive(Debug, thiserror::Error)]
pub enum LockError {
    /// Another process holds it.
    #[error(
        "{dir} is in use by another coordinator ({holder}); one coordinator per run directory"
    )]
    Held {
        /// The run directory.
        dir: String,
        /// "pid N on host H", as the holder wrote it.
        holder: String,
    },
    /// The run directory's path names something else: a file, a device.
    #[error("{0} exists and is not a directory; a run directory is made where nothing is")]
    NotADirectory(PathBuf),
    /// File-system error.
    #[error("{path}: {cause}")]
    Io {
        /// The lock file.
        path: PathBuf,
        /// The cause.
        cause: std::io::Error,
    },
}

fn host() -> String {
    std::fs::read_to_string("/proc/sys/kernel/hostname")
        .or_else(|_| std::fs::read_to_string("/etc/hostname"))
        .map(|h| h.trim().to_string())
        .ok()
        .filter(|h| !h.is_empty())
        .unwrap_or_else(|| "an unknown host".into())
}

/// Whether `text` is what a coordinator writes into its lock: nothing yet,
/// or `pid N on HOST` and a newline.
pub(crate) fn is_lock_text(text: &[u8]) -> bool {
    let Ok(text) = std::str::from_utf8(text) else {
        return false;
    };
    if text.is_empty() {
        return true;
    }
    let Some(line) = text.strip_suffix('\n') else {
        return false;
    };
    line.strip_prefix("pid ")
        .and_then(|rest| rest.split_once(" on "))
        .is_some_and(|(pid, host)| {
            !pid.is_empty()
                && pid.bytes().all(|b| b.is_ascii_digit())
                && !host.is_empty()
                && !host.contains('\n')
        })
}

impl RunLock {
    /// Takes the lock of `dir` (created if missing), or says who holds it.
    pub fn acquire(dir: &Path) -> Result<Self, LockError> {
        let path = dir.join(LOCK_FILE);
        let io = |cause| LockError::Io {
            path: path.clone(),
            cause,
        };
        if dir.exists() && !dir.is_dir() {
            return Err(LockError::NotADirectory(dir.to_path_buf()));
        }
        std::fs::create_dir_all(dir).map_err(io)?;
        let mut file = OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(&path)
            .map_err(io)?;
        match file.try_lock() {
            Ok(()) => {}
            Err(std::fs::TryLockError::WouldBlock) => {
                let mut text = String::new();
                let _ = file.read_to_string(&mut text);
                let holder = text.trim();
                return Err(LockError::Held {
                    dir: dir.display().to_string(),
                    holder: if holder.is_empty() {
                        "a process that has not yet written its pid".into()
                    } else {
                        holder.to_string()
                    },
                });
            }
            Err(std::fs::TryLockError::Error(e)) => return Err(io(e)),
        }
        let me = format!("pid {} on {}\n", std::process::id(), host());
        file.set_len(0)
            .and_then(|()| file.rewind())
            .and_then(|()| file.write_all(me.as_bytes()))
            .and_then(|()| file.sync_all())
            .map_err(io)?;
        Ok(Self { _file: file })
    }

    /// Whether a coordinator holds `dir`'s lock now (a reader's question).
    #[must_use]
    pub fn is_held(dir: &Path) -> bool {
        let Ok(file) = File::open(dir.join(LOCK_FILE)) else {
            return false;
        };
        matches!(
            file.try_lock_shared(),
            Err(std::fs::TryLockError::WouldBlock)
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_second_holder_is_refused_with_the_first_ones_pid() {
        let d = crate::test_dir::test_dir("lock");
        let a = RunLock::acquire(&d).unwrap();
        assert!(RunLock::is_held(&d));
        let e = RunLock::acquire(&d).unwrap_err().to_string();
        assert!(e.contains(&format!("pid {}", std::process::id())), "{e}");
        drop(a);
        assert!(!RunLock::is_held(&d));
        let _b = RunLock::acquire(&d).unwrap();
    }

    #[test]
    fn a_file_where_the_run_directory_goes_is_refused_and_kept() {
        let d = crate::test_dir::test_dir("lock-file");
        std::fs::create_dir_all(&*d).unwrap();
        let file = d.join("notes.txt");
        std::fs::write(&file, b"someone's notes").unwrap();
        let e = RunLock::acquire(&file).unwrap_err();
        assert!(matches!(e, LockError::NotADirectory(_)), "{e}");
        assert!(e.to_string().contains("is not a directory"), "{e}");
        assert_eq!(std::fs::read(&file).unwrap(), b"someone's notes");
    }

    /// A lock's text is what `acquire` writes, or nothing yet; anything else
    /// is someone's file named `lock`.
    #[test]
    fn a_locks_text_is_the_pid_and_host_it_writes() {
        let d = crate::test_dir::test_dir("lock-text");
        let held = RunLock::acquire(&d).unwrap();
        assert!(is_lock_text(&std::fs::read(d.join(LOCK_FILE)).unwrap()));
        drop(held);
        for ours in ["", "pid 1 on vm\n", "pid 4242 on an unknown host\n"] {
            assert!(is_lock_text(ours.as_bytes()), "{ours:?}");
        }
        for theirs in [
            "my lock notes\n",
            "pid 12 on vm",
            "pid on vm\n",
            "pid 1x on vm\n",
            "pid 1 on \n",
            "pid 1 on vm\nmore\n",
        ] {
            assert!(!is_lock_text(theirs.as_bytes()), "{theirs:?}");
        }
        assert!(!is_lock_text(&[0xff, 0xfe]));
    }
}
