//! The COM crate's floors (`crates/ctopc-com/src/lib.rs`): the plumbing (`com/`) never
//! imports from the DA floor (`da/`), the crate's own modules name each other by their
//! floor paths (`crate::com::abi`, not the re-exported `crate::abi`), and the graph of its
//! modules (a module being a file or folder directly under a floor) has no cycle. A file's
//! unit tests (`#[cfg(test)] mod tests`) are left out of the graph.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

fn src() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../crates/ctopc-com/src")
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// `com::abi` for `com/abi.rs`, `da::group` for `da/group/io.rs`; None for the floors'
/// own `mod.rs` and `lib.rs`.
fn module_of(rel: &Path) -> Option<String> {
    let parts: Vec<String> = rel
        .iter()
        .map(|p| p.to_string_lossy().trim_end_matches(".rs").to_string())
        .collect();
    match parts.as_slice() {
        [floor, m, ..] if m != "mod" => Some(format!("{floor}::{m}")),
        _ => None,
    }
}

/// Every `crate::<floor>::<module>` a text names, and every `crate::<name>` that is not a
/// floor.
fn references(text: &str) -> (BTreeSet<String>, BTreeSet<String>) {
    let mut floors = BTreeSet::new();
    let mut bare = BTreeSet::new();
    let ident = |s: &str| -> String {
        s.chars()
            .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
            .collect()
    };
    for (i, _) in text.match_indices("crate::") {
        let rest = &text[i + "crate::".len()..];
        let first = ident(rest);
        if first == "com" || first == "da" {
            let after = &rest[first.len()..];
            if let Some(after) = after.strip_prefix("::") {
                let m = ident(after);
                if !m.is_empty() {
                    floors.insert(format!("{first}::{m}"));
                } else if let Some(group) = after.strip_prefix('{') {
                    for m in group.split('}').next().unwrap_or("").split(',') {
                        let m = ident(m.trim());
                        if !m.is_empty() {
                            floors.insert(format!("{first}::{m}"));
                        }
                    }
                }
            }
        } else if !first.is_empty() {
            bare.insert(first);
        }
    }
    (floors, bare)
}

fn graph() -> BTreeMap<String, BTreeSet<String>> {
    let root = src();
    let mut files = Vec::new();
    rust_files(&root, &mut files);
    let mut g: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for f in files {
        let rel = f.strip_prefix(&root).unwrap().to_path_buf();
        let Some(m) = module_of(&rel) else { continue };
        let text = std::fs::read_to_string(&f).unwrap();
        // A file's unit tests are not part of the product's graph.
        let product = text.split("#[cfg(test)]\nmod tests").next().unwrap_or("");
        // Comments may name any module; only code makes an edge.
        let code: String = product
            .lines()
            .filter(|l| !l.trim_start().starts_with("//"))
            .collect::<Vec<_>>()
            .join("\n");
        let (refs, bare) = references(&code);
        assert!(
            bare.is_empty(),
            "{}: names {bare:?} by the crate root; use the floor path (crate::com::.. or crate::da::..)",
            rel.display()
        );
        let deps = g.entry(m.clone()).or_default();
        deps.extend(refs.into_iter().filter(|r| *r != m));
    }
    g
}

#[test]
fn the_plumbing_never_imports_from_the_da_floor() {
    let g = graph();
    assert!(g.keys().any(|m| m.starts_with("com::")), "{g:?}");
    assert!(g.keys().any(|m| m.starts_with("da::")), "{g:?}");
    for (m, deps) in &g {
        if m.starts_with("com::") {
            let up: Vec<_> = deps.iter().filter(|d| d.starts_with("da::")).collect();
            assert!(up.is_empty(), "{m} imports from the DA floor: {up:?}");
        }
    }
}

#[test]
fn the_module_graph_has_no_cycle() {
    let g = graph();
    // Depth-first search with colours; a grey node reached again closes a cycle.
    fn visit(
        m: &str,
        g: &BTreeMap<String, BTreeSet<String>>,
        state: &mut BTreeMap<String, u8>,
        path: &mut Vec<String>,
    ) {
        match state.get(m) {
            Some(2) => return,
            Some(1) => {
                let start = path.iter().position(|p| p == m).unwrap();
                panic!("a cycle: {} -> {m}", path[start..].join(" -> "));
            }
            _ => {}
        }
        state.insert(m.to_string(), 1);
        path.push(m.to_string());
        for d in g.get(m).into_iter().flatten() {
            visit(d, g, state, path);
        }
        path.pop();
        state.insert(m.to_string(), 2);
    }
    let mut state = BTreeMap::new();
    for m in g.keys() {
        visit(m, &g, &mut state, &mut Vec::new());
    }
}

#[test]
fn the_reference_scanner_sees_paths_and_groups() {
    let (floors, bare) = references(
        "use crate::com::{abi, error};\nuse crate::da::context::Context;\nx(crate::clock::now())",
    );
    assert_eq!(
        floors.into_iter().collect::<Vec<_>>(),
        ["com::abi", "com::error", "da::context"]
    );
    assert_eq!(bare.into_iter().collect::<Vec<_>>(), ["clock"]);
}
