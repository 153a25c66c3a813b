//! Operations settings the COM layer needs besides the engine's, and the pure decisions
//! behind them: the write audit ([`crate::audit`]) and the watch over slow and hung
//! callback clients ([`CallbackWatch`]). Plain values, filled from `[Server]` by the
//! configuration reader.

use crate::model::GroupHandle;
use crate::Timestamp;

/// Default `CallbackTimeout`, ms.
pub const DEFAULT_CALLBACK_TIMEOUT_MS: u32 = 10_000;
/// Default `CallbackFailures`.
pub const DEFAULT_CALLBACK_FAILURES: u32 = 3;

/// What `[Server]` says about operations (defaults: [`OpsConfig::default`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct OpsConfig {
    /// `AuditWrites` (default tak): one audit line per written item ([`crate::audit`]).
    pub audit_writes: bool,
    /// `CallbackTimeout`, ms (default [`DEFAULT_CALLBACK_TIMEOUT_MS`]): a callback to a
    /// client that has not returned by then counts as failed ([`CallbackWatch`]).
    pub callback_timeout_ms: u32,
    /// `CallbackFailures` (default [`DEFAULT_CALLBACK_FAILURES`]): after this many
    /// consecutive failed callbacks the client's callback sinks are dropped.
    pub callback_failures: u32,
    /// `MetricsAddress` (default none: off): the loopback `ip:port` the runtime shows the
    /// counters of [`crate::metrics`] on.
    pub metrics_address: Option<String>,
    /// `[WriteRights]`: who may write ([`crate::write_rights`]; default open).
    pub write_rights: std::sync::Arc<crate::write_rights::WriteRights>,
}

impl Default for OpsConfig {
    fn default() -> Self {
        OpsConfig {
            audit_writes: true,
            callback_timeout_ms: DEFAULT_CALLBACK_TIMEOUT_MS,
            callback_failures: DEFAULT_CALLBACK_FAILURES,
            metrics_address: None,
            write_rights: std::sync::Arc::default(),
        }
    }
}

/// The callback under way on a client's worker.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct InFlight {
    since: Timestamp,
    group: GroupHandle,
    paced: bool,
    /// Already counted as failed (its timeout passed).
    timed_out: bool,
}

/// What to do with a callback about to be queued to a client ([`CallbackWatch::admit`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Admit {
    /// Queue it.
    Queue,
    /// Do not queue it behind a call that is over its timeout (it counted as a failure).
    Refuse,
    /// As `Refuse`, and that was the last failure allowed: drop the client's sinks.
    Drop,
}

/// What became of the call under way when it ended ([`CallbackWatch::finish`]) or was
/// checked ([`CallbackWatch::poll`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Verdict {
    /// The paced OnDataChange of this group is done with, as far as pacing goes (report
    /// `Report::Ended`): once per call, at its end or at its timeout, whichever is first.
    pub ended: Option<GroupHandle>,
    /// The failures reached `CallbackFailures`: drop the client's sinks.
    pub drop_sinks: bool,
    /// A failure was counted (for the metrics).
    pub failed: bool,
}

/// The callbacks of one client (its worker calls them one at a time), pure: time is an
/// argument. The worker calls [`start`](Self::start) and [`finish`](Self::finish) around
/// each call; the thread that queues callbacks calls [`admit`](Self::admit) for each new
/// one and [`poll`](Self::poll) now and then (every driver step).
///
/// A call that takes longer than the timeout counts as one failure (when it returns, or
/// at once when `poll` sees it over its timeout); then every callback that would be queued
/// behind it is refused and counts as another failure, so that a hung client does not
/// collect a queue it will never serve. A call that returns within the timeout ends the
/// run of failures. At `max_failures` consecutive failures the verdict is to drop the
/// client's sinks (once; the count starts again).
///
/// Pacing: a paced OnDataChange whose call passed its timeout is reported ended then
/// (not again when it returns), so that the engine offers the next update, which is refused
/// and counts: a hung client reaches its limit in about timeout + (failures - 1) update
/// periods.
#[derive(Debug, Clone)]
pub struct CallbackWatch {
    timeout_ms: u64,
    max_failures: u32,
    in_flight: Option<InFlight>,
    failures: u32,
    /// For the `_Diagnostics` branch: every failure counted, admitted callbacks not yet
    /// started, the duration of the last call that returned.
    total_failures: u64,
    queued: u64,
    last_latency_ms: Option<f64>,
}

impl CallbackWatch {
    /// `timeout_ms` 0 turns the timeout off; `max_failures` 0 is taken as 1.
    pub fn new(timeout_ms: u32, max_failures: u32) -> Self {
        CallbackWatch {
            timeout_ms: u64::from(timeout_ms),
            max_failures: max_failures.max(1),
            in_flight: None,
            failures: 0,
            total_failures: 0,
            queued: 0,
            last_latency_ms: None,
        }
    }

    /// Every failure counted since the watch was made (timeouts and refusals).
    pub fn total_failures(&self) -> u64 {
        self.total_failures
    }

    /// Callbacks admitted ([`Admit::Queue`]) whose call has not started yet.
    pub fn queued(&self) -> u64 {
        self.queued
    }

    /// How long the last call that returned took, ms (`None`: none yet).
    pub fn last_latency_ms(&self) -> Option<f64> {
        self.last_latency_ms
    }

    /// Consecutive failures so far.
    pub fn failures(&self) -> u32 {
        self.failures
    }

    /// True while a call is under way and over its timeout.
    pub fn hung(&self) -> bool {
        self.in_flight.is_some_and(|f| f.timed_out)
    }

    fn over(&self, since: Timestamp, now: Timestamp) -> bool {
        self.timeout_ms != 0 && now.millis_since(since) >= self.timeout_ms
    }

    /// One more failure; true when that reaches the limit (then the count starts again).
    fn fail(&mut self) -> bool {
        self.failures += 1;
        self.total_failures += 1;
        if self.failures >= self.max_failures {
            self.failures = 0;
            true
        } else {
            false
        }
    }

    /// A new callback for this client, about to be queued (call [`poll`](Self::poll)
    /// first: a call under way is over its timeout once `poll` said so).
    pub fn admit(&mut self) -> Admit {
        if !self.hung() {
            self.queued += 1;
            return Admit::Queue;
        }
        if self.fail() {
            Admit::Drop
        } else {
            Admit::Refuse
        }
    }

    /// Checks the call under way: the first time it is over its timeout it counts as
    /// failed (and a paced one is reported ended).
    pub fn poll(&mut self, now: Timestamp) -> Verdict {
        let Some(f) = self.in_flight else {
            return Verdict::default();
        };
        if f.timed_out || !self.over(f.since, now) {
            return Verdict::default();
        }
        self.in_flight = Some(InFlight {
            timed_out: true,
            ..f
        });
        Verdict {
            ended: f.paced.then_some(f.group),
            drop_sinks: self.fail(),
            failed: true,
        }
    }

    /// The worker starts a call to `group`'s sink (`paced`: a scheduled OnDataChange).
    pub fn start(&mut self, now: Timestamp, group: GroupHandle, paced: bool) {
        self.queued = self.queued.saturating_sub(1);
        self.in_flight = Some(InFlight {
            since: now,
            group,
            paced,
            timed_out: false,
        });
    }

    /// The call under way returned (whatever its result).
    pub fn finish(&mut self, now: Timestamp) -> Verdict {
        let Some(f) = self.in_flight.take() else {
            return Verdict::default();
        };
        let ticks = now.filetime().saturating_sub(f.since.filetime()).max(0);
        self.last_latency_ms = Some(ticks as f64 / Timestamp::TICKS_PER_MS as f64);
        if f.timed_out {
            // Counted (and reported ended) when its timeout passed.
            return Verdict::default();
        }
        let ended = f.paced.then_some(f.group);
        if self.over(f.since, now) {
            Verdict {
                ended,
                drop_sinks: self.fail(),
                failed: true,
            }
        } else {
            self.failures = 0;
            Verdict {
                ended,
                ..Verdict::default()
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const G: GroupHandle = GroupHandle(7);

    fn at(ms: u64) -> Timestamp {
        Timestamp::from_unix_millis(1_000_000).add_millis(ms)
    }

    #[test]
    fn a_call_within_the_timeout_is_fine_and_ends_a_run_of_failures() {
        let mut w = CallbackWatch::new(1000, 3);
        w.start(at(0), G, true);
        assert_eq!(w.admit(), Admit::Queue);
        assert_eq!(
            w.finish(at(999)),
            Verdict {
                ended: Some(G),
                ..Verdict::default()
            }
        );
        // Two slow calls, then a quick one: the count starts again.
        for t in [2000, 4000] {
            w.start(at(t), G, false);
            assert_eq!(
                w.finish(at(t + 1500)),
                Verdict {
                    failed: true,
                    ..Verdict::default()
                }
            );
        }
        assert_eq!(w.failures(), 2);
        w.start(at(6000), G, false);
        w.finish(at(6001));
        assert_eq!(w.failures(), 0);
    }

    #[test]
    fn consecutive_slow_calls_drop_the_sinks_at_the_limit() {
        let mut w = CallbackWatch::new(1000, 3);
        let mut verdicts = Vec::new();
        for i in 0..3u64 {
            w.start(at(i * 5000), G, false);
            verdicts.push(w.finish(at(i * 5000 + 1000)).drop_sinks);
        }
        assert_eq!(verdicts, vec![false, false, true]);
        assert_eq!(w.failures(), 0, "the count starts again after a drop");
    }

    #[test]
    fn a_hung_call_counts_at_its_timeout_and_refuses_what_would_queue_behind_it() {
        let mut w = CallbackWatch::new(1000, 3);
        w.start(at(0), G, true);
        assert_eq!(w.poll(at(999)), Verdict::default());
        assert_eq!(w.admit(), Admit::Queue, "not yet over its timeout");
        // At the timeout: one failure, the paced callback reported ended (once).
        assert_eq!(
            w.poll(at(1000)),
            Verdict {
                ended: Some(G),
                drop_sinks: false,
                failed: true,
            }
        );
        assert_eq!(w.poll(at(1500)), Verdict::default());
        assert!(w.hung());
        // Every new callback is refused and counts: the third failure drops.
        assert_eq!(w.admit(), Admit::Refuse);
        assert_eq!(w.admit(), Admit::Drop);
        assert_eq!(w.admit(), Admit::Refuse, "counting starts again");
        // The call returns at last: not counted again, not reported ended again.
        assert_eq!(w.finish(at(60_000)), Verdict::default());
        assert!(!w.hung());
        assert_eq!(w.admit(), Admit::Queue);
    }

    #[test]
    fn with_a_limit_of_two_the_first_refusal_drops() {
        let mut w = CallbackWatch::new(1000, 2);
        w.start(at(0), G, false);
        // The call's own timeout is the first failure, this refusal the second.
        assert!(w.poll(at(1200)).failed);
        assert_eq!(w.admit(), Admit::Drop);
    }

    #[test]
    fn the_counts_for_diagnostics_follow_the_calls() {
        let mut w = CallbackWatch::new(1000, 5);
        assert_eq!(
            (w.queued(), w.total_failures(), w.last_latency_ms()),
            (0, 0, None)
        );
        assert_eq!(w.admit(), Admit::Queue);
        assert_eq!(w.admit(), Admit::Queue);
        assert_eq!(w.queued(), 2);
        w.start(at(0), G, true);
        assert_eq!(w.queued(), 1);
        w.finish(at(3));
        assert_eq!(w.last_latency_ms(), Some(3.0));
        w.start(at(10), G, true);
        assert!(w.poll(at(1100)).failed);
        assert_eq!(w.admit(), Admit::Refuse);
        assert_eq!(w.total_failures(), 2);
        w.finish(at(2010));
        assert_eq!(w.last_latency_ms(), Some(2000.0));
        assert_eq!(w.failures(), 2, "consecutive, not reset by the late return");
        assert_eq!(w.queued(), 0);
    }

    #[test]
    fn a_zero_timeout_never_times_out() {
        let mut w = CallbackWatch::new(0, 1);
        w.start(at(0), G, true);
        assert_eq!(w.admit(), Admit::Queue);
        assert_eq!(w.poll(at(10_000_000)), Verdict::default());
        assert!(!w.finish(at(10_000_000)).drop_sinks);
    }
}
