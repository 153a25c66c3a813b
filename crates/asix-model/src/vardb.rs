//! The variable database: the attribute table (CSV) and the variable set (the browse
//! tree, a `.zez` text file). The format is specified for users in
//! `docs/variable-database.md`; this module is its reference implementation.
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

use std::collections::BTreeMap;
use std::fmt;
use std::path::Path;
use std::sync::OnceLock;

use hashbrown::HashTable;

use super::format::FormatSpec;
use super::text::{decode_text, parse_bool, parse_number, trim, Warning};
use ctopc_core::{OpcError, VarType};

/// A database that cannot be used: `code` is `ASKOM_E_VarBaseNotFound` (a file is missing)
/// or `ASKOM_E_ErrorDuringOpeningVarBase` (unreadable or invalid).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DbError {
    pub code: OpcError,
    pub file: String,
    /// 1-based line; 0 when the error concerns the whole file.
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

// ---------------------------------------------------------------------------------------
// CSV
// ---------------------------------------------------------------------------------------

/// One CSV record: the line it starts on and its fields.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CsvRecord {
    pub line: usize,
    pub fields: Vec<String>,
}

/// The separator of a CSV text: the most frequent of `;`, tab and `,` outside quotes in
/// the first record (ties in that order; `;` when there is none).
pub fn detect_separator(text: &str) -> char {
    let mut counts = [0usize; 3];
    let mut quoted = false;
    for c in text.chars() {
        match c {
            '"' => quoted = !quoted,
            '\n' | '\r' if !quoted => break,
            ';' if !quoted => counts[0] += 1,
            '\t' if !quoted => counts[1] += 1,
            ',' if !quoted => counts[2] += 1,
            _ => {}
        }
    }
    let seps = [';', '\t', ','];
    let mut best = 0;
    for i in 1..3 {
        if counts[i] > counts[best] {
            best = i;
        }
    }
    seps[best]
}

/// The fields of one CSV record as [`for_each_csv_record`] hands them out: one text buffer
/// and the end of each field in it (no `String` per field).
#[derive(Debug, Default)]
pub struct CsvFields {
    buf: String,
    ends: Vec<usize>,
}

impl CsvFields {
    /// The number of fields.
    pub fn len(&self) -> usize {
        self.ends.len()
    }

    pub fn is_empty(&self) -> bool {
        self.ends.is_empty()
    }

    /// Field `i` (`""` past the end).
    pub fn get(&self, i: usize) -> &str {
        match self.ends.get(i) {
            Some(&end) => &self.buf[if i == 0 { 0 } else { self.ends[i - 1] }..end],
            None => "",
        }
    }

    /// Every field, in order.
    pub fn iter(&self) -> impl Iterator<Item = &str> + '_ {
        (0..self.len()).map(|i| self.get(i))
    }

    fn start(&self) -> usize {
        self.ends.last().copied().unwrap_or(0)
    }

    /// Ends the field that started at [`CsvFields::start`]; unquoted fields are trimmed.
    fn end_field(&mut self, quoted: bool) {
        let start = self.start();
        let plain =
            |b: Option<&u8>| b.is_some_and(|&b| b.is_ascii() && !(b as char).is_whitespace());
        let field = &self.buf.as_bytes()[start..];
        // Nothing to trim when both ends are ASCII and not blank (the usual cell).
        let trimmed = field.is_empty() || plain(field.first()) && plain(field.last());
        if !quoted && !trimmed {
            let s = &self.buf[start..];
            let lead = s.len() - s.trim_start().len();
            let len = s.trim().len();
            self.buf.drain(start..start + lead);
            self.buf.truncate(start + len);
        }
        self.ends.push(self.buf.len());
    }

    fn clear(&mut self) {
        self.buf.clear();
        self.ends.clear();
    }
}

/// Splits CSV text into records (RFC 4180 quoting: `"a ""b"""`, quoted fields may hold
/// separators and line breaks). Unquoted fields are trimmed; blank lines are skipped.
/// Errors: `(line, message)` for text after a closing quote or an unterminated quote.
pub fn parse_csv(text: &str, sep: char) -> Result<Vec<CsvRecord>, (usize, String)> {
    let mut records = Vec::new();
    for_each_csv_record(text, sep, |line, fields| {
        records.push(CsvRecord {
            line,
            fields: fields.iter().map(str::to_owned).collect(),
        });
        Ok(())
    })?;
    Ok(records)
}

/// [`parse_csv`] streaming: calls `record(line, fields)` for each record as it is read,
/// with one reused buffer; an error of `record` stops the reading and is returned.
///
/// Reads bytes, not chars: every byte that means something (the separator's first byte,
/// `"`, CR, LF) is ASCII or starts a char, so the text between two of them is copied as
/// one slice (a large plant's million rows are read at start).
pub fn for_each_csv_record(
    text: &str,
    sep: char,
    mut record: impl FnMut(usize, &CsvFields) -> Result<(), (usize, String)>,
) -> Result<(), (usize, String)> {
    let mut sep_utf8 = [0u8; 4];
    let sep_str: &str = sep.encode_utf8(&mut sep_utf8);
    let sep0 = sep_str.as_bytes()[0];
    let bytes = text.as_bytes();
    let special = |b: u8| b == sep0 || matches!(b, b'"' | b'\r' | b'\n');
    let mut fields = CsvFields::default();
    let mut line = 1usize;
    let mut record_line = 1usize;
    // State of the current field: was it quoted, and is the quote closed.
    let mut quoted = false;
    let mut in_quotes = false;
    let mut quote_line = 0usize;
    let mut after_quote = false;
    let mut end_record =
        |fields: &mut CsvFields, quoted: bool, record_line: usize| -> Result<(), (usize, String)> {
            fields.end_field(quoted);
            let r = if !(fields.len() == 1 && fields.get(0).is_empty() && !quoted) {
                record(record_line, fields)
            } else {
                Ok(())
            };
            fields.clear();
            r
        };
    let mut i = 0;
    while i < bytes.len() {
        let b = bytes[i];
        if in_quotes {
            match b {
                b'"' if bytes.get(i + 1) == Some(&b'"') => {
                    fields.buf.push('"');
                    i += 2;
                }
                b'"' => {
                    in_quotes = false;
                    after_quote = true;
                    i += 1;
                }
                b'\r' | b'\n' => {
                    i += if b == b'\r' && bytes.get(i + 1) == Some(&b'\n') {
                        2
                    } else {
                        1
                    };
                    line += 1;
                    fields.buf.push('\n');
                }
                _ => {
                    let run = bytes[i..]
                        .iter()
                        .position(|&b| matches!(b, b'"' | b'\r' | b'\n'))
                        .map_or(bytes.len(), |k| i + k);
                    fields.buf.push_str(&text[i..run]);
                    i = run;
                }
            }
            continue;
        }
        if b == sep0 && (sep_str.len() == 1 || text[i..].starts_with(sep_str)) {
            fields.end_field(quoted);
            quoted = false;
            after_quote = false;
            i += sep_str.len();
            continue;
        }
        match b {
            b'\r' | b'\n' => {
                i += if b == b'\r' && bytes.get(i + 1) == Some(&b'\n') {
                    2
                } else {
                    1
                };
                end_record(&mut fields, quoted, record_line)?;
                quoted = false;
                after_quote = false;
                line += 1;
                record_line = line;
            }
            _ if after_quote => {
                let c = text[i..].chars().next().unwrap_or(' ');
                if !c.is_whitespace() {
                    return Err((line, format!("text `{c}` after a closing quote")));
                }
                i += c.len_utf8();
            }
            b'"' if fields.buf[fields.start()..].trim().is_empty() => {
                let start = fields.start();
                fields.buf.truncate(start);
                quoted = true;
                in_quotes = true;
                quote_line = line;
                i += 1;
            }
            _ => {
                // Up to the next byte that means something (a char boundary).
                let run = bytes[i + 1..]
                    .iter()
                    .position(|&b| special(b))
                    .map_or(bytes.len(), |k| i + 1 + k);
                fields.buf.push_str(&text[i..run]);
                i = run;
            }
        }
    }
    if in_quotes {
        return Err((quote_line, "quoted field is not closed".into()));
    }
    if !fields.is_empty() || fields.buf.len() > fields.start() || quoted {
        end_record(&mut fields, quoted, record_line)?;
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------
// Attribute table
// ---------------------------------------------------------------------------------------

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

/// The attribute table streamed into a [`CellTable`]: what [`load_database_file`] reads,
/// without a `String` per cell.
fn read_cell_table(bytes: &[u8], file: &str) -> Result<(Vec<String>, CellTable), DbError> {
    let mut cells = CellTable::default();
    let columns = read_table(bytes, file, |line, fields, ncols| {
        cells.ncols = ncols;
        cells.push_fields(line, fields, ncols)
    })?;
    cells.ncols = columns.len();
    Ok((columns, cells))
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

// ---------------------------------------------------------------------------------------
// Variable set (tree)
// ---------------------------------------------------------------------------------------

/// One `[Group/Sub]` block of a variable-set file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct VarSetGroup {
    /// Path segments from the root; empty for the root (`[/]`).
    pub path: Vec<String>,
    pub line: usize,
    /// Variable (real) names with their lines.
    pub variables: Vec<(String, usize)>,
}

/// A parsed variable-set file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct VarSetFile {
    pub file: String,
    /// `Attributes = ...`: the attribute table, relative to the set file's folder.
    pub attributes: Option<String>,
    /// `Title = ...`: a display name.
    pub title: Option<String>,
    pub groups: Vec<VarSetGroup>,
}

/// Parses a variable-set file (`.zez`).
pub fn parse_var_set(bytes: &[u8], file: &str) -> Result<(VarSetFile, Vec<Warning>), DbError> {
    let (text, _) = decode_text(bytes);
    let mut set = VarSetFile {
        file: file.to_owned(),
        attributes: None,
        title: None,
        groups: Vec::new(),
    };
    let mut warnings = Vec::new();
    for_each_var_set_line(&text, file, |line, l| {
        match l {
            SetLine::Group(path) => set.groups.push(VarSetGroup {
                path: path.into_iter().map(str::to_owned).collect(),
                line,
                variables: Vec::new(),
            }),
            SetLine::Variable(name) => {
                if let Some(group) = set.groups.last_mut() {
                    group.variables.push((name.to_owned(), line));
                }
            }
            SetLine::Setting(key, value) => {
                apply_setting(&mut set, &mut warnings, line, key, value)
            }
        }
        true
    })?;
    Ok((set, warnings))
}

fn apply_setting(
    set: &mut VarSetFile,
    warnings: &mut Vec<Warning>,
    line: usize,
    key: &str,
    value: &str,
) {
    let value = (!value.is_empty()).then(|| value.to_owned());
    match key.to_ascii_lowercase().as_str() {
        "attributes" => set.attributes = value,
        "title" => set.title = value,
        other => warnings.push(Warning::new(
            &set.file,
            line,
            format!("unknown setting `{other}` ignored"),
        )),
    }
}

/// A line of a variable-set file that means something.
enum SetLine<'t> {
    /// `[a/b]`: the path from the root (empty for `[/]`).
    Group(Vec<&'t str>),
    /// A variable of the last group.
    Variable(&'t str),
    /// `key = value` before the first group (both trimmed).
    Setting(&'t str, &'t str),
}

/// Reads a variable-set text line by line, borrowing every name from it; `f` returns
/// whether to go on.
fn for_each_var_set_line<'t>(
    text: &'t str,
    file: &str,
    mut f: impl FnMut(usize, SetLine<'t>) -> bool,
) -> Result<(), DbError> {
    let mut in_group = false;
    for (index, raw) in text.lines().enumerate() {
        let line = index + 1;
        let t = trim(raw);
        if t.is_empty() || t.starts_with(';') || t.starts_with('#') {
            continue;
        }
        let l = if let Some(rest) = t.strip_prefix('[') {
            let inner = rest
                .strip_suffix(']')
                .ok_or_else(|| {
                    DbError::invalid(file, line, format!("group header `{t}` has no closing `]`"))
                })?
                .trim();
            let path: Vec<&str> = if inner.is_empty() || inner == "/" {
                Vec::new()
            } else {
                let segments: Vec<&str> = inner.split('/').map(str::trim).collect();
                if segments.iter().any(|s| s.is_empty()) {
                    return Err(DbError::invalid(
                        file,
                        line,
                        format!("group path `{inner}` has an empty segment"),
                    ));
                }
                segments
            };
            in_group = true;
            SetLine::Group(path)
        } else if in_group {
            if has_control(t) {
                return Err(DbError::invalid(
                    file,
                    line,
                    "variable name with a control character",
                ));
            }
            SetLine::Variable(t)
        } else {
            let Some((key, value)) = t.split_once('=') else {
                return Err(DbError::invalid(
                    file,
                    line,
                    format!("`{t}` is before the first group header (use [/] for the root group)"),
                ));
            };
            SetLine::Setting(key.trim(), value.trim())
        };
        if !f(line, l) {
            break;
        }
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------
// The database
// ---------------------------------------------------------------------------------------

/// A limit attribute: a number, or the name of a variable holding the limit.
#[derive(Debug, Clone, PartialEq)]
pub enum Limit {
    Value(f64),
    Variable(String),
}

impl Limit {
    /// The numeric limit, if the attribute holds a number.
    pub fn value(&self) -> Option<f64> {
        match self {
            Limit::Value(v) => Some(*v),
            Limit::Variable(_) => None,
        }
    }
}

/// A limit attribute as stored: a number, or the name of a variable holding the limit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum LimitRef<'a> {
    Value(f64),
    Variable(&'a str),
}

impl LimitRef<'_> {
    pub fn to_limit(self) -> Limit {
        match self {
            LimitRef::Value(v) => Limit::Value(v),
            LimitRef::Variable(n) => Limit::Variable(n.to_owned()),
        }
    }
}

/// One variable with its well-known attributes decoded: a copy made from the compact
/// table ([`Variables`]) when it is first asked for, then kept.
#[derive(Debug, Clone, PartialEq)]
pub struct Variable {
    /// The asix name (column `Name`).
    pub name: String,
    /// The name clients use: the alias in alias mode, else `name`.
    pub public_name: String,
    /// Line in the attribute table.
    pub line: usize,
    pub description: String,
    /// `DescriptionEn`; empty when not given.
    pub description_en: String,
    pub unit: String,
    /// (RangeFrom, RangeTo) when both are set and differ.
    pub range: Option<(f64, f64)>,
    /// Canonical type of the current value (`DataType`, default R4).
    pub data_type: VarType,
    /// `Format` as written.
    pub format_text: String,
    /// `Format` parsed; `None` when empty or unusable (the default form applies).
    pub format: Option<FormatSpec>,
    pub warn_low: Option<Limit>,
    pub warn_high: Option<Limit>,
    pub alarm_low: Option<Limit>,
    pub alarm_high: Option<Limit>,
    /// `ControlVariable`: the asix name of the control variable.
    pub control_variable: Option<String>,
    /// `BarBase` (default: the range low).
    pub bar_base: Option<f64>,
    /// `Writable` (default tak).
    pub writable: bool,
    /// Every cell, in column order.
    pub cells: Vec<String>,
}

impl Variable {
    /// The bar base: `BarBase`, else the range low.
    pub fn effective_bar_base(&self) -> Option<f64> {
        self.bar_base.or(self.range.map(|r| r.0))
    }
}

/// A group of the browse tree.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct GroupNode {
    pub name: String,
    pub groups: Vec<GroupNode>,
    /// Indexes into [`VarDatabase::variables`].
    pub variables: Vec<u32>,
}

impl GroupNode {
    fn child_pos(&mut self, name: &str) -> usize {
        match self.groups.iter().position(|g| g.name == name) {
            Some(p) => p,
            None => {
                self.groups.push(GroupNode {
                    name: name.to_owned(),
                    ..GroupNode::default()
                });
                self.groups.len() - 1
            }
        }
    }
}

/// Every cell of the attribute table in one text, row after row: the start of each row
/// in it (`u32`) and the end of each cell relative to its row's start: cell `k` (row
/// `r = k / ncols`, column `c = k % ncols`) is `text[starts[r] + ends[k - 1]..starts[r] +
/// ends[k]]` (from the row's start when `c` is 0). The ends are one byte (`u8`) for rows
/// of up to 255 bytes of text, the usual row; a longer row (at most 65,535 bytes) has its
/// ends in `wide_ends` (`u16`), found through `wide_rows`, and zeros in `ends`. So 1 byte
/// per cell and 4 per row plus the text itself, and a line per run of rows on consecutive
/// lines (one run for a file without blank lines or line breaks in quoted cells).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
struct CellTable {
    text: String,
    starts: Vec<u32>,
    ends: Vec<u8>,
    /// The rows of more than 255 bytes, by row: (row, where its ends start in `wide_ends`).
    wide_rows: Vec<(u32, u32)>,
    wide_ends: Vec<u16>,
    ncols: usize,
    /// Runs of rows on consecutive lines of the file, by row: (first row, its line).
    line_runs: Vec<(u32, u32)>,
}

/// The most text a row of the attribute table may hold ([`CellTable`]'s `u16` ends).
pub const MAX_ROW_BYTES: usize = u16::MAX as usize;

/// The most text of a row whose cell ends are one byte each ([`CellTable`]).
const NARROW_ROW_BYTES: usize = u8::MAX as usize;

impl CellTable {
    fn rows(&self) -> usize {
        self.starts.len()
    }

    fn push_row<'a>(
        &mut self,
        line: usize,
        cells: impl Iterator<Item = &'a str>,
    ) -> Result<(), (usize, String)> {
        let start = self.text.len();
        let too_long = |m: &str| (line, m.to_owned());
        let start32 = u32::try_from(start)
            .map_err(|_| too_long("the attribute table holds more than 4 GB of text"))?;
        let row = u32::try_from(self.starts.len())
            .map_err(|_| too_long("the attribute table holds more than 4 billion rows"))?;
        let cells_before = self.ends.len();
        let wide_before = self.wide_ends.len();
        let wide_start = u32::try_from(wide_before)
            .map_err(|_| too_long("the attribute table holds too many long rows"))?;
        let mut wide = false;
        for c in cells {
            self.text.push_str(c);
            let len = self.text.len() - start;
            let Ok(end) = u16::try_from(len) else {
                self.text.truncate(start);
                self.ends.truncate(cells_before);
                self.wide_ends.truncate(wide_before);
                return Err(too_long(&format!(
                    "the row holds more than {MAX_ROW_BYTES} bytes of text"
                )));
            };
            if !wide && len > NARROW_ROW_BYTES {
                // The row's ends so far move to `wide_ends`.
                wide = true;
                let row_ends = &mut self.ends[cells_before..];
                self.wide_ends
                    .extend(row_ends.iter().map(|&e| u16::from(e)));
                row_ends.fill(0);
            }
            if wide {
                self.wide_ends.push(end);
                self.ends.push(0);
            } else {
                self.ends.push(end as u8);
            }
        }
        if wide {
            self.wide_rows.push((row, wide_start));
        }
        self.starts.push(start32);
        self.push_line(row, line);
        Ok(())
    }

    /// [`CellTable::push_row`] of the first `ncols` fields of a CSV record (missing ones
    /// empty): the record's buffer is its cells one after the other, so a row of up to
    /// 255 bytes is copied at once with its ends.
    fn push_fields(
        &mut self,
        line: usize,
        fields: &CsvFields,
        ncols: usize,
    ) -> Result<(), (usize, String)> {
        let n = fields.len().min(ncols);
        let len = n.checked_sub(1).map_or(0, |last| fields.ends[last]);
        let (Ok(start), Ok(row)) = (
            u32::try_from(self.text.len()),
            u32::try_from(self.starts.len()),
        ) else {
            return self.push_row(line, (0..ncols).map(|i| fields.get(i)));
        };
        if len > NARROW_ROW_BYTES {
            return self.push_row(line, (0..ncols).map(|i| fields.get(i)));
        }
        self.text.push_str(&fields.buf[..len]);
        self.ends.extend(fields.ends[..n].iter().map(|&e| e as u8));
        self.ends.extend(std::iter::repeat_n(len as u8, ncols - n));
        self.starts.push(start);
        self.push_line(row, line);
        Ok(())
    }

    /// Notes that `row` is on `line` (a new run unless the last run goes on to it).
    fn push_line(&mut self, row: u32, line: usize) {
        let line = u32::try_from(line).unwrap_or(u32::MAX);
        if self
            .line_runs
            .last()
            .map(|&(r, l)| l.saturating_add(row - r))
            != Some(line)
        {
            self.line_runs.push((row, line));
        }
    }

    /// The line of `row` in the file.
    fn line(&self, row: usize) -> usize {
        let run = self.line_runs.partition_point(|&(r, _)| r as usize <= row);
        match run.checked_sub(1).and_then(|k| self.line_runs.get(k)) {
            Some(&(r, l)) => l.saturating_add((row - r as usize) as u32) as usize,
            None => 0,
        }
    }

    fn cell(&self, row: usize, col: usize) -> &str {
        let base = self.starts[row] as usize;
        let row_end = self
            .starts
            .get(row + 1)
            .map_or(self.text.len(), |&s| s as usize);
        let (start, end) = if row_end - base <= NARROW_ROW_BYTES {
            let k = row * self.ncols + col;
            let start = if col == 0 { 0 } else { self.ends[k - 1] };
            (usize::from(start), usize::from(self.ends[k]))
        } else {
            let w = self.wide_rows.partition_point(|&(r, _)| (r as usize) < row);
            let k = self.wide_rows[w].1 as usize + col;
            let start = if col == 0 { 0 } else { self.wide_ends[k - 1] };
            (usize::from(start), usize::from(self.wide_ends[k]))
        };
        &self.text[base + start..base + end]
    }

    fn shrink_to_fit(&mut self) {
        self.text.shrink_to_fit();
        self.starts.shrink_to_fit();
        self.ends.shrink_to_fit();
        self.wide_rows.shrink_to_fit();
        self.wide_ends.shrink_to_fit();
        self.line_runs.shrink_to_fit();
    }
}

/// Every variable of the table (hidden ones included), in table order, stored compactly:
/// the cells in one [`CellTable`] (the text of the row, 1 byte a cell, 4 a row) and a slot
/// for the decoded [`Variable`] (chunks of 64 slots made when one of them is first asked
/// for: [`Variables::get`], [`VarDatabase::find_public`], iteration). Scans over many
/// variables use [`Variables::view`], which decodes nothing it is not asked for.
#[derive(Debug, Clone, Default)]
pub struct Variables {
    cells: CellTable,
    name_col: usize,
    /// The alias column in alias mode, else `name_col`.
    public_col: usize,
    /// The column of each of [`columns::ALL`].
    known: Vec<Option<usize>>,
    /// A slot for each variable's decoded copy, in chunks of [`DECODED_CHUNK`] made when
    /// one of their variables is first decoded (no slot per variable until then).
    decoded: Vec<OnceLock<DecodedChunk>>,
}

/// The decoded slots of [`DECODED_CHUNK`] variables.
type DecodedChunk = Box<[OnceLock<Box<Variable>>]>;

/// Variables per chunk of [`Variables`]' decoded slots.
const DECODED_CHUNK: usize = 64;

impl PartialEq for Variables {
    fn eq(&self, other: &Self) -> bool {
        (&self.cells, self.name_col, self.public_col, &self.known)
            == (&other.cells, other.name_col, other.public_col, &other.known)
    }
}

impl Variables {
    pub fn len(&self) -> usize {
        self.cells.rows()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Variable `i`, decoded (and kept decoded).
    pub fn get(&self, i: usize) -> Option<&Variable> {
        (i < self.len()).then(|| self.decoded_at(i))
    }

    /// Variable `i` (`i < len()`), decoded (and kept decoded).
    fn decoded_at(&self, i: usize) -> &Variable {
        let chunk = self.decoded[i / DECODED_CHUNK]
            .get_or_init(|| (0..DECODED_CHUNK).map(|_| OnceLock::new()).collect());
        chunk[i % DECODED_CHUNK].get_or_init(|| Box::new(self.view(i).decode()))
    }

    pub fn first(&self) -> Option<&Variable> {
        self.get(0)
    }

    /// Every variable, decoded (see [`Variables::views`] for a scan that decodes nothing).
    pub fn iter(&self) -> impl ExactSizeIterator<Item = &Variable> + '_ {
        (0..self.len()).map(|i| self.decoded_at(i))
    }

    /// A view of variable `i` (`i < len()`), reading its cells in place.
    pub fn view(&self, i: usize) -> VarView<'_> {
        VarView { vars: self, i }
    }

    /// A view of every variable, in table order.
    pub fn views(&self) -> impl ExactSizeIterator<Item = VarView<'_>> + '_ {
        (0..self.len()).map(|i| self.view(i))
    }
}

impl<'a> IntoIterator for &'a Variables {
    type Item = &'a Variable;
    type IntoIter = Box<dyn Iterator<Item = &'a Variable> + 'a>;
    fn into_iter(self) -> Self::IntoIter {
        Box::new(self.iter())
    }
}

/// The position of a well-known column in [`columns::ALL`] (a match, not a search: every
/// attribute of every row is found through it at load).
fn known_index(name: &str) -> Option<usize> {
    use columns::*;
    Some(match name {
        NAME => 0,
        DESCRIPTION => 1,
        DESCRIPTION_EN => 2,
        UNIT => 3,
        RANGE_FROM => 4,
        RANGE_TO => 5,
        DATA_TYPE => 6,
        FORMAT => 7,
        WARN_LOW => 8,
        WARN_HIGH => 9,
        ALARM_LOW => 10,
        ALARM_HIGH => 11,
        CONTROL_VARIABLE => 12,
        BAR_BASE => 13,
        WRITABLE => 14,
        _ => return None,
    })
}

/// One variable read in place from the compact table: its cells and, on demand, each
/// decoded attribute. The decoders are the ones [`VarDatabase::build`] validated with, so
/// on a built database they do not fail.
#[derive(Debug, Clone, Copy)]
pub struct VarView<'a> {
    vars: &'a Variables,
    i: usize,
}

impl<'a> VarView<'a> {
    /// The index of the variable in [`VarDatabase::variables`].
    pub fn index(&self) -> usize {
        self.i
    }

    pub fn name(&self) -> &'a str {
        self.cell(self.vars.name_col)
    }

    /// The name clients use: the alias in alias mode, else the name; empty: hidden.
    pub fn public_name(&self) -> &'a str {
        self.cell(self.vars.public_col)
    }

    pub fn line(&self) -> usize {
        self.vars.cells.line(self.i)
    }

    /// The cell of column `col` (`""` past the last column).
    pub fn cell(&self, col: usize) -> &'a str {
        if col < self.vars.cells.ncols {
            self.vars.cells.cell(self.i, col)
        } else {
            ""
        }
    }

    /// Every cell, in column order.
    pub fn cells(&self) -> impl Iterator<Item = &'a str> + 'a {
        let v = *self;
        (0..self.vars.cells.ncols).map(move |c| v.cell(c))
    }

    /// The cell of a well-known column ([`columns`]); `""` when the table has none.
    pub fn known(&self, name: &str) -> &'a str {
        known_index(name)
            .and_then(|i| self.vars.known.get(i).copied().flatten())
            .map_or("", |c| self.cell(c))
    }

    fn number(&self, column: &str) -> Result<Option<f64>, String> {
        let t = self.known(column);
        if trim(t).is_empty() {
            return Ok(None);
        }
        parse_number(t)
            .map(Some)
            .ok_or_else(|| format!("{column} of {}: `{t}` is not a number", self.name()))
    }

    /// (RangeFrom, RangeTo) when both are set and differ.
    pub fn range(&self) -> Option<(f64, f64)> {
        match (
            self.number(columns::RANGE_FROM),
            self.number(columns::RANGE_TO),
        ) {
            (Ok(Some(a)), Ok(Some(b))) if a != b => Some((a, b)),
            _ => None,
        }
    }

    fn data_type_checked(&self) -> Result<VarType, String> {
        let dt = self.known(columns::DATA_TYPE);
        parse_data_type(dt).ok_or_else(|| {
            format!(
                "DataType of {}: `{dt}` is not R4, I2, UI2, I4, UI4 or UI1",
                self.name()
            )
        })
    }

    /// `DataType` (default R4).
    pub fn data_type(&self) -> VarType {
        self.data_type_checked().unwrap_or(VarType::R4)
    }

    /// `Format` as written (trimmed).
    pub fn format_text(&self) -> &'a str {
        trim(self.known(columns::FORMAT))
    }

    /// A limit column (`WarnLow` .. `AlarmHigh`).
    pub fn limit(&self, column: &str) -> Option<LimitRef<'a>> {
        let t = trim(self.known(column));
        if t.is_empty() {
            return None;
        }
        Some(match parse_number(t) {
            Some(v) => LimitRef::Value(v),
            None => LimitRef::Variable(t),
        })
    }

    /// `ControlVariable`.
    pub fn control_variable(&self) -> Option<&'a str> {
        let c = trim(self.known(columns::CONTROL_VARIABLE));
        (!c.is_empty()).then_some(c)
    }

    fn writable_checked(&self) -> Result<bool, String> {
        let w = self.known(columns::WRITABLE);
        if trim(w).is_empty() {
            return Ok(true);
        }
        parse_bool(w).ok_or_else(|| {
            format!(
                "Writable of {}: `{w}` is not tak/nie/true/false/1/0",
                self.name()
            )
        })
    }

    /// `Writable` (default tak).
    pub fn writable(&self) -> bool {
        self.writable_checked().unwrap_or(true)
    }

    /// The decoded copy of the variable.
    pub fn decode(&self) -> Variable {
        let limit = |c: &str| self.limit(c).map(LimitRef::to_limit);
        let format_text = self.format_text();
        Variable {
            name: self.name().to_owned(),
            public_name: self.public_name().to_owned(),
            line: self.line(),
            description: self.known(columns::DESCRIPTION).to_owned(),
            description_en: self.known(columns::DESCRIPTION_EN).to_owned(),
            unit: self.known(columns::UNIT).to_owned(),
            range: self.range(),
            data_type: self.data_type(),
            format_text: format_text.to_owned(),
            format: if format_text.is_empty() {
                None
            } else {
                FormatSpec::parse(format_text).ok()
            },
            warn_low: limit(columns::WARN_LOW),
            warn_high: limit(columns::WARN_HIGH),
            alarm_low: limit(columns::ALARM_LOW),
            alarm_high: limit(columns::ALARM_HIGH),
            control_variable: self.control_variable().map(str::to_owned),
            bar_base: self.number(columns::BAR_BASE).ok().flatten(),
            writable: self.writable(),
            cells: self.cells().map(str::to_owned).collect(),
        }
    }
}

/// An index from a name to the variable holding it in one column: a
/// `hashbrown::HashTable<u32>` of variable indexes (4 bytes and a control byte a bucket);
/// the names are compared in the [`CellTable`], so none is stored twice.
#[derive(Clone, Default)]
struct NameIndex {
    col: usize,
    table: HashTable<u32>,
}

/// A fast string hash (names come from the configuration, so no protection against
/// chosen collisions is needed): 8 bytes a step, multiply-rotate, folded so that
/// hashbrown's bucket (low bits) and tag (top bits) both vary.
pub fn hash_name(name: &str) -> u64 {
    const K: u64 = 0x9E37_79B9_7F4A_7C15;
    let bytes = name.as_bytes();
    let mut h = 0u64;
    let mut chunks = bytes.chunks_exact(8);
    for c in &mut chunks {
        let mut w = [0u8; 8];
        w.copy_from_slice(c);
        h = (h.rotate_left(5) ^ u64::from_le_bytes(w)).wrapping_mul(K);
    }
    let mut tail = 0u64;
    for (i, &b) in chunks.remainder().iter().enumerate() {
        tail |= u64::from(b) << (8 * i);
    }
    h = (h.rotate_left(5) ^ tail ^ (bytes.len() as u64) << 56).wrapping_mul(K);
    h ^ (h >> 32)
}

impl NameIndex {
    fn new(col: usize, capacity: usize) -> Self {
        NameIndex {
            col,
            table: HashTable::with_capacity(capacity),
        }
    }

    fn find(&self, cells: &CellTable, name: &str) -> Option<usize> {
        self.table
            .find(hash_name(name), |&i| {
                cells.cell(i as usize, self.col) == name
            })
            .map(|&i| i as usize)
    }

    /// Adds row `i` unless its name is already there; returns the row holding the name.
    fn insert(&mut self, cells: &CellTable, i: usize) -> usize {
        let name = cells.cell(i, self.col);
        let col = self.col;
        match self.table.entry(
            hash_name(name),
            |&j| cells.cell(j as usize, col) == name,
            |&j| hash_name(cells.cell(j as usize, col)),
        ) {
            hashbrown::hash_table::Entry::Occupied(e) => *e.get() as usize,
            hashbrown::hash_table::Entry::Vacant(e) => {
                e.insert(i as u32);
                i
            }
        }
    }

    fn len(&self) -> usize {
        self.table.len()
    }
}

impl fmt::Debug for NameIndex {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "NameIndex(column {}, {} names)",
            self.col,
            self.table.len()
        )
    }
}

/// The index is a function of the table, so two indexes of equal tables are equal.
impl PartialEq for NameIndex {
    fn eq(&self, other: &Self) -> bool {
        (self.col, self.table.len()) == (other.col, other.table.len())
    }
}

/// A loaded, validated variable database, with aliases applied.
///
/// Layout: one [`CellTable`] holds every cell as text with a `u8` end per
/// cell (rows of up to 255 bytes) and a `u32` start per row; the name index (`Name`; the
/// public name's is another in alias mode only) is a hash table of `u32` row indexes that
/// compare names in that table; the tree holds `u32` indexes. For a row of 17 cells of
/// about 90 bytes that is about 90 + 17 (cell ends) + 4 (row start) + ~10 (index at a
/// million) + 4 (tree) ≈ 125 bytes per variable until a variable is decoded (its
/// [`Variable`] copy, about 1 KB, is kept once made).
#[derive(Debug, Clone, PartialEq)]
pub struct VarDatabase {
    pub title: Option<String>,
    pub columns: Vec<String>,
    /// Every variable of the table (hidden ones included), in table order.
    pub variables: Variables,
    /// The browse tree (only visible variables).
    pub root: GroupNode,
    pub alias_column: Option<String>,
    /// The public-name index in alias mode; without aliases the public names are the
    /// names, and `by_name` serves both.
    by_public: Option<NameIndex>,
    by_name: NameIndex,
}

/// Whether `name` holds a control character (bytes for ASCII, the usual name).
fn has_control(name: &str) -> bool {
    if name.is_ascii() {
        name.bytes().any(|b| b.is_ascii_control())
    } else {
        name.chars().any(char::is_control)
    }
}

fn check_name(kind: &str, name: &str) -> Result<(), String> {
    if name.starts_with('.') || name.ends_with('.') || name.contains("..") {
        return Err(format!(
            "{kind} `{name}` may not start or end with `.` or contain `..`"
        ));
    }
    if has_control(name) || trim(name) != name {
        return Err(format!(
            "{kind} `{name}` has control characters or surrounding blanks"
        ));
    }
    Ok(())
}

fn parse_data_type(text: &str) -> Option<VarType> {
    let t = trim(text);
    if t.is_empty() {
        return Some(VarType::R4);
    }
    super::itemid::AsmenType::parse(t).map(|t| t.var_type())
}

impl VarDatabase {
    /// Builds the database from its parts. `alias` is the channel's `AliasAttributeName`:
    /// a column whose non-empty cells replace the names; variables with an empty alias are
    /// hidden. Without a variable set, every visible variable is a leaf of the root.
    pub fn build(
        table: &AttributeTable,
        set: Option<&VarSetFile>,
        alias: Option<&str>,
    ) -> Result<(VarDatabase, Vec<Warning>), DbError> {
        let mut cells = CellTable {
            ncols: table.columns.len(),
            ..CellTable::default()
        };
        for (line, row) in &table.rows {
            cells
                .push_row(*line, row.iter().map(String::as_str))
                .map_err(|(line, m)| DbError::invalid(&table.file, line, m))?;
        }
        Self::build_cells(
            &table.file,
            table.columns.clone(),
            cells,
            set.map(|s| (s, None)),
            alias,
        )
    }

    /// `set`: the variable set, with the text to stream its groups from when they were
    /// not parsed into it.
    fn build_cells(
        file: &str,
        table_columns: Vec<String>,
        mut cells: CellTable,
        set: Option<(&VarSetFile, Option<&str>)>,
        alias: Option<&str>,
    ) -> Result<(VarDatabase, Vec<Warning>), DbError> {
        let mut warnings = Vec::new();
        let col = |name: &str| {
            table_columns
                .iter()
                .position(|c| c.eq_ignore_ascii_case(name))
        };
        let name_col =
            col(columns::NAME).ok_or_else(|| DbError::invalid(file, 0, "no `Name` column"))?;
        let alias_col = match alias {
            None => None,
            Some(a) => Some(
                table_columns
                    .iter()
                    .position(|c| c == a)
                    .or_else(|| col(a))
                    .ok_or_else(|| {
                        DbError::invalid(
                            file,
                            1,
                            format!("AliasAttributeName `{a}` is not a column of the table"),
                        )
                    })?,
            ),
        };
        cells.shrink_to_fit();
        let n = cells.rows();
        let variables = Variables {
            cells,
            name_col,
            public_col: alias_col.unwrap_or(name_col),
            known: columns::ALL.iter().map(|c| col(c)).collect(),
            decoded: (0..n.div_ceil(DECODED_CHUNK))
                .map(|_| OnceLock::new())
                .collect(),
        };
        let cells = &variables.cells;
        // Every name first (limits and control variables may name later rows); the row a
        // name maps to is its first.
        let mut by_name = NameIndex::new(name_col, n);
        // The rows whose name an earlier row has (an error, reported in row order below).
        let mut repeated: Vec<u32> = Vec::new();
        for i in 0..n {
            if by_name.insert(cells, i) != i {
                repeated.push(i as u32);
            }
        }
        // The last control variable looked up, and whether the table has it (a run of
        // rows usually names the same one).
        let mut last_control: Option<(&str, bool)> = None;
        // Only in alias mode: else every public name is the (unique, non-empty) name.
        let mut by_public = alias_col.map(|col| NameIndex::new(col, n));
        for v in variables.views() {
            let line = v.line();
            let err = |m: String| DbError::invalid(file, line, m);
            let name = v.name();
            if name.is_empty() {
                return Err(err("a variable without a name".into()));
            }
            check_name("variable name", name).map_err(err)?;
            let from = v.number(columns::RANGE_FROM).map_err(err)?;
            let to = v.number(columns::RANGE_TO).map_err(err)?;
            match (from, to) {
                (Some(a), Some(b)) if a != b => {}
                (None, None) => {}
                _ => warnings.push(Warning::new(
                    file,
                    line,
                    format!("{name}: incomplete or empty range ignored"),
                )),
            }
            v.data_type_checked().map_err(err)?;
            let format_text = v.format_text();
            if !format_text.is_empty() {
                if let Err(m) = FormatSpec::parse(format_text) {
                    warnings.push(Warning::new(
                        file,
                        line,
                        format!("{name}: Format {m}; the default form is used"),
                    ));
                }
            }
            for column in [
                columns::WARN_LOW,
                columns::WARN_HIGH,
                columns::ALARM_LOW,
                columns::ALARM_HIGH,
            ] {
                if let Some(LimitRef::Variable(t)) = v.limit(column) {
                    if by_name.find(cells, t).is_none() {
                        warnings.push(Warning::new(
                            file,
                            line,
                            format!("{name}: {column} names unknown variable `{t}`"),
                        ));
                    }
                }
            }
            if let Some(control) = v.control_variable() {
                let known = match last_control {
                    Some((c, known)) if c == control => known,
                    _ => by_name.find(cells, control).is_some(),
                };
                last_control = Some((control, known));
                if !known {
                    warnings.push(Warning::new(
                        file,
                        line,
                        format!("{name}: ControlVariable `{control}` is not in the table"),
                    ));
                }
            }
            v.writable_checked().map_err(err)?;
            v.number(columns::BAR_BASE).map_err(err)?;
            let index = v.index();
            if repeated.binary_search(&(index as u32)).is_ok() {
                return Err(err(format!("variable `{name}` is defined twice")));
            }
            let public_name = v.public_name();
            // Without aliases the public name is the name, checked and indexed above.
            if let (false, Some(by_public)) = (public_name.is_empty(), by_public.as_mut()) {
                check_name("alias", public_name).map_err(err)?;
                if by_public.insert(cells, index) != index {
                    return Err(err(format!(
                        "alias `{public_name}` of {name} is used twice"
                    )));
                }
            }
        }
        let mut root = GroupNode::default();
        let visible = |i: usize| !variables.view(i).public_name().is_empty();
        // The group being filled: child positions from the root.
        let mut current: Vec<usize> = Vec::new();
        let mut enter = |root: &mut GroupNode, path: &mut dyn Iterator<Item = &str>| {
            current.clear();
            let mut node = root;
            for segment in path {
                let pos = node.child_pos(segment);
                current.push(pos);
                node = &mut node.groups[pos];
            }
            current.clone()
        };
        let add = |root: &mut GroupNode,
                   at: &[usize],
                   warnings: &mut Vec<Warning>,
                   set_file: &str,
                   var: &str,
                   line: usize| {
            let mut node = root;
            for &pos in at {
                node = &mut node.groups[pos];
            }
            match by_name.find(cells, var) {
                None => warnings.push(Warning::new(
                    set_file,
                    line,
                    format!("variable `{var}` is not in the attribute table; skipped"),
                )),
                Some(i) if !visible(i) => {}
                Some(i) if node.variables.contains(&(i as u32)) => warnings.push(Warning::new(
                    set_file,
                    line,
                    format!("variable `{var}` listed twice in the group; skipped"),
                )),
                Some(i) => node.variables.push(i as u32),
            }
        };
        match set {
            None => {
                root.variables = (0..n).filter(|&i| visible(i)).map(|i| i as u32).collect();
            }
            Some((set, None)) => {
                for group in &set.groups {
                    let at = enter(&mut root, &mut group.path.iter().map(String::as_str));
                    for (var, line) in &group.variables {
                        add(&mut root, &at, &mut warnings, &set.file, var, *line);
                    }
                }
            }
            Some((set, Some(text))) => {
                // The groups streamed from the set's text (its settings were read already).
                let mut at = Vec::new();
                for_each_var_set_line(text, &set.file, |line, l| {
                    match l {
                        SetLine::Group(path) => at = enter(&mut root, &mut path.into_iter()),
                        SetLine::Variable(var) => {
                            add(&mut root, &at, &mut warnings, &set.file, var, line)
                        }
                        SetLine::Setting(..) => {}
                    }
                    true
                })?;
            }
        }
        let db = VarDatabase {
            title: set.and_then(|s| s.0.title.clone()),
            alias_column: alias_col.map(|i| table_columns[i].clone()),
            columns: table_columns,
            variables,
            root,
            by_public,
            by_name,
        };
        Ok((db, warnings))
    }

    /// The visible variable a client names (alias in alias mode).
    pub fn find_public(&self, name: &str) -> Option<&Variable> {
        self.find_public_index(name)
            .and_then(|i| self.variables.get(i))
    }

    /// The index of the visible variable a client names, decoding nothing.
    pub fn find_public_index(&self, name: &str) -> Option<usize> {
        self.public_index().find(&self.variables.cells, name)
    }

    /// The variable with this asix name (visible or not).
    pub fn find_real(&self, name: &str) -> Option<&Variable> {
        self.find_real_index(name)
            .and_then(|i| self.variables.get(i))
    }

    /// The index of the variable with this asix name, decoding nothing.
    pub fn find_real_index(&self, name: &str) -> Option<usize> {
        self.by_name.find(&self.variables.cells, name)
    }

    /// The index of a column, by its exact (case-sensitive) spelling.
    pub fn column(&self, attribute: &str) -> Option<usize> {
        self.columns.iter().position(|c| c == attribute)
    }

    /// The cell of attribute `attribute` (a column name, case-sensitive) of `var`.
    pub fn attribute<'a>(&self, var: &'a Variable, attribute: &str) -> Option<&'a str> {
        self.column(attribute).map(|i| var.cells[i].as_str())
    }

    /// The number of visible variables.
    pub fn visible_count(&self) -> usize {
        self.public_index().len()
    }

    fn public_index(&self) -> &NameIndex {
        self.by_public.as_ref().unwrap_or(&self.by_name)
    }

    /// All attributes of a variable as (column, cell) pairs.
    pub fn attributes<'a>(
        &'a self,
        var: &'a Variable,
    ) -> impl Iterator<Item = (&'a str, &'a str)> + 'a {
        self.columns
            .iter()
            .map(String::as_str)
            .zip(var.cells.iter().map(String::as_str))
    }

    /// Variable counts per data type (a summary for logs).
    pub fn type_summary(&self) -> BTreeMap<u16, usize> {
        let mut m = BTreeMap::new();
        for v in self.variables.views() {
            *m.entry(v.data_type().0).or_insert(0) += 1;
        }
        m
    }
}

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

#[cfg(test)]
/// A char-by-char reader, the plain reference that [`for_each_csv_record`]'s tests
/// compare the byte reader with.
///
/// [`parse_csv`] streaming: calls `record(line, fields)` for each record as it is read,
/// with one reused buffer; an error of `record` stops the reading and is returned.
pub(crate) fn for_each_csv_record_chars(
    text: &str,
    sep: char,
    mut record: impl FnMut(usize, &CsvFields) -> Result<(), (usize, String)>,
) -> Result<(), (usize, String)> {
    let mut fields = CsvFields::default();
    let mut line = 1usize;
    let mut record_line = 1usize;
    let mut chars = text.chars().peekable();
    // State of the current field: was it quoted, and is the quote closed.
    let mut quoted = false;
    let mut in_quotes = false;
    let mut quote_line = 0usize;
    let mut after_quote = false;
    let mut end_record =
        |fields: &mut CsvFields, quoted: bool, record_line: usize| -> Result<(), (usize, String)> {
            fields.end_field(quoted);
            let r = if !(fields.len() == 1 && fields.get(0).is_empty() && !quoted) {
                record(record_line, fields)
            } else {
                Ok(())
            };
            fields.clear();
            r
        };
    while let Some(c) = chars.next() {
        if in_quotes {
            match c {
                '"' if chars.peek() == Some(&'"') => {
                    chars.next();
                    fields.buf.push('"');
                }
                '"' => {
                    in_quotes = false;
                    after_quote = true;
                }
                '\r' => {
                    if chars.peek() == Some(&'\n') {
                        chars.next();
                    }
                    line += 1;
                    fields.buf.push('\n');
                }
                '\n' => {
                    line += 1;
                    fields.buf.push('\n');
                }
                _ => fields.buf.push(c),
            }
            continue;
        }
        if c == sep {
            fields.end_field(quoted);
            quoted = false;
            after_quote = false;
            continue;
        }
        match c {
            '\r' | '\n' => {
                if c == '\r' && chars.peek() == Some(&'\n') {
                    chars.next();
                }
                end_record(&mut fields, quoted, record_line)?;
                quoted = false;
                after_quote = false;
                line += 1;
                record_line = line;
            }
            _ if after_quote => {
                if !c.is_whitespace() {
                    return Err((line, format!("text `{c}` after a closing quote")));
                }
            }
            '"' if fields.buf[fields.start()..].trim().is_empty() => {
                let start = fields.start();
                fields.buf.truncate(start);
                quoted = true;
                in_quotes = true;
                quote_line = line;
            }
            _ => fields.buf.push(c),
        }
    }
    if in_quotes {
        return Err((quote_line, "quoted field is not closed".into()));
    }
    if !fields.is_empty() || fields.buf.len() > fields.start() || quoted {
        end_record(&mut fields, quoted, record_line)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn a_row_of_more_than_64_kb_of_text_is_refused_with_its_line() {
        let mut t = CellTable {
            ncols: 2,
            ..CellTable::default()
        };
        t.push_row(2, ["A", "bb"].into_iter()).unwrap();
        let long = "x".repeat(MAX_ROW_BYTES);
        let e = t.push_row(3, ["y", long.as_str()].into_iter()).unwrap_err();
        assert_eq!(e.0, 3);
        assert!(e.1.contains("65535 bytes"), "{e:?}");
        // The refused row left nothing behind; the next one is whole.
        t.push_row(4, ["", long.as_str()].into_iter()).unwrap();
        assert_eq!(t.rows(), 2);
        assert_eq!((t.cell(0, 0), t.cell(0, 1)), ("A", "bb"));
        assert_eq!((t.cell(1, 0), t.cell(1, 1).len()), ("", MAX_ROW_BYTES));
    }

    #[test]
    fn csv_quoting_separators_and_lines() {
        let text = "Name;Description;Unit\r\nA;\"Opis; z \"\"cudzysłowem\"\"\";m\n\nB;\"dwie\nlinie\";  °C  \nC\n";
        assert_eq!(detect_separator(text), ';');
        let r = parse_csv(text, ';').unwrap();
        assert_eq!(r.len(), 4);
        assert_eq!(r[1].fields, vec!["A", "Opis; z \"cudzysłowem\"", "m"]);
        assert_eq!(
            (r[2].line, r[2].fields.clone()),
            (4, vec!["B".into(), "dwie\nlinie".into(), "°C".into()])
        );
        assert_eq!(r[3].line, 6);
        assert_eq!(detect_separator("Name,Unit,\"a;b;c\"\n"), ',');
        assert_eq!(detect_separator("Name\tUnit\n"), '\t');
        assert_eq!(detect_separator("Name\n"), ';');
        assert_eq!(parse_csv("a;\"b\" x\n", ';').unwrap_err().0, 1);
        assert_eq!(parse_csv("a\nb;\"open\n\n", ';').unwrap_err().0, 2);
        assert_eq!(parse_csv("a;\"\"\n", ';').unwrap()[0].fields, vec!["a", ""]);
        assert_eq!(
            parse_csv("x;\"q\" ;y", ';').unwrap()[0].fields,
            vec!["x", "q", "y"]
        );
    }

    fn table(text: &str) -> Result<AttributeTable, DbError> {
        parse_attribute_table(text.as_bytes(), "t.csv")
    }

    #[test]
    fn attribute_table_errors_name_the_line() {
        let rows: &[(&str, usize, &str)] = &[
            ("", 0, "empty"),
            ("Description;Unit\nx;y\n", 1, "no `Name`"),
            ("Name;;Unit\n", 1, "no name"),
            ("Name;Unit;unit\n", 1, "repeats"),
            ("Name;A.B\n", 1, "may not contain"),
            ("Name;Unit\nA;m\nB;m;x\n", 3, "3 cells"),
            ("Name;Unit\nA;\"m\n", 2, "not closed"),
        ];
        for (text, line, msg) in rows {
            let e = table(text).unwrap_err();
            assert_eq!(e.code, OpcError::ErrorDuringOpeningVarBase);
            assert_eq!(e.line, *line, "{text:?}: {e}");
            assert!(e.message.contains(msg), "{text:?}: {e}");
        }
        // Short rows are padded; empty trailing cells dropped.
        let t = table("Name;Unit;\nA\nB;m;;\n").unwrap();
        assert_eq!(t.columns, vec!["Name", "Unit"]);
        assert_eq!(t.rows[0].1, vec!["A", ""]);
        assert_eq!(t.rows[1].1, vec!["B", "m"]);
    }

    #[test]
    fn well_known_columns_are_found_at_their_place() {
        for (i, c) in columns::ALL.iter().enumerate() {
            assert_eq!(known_index(c), Some(i), "{c}");
        }
        assert_eq!(known_index("Alias"), None);
        assert_eq!(known_index("name"), None, "as before: exact names");
    }

    #[test]
    fn build_errors_and_warnings() {
        let err_rows: &[(&str, usize, &str)] = &[
            ("Name;RangeFrom\nA;abc\n", 2, "not a number"),
            ("Name;DataType\nA;R8\n", 2, "DataType"),
            ("Name;Writable\nA;maybe\n", 2, "Writable"),
            ("Name\nA\nB\nA\n", 4, "twice"),
            ("Name\n\"\"\n", 2, "without a name"),
            ("Name\nA..B\n", 2, "`..`"),
            ("Name\n.A\n", 2, "`.`"),
        ];
        for (text, line, msg) in err_rows {
            let e = VarDatabase::build(&table(text).unwrap(), None, None).unwrap_err();
            assert_eq!(
                (e.line, e.code),
                (*line, OpcError::ErrorDuringOpeningVarBase),
                "{text:?}: {e}"
            );
            assert!(e.message.contains(msg), "{text:?}: {e}");
        }
        let text =
            "Name;RangeFrom;RangeTo;Format;WarnHigh;ControlVariable\nA;0;;%q;B;Z\nB;5;5;%d;;\n";
        let (db, w) = VarDatabase::build(&table(text).unwrap(), None, None).unwrap();
        let lines: Vec<usize> = w.iter().map(|w| w.line).collect();
        assert_eq!(lines, vec![2, 2, 2, 3], "{w:?}");
        let a = db.find_public("A").unwrap();
        assert_eq!(a.range, None);
        assert_eq!(a.format, None);
        assert_eq!(a.format_text, "%q");
        assert_eq!(a.warn_high, Some(Limit::Variable("B".into())));
        assert_eq!(a.control_variable.as_deref(), Some("Z"));
        assert_eq!(a.data_type, VarType::R4);
        assert!(a.writable);
        // A run of rows naming the same control variable: each is warned of, or none.
        let text = "Name;ControlVariable\nA;Z\nB;Z\nC;A\nD;A\nE;Z\n";
        let (_, w) = VarDatabase::build(&table(text).unwrap(), None, None).unwrap();
        let lines: Vec<usize> = w.iter().map(|w| w.line).collect();
        assert_eq!(lines, vec![2, 3, 6], "{w:?}");
        let e = VarDatabase::build(&table("Name;Alias\nA;x\n").unwrap(), None, Some("Alias2"))
            .unwrap_err();
        assert!(e.message.contains("AliasAttributeName"));
    }

    #[test]
    fn aliases_replace_names_and_hide_empty_ones() {
        let text = "Name;Alias;Unit\nKW_A000;LI101;m\nKW_A001;;m\nKW_A002;TI.102;°C\n";
        let t = table(text).unwrap();
        let (db, _) = VarDatabase::build(&t, None, Some("alias")).unwrap();
        assert_eq!(db.alias_column.as_deref(), Some("Alias"));
        assert_eq!(db.find_public("LI101").unwrap().name, "KW_A000");
        assert!(db.find_public("KW_A000").is_none());
        assert!(db.find_public("KW_A001").is_none());
        assert_eq!(db.find_real("KW_A001").unwrap().public_name, "");
        assert_eq!(db.visible_count(), 2);
        assert_eq!(db.root.variables, vec![0, 2]);
        let e = VarDatabase::build(
            &table("Name;Alias\nA;x\nB;x\n").unwrap(),
            None,
            Some("Alias"),
        )
        .unwrap_err();
        assert_eq!(e.line, 3);
    }

    #[test]
    fn var_set_tree() {
        let text = "\
; Zestaw
Title = Wytwórnia
Attributes = atrybuty.csv
Foo = 1
[Magazyn/Zbiornik Z101]
A
B
[/]
C
[Magazyn]
D
[ Magazyn / Zbiornik Z101 ]
A
X
";
        let (set, w) = parse_var_set(text.as_bytes(), "s.zez").unwrap();
        assert_eq!(w.len(), 1);
        assert_eq!(w[0].line, 4);
        assert_eq!(set.attributes.as_deref(), Some("atrybuty.csv"));
        assert_eq!(set.title.as_deref(), Some("Wytwórnia"));
        assert_eq!(set.groups.len(), 4);
        assert_eq!(set.groups[0].path, vec!["Magazyn", "Zbiornik Z101"]);
        assert!(set.groups[1].path.is_empty());
        let t = table("Name\nA\nB\nC\nD\n").unwrap();
        let (db, w) = VarDatabase::build(&t, Some(&set), None).unwrap();
        let msgs: Vec<(usize, bool)> = w.iter().map(|w| (w.line, w.file == "s.zez")).collect();
        assert_eq!(msgs, vec![(13, true), (14, true)], "{w:?}");
        assert_eq!(db.root.variables, vec![2]);
        assert_eq!(db.root.groups.len(), 1);
        let magazyn = &db.root.groups[0];
        assert_eq!(magazyn.variables, vec![3]);
        assert_eq!(magazyn.groups[0].name, "Zbiornik Z101");
        assert_eq!(magazyn.groups[0].variables, vec![0, 1]);
        for (text, line) in [("A\n", 1), ("[a/\n", 1), ("[x]\n[a//b]\n", 2)] {
            assert_eq!(
                parse_var_set(text.as_bytes(), "s.zez").unwrap_err().line,
                line,
                "{text}"
            );
        }
    }

    #[test]
    fn missing_files_are_var_base_not_found() {
        let e = load_database_file(Path::new("/nonexistent/baza.zez"), None).unwrap_err();
        assert_eq!(e.code, OpcError::VarBaseNotFound);
        assert!(e.to_string().contains("/nonexistent/baza.zez"));
        let e = load_database_file(Path::new("/nonexistent/baza.csv"), None).unwrap_err();
        assert_eq!(e.code, OpcError::VarBaseNotFound);
    }

    proptest! {
        #[test]
        fn readers_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..512)) {
            if let Ok(t) = parse_attribute_table(&bytes, "f.csv") {
                let _ = VarDatabase::build(&t, None, None);
                let _ = VarDatabase::build(&t, None, Some("Alias"));
            }
            let _ = parse_var_set(&bytes, "f.zez");
        }

        #[test]
        fn csv_like_text_never_panics(text in "([;,\t\"\r\n ]|[A-Za-z0-9%.]){0,200}") {
            if let Ok(t) = parse_attribute_table(text.as_bytes(), "f.csv") {
                if let Ok((_, _)) = VarDatabase::build(&t, None, None) {}
            }
            let head = format!("Name;RangeFrom;RangeTo;Format;WarnLow;Writable;DataType;Alias\n{text}");
            if let Ok(t) = parse_attribute_table(head.as_bytes(), "f.csv") {
                let _ = VarDatabase::build(&t, None, Some("Alias"));
            }
            let _ = parse_var_set(text.as_bytes(), "f.zez");
        }

        /// The compact table holds every cell and line as the table of strings does: rows
        /// short and long (one-byte ends and two-byte ends), blank lines and line breaks in
        /// quoted cells between them.
        #[test]
        fn the_cell_table_holds_what_the_csv_says(
            rows in proptest::collection::vec(
                (proptest::collection::vec(0usize..200, 3), 0usize..3, any::<bool>(), 0usize..3),
                0..12,
            ),
        ) {
            let mut csv = String::from("Name;Description;Unit\n");
            for (r, (lens, blanks, multiline, tail)) in rows.iter().enumerate() {
                let desc = "ż".repeat(lens[1]);
                let unit = "u".repeat(lens[2]);
                let desc = if *multiline { format!("\"{desc}\nnext\"") } else { desc };
                let name = format!("N{r}_{}", "n".repeat(lens[0]));
                // Every cell, the last missing, or empty cells past the header's.
                csv.push_str(&match tail {
                    0 => format!("{name};{desc};{unit}\n"),
                    1 => format!("{name};{desc}\n"),
                    _ => format!("{name};{desc};{unit};;\n"),
                });
                csv.push_str(&"\n".repeat(*blanks));
            }
            let table = parse_attribute_table(csv.as_bytes(), "t.csv").unwrap();
            let (columns, cells) = read_cell_table(csv.as_bytes(), "t.csv").unwrap();
            prop_assert_eq!(&columns, &table.columns);
            prop_assert_eq!(cells.rows(), table.rows.len());
            for (r, (line, row)) in table.rows.iter().enumerate() {
                prop_assert_eq!(cells.line(r), *line);
                for (c, cell) in row.iter().enumerate() {
                    prop_assert_eq!(cells.cell(r, c), cell.as_str());
                }
            }
            let long = table
                .rows
                .iter()
                .filter(|(_, row)| row.iter().map(String::len).sum::<usize>() > NARROW_ROW_BYTES)
                .count();
            prop_assert_eq!(cells.wide_rows.len(), long);
        }

        /// The fast `trim` and control check agree with `str::trim` and `char::is_control`.
        #[test]
        fn fast_trim_and_control_check_are_the_std_ones(
            s in "([ \t\u{b}\u{1f}\u{7f}\u{85}\u{a0}\u{3000}]|[A-Za-z0-9]|ż){0,12}",
        ) {
            prop_assert_eq!(trim(&s), s.trim());
            prop_assert_eq!(has_control(&s), s.chars().any(char::is_control));
        }

        /// The byte reader reads every text as the char-by-char reference does: the same
        /// records, lines and errors (separators of one and more bytes, quotes, line
        /// breaks, blanks ASCII and not, non-ASCII text).
        #[test]
        fn the_byte_csv_reader_is_the_char_reader(
            text in "([;,\t\"\r\n \u{b}\u{a0}\u{3000}§]|[A-Za-z0-9%.]|ż){0,200}",
            sep in prop::sample::select(vec![';', ',', '\t', '§', 'ż']),
        ) {
            let read = |chars: bool| {
                let mut out = Vec::new();
                let push = |line: usize, f: &CsvFields| {
                    out.push((line, f.iter().map(str::to_owned).collect::<Vec<_>>()));
                    Ok(())
                };
                let r = if chars {
                    super::for_each_csv_record_chars(&text, sep, push)
                } else {
                    for_each_csv_record(&text, sep, push)
                };
                (r, out)
            };
            prop_assert_eq!(read(false), read(true));
        }
    }
}
