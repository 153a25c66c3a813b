//! Running `opcdiag doctor` against broken installations without breaking the prefix the
//! other tests use: each broken setup is a **copy of the registered prefix** under
//! `target/wine/doctor-<case>` (its registry files copied, `drive_c` shared through a
//! symbolic link: the registry is what the cases break), with a wineserver of its own, so
//! that a server it starts never answers another test's client.
//!
//! The copy is made and used from the Unix side: Wine starts Unix programs (here
//! `/bin/sh`), but gives no handle to wait for, so the script's output and exit status
//! come back through files, polled with a time limit.

use crate::start::StartRetrying;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// What one opcdiag doctor run gave.
pub struct Run {
    pub code: i32,
    pub stdout: String,
    pub stderr: String,
}

impl std::fmt::Debug for Run {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "exit code {}\n--- stdout ---\n{}--- stderr ---\n{}",
            self.code, self.stdout, self.stderr
        )
    }
}

/// One check of `--json`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct JsonCheck {
    pub name: String,
    pub status: String,
    pub detail: String,
    pub fix: String,
}

impl Run {
    /// The checks of a `--json` report (one object a line, as opcdiag writes them).
    pub fn checks(&self) -> Vec<JsonCheck> {
        self.stdout
            .lines()
            .filter_map(|l| {
                let fields = json_fields(l.trim().trim_end_matches(','))?;
                let get = |k: &str| {
                    fields
                        .iter()
                        .find(|(n, _)| n == k)
                        .map(|(_, v)| v.clone())
                        .unwrap_or_default()
                };
                Some(JsonCheck {
                    name: get("name"),
                    status: get("status"),
                    detail: get("detail"),
                    fix: get("fix"),
                })
            })
            .collect()
    }

    /// The check named `name` (panics with the report when there is none).
    pub fn check(&self, name: &str) -> JsonCheck {
        self.checks()
            .into_iter()
            .find(|c| c.name == name)
            .unwrap_or_else(|| panic!("no check {name:?} in\n{self:?}"))
    }
}

/// The `"key": "value"` pairs of a flat JSON object of strings.
fn json_fields(line: &str) -> Option<Vec<(String, String)>> {
    let body = line.strip_prefix('{')?.strip_suffix('}')?;
    let mut chars = body.chars().peekable();
    let mut out = Vec::new();
    let read_string = |chars: &mut std::iter::Peekable<std::str::Chars>| -> Option<String> {
        while chars.peek().is_some_and(|c| *c != '"') {
            chars.next();
        }
        chars.next()?;
        let mut s = String::new();
        loop {
            match chars.next()? {
                '"' => return Some(s),
                '\\' => match chars.next()? {
                    'n' => s.push('\n'),
                    'r' => s.push('\r'),
                    't' => s.push('\t'),
                    'u' => {
                        let hex: String = chars.by_ref().take(4).collect();
                        s.push(char::from_u32(u32::from_str_radix(&hex, 16).ok()?)?);
                    }
                    c => s.push(c),
                },
                c => s.push(c),
            }
        }
    };
    while let Some(key) = read_string(&mut chars) {
        let value = read_string(&mut chars)?;
        out.push((key, value));
    }
    Some(out)
}

/// The Unix path of a Windows path on Wine's `Z:` drive.
pub fn unix_path(p: &Path) -> String {
    let s = p.display().to_string();
    let s = s.strip_prefix(r"\\?\").unwrap_or(&s);
    let s = s
        .strip_prefix("Z:")
        .or_else(|| s.strip_prefix("z:"))
        .unwrap_or(s);
    s.replace('\\', "/")
}

/// The Windows path (on `Z:`) of a Unix path.
pub fn windows_path(unix: &str) -> PathBuf {
    PathBuf::from(format!("Z:{}", unix.replace('/', "\\")))
}

/// The repository's root (the test binary is in target/<triple>/release/deps).
pub fn repo_root() -> PathBuf {
    let exe = std::env::current_exe().expect("current_exe");
    exe.ancestors()
        .nth(5)
        .expect("repository root above target/<triple>/release/deps")
        .to_path_buf()
}

/// The Wine loader of the test's own bitness (it runs the opcdiag of that bitness).
pub fn loader() -> &'static str {
    if cfg!(target_pointer_width = "64") {
        "/usr/lib/wine/wine64"
    } else {
        "/usr/lib/wine/wine"
    }
}

/// Single-quoted for `sh`.
pub fn sh_quote(s: &str) -> String {
    format!("'{}'", s.replace('\'', r"'\''"))
}

/// Runs `script` with `/bin/sh` on the Unix side, in `dir` (a Unix path, created), within
/// `limit`: its exit status and output (stdout and stderr together).
// Wine gives no handle of a Unix process to wait for: the script reports through files.
#[allow(clippy::zombie_processes)]
pub fn unix_sh(dir: &str, script: &str, limit: Duration) -> (i32, String) {
    let wdir = windows_path(dir);
    std::fs::create_dir_all(&wdir).expect("create the case's folder");
    let rc = wdir.join("rc");
    let out = wdir.join("out");
    let _ = std::fs::remove_file(&rc);
    let d = sh_quote(dir);
    // Wine's own variables of this process would confuse the Wine the script starts.
    let wrapped = format!(
        "unset WINESERVERSOCKET WINELOADERNOEXEC WINEPRELOADRESERVE; cd {d} && ( {script} ) > {d}/out 2>&1; echo $? > {d}/rc.tmp; mv {d}/rc.tmp {d}/rc"
    );
    std::process::Command::new("/bin/sh")
        .args(["-c", &wrapped])
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn_retrying()
        .expect("start /bin/sh through Wine");
    // The script writes its exit code last: wait for that file.
    let code = test_support::wait::wait_for(limit, || std::fs::read_to_string(&rc).ok())
        .unwrap_or_else(|| {
            panic!(
                "the script in {dir} did not end within {limit:?}; output so far:\n{}",
                std::fs::read_to_string(&out).unwrap_or_default()
            )
        });
    (
        code.trim().parse().unwrap_or(-1),
        std::fs::read_to_string(&out).unwrap_or_default(),
    )
}

/// A broken copy of the test prefix: `target/wine/doctor-<case>`.
pub struct BrokenPrefix {
    /// Unix path of the copy.
    pub dir: String,
}

impl BrokenPrefix {
    /// Copies the prefix the test runs in (`WINEPREFIX`) and runs `setup` (sh commands,
    /// with `$W` the Wine loader and `WINEPREFIX` the copy) in it.
    pub fn new(case: &str, setup: &str) -> BrokenPrefix {
        let src = std::env::var("WINEPREFIX").expect("WINEPREFIX (set by the Wine runner)");
        let src = src.trim_end_matches('/').to_owned();
        let parent = Path::new(&src)
            .parent()
            .expect("the prefix's folder")
            .display()
            .to_string();
        let dir = format!("{parent}/doctor-{case}");
        let (s, d) = (sh_quote(&src), sh_quote(&dir));
        let script = format!(
            "set -e; rm -rf {d}/pfx; mkdir -p {d}/pfx; \
             for f in {s}/* {s}/.[!.]*; do [ \"$(basename \"$f\")\" = drive_c ] || cp -a \"$f\" {d}/pfx/; done; \
             ln -s {s}/drive_c {d}/pfx/drive_c; \
             export WINEPREFIX={d}/pfx WINEARCH=win64 WINEDEBUG=-all WINEDLLOVERRIDES='mscoree,mshtml='; \
             W={w}; {setup}",
            w = loader()
        );
        let (code, out) = unix_sh(&dir, &script, Duration::from_secs(60));
        assert_eq!(code, 0, "setting up the broken prefix {dir} failed:\n{out}");
        BrokenPrefix { dir }
    }

    /// Runs `opcdiag doctor --json ARGS` in the copy, then ends its wineserver.
    pub fn doctor(&self, args: &[&str], limit: Duration) -> Run {
        let exe = unix_path(&crate::own_artifact("opcdiag.exe"));
        let d = sh_quote(&self.dir);
        let args: Vec<String> = args.iter().map(|a| sh_quote(a)).collect();
        let script = format!(
            "export WINEPREFIX={d}/pfx WINEARCH=win64 WINEDEBUG=-all WINEDLLOVERRIDES='mscoree,mshtml='; \
             {w} {exe} doctor --json {args} > {d}/stdout 2> {d}/stderr; rc=$?; \
             /usr/lib/wine/wineserver -k; exit $rc",
            w = loader(),
            exe = sh_quote(&exe),
            args = args.join(" ")
        );
        let (code, out) = unix_sh(&self.dir, &script, limit);
        let read =
            |f: &str| std::fs::read_to_string(windows_path(&self.dir).join(f)).unwrap_or_default();
        Run {
            code,
            stdout: read("stdout"),
            stderr: format!("{}{out}", read("stderr")),
        }
    }
}

impl Drop for BrokenPrefix {
    fn drop(&mut self) {
        // The copy's registry files only (drive_c is the shared prefix's: not followed).
        let d = sh_quote(&self.dir);
        let _ = std::process::Command::new("/bin/sh")
            .args(["-c", &format!("rm -rf {d}/pfx")])
            .stdin(std::process::Stdio::null())
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn_retrying();
    }
}
