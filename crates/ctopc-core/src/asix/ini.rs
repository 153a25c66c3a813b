//! A small INI reader with the rules of the Windows profile API, as `ASIXConnect.ini` was
//! written by the original configuration program:
//!
//! - `[Section]` headers; `key = value` lines; blanks around names and values ignored;
//! - comment lines start with `;` or `#` (after optional blanks); there are no trailing
//!   comments, so `;` and `#` inside a value belong to the value;
//! - a value wholly enclosed in double quotes loses the quotes (`"C:\a b"` -> `C:\a b`);
//! - section and key names compare ASCII case-insensitively; the spelling is kept;
//! - the same section twice is merged; the same key twice in a section: the first wins
//!   (as `GetPrivateProfileString`), with a warning;
//! - a line that is neither a comment, a header nor `key = value`, or a key before any
//!   section, is skipped with a warning; an unterminated `[header` is an error, because
//!   the keys under it would otherwise land in the previous section.
//!
//! Bytes are decoded by [`decode_text`] (UTF-8, UTF-8 with BOM,
//! UTF-16 LE with BOM or Windows-1250).

use super::text::{decode_text, Warning};

/// One `key = value` line.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct IniEntry {
    pub key: String,
    pub value: String,
    /// 1-based line number.
    pub line: usize,
}

/// A section with its entries in file order (duplicates already removed).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct IniSection {
    /// The name between the brackets, trimmed, as spelled at its first occurrence.
    pub name: String,
    /// Line of the first header.
    pub line: usize,
    pub entries: Vec<IniEntry>,
}

impl IniSection {
    /// The entry for `key` (ASCII case-insensitive).
    pub fn get(&self, key: &str) -> Option<&IniEntry> {
        self.entries
            .iter()
            .find(|e| e.key.eq_ignore_ascii_case(key))
    }
}

/// A parsed INI file.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct IniDocument {
    /// The file name used in messages.
    pub file: String,
    pub sections: Vec<IniSection>,
}

impl IniDocument {
    /// The section called `name` (ASCII case-insensitive).
    pub fn section(&self, name: &str) -> Option<&IniSection> {
        self.sections
            .iter()
            .find(|s| s.name.eq_ignore_ascii_case(name))
    }
}

/// A syntax error that makes the file unusable.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct IniSyntaxError {
    pub line: usize,
    pub message: String,
}

/// Parses INI bytes; `file` names the file in warnings.
pub fn parse_ini(bytes: &[u8], file: &str) -> Result<(IniDocument, Vec<Warning>), IniSyntaxError> {
    let (text, _) = decode_text(bytes);
    parse_ini_text(&text, file)
}

/// Parses INI text (see [`parse_ini`]).
pub fn parse_ini_text(
    text: &str,
    file: &str,
) -> Result<(IniDocument, Vec<Warning>), IniSyntaxError> {
    let mut doc = IniDocument {
        file: file.to_owned(),
        sections: Vec::new(),
    };
    let mut warnings = Vec::new();
    let mut current: Option<usize> = None;
    for (index, raw) in text.lines().enumerate() {
        let line = index + 1;
        let trimmed = raw.trim();
        if trimmed.is_empty() || trimmed.starts_with(';') || trimmed.starts_with('#') {
            continue;
        }
        if let Some(rest) = trimmed.strip_prefix('[') {
            let Some(name) = rest.strip_suffix(']') else {
                return Err(IniSyntaxError {
                    line,
                    message: format!("section header `{trimmed}` has no closing `]`"),
                });
            };
            let name = name.trim();
            let pos = doc
                .sections
                .iter()
                .position(|s| s.name.eq_ignore_ascii_case(name));
            current = Some(match pos {
                Some(p) => {
                    warnings.push(Warning::new(
                        file,
                        line,
                        format!(
                            "section [{name}] repeated (first at line {}); merged",
                            doc.sections[p].line
                        ),
                    ));
                    p
                }
                None => {
                    doc.sections.push(IniSection {
                        name: name.to_owned(),
                        line,
                        entries: Vec::new(),
                    });
                    doc.sections.len() - 1
                }
            });
            continue;
        }
        let Some((key, value)) = trimmed.split_once('=') else {
            warnings.push(Warning::new(
                file,
                line,
                format!("line ignored: `{trimmed}` is not `key = value`"),
            ));
            continue;
        };
        let key = key.trim();
        if key.is_empty() {
            warnings.push(Warning::new(file, line, "line ignored: no key before `=`"));
            continue;
        }
        let Some(section) = current else {
            warnings.push(Warning::new(
                file,
                line,
                format!("`{key}` ignored: it is not in a section"),
            ));
            continue;
        };
        let mut value = value.trim();
        if value.len() >= 2 && value.starts_with('"') && value.ends_with('"') {
            value = &value[1..value.len() - 1];
        }
        let section = &mut doc.sections[section];
        if let Some(first) = section.get(key) {
            warnings.push(Warning::new(
                file,
                line,
                format!(
                    "`{key}` repeated in [{}] (first at line {}); the first value is used",
                    section.name, first.line
                ),
            ));
            continue;
        }
        section.entries.push(IniEntry {
            key: key.to_owned(),
            value: value.to_owned(),
            line,
        });
    }
    Ok((doc, warnings))
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn sections_keys_comments_quotes_and_duplicates() {
        let text = "\
; comment
# another
orphan = 1
[Server]
  LogDirectory =  \"C:\\asix\\Log\"  
Path = a;b#c
junk line
[server]
logdirectory = second
[ Channel:* ]
ItemsDatabase=x.zez
=novalue
";
        let (doc, warnings) = parse_ini_text(text, "t.ini").unwrap();
        assert_eq!(doc.sections.len(), 2);
        let server = doc.section("SERVER").unwrap();
        assert_eq!(server.get("logdirectory").unwrap().value, "C:\\asix\\Log");
        assert_eq!(server.get("logdirectory").unwrap().line, 5);
        assert_eq!(server.get("path").unwrap().value, "a;b#c");
        assert_eq!(
            doc.section("channel:*")
                .unwrap()
                .get("ItemsDatabase")
                .unwrap()
                .value,
            "x.zez"
        );
        let lines: Vec<usize> = warnings.iter().map(|w| w.line).collect();
        assert_eq!(lines, vec![3, 7, 8, 9, 12], "{warnings:?}");
        assert!(warnings[0].to_string().starts_with("t.ini:3: "));
    }

    #[test]
    fn unterminated_header_is_an_error() {
        let err = parse_ini_text("[Server]\n[Channel:*\nx=1\n", "t.ini").unwrap_err();
        assert_eq!(err.line, 2);
    }

    proptest! {
        #[test]
        fn never_panics_on_arbitrary_bytes(bytes in proptest::collection::vec(any::<u8>(), 0..512)) {
            let _ = parse_ini(&bytes, "fuzz.ini");
        }

        #[test]
        fn never_panics_on_ini_like_text(text in "([\\[\\]=;# \"a-zA-Z0-9*:\n\r\t]|ą|ł){0,200}") {
            let _ = parse_ini(text.as_bytes(), "fuzz.ini");
        }
    }
}
