//! The attribute table: its header and rows, as strings or streamed into a [`CellTable`].

use super::cells::CellTable;
use super::csv::{detect_separator, for_each_csv_record, CsvFields};
use super::paradox::{for_each_paradox_record, read_paradox_header, ParadoxSource};
use super::DbError;
use crate::text::{decode_text, Warning};

/// The attribute table as read: column names and rows of cells (one row per variable).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct AttributeTable {
    pub file: String,
    pub columns: Vec<String>,
    /// Rows with their line numbers; every row has `columns.len()` cells.
    pub rows: Vec<(usize, Vec<String>)>,
}

/// Well-known columns (matched ASCII case-insensitively).
pub mod columns {
    pub const NAME: &str = "Name";
    pub const DESCRIPTION: &str = "Description";
    pub const DESCRIPTION_EN: &str = "DescriptionEn";
    pub const UNIT: &str = "Unit";
    pub const RANGE_FROM: &str = "RangeFrom";
    pub const RANGE_TO: &str = "RangeTo";
    pub const DATA_TYPE: &str = "DataType";
    pub const FORMAT: &str = "Format";
    pub const WARN_LOW: &str = "WarnLow";
    pub const WARN_HIGH: &str = "WarnHigh";
    pub const ALARM_LOW: &str = "AlarmLow";
    pub const ALARM_HIGH: &str = "AlarmHigh";
    pub const CONTROL_VARIABLE: &str = "ControlVariable";
    pub const BAR_BASE: &str = "BarBase";
    pub const WRITABLE: &str = "Writable";
    /// Every well-known column.
    pub const ALL: &[&str] = &[
        NAME,
        DESCRIPTION,
        DESCRIPTION_EN,
        UNIT,
        RANGE_FROM,
        RANGE_TO,
        DATA_TYPE,
        FORMAT,
        WARN_LOW,
        WARN_HIGH,
        ALARM_LOW,
        ALARM_HIGH,
        CONTROL_VARIABLE,
        BAR_BASE,
        WRITABLE,
    ];
}

/// Parses the attribute table (CSV bytes; encoding and separator detected).
pub fn parse_attribute_table(bytes: &[u8], file: &str) -> Result<AttributeTable, DbError> {
    let mut rows = Vec::new();
    let columns = read_table(bytes, file, |line, fields, ncols| {
        let row = (0..ncols).map(|i| fields.get(i).to_owned()).collect();
        rows.push((line, row));
        Ok(())
    })?;
    Ok(AttributeTable {
        file: file.to_owned(),
        columns,
        rows,
    })
}

/// The attribute table streamed into a [`CellTable`]: what
/// [`load_database_file`](super::load_database_file) reads, without a `String` per cell.
pub(super) fn read_cell_table(
    bytes: &[u8],
    file: &str,
) -> Result<(Vec<String>, CellTable), DbError> {
    let mut cells = CellTable::default();
    let columns = read_table(bytes, file, |line, fields, ncols| {
        cells.ncols = ncols;
        cells.push_fields(line, fields, ncols)
    })?;
    cells.ncols = columns.len();
    Ok((columns, cells))
}

/// Parses a Paradox attribute table (the `.DB` bytes, and its `.MB` memo file when it has
/// one): the same table as [`parse_attribute_table`] makes of a CSV, the line of a row
/// being its record number. Warnings: a code page read as Windows-1250.
pub fn parse_paradox_table(
    bytes: &[u8],
    memo: Option<&[u8]>,
    file: &str,
) -> Result<(AttributeTable, Vec<Warning>), DbError> {
    let mut rows = Vec::new();
    let mut warnings = Vec::new();
    let columns = read_paradox(bytes, memo, file, &mut warnings, |n, fields, ncols| {
        rows.push((n, (0..ncols).map(|i| fields.get(i).to_owned()).collect()));
        Ok(())
    })?;
    let table = AttributeTable {
        file: file.to_owned(),
        columns,
        rows,
    };
    Ok((table, warnings))
}

/// [`parse_paradox_table`] streamed into a [`CellTable`], from a file or bytes.
pub(super) fn read_paradox_cell_table(
    src: impl ParadoxSource,
    memo: Option<&[u8]>,
    file: &str,
    warnings: &mut Vec<Warning>,
) -> Result<(Vec<String>, CellTable), DbError> {
    let mut cells = CellTable::default();
    let columns = read_paradox(src, memo, file, warnings, |n, fields, ncols| {
        cells.ncols = ncols;
        cells.push_fields(n, fields, ncols)
    })?;
    cells.ncols = columns.len();
    Ok((columns, cells))
}

/// Reads a Paradox table's header, checks its field names as a CSV header's, then hands
/// each record with the number of columns to `row`. Returns the columns.
fn read_paradox(
    mut src: impl ParadoxSource,
    memo: Option<&[u8]>,
    file: &str,
    warnings: &mut Vec<Warning>,
    mut row: impl FnMut(usize, &CsvFields, usize) -> Result<(), (usize, String)>,
) -> Result<Vec<String>, DbError> {
    let header = read_paradox_header(&mut src, file)?;
    let names = header.fields.iter().map(|f| f.name.clone()).collect();
    let columns = check_columns(0, names)
        .map_err(|(line, m)| DbError::invalid(file, line, format!("the field names: {m}")))?;
    let ncols = columns.len();
    for_each_paradox_record(src, &header, memo, file, warnings, |n, fields| {
        row(n, fields, ncols)
    })?;
    Ok(columns)
}

/// Reads the header (checked) and hands each row with the number of columns to `row`
/// (cells past the header's are empty: [`CsvFields::get`]). Returns the columns.
fn read_table(
    bytes: &[u8],
    file: &str,
    mut row: impl FnMut(usize, &CsvFields, usize) -> Result<(), (usize, String)>,
) -> Result<Vec<String>, DbError> {
    let (text, _) = decode_text(bytes);
    let sep = detect_separator(&text);
    let mut columns: Option<Vec<String>> = None;
    for_each_csv_record(&text, sep, |line, fields| match &columns {
        None => {
            columns = Some(check_header(line, fields)?);
            Ok(())
        }
        Some(columns) => {
            let ncols = columns.len();
            if fields.len() > ncols && (ncols..fields.len()).any(|i| !fields.get(i).is_empty()) {
                return Err((
                    line,
                    format!(
                        "{} cells, but the header has {} columns",
                        fields.len(),
                        ncols
                    ),
                ));
            }
            row(line, fields, ncols)
        }
    })
    .map_err(|(line, m)| DbError::invalid(file, line, m))?;
    columns.ok_or_else(|| DbError::invalid(file, 0, "the attribute table is empty (no header row)"))
}

fn check_header(line: usize, fields: &CsvFields) -> Result<Vec<String>, (usize, String)> {
    let mut columns: Vec<String> = fields.iter().map(str::to_owned).collect();
    // Trailing empty header cells (a spreadsheet's trailing separators) are dropped.
    while columns.last().is_some_and(|c| c.is_empty()) && columns.len() > 1 {
        columns.pop();
    }
    check_columns(line, columns)
}

/// The rules of column names, for the CSV header and the Paradox fields alike.
fn check_columns(line: usize, columns: Vec<String>) -> Result<Vec<String>, (usize, String)> {
    for (i, c) in columns.iter().enumerate() {
        if c.is_empty() {
            return Err((line, format!("column {} has no name", i + 1)));
        }
        if c.contains('.') || c.chars().any(char::is_control) {
            return Err((line, format!("column name `{c}` may not contain `.`")));
        }
        if let Some(prev) = columns[..i].iter().find(|p| p.eq_ignore_ascii_case(c)) {
            return Err((line, format!("column `{c}` repeats column `{prev}`")));
        }
    }
    if !columns
        .iter()
        .any(|c| c.eq_ignore_ascii_case(columns::NAME))
    {
        return Err((line, "the header has no `Name` column".into()));
    }
    Ok(columns)
}
