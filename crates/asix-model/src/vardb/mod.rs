//! The variable database: the attribute table (CSV, or the original's Paradox `.DB`) and
//! the variable set (the browse tree, a `.zez` text file). The format is specified for
//! users in `docs/variable-database.md`; this module is its reference implementation.
//!
//! All logic is in the pure `parse_*` functions and [`VarDatabase::build`];
//! [`load_database_file`] only reads the files.
//!
//! Layout (large plants have up to a million variables). No `String` per cell
//! or per map key:
//! - every cell of the table is text in one `CellTable`, row after row, with a `u8` end
//!   per cell relative to its row (17 columns: 17 B; `u16` ends aside for a row of more
//!   than 255 B) and a `u32` start per row; the row's text is ~90 B (at most 65,535 B,
//!   [`MAX_ROW_BYTES`]); the lines are kept as runs of consecutive lines (one run for a
//!   file without blank lines or line breaks in quoted cells);
//! - the `Name` index is a `hashbrown::HashTable<u32>` of row numbers, names compared in
//!   the table (~10 B per variable at 1,000,000); the public-name index is another in
//!   alias mode only (else the public names are the names);
//! - the tree ([`GroupNode`]) holds `u32` rows (4 B per variable);
//! - a slot for each variable's decoded [`Variable`], in chunks of 64 made on first use.
//!
//! About 125 B per variable in all (134 B measured with 1,000,000 variables by
//! `cargo bench -p asix-net --bench scale_start`). [`load_database_file`] streams the CSV
//! into the table ([`for_each_csv_record`], reading bytes); [`VarView`] reads a variable's
//! attributes in place.
//!
//! A Paradox table is read by a second reader (`paradox`, block by block from the file)
//! that hands each record out as text cells like a CSV record, into the same table and
//! the same checks.
//!
//! One file per concern: `csv` (the CSV reader), `paradox` (the Paradox reader), `table`
//! (the attribute table), `varset` (the variable set, `.zez`), `cells` (`CellTable`),
//! `index` (the name index), `variables` ([`Variables`], [`VarView`], [`Variable`]),
//! `database` ([`VarDatabase::build`] and the look-ups), `load` (the files).

mod cells;
mod csv;
mod database;
mod index;
mod load;
mod paradox;
mod table;
#[cfg(test)]
mod tests;
mod variables;
mod varset;

use std::fmt;

use ctopc_core::OpcError;

pub use cells::MAX_ROW_BYTES;
pub use csv::{detect_separator, for_each_csv_record, parse_csv, CsvFields, CsvRecord};
pub use database::{GroupNode, VarDatabase};
pub use index::hash_name;
pub use load::{export_table_csv, load_database_file};
pub use paradox::{
    for_each_paradox_record, paradox_to_csv, read_paradox_header, CodePage, FieldType,
    ParadoxField, ParadoxHeader, ParadoxSource,
};
pub use table::{columns, parse_attribute_table, parse_paradox_table, AttributeTable};
pub use variables::{Limit, LimitRef, VarView, Variable, Variables};
pub use varset::{parse_var_set, VarSetFile, VarSetGroup};

/// A database that cannot be used: `code` is `ASKOM_E_VarBaseNotFound` (a file is missing)
/// or `ASKOM_E_ErrorDuringOpeningVarBase` (unreadable or invalid).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DbError {
    pub code: OpcError,
    pub file: String,
    /// 1-based line (the record in a Paradox table); 0 when the error concerns the whole
    /// file.
    pub line: usize,
    pub message: String,
}

impl DbError {
    fn invalid(file: &str, line: usize, message: impl Into<String>) -> Self {
        DbError {
            code: OpcError::ErrorDuringOpeningVarBase,
            file: file.to_owned(),
            line,
            message: message.into(),
        }
    }
}

impl fmt::Display for DbError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.file)?;
        if self.line > 0 {
            write!(f, ":{}", self.line)?;
        }
        write!(f, ": {} [{}]", self.message, self.code.symbol())
    }
}

impl std::error::Error for DbError {}

impl From<DbError> for OpcError {
    fn from(e: DbError) -> OpcError {
        e.code
    }
}

/// Whether `name` holds a control character (bytes for ASCII, the usual name).
fn has_control(name: &str) -> bool {
    if name.is_ascii() {
        name.bytes().any(|b| b.is_ascii_control())
    } else {
        name.chars().any(char::is_control)
    }
}
