//! The end-to-end runs of `cargo xtask test`, one test binary at a time under a **stall
//! guard**.
//!
//! One `cargo test --release --target T --no-run` builds every binary first; each then runs
//! directly under the target's runner (`xtask/wine-runner*.sh`, as cargo would run it: from
//! its package's folder, `-- --test-threads=1`), its output passed through line by line.
//! Running the built executables, rather than one `cargo test` per unit, keeps cargo from
//! resolving each unit's package alone, which unifies other features and rebuilds the
//! dependencies (minutes per bitness), and saves its check of the whole graph per unit. A
//! binary that prints nothing for [`QUIET_LIMIT`] has stalled: no test of ours is silent
//! that long (the slowest, the hostile 800,000-level VARIANTs, prints within 120 s). Then,
//! before anything is stopped, winedbg backtraces of every thread of the prefix's
//! processes of ours (the server and the test binary) and the Linux threads' wait channels
//! go to `target/stall/stall-<unix time>.txt` (the soak's capture, `soak::capture`), the
//! path and the stalled test are printed, the prefix's processes are ended, and that
//! binary runs **once more**; a second stall, or any failure, fails the run. Each rerun is
//! counted in the run's log of forgiven Wine trouble ([`forgiven`]) with its report, so
//! that the run's last line counts it and the lines above it name each stall.
//!
//! Why a retry: a stall of a test binary (in CI: 32-bit `group_async`, 1500 s silent)
//! matches Wine 8's combase deadlock of `docs/limits.md` (a last release unregistering an
//! interface while a call on it marshals another), a Wine bug that no input of ours
//! controls. A retry keeps one such stall from failing a 25-minute run while the report
//! keeps the evidence.

use super::forgiven::{self, Kind};
use crate::{soak, util, wine};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, ExitStatus, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// A binary silent this long has stalled (`CTOPC_STALL_SECONDS` overrides it, to see the
/// guard work on a test made to hang).
pub const QUIET_LIMIT: Duration = Duration::from_secs(240);

fn quiet_limit() -> Duration {
    std::env::var("CTOPC_STALL_SECONDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .map_or(QUIET_LIMIT, Duration::from_secs)
}

/// One test binary: a label and the cargo arguments that select it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Unit {
    pub label: String,
    pub cargo_args: Vec<String>,
}

impl Unit {
    /// The integration test `name` of package `package`.
    pub fn test(package: &str, name: &str) -> Unit {
        Unit {
            label: format!("{package} --test {name}"),
            cargo_args: ["-p", package, "--test", name].map(String::from).to_vec(),
        }
    }

    /// The unit tests of `package`'s library (the packages with end-to-end units have no
    /// tests in their binaries; selecting `--bins` would build every selected package's
    /// binaries as tests, the product's too).
    pub fn lib(package: &str) -> Unit {
        Unit {
            label: format!("{package} (unit tests)"),
            cargo_args: ["-p", package, "--lib"].map(String::from).to_vec(),
        }
    }
}

/// The integration tests of a package: the `.rs` files of its `tests/` folder, sorted.
pub fn integration_tests(dir: &Path) -> Result<Vec<String>, String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .map_err(|e| format!("{}: {e}", dir.display()))?
        .flatten()
        .filter_map(|e| {
            let name = e.file_name().to_string_lossy().into_owned();
            let stem = name.strip_suffix(".rs")?.to_owned();
            e.file_type().ok()?.is_file().then_some(stem)
        })
        .collect();
    names.sort();
    Ok(names)
}

/// The cargo arguments that select every unit at once (for the one `--no-run` build):
/// each `-p`, `--lib` and `--bins` once, every other argument (`--test NAME`) as it comes.
pub fn build_args(units: &[Unit]) -> Vec<String> {
    let mut out: Vec<String> = Vec::new();
    let mut seen: Vec<(String, String)> = Vec::new();
    for u in units {
        let mut args = u.cargo_args.iter();
        while let Some(a) = args.next() {
            match a.as_str() {
                "-p" | "--package" | "--test" => {
                    let Some(v) = args.next() else { break };
                    let key = (a.replace("--package", "-p"), v.clone());
                    if !seen.contains(&key) {
                        out.push(key.0.clone());
                        out.push(v.clone());
                        seen.push(key);
                    }
                }
                flag => {
                    let key = (flag.to_owned(), String::new());
                    if !seen.contains(&key) {
                        out.push(flag.to_owned());
                        seen.push(key);
                    }
                }
            }
        }
    }
    out
}

/// A test executable of the `--no-run` build (cargo's `compiler-artifact` message).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Built {
    pub package: String,
    /// `lib`, `bin` or `test`.
    pub kind: String,
    pub name: String,
    pub exe: PathBuf,
    /// The package's folder: cargo runs a test binary from there.
    pub dir: PathBuf,
    /// The target's source file, for the `Running` line.
    pub src: PathBuf,
}

/// Runs the `--no-run` build with JSON messages on standard output (the diagnostics still
/// rendered on standard error) and returns its test executables.
fn build_all(cmd: &mut Command) -> Result<Vec<Built>, String> {
    let what = format!("{cmd:?}");
    let out = cmd
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .output()
        .map_err(|e| format!("cannot start {what}: {e}"))?;
    if !out.status.success() {
        return Err(format!("{what}: {}", out.status));
    }
    Ok(String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter_map(built_of)
        .collect())
}

/// One line of cargo's JSON messages → a test executable, when it is one.
pub fn built_of(line: &str) -> Option<Built> {
    let v: serde_json::Value = serde_json::from_str(line).ok()?;
    if v["reason"] != "compiler-artifact" || v["profile"]["test"] != true {
        return None;
    }
    let exe = PathBuf::from(v["executable"].as_str()?);
    let manifest = PathBuf::from(v["manifest_path"].as_str()?);
    let target = &v["target"];
    Some(Built {
        package: package_name(v["package_id"].as_str()?)?.to_owned(),
        kind: target["kind"][0].as_str()?.to_owned(),
        name: target["name"].as_str()?.to_owned(),
        exe,
        dir: manifest.parent()?.to_path_buf(),
        src: PathBuf::from(target["src_path"].as_str()?),
    })
}

/// A package's name from cargo's package ID: `path+file:///w/tests#e2e-tests@0.1.0`, or
/// `path+file:///w/crates/ctopc-com#0.1.0` when the folder has the package's name.
pub fn package_name(id: &str) -> Option<&str> {
    let (url, frag) = id.rsplit_once('#')?;
    match frag.split_once('@') {
        Some((name, _)) => Some(name),
        None => url.rsplit('/').next(),
    }
}

/// The executables of `unit` when it is one of [`Unit::test`] or [`Unit::lib`]'s shapes
/// and the build made them; `None` for other cargo arguments (they run through cargo).
pub fn executables(built: &[Built], unit: &Unit) -> Option<Vec<Built>> {
    let args: Vec<&str> = unit.cargo_args.iter().map(String::as_str).collect();
    let found: Vec<Built> = match args.as_slice() {
        ["-p", package, "--test", name] => built
            .iter()
            .filter(|b| b.package == *package && b.kind == "test" && b.name == *name)
            .cloned()
            .collect(),
        ["-p", package, "--lib"] => built
            .iter()
            .filter(|b| b.package == *package && b.kind == "lib")
            .cloned()
            .collect(),
        _ => return None,
    };
    (!found.is_empty()).then_some(found)
}

/// The runner `.cargo/config.toml` names for a Windows target.
fn runner(target: &str) -> Option<PathBuf> {
    let script = match target {
        "x86_64-pc-windows-gnu" => "xtask/wine-runner.sh",
        "i686-pc-windows-gnu" => "xtask/wine-runner32.sh",
        _ => return None,
    };
    Some(util::root().join(script))
}

/// Runs a unit's executables one after the other, as `cargo test` would; the first that
/// does not pass ends the unit.
fn run_executables(
    runner: &Path,
    exes: &[Built],
    test_args: &[String],
) -> Result<(Outcome, std::process::Child), String> {
    let mut last = None;
    for b in exes {
        let src = b.src.strip_prefix(&b.dir).unwrap_or(&b.src);
        println!("     Running {} ({})", src.display(), b.exe.display());
        let _ = std::io::stdout().flush();
        let mut c = Command::new(runner);
        c.arg(&b.exe)
            .arg("--test-threads=1")
            .args(test_args)
            .current_dir(&b.dir)
            .env("CARGO_MANIFEST_DIR", &b.dir)
            .env("CARGO_PKG_NAME", &b.package);
        let (outcome, child) = run_watched(&mut c, quiet_limit())?;
        let passed = matches!(&outcome, Outcome::Exited(s) if s.success());
        if !passed {
            return Ok((outcome, child));
        }
        last = Some((outcome, child));
    }
    last.ok_or_else(|| "a unit without executables".to_owned())
}

/// How one run of a unit ended.
#[derive(Debug)]
pub enum Outcome {
    Exited(ExitStatus),
    /// Silent for [`QUIET_LIMIT`]; the last line it printed.
    Stalled {
        last_line: String,
    },
}

/// The test that was running when a binary went quiet: the last `test NAME ... ` line
/// without a result, from libtest's output.
pub fn running_test(last_line: &str) -> Option<&str> {
    let rest = last_line.strip_prefix("test ")?;
    let name = rest
        .strip_suffix(" ...")
        .or_else(|| rest.strip_suffix(" ... "))?;
    Some(name.trim())
}

/// Runs `cmd` with its output passed through; stops waiting when it has printed nothing
/// for `quiet` (the child is left running: the caller captures, then ends it).
pub fn run_watched(
    cmd: &mut Command,
    quiet: Duration,
) -> Result<(Outcome, std::process::Child), String> {
    let what = format!("{cmd:?}");
    let mut child = cmd
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| format!("cannot start {what}: {e}"))?;
    let last = Arc::new(Mutex::new((Instant::now(), String::new())));
    let mut readers = Vec::new();
    if let Some(out) = child.stdout.take() {
        readers.push(pass_through(out, Arc::clone(&last), false));
    }
    if let Some(err) = child.stderr.take() {
        readers.push(pass_through(err, Arc::clone(&last), true));
    }
    loop {
        match child.try_wait() {
            Ok(Some(status)) => {
                // The rest of its output, but no waiting on a pipe that a process it
                // started (a wineserver) may hold open.
                let until = Instant::now() + Duration::from_secs(2);
                while readers.iter().any(|r| !r.is_finished()) && Instant::now() < until {
                    std::thread::sleep(Duration::from_millis(20));
                }
                return Ok((Outcome::Exited(status), child));
            }
            Ok(None) => {
                let (at, line) = match last.lock() {
                    Ok(g) => g.clone(),
                    Err(p) => p.into_inner().clone(),
                };
                if at.elapsed() >= quiet {
                    return Ok((Outcome::Stalled { last_line: line }, child));
                }
                std::thread::sleep(Duration::from_millis(200));
            }
            Err(e) => return Err(format!("waiting for {what}: {e}")),
        }
    }
}

/// Copies `from` to our stdout (or stderr) as it comes — a partial line too (libtest's
/// `test NAME ... ` waits for its result) — and notes the time and the line of each chunk.
fn pass_through(
    mut from: impl std::io::Read + Send + 'static,
    last: Arc<Mutex<(Instant, String)>>,
    to_stderr: bool,
) -> std::thread::JoinHandle<()> {
    std::thread::spawn(move || {
        let mut buf = [0u8; 4096];
        let mut line = String::new();
        loop {
            let n = match from.read(&mut buf) {
                Ok(0) | Err(_) => return,
                Ok(n) => n,
            };
            let chunk = &buf[..n];
            if to_stderr {
                let _ = std::io::stderr().write_all(chunk);
            } else {
                let mut o = std::io::stdout();
                let _ = o.write_all(chunk);
                let _ = o.flush();
            }
            for part in String::from_utf8_lossy(chunk).split_inclusive('\n') {
                if line.ends_with('\n') {
                    line.clear();
                }
                line.push_str(part);
            }
            if let Ok(mut g) = last.lock() {
                *g = (Instant::now(), line.trim_end().to_owned());
            }
        }
    })
}

/// The Linux PIDs of the processes running in the project prefix (their environment
/// names it), and the Unix paths of the `.exe`s on their command lines.
fn prefix_processes() -> (Vec<u32>, Vec<PathBuf>) {
    let want = format!("WINEPREFIX={}", wine::prefix().display());
    let mut pids = Vec::new();
    let mut exes = Vec::new();
    let Ok(dir) = std::fs::read_dir("/proc") else {
        return (pids, exes);
    };
    for e in dir.flatten() {
        let Ok(pid) = e.file_name().to_string_lossy().parse::<u32>() else {
            continue;
        };
        let Ok(env) = std::fs::read(e.path().join("environ")) else {
            continue;
        };
        if !env.split(|b| *b == 0).any(|v| v == want.as_bytes()) {
            continue;
        }
        pids.push(pid);
        let cmd = std::fs::read(e.path().join("cmdline")).unwrap_or_default();
        for arg in String::from_utf8_lossy(&cmd).split('\0') {
            if let Some(p) = windows_exe_path(arg) {
                if !exes.contains(&p) {
                    exes.push(p);
                }
            }
        }
    }
    (pids, exes)
}

/// `Z:\work\x\y.exe` (Wine's Unix drive) or `/work/x/y.exe` as a Unix path; `None` for
/// anything else (a switch, a `C:` path of Wine's own programs).
pub fn windows_exe_path(arg: &str) -> Option<PathBuf> {
    let unix = match arg.strip_prefix("Z:").or_else(|| arg.strip_prefix("z:")) {
        Some(rest) => rest.replace('\\', "/"),
        None => arg.to_owned(),
    };
    let is_exe = unix.to_ascii_lowercase().ends_with(".exe");
    (is_exe && unix.starts_with('/')).then(|| PathBuf::from(unix))
}

/// The module name winedbg gives an exe: its file stem, lower case, without cargo's hash.
pub fn module_name(exe: &Path) -> String {
    exe.file_stem()
        .map(|s| s.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default()
}

/// A stall of `unit`: the report, then every process of the prefix ended.
fn on_stall(unit: &Unit, last_line: &str, mut child: std::process::Child) -> String {
    let test = running_test(last_line).unwrap_or("(between tests)");
    let what = format!(
        "{}: no output for {} s, in {test}",
        unit.label,
        quiet_limit().as_secs()
    );
    println!("\nguard: {what}: taking backtraces before stopping anything");
    let (pids, exes) = prefix_processes();
    let names: Vec<String> = exes.iter().map(|p| module_name(p)).collect();
    let named: Vec<(&str, &Path)> = names
        .iter()
        .map(String::as_str)
        .zip(exes.iter().map(PathBuf::as_path))
        .collect();
    let is_ours = |n: &str| {
        let n = n.to_ascii_lowercase();
        names.iter().any(|m| n.ends_with(&format!("{m}.exe")))
    };
    let dir = util::root().join("target/stall");
    let report = match soak::capture(&dir, &wine::prefix(), &pids, &named, &is_ours, &what) {
        Ok(path) => format!("{what}; report: {}", path.display()),
        Err(e) => format!("{what}; no report: {e}"),
    };
    let _ = child.kill();
    let _ = child.wait();
    wine::kill_all();
    println!("guard: {report}");
    report
}

/// How [`run_units`] runs its units.
pub struct Plan<'a> {
    pub target: &'a str,
    /// Arguments for the test binaries (after `--test-threads=1`): a name filter, say.
    pub test_args: &'a [String],
    /// The whole run may not take longer.
    pub limit: Duration,
    /// How many times a stalled unit runs again (`cargo xtask test`: 1).
    pub retries: u32,
    /// The cargo arguments of the one `--no-run` build (`build::test_selection`: what the
    /// Windows build built, so nothing is built again); empty: the units' own
    /// ([`build_args`]).
    pub build: &'a [String],
}

/// Runs each of `units` (`cargo test --release --target TARGET <unit> -- --test-threads=1
/// TEST_ARGS`) in turn, running a stalled one again up to `retries` times (each rerun
/// counted: [`Kind::StallRerun`]).
/// Fails at the first failure, a stall beyond the retries, or when the whole run passes
/// `limit`.
pub fn run_units(plan: &Plan<'_>, units: &[Unit]) -> Result<(), String> {
    let Plan {
        target,
        test_args,
        limit,
        retries,
        build,
    } = *plan;
    let start = Instant::now();
    let command = |extra: &[&str], unit: Option<&Unit>| {
        let mut c = util::cargo();
        c.args(["test", "--release", "--target", target]);
        match unit {
            Some(u) => {
                c.args(&u.cargo_args);
            }
            None if build.is_empty() => {
                c.args(build_args(units));
            }
            None => {
                c.args(build);
            }
        }
        c.args(extra);
        c
    };
    // One build of every binary first, so that no build counts as a test's silence.
    let built = build_all(&mut command(
        &["--no-run", "--message-format=json-render-diagnostics"],
        None,
    ))?;
    let runner = runner(target);
    for unit in units {
        let mut tries = 0;
        loop {
            if start.elapsed() >= limit {
                return Err(format!(
                    "end-to-end tests ({target}): over {} s, stopped before {}",
                    limit.as_secs(),
                    unit.label
                ));
            }
            tries += 1;
            let t0 = Instant::now();
            let (outcome, child) = match (executables(&built, unit), &runner) {
                (Some(exes), Some(runner)) => run_executables(runner, &exes, test_args)?,
                _ => {
                    let mut c = command(&["--", "--test-threads=1"], Some(unit));
                    c.args(test_args);
                    run_watched(&mut c, quiet_limit())?
                }
            };
            match outcome {
                Outcome::Exited(status) if status.success() => {
                    println!(
                        "guard: {} passed in {:.1} s",
                        unit.label,
                        t0.elapsed().as_secs_f64()
                    );
                    break;
                }
                Outcome::Exited(status) => {
                    return Err(format!(
                        "end-to-end tests ({target}) failed: {}: {status}",
                        unit.label
                    ))
                }
                Outcome::Stalled { last_line } => {
                    let report = on_stall(unit, &last_line, child);
                    if tries > retries {
                        return Err(format!(
                            "end-to-end tests ({target}): {} stalled ({tries} of {tries} runs): {report}",
                            unit.label
                        ));
                    }
                    forgiven::record(Kind::StallRerun, &report);
                    println!("guard: running {} once more", unit.label);
                }
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_running_test_is_the_last_line_without_a_result() {
        assert_eq!(
            running_test("test async_write_completes_with_on_write_complete ..."),
            Some("async_write_completes_with_on_write_complete")
        );
        assert_eq!(running_test("test a ... ok"), None);
        assert_eq!(running_test("running 12 tests"), None);
    }

    #[test]
    fn package_names_from_cargo_package_ids() {
        assert_eq!(
            package_name("path+file:///w/tests#e2e-tests@0.1.0"),
            Some("e2e-tests")
        );
        assert_eq!(
            package_name("path+file:///w/crates/ctopc-com#0.1.0"),
            Some("ctopc-com")
        );
        assert_eq!(package_name("no fragment"), None);
    }

    #[test]
    fn test_executables_from_cargo_messages_and_units() {
        let line = |pkg: &str, kind: &str, name: &str, test: bool| {
            format!(
                r#"{{"reason":"compiler-artifact","package_id":"path+file:///w/{pkg}#0.1.0","manifest_path":"/w/{pkg}/Cargo.toml","target":{{"kind":["{kind}"],"name":"{name}","src_path":"/w/{pkg}/src/{name}.rs"}},"profile":{{"test":{test}}},"executable":"/t/{name}.exe"}}"#
            )
        };
        let built: Vec<Built> = [
            line("ctopc-com", "lib", "ctopc_com", true),
            line("ctopc-com", "lib", "ctopc_com", false),
            line("ctopc-com", "test", "inproc_server", true),
            line("tests", "test", "group_io", true),
            r#"{"reason":"build-finished","success":true}"#.to_owned(),
            "not json".to_owned(),
        ]
        .iter()
        .filter_map(|l| built_of(l))
        .collect();
        assert_eq!(built.len(), 3, "{built:?}");
        assert_eq!(built[0].dir, PathBuf::from("/w/ctopc-com"));
        let lib = executables(&built, &Unit::lib("ctopc-com")).unwrap();
        assert_eq!(lib.len(), 1);
        assert_eq!(lib[0].exe, PathBuf::from("/t/ctopc_com.exe"));
        let t = executables(&built, &Unit::test("tests", "group_io")).unwrap();
        assert_eq!(t[0].name, "group_io");
        assert_eq!(executables(&built, &Unit::test("tests", "missing")), None);
        let other = Unit {
            label: "custom".into(),
            cargo_args: vec!["-p".into(), "ctopc-com".into()],
        };
        assert_eq!(executables(&built, &other), None);
    }

    #[test]
    fn exe_paths_from_wine_command_lines() {
        assert_eq!(
            windows_exe_path(r"Z:\work\main\target\x\release\ServerCTOPC.exe"),
            Some(PathBuf::from("/work/main/target/x/release/ServerCTOPC.exe"))
        );
        assert_eq!(
            windows_exe_path("/work/main/target/deps/group_async-5caeb.exe"),
            Some(PathBuf::from(
                "/work/main/target/deps/group_async-5caeb.exe"
            ))
        );
        assert_eq!(windows_exe_path("-Embedding"), None);
        assert_eq!(windows_exe_path(r"C:\windows\system32\rpcss.exe"), None);
        assert_eq!(
            module_name(Path::new("/t/deps/group_async-5caeb.exe")),
            "group_async-5caeb"
        );
    }

    #[test]
    fn a_silent_command_is_a_stall_with_its_last_line_and_a_talking_one_exits() {
        let mut c = Command::new("sh");
        c.args([
            "-c",
            "echo running 1 test; printf 'test slow ... '; sleep 30",
        ]);
        let t0 = Instant::now();
        let (outcome, mut child) = run_watched(&mut c, Duration::from_millis(700)).unwrap();
        let _ = child.kill();
        let _ = child.wait();
        assert!(t0.elapsed() < Duration::from_secs(10));
        match outcome {
            Outcome::Stalled { last_line } => {
                assert_eq!(running_test(&last_line), Some("slow"), "{last_line:?}")
            }
            Outcome::Exited(s) => panic!("exited: {s}"),
        }
        // Output every 300 ms keeps a 700 ms guard quiet; the exit status comes back.
        let mut c = Command::new("sh");
        c.args([
            "-c",
            "for i in 1 2 3 4 5; do echo $i; sleep 0.3; done; exit 3",
        ]);
        let (outcome, _) = run_watched(&mut c, Duration::from_millis(700)).unwrap();
        match outcome {
            Outcome::Exited(s) => assert_eq!(s.code(), Some(3)),
            Outcome::Stalled { last_line } => panic!("stalled after {last_line:?}"),
        }
    }

    #[test]
    fn units_select_one_binary_each() {
        assert_eq!(
            Unit::test("e2e-tests", "da10").cargo_args,
            ["-p", "e2e-tests", "--test", "da10"]
        );
        assert_eq!(
            Unit::lib("ctopc-com").cargo_args,
            ["-p", "ctopc-com", "--lib"]
        );
    }

    #[test]
    fn one_build_selects_each_package_and_flag_once() {
        let units = [
            Unit::lib("ctopc-com"),
            Unit::test("ctopc-com", "inproc_server"),
            Unit::lib("e2e-tests"),
            Unit::test("e2e-tests", "da10"),
        ];
        assert_eq!(
            build_args(&units).join(" "),
            "-p ctopc-com --lib --test inproc_server -p e2e-tests --test da10"
        );
    }

    #[test]
    fn integration_tests_are_the_rs_files_of_the_folder_sorted() {
        let dir = std::env::temp_dir().join(format!("guard-{}", std::process::id()));
        std::fs::create_dir_all(dir.join("common")).unwrap();
        for f in ["b.rs", "a.rs", "notes.txt"] {
            std::fs::write(dir.join(f), "").unwrap();
        }
        let names = integration_tests(&dir).unwrap();
        let _ = std::fs::remove_dir_all(&dir);
        assert_eq!(names, ["a", "b"]);
    }
}
