//! Waiting on a condition, bounded, instead of sleeping for a guessed time: a test that
//! waits for a callback, a state, a log line or a process exit looks at the condition
//! every [`POLL`] and goes on as soon as it holds; the limit only bounds a failure.
//!
//! (A test that checks that something does *not* happen lets time pass on purpose: that
//! is a plain `sleep`, commented, in the test.)

use std::io;
use std::process::{Child, ExitStatus};
use std::time::{Duration, Instant};

/// The pause between two looks at a condition.
pub const POLL: Duration = Duration::from_millis(20);

/// Looks at `cond` until it holds, for at most `limit` (and once more when the limit is
/// reached): whether it held.
pub fn wait_until(limit: Duration, mut cond: impl FnMut() -> bool) -> bool {
    wait_for(limit, || cond().then_some(())).is_some()
}

/// Calls `probe` until it gives a value, for at most `limit` (and once more when the limit
/// is reached): the value, or `None` when the time ran out.
pub fn wait_for<T>(limit: Duration, mut probe: impl FnMut() -> Option<T>) -> Option<T> {
    let deadline = Instant::now() + limit;
    loop {
        if let Some(v) = probe() {
            return Some(v);
        }
        let now = Instant::now();
        if now >= deadline {
            return None;
        }
        std::thread::sleep(POLL.min(deadline - now));
    }
}

/// Waits at most `limit` for `child` to exit: its status, or `None` while it still runs.
pub fn wait_exit(child: &mut Child, limit: Duration) -> io::Result<Option<ExitStatus>> {
    wait_for(limit, || child.try_wait().transpose()).transpose()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::cell::Cell;

    #[test]
    fn a_condition_that_comes_true_ends_the_wait_at_once() {
        let looks = Cell::new(0);
        let start = Instant::now();
        let held = wait_until(Duration::from_secs(60), || {
            looks.set(looks.get() + 1);
            looks.get() == 3
        });
        assert!(held);
        assert_eq!(looks.get(), 3);
        assert!(start.elapsed() < Duration::from_secs(10));
    }

    #[test]
    fn a_condition_that_never_holds_is_false_after_the_limit() {
        let looks = Cell::new(0);
        let start = Instant::now();
        let held = wait_until(Duration::from_millis(100), || {
            looks.set(looks.get() + 1);
            false
        });
        assert!(!held);
        assert!(start.elapsed() >= Duration::from_millis(100));
        assert!(looks.get() >= 2, "looked at the end again: {}", looks.get());
    }

    #[test]
    fn wait_for_gives_the_first_value() {
        let n = Cell::new(0);
        let v = wait_for(Duration::from_secs(60), || {
            n.set(n.get() + 1);
            (n.get() >= 2).then(|| n.get() * 10)
        });
        assert_eq!(v, Some(20));
        assert_eq!(wait_for(Duration::ZERO, || None::<u8>), None);
    }

    #[cfg(unix)]
    #[test]
    fn wait_exit_gives_the_status_or_none_while_it_runs() {
        let mut quick = std::process::Command::new("true").spawn().unwrap();
        let status = wait_exit(&mut quick, Duration::from_secs(60)).unwrap();
        assert!(status.is_some_and(|s| s.success()));
        let mut slow = std::process::Command::new("sleep")
            .arg("60")
            .spawn()
            .unwrap();
        assert!(wait_exit(&mut slow, Duration::from_millis(50))
            .unwrap()
            .is_none());
        slow.kill().unwrap();
        slow.wait().unwrap();
    }
}
