//! Starting a program under Wine again when Wine failed its start without a word.
//!
//! Wine ends a process that fails in its own start-up with a failure code and no output
//! (its messages are off with `WINEDEBUG=-all`), as it answers `ERROR_INTERNAL_ERROR` to
//! `CreateProcess` for one started inside Wine (`tests/src/start.rs`). opcdiag prints a line
//! on every failure (`opcdiag: error: ...` on stderr), so an opcdiag that failed having
//! printed nothing did not run ([`silent_start_failure`]); [`retrying`] starts it again,
//! [`START_TRIES`] times at most, each retry printed and counted
//! ([`forgiven::Kind::OpcdiagRetry`]). The msi-test of a clean-clone CI failed once on it,
//! a subscriber after the upgrade with exit 1 and no output.

use super::forgiven::{self, Kind};

/// Starts tried at most, the first included.
pub const START_TRIES: u32 = 3;

/// Whether a program under Wine ended with a failure having printed nothing (`out`: its
/// stdout and stderr). 124 is `timeout`'s own, not a start failure.
pub fn silent_start_failure(code: i32, out: &str) -> bool {
    code != 0 && code != 124 && out.trim().is_empty()
}

/// Runs `start` again while it fails silently (its error comes with `true`), [`START_TRIES`]
/// times at most; each retry is printed (naming `what`) and counted in the run's
/// [`forgiven`] log. Any other failure, and the last silent one, is returned.
pub fn retrying<T>(
    what: &str,
    start: impl FnMut() -> Result<T, (String, bool)>,
) -> Result<T, String> {
    retrying_noted(what, start, |what| {
        forgiven::record(Kind::OpcdiagRetry, what)
    })
}

/// [`retrying`], with `note` called for each retry.
fn retrying_noted<T>(
    what: &str,
    mut start: impl FnMut() -> Result<T, (String, bool)>,
    mut note: impl FnMut(&str),
) -> Result<T, String> {
    let mut tries = 1;
    loop {
        match start() {
            Err((e, true)) if tries < START_TRIES => {
                tries += 1;
                let first = e.lines().next().unwrap_or("").trim();
                println!(
                    "wine: {what} ended having printed nothing (Wine's start failure: {first}); try {tries} of {START_TRIES}"
                );
                note(what);
            }
            done => return done.map_err(|(e, _)| e),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_failure_with_nothing_printed_is_a_start_failure() {
        assert!(silent_start_failure(1, ""));
        assert!(silent_start_failure(1, " \n"));
        assert!(!silent_start_failure(0, ""), "a success");
        assert!(!silent_start_failure(124, ""), "timeout's own code");
        assert!(!silent_start_failure(
            1,
            "opcdiag: error: CoCreateInstance failed"
        ));
    }

    #[test]
    fn a_silent_failure_is_retried_and_noted_until_a_start_succeeds() {
        let mut calls = 0;
        let mut noted = Vec::new();
        let r = retrying_noted(
            "X64 opcdiag status",
            || {
                calls += 1;
                if calls < START_TRIES {
                    Err(("exit 1".to_owned(), true))
                } else {
                    Ok(calls)
                }
            },
            |w| noted.push(w.to_owned()),
        );
        assert_eq!(r, Ok(START_TRIES));
        assert_eq!(noted.len(), START_TRIES as usize - 1);
        assert_eq!(noted[0], "X64 opcdiag status");
    }

    #[test]
    fn the_last_silent_failure_and_any_other_failure_are_returned_unnoted() {
        let mut calls = 0;
        let mut notes = 0;
        let r: Result<(), String> = retrying_noted(
            "x",
            || {
                calls += 1;
                Err((format!("silent {calls}"), true))
            },
            |_| notes += 1,
        );
        assert_eq!(r, Err(format!("silent {START_TRIES}")));
        assert_eq!(notes, START_TRIES - 1);

        let mut calls = 0;
        let mut notes = 0;
        let r: Result<(), String> = retrying_noted(
            "x",
            || {
                calls += 1;
                Err(("opcdiag: error: E_FAIL".to_owned(), false))
            },
            |_| notes += 1,
        );
        assert_eq!(r, Err("opcdiag: error: E_FAIL".to_owned()));
        assert_eq!(
            (calls, notes),
            (1, 0),
            "a failure that said why is not retried"
        );
    }
}
