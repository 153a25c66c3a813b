//! Small process helpers: running commands with timeouts and clear errors.

use std::path::{Path, PathBuf};
use std::process::{Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

/// The workspace root (the parent of xtask/).
pub fn root() -> PathBuf {
    let manifest = std::env::var("CARGO_MANIFEST_DIR").unwrap_or_else(|_| ".".into());
    let p = Path::new(&manifest);
    p.parent()
        .map(Path::to_path_buf)
        .unwrap_or_else(|| p.to_path_buf())
}

/// `cargo` as invoked by the user (respects $CARGO, rustup's proxy).
pub fn cargo() -> Command {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let mut c = Command::new(cargo);
    c.current_dir(root());
    c
}

fn describe(cmd: &Command) -> String {
    let mut s = cmd.get_program().to_string_lossy().into_owned();
    for a in cmd.get_args() {
        s.push(' ');
        s.push_str(&a.to_string_lossy());
    }
    s
}

/// Runs `cmd`, inheriting stdio; an error names the command and its status.
pub fn run(cmd: &mut Command) -> Result<(), String> {
    let status = cmd
        .status()
        .map_err(|e| format!("cannot start `{}`: {e}", describe(cmd)))?;
    if status.success() {
        Ok(())
    } else {
        Err(format!("`{}` failed: {status}", describe(cmd)))
    }
}

/// Runs `cmd` and returns its stdout; an error carries stderr.
pub fn output(cmd: &mut Command) -> Result<String, String> {
    let out = cmd
        .stderr(Stdio::piped())
        .stdout(Stdio::piped())
        .output()
        .map_err(|e| format!("cannot start `{}`: {e}", describe(cmd)))?;
    if out.status.success() {
        Ok(String::from_utf8_lossy(&out.stdout).into_owned())
    } else {
        Err(format!(
            "`{}` failed: {}\n{}",
            describe(cmd),
            out.status,
            String::from_utf8_lossy(&out.stderr)
        ))
    }
}

/// Runs `cmd` (stdio inherited) and kills it after `limit`. Returns the exit status,
/// or an error when it timed out.
pub fn run_with_timeout(cmd: &mut Command, limit: Duration) -> Result<ExitStatus, String> {
    let what = describe(cmd);
    let mut child = cmd
        .spawn()
        .map_err(|e| format!("cannot start `{what}`: {e}"))?;
    let start = Instant::now();
    loop {
        match child.try_wait() {
            Ok(Some(status)) => return Ok(status),
            Ok(None) if start.elapsed() >= limit => {
                let _ = child.kill();
                let _ = child.wait();
                return Err(format!(
                    "`{what}` timed out after {} s and was killed",
                    limit.as_secs()
                ));
            }
            Ok(None) => std::thread::sleep(Duration::from_millis(50)),
            Err(e) => return Err(format!("waiting for `{what}`: {e}")),
        }
    }
}

/// True when `path` exists and is newer than every file in `inputs` (recursively).
pub fn up_to_date(path: &Path, inputs: &[PathBuf]) -> bool {
    let Ok(out_time) = path.metadata().and_then(|m| m.modified()) else {
        return false;
    };
    fn newest(p: &Path) -> Option<std::time::SystemTime> {
        let meta = p.metadata().ok()?;
        if meta.is_dir() {
            let mut best = meta.modified().ok();
            for e in std::fs::read_dir(p).ok()?.flatten() {
                if let Some(t) = newest(&e.path()) {
                    best = Some(best.map_or(t, |b| b.max(t)));
                }
            }
            best
        } else {
            meta.modified().ok()
        }
    }
    inputs
        .iter()
        .all(|i| newest(i).is_some_and(|t| t <= out_time))
}

pub fn is_root() -> bool {
    output(Command::new("id").arg("-u"))
        .map(|s| s.trim() == "0")
        .unwrap_or(false)
}
