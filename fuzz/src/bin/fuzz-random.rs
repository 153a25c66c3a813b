//! The stable fuzz runner: every target (or those named) for `--seconds N` each, with
//! random mutations of their seeds (`ctopc_fuzz::run`). Used by `cargo xtask fuzz` when
//! cargo-fuzz or a nightly toolchain is missing, and by CI. A failing input is saved to
//! `target/fuzz-failures/` and the run exits 1.
//!
//! `fuzz-random [--seconds N] [--seed S] [TARGET...]`

use std::process::ExitCode;
use std::time::Duration;

fn main() -> ExitCode {
    let mut seconds = 5.0f64;
    let mut seed = 0x5EED_u64;
    let mut names: Vec<String> = Vec::new();
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--seconds" => seconds = args.next().and_then(|s| s.parse().ok()).unwrap_or(seconds),
            "--seed" => seed = args.next().and_then(|s| s.parse().ok()).unwrap_or(seed),
            other => names.push(other.to_owned()),
        }
    }
    // Panics are caught per input: keep their messages out of the output.
    std::panic::set_hook(Box::new(|_| {}));
    let mut failed = false;
    for (name, _) in ctopc_fuzz::TARGETS {
        if !names.is_empty() && !names.iter().any(|n| n == name) {
            continue;
        }
        match ctopc_fuzz::run(name, Duration::from_secs_f64(seconds), seed) {
            Ok(n) => println!("fuzz: {name}: {n} inputs in {seconds} s, no failure"),
            Err(f) => {
                failed = true;
                let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
                    .join("../target/fuzz-failures");
                let hash = f.input.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, b| {
                    (h ^ u64::from(*b)).wrapping_mul(0x100_0000_01b3)
                });
                let path = dir.join(format!("{name}-{hash:016x}.bin"));
                let saved = std::fs::create_dir_all(&dir)
                    .and_then(|()| std::fs::write(&path, &f.input))
                    .map(|()| path.display().to_string())
                    .unwrap_or_else(|e| format!("(not saved: {e})"));
                println!(
                    "fuzz: {name}: FAILED: {} on {} bytes, saved to {saved}",
                    f.message,
                    f.input.len()
                );
            }
        }
    }
    if failed {
        ExitCode::FAILURE
    } else {
        ExitCode::SUCCESS
    }
}
