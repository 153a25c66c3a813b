//! A synthetic variable database of any size, in the documented format
//! (`docs/variable-database.md`): an attribute table of 17 columns (about 90 bytes a row)
//! and a variable set with branches of 100 variables, 100 branches to an area
//! (200,000 variables make 2,000 branches in 20 areas, 2,020 in all).
//!
//! For benchmarks and scale tests (`cargo bench -p asix-model --bench vardb`); written in
//! Rust rather than in the demo's `generate.py` so that CI and the benchmarks need no
//! Python, and so that tests can make a database in memory. Pure: it returns the texts.

use std::fmt::Write as _;

/// Variables per branch of the tree.
pub const BRANCH_SIZE: usize = 100;
/// Branches per area (the first level of the tree).
pub const AREA_SIZE: usize = 100;

/// A generated database: the variable set (`.zez`, naming `atrybuty.csv`) and the
/// attribute table.
#[derive(Debug, Clone)]
pub struct SyntheticDb {
    pub zez: String,
    pub csv: String,
}

/// The asix name of the synthetic variable `i`.
pub fn variable_name(i: usize) -> String {
    format!("SC_{i:07}")
}

/// The alias (column `Alias`) of the synthetic variable `i`.
pub fn variable_alias(i: usize) -> String {
    format!("T{i:07}")
}

/// Generates a database of `n` variables. Every tenth is an integer (`I2`), every fifth
/// writable; limits are numbers, and every variable's control variable is the first of
/// its branch.
pub fn synthetic_database(n: usize) -> SyntheticDb {
    let mut csv = String::with_capacity(n * 96 + 256);
    csv.push_str(
        "Name;Alias;Description;DescriptionEn;Unit;RangeFrom;RangeTo;DataType;Format;\
         WarnLow;WarnHigh;AlarmLow;AlarmHigh;ControlVariable;BarBase;Writable;Channel\n",
    );
    let mut zez = String::with_capacity(n * 12 + n / BRANCH_SIZE * 32 + 128);
    zez.push_str("; Synthetic database (asix_model::synthetic)\nTitle = Synthetic\nAttributes = atrybuty.csv\n");
    const UNITS: [&str; 5] = ["m", "°C", "bar", "t/h", "%"];
    for i in 0..n {
        let branch = i / BRANCH_SIZE;
        if i % BRANCH_SIZE == 0 {
            let _ = write!(
                zez,
                "\n[Obszar {:03}/Sekcja {:05}]\n",
                branch / AREA_SIZE,
                branch
            );
        }
        let _ = writeln!(zez, "SC_{i:07}");
        let (dt, fmt) = if i % 10 == 9 {
            ("I2", "%d")
        } else {
            ("R4", "%.2f")
        };
        let _ = writeln!(
            csv,
            "SC_{i:07};T{i:07};Pomiar {i} sekcji {branch};Measurement {i};{unit};0;100;{dt};{fmt};10;90;5;95;SC_{ctl:07};;{w};K{ch:02}",
            unit = UNITS[i % UNITS.len()],
            ctl = branch * BRANCH_SIZE,
            w = if i % 5 == 0 { "tak" } else { "nie" },
            ch = branch % 100,
        );
    }
    SyntheticDb { zez, csv }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vardb::{parse_attribute_table, parse_var_set, VarDatabase};

    #[test]
    fn a_synthetic_database_loads_without_warnings() {
        let g = synthetic_database(250);
        let t = parse_attribute_table(g.csv.as_bytes(), "atrybuty.csv").unwrap();
        assert_eq!(t.columns.len(), 17);
        let row_bytes = g.csv.len() / 251;
        assert!((80..=110).contains(&row_bytes), "{row_bytes} B a row");
        let (set, w) = parse_var_set(g.zez.as_bytes(), "s.zez").unwrap();
        assert!(w.is_empty(), "{w:?}");
        let (db, w) = VarDatabase::build(&t, Some(&set), Some("Alias")).unwrap();
        assert!(w.is_empty(), "{w:?}");
        assert_eq!(db.visible_count(), 250);
        assert_eq!(db.root.groups.len(), 1);
        assert_eq!(db.root.groups[0].groups.len(), 3);
        assert_eq!(db.root.groups[0].groups[2].variables.len(), 50);
        assert!(db.find_public(&variable_alias(249)).is_some());
        assert!(db.find_real(&variable_name(0)).is_some());
    }
}
