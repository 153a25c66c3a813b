//! Every input that once failed a fuzz target (`fuzz/regressions/<target>/*`), replayed:
//! each must pass. A new failure found by `cargo xtask fuzz` goes there once fixed.

use std::path::Path;

#[test]
fn every_saved_failure_passes_now() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("regressions");
    let mut replayed = 0;
    for (name, f) in ctopc_fuzz::TARGETS {
        let Ok(dir) = std::fs::read_dir(root.join(name)) else {
            continue;
        };
        for entry in dir.flatten() {
            let input = std::fs::read(entry.path()).expect("read a regression input");
            f(&input);
            replayed += 1;
        }
    }
    println!("replayed {replayed} saved inputs");
}

#[test]
fn every_target_has_a_libfuzzer_entry() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz_targets");
    for (name, _) in ctopc_fuzz::TARGETS {
        assert!(
            dir.join(format!("{name}.rs")).is_file(),
            "fuzz_targets/{name}.rs"
        );
    }
}

#[test]
fn xtask_lists_every_target() {
    let xtask = include_str!("../../xtask/src/fuzz.rs");
    for (name, _) in ctopc_fuzz::TARGETS {
        assert!(
            xtask.contains(&format!("\"{name}\",")),
            "xtask/src/fuzz.rs TARGETS: {name}"
        );
    }
}
