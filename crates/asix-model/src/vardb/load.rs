//! Loading a database from its files (the only file access).

use std::path::{Path, PathBuf};

use ctopc_core::OpcError;

use super::cells::CellTable;
use super::database::VarDatabase;
use super::paradox::paradox_to_csv;
use super::table::{read_cell_table, read_paradox_cell_table};
use super::varset::{apply_setting, for_each_var_set_line, SetLine, VarSetFile};
use super::DbError;
use crate::text::{decode_text, Warning};

fn read(path: &Path) -> Result<Vec<u8>, DbError> {
    std::fs::read(path).map_err(|e| io_error(path, e))
}

fn io_error(path: &Path, e: std::io::Error) -> DbError {
    DbError {
        code: if e.kind() == std::io::ErrorKind::NotFound {
            OpcError::VarBaseNotFound
        } else {
            OpcError::ErrorDuringOpeningVarBase
        },
        file: path.display().to_string(),
        line: 0,
        message: e.to_string(),
    }
}

/// Whether `path` is a Paradox table (`.DB`, any case).
fn is_paradox(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("db"))
}

/// The memo file of Paradox table `table` (`.MB` beside it), when there is one.
fn read_memo(table: &Path) -> Result<Option<Vec<u8>>, DbError> {
    for ext in ["MB", "mb"] {
        let mb = table.with_extension(ext);
        if mb.is_file() {
            return read(&mb).map(Some);
        }
    }
    Ok(None)
}

/// Reads the attribute table at `path`, CSV or Paradox by its extension.
fn read_table(
    path: &Path,
    warnings: &mut Vec<Warning>,
) -> Result<(Vec<String>, CellTable), DbError> {
    let file = path.display().to_string();
    if is_paradox(path) {
        let table = std::fs::File::open(path).map_err(|e| io_error(path, e))?;
        let memo = read_memo(path)?;
        read_paradox_cell_table(table, memo.as_deref(), &file, warnings)
    } else {
        read_cell_table(&read(path)?, &file)
    }
}

/// The attribute table of the variable set at `set` whose `Attributes` setting is
/// `attributes`: that file (relative to the set's folder); without the setting the set's
/// name with `.csv`, else with `.DB`, else the only `.DB` in the set's folder (the
/// original's database folder). The CSV comes first, so that a plant that exported its
/// Paradox table (`opcdiag export-db`) uses the export without deleting the table.
fn table_path(set: &Path, attributes: Option<&str>) -> Result<PathBuf, DbError> {
    let folder = set.parent().unwrap_or(Path::new(""));
    if let Some(a) = attributes {
        let a = if std::path::MAIN_SEPARATOR == '/' {
            a.replace('\\', "/")
        } else {
            a.to_owned()
        };
        return Ok(folder.join(a));
    }
    let csv = set.with_extension("csv");
    if csv.is_file() {
        return Ok(csv);
    }
    for ext in ["DB", "db"] {
        let db = set.with_extension(ext);
        if db.is_file() {
            return Ok(db);
        }
    }
    let dir = if folder.as_os_str().is_empty() {
        Path::new(".")
    } else {
        folder
    };
    let mut tables: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|d| {
            d.flatten()
                .map(|e| e.path())
                .filter(|p| is_paradox(p) && p.is_file())
                .collect()
        })
        .unwrap_or_default();
    match tables.len() {
        0 => Ok(csv),
        1 => Ok(tables.remove(0)),
        _ => {
            tables.sort();
            let names: Vec<String> = tables
                .iter()
                .filter_map(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
                .collect();
            Err(DbError {
                code: OpcError::VarBaseNotFound,
                file: set.display().to_string(),
                line: 0,
                message: format!(
                    "no `Attributes =` setting, no {} and several Paradox tables in the \
                     folder ({}): name the attribute table with `Attributes =`",
                    csv.file_name()
                        .map_or(String::new(), |n| n.to_string_lossy().into_owned()),
                    names.join(", ")
                ),
            })
        }
    }
}

/// Reads the variable set's settings (the lines before the first group).
fn read_set_settings(path: &Path) -> Result<(VarSetFile, String, Vec<Warning>), DbError> {
    let (text, _) = decode_text(&read(path)?);
    let mut set = VarSetFile {
        file: path.display().to_string(),
        attributes: None,
        title: None,
        groups: Vec::new(),
    };
    let mut warnings = Vec::new();
    let set_file = set.file.clone();
    for_each_var_set_line(&text, &set_file, |line, l| match l {
        SetLine::Setting(key, value) => {
            apply_setting(&mut set, &mut warnings, line, key, value);
            true
        }
        SetLine::Group(_) | SetLine::Variable(_) => false,
    })?;
    Ok((set, text, warnings))
}

/// The Paradox attribute table at `path` (a `.DB`, or a variable set whose table is one)
/// as the CSV text the loader reads (`opcdiag export-db`), with the table's path.
pub fn export_table_csv(path: &Path) -> Result<(String, PathBuf, Vec<Warning>), DbError> {
    let (table, mut warnings) = if is_paradox(path) {
        (path.to_path_buf(), Vec::new())
    } else {
        let (set, _, warnings) = read_set_settings(path)?;
        (table_path(path, set.attributes.as_deref())?, warnings)
    };
    if !is_paradox(&table) {
        return Err(DbError::invalid(
            &table.display().to_string(),
            0,
            "the attribute table is not a Paradox table (.DB)",
        ));
    }
    let file = std::fs::File::open(&table).map_err(|e| io_error(&table, e))?;
    let memo = read_memo(&table)?;
    let csv = paradox_to_csv(
        file,
        memo.as_deref(),
        &table.display().to_string(),
        &mut warnings,
    )?;
    Ok((csv, table, warnings))
}

/// Loads a database: `path` is a variable-set file (its `Attributes` setting names the
/// table, relative to the set's folder; without it the set's name with `.csv`, else with
/// `.DB`, else the folder's only `.DB`), or an attribute table used without a tree:
/// `.csv`, or a Paradox `.DB` (with its `.MB` memo file).
pub fn load_database_file(
    path: &Path,
    alias: Option<&str>,
) -> Result<(VarDatabase, Vec<Warning>), DbError> {
    let is_csv = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("csv"));
    if is_csv || is_paradox(path) {
        let file = path.display().to_string();
        let mut warnings = Vec::new();
        let (columns, cells) = read_table(path, &mut warnings)?;
        let (db, more) = VarDatabase::build_cells(&file, columns, cells, None, alias)?;
        warnings.extend(more);
        return Ok((db, warnings));
    }
    // The settings only (they come before the first group); the groups are streamed
    // from the text into the tree when the table is in.
    let (set, text, mut warnings) = read_set_settings(path)?;
    let table_path = table_path(path, set.attributes.as_deref())?;
    let file = table_path.display().to_string();
    let (columns, cells) = read_table(&table_path, &mut warnings)?;
    let (db, more) =
        VarDatabase::build_cells(&file, columns, cells, Some((&set, Some(&text))), alias)?;
    warnings.extend(more);
    Ok((db, warnings))
}
