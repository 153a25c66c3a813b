//! opcdiag's OPC UA side as an operator meets it without a server: the client certificate
//! made at first use and kept, a server that is not there (exit 3, no session, at once),
//! and bad options (exit 2). The scenario against a running server is `cargo xtask
//! ua-interop` (xtask/src/ua_client.rs), which runs the binary these tests make cargo build.
#![cfg(not(windows))]
// A test's failure is its panic (the crate denies expect for its library and opcdiag).
#![allow(clippy::expect_used)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

const EXE: &str = env!("CARGO_BIN_EXE_opcdiag");

fn scratch(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join("opcdiag-cli")
        .join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("scratch folder");
    dir
}

fn opcdiag(args: &[&str]) -> Output {
    Command::new(EXE)
        .args(args)
        .stdin(Stdio::null())
        .output()
        .expect("run opcdiag")
}

fn thumbprint(o: &Output) -> String {
    let out = String::from_utf8_lossy(&o.stdout);
    out.lines()
        .find_map(|l| l.strip_prefix("Thumbprint"))
        .map(|rest| rest.split_whitespace().next().unwrap_or("").to_string())
        .unwrap_or_default()
}

#[test]
fn the_client_certificate_is_made_at_first_use_and_kept() {
    let pki = scratch("cert");
    let pki_arg = pki.to_str().expect("utf-8");
    let first = opcdiag(&["cert", "--pki", pki_arg]);
    assert_eq!(first.status.code(), Some(0), "{first:?}");
    let t1 = thumbprint(&first);
    assert_eq!(t1.len(), 40, "a SHA-1 thumbprint in hex: {first:?}");
    assert!(pki.join("own").join("cert.der").is_file());
    let out = String::from_utf8_lossy(&first.stdout);
    assert!(out.contains("ServerCTOPC pki trust"), "{out}");

    let second = opcdiag(&["cert", "--pki", pki_arg]);
    assert_eq!(second.status.code(), Some(0), "{second:?}");
    assert_eq!(thumbprint(&second), t1, "the certificate was made again");
}

#[test]
fn no_server_at_the_url_is_exit_3_at_once() {
    let pki = scratch("no-server");
    // A port that was free a moment ago: nothing listens there.
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("a free port")
        .port();
    let url = format!("opc.tcp://127.0.0.1:{port}");
    let started = Instant::now();
    let o = opcdiag(&[
        "--url",
        &url,
        "--pki",
        pki.to_str().expect("utf-8"),
        "read",
        "A000",
    ]);
    assert_eq!(o.status.code(), Some(3), "{o:?}");
    assert!(
        started.elapsed() < Duration::from_secs(30),
        "a refused connection took {:?}",
        started.elapsed()
    );
    assert!(!String::from_utf8_lossy(&o.stderr).is_empty(), "no message");
}

#[test]
fn bad_options_are_exit_2() {
    for args in [
        &[
            "--url",
            "opc.tcp://127.0.0.1:4840",
            "--security",
            "bogus",
            "read",
            "A000",
        ][..],
        &["--url", "opc.tcp://127.0.0.1:4840", "frobnicate"],
    ] {
        let o = opcdiag(args);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {o:?}");
    }
}

#[test]
fn a_user_without_a_terminal_is_told_to_use_password_stdin() {
    let pki = scratch("no-terminal");
    // Standard input is not a terminal: no prompt, no connection, exit 2 at once.
    let o = opcdiag(&[
        "--url",
        "opc.tcp://127.0.0.1:9",
        "--pki",
        pki.to_str().expect("utf-8"),
        "--user",
        "jan",
        "read",
        "A000",
    ]);
    assert_eq!(o.status.code(), Some(2), "{o:?}");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains(
            "standard input is not a terminal: cannot ask for the password of jan; pipe it with --password-stdin"
        ),
        "{err}"
    );
}
