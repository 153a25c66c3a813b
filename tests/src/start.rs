//! Starting processes from the tests through Wine's transient start failure.
//!
//! Under load, Wine's `CreateProcess` now and then fails with `ERROR_INTERNAL_ERROR` (1359,
//! "Internal error."): `NtCreateUserProcess` (dlls/ntdll/unix/process.c) waits for the new
//! process's start-up and, when the child ended before it finished and left exit code 0,
//! answers `STATUS_INTERNAL_ERROR`. None of the started program has run then (its `main`
//! is not reached), so the start is tried again: at most [`TRIES`] times, each retry
//! printed on stderr and counted in the log of forgiven Wine trouble that `cargo xtask
//! test` names in [`FORGIVEN_LOG`] (`xtask/src/wine/forgiven.rs` prints the count as the
//! run's last line). Any other error, and the third 1359, is returned as it is.
//!
//! The file is also compiled into the COM crate's in-process tests
//! (`crates/ctopc-com/tests/common/mod.rs`, by `#[path]`), which start their own test
//! binary as a child: it depends on `std` only.

use std::io::{self, Write as _};
use std::process::{Child, Command, ExitStatus, Output};
use std::time::Duration;

/// `ERROR_INTERNAL_ERROR`, Wine's answer when a child died during its start-up.
pub const ERROR_INTERNAL_ERROR: i32 = 1359;

/// Starts tried at most, the first included.
pub const TRIES: u32 = 3;

/// The pause before a retry: the failure comes under load, so the retry waits a little.
const PAUSE: Duration = Duration::from_millis(500);

/// The environment variable naming the log where xtask counts what it forgives Wine: a
/// Unix path, opened here by its Wine path ([`wine_path`]).
pub const FORGIVEN_LOG: &str = "CTOPC_FORGIVEN_LOG";

/// The first word of a retry's line in that log (`xtask/src/wine/forgiven.rs`, `Kind::tag`).
const FORGIVEN_TAG: &str = "createprocess-1359-retry";

/// Runs `start` (one `spawn`, `output` or `status` of a command) again while it fails with
/// [`ERROR_INTERNAL_ERROR`], [`TRIES`] times at most; `what` names the program on stderr
/// and in the count of forgiven retries.
pub fn retrying<T>(what: &str, start: impl FnMut() -> io::Result<T>) -> io::Result<T> {
    retrying_noted(what, start, count_retry)
}

/// [`retrying`], with `note` called for each retry.
fn retrying_noted<T>(
    what: &str,
    mut start: impl FnMut() -> io::Result<T>,
    mut note: impl FnMut(&str, &io::Error),
) -> io::Result<T> {
    let mut tries = 1;
    loop {
        match start() {
            Err(e) if is_transient(&e) && tries < TRIES => {
                tries += 1;
                eprintln!("start of {what} failed: {e}; Wine's transient start failure, try {tries} of {TRIES}");
                note(what, &e);
                std::thread::sleep(PAUSE);
            }
            done => return done,
        }
    }
}

/// Counts one retry: a line appended, in one write, to the log [`FORGIVEN_LOG`] names
/// (nothing when it names none: a run not started by xtask). A log that cannot be written
/// is said on stderr; the retry goes on.
fn count_retry(what: &str, e: &io::Error) {
    let Some(log) = std::env::var_os(FORGIVEN_LOG) else {
        return;
    };
    let path = wine_path(&log.to_string_lossy());
    let line = format!("{FORGIVEN_TAG} {what}: {e}\n");
    let written = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(&path)
        .and_then(|mut f| f.write_all(line.as_bytes()));
    if let Err(err) = written {
        eprintln!("cannot count the retry of {what} in {path}: {err}");
    }
}

/// A Unix path as a Windows process under Wine opens it: `/a/b` is `Z:\a\b` (Wine's drive
/// Z: is the Unix root); any other path is returned as it is.
pub fn wine_path(unix: &str) -> String {
    if unix.starts_with('/') {
        format!("Z:{}", unix.replace('/', "\\"))
    } else {
        unix.to_owned()
    }
}

/// Whether `e` is the start failure that [`retrying`] tries again.
pub fn is_transient(e: &io::Error) -> bool {
    e.raw_os_error() == Some(ERROR_INTERNAL_ERROR)
}

/// `spawn`, `output` and `status` of a [`Command`] through [`retrying`].
pub trait StartRetrying {
    fn spawn_retrying(&mut self) -> io::Result<Child>;
    fn output_retrying(&mut self) -> io::Result<Output>;
    fn status_retrying(&mut self) -> io::Result<ExitStatus>;
}

impl StartRetrying for Command {
    fn spawn_retrying(&mut self) -> io::Result<Child> {
        let what = self.get_program().to_string_lossy().into_owned();
        retrying(&what, || self.spawn())
    }

    fn output_retrying(&mut self) -> io::Result<Output> {
        let what = self.get_program().to_string_lossy().into_owned();
        retrying(&what, || self.output())
    }

    fn status_retrying(&mut self) -> io::Result<ExitStatus> {
        let what = self.get_program().to_string_lossy().into_owned();
        retrying(&what, || self.status())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::cell::Cell;

    fn failure(code: i32) -> io::Error {
        io::Error::from_raw_os_error(code)
    }

    #[test]
    fn a_transient_failure_is_tried_again_until_a_start_succeeds() {
        let calls = Cell::new(0);
        let notes = Cell::new(0);
        let r = retrying_noted(
            "x",
            || {
                calls.set(calls.get() + 1);
                if calls.get() < TRIES {
                    Err(failure(ERROR_INTERNAL_ERROR))
                } else {
                    Ok(7)
                }
            },
            |_, _| notes.set(notes.get() + 1),
        );
        assert_eq!(r.unwrap(), 7);
        assert_eq!(calls.get(), TRIES);
        assert_eq!(notes.get(), TRIES - 1, "each retry is counted");
    }

    #[test]
    fn the_last_transient_failure_and_any_other_error_are_returned() {
        let calls = Cell::new(0);
        let notes = Cell::new(0);
        let note = |_: &str, _: &io::Error| notes.set(notes.get() + 1);
        let r: io::Result<()> = retrying_noted(
            "x",
            || {
                calls.set(calls.get() + 1);
                Err(failure(ERROR_INTERNAL_ERROR))
            },
            note,
        );
        assert_eq!(r.unwrap_err().raw_os_error(), Some(ERROR_INTERNAL_ERROR));
        assert_eq!(calls.get(), TRIES);
        assert_eq!(notes.get(), TRIES - 1, "the last failure is not retried");

        calls.set(0);
        notes.set(0);
        let r: io::Result<()> = retrying_noted(
            "x",
            || {
                calls.set(calls.get() + 1);
                Err(failure(2))
            },
            note,
        );
        assert_eq!(r.unwrap_err().raw_os_error(), Some(2));
        assert_eq!(calls.get(), 1, "a missing file is not tried again");
        assert_eq!(notes.get(), 0);
    }

    #[test]
    fn the_log_is_opened_by_its_wine_path() {
        assert_eq!(
            wine_path("/work/main/target/wine/forgiven.log"),
            r"Z:\work\main\target\wine\forgiven.log"
        );
        assert_eq!(wine_path(r"C:\x.log"), r"C:\x.log");
    }
}
