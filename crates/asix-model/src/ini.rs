//! The project's one INI reader, with the rules of the Windows profile API
//! (`GetPrivateProfileString`), for `ASIXConnect.ini` as the original configuration
//! program wrote it and for the files of the asix side (`aslink.ini`, the asix
//! application ini):
//!
//! - `[Section]` headers; `key = value` lines; blanks around names and values ignored;
//! - comment lines start with `;` or `#` (after optional blanks); there are no trailing
//!   comments, so `;` and `#` inside a value belong to the value;
//! - a value wholly enclosed in double quotes loses the quotes (`"C:\a b"` -> `C:\a b`);
//! - section and key names compare ASCII case-insensitively; the spelling is kept;
//! - the same section twice is merged, with a warning;
//! - a line that is neither a comment, a header nor `key = value`, or a key before any
//!   section, is skipped with a warning.
//!
//! Two entry points differ only where the files they read differ:
//!
//! - [`parse_ini`] (`ASIXConnect.ini`, one value per option): the same key twice in a
//!   section keeps the first (as `GetPrivateProfileString`) and drops the others with a
//!   warning; an unterminated `[header` is an error, because the keys under it would
//!   otherwise land in the previous section. [`parse_ini_with_lists`] is the same except
//!   that the sections it names keep every repeated key (list sections such as
//!   `[WriteRights]`, whose lines are entries, not options).
//! - [`parse_ini_tolerant`] (files written by the asix side, read as asix reads them):
//!   never fails. A repeated key is kept in [`IniSection::entries`] (asix lists such as
//!   `ZEZWOLENIE_ZAPISU` repeat a key, as `GetPrivateProfileSection` returns them), while
//!   [`IniSection::get`] and [`IniDocument::get`] still give the first value. A header
//!   without `]` is skipped with a warning, and the keys under it with it (they belong
//!   to no section); text after a header's last `]` is ignored with a warning.
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

/// A section with its entries in file order ([`parse_ini`] has already removed repeated
/// keys; [`parse_ini_tolerant`] keeps them).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct IniSection {
    /// The name between the brackets, trimmed, as spelled at its first occurrence.
    pub name: String,
    /// Line of the first header.
    pub line: usize,
    pub entries: Vec<IniEntry>,
}

impl IniSection {
    /// The first entry for `key` (ASCII case-insensitive).
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

    /// The first value of `key` in `section`, both ASCII case-insensitive, as
    /// `GetPrivateProfileString` returns it.
    pub fn get(&self, section: &str, key: &str) -> Option<&str> {
        self.section(section)?.get(key).map(|e| e.value.as_str())
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
    parse_ini_with_lists(bytes, file, &[])
}

/// As [`parse_ini`], except that in the sections named in `lists` (ASCII
/// case-insensitive) a repeated key is kept, as [`parse_ini_tolerant`] keeps it: sections
/// whose lines are list entries (`[WriteRights]`, `ZEZWOLENIE_ZAPISU`), not options.
pub fn parse_ini_with_lists(
    bytes: &[u8],
    file: &str,
    lists: &[&str],
) -> Result<(IniDocument, Vec<Warning>), IniSyntaxError> {
    let (text, _) = decode_text(bytes);
    parse(&text, file, Mode::Strict, lists)
}

/// Parses INI text (see [`parse_ini`]).
pub fn parse_ini_text(
    text: &str,
    file: &str,
) -> Result<(IniDocument, Vec<Warning>), IniSyntaxError> {
    parse(text, file, Mode::Strict, &[])
}

/// Parses INI bytes written by the asix side; never fails: what it cannot read is skipped
/// with a warning (see the module documentation). `file` names the file in warnings.
pub fn parse_ini_tolerant(bytes: &[u8], file: &str) -> (IniDocument, Vec<Warning>) {
    let (text, _) = decode_text(bytes);
    match parse(&text, file, Mode::Tolerant, &[]) {
        Ok(parsed) => parsed,
        // Unreachable: the tolerant mode reports every problem as a warning.
        Err(e) => (
            IniDocument {
                file: file.to_owned(),
                sections: Vec::new(),
            },
            vec![Warning::new(file, e.line, e.message)],
        ),
    }
}

/// Splits an INI list value (`S1, S2`) at commas, trimming the items and dropping empty ones.
pub fn split_list(value: &str) -> Vec<String> {
    value
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(str::to_owned)
        .collect()
}

/// Where the two entry points differ (see the module documentation).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Mode {
    Strict,
    Tolerant,
}

fn parse(
    text: &str,
    file: &str,
    mode: Mode,
    lists: &[&str],
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
            let name = match (rest.strip_suffix(']'), rest.rfind(']'), mode) {
                (Some(name), _, _) => name,
                (None, Some(end), Mode::Tolerant) => {
                    warnings.push(Warning::new(
                        file,
                        line,
                        format!("text after `]` ignored: `{}`", rest[end + 1..].trim()),
                    ));
                    &rest[..end]
                }
                (None, None, Mode::Tolerant) => {
                    warnings.push(Warning::new(
                        file,
                        line,
                        format!(
                            "section header `{trimmed}` has no closing `]`; it is ignored with its keys"
                        ),
                    ));
                    current = None;
                    continue;
                }
                (None, _, Mode::Strict) => {
                    return Err(IniSyntaxError {
                        line,
                        message: format!("section header `{trimmed}` has no closing `]`"),
                    })
                }
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
        let is_list = lists.iter().any(|l| l.eq_ignore_ascii_case(&section.name));
        if mode == Mode::Strict && !is_list {
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

    /// One row of the tolerant reader's table: a file, (section, key, expected value)
    /// look-ups, and the lines that must be warned about.
    struct Row {
        case: &'static str,
        bytes: &'static [u8],
        lookups: &'static [(&'static str, &'static str, Option<&'static str>)],
        warned_lines: &'static [usize],
    }

    const TOLERANT_ROWS: &[Row] = &[
        Row {
            case: "comment lines are skipped; `;` and `#` inside a value belong to it",
            bytes: b"; comment\n  # comment\n[ASLINK]\n; Nazwa = X\nNazwa = KE2 ; #1\n",
            lookups: &[("ASLINK", "Nazwa", Some("KE2 ; #1"))],
            warned_lines: &[],
        },
        Row {
            case: "section and key names are ASCII case-insensitive",
            bytes: b"[aslink]\nnazwa = KE2\n",
            lookups: &[
                ("ASLINK", "NAZWA", Some("KE2")),
                ("AsLink", "Nazwa", Some("KE2")),
                ("OTHER", "Nazwa", None),
                ("ASLINK", "Inne", None),
            ],
            warned_lines: &[],
        },
        Row {
            case: "a repeated key: the first value wins, as in Windows",
            bytes: b"[ASLINK]\nNazwa = FIRST\nNAZWA = SECOND\n[aslink]\nnazwa = THIRD\n",
            lookups: &[("ASLINK", "Nazwa", Some("FIRST"))],
            warned_lines: &[4],
        },
        Row {
            case: "Windows-1250 bytes",
            bytes: b"[Wytw\xF3rnia]\nNazwa = \xA3\xF3d\x9F \xBF\xF3\xB3w\n",
            lookups: &[("wytwórnia", "NAZWA", Some("Łódź żółw"))],
            warned_lines: &[],
        },
        Row {
            case: "UTF-8 with a byte-order mark",
            bytes: b"\xEF\xBB\xBF[ASLINK]\nNazwa = \xC5\x81\xC3\xB3d\xC5\xBA\n",
            lookups: &[("ASLINK", "Nazwa", Some("Łódź"))],
            warned_lines: &[],
        },
        Row {
            case: "UTF-16 LE with a byte-order mark",
            bytes: b"\xFF\xFE[\x00S\x00]\x00\n\x00k\x00=\x00\x05\x01\n\x00",
            lookups: &[("s", "K", Some("ą"))],
            warned_lines: &[],
        },
        Row {
            case: "a malformed line is skipped with a warning",
            bytes: b"[ASMEN]\nKANAL1 = NONE\njunk line\n= no key\nKANAL2 = NONE\n",
            lookups: &[
                ("ASMEN", "KANAL1", Some("NONE")),
                ("ASMEN", "KANAL2", Some("NONE")),
            ],
            warned_lines: &[3, 4],
        },
        Row {
            case: "a header without `]` is skipped with its keys, not an error",
            bytes: b"[ASMEN]\nA = 1\n[KANAL1\nZAPIS_CZASU_I_STATUSU = TAK\n[KANAL2]\nB = 2\n",
            lookups: &[
                ("ASMEN", "A", Some("1")),
                ("ASMEN", "ZAPIS_CZASU_I_STATUSU", None),
                ("KANAL1", "ZAPIS_CZASU_I_STATUSU", None),
                ("KANAL2", "B", Some("2")),
            ],
            warned_lines: &[3, 4],
        },
        Row {
            case: "text after a header's `]` is ignored with a warning",
            bytes: b"[ASLINK] ; the link\nNazwa = KE2\n",
            lookups: &[("ASLINK", "Nazwa", Some("KE2"))],
            warned_lines: &[1],
        },
        Row {
            case: "a key before any section is skipped with a warning",
            bytes: b"top = 1\n[S]\nk = v\n",
            lookups: &[("", "top", None), ("S", "k", Some("v"))],
            warned_lines: &[1],
        },
        Row {
            case: "a value in double quotes loses them; blanks around it do not count",
            bytes: b"[S]\n  Path  =  \"C:\\a b\"  \nEmpty =\n",
            lookups: &[("S", "path", Some("C:\\a b")), ("S", "Empty", Some(""))],
            warned_lines: &[],
        },
    ];

    #[test]
    fn tolerant_reader_table() {
        for row in TOLERANT_ROWS {
            let (doc, warnings) = parse_ini_tolerant(row.bytes, "asix.ini");
            for &(section, key, value) in row.lookups {
                assert_eq!(
                    doc.get(section, key),
                    value,
                    "{}: [{section}] {key}",
                    row.case
                );
            }
            let lines: Vec<usize> = warnings.iter().map(|w| w.line).collect();
            assert_eq!(lines, row.warned_lines, "{}: {warnings:?}", row.case);
            for w in &warnings {
                assert!(
                    w.to_string().starts_with(&format!("asix.ini:{}: ", w.line)),
                    "{}: {w}",
                    row.case
                );
            }
        }
    }

    #[test]
    fn tolerant_reader_keeps_repeated_keys_and_merges_sections_in_file_order() {
        let text = "\u{feff}top=1\n[ASMEN]\n; comment\nZEZWOLENIE_ZAPISU = K1, KE2\nzezwolenie_zapisu=K2,X\n[asmen]\nZEZWOLENIE_ZAPISU = K3 , Y \n";
        let (doc, warnings) = parse_ini_tolerant(text.as_bytes(), "app.ini");
        // A key before any section is out of reach, as for `GetPrivateProfileString`.
        assert_eq!(doc.get("", "TOP"), None);
        let all: Vec<&str> = doc
            .section("Asmen")
            .unwrap()
            .entries
            .iter()
            .filter(|e| e.key.eq_ignore_ascii_case("Zezwolenie_Zapisu"))
            .map(|e| e.value.as_str())
            .collect();
        assert_eq!(all, ["K1, KE2", "K2,X", "K3 , Y"]);
        assert_eq!(split_list(all[2]), ["K3", "Y"]);
        assert_eq!(doc.get("asmen", "ZEZWOLENIE_ZAPISU"), Some("K1, KE2"));
        assert_eq!(doc.get("NOPE", "x"), None);
        let lines: Vec<usize> = warnings.iter().map(|w| w.line).collect();
        assert_eq!(lines, [1, 6], "{warnings:?}");
        // The strict reader keeps the first and warns about the others.
        let (strict, warnings) = parse_ini(text.as_bytes(), "app.ini").unwrap();
        assert_eq!(strict.section("ASMEN").unwrap().entries.len(), 1);
        let lines: Vec<usize> = warnings.iter().map(|w| w.line).collect();
        assert_eq!(lines, [1, 5, 6, 7], "{warnings:?}");
        // ... unless the section is a list section.
        let (lists, warnings) =
            parse_ini_with_lists(text.as_bytes(), "app.ini", &["asmen"]).unwrap();
        assert_eq!(lists.section("ASMEN").unwrap().entries.len(), 3);
        let lines: Vec<usize> = warnings.iter().map(|w| w.line).collect();
        assert_eq!(lines, [1, 6], "{warnings:?}");
    }

    #[test]
    fn list_values_split_at_commas() {
        let rows: [(&str, &[&str]); 5] = [
            ("S1", &["S1"]),
            (" S1 , S2 ,", &["S1", "S2"]),
            ("S1,,S2", &["S1", "S2"]),
            (" , ", &[]),
            ("", &[]),
        ];
        for (value, items) in rows {
            assert_eq!(split_list(value), items, "{value:?}");
        }
    }

    proptest! {
        #[test]
        fn never_panics_on_arbitrary_bytes(bytes in proptest::collection::vec(any::<u8>(), 0..512)) {
            let _ = parse_ini(&bytes, "fuzz.ini");
            let _ = parse_ini_tolerant(&bytes, "fuzz.ini");
        }

        #[test]
        fn never_panics_on_ini_like_text(text in "([\\[\\]=;# \"a-zA-Z0-9*:\n\r\t]|ą|ł){0,200}") {
            let _ = parse_ini(text.as_bytes(), "fuzz.ini");
            let _ = parse_ini_tolerant(text.as_bytes(), "fuzz.ini");
        }

        /// Where the strict reader accepts a file, the tolerant one reads the same sections
        /// and the same (first) values.
        #[test]
        fn tolerant_agrees_with_strict_on_what_strict_accepts(text in "([\\[\\]=;# \"a-cA-C0-9\n]|ą){0,200}") {
            if let Ok((strict, _)) = parse_ini(text.as_bytes(), "fuzz.ini") {
                let (tolerant, _) = parse_ini_tolerant(text.as_bytes(), "fuzz.ini");
                let names = |d: &IniDocument| d.sections.iter().map(|s| s.name.clone()).collect::<Vec<_>>();
                prop_assert_eq!(names(&strict), names(&tolerant));
                for s in &strict.sections {
                    for e in &s.entries {
                        prop_assert_eq!(tolerant.get(&s.name, &e.key), Some(e.value.as_str()));
                    }
                }
            }
        }
    }
}
