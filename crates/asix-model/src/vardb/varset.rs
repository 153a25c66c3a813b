//! The variable set (`.zez`): settings and the groups of the browse tree.

use super::{has_control, DbError};
use crate::text::{decode_text, trim, Warning};

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

pub(super) fn apply_setting(
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
pub(super) enum SetLine<'t> {
    /// `[a/b]`: the path from the root (empty for `[/]`).
    Group(Vec<&'t str>),
    /// A variable of the last group.
    Variable(&'t str),
    /// `key = value` before the first group (both trimmed).
    Setting(&'t str, &'t str),
}

/// Reads a variable-set text line by line, borrowing every name from it; `f` returns
/// whether to go on.
pub(super) fn for_each_var_set_line<'t>(
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
