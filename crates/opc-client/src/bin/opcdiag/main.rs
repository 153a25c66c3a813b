//! `opcdiag`: a diagnostic OPC DA client shipped with ServerCTOPC, usable against any
//! OPC DA 2.05a/3.0 server on the same computer: status, browse, properties, read, write,
//! subscribe, and the demo plant tour; and `export-db`, the original's Paradox attribute
//! table as the CSV the server reads. `opcdiag --help` lists the commands.
//!
//! With `--url opc.tcp://HOST:PORT`, browse, read, write and subscribe speak OPC UA
//! instead (`ua`, async-opcua's client; on every host but 32-bit Windows, `cfg(ua)` from
//! build.rs).
//!
//! The command line and every formatting rule are plain Rust (`cli`, `text`, `ua::show`:
//! tested natively; `export` reads files only and runs everywhere); the COM calls (`win`,
//! `demo`) exist on Windows only and go through the safe
//! client wrapper `opc_client`.

/// `println!` that does not panic when stdout is gone (piped into `head`, say): the
/// line is dropped and [`out::closed`] turns true, which ends a subscription.
#[cfg(windows)]
macro_rules! say {
    () => { $crate::out::line(format_args!("")) };
    ($($t:tt)*) => { $crate::out::line(format_args!($($t)*)) };
}

mod cli;
#[cfg(windows)]
mod demo;
mod doctor;
mod export;
#[cfg(any(windows, ua))]
mod out;
mod text;
#[cfg(ua)]
mod ua;
#[cfg(windows)]
mod win;

use std::process::ExitCode;

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match cli::parse(&args) {
        Ok(cli::Parsed::Help(text)) => {
            print!("{text}");
            ExitCode::from(cli::EXIT_OK)
        }
        // Reads files only: runs on every host.
        Ok(cli::Parsed::Run(_, cli::Command::ExportDb { source, out })) => {
            ExitCode::from(export::run(&source, out.as_deref()))
        }
        // OPC UA: `--url`, and `cert` (opcdiag's client certificate).
        Ok(cli::Parsed::Run(global, command))
            if global.ua.url.is_some() || command == cli::Command::Cert =>
        {
            ExitCode::from(run_ua(&global, command))
        }
        Ok(cli::Parsed::Run(global, command)) => run(global, command),
        Err(e) => {
            eprintln!("opcdiag: {}\n\n{}", e.message, e.help);
            ExitCode::from(cli::EXIT_USAGE)
        }
    }
}

#[cfg(ua)]
fn run_ua(global: &cli::Global, command: cli::Command) -> u8 {
    ua::run(global, command)
}

#[cfg(not(ua))]
fn run_ua(_global: &cli::Global, _command: cli::Command) -> u8 {
    eprintln!(
        "opcdiag: this opcdiag is built without OPC UA (the 32-bit one is OPC DA only): use \
         the 64-bit opcdiag for --url and cert"
    );
    cli::EXIT_USAGE
}

#[cfg(windows)]
fn run(global: cli::Global, command: cli::Command) -> ExitCode {
    let result = match command {
        cli::Command::Demo { for_secs } => {
            win::Session::connect(&global).and_then(|s| demo::run(&s, for_secs))
        }
        command => win::run(&global, command),
    };
    match result {
        Ok(code) => ExitCode::from(code),
        Err(e) => {
            eprintln!("opcdiag: error: {e}");
            ExitCode::from(cli::EXIT_FAILED)
        }
    }
}

#[cfg(not(windows))]
fn run(_global: cli::Global, _command: cli::Command) -> ExitCode {
    eprintln!(
        "opcdiag: OPC DA is COM, which exists on Windows only: run opcdiag.exe on Windows \
         (or under Wine, as `cargo xtask demo` does)."
    );
    ExitCode::from(cli::EXIT_FAILED)
}
