//! opcdiag.exe (the diagnostic client we ship) against the test server: the embedded demo
//! plant, simulated (state TEST). Each case runs the real executable, as a person would,
//! and checks what it prints and its exit code.
//!
//! Spec: The client side of OPC Common 1.10 IOPCServerList and IOPCServerList2 (servers),
//! OPC DA 2.05a §4.4.4 IOPCServer::GetStatus (status), OPC DA 3.0 IOPCBrowse::Browse and
//! OPC DA 2.05a §4.4.8 IOPCBrowseServerAddressSpace (browse, the latter with
//! OPCDIAG_BROWSE_DA2), §4.4.6 IOPCItemProperties (props), §4.5.5 IOPCSyncIO (read, write),
//! §4.3.3 Subscription via IOPCDataCallback (subscribe).
#![cfg(windows)]

use e2e_tests::own_artifact;
use e2e_tests::start::StartRetrying;
use std::io::Read;
use std::process::{Command, Stdio};
use std::time::Duration;
use test_support::wait::wait_exit;

/// What one opcdiag run printed.
struct Run {
    code: i32,
    stdout: String,
    stderr: String,
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

/// Runs opcdiag.exe with `args` (English texts unless `args` says otherwise), killed after
/// `limit`.
fn opcdiag_for(args: &[&str], limit: Duration) -> Run {
    opcdiag_with(args, &[], limit)
}

/// [`opcdiag_for`] with extra environment variables.
fn opcdiag_with(args: &[&str], env: &[(&str, &str)], limit: Duration) -> Run {
    let exe = own_artifact("opcdiag.exe");
    let mut child = Command::new(&exe)
        .args(args)
        .envs(env.iter().copied())
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn_retrying()
        .unwrap_or_else(|e| {
            panic!(
                "start {}: {e} (built by `cargo xtask build`)",
                exe.display()
            )
        });
    let mut out = child.stdout.take().expect("stdout");
    let mut err = child.stderr.take().expect("stderr");
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
    let Some(status) = wait_exit(&mut child, limit).expect("wait for opcdiag") else {
        let _ = child.kill();
        let _ = child.wait();
        panic!("opcdiag {args:?} did not finish within {limit:?}");
    };
    Run {
        code: status.code().unwrap_or(-1),
        stdout: reader.join().expect("stdout reader"),
        stderr: err_reader.join().expect("stderr reader"),
    }
}

fn opcdiag(args: &[&str]) -> Run {
    opcdiag_for(args, Duration::from_secs(60))
}

#[test]
fn status_shows_the_vendor_and_the_test_state() {
    let r = opcdiag(&["status"]);
    assert_eq!(r.code, 0, "{r:?}");
    let state = r
        .stdout
        .lines()
        .find(|l| l.starts_with("State"))
        .unwrap_or_else(|| panic!("no State line: {r:?}"));
    assert!(state.contains("TEST"), "{r:?}");
    let vendor = r
        .stdout
        .lines()
        .find(|l| l.starts_with("Vendor"))
        .unwrap_or_else(|| panic!("no Vendor line: {r:?}"));
    assert!(vendor.contains("ServerCTOPC"), "{r:?}");
    assert!(r.stdout.contains("Server        ServerCTOPC.App"), "{r:?}");
}

#[test]
fn browse_shows_the_plant_tree_indented() {
    let r = opcdiag(&["browse"]);
    assert_eq!(r.code, 0, "{r:?}");
    let lines: Vec<&str> = r.stdout.lines().collect();
    let top = lines
        .iter()
        .position(|l| *l == "Magazyn siarki/")
        .unwrap_or_else(|| panic!("no top branch Magazyn siarki: {r:?}"));
    assert!(
        lines[top + 1].starts_with("  ") && lines[top + 1].ends_with('/'),
        "a second-level branch follows: {r:?}"
    );
    assert!(
        lines
            .iter()
            .any(|l| l.trim() == "KW_A000" && l.starts_with("    ")),
        "KW_A000 as a third-level leaf: {r:?}"
    );

    let flat = opcdiag(&["browse", "--flat"]);
    assert_eq!(flat.code, 0, "{flat:?}");
    assert!(flat.stdout.lines().any(|l| l == "KW_A000"), "{flat:?}");
    assert!(
        flat.stdout.lines().count() > 100,
        "every variable: {flat:?}"
    );

    let branch = opcdiag(&[
        "browse",
        "--branch",
        "Magazyn siarki/Zbiornik siarki ciekłej Z101",
    ]);
    assert_eq!(branch.code, 0, "{branch:?}");
    assert_eq!(
        branch.stdout.lines().collect::<Vec<_>>(),
        ["KW_A000", "KW_A001", "KW_A002"],
        "{branch:?}"
    );
}

/// A browse listing without the `_Diagnostics` branch (its client branches are each
/// opcdiag run's own session: `Client<N>`, different in every run): its line and the
/// indented lines below it, or its item IDs in a flat listing.
fn without_diagnostics(listing: &str) -> String {
    let mut out = String::new();
    let mut inside = false;
    for line in listing.lines() {
        if line == "_Diagnostics/" {
            inside = true;
            continue;
        }
        if inside && line.starts_with(' ') {
            continue;
        }
        inside = false;
        if !line.starts_with("_Diagnostics.") {
            out.push_str(line);
            out.push('\n');
        }
    }
    out
}

/// The tree through IOPCBrowse::Browse (one call per branch, the item IDs in the reply)
/// is the listing the DA 2.05a path gives (ChangeBrowsePosition, BrowseOPCItemIDs and
/// GetItemID per leaf; `OPCDIAG_BROWSE_DA2=1` forces it), whole, from a branch and to a
/// depth; and the demo is too short for progress lines on stderr.
#[test]
fn browse_through_iopcbrowse_lists_what_da2_lists() {
    let da2 = [("OPCDIAG_BROWSE_DA2", "1")];
    for args in [
        &["browse"][..],
        &["browse", "--depth", "2"],
        &["browse", "--branch", "Magazyn siarki"],
        &["browse", "--flat"],
    ] {
        let new = opcdiag(args);
        assert_eq!(new.code, 0, "{args:?}: {new:?}");
        assert_eq!(
            new.stderr, "",
            "{args:?}: no progress for the demo: {new:?}"
        );
        let old = opcdiag_with(args, &da2, Duration::from_secs(60));
        assert_eq!(old.code, 0, "{args:?}: {old:?}");
        assert_eq!(
            without_diagnostics(&new.stdout),
            without_diagnostics(&old.stdout),
            "{args:?}"
        );
        assert!(new.stdout.lines().count() > 3, "{args:?}: {new:?}");
    }
    // Leaves whose item ID is not their name show it.
    let r = opcdiag(&["browse"]);
    assert!(r.stdout.contains("KW_A000"), "{r:?}");
}

#[test]
fn props_lists_id_description_and_value() {
    let r = opcdiag(&["--lang", "en", "props", "KW_A000"]);
    assert_eq!(r.code, 0, "{r:?}");
    let line = |id: &str| {
        r.stdout
            .lines()
            .find(|l| l.split_whitespace().next() == Some(id))
            .unwrap_or_else(|| panic!("no property {id}: {r:?}"))
            .to_string()
    };
    assert!(
        line("1").contains("Item Canonical Data Type") && line("1").contains("R4 (4)"),
        "{r:?}"
    );
    assert!(line("3").contains("GOOD"), "{r:?}");
    assert!(line("100").contains("\"m\""), "{r:?}");
    assert!(
        line("101").contains("Liquid sulphur level in tank Z101"),
        "{r:?}"
    );
}

#[test]
fn read_prints_value_type_quality_and_local_time() {
    let r = opcdiag(&["read", "KW_A000"]);
    assert_eq!(r.code, 0, "{r:?}");
    let line = r
        .stdout
        .lines()
        .find(|l| l.starts_with("KW_A000"))
        .unwrap_or_else(|| panic!("{r:?}"));
    let f: Vec<&str> = line.split_whitespace().collect();
    assert!(f[1].parse::<f32>().is_ok(), "a number: {r:?}");
    assert_eq!(f[2], "R4", "{r:?}");
    // Quality is GOOD, possibly with limit bits ("GOOD [Low limit]": the simulated level
    // crosses its warning limits); the local time is the last field.
    assert_eq!(f[3], "GOOD", "{r:?}");
    let time = f[f.len() - 1];
    assert!(
        time.len() == "2026-01-05T13:04:05.120+01:00".len() && time.contains('T'),
        "ISO local time: {r:?}"
    );

    let d = opcdiag(&["read", "KW_A000", "KW_A001", "--device"]);
    assert_eq!(d.code, 0, "{d:?}");
    assert_eq!(
        d.stdout.lines().filter(|l| l.contains(" GOOD ")).count(),
        2,
        "{d:?}"
    );
}

#[test]
fn read_of_an_unknown_item_fails_with_the_servers_text() {
    let r = opcdiag(&["--lang", "en", "read", "KW_A000", "KW_NO_SUCH"]);
    assert_eq!(r.code, 1, "{r:?}");
    assert!(
        r.stdout
            .lines()
            .any(|l| l.starts_with("KW_A000") && l.contains("GOOD")),
        "the good item is still read: {r:?}"
    );
    let bad = r
        .stdout
        .lines()
        .find(|l| l.starts_with("KW_NO_SUCH"))
        .unwrap_or_else(|| panic!("{r:?}"));
    assert!(
        bad.contains("0xC0040007 OPC_E_UNKNOWNITEMID: The item ID is not defined"),
        "{r:?}"
    );
}

#[test]
fn write_then_read_back() {
    // Keeps the server process up between the runs, so that it keeps the written value.
    let (_com, _server) = e2e_tests::connect();
    let before = opcdiag(&["read", "KW_A110"]);
    let original = before
        .stdout
        .split_whitespace()
        .nth(1)
        .unwrap_or_else(|| panic!("{before:?}"))
        .to_string();
    let w = opcdiag(&["write", "KW_A110", "12.5"]);
    assert_eq!(w.code, 0, "{w:?}");
    assert!(w.stdout.contains("KW_A110: written 12.5 (R4): OK"), "{w:?}");
    let r = opcdiag(&["read", "KW_A110"]);
    assert_eq!(r.code, 0, "{r:?}");
    let f: Vec<&str> = r
        .stdout
        .lines()
        .find(|l| l.starts_with("KW_A110"))
        .unwrap_or_else(|| panic!("{r:?}"))
        .split_whitespace()
        .collect();
    assert_eq!((f[1], f[3]), ("12.5", "GOOD"), "{r:?}");

    // --type: the value goes as I4 and the server converts it.
    let w = opcdiag(&["write", "KW_A110", "7", "--type", "I4"]);
    assert_eq!(w.code, 0, "{w:?}");
    assert!(w.stdout.contains("written 7 (I4): OK"), "{w:?}");

    // The setpoint back as it was, for the tests that run after this one.
    let w = opcdiag(&["write", "KW_A110", &original]);
    assert_eq!(w.code, 0, "{w:?}");
}

#[test]
fn write_to_a_read_only_item_fails_readably() {
    let r = opcdiag(&["--lang", "en", "write", "KW_A000", "1"]);
    assert_eq!(r.code, 1, "{r:?}");
    assert!(
        r.stdout.contains("KW_A000: write 1 (R4) failed: 0xC0040006 OPC_E_BADRIGHTS: The item's access rights do not allow the operation."),
        "{r:?}"
    );
    // In Polish, from the server's GetErrorString.
    let pl = opcdiag(&["--lang", "pl", "write", "KW_A000", "1"]);
    assert_eq!(pl.code, 1, "{pl:?}");
    assert!(
        pl.stdout.contains(
            "0xC0040006 OPC_E_BADRIGHTS: Prawa dostępu do elementu nie pozwalają na tę operację."
        ),
        "{pl:?}"
    );
    // A value that does not fit the type is a usage error, found before writing.
    let bad = opcdiag(&["write", "KW_A110", "abc"]);
    assert_eq!(bad.code, 2, "{bad:?}");
    assert!(
        bad.stderr.contains("\"abc\" is not a valid value for R4"),
        "{bad:?}"
    );
}

#[test]
fn subscribe_prints_changes_as_they_arrive() {
    let r = opcdiag_for(
        &["subscribe", "KW_A000", "--for", "5"],
        Duration::from_secs(90),
    );
    assert_eq!(r.code, 0, "{r:?}");
    // GOOD, possibly with limit bits while the simulated level is past a warning limit.
    let changes: Vec<&str> = r
        .stdout
        .lines()
        .filter(|l| l.contains("KW_A000") && (l.ends_with("GOOD") || l.contains(" GOOD [")))
        .collect();
    assert!(changes.len() >= 2, "at least two changes in 5 s: {r:?}");
    // hh:mm:ss.mmm  KW_A000  value  GOOD [limit]
    let f: Vec<&str> = changes[1].split_whitespace().collect();
    assert_eq!(f[0].len(), "13:04:05.120".len(), "{r:?}");
    assert!(f[2].parse::<f32>().is_ok(), "{r:?}");
    assert!(
        r.stdout
            .lines()
            .last()
            .is_some_and(|l| l.contains("change(s) in")),
        "{r:?}"
    );
}

#[test]
fn help_usage_errors_and_a_missing_server() {
    let h = opcdiag(&["--help"]);
    assert_eq!(h.code, 0, "{h:?}");
    for c in [
        "status",
        "browse",
        "props",
        "read",
        "write",
        "subscribe",
        "demo",
    ] {
        assert!(h.stdout.contains(c), "{c}: {h:?}");
        let ch = opcdiag(&[c, "--help"]);
        assert_eq!(ch.code, 0, "{ch:?}");
        assert!(
            ch.stdout.contains(&format!("Usage: opcdiag {c} [OPTIONS]"))
                && ch.stdout.contains("--server <PROGID>"),
            "{ch:?}"
        );
    }
    let u = opcdiag(&["read"]);
    assert_eq!(u.code, 2, "{u:?}");
    assert!(u.stderr.contains("read needs at least one ITEMID"), "{u:?}");

    let m = opcdiag(&["--server", "No.Such.Server", "status"]);
    assert_eq!(m.code, 1, "{m:?}");
    assert!(
        m.stderr
            .contains("cannot connect to No.Such.Server: 0x800401F3 CO_E_CLASSSTRING"),
        "{m:?}"
    );
}

#[test]
fn demo_shows_status_tree_and_live_values() {
    let r = opcdiag_for(
        &["--lang", "en", "demo", "--for", "3"],
        Duration::from_secs(90),
    );
    assert_eq!(r.code, 0, "{r:?}");
    assert!(r.stdout.contains("State         TEST"), "{r:?}");
    assert!(
        r.stdout.lines().any(|l| l == "  Magazyn siarki/"),
        "the plant tree: {r:?}"
    );
    assert!(
        r.stdout
            .contains("KW_A000  Liquid sulphur level in tank Z101 [m]"),
        "the legend: {r:?}"
    );
    let live = r
        .stdout
        .lines()
        .filter(|l| l.contains(" KW_A") && (l.ends_with("GOOD") || l.contains("GOOD [")))
        .count();
    assert!(live >= 8, "a value of every variable at least: {r:?}");
}

#[test]
fn servers_lists_serverctopc_through_the_server_browser() {
    let r = opcdiag(&["servers"]);
    assert_eq!(r.code, 0, "{r:?}");
    assert!(
        r.stdout.contains("through OPC.ServerList.1"),
        "the browser was used: {r:?}"
    );
    let line = r
        .stdout
        .lines()
        .find(|l| l.split_whitespace().next() == Some("ServerCTOPC.App"))
        .unwrap_or_else(|| panic!("ServerCTOPC listed: {r:?}"));
    assert!(line.contains("2.0, 3.0"), "{line}");
    assert!(
        line.contains("ServerCTOPC OPC DA Server for asix"),
        "{line}"
    );
    assert!(
        line.ends_with("{3277B556-BA68-4BDE-8687-8EE4E4B46336}"),
        "{line}"
    );
}
