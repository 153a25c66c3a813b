//! The Paradox attribute table against files another implementation wrote: pxlib
//! (Debian's `pxlib-dev`, installed by `cargo xtask setup`) through the generator
//! `tests/paradox/mkpx.c`, compiled and run here. The demo plant's table written as
//! Paradox (Windows-1250 and CP852) must load, browse and read as the CSV it was made
//! from; damaged copies of it must give clear errors.
//!
//! `tests/paradox/types.DB` (and `.MB`) is committed, written by the same generator: the
//! fuzz target's seed and the field-type test without pxlib; a test checks that pxlib
//! still writes it so. Without a C compiler or pxlib the pxlib tests are skipped, except
//! under `CI=true`, where they fail.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

use asix_model::config::parse_config;
use asix_model::namespace::{AsixNamespace, ChannelDatabase};
use asix_model::text::{decode_cp852, decode_windows_1250};
use asix_model::vardb::{
    export_table_csv, load_database_file, parse_paradox_table, read_paradox_header, CodePage,
    VarDatabase,
};
use ctopc_core::namespace::Namespace;
use ctopc_core::OpcError;

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/paradox")
}

fn work_dir(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join("paradox")
        .join(name);
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("work dir");
    d
}

/// The generator, compiled once; `None` (skip) without a compiler or pxlib, a panic
/// under CI.
fn mkpx() -> Option<&'static Path> {
    static MKPX: OnceLock<Result<PathBuf, String>> = OnceLock::new();
    let r = MKPX.get_or_init(|| {
        let out = Path::new(env!("CARGO_TARGET_TMPDIR")).join("mkpx");
        let cc = std::env::var("CC").unwrap_or_else(|_| "cc".into());
        let status = Command::new(&cc)
            .arg("-O1")
            .arg("-o")
            .arg(&out)
            .arg(fixtures().join("mkpx.c"))
            .arg("-lpx")
            .status()
            .map_err(|e| format!("{cc}: {e}"))?;
        if !status.success() {
            return Err(format!(
                "{cc} mkpx.c -lpx failed ({status}): is pxlib-dev installed?"
            ));
        }
        Ok(out)
    });
    match r {
        Ok(p) => Some(p),
        Err(e) if std::env::var("CI").is_ok_and(|v| v == "true") => {
            panic!("pxlib is needed under CI (cargo xtask setup installs pxlib-dev): {e}")
        }
        Err(e) => {
            eprintln!("skipped: no pxlib ({e}); `apt-get install pxlib-dev` to run it");
            None
        }
    }
}

fn run_mkpx(mkpx: &Path, args: &[&str]) {
    let out = Command::new(mkpx).args(args).output().expect("run mkpx");
    assert!(
        out.status.success(),
        "mkpx {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// The typed columns of the demo's table (the others are alpha fields).
const DEMO_TYPES: &[&str] = &[
    "RangeFrom=N",
    "RangeTo=N",
    "BarBase=N",
    "Writable=L",
    "SampleRate=S",
];

/// The demo's table as a CSV in `dir` (`atrybuty.csv`), with what neither code page
/// holds (the demo's `φ`) as `?`: a Paradox table holds only its code page.
fn demo_csv(dir: &Path) -> PathBuf {
    let high: Vec<u8> = (0x80..=0xFF).collect();
    let cp1250 = decode_windows_1250(&high);
    let cp852 = decode_cp852(&high);
    let text = std::fs::read_to_string(repo().join("demo/wytwornia_kwasu/atrybuty.csv"))
        .unwrap()
        .chars()
        .map(|c| {
            let ok = c.is_ascii() || c == '\u{FEFF}' || cp1250.contains(c) && cp852.contains(c);
            if ok {
                c
            } else {
                '?'
            }
        })
        .collect::<String>();
    let csv = dir.join("atrybuty.csv");
    std::fs::write(&csv, text).unwrap();
    let set =
        std::fs::read_to_string(repo().join("demo/wytwornia_kwasu/wytwornia_kwasu.zez")).unwrap();
    std::fs::write(dir.join("csv.zez"), set).unwrap();
    csv
}

/// The demo's table as Paradox in `dir` (`atrybuty.DB`, from [`demo_csv`]), with the
/// demo's variable set naming it; the set naming the CSV is `csv.zez`.
fn demo_twin(mkpx: &Path, dir: &Path, code_page: &str, types: &[&str]) -> PathBuf {
    let csv = demo_csv(dir);
    let db = dir.join("atrybuty.DB");
    let mut args = vec![
        "csv",
        csv.to_str().unwrap(),
        db.to_str().unwrap(),
        code_page,
    ];
    args.extend_from_slice(types);
    run_mkpx(mkpx, &args);
    let set = std::fs::read_to_string(repo().join("demo/wytwornia_kwasu/wytwornia_kwasu.zez"))
        .unwrap()
        .replace("Attributes = atrybuty.csv", "Attributes = atrybuty.DB");
    let zez = dir.join("wytwornia_kwasu.zez");
    std::fs::write(&zez, set).unwrap();
    zez
}

fn namespace(items_database: &Path, alias: bool) -> AsixNamespace {
    let ini = format!(
        "[Channel:*]\nItemsDatabase = {}\n{}",
        items_database.display(),
        if alias {
            "AliasAttributeName = Alias\n"
        } else {
            ""
        }
    );
    let (cfg, _) = parse_config(ini.as_bytes(), "t.ini").expect("config");
    let (ns, warnings) = AsixNamespace::load(cfg);
    assert!(warnings.is_empty(), "{warnings:?}");
    assert_eq!(ns.no_config_reason(), None);
    ns
}

/// Two namespaces are the same to a client: the browse tree, and for every item its
/// definition and properties, and every attribute of every variable.
fn assert_same_namespace(a: &AsixNamespace, b: &AsixNamespace) {
    let nodes: Vec<_> = a.browse_nodes().collect();
    assert_eq!(nodes, b.browse_nodes().collect::<Vec<_>>());
    assert!(nodes.len() > 200);
    let (da, db) = (a.database("*").unwrap(), b.database("*").unwrap());
    assert_eq!(da.columns, db.columns);
    assert_eq!(da.title, db.title);
    assert_eq!(da.variables.len(), db.variables.len());
    for i in 0..da.variables.len() {
        let (mut va, mut vb) = (
            da.variables.get(i).unwrap().clone(),
            db.variables.get(i).unwrap().clone(),
        );
        // The CSV's line, the table's record.
        (va.line, vb.line) = (0, 0);
        assert_eq!(va, vb);
    }
    for n in &nodes {
        let Some(id) = &n.item_id else { continue };
        assert_eq!(
            a.resolve_with_attributes(id, ""),
            b.resolve_with_attributes(id, ""),
            "{id}"
        );
        if let Ok(def) = a.resolve(id, "") {
            assert_eq!(Some(&def), b.resolve(id, "").as_ref().ok(), "{id}");
        }
        for c in &da.columns {
            let attr = format!("{id}.{c}");
            assert_eq!(
                a.resolve_with_attributes(&attr, ""),
                b.resolve_with_attributes(&attr, ""),
                "{attr}"
            );
        }
    }
}

#[test]
fn the_demo_as_paradox_loads_browses_and_reads_as_its_csv() {
    let Some(mkpx) = mkpx() else { return };
    for (code_page, expect) in [("1250", CodePage::Windows1250), ("852", CodePage::Cp852)] {
        let dir = work_dir(&format!("demo{code_page}"));
        let zez = demo_twin(mkpx, &dir, code_page, DEMO_TYPES);
        let csv_set = dir.join("csv.zez");
        let mut table = std::fs::File::open(dir.join("atrybuty.DB")).unwrap();
        let header = read_paradox_header(&mut table, "atrybuty.DB").unwrap();
        assert_eq!(header.code_page, expect);
        assert_eq!(header.records, 228);
        for alias in [false, true] {
            assert_same_namespace(&namespace(&csv_set, alias), &namespace(&zez, alias));
        }
        // The table alone, without a tree: every variable a leaf of the root, as the CSV.
        let (a, _) = load_database_file(&dir.join("atrybuty.csv"), None).unwrap();
        let (b, _) = load_database_file(&dir.join("atrybuty.DB"), None).unwrap();
        assert_eq!(a.root, b.root);
        assert_eq!(
            b.find_public("KW_A508").unwrap().description,
            "Ciśnienie pary; kolektor wysokoprężny"
        );
    }
}

#[test]
fn memo_and_alpha_descriptions_read_alike() {
    // Descriptions as memos (heads of 12 bytes: most in the .MB file).
    let Some(mkpx) = mkpx() else { return };
    let dir = work_dir("memo");
    let mut types = DEMO_TYPES.to_vec();
    types.extend(["Description=M12", "DescriptionEn=M40"]);
    let zez = demo_twin(mkpx, &dir, "1250", &types);
    let csv_set = dir.join("csv.zez");
    assert_same_namespace(&namespace(&csv_set, false), &namespace(&zez, false));
    // Without its .MB file the table cannot be read, and the error says where.
    std::fs::remove_file(dir.join("atrybuty.MB")).unwrap();
    let e = load_database_file(&zez, None).unwrap_err();
    assert_eq!(e.code, OpcError::ErrorDuringOpeningVarBase);
    assert_eq!(e.line, 1);
    assert!(
        e.message.contains("record 1, field `Description` (M)") && e.message.contains(".MB"),
        "{e}"
    );
}

#[test]
fn exported_csv_loads_as_the_table() {
    let Some(mkpx) = mkpx() else { return };
    let dir = work_dir("export");
    let mut types = DEMO_TYPES.to_vec();
    types.push("Description=M12");
    let zez = demo_twin(mkpx, &dir, "852", &types);
    let (csv, table, warnings) = export_table_csv(&zez).unwrap();
    assert!(warnings.is_empty(), "{warnings:?}");
    assert_eq!(table, dir.join("atrybuty.DB"));
    std::fs::write(dir.join("export.csv"), &csv).unwrap();
    let set = std::fs::read_to_string(&zez)
        .unwrap()
        .replace("Attributes = atrybuty.DB", "Attributes = export.csv");
    let csv_zez = dir.join("export.zez");
    std::fs::write(&csv_zez, set).unwrap();
    for alias in [false, true] {
        assert_same_namespace(&namespace(&zez, alias), &namespace(&csv_zez, alias));
    }
    // The table named directly exports the same text.
    assert_eq!(export_table_csv(&table).unwrap().0, csv);
    // A CSV is not exported.
    let csv_path = repo().join("demo/wytwornia_kwasu/wytwornia_kwasu.zez");
    assert!(export_table_csv(&csv_path).is_err());
}

#[test]
fn a_set_without_attributes_finds_its_table_csv_first() {
    let Some(mkpx) = mkpx() else { return };
    let dir = work_dir("precedence");
    let zez = demo_twin(mkpx, &dir, "1250", DEMO_TYPES);
    let text = std::fs::read_to_string(&zez)
        .unwrap()
        .replace("Attributes = atrybuty.DB\n", "");
    // The original's layout: the set in the database folder with one Paradox table.
    let set = dir.join("zestaw.zez");
    std::fs::write(&set, &text).unwrap();
    let (db, _) = load_database_file(&set, None).unwrap();
    assert_eq!(db.variables.len(), 228);
    // The set's own name with .DB.
    std::fs::copy(dir.join("atrybuty.DB"), dir.join("zestaw.DB")).unwrap();
    std::fs::write(dir.join("atrybuty.DB"), b"not a table").unwrap();
    assert!(load_database_file(&set, None).is_ok());
    // A CSV of the set's name comes first.
    std::fs::write(dir.join("zestaw.csv"), "Name\nKW_A000\n").unwrap();
    let (db, _) = load_database_file(&set, None).unwrap();
    assert_eq!(db.variables.len(), 1);
    // Several tables and no name: not found, and the message says what to do.
    let lone = dir.join("lone");
    std::fs::create_dir_all(&lone).unwrap();
    std::fs::write(lone.join("zestaw.zez"), &text).unwrap();
    std::fs::write(lone.join("a.DB"), b"").unwrap();
    std::fs::write(lone.join("b.db"), b"").unwrap();
    let e = load_database_file(&lone.join("zestaw.zez"), None).unwrap_err();
    assert_eq!(e.code, OpcError::VarBaseNotFound);
    assert!(e.message.contains("Attributes ="), "{e}");
}

/// The demo's table as Paradox bytes (Windows-1250).
fn demo_table_bytes(mkpx: &Path, name: &str) -> (PathBuf, Vec<u8>) {
    let dir = work_dir(name);
    let zez = demo_twin(mkpx, &dir, "1250", DEMO_TYPES);
    let bytes = std::fs::read(dir.join("atrybuty.DB")).unwrap();
    (zez, bytes)
}

fn le16(b: &[u8], at: usize) -> usize {
    usize::from(u16::from_le_bytes([b[at], b[at + 1]]))
}

#[test]
fn damaged_tables_give_clear_errors() {
    let Some(mkpx) = mkpx() else { return };
    let (zez, good) = demo_table_bytes(mkpx, "damaged");
    let table = zez.with_file_name("atrybuty.DB");
    let header_size = le16(&good, 2);
    let block_size = usize::from(good[5]) * 0x400;
    let first = header_size; // block 1
    let nfields = le16(&good, 0x21);
    let patch = |f: &dyn Fn(&mut Vec<u8>)| {
        let mut b = good.clone();
        f(&mut b);
        b
    };
    let cases: Vec<(&str, Vec<u8>, usize, &str)> = vec![
        (
            "truncated in the header",
            good[..0x40].to_vec(),
            0,
            "shorter than",
        ),
        (
            "truncated in the data",
            good[..first + block_size + 100].to_vec(),
            0,
            "truncated",
        ),
        ("an index file", patch(&|b| b[4] = 1), 0, "not a data table"),
        ("a bad block size", patch(&|b| b[5] = 0), 0, "block size"),
        (
            "a header size smaller than a header",
            patch(&|b| b[2..4].copy_from_slice(&0x10u16.to_le_bytes())),
            0,
            "header size 16 is smaller",
        ),
        (
            "a loop in the block chain",
            patch(&|b| b[first..first + 2].copy_from_slice(&1u16.to_le_bytes())),
            0,
            "loops",
        ),
        (
            "a chain past the blocks",
            patch(&|b| b[first..first + 2].copy_from_slice(&999u16.to_le_bytes())),
            0,
            "past the",
        ),
        (
            "a block size that is not whole records",
            patch(&|b| b[first + 4..first + 6].copy_from_slice(&7u16.to_le_bytes())),
            0,
            "not a whole number",
        ),
        (
            "a record count the blocks do not hold",
            patch(&|b| b[6..10].copy_from_slice(&300u32.to_le_bytes())),
            0,
            "the data blocks hold 228",
        ),
        (
            "a BLOb field",
            // The second field (Alias) made a binary BLOb.
            patch(&|b| b[0x78 + 2] = 0x0D),
            0,
            "field 2 `Alias` is a binary BLOb",
        ),
        (
            "an encrypted table",
            patch(&|b| b[0x5C] = 1),
            0,
            "encrypted",
        ),
        (
            "a logical that is neither",
            {
                // Writable of record 1: the record's offset of that field.
                let types: Vec<(u8, u8)> = (0..nfields)
                    .map(|i| (good[0x78 + 2 * i], good[0x78 + 2 * i + 1]))
                    .collect();
                let at: usize = types
                    .iter()
                    .take_while(|t| t.0 != 0x09)
                    .map(|t| usize::from(t.1))
                    .sum();
                patch(&move |b| b[first + 6 + at] = 0x85)
            },
            1,
            "record 1, field `Writable` (L): 0x85",
        ),
    ];
    for (what, bytes, line, message) in cases {
        std::fs::write(&table, &bytes).unwrap();
        let e = load_database_file(&zez, None).unwrap_err();
        assert_eq!(e.code, OpcError::ErrorDuringOpeningVarBase, "{what}: {e}");
        assert_eq!(
            (e.line, e.file.as_str()),
            (line, table.to_str().unwrap()),
            "{what}: {e}"
        );
        assert!(e.message.contains(message), "{what}: {e}");
        // The same from bytes.
        assert!(parse_paradox_table(&bytes, None, "t.DB").is_err(), "{what}");
        // And channel `*` without its database is OPC_STATUS_NOCONFIG, as with a CSV.
        let ini = format!("[Channel:*]\nItemsDatabase = {}\n", zez.display());
        let (ns, _) = AsixNamespace::load(parse_config(ini.as_bytes(), "t.ini").unwrap().0);
        assert!(matches!(ns.database_state("*"), ChannelDatabase::Failed(_)));
        assert!(ns.no_config_reason().unwrap().contains(message), "{what}");
    }
    // A missing table is VarBaseNotFound.
    std::fs::remove_file(&table).unwrap();
    let e = load_database_file(&zez, None).unwrap_err();
    assert_eq!(e.code, OpcError::VarBaseNotFound);
}

#[test]
fn every_field_type_reads_as_text() {
    let db = std::fs::read(fixtures().join("types.DB")).unwrap();
    let mb = std::fs::read(fixtures().join("types.MB")).unwrap();
    let (t, warnings) = parse_paradox_table(&db, Some(&mb), "types.DB").unwrap();
    assert!(warnings.is_empty(), "{warnings:?}");
    assert_eq!(
        t.columns,
        [
            "Name", "Count", "Total", "Ratio", "Price", "Flag", "Day", "At", "Stamp", "Serial",
            "Note"
        ]
    );
    let rows: Vec<(usize, Vec<&str>)> = t
        .rows
        .iter()
        .map(|(n, r)| (*n, r.iter().map(String::as_str).collect()))
        .collect();
    let big: String = (0..4999usize)
        .map(|i| char::from(b'a' + (i % 26) as u8))
        .collect();
    assert_eq!(
        rows[0],
        (
            1,
            vec![
                "KW_ŻÓŁW",
                "32767",
                "4000000",
                "0.5",
                "12.99",
                "tak",
                "2024-02-29",
                "13:05:07",
                "2001-09-11 08:46:40",
                "1",
                "Notatka dłuższa niż nagłówek pola,\nw pliku .MB"
            ]
        )
    );
    assert_eq!(
        rows[1],
        (
            2,
            vec![
                "KW_minus",
                "-32767",
                "-7",
                "-1234.125",
                "-0.01",
                "nie",
                "1999-12-31",
                "00:00:01",
                "2001-09-11 08:46:40",
                "2",
                big.as_str()
            ]
        )
    );
    assert_eq!(
        rows[2],
        (3, vec!["BLANK", "", "", "", "", "", "", "", "", "", ""])
    );
    assert_eq!(rows[3].1[0], "SHORT");
    assert_eq!(rows[3].1[10], "krótka");
    assert_eq!(rows.len(), 4);
    // Without the .MB file only the memos that are not in the record fail.
    let e = parse_paradox_table(&db, None, "types.DB").unwrap_err();
    assert_eq!(e.line, 1, "{e}");
    // Every prefix of the table: an error or the table, never a panic.
    for n in 0..db.len() {
        let _ = parse_paradox_table(&db[..n], Some(&mb), "types.DB");
        let _ = parse_paradox_table(&db, Some(&mb[..n.min(mb.len())]), "types.DB");
    }
}

/// xorshift64*: the random values below, the same on every run.
fn next(state: &mut u64) -> u64 {
    *state ^= *state >> 12;
    *state ^= *state << 25;
    *state ^= *state >> 27;
    state.wrapping_mul(0x2545_F491_4F6C_DD1D)
}

#[test]
fn random_values_written_by_pxlib_read_back_in_both_code_pages() {
    let Some(mkpx) = mkpx() else { return };
    let dir = work_dir("random");
    let letters: Vec<char> = "abcxyzKW_019-. ;\"ąćęłńóśźżĄĆĘŁŃÓŚŹŻ°".chars().collect();
    let mut state = 0x1234_5678_9ABC_DEF0u64;
    let mut csv = String::from("Name;Text;Real;Small;Big;Flag\n");
    let mut expected: Vec<Vec<String>> = Vec::new();
    for i in 0..3000 {
        let len = (next(&mut state) % 40) as usize;
        let text: String = (0..len)
            .map(|_| letters[(next(&mut state) % letters.len() as u64) as usize])
            .collect();
        // Any finite double but -0 (which Paradox stores as 0), and plain ones.
        let real = match next(&mut state) % 3 {
            0 => f64::from_bits(next(&mut state)),
            1 => (next(&mut state) % 20_001) as f64 / 8.0 - 1250.0,
            _ => f64::NAN,
        };
        let real = if real.is_finite() && real.to_bits() != (-0.0f64).to_bits() {
            real.to_string()
        } else {
            String::new()
        };
        // Blank is the lowest value of the type (-32768, i32::MIN): never written.
        let small = (next(&mut state) as i16).max(i16::MIN + 1).to_string();
        let big = (next(&mut state) as i32).max(i32::MIN + 1).to_string();
        let flag = ["tak", "nie", ""][(next(&mut state) % 3) as usize];
        let quoted = format!("\"{}\"", text.replace('"', "\"\""));
        csv.push_str(&format!("V{i};{quoted};{real};{small};{big};{flag}\n"));
        expected.push(vec![
            format!("V{i}"),
            text.trim().to_owned(),
            real,
            small,
            big,
            flag.to_owned(),
        ]);
    }
    let csv_path = dir.join("random.csv");
    std::fs::write(&csv_path, csv).unwrap();
    for code_page in ["1250", "852"] {
        let db = dir.join(format!("random{code_page}.DB"));
        run_mkpx(
            mkpx,
            &[
                "csv",
                csv_path.to_str().unwrap(),
                db.to_str().unwrap(),
                code_page,
                "Real=N",
                "Small=S",
                "Big=I",
                "Flag=L",
            ],
        );
        let (t, warnings) =
            parse_paradox_table(&std::fs::read(&db).unwrap(), None, "r.DB").unwrap();
        assert!(warnings.is_empty(), "{warnings:?}");
        assert_eq!(t.rows.len(), expected.len());
        for ((n, row), want) in t.rows.iter().zip(&expected) {
            assert_eq!(row, want, "{code_page}: record {n}");
        }
    }
}

#[test]
fn another_code_page_is_read_as_windows_1250_with_a_warning() {
    let mut db = std::fs::read(fixtures().join("types.DB")).unwrap();
    let mb = std::fs::read(fixtures().join("types.MB")).unwrap();
    db[0x6A..0x6C].copy_from_slice(&1252u16.to_le_bytes());
    let (t, warnings) = parse_paradox_table(&db, Some(&mb), "types.DB").unwrap();
    assert_eq!(t.rows[0].1[0], "KW_ŻÓŁW");
    assert_eq!(warnings.len(), 1, "{warnings:?}");
    assert!(
        warnings[0].message.contains("code page is 1252"),
        "{warnings:?}"
    );
    // The header decides: the same bytes as CP852 are other letters, without a warning.
    db[0x6A..0x6C].copy_from_slice(&852u16.to_le_bytes());
    let (t, warnings) = parse_paradox_table(&db, Some(&mb), "types.DB").unwrap();
    assert!(warnings.is_empty());
    assert_ne!(t.rows[0].1[0], "KW_ŻÓŁW");
}

#[test]
fn records_sharing_a_memo_are_refused() {
    // Every record pointing at the 4,999-byte memo of record 2: more memo text than the
    // .MB file holds, which a table with a memo per record cannot have.
    let mut db = std::fs::read(fixtures().join("types.DB")).unwrap();
    let mb = std::fs::read(fixtures().join("types.MB")).unwrap();
    let (record_size, first) = (le16(&db, 0), le16(&db, 2) + 6);
    let memo_ref = |r: usize| first + (r + 1) * record_size - 10;
    let big: Vec<u8> = db[memo_ref(1)..memo_ref(1) + 10].to_vec();
    for r in [0, 2, 3] {
        db[memo_ref(r)..memo_ref(r) + 10].copy_from_slice(&big);
    }
    let e = parse_paradox_table(&db, Some(&mb), "types.DB").unwrap_err();
    assert!(e.message.contains("records share memos"), "{e}");
    assert!(e.message.contains("field `Note` (M)"), "{e}");
}

/// The table without the bytes pxlib writes from its memory, the clock and the path:
/// the run-time pointers (0x30, and the table-name and field-name pointers after the
/// field descriptors), the update time (0x60) and the table name (the path given).
fn masked(mut db: Vec<u8>) -> Vec<u8> {
    let nfields = le16(&db, 0x21);
    let pointers = 0x78 + 2 * nfields;
    let name_end = pointers + 4 + 4 * nfields + 261;
    for r in [0x30..0x38, 0x60..0x64, pointers..name_end] {
        db[r].fill(0);
    }
    db
}

#[test]
fn the_committed_types_table_is_what_pxlib_writes() {
    let Some(mkpx) = mkpx() else { return };
    let dir = work_dir("types");
    let db = dir.join("types.DB");
    run_mkpx(mkpx, &["types", db.to_str().unwrap()]);
    let fresh = std::fs::read(&db).unwrap();
    let committed = std::fs::read(fixtures().join("types.DB")).unwrap();
    assert!(
        masked(fresh) == masked(committed),
        "tests/paradox/types.DB differs from what mkpx writes now: \
         `mkpx types crates/asix-model/tests/paradox/types.DB` to regenerate"
    );
    assert_eq!(
        std::fs::read(dir.join("types.MB")).unwrap(),
        std::fs::read(fixtures().join("types.MB")).unwrap()
    );
}

#[test]
fn a_database_from_bytes_is_the_database_from_the_file() {
    let Some(mkpx) = mkpx() else { return };
    let (zez, bytes) = demo_table_bytes(mkpx, "bytes");
    let (table, _) = parse_paradox_table(&bytes, None, "atrybuty.DB").unwrap();
    let (from_bytes, _) = VarDatabase::build(&table, None, None).unwrap();
    let (from_file, _) = load_database_file(&zez.with_file_name("atrybuty.DB"), None).unwrap();
    assert_eq!(from_bytes.columns, from_file.columns);
    assert_eq!(from_bytes.root, from_file.root);
}
