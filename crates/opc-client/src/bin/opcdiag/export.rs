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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_the_table_as_csv_and_fails_on_a_missing_one() {
        let fixtures = Path::new(env!("CARGO_MANIFEST_DIR")).join("../asix-model/tests/paradox");
        let out = std::env::temp_dir().join(format!("opcdiag-export-{}.csv", std::process::id()));
        let table = fixtures.join("types.DB");
        assert_eq!(
            run(table.to_str().unwrap_or_default(), out.to_str()),
            EXIT_OK
        );
        let csv = std::fs::read_to_string(&out).unwrap_or_default();
        let _ = std::fs::remove_file(&out);
        assert!(
            csv.starts_with(
                "\u{FEFF}Name;Count;Total;Ratio;Price;Flag;Day;At;Stamp;Serial;Note\r\n"
            ),
            "{csv}"
        );
        assert!(csv.contains("KW_ŻÓŁW;32767;4000000;0.5;12.99;tak;2024-02-29;13:05:07;"));
        assert_eq!(run("no-such-table.DB", None), EXIT_FAILED);
    }
}
