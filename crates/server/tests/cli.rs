//! The native command line of `ServerCTOPC` as an operator meets it: `user add`, `pki
//! trust` and `/ProtectSecrets` against a configuration in a scratch folder, and the
//! refusals of bad input (exit code and message). Linux only: on Windows those commands belong to the COM build.
#![cfg(not(windows))]

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

const EXE: &str = env!("CARGO_BIN_EXE_ServerCTOPC");

/// A fresh folder with an `ASIXConnect.ini` serving the demo plant from the simulation.
fn scratch(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join("server-cli")
        .join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("scratch folder");
    let db = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../demo/wytwornia_kwasu/wytwornia_kwasu.zez")
        .canonicalize()
        .expect("the demo plant's database");
    std::fs::write(
        dir.join("ASIXConnect.ini"),
        format!(
            "[Server]\nSimulateCurrentData = tak\n[Channel:*]\nItemsDatabase = {}\n",
            db.display()
        ),
    )
    .expect("ini");
    dir
}

/// Runs the server with `args`, the configuration in `dir`, and `stdin` as its input.
fn run(dir: &Path, args: &[&str], stdin: &str) -> Output {
    let mut child = Command::new(EXE)
        .args(args)
        .env("SERVERCTOPC_INI", dir.join("ASIXConnect.ini"))
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start ServerCTOPC");
    // A refusal may end the server before it reads its input: a closed pipe is no error.
    match child
        .stdin
        .take()
        .expect("stdin")
        .write_all(stdin.as_bytes())
    {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => panic!("write stdin: {e}"),
        _ => {}
    }
    child.wait_with_output().expect("ServerCTOPC ends")
}

/// `user add NAME --role ROLE --password-stdin` with `password` piped in.
fn user_add(dir: &Path, name: &str, role: &str, password: &str) -> Output {
    run(
        dir,
        &["user", "add", name, "--role", role, "--password-stdin"],
        &format!("{password}\n"),
    )
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn user_add_keeps_a_salted_hash_and_never_the_password() {
    let dir = scratch("user-add");
    let password = "Kwas-siarkowy-98%";
    let o = user_add(&dir, "operator1", "writer", password);
    assert!(o.status.success(), "user add failed: {}", stderr(&o));
    let users = std::fs::read_to_string(dir.join("ua-users.txt")).expect("the users file");
    let line = users
        .lines()
        .find(|l| l.starts_with("operator1:"))
        .expect("a line for operator1");
    let fields: Vec<&str> = line.split(':').collect();
    assert_eq!(fields[..3], ["operator1", "writer", "pbkdf2-sha256"]);
    assert_eq!(fields.len(), 6, "{line}");
    assert!(!users.contains(password), "the password is stored in clear");
    assert!(!String::from_utf8_lossy(&o.stdout).contains(password));

    // The same name again replaces the user (a new salt), it does not add a second line.
    let o = user_add(&dir, "operator1", "reader", "another one");
    assert!(o.status.success(), "{}", stderr(&o));
    let users = std::fs::read_to_string(dir.join("ua-users.txt")).expect("the users file");
    let lines: Vec<&str> = users
        .lines()
        .filter(|l| l.starts_with("operator1:"))
        .collect();
    assert_eq!(lines.len(), 1, "{users}");
    assert!(lines[0].starts_with("operator1:reader:"), "{users}");
    assert_ne!(lines[0], line, "the hash did not change");
}

#[test]
fn user_add_refuses_bad_input_and_writes_nothing() {
    let dir = scratch("user-add-bad");
    let cases: [(&[&str], &str, &str); 4] = [
        (
            // Without --password-stdin it asks on the terminal; piped, it cannot.
            &["user", "add", "x", "--role", "reader"],
            "pw\n",
            "standard input is not a terminal: cannot ask for the password; pipe it with --password-stdin",
        ),
        (
            &["user", "add", "x", "--role", "admin", "--password-stdin"],
            "pw\n",
            "--role takes reader or writer",
        ),
        (
            &["user", "add", "a:b", "--role", "reader", "--password-stdin"],
            "pw\n",
            "a user name is",
        ),
        (
            &["user", "add", "x", "--role", "reader", "--password-stdin"],
            "\n",
            "the password is empty",
        ),
    ];
    for (args, input, message) in cases {
        let o = run(&dir, args, input);
        assert!(!o.status.success(), "{args:?} succeeded");
        assert!(stderr(&o).contains(message), "{args:?}: {}", stderr(&o));
    }
    assert!(
        !dir.join("ua-users.txt").exists(),
        "a refused user was saved"
    );
}

#[test]
fn bad_switches_exit_2_with_the_usage() {
    let dir = scratch("switches");
    for args in [
        &["/Frobnicate"][..],
        &["serve", "now"],
        &["pki", "trust"],
        &[],
    ] {
        let o = run(&dir, args, "");
        assert_eq!(o.status.code(), Some(2), "{args:?}: {}", stderr(&o));
        assert!(stderr(&o).contains("usage: ServerCTOPC.exe"), "{args:?}");
    }
}

#[test]
fn pki_trust_refuses_what_is_not_a_certificate_and_trusts_nothing() {
    let dir = scratch("pki-trust");
    std::fs::write(dir.join("notes.der"), b"not a certificate").expect("write");
    // (the file given to `pki trust`, what the refusal must say)
    let cases = [
        ("no-such-client.der", "no-such-client.der"),
        ("notes.der", "is not an X.509 certificate"),
    ];
    for (file, message) in cases {
        let path = dir.join(file);
        let o = run(&dir, &["pki", "trust", path.to_str().expect("utf-8")], "");
        assert!(!o.status.success(), "{file}: trusted");
        assert!(stderr(&o).contains(message), "{file}: {}", stderr(&o));
    }
    assert!(
        !dir.join("pki").join("trusted").exists(),
        "something was trusted"
    );
}

/// `-ProtectSecrets --config FILE` (the configuration named, not `SERVERCTOPC_INI`'s): the
/// users file someone opened narrowed to 0600, the certificate store made 0700, a line per
/// path and the summary; a configuration that cannot be read is exit 1 naming it.
#[test]
fn protect_secrets_narrows_the_named_configurations_secrets() {
    use std::os::unix::fs::PermissionsExt as _;
    let mode = |p: &Path| std::fs::metadata(p).expect("metadata").permissions().mode() & 0o777;
    let elsewhere = scratch("protect-env");
    let dir = scratch("protect");
    let o = user_add(&dir, "operator1", "writer", "Kwas-siarkowy-98%");
    assert!(o.status.success(), "user add failed: {}", stderr(&o));
    let users = dir.join("ua-users.txt");
    std::fs::set_permissions(&users, std::fs::Permissions::from_mode(0o644)).expect("chmod");
    let ini = dir.join("ASIXConnect.ini");
    let o = run(
        &elsewhere,
        &["-ProtectSecrets", "--config", ini.to_str().expect("utf-8")],
        "",
    );
    let out = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(o.status.success(), "{out}{}", stderr(&o));
    assert_eq!(mode(&users), 0o600);
    assert_eq!(mode(&dir.join("pki")), 0o700);
    assert_eq!(mode(&dir.join("pki/private")), 0o700);
    assert!(
        !elsewhere.join("pki").exists(),
        "SERVERCTOPC_INI's folder was used"
    );
    assert!(
        out.contains(&format!(
            "ProtectSecrets: OPC UA users file {}: private",
            users.display()
        )),
        "{out}"
    );
    assert!(
        out.lines().last().is_some_and(|l| l.starts_with(
            "ProtectSecrets: 3 paths private, 1 not there yet, 0 failed (configuration: "
        )),
        "{out}"
    );
    let missing = dir.join("missing.ini");
    let o = run(
        &dir,
        &[
            "/ProtectSecrets",
            "/config",
            missing.to_str().expect("utf-8"),
        ],
        "",
    );
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains("ProtectSecrets: the configuration cannot be read: ")
            && stderr(&o).contains("missing.ini"),
        "{}",
        stderr(&o)
    );
}
