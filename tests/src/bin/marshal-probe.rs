//! marshal-probe.exe: the test COM server `ServerCTOPC.MarshalProbe`, whose objects return a
//! distinct non-ASCII text in every string out-parameter of every OPC interface
//! (`e2e_tests::probe`). Driven out of process by `tests/tests/marshal_strings.rs`, which
//! registers it with `/RegServer`; COM starts it with `-Embedding`.
//!
//! Switches as ServerCTOPC.exe: case-insensitive, starting with `/` or `-`.

const USAGE: &str = "usage: marshal-probe.exe /RegServer | /UnregServer | -Embedding";

#[cfg(windows)]
fn main() -> std::process::ExitCode {
    use e2e_tests::probe;
    use std::process::ExitCode;

    let args: Vec<String> = std::env::args().skip(1).collect();
    let switch = match args.as_slice() {
        [one] => one
            .strip_prefix('/')
            .or_else(|| one.strip_prefix('-'))
            .map(str::to_ascii_lowercase),
        _ => None,
    };
    let result = match switch.as_deref() {
        Some("regserver") => probe::register(),
        Some("unregserver") => probe::unregister(),
        Some("embedding") => probe::serve(),
        _ => {
            eprintln!("marshal-probe: {USAGE}");
            return ExitCode::from(2);
        }
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("marshal-probe: {e}");
            ExitCode::FAILURE
        }
    }
}

#[cfg(not(windows))]
fn main() -> std::process::ExitCode {
    eprintln!("marshal-probe: a Windows COM server (run it under Wine); {USAGE}");
    std::process::ExitCode::FAILURE
}
