//! Tidy: the code rules of DEVELOPERS.md that a machine can check.
//! - `unsafe` only in crates/ctopc-com and in the end-to-end tests under tests/ (which
//!   pass deliberately invalid raw pointers to the server, and hold the marshal probe's
//!   COM server in tests/src/probe);
//! - every `unsafe {` block in ctopc-com and in tests/src/probe has a `// SAFETY:` comment
//!   just above it (or on the line);
//! - no `.unwrap()` / `.expect(` in ctopc-com or tests/src/probe outside tests (a panic
//!   would cross COM);
//! - the core crate forbids unsafe code and has no `windows` dependency.

use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .unwrap()
        .to_path_buf()
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for e in entries.flatten() {
        let p = e.path();
        let name = p.file_name().and_then(|n| n.to_str()).unwrap_or("");
        if p.is_dir() {
            if name != "target" && !name.starts_with('.') {
                rust_files(&p, out);
            }
        } else if name.ends_with(".rs") {
            out.push(p);
        }
    }
}

/// Lines of code outside `#[cfg(test)]` modules and with comments and strings blanked,
/// keeping line numbers. (A simple scanner: enough for this codebase's style.)
fn code_lines(text: &str) -> Vec<(usize, String, bool)> {
    let mut out = Vec::new();
    let mut in_test_mod = false;
    let mut depth_at_test: i32 = 0;
    let mut depth: i32 = 0;
    let mut pending_cfg_test = false;
    for (i, line) in text.lines().enumerate() {
        let trimmed = line.trim();
        let code = match trimmed.find("//") {
            Some(pos) => &trimmed[..pos],
            None => trimmed,
        };
        if code.contains("#[cfg(test)]") {
            pending_cfg_test = true;
        } else if pending_cfg_test && code.starts_with("mod ") {
            in_test_mod = true;
            depth_at_test = depth;
            pending_cfg_test = false;
        } else if !code.is_empty() && !code.starts_with("#[") {
            pending_cfg_test = false;
        }
        for c in code.chars() {
            match c {
                '{' => depth += 1,
                '}' => depth -= 1,
                _ => {}
            }
        }
        out.push((i + 1, code.to_string(), in_test_mod));
        if in_test_mod && depth <= depth_at_test && code.contains('}') {
            in_test_mod = false;
        }
    }
    out
}

fn has_unsafe_token(code: &str) -> bool {
    code.split(|c: char| !c.is_alphanumeric() && c != '_')
        .any(|w| w == "unsafe")
        && !code.contains("\"")
}

/// The code of COM objects: the COM crate and the marshal probe of the e2e tests.
const COM_SERVER_CODE: [&str; 2] = ["crates/ctopc-com/src", "tests/src/probe"];

#[test]
fn unsafe_code_lives_only_in_the_com_crate() {
    let root = root();
    let mut files = Vec::new();
    for dir in ["crates", "xtask/src"] {
        rust_files(&root.join(dir), &mut files);
    }
    let mut bad = Vec::new();
    for f in files {
        let rel = f
            .strip_prefix(&root)
            .unwrap()
            .to_string_lossy()
            .replace('\\', "/");
        if rel.starts_with("crates/ctopc-com/") {
            continue;
        }
        let text = std::fs::read_to_string(&f).unwrap();
        for (n, code, _) in code_lines(&text) {
            if has_unsafe_token(&code)
                && !code.contains("forbid(unsafe_code)")
                && !code.contains("deny(unsafe_code)")
            {
                bad.push(format!("{rel}:{n}: {code}"));
            }
        }
    }
    assert!(
        bad.is_empty(),
        "unsafe outside crates/ctopc-com:\n{}",
        bad.join("\n")
    );
}

#[test]
fn every_unsafe_block_in_the_com_crate_has_a_safety_comment() {
    let root = root();
    let mut files = Vec::new();
    for dir in COM_SERVER_CODE {
        rust_files(&root.join(dir), &mut files);
    }
    let mut bad = Vec::new();
    for f in files {
        let rel = f
            .strip_prefix(&root)
            .unwrap()
            .to_string_lossy()
            .into_owned();
        let text = std::fs::read_to_string(&f).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        for (i, line) in lines.iter().enumerate() {
            let code = line.split("//").next().unwrap_or("");
            if !(code.contains("unsafe {") || code.trim_end().ends_with("unsafe")) {
                continue;
            }
            // Look upwards through the statement's preceding lines for a SAFETY comment.
            let from = i.saturating_sub(6);
            let found =
                line.contains("SAFETY") || lines[from..i].iter().any(|l| l.contains("// SAFETY"));
            if !found {
                bad.push(format!("{rel}:{}: {}", i + 1, line.trim()));
            }
        }
    }
    assert!(
        bad.is_empty(),
        "unsafe blocks without a `// SAFETY:` comment:\n{}",
        bad.join("\n")
    );
}

#[test]
fn the_com_crate_does_not_unwrap_outside_tests() {
    let root = root();
    let mut files = Vec::new();
    for dir in COM_SERVER_CODE {
        rust_files(&root.join(dir), &mut files);
    }
    let mut bad = Vec::new();
    for f in files {
        let rel = f
            .strip_prefix(&root)
            .unwrap()
            .to_string_lossy()
            .into_owned();
        let text = std::fs::read_to_string(&f).unwrap();
        for (n, code, in_test) in code_lines(&text) {
            if !in_test && (code.contains(".unwrap()") || code.contains(".expect(")) {
                bad.push(format!("{rel}:{n}: {code}"));
            }
        }
    }
    assert!(
        bad.is_empty(),
        "unwrap/expect in the COM crate (a panic would cross COM):\n{}",
        bad.join("\n")
    );
}

/// `windows::core::Error::new(code, message)` calls RoOriginateErrorW, which Wine 8 only
/// stubs: the process aborts. Errors with a message go through `ctopc_com::error::error`
/// (CreateErrorInfo), and core errors through `ctopc_com::error::to_com`.
#[test]
fn com_errors_with_messages_go_through_error_error() {
    let root = root();
    let mut files = Vec::new();
    for dir in COM_SERVER_CODE {
        rust_files(&root.join(dir), &mut files);
    }
    rust_files(&root.join("crates/server/src"), &mut files);
    let mut bad = Vec::new();
    for f in files {
        let rel = f
            .strip_prefix(&root)
            .unwrap()
            .to_string_lossy()
            .into_owned();
        if rel.ends_with("ctopc-com/src/error.rs") {
            continue;
        }
        let text = std::fs::read_to_string(&f).unwrap();
        for (n, code, in_test) in code_lines(&text) {
            if !in_test && code.contains("Error::new(") {
                bad.push(format!("{rel}:{n}: {code}"));
            }
        }
    }
    assert!(
        bad.is_empty(),
        "use ctopc_com::error::error (Error::new aborts under Wine):\n{}",
        bad.join("\n")
    );
}

#[test]
fn the_core_forbids_unsafe_and_does_not_depend_on_windows() {
    let root = root();
    let lib = std::fs::read_to_string(root.join("crates/ctopc-core/src/lib.rs")).unwrap();
    assert!(lib.contains("#![forbid(unsafe_code)]"));
    let manifest = std::fs::read_to_string(root.join("crates/ctopc-core/Cargo.toml")).unwrap();
    assert!(
        !manifest
            .lines()
            .any(|l| l.trim_start().starts_with("windows")),
        "ctopc-core must not depend on windows crates"
    );
}

#[test]
fn the_scanner_skips_test_modules_and_comments() {
    let src = "fn a() { x.unwrap(); }\n// y.unwrap()\n#[cfg(test)]\nmod tests {\n    fn b() { z.unwrap(); }\n}\nfn c() {}\n";
    let lines = code_lines(src);
    let flagged: Vec<usize> = lines
        .iter()
        .filter(|(_, c, t)| !t && c.contains(".unwrap()"))
        .map(|(n, _, _)| *n)
        .collect();
    assert_eq!(flagged, vec![1]);
    assert!(has_unsafe_token("unsafe { f() }"));
    assert!(!has_unsafe_token("let unsafely = 1;"));
}
