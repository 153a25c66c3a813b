//! [`VarDatabase`]: the database built and checked from its table and variable set, and its
//! look-ups.

use std::collections::BTreeMap;
use std::sync::OnceLock;

use super::cells::CellTable;
use super::index::NameIndex;
use super::table::{columns, AttributeTable};
use super::variables::{LimitRef, Variable, Variables, DECODED_CHUNK};
use super::varset::{for_each_var_set_line, SetLine, VarSetFile};
use super::{has_control, DbError};
use crate::format::FormatSpec;
use crate::text::{trim, Warning};

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
    pub(super) fn build_cells(
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
