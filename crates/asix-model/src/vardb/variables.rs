//! The variables of the database: read in place ([`VarView`]) or decoded ([`Variable`]).

use std::sync::OnceLock;

use ctopc_core::VarType;

use super::cells::CellTable;
use super::columns;
use crate::format::FormatSpec;
use crate::text::{parse_bool, parse_number, trim};

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
    /// Line in the attribute table (the record in a Paradox table).
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

/// Every variable of the table (hidden ones included), in table order, stored compactly:
/// the cells in one [`CellTable`] (the text of the row, 1 byte a cell, 4 a row) and a slot
/// for the decoded [`Variable`] (chunks of 64 slots made when one of them is first asked
/// for: [`Variables::get`], [`VarDatabase::find_public`](super::VarDatabase::find_public),
/// iteration). Scans over many variables use [`Variables::view`], which decodes nothing it
/// is not asked for.
#[derive(Debug, Clone, Default)]
pub struct Variables {
    pub(super) cells: CellTable,
    pub(super) name_col: usize,
    /// The alias column in alias mode, else `name_col`.
    pub(super) public_col: usize,
    /// The column of each of [`columns::ALL`].
    pub(super) known: Vec<Option<usize>>,
    /// A slot for each variable's decoded copy, in chunks of [`DECODED_CHUNK`] made when
    /// one of their variables is first decoded (no slot per variable until then).
    pub(super) decoded: Vec<OnceLock<DecodedChunk>>,
}

/// The decoded slots of [`DECODED_CHUNK`] variables.
type DecodedChunk = Box<[OnceLock<Box<Variable>>]>;

/// Variables per chunk of [`Variables`]' decoded slots.
pub(super) const DECODED_CHUNK: usize = 64;

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
pub(super) fn known_index(name: &str) -> Option<usize> {
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
/// decoded attribute. The decoders are the ones
/// [`VarDatabase::build`](super::VarDatabase::build) validated with, so on a built
/// database they do not fail.
#[derive(Debug, Clone, Copy)]
pub struct VarView<'a> {
    vars: &'a Variables,
    i: usize,
}

impl<'a> VarView<'a> {
    /// The index of the variable in [`VarDatabase::variables`](super::VarDatabase::variables).
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

    pub(super) fn number(&self, column: &str) -> Result<Option<f64>, String> {
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

    pub(super) fn data_type_checked(&self) -> Result<VarType, String> {
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

    pub(super) fn writable_checked(&self) -> Result<bool, String> {
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

fn parse_data_type(text: &str) -> Option<VarType> {
    let t = trim(text);
    if t.is_empty() {
        return Some(VarType::R4);
    }
    crate::itemid::AsmenType::parse(t).map(|t| t.var_type())
}
