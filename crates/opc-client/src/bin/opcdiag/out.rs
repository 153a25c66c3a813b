//! Standard output that survives a closed pipe.

use std::io::Write;
use std::sync::atomic::{AtomicBool, Ordering};

static CLOSED: AtomicBool = AtomicBool::new(false);

/// Writes one line to stdout (line-buffered: it appears at once); on an error stdout is
/// taken as closed.
pub fn line(args: std::fmt::Arguments) {
    let mut out = std::io::stdout().lock();
    if writeln!(out, "{args}").and_then(|()| out.flush()).is_err() {
        CLOSED.store(true, Ordering::SeqCst);
    }
}

/// True once a write to stdout failed.
pub fn closed() -> bool {
    CLOSED.load(Ordering::SeqCst)
}
