//! The variable database: the attribute table (CSV) and the variable set (the browse
//! tree, a `.zez` text file). The format is specified for users in
//! `docs/variable-database.md`; this module is its reference implementation.
//!
//! All logic is in the pure `parse_*` functions and [`VarDatabase::build`];
//! [`load_database_file`] only reads the files.

use std::collections::{BTreeMap, HashMap};
use std::fmt;
use std::path::Path;

use super::format::FormatSpec;
use super::text::{decode_text, parse_bool, parse_number, Warning};
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

/// Splits CSV text into records (RFC 4180 quoting: `"a ""b"""`, quoted fields may hold
/// separators and line breaks). Unquoted fields are trimmed; blank lines are skipped.
/// Errors: `(line, message)` for text after a closing quote or an unterminated quote.
pub fn parse_csv(text: &str, sep: char) -> Result<Vec<CsvRecord>, (usize, String)> {
    let mut records = Vec::new();
    let mut fields: Vec<String> = Vec::new();
    let mut field = String::new();
    let mut line = 1usize;
    let mut record_line = 1usize;
    let mut chars = text.chars().peekable();
    // State of the current field: was it quoted, and is the quote closed.
    let mut quoted = false;
    let mut in_quotes = false;
    let mut quote_line = 0usize;
    let mut after_quote = false;
    let mut end_record =
        |fields: &mut Vec<String>, field: &mut String, quoted: bool, record_line: usize| {
            fields.push(if quoted {
                std::mem::take(field)
            } else {
                std::mem::take(field).trim().to_owned()
            });
            let f = std::mem::take(fields);
            if !(f.len() == 1 && f[0].is_empty() && !quoted) {
                records.push(CsvRecord {
                    line: record_line,
                    fields: f,
                });
            }
        };
    while let Some(c) = chars.next() {
        if in_quotes {
            match c {
                '"' if chars.peek() == Some(&'"') => {
                    chars.next();
                    field.push('"');
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
                    field.push('\n');
                }
                '\n' => {
                    line += 1;
                    field.push('\n');
                }
                _ => field.push(c),
            }
            continue;
        }
        if c == sep {
            fields.push(if quoted {
                std::mem::take(&mut field)
            } else {
                std::mem::take(&mut field).trim().to_owned()
            });
            quoted = false;
            after_quote = false;
            continue;
        }
        match c {
            '\r' | '\n' => {
                if c == '\r' && chars.peek() == Some(&'\n') {
                    chars.next();
                }
                end_record(&mut fields, &mut field, quoted, record_line);
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
            '"' if field.trim().is_empty() => {
                field.clear();
                quoted = true;
                in_quotes = true;
                quote_line = line;
            }
            _ => field.push(c),
        }
    }
    if in_quotes {
        return Err((quote_line, "quoted field is not closed".into()));
    }
    if !fields.is_empty() || !field.is_empty() || quoted {
        end_record(&mut fields, &mut field, quoted, record_line);
    }
    Ok(records)
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
    let (text, _) = decode_text(bytes);
    let sep = detect_separator(&text);
    let records = parse_csv(&text, sep).map_err(|(line, m)| DbError::invalid(file, line, m))?;
    let mut records = records.into_iter();
    let header = records
        .next()
        .ok_or_else(|| DbError::invalid(file, 0, "the attribute table is empty (no header row)"))?;
    let mut columns: Vec<String> = header.fields;
    // Trailing empty header cells (a spreadsheet's trailing separators) are dropped.
    while columns.last().is_some_and(|c| c.is_empty()) && columns.len() > 1 {
        columns.pop();
    }
    for (i, c) in columns.iter().enumerate() {
        if c.is_empty() {
            return Err(DbError::invalid(
                file,
                header.line,
                format!("column {} has no name", i + 1),
            ));
        }
        if c.contains('.') || c.chars().any(char::is_control) {
            return Err(DbError::invalid(
                file,
                header.line,
                format!("column name `{c}` may not contain `.`"),
            ));
        }
        if let Some(prev) = columns[..i].iter().find(|p| p.eq_ignore_ascii_case(c)) {
            return Err(DbError::invalid(
                file,
                header.line,
                format!("column `{c}` repeats column `{prev}`"),
            ));
        }
    }
    if !columns
        .iter()
        .any(|c| c.eq_ignore_ascii_case(columns::NAME))
    {
        return Err(DbError::invalid(
            file,
            header.line,
            "the header has no `Name` column",
        ));
    }
    let mut rows = Vec::new();
    for mut r in records {
        if r.fields.len() > columns.len() {
            if r.fields[columns.len()..].iter().any(|f| !f.is_empty()) {
                return Err(DbError::invalid(
                    file,
                    r.line,
                    format!(
                        "{} cells, but the header has {} columns",
                        r.fields.len(),
                        columns.len()
                    ),
                ));
            }
            r.fields.truncate(columns.len());
        }
        r.fields.resize(columns.len(), String::new());
        rows.push((r.line, r.fields));
    }
    Ok(AttributeTable {
        file: file.to_owned(),
        columns,
        rows,
    })
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
    for (index, raw) in text.lines().enumerate() {
        let line = index + 1;
        let t = raw.trim();
        if t.is_empty() || t.starts_with(';') || t.starts_with('#') {
            continue;
        }
        if let Some(rest) = t.strip_prefix('[') {
            let inner = rest
                .strip_suffix(']')
                .ok_or_else(|| {
                    DbError::invalid(file, line, format!("group header `{t}` has no closing `]`"))
                })?
                .trim();
            let path: Vec<String> = if inner.is_empty() || inner == "/" {
                Vec::new()
            } else {
                let segments: Vec<String> = inner.split('/').map(|s| s.trim().to_owned()).collect();
                if segments.iter().any(String::is_empty) {
                    return Err(DbError::invalid(
                        file,
                        line,
                        format!("group path `{inner}` has an empty segment"),
                    ));
                }
                segments
            };
            set.groups.push(VarSetGroup {
                path,
                line,
                variables: Vec::new(),
            });
            continue;
        }
        match set.groups.last_mut() {
            Some(group) => {
                if t.chars().any(char::is_control) {
                    return Err(DbError::invalid(
                        file,
                        line,
                        "variable name with a control character",
                    ));
                }
                group.variables.push((t.to_owned(), line));
            }
            None => {
                let Some((key, value)) = t.split_once('=') else {
                    return Err(DbError::invalid(
                        file,
                        line,
                        format!(
                            "`{t}` is before the first group header (use [/] for the root group)"
                        ),
                    ));
                };
                let value = value.trim();
                let value = (!value.is_empty()).then(|| value.to_owned());
                match key.trim().to_ascii_lowercase().as_str() {
                    "attributes" => set.attributes = value,
                    "title" => set.title = value,
                    other => warnings.push(Warning::new(
                        file,
                        line,
                        format!("unknown setting `{other}` ignored"),
                    )),
                }
            }
        }
    }
    Ok((set, warnings))
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

/// One variable with its well-known attributes decoded.
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
    pub variables: Vec<usize>,
}

impl GroupNode {
    fn child(&mut self, name: &str) -> &mut GroupNode {
        let pos = match self.groups.iter().position(|g| g.name == name) {
            Some(p) => p,
            None => {
                self.groups.push(GroupNode {
                    name: name.to_owned(),
                    ..GroupNode::default()
                });
                self.groups.len() - 1
            }
        };
        &mut self.groups[pos]
    }
}

/// A loaded, validated variable database, with aliases applied.
#[derive(Debug, Clone, PartialEq)]
pub struct VarDatabase {
    pub title: Option<String>,
    pub columns: Vec<String>,
    /// Every variable of the table (hidden ones included), in table order.
    pub variables: Vec<Variable>,
    /// The browse tree (only visible variables).
    pub root: GroupNode,
    pub alias_column: Option<String>,
    by_public: HashMap<String, usize>,
    by_name: HashMap<String, usize>,
}

fn check_name(kind: &str, name: &str) -> Result<(), String> {
    if name.starts_with('.') || name.ends_with('.') || name.contains("..") {
        return Err(format!(
            "{kind} `{name}` may not start or end with `.` or contain `..`"
        ));
    }
    if name.chars().any(char::is_control) || name.trim() != name {
        return Err(format!(
            "{kind} `{name}` has control characters or surrounding blanks"
        ));
    }
    Ok(())
}

fn parse_data_type(text: &str) -> Option<VarType> {
    let t = text.trim();
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
        let file = table.file.as_str();
        let mut warnings = Vec::new();
        let col = |name: &str| {
            table
                .columns
                .iter()
                .position(|c| c.eq_ignore_ascii_case(name))
        };
        let name_col =
            col(columns::NAME).ok_or_else(|| DbError::invalid(file, 0, "no `Name` column"))?;
        let alias_col = match alias {
            None => None,
            Some(a) => Some(
                table
                    .columns
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
        let cols: Vec<Option<usize>> = columns::ALL.iter().map(|c| col(c)).collect();
        let cell = |row: &[String], name: &str| -> String {
            let i = columns::ALL
                .iter()
                .position(|c| *c == name)
                .and_then(|i| cols[i]);
            i.map(|i| row[i].clone()).unwrap_or_default()
        };
        let names: HashMap<&str, usize> = table
            .rows
            .iter()
            .enumerate()
            .map(|(i, (_, r))| (r[name_col].as_str(), i))
            .collect();
        let mut variables = Vec::with_capacity(table.rows.len());
        let mut by_name = HashMap::new();
        let mut by_public = HashMap::new();
        for (line, row) in &table.rows {
            let line = *line;
            let err = |m: String| DbError::invalid(file, line, m);
            let name = row[name_col].clone();
            if name.is_empty() {
                return Err(err("a variable without a name".into()));
            }
            check_name("variable name", &name).map_err(err)?;
            let number = |column: &str| -> Result<Option<f64>, DbError> {
                let t = cell(row, column);
                if t.trim().is_empty() {
                    return Ok(None);
                }
                parse_number(&t)
                    .map(Some)
                    .ok_or_else(|| err(format!("{column} of {name}: `{t}` is not a number")))
            };
            let (from, to) = (number(columns::RANGE_FROM)?, number(columns::RANGE_TO)?);
            let range = match (from, to) {
                (Some(a), Some(b)) if a != b => Some((a, b)),
                (None, None) => None,
                _ => {
                    warnings.push(Warning::new(
                        file,
                        line,
                        format!("{name}: incomplete or empty range ignored"),
                    ));
                    None
                }
            };
            let dt = cell(row, columns::DATA_TYPE);
            let data_type = parse_data_type(&dt).ok_or_else(|| {
                err(format!(
                    "DataType of {name}: `{dt}` is not R4, I2, UI2, I4, UI4 or UI1"
                ))
            })?;
            let format_text = cell(row, columns::FORMAT).trim().to_owned();
            let format = if format_text.is_empty() {
                None
            } else {
                match FormatSpec::parse(&format_text) {
                    Ok(f) => Some(f),
                    Err(m) => {
                        warnings.push(Warning::new(
                            file,
                            line,
                            format!("{name}: Format {m}; the default form is used"),
                        ));
                        None
                    }
                }
            };
            let mut limit = |column: &str| -> Option<Limit> {
                let t = cell(row, column).trim().to_owned();
                if t.is_empty() {
                    return None;
                }
                if let Some(v) = parse_number(&t) {
                    return Some(Limit::Value(v));
                }
                if !names.contains_key(t.as_str()) {
                    warnings.push(Warning::new(
                        file,
                        line,
                        format!("{name}: {column} names unknown variable `{t}`"),
                    ));
                }
                Some(Limit::Variable(t))
            };
            let (warn_low, warn_high) = (limit(columns::WARN_LOW), limit(columns::WARN_HIGH));
            let (alarm_low, alarm_high) = (limit(columns::ALARM_LOW), limit(columns::ALARM_HIGH));
            let control = cell(row, columns::CONTROL_VARIABLE).trim().to_owned();
            let control_variable = if control.is_empty() {
                None
            } else {
                if !names.contains_key(control.as_str()) {
                    warnings.push(Warning::new(
                        file,
                        line,
                        format!("{name}: ControlVariable `{control}` is not in the table"),
                    ));
                }
                Some(control)
            };
            let w = cell(row, columns::WRITABLE);
            let writable = if w.trim().is_empty() {
                true
            } else {
                parse_bool(&w).ok_or_else(|| {
                    err(format!(
                        "Writable of {name}: `{w}` is not tak/nie/true/false/1/0"
                    ))
                })?
            };
            let bar_base = number(columns::BAR_BASE)?;
            let public_name = match alias_col {
                None => name.clone(),
                Some(a) => row[a].clone(),
            };
            let index = variables.len();
            if by_name.insert(name.clone(), index).is_some() {
                return Err(err(format!("variable `{name}` is defined twice")));
            }
            if !public_name.is_empty() {
                check_name("alias", &public_name).map_err(err)?;
                if by_public.insert(public_name.clone(), index).is_some() {
                    return Err(err(format!(
                        "alias `{public_name}` of {name} is used twice"
                    )));
                }
            }
            variables.push(Variable {
                name,
                public_name,
                line,
                description: cell(row, columns::DESCRIPTION),
                description_en: cell(row, columns::DESCRIPTION_EN),
                unit: cell(row, columns::UNIT),
                range,
                data_type,
                format_text,
                format,
                warn_low,
                warn_high,
                alarm_low,
                alarm_high,
                control_variable,
                bar_base,
                writable,
                cells: row.clone(),
            });
        }
        let mut root = GroupNode::default();
        match set {
            None => {
                root.variables = (0..variables.len())
                    .filter(|&i| !variables[i].public_name.is_empty())
                    .collect();
            }
            Some(set) => {
                for group in &set.groups {
                    let mut node = &mut root;
                    for segment in &group.path {
                        node = node.child(segment);
                    }
                    for (var, line) in &group.variables {
                        match by_name.get(var) {
                            None => warnings.push(Warning::new(
                                &set.file,
                                *line,
                                format!("variable `{var}` is not in the attribute table; skipped"),
                            )),
                            Some(&i) if variables[i].public_name.is_empty() => {}
                            Some(&i) if node.variables.contains(&i) => warnings.push(Warning::new(
                                &set.file,
                                *line,
                                format!("variable `{var}` listed twice in the group; skipped"),
                            )),
                            Some(&i) => node.variables.push(i),
                        }
                    }
                }
            }
        }
        let db = VarDatabase {
            title: set.and_then(|s| s.title.clone()),
            columns: table.columns.clone(),
            variables,
            root,
            alias_column: alias_col.map(|i| table.columns[i].clone()),
            by_public,
            by_name,
        };
        Ok((db, warnings))
    }

    /// The visible variable a client names (alias in alias mode).
    pub fn find_public(&self, name: &str) -> Option<&Variable> {
        self.by_public.get(name).map(|&i| &self.variables[i])
    }

    /// The variable with this asix name (visible or not).
    pub fn find_real(&self, name: &str) -> Option<&Variable> {
        self.by_name.get(name).map(|&i| &self.variables[i])
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
        self.by_public.len()
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
        for v in &self.variables {
            *m.entry(v.data_type.0).or_insert(0) += 1;
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
        let table = parse_attribute_table(&read(path)?, &path.display().to_string())?;
        return VarDatabase::build(&table, None, alias);
    }
    let (set, mut warnings) = parse_var_set(&read(path)?, &path.display().to_string())?;
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
    let table = parse_attribute_table(&read(&table_path)?, &table_path.display().to_string())?;
    let (db, more) = VarDatabase::build(&table, Some(&set), alias)?;
    warnings.extend(more);
    Ok((db, warnings))
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

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
    }
}
