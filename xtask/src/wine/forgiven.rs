//! The count of the Wine trouble the harness forgives. A green `cargo xtask test` means
//! "green, forgiving what its last line counts":
//!
//! `forgiven: 0 SIGKILL-after-ok, 1 stall rerun, 0 CreateProcess-1359 retry, 0 opcdiag retry`
//!
//! Four places forgive, each appending one line `<tag> <what>` ([`Kind::tag`]) to the run's
//! log when the environment variable [`ENV`] names one:
//! - `xtask/wine-run.sh` (both cargo runners): a test binary that Wine SIGKILLed after
//!   libtest's final `test result: ok.` is counted as passed ([`Kind::SigkillAfterOk`]);
//! - [`guard`](super::guard): a test binary that stalled runs once more
//!   ([`Kind::StallRerun`]);
//! - `tests/src/start.rs`, inside the Wine test processes: a start that Wine's
//!   `CreateProcess` failed with `ERROR_INTERNAL_ERROR` (1359) is tried again
//!   ([`Kind::CreateProcessRetry`]); it opens the log by its `Z:` path;
//! - [`start`](super::start) (the msi-test's opcdiag runs): an opcdiag that failed having
//!   printed nothing is started again ([`Kind::OpcdiagRetry`]).
//!
//! The xtask command that owns a run ([`Ledger::begin`]: `test` and `e2e`, or `msi-test`
//! run alone) truncates its log ([`path`], `target/wine/forgiven.log`; the msi-test's
//! `target/msi-test/forgiven.log`) and names it in [`ENV`] for every process it starts
//! (an xtask started by it, the background `msi-test --built`, finds [`ENV`] set and writes
//! to the same log); at its end it prints the tally, also when the run failed
//! ([`Ledger::end`]). Each line is one `write` to a file opened for appending, so the lines
//! of processes that forgive at the same moment do not mix.

use crate::util;
use std::io::Write as _;
use std::path::{Path, PathBuf};

/// The environment variable naming the log (a Unix path), set by the owning xtask.
pub const ENV: &str = "CTOPC_FORGIVEN_LOG";

/// One kind of Wine trouble the harness forgives.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    SigkillAfterOk,
    StallRerun,
    CreateProcessRetry,
    OpcdiagRetry,
}

impl Kind {
    /// In the order of the summary line.
    pub const ALL: [Kind; 4] = [
        Kind::SigkillAfterOk,
        Kind::StallRerun,
        Kind::CreateProcessRetry,
        Kind::OpcdiagRetry,
    ];

    /// The first word of its lines in the log. `xtask/wine-run.sh` and `tests/src/start.rs`
    /// write theirs as text: keep them equal.
    pub fn tag(self) -> &'static str {
        match self {
            Kind::SigkillAfterOk => "sigkill-after-ok",
            Kind::StallRerun => "stall-rerun",
            Kind::CreateProcessRetry => "createprocess-1359-retry",
            Kind::OpcdiagRetry => "opcdiag-retry",
        }
    }

    /// Its name in the summary line.
    pub fn label(self) -> &'static str {
        match self {
            Kind::SigkillAfterOk => "SIGKILL-after-ok",
            Kind::StallRerun => "stall rerun",
            Kind::CreateProcessRetry => "CreateProcess-1359 retry",
            Kind::OpcdiagRetry => "opcdiag retry",
        }
    }

    fn from_tag(tag: &str) -> Option<Kind> {
        Kind::ALL.into_iter().find(|k| k.tag() == tag)
    }
}

/// The log of `cargo xtask test` and `e2e`.
pub fn path() -> PathBuf {
    util::root().join("target/wine/forgiven.log")
}

/// Appends `<tag> <what>` to `log` in one write (`what` on one line).
pub fn append(log: &Path, kind: Kind, what: &str) -> std::io::Result<()> {
    let what = what.replace(['\r', '\n'], " ");
    let line = format!("{} {}\n", kind.tag(), what.trim());
    std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(log)?
        .write_all(line.as_bytes())
}

/// Counts one forgiveness in the log [`ENV`] names (nothing when it names none: a command
/// that owns no run); a log that cannot be written is said on stderr, not fatal.
pub fn record(kind: Kind, what: &str) {
    let Some(log) = std::env::var_os(ENV) else {
        return;
    };
    let log = PathBuf::from(log);
    if let Err(e) = append(&log, kind, what) {
        eprintln!(
            "forgiven: cannot count a {} in {}: {e}",
            kind.label(),
            log.display()
        );
    }
}

/// What a log holds: the count of each kind, every line's detail, and the lines whose tag
/// is none of [`Kind::ALL`] (counted apart, so that a misspelt tag is not lost).
#[derive(Debug, Default, PartialEq, Eq)]
pub struct Tally {
    counts: [usize; Kind::ALL.len()],
    details: Vec<(Kind, String)>,
    unrecognised: Vec<String>,
}

impl Tally {
    pub fn parse(text: &str) -> Tally {
        let mut t = Tally::default();
        for line in text.lines().map(str::trim).filter(|l| !l.is_empty()) {
            let (tag, what) = line.split_once(' ').unwrap_or((line, ""));
            match Kind::from_tag(tag) {
                Some(kind) => {
                    if let Some(i) = Kind::ALL.iter().position(|k| *k == kind) {
                        t.counts[i] += 1;
                    }
                    t.details.push((kind, what.trim().to_owned()));
                }
                None => t.unrecognised.push(line.to_owned()),
            }
        }
        t
    }

    pub fn count(&self, kind: Kind) -> usize {
        Kind::ALL
            .iter()
            .position(|k| *k == kind)
            .map_or(0, |i| self.counts[i])
    }

    /// The summary line: every kind, zeros included.
    pub fn line(&self) -> String {
        let mut parts: Vec<String> = Kind::ALL
            .iter()
            .map(|k| format!("{} {}", self.count(*k), k.label()))
            .collect();
        if !self.unrecognised.is_empty() {
            parts.push(format!("{} unrecognised", self.unrecognised.len()));
        }
        format!("forgiven: {}", parts.join(", "))
    }

    /// One line per forgiveness (what was forgiven), then [`Self::line`].
    pub fn report(&self) -> String {
        let mut out = String::new();
        for (kind, what) in &self.details {
            out.push_str(&format!("forgiven {}: {what}\n", kind.label()));
        }
        for line in &self.unrecognised {
            out.push_str(&format!("forgiven, unrecognised line: {line}\n"));
        }
        out.push_str(&self.line());
        out
    }
}

/// The log of one xtask run; only the owner (the outermost xtask) truncates and tallies it.
pub struct Ledger {
    log: PathBuf,
    owner: bool,
}

impl Ledger {
    /// Opens the run's log: the one [`ENV`] names when an xtask above this one set it, else
    /// `log` ([`path`] for `test` and `e2e`), truncated and named in [`ENV`] for every
    /// process started from now on. Call it first, before any thread is started.
    pub fn begin(log: &Path) -> Result<Ledger, String> {
        if let Some(above) = std::env::var_os(ENV) {
            return Ok(Ledger {
                log: PathBuf::from(above),
                owner: false,
            });
        }
        if let Some(dir) = log.parent() {
            std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
        }
        std::fs::File::create(log).map_err(|e| format!("{}: {e}", log.display()))?;
        std::env::set_var(ENV, log);
        Ok(Ledger {
            log: log.to_path_buf(),
            owner: true,
        })
    }

    /// `result` with the tally at its end: printed as the run's last line when it passed,
    /// appended to the error when it failed. A ledger that does not own the log returns
    /// `result` as it is.
    pub fn end(self, result: Result<(), String>) -> Result<(), String> {
        if !self.owner {
            return result;
        }
        let text = std::fs::read_to_string(&self.log).unwrap_or_default();
        with_report(result, &Tally::parse(&text))
    }
}

fn with_report(result: Result<(), String>, tally: &Tally) -> Result<(), String> {
    match result {
        Ok(()) => {
            println!("{}", tally.report());
            Ok(())
        }
        Err(e) => Err(format!("{e}\n{}", tally.report())),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::process::Command;

    fn temp_log(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("forgiven-{}-{name}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let log = dir.join("forgiven.log");
        let _ = std::fs::remove_file(&log);
        log
    }

    #[test]
    fn an_empty_log_counts_zero_of_each_kind() {
        let t = Tally::parse("");
        assert_eq!(
            t.line(),
            "forgiven: 0 SIGKILL-after-ok, 0 stall rerun, 0 CreateProcess-1359 retry, 0 opcdiag retry"
        );
        assert_eq!(t.report(), t.line());
    }

    #[test]
    fn each_line_counts_its_kind_and_unknown_tags_are_counted_apart() {
        let text = "\
stall-rerun e2e-tests --test group_async: no output for 240 s, in a_test; report: /t/stall-1.txt
createprocess-1359-retry Z:\\w\\opcdiag.exe: Internal error. (os error 1359)

createprocess-1359-retry Z:\\w\\opcdiag.exe: Internal error. (os error 1359)
sigkill-after-ok Z:\\w\\group_callbacks-1a2b.exe
stall-retry misspelt
";
        let t = Tally::parse(text);
        assert_eq!(t.count(Kind::SigkillAfterOk), 1);
        assert_eq!(t.count(Kind::StallRerun), 1);
        assert_eq!(t.count(Kind::CreateProcessRetry), 2);
        assert_eq!(t.count(Kind::OpcdiagRetry), 0);
        assert_eq!(
            t.line(),
            "forgiven: 1 SIGKILL-after-ok, 1 stall rerun, 2 CreateProcess-1359 retry, 0 opcdiag retry, 1 unrecognised"
        );
        let report = t.report();
        assert!(report.starts_with("forgiven stall rerun: e2e-tests --test group_async"));
        assert!(report.contains("forgiven, unrecognised line: stall-retry misspelt\n"));
        assert!(report.ends_with(&t.line()), "{report}");
    }

    #[test]
    fn appended_lines_are_tallied_by_kind() {
        let log = temp_log("append");
        for kind in Kind::ALL {
            append(&log, kind, "what\nit was").unwrap();
        }
        append(&log, Kind::OpcdiagRetry, "X64 opcdiag status").unwrap();
        let text = std::fs::read_to_string(&log).unwrap();
        assert_eq!(text.lines().count(), 5, "{text}");
        assert!(text.contains("stall-rerun what it was\n"), "{text}");
        let t = Tally::parse(&text);
        assert_eq!(
            t.line(),
            "forgiven: 1 SIGKILL-after-ok, 1 stall rerun, 1 CreateProcess-1359 retry, 2 opcdiag retry"
        );
    }

    #[test]
    fn a_failed_run_carries_the_tally_as_the_last_lines_of_its_error() {
        let t = Tally::parse("opcdiag-retry X86 opcdiag status\n");
        let e = with_report(Err("msi-test failed".into()), &t).unwrap_err();
        assert_eq!(
            e,
            "msi-test failed\nforgiven opcdiag retry: X86 opcdiag status\n\
             forgiven: 0 SIGKILL-after-ok, 0 stall rerun, 0 CreateProcess-1359 retry, 1 opcdiag retry"
        );
        assert_eq!(with_report(Ok(()), &t), Ok(()));
    }

    /// The tags written as text elsewhere are the ones the tally knows.
    #[test]
    fn the_runner_script_and_the_test_helper_write_known_tags() {
        let root = util::root();
        let script = std::fs::read_to_string(root.join("xtask/wine-run.sh")).unwrap();
        assert!(
            script.contains(&format!("echo \"{} ", Kind::SigkillAfterOk.tag())),
            "xtask/wine-run.sh does not count with the tag {}",
            Kind::SigkillAfterOk.tag()
        );
        let start = std::fs::read_to_string(root.join("tests/src/start.rs")).unwrap();
        assert!(
            start.contains(&format!("\"{}\"", Kind::CreateProcessRetry.tag())),
            "tests/src/start.rs does not count with the tag {}",
            Kind::CreateProcessRetry.tag()
        );
        assert!(
            start.contains(&format!("\"{ENV}\"")),
            "tests/src/start.rs reads {ENV}"
        );
    }

    /// The runner script on a fake loader (`sh -c ...`): a SIGKILL after `test result: ok.`
    /// is exit 0 and one counted line; a SIGKILL before it is the program's 137, uncounted.
    #[test]
    fn the_runner_script_counts_a_sigkill_after_ok_and_nothing_else() {
        let script = util::root().join("xtask/wine-run.sh");
        let run = |log: &Path, program: &str| {
            let out = Command::new("sh")
                .arg(&script)
                .args(["sh", "-c", program])
                .env(ENV, log)
                .output()
                .unwrap();
            (
                out.status.code(),
                String::from_utf8_lossy(&out.stdout).into_owned(),
            )
        };
        let log = temp_log("runner");
        let (code, out) = run(
            &log,
            "echo 'test result: ok. 3 passed; 0 failed'; kill -9 $$",
        );
        assert_eq!(code, Some(0), "{out}");
        assert!(
            out.contains("test result: ok."),
            "the output streams: {out:?}"
        );
        let text = std::fs::read_to_string(&log).unwrap();
        assert_eq!(Tally::parse(&text).count(Kind::SigkillAfterOk), 1, "{text}");
        assert_eq!(text, "sigkill-after-ok -c\n");

        let log = temp_log("runner-fail");
        let (code, _) = run(&log, "echo 'running 3 tests'; kill -9 $$");
        assert_eq!(code, Some(137));
        let (code, _) = run(
            &log,
            "echo 'test result: ok.'; echo 'test result: FAILED.'; kill -9 $$",
        );
        assert_eq!(code, Some(137));
        let (code, _) = run(&log, "echo 'test result: ok.'; exit 0");
        assert_eq!(code, Some(0));
        assert!(!log.exists(), "nothing forgiven, nothing written");
    }
}
