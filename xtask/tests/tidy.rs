//! Tidy: the code rules of ARCHITECTURE.md that no compiler lint can say.
//!
//! Most rules are lints, checked by `cargo clippy -- -D warnings` in `cargo xtask test`,
//! with their levels in the `[lints]` tables of the manifests and their settings in
//! `clippy.toml`:
//! - `unsafe` only in crates/ctopc-com, the client library (crates/opc-client), the server
//!   browser (crates/serverlist) and the end-to-end tests (tests/, which pass deliberately
//!   invalid raw pointers and hold the marshal probe in tests/src/probe) and the COM test
//!   double tests/xconnect-double: rustc's `unsafe_code = "forbid"`
//!   (`[workspace.lints.rust]`), relaxed only in the `[lints]` tables of those crates;
//! - a `// SAFETY:` comment at every unsafe block: clippy's `undocumented_unsafe_blocks`;
//! - no `.unwrap()` / `.expect(` in ctopc-com, opc-client, serverlist, tests/src/probe and
//!   tests/xconnect-double outside tests (a panic would cross COM): clippy's `unwrap_used` and `expect_used`
//!   (those crates' `[lints]`, the probe's `#![deny]`; `allow-unwrap-in-tests` in
//!   clippy.toml);
//! - no `windows::core::Error::new` outside `ctopc_com::error` (it aborts under Wine):
//!   clippy's `disallowed_methods` (clippy.toml).
//!
//! What is left: the core and the registration data have no `windows` dependency (a
//! manifest, not code), and the lint configuration itself is in place (a member that set `[lints]` of its own, or dropped
//! it, would silently escape every rule above).

use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .unwrap()
        .to_path_buf()
}

fn read(rel: &str) -> String {
    std::fs::read_to_string(root().join(rel)).unwrap_or_else(|e| panic!("{rel}: {e}"))
}

/// The lines of the manifest's `[name]` table, trimmed, without comments and blank lines.
fn table(manifest: &str, name: &str) -> Vec<String> {
    let header = format!("[{name}]");
    let mut out = Vec::new();
    let mut inside = false;
    for line in manifest.lines().map(str::trim) {
        if line.starts_with('[') {
            inside = line == header;
        } else if inside && !line.is_empty() && !line.starts_with('#') {
            out.push(line.to_string());
        }
    }
    out
}

/// The `members = [...]` of the root manifest.
fn workspace_members(manifest: &str) -> Vec<String> {
    let start = manifest.find("members = [").expect("members") + "members = [".len();
    let end = start + manifest[start..].find(']').expect("members' ]");
    manifest[start..end]
        .split(',')
        .map(|m| m.trim().trim_matches('"').to_string())
        .filter(|m| !m.is_empty())
        .collect()
}

#[test]
fn the_core_forbids_unsafe_and_does_not_depend_on_windows() {
    let lib = read("crates/ctopc-core/src/lib.rs");
    assert!(lib.contains("#![forbid(unsafe_code)]"));
    let manifest = read("crates/ctopc-core/Cargo.toml");
    assert!(
        !manifest
            .lines()
            .any(|l| l.trim_start().starts_with("windows")),
        "ctopc-core must not depend on windows crates"
    );
}

#[test]
fn the_registration_data_does_not_depend_on_windows() {
    let manifest = read("crates/registration/Cargo.toml");
    assert!(
        !manifest
            .lines()
            .any(|l| l.trim_start().starts_with("windows")),
        "ctopc-registration must not depend on windows crates"
    );
    assert_eq!(table(&manifest, "lints"), ["workspace = true"]);
}

#[test]
fn the_workspace_lints_forbid_unsafe_and_deny_the_com_rules() {
    let manifest = read("Cargo.toml");
    assert!(table(&manifest, "workspace.lints.rust").contains(&r#"unsafe_code = "forbid""#.into()));
    let clippy = table(&manifest, "workspace.lints.clippy");
    for lint in ["undocumented_unsafe_blocks", "disallowed_methods"] {
        assert!(
            clippy.contains(&format!(r#"{lint} = "deny""#)),
            "[workspace.lints.clippy] must deny {lint}"
        );
    }
    let config = read("clippy.toml");
    assert!(
        config.contains(r#"path = "windows_core::Error::new""#),
        "clippy.toml must disallow windows_core::Error::new"
    );
}

#[test]
fn every_member_inherits_the_workspace_lints_or_relaxes_only_unsafe_code() {
    let inheriting = [
        "crates/ctopc-core",
        "crates/asix-model",
        "crates/registration",
        "crates/runtime",
        "crates/asix-net",
        "crates/asix-gate",
        "crates/server",
        "crates/test-support",
        "crates/ua",
        "xtask",
    ];
    let own = [
        "crates/ctopc-com",
        "crates/opc-client",
        "crates/serverlist",
        "tests",
        "tests/xconnect-double",
        "fuzz",
    ];
    let mut all: Vec<&str> = inheriting.iter().chain(&own).copied().collect();
    all.sort_unstable();
    let mut members = workspace_members(&read("Cargo.toml"));
    members.sort_unstable();
    assert_eq!(
        members, all,
        "a new member needs its [lints] (and a line here)"
    );
    for m in inheriting {
        let manifest = read(&format!("{m}/Cargo.toml"));
        assert_eq!(
            table(&manifest, "lints"),
            ["workspace = true"],
            "{m}/Cargo.toml: [lints] workspace = true"
        );
    }
    // Their own tables (forbid cannot be relaxed inside a crate): unsafe code allowed, the
    // workspace's clippy lints kept; the COM crate, the client library, the server
    // browser and the COM test double also deny unwrap/expect.
    for (m, extra) in [
        ("crates/ctopc-com", &["unwrap_used", "expect_used"][..]),
        ("crates/opc-client", &["unwrap_used", "expect_used"][..]),
        ("crates/serverlist", &["unwrap_used", "expect_used"][..]),
        ("tests", &[][..]),
        ("tests/xconnect-double", &["unwrap_used", "expect_used"][..]),
        ("fuzz", &[][..]),
    ] {
        let manifest = read(&format!("{m}/Cargo.toml"));
        assert_eq!(
            table(&manifest, "lints.rust"),
            [r#"unsafe_code = "allow""#],
            "{m}/Cargo.toml [lints.rust]"
        );
        let clippy = table(&manifest, "lints.clippy");
        for lint in ["undocumented_unsafe_blocks", "disallowed_methods"]
            .iter()
            .chain(extra)
        {
            assert!(
                clippy.contains(&format!(r#"{lint} = "deny""#)),
                "{m}/Cargo.toml [lints.clippy] must deny {lint}"
            );
        }
    }
    // The marshal probe is a COM server: the COM crate's unwrap rule, as an attribute.
    assert!(read("tests/src/probe/mod.rs")
        .contains("#![deny(clippy::unwrap_used, clippy::expect_used)]"));
}

#[test]
fn the_table_reader_takes_one_table() {
    let m = "[a]\nx = 1 # c\n\n# note\n[a.b]\ny = 2\n[a]\nz = 3\n";
    assert_eq!(table(m, "a"), ["x = 1 # c", "z = 3"]);
    assert_eq!(table(m, "a.b"), ["y = 2"]);
    assert!(table(m, "b").is_empty());
    let ws = "[workspace]\nmembers = [\n    \"a\",\n    \"b/c\",\n]\n";
    assert_eq!(workspace_members(ws), ["a", "b/c"]);
}
