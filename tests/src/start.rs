//! Starting processes from the tests through Wine's transient start failure.
//!
//! Under load, Wine's `CreateProcess` now and then fails with `ERROR_INTERNAL_ERROR` (1359,
//! "Internal error."): `NtCreateUserProcess` (dlls/ntdll/unix/process.c) waits for the new
//! process's start-up and, when the child ended before it finished and left exit code 0,
//! answers `STATUS_INTERNAL_ERROR`. None of the started program has run then (its `main`
//! is not reached), so the start is tried again: at most [`TRIES`] times, each retry
//! printed on stderr. Any other error, and the third 1359, is returned as it is.
//!
//! The file is also compiled into the COM crate's in-process tests
//! (`crates/ctopc-com/tests/common/mod.rs`, by `#[path]`), which start their own test
//! binary as a child: it depends on `std` only.

use std::io;
use std::process::{Child, Command, ExitStatus, Output};
use std::time::Duration;

/// `ERROR_INTERNAL_ERROR`, Wine's answer when a child died during its start-up.
pub const ERROR_INTERNAL_ERROR: i32 = 1359;

/// Starts tried at most, the first included.
pub const TRIES: u32 = 3;

/// The pause before a retry: the failure comes under load, so the retry waits a little.
const PAUSE: Duration = Duration::from_millis(500);

/// Runs `start` (one `spawn`, `output` or `status` of a command) again while it fails with
/// [`ERROR_INTERNAL_ERROR`], [`TRIES`] times at most; `what` names the program on stderr.
pub fn retrying<T>(what: &str, mut start: impl FnMut() -> io::Result<T>) -> io::Result<T> {
    let mut tries = 1;
    loop {
        match start() {
            Err(e) if is_transient(&e) && tries < TRIES => {
                tries += 1;
                eprintln!("start of {what} failed: {e}; Wine's transient start failure, try {tries} of {TRIES}");
                std::thread::sleep(PAUSE);
            }
            done => return done,
        }
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
        let r = retrying("x", || {
            calls.set(calls.get() + 1);
            if calls.get() < TRIES {
                Err(failure(ERROR_INTERNAL_ERROR))
            } else {
                Ok(7)
            }
        });
        assert_eq!(r.unwrap(), 7);
        assert_eq!(calls.get(), TRIES);
    }

    #[test]
    fn the_last_transient_failure_and_any_other_error_are_returned() {
        let calls = Cell::new(0);
        let r: io::Result<()> = retrying("x", || {
            calls.set(calls.get() + 1);
            Err(failure(ERROR_INTERNAL_ERROR))
        });
        assert_eq!(r.unwrap_err().raw_os_error(), Some(ERROR_INTERNAL_ERROR));
        assert_eq!(calls.get(), TRIES);

        calls.set(0);
        let r: io::Result<()> = retrying("x", || {
            calls.set(calls.get() + 1);
            Err(failure(2))
        });
        assert_eq!(r.unwrap_err().raw_os_error(), Some(2));
        assert_eq!(calls.get(), 1, "a missing file is not tried again");
    }
}
