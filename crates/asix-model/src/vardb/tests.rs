use std::path::Path;

use ctopc_core::{OpcError, VarType};
use proptest::prelude::*;

use super::cells::{CellTable, NARROW_ROW_BYTES};
use super::csv::for_each_csv_record_chars;
use super::table::read_cell_table;
use super::variables::known_index;
use super::*;
use crate::text::trim;

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
    let text = "Name;RangeFrom;RangeTo;Format;WarnHigh;ControlVariable\nA;0;;%q;B;Z\nB;5;5;%d;;\n";
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
    let e =
        VarDatabase::build(&table("Name;Alias\nA;x\n").unwrap(), None, Some("Alias2")).unwrap_err();
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
                for_each_csv_record_chars(&text, sep, push)
            } else {
                for_each_csv_record(&text, sep, push)
            };
            (r, out)
        };
        prop_assert_eq!(read(false), read(true));
    }
}
