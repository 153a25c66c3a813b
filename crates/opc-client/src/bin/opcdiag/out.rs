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

/// Writes `text` (whole lines, each ending in '\n') to stdout in one write rather than one
/// per line: a listing of 1,000,000 names is a few writes, not 1,000,000 (each a system
/// call, and a slow one under Wine). On an error stdout is taken as closed.
pub fn text(text: &str) {
    let mut out = std::io::stdout().lock();
    if out
        .write_all(text.as_bytes())
        .and_then(|()| out.flush())
        .is_err()
    {
        CLOSED.store(true, Ordering::SeqCst);
    }
}
