//! Pipe-safe standard output for every command: `outln!` writes a line and
//! never panics. When the reader has gone (`naofarm model | head -1`), the
//! rest of the output is dropped quietly and the command goes on (a run keeps
//! its journal); any other write error is said once on stderr.

use std::{
    io::Write,
    sync::atomic::{AtomicBool, Ordering},
};

static CLOSED: AtomicBool = AtomicBool::new(false);

/// Writes `text` to stdout unless it is closed; false once it is.
pub fn write(text: &str) -> bool {
    if CLOSED.load(Ordering::Relaxed) {
        return false;
    }
    let mut out = std::io::stdout().lock();
    match out.write_all(text.as_bytes()).and_then(|()| out.flush()) {
        Ok(()) => true,
        Err(e) => {
            if !CLOSED.swap(true, Ordering::Relaxed) && e.kind() != std::io::ErrorKind::BrokenPipe {
                eprintln!("warning: standard output failed ({e}); further output is dropped");
            }
            false
        }
    }
}

/// Writes a formatted line (what `outln!` expands to).
pub fn line(args: std::fmt::Arguments<'_>) {
    write(&format!("{args}\n"));
}

/// `println!` that never panics on a closed pipe.
macro_rules! outln {
    ($($t:tt)*) => {
        $crate::out::line(format_args!($($t)*))
    };
}
