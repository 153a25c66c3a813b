//! Loading a database from its files (the only file access).

use std::path::Path;

use ctopc_core::OpcError;

use super::database::VarDatabase;
use super::table::read_cell_table;
use super::varset::{apply_setting, for_each_var_set_line, SetLine, VarSetFile};
use super::DbError;
use crate::text::{decode_text, Warning};

fn read(path: &Path) -> Result<Vec<u8>, DbError> {
    std::fs::read(path).map_err(|e| DbError {
        code: if e.kind() == std::io::ErrorKind::NotFound {
            OpcError::VarBaseNotFound
        } else {
            OpcError::ErrorDuringOpeningVarBase
        },
        file: path.display().to_string(),
        line: 0,
        message: e.to_string(),
    })
}

/// Loads a database: `path` is a variable-set file (its `Attributes` setting names the
/// table, relative to the set's folder; default: the set's name with `.csv`), or a `.csv`
/// attribute table used without a tree.
pub fn load_database_file(
    path: &Path,
    alias: Option<&str>,
) -> Result<(VarDatabase, Vec<Warning>), DbError> {
    let is_csv = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("csv"));
    if is_csv {
        let file = path.display().to_string();
        let (columns, cells) = read_cell_table(&read(path)?, &file)?;
        return VarDatabase::build_cells(&file, columns, cells, None, alias);
    }
    // The settings only (they come before the first group); the groups are streamed
    // from the text into the tree when the table is in.
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
    let table_path = match &set.attributes {
        Some(a) => {
            let a = if std::path::MAIN_SEPARATOR == '/' {
                a.replace('\\', "/")
            } else {
                a.clone()
            };
            path.parent().unwrap_or(Path::new("")).join(a)
        }
        None => path.with_extension("csv"),
    };
    let file = table_path.display().to_string();
    let (columns, cells) = read_cell_table(&read(&table_path)?, &file)?;
    let (db, more) =
        VarDatabase::build_cells(&file, columns, cells, Some((&set, Some(&text))), alias)?;
    warnings.extend(more);
    Ok((db, warnings))
}
