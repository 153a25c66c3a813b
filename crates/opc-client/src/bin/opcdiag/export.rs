//! `opcdiag export-db`: the original's Paradox attribute table as the CSV the server
//! reads, by the server's own reader (`asix_model::vardb::export_table_csv`, tested
//! there). Reads and writes files only, so it runs on every host.

use std::io::Write as _;
use std::path::Path;

use crate::cli::{EXIT_FAILED, EXIT_OK};

/// Exports `source` (a variable set or a `.DB`) to `out` (standard output when `None`);
/// the exit code. Warnings and errors go to standard error.
pub fn run(source: &str, out: Option<&str>) -> u8 {
    match export(source, out) {
        Ok(()) => EXIT_OK,
        Err(e) => {
            eprintln!("opcdiag: error: {e}");
            EXIT_FAILED
        }
    }
}

fn export(source: &str, out: Option<&str>) -> Result<(), String> {
    let (csv, table, warnings) =
        asix_model::vardb::export_table_csv(Path::new(source)).map_err(|e| e.to_string())?;
    for w in &warnings {
        eprintln!("opcdiag: warning: {w}");
    }
    match out {
        Some(file) => {
            std::fs::write(file, &csv).map_err(|e| format!("{file}: {e}"))?;
            eprintln!("opcdiag: {} -> {file}", table.display());
        }
        None => std::io::stdout()
            .write_all(csv.as_bytes())
            .map_err(|e| format!("standard output: {e}"))?,
    }
    Ok(())
}
