//! `opcdiag doctor` against a working installation (the test prefix: every check OK but
//! the warnings Wine always gives, exit code 0) and against broken ones, each made in a
//! copy of the prefix (`e2e_tests::doctor::BrokenPrefix`, so the prefix the other tests
//! use is never broken): the proxy/stub unregistered, the exe moved, an invalid
//! configuration, a missing variable database, an unreachable asix server. Each is found
//! with FAIL and its fix, and the exit code is 1. A users file open to Everyone is a
//! WARN with the fix.
//!
//! Spec: OPC DA 2.05a §5.1 Component Categories and §5.2 Registry Entries for Custom
//! Interface (the server's and the proxy/stub's registration that doctor checks); OPC DA
//! 2.05a §4.4.4 IOPCServer::GetStatus and §4.3.3 Subscription via IOPCDataCallback (its
//! connection, read and callback checks).
#![cfg(windows)]
#![allow(clippy::unwrap_used, clippy::expect_used)]

use e2e_tests::doctor::{repo_root, unix_path, BrokenPrefix, Run};
use e2e_tests::own_artifact;
use e2e_tests::start::StartRetrying;
use std::io::Read;
use std::process::{Command, Stdio};
use std::sync::Mutex;
use std::time::Duration;
use test_support::wait::wait_exit;

/// The broken prefixes one at a time (each starts a wineserver and a server of its own; two
/// cores are shared with everything else).
static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());

const CLSID_KEY: &str = r"HKCR\CLSID\{3277B556-BA68-4BDE-8687-8EE4E4B46336}\LocalServer32";

fn serial() -> std::sync::MutexGuard<'static, ()> {
    ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner())
}

/// `opcdiag doctor --json ARGS` in the test prefix itself, killed after `limit`.
fn doctor_here(args: &[&str], limit: Duration) -> Run {
    let exe = own_artifact("opcdiag.exe");
    let mut child = Command::new(&exe)
        .arg("doctor")
        .arg("--json")
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn_retrying()
        .unwrap_or_else(|e| panic!("start {}: {e}", exe.display()));
    let mut out = child.stdout.take().unwrap();
    let mut err = child.stderr.take().unwrap();
    let reader = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = out.read_to_string(&mut s);
        s
    });
    let err_reader = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = err.read_to_string(&mut s);
        s
    });
    let Some(status) = wait_exit(&mut child, limit).unwrap() else {
        let _ = child.kill();
        panic!("opcdiag doctor did not end within {limit:?}: it must never hang");
    };
    Run {
        code: status.code().unwrap_or(-1),
        stdout: reader.join().unwrap(),
        stderr: err_reader.join().unwrap(),
    }
}

fn assert_failed(run: &Run, check: &str, detail: &str, fix: &str) {
    let c = run.check(check);
    assert_eq!(c.status, "FAIL", "{check}: {run:?}");
    assert!(
        c.detail.contains(detail),
        "{check}: {detail:?} not in {:?}",
        c.detail
    );
    assert!(c.fix.contains(fix), "{check}: {fix:?} not in {:?}", c.fix);
    assert_eq!(run.code, 1, "a FAIL gives exit code 1: {run:?}");
}

#[test]
fn a_working_installation_has_no_failure_and_exit_code_0() {
    // The server of an earlier test (its own configuration) may still be ending: Wine hands
    // an activation to the first server that registered the class, and one that is ending
    // answers E_NOINTERFACE.
    e2e_tests::wait_for_no_other_server();
    let run = doctor_here(&[], Duration::from_secs(60));
    let checks = run.checks();
    assert!(checks.len() >= 15, "{run:?}");
    let failed: Vec<_> = checks.iter().filter(|c| c.status == "FAIL").collect();
    assert!(failed.is_empty(), "{failed:?}\n{run:?}");
    assert_eq!(run.code, 0, "{run:?}");
    for name in [
        "registration (64-bit view)",
        "registration (32-bit view)",
        "server exe",
        "proxy/stub (64-bit view)",
        "proxy/stub (32-bit view)",
        "server browser (64-bit view)",
        "server browser (32-bit view)",
        "NT service",
        "configuration",
        "database [Channel:*]",
        "asix link",
        "connection",
        "read",
        "callback",
    ] {
        assert_eq!(run.check(name).status, "OK", "{name}: {run:?}");
    }
    assert!(run
        .check("proxy/stub (64-bit view)")
        .detail
        .contains("opc_ps.dll"));
    // The AppID's security as /RegServer wrote it: the defaults, nothing weaker.
    for name in [
        "AppID AccessPermission",
        "AppID LaunchPermission",
        "AppID AuthenticationLevel",
        "COM security",
    ] {
        assert_eq!(run.check(name).status, "OK", "{name}: {run:?}");
    }
    assert!(run
        .check("AppID AccessPermission")
        .detail
        .contains("(A;;0x3;;;S-1-5-32-544)"));
    // The test configuration has no [WriteRights]: every client may write, said so.
    let rights = run.check("write rights");
    assert_eq!(rights.status, "WARN", "{rights:?}");
    assert!(rights.detail.contains("every connected client may write"));
    // What Wine cannot tell is a warning, never a failure.
    for c in checks.iter().filter(|c| c.status == "WARN") {
        assert!(!c.fix.is_empty(), "a warning has its fix: {c:?}");
    }
}

#[test]
fn the_text_report_has_one_line_per_check_and_a_summary() {
    let exe = own_artifact("opcdiag.exe");
    let out = Command::new(&exe)
        .args(["doctor", "--timeout", "30"])
        .stdin(Stdio::null())
        .output_retrying()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.lines()
            .any(|l| l.starts_with("OK    registration (64-bit view)")),
        "{text}"
    );
    assert!(
        text.lines().last().unwrap_or("").contains(", 0 FAIL"),
        "{text}"
    );
    assert_eq!(out.status.code(), Some(0), "{text}");
}

#[test]
fn an_unregistered_proxy_stub_is_a_failure_with_regsvr32_as_the_fix() {
    let _one = serial();
    let dll = unix_path(&e2e_tests::artifact("opc_ps.dll"));
    let pfx = BrokenPrefix::new(
        "proxy",
        &format!(
            "/usr/lib/wine/wine64 regsvr32 /u /s {}",
            e2e_tests::doctor::sh_quote(&format!("Z:{}", dll.replace('/', "\\")))
        ),
    );
    let run = pfx.doctor(&["--timeout", "20"], Duration::from_secs(90));
    assert_failed(
        &run,
        "proxy/stub (64-bit view)",
        "no proxy/stub registered for any OPC interface",
        "regsvr32 opc_ps.dll",
    );
    assert_eq!(
        run.check("proxy/stub (32-bit view)").status,
        "OK",
        "{run:?}"
    );
}

#[test]
fn a_moved_exe_is_a_failure_with_regserver_as_the_fix() {
    let _one = serial();
    let moved = r#""C:\moved\ServerCTOPC.exe""#;
    let q = e2e_tests::doctor::sh_quote;
    let pfx = BrokenPrefix::new(
        "exe",
        &format!(
            "$W reg add {k} /ve /d {m} /f /reg:64 && $W reg add {k} /ve /d {m} /f /reg:32",
            k = q(CLSID_KEY),
            m = q(moved)
        ),
    );
    let run = pfx.doctor(&["--timeout", "20"], Duration::from_secs(90));
    assert_failed(
        &run,
        "server exe",
        r"C:\moved\ServerCTOPC.exe (LocalServer32) does not exist",
        "/RegServer",
    );
    assert_eq!(run.check("connection").status, "FAIL", "{run:?}");
}

/// Runs doctor in a copy of the prefix with `ini` as its configuration (`--config`).
fn with_config(case: &str, ini: &str) -> Run {
    let _one = serial();
    let pfx = BrokenPrefix::new(case, "true");
    let path = e2e_tests::doctor::windows_path(&format!("{}/ASIXConnect.ini", pfx.dir));
    std::fs::write(&path, ini).unwrap();
    let config = path.display().to_string();
    pfx.doctor(
        &["--config", &config, "--timeout", "20"],
        Duration::from_secs(90),
    )
}

#[test]
fn an_invalid_configuration_is_a_failure_naming_file_line_and_option() {
    let run = with_config(
        "config",
        "[Server]\nLogLevel = info\nMinUpdateRate = soon\n",
    );
    assert_failed(
        &run,
        "configuration",
        "ASIXConnect.ini:3: option MinUpdateRate",
        "correct the option",
    );
}

#[test]
fn a_missing_database_is_a_failure_of_its_channel() {
    let run = with_config("database", "[Channel:*]\nItemsDatabase = missing.zez\n");
    assert_failed(
        &run,
        "database [Channel:*]",
        "missing.zez",
        "ItemsDatabase of [Channel:*]",
    );
}

#[test]
fn an_unreachable_asix_server_is_a_failure_after_find_server_timeout() {
    let zez = repo_root().join(r"demo\wytwornia_kwasu\wytwornia_kwasu.zez");
    let ini = format!(
        "[Server]\nSimulateCurrentData = nie\nBroadcastAddress = 127.0.0.1\nDiscoveryPort = 48997\n\
         [Channel:*]\nItemsDatabase = {}\nFindServerTimeout = 500\n",
        zez.display()
    );
    let run = with_config("asix", &ini);
    let links: Vec<_> = run
        .checks()
        .into_iter()
        .filter(|c| c.name.starts_with("asix link [Channel:*] "))
        .collect();
    assert!(!links.is_empty(), "{run:?}");
    for c in &links {
        assert_eq!(c.status, "FAIL", "{c:?}");
        assert!(
            c.detail.contains("within FindServerTimeout (500 ms)"),
            "{c:?}"
        );
        assert!(c.fix.contains("DiscoveryPort"), "{c:?}");
    }
    assert_eq!(run.check("database [Channel:*]").status, "OK", "{run:?}");
    assert_eq!(run.code, 1, "{run:?}");
}

#[test]
fn a_users_file_open_to_everyone_is_a_warning_with_the_fix() {
    use ctopc_com::com::secret_file;
    use ctopc_registration::security::{Ace, Sid, EVERYONE};
    let dir = std::env::temp_dir().join(format!("ctopc-doctor-secrets-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    // Made private, then opened to Everyone (read) as a careless copy would leave it.
    let users = dir.join("users.txt");
    secret_file::create(&users).unwrap();
    let mut open = secret_file::descriptor_to_write(false).unwrap();
    open.dacl
        .get_or_insert_with(Vec::new)
        .push(Ace::allow(Sid::parse(EVERYONE).unwrap(), 0x0012_00A9));
    secret_file::set_dacl(&users, &open).unwrap();
    let run = with_config(
        "secrets",
        &format!(
            "[UA]\nEnabled = nie\nUsersFile = {}\nPkiDirectory = {}\n",
            users.display(),
            dir.join("pki").display()
        ),
    );
    let c = run.check("secret: OPC UA users file");
    assert_eq!(c.status, "WARN", "{run:?}");
    assert!(c.detail.contains("Everyone (S-1-1-0) may read it"), "{c:?}");
    assert!(c.fix.contains("icacls"), "{c:?}");
    // The key that is not there yet is no finding.
    let key = run.check("secret: OPC UA private key");
    assert_eq!(key.status, "OK", "{key:?}");
    assert!(key.detail.contains("not there"), "{key:?}");
    // Narrowed again (as ServerCTOPC.exe writes it): private.
    secret_file::narrow(&users, false).unwrap();
    assert_eq!(secret_file::findings(&users, &[]), None);
    std::fs::remove_dir_all(&dir).unwrap();
}
