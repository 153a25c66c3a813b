//! The machine's COM classes with component categories, as the server browser
//! (`OPC.ServerList.1`, crates/serverlist) answers about them: the entries of
//! both registry views merged ([`Catalog::merge`]), the category filter of
//! `IOPCServerList::EnumClassesOfCategories` ([`Catalog::classes_of_categories`], the rules
//! of `ICatInformation::EnumClassesOfCategories`), the details of a class and the ProgID
//! lookup. Plain Rust (no `windows`), compiled and tested on every host; the browser
//! reads the registry into [`ClassEntry`]s.

use crate::View;

/// One class of one registry view: `HKCR\CLSID\{clsid}` with its categories.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ClassEntry {
    pub clsid: u128,
    /// The subkeys of `Implemented Categories`.
    pub implemented: Vec<u128>,
    /// The subkeys of `Required Categories`.
    pub required: Vec<u128>,
    /// The `ProgID` subkey's default value (version-dependent, e.g. `ServerCTOPC.App.1`).
    pub progid: Option<String>,
    /// The `VersionIndependentProgID` subkey's default value.
    pub version_independent_progid: Option<String>,
    /// The CLSID key's default value (the user type name, the description clients show).
    pub user_type: Option<String>,
}

/// The classes of the machine, both views merged, in the order first seen (64-bit view
/// first).
#[derive(Clone, Debug, Default)]
pub struct Catalog {
    pub entries: Vec<ClassEntry>,
}

fn union(into: &mut Vec<u128>, from: &[u128]) {
    for c in from {
        if !into.contains(c) {
            into.push(*c);
        }
    }
}

impl Catalog {
    /// Merges the views' entries: a class registered in both is one entry with the union
    /// of its categories, and each text from the first view that has it (the 64-bit view
    /// when `views` lists it first); a class in one view only is listed too.
    pub fn merge(views: Vec<(View, Vec<ClassEntry>)>) -> Catalog {
        let mut entries: Vec<ClassEntry> = Vec::new();
        for (_, list) in views {
            for e in list {
                match entries.iter_mut().find(|x| x.clsid == e.clsid) {
                    Some(x) => {
                        union(&mut x.implemented, &e.implemented);
                        union(&mut x.required, &e.required);
                        if x.progid.is_none() {
                            x.progid = e.progid;
                        }
                        if x.version_independent_progid.is_none() {
                            x.version_independent_progid = e.version_independent_progid;
                        }
                        if x.user_type.is_none() {
                            x.user_type = e.user_type;
                        }
                    }
                    None => entries.push(e),
                }
            }
        }
        Catalog { entries }
    }

    /// `EnumClassesOfCategories` as `ICatInformation` answers it: the classes implementing
    /// at least one of `implemented` (`None`, a count of `(ULONG)-1`: any class) whose
    /// required categories are all among `required` (`None`: requirements not checked;
    /// an empty list: only classes requiring nothing).
    pub fn classes_of_categories(
        &self,
        implemented: Option<&[u128]>,
        required: Option<&[u128]>,
    ) -> Vec<u128> {
        self.entries
            .iter()
            .filter(|e| {
                implemented.is_none_or(|want| e.implemented.iter().any(|c| want.contains(c)))
            })
            .filter(|e| required.is_none_or(|given| e.required.iter().all(|c| given.contains(c))))
            .map(|e| e.clsid)
            .collect()
    }

    /// The entry of `clsid`, if either view registers it.
    pub fn details(&self, clsid: u128) -> Option<&ClassEntry> {
        self.entries.iter().find(|e| e.clsid == clsid)
    }
}

/// Parses a registry GUID spelling, `{XXXXXXXX-XXXX-XXXX-XXXX-XXXXXXXXXXXX}` (any case);
/// `None` for anything else (a `CLSID` subkey such as `CLSID` junk is skipped).
pub fn parse_guid(s: &str) -> Option<u128> {
    let inner = s.strip_prefix('{')?.strip_suffix('}')?;
    let parts: Vec<&str> = inner.split('-').collect();
    let lens = [8, 4, 4, 4, 12];
    if parts.len() != 5 || parts.iter().zip(lens).any(|(p, n)| p.len() != n) {
        return None;
    }
    let hex: String = parts.concat();
    if !hex.bytes().all(|b| b.is_ascii_hexdigit()) {
        return None;
    }
    u128::from_str_radix(&hex, 16).ok()
}

/// The CLSID of a ProgID as `CLSIDFromProgID` finds it, over one registry view's reader
/// of default values (`read("Some.ProgID\\CLSID")`): the ProgID's own `CLSID` subkey,
/// else, for a version-independent ProgID that has none, the `CLSID` of the ProgID its
/// `CurVer` names (one step: a `CurVer` naming a ProgID without a `CLSID` is not
/// followed further).
pub fn resolve_progid(progid: &str, read: impl Fn(&str) -> Option<String>) -> Option<u128> {
    if let Some(id) = read(&format!("{progid}\\CLSID")).and_then(|s| parse_guid(&s)) {
        return Some(id);
    }
    let current = read(&format!("{progid}\\CurVer"))?;
    let current = current.trim();
    if current.is_empty() || current.eq_ignore_ascii_case(progid) {
        return None;
    }
    parse_guid(&read(&format!("{current}\\CLSID"))?)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_progid_resolves_directly_or_through_cur_ver() {
        let reg: std::collections::HashMap<&str, &str> = [
            ("A.Server\\CLSID", "{00000000-0000-0000-0000-00000000000A}"),
            ("A.Server\\CurVer", "A.Server.2"),
            ("B.Server\\CurVer", "B.Server.3"),
            (
                "B.Server.3\\CLSID",
                "{00000000-0000-0000-0000-00000000000B}",
            ),
            ("Loop\\CurVer", "Loop"),
            ("Dangling\\CurVer", "Gone.1"),
            ("Bad\\CLSID", "not a guid"),
        ]
        .into_iter()
        .collect();
        let read = |k: &str| reg.get(k).map(|v| v.to_string());
        assert_eq!(
            resolve_progid("A.Server", read),
            Some(0xA),
            "own CLSID first"
        );
        assert_eq!(
            resolve_progid("B.Server", read),
            Some(0xB),
            "through CurVer"
        );
        assert_eq!(resolve_progid("B.Server.3", read), Some(0xB));
        assert_eq!(resolve_progid("Loop", read), None);
        assert_eq!(resolve_progid("Dangling", read), None);
        assert_eq!(resolve_progid("Bad", read), None);
        assert_eq!(resolve_progid("Unknown", read), None);
    }

    const DA10: u128 = 0x63d5f430_cfe4_11d1_b2c8_0060083ba1fb;
    const DA20: u128 = 0x63d5f432_cfe4_11d1_b2c8_0060083ba1fb;
    const DA30: u128 = 0xcc603642_66d7_48f1_b69a_b625e73652d7;
    const REQ: u128 = 0x1111;

    fn entry(clsid: u128, implemented: &[u128], progid: Option<&str>) -> ClassEntry {
        ClassEntry {
            clsid,
            implemented: implemented.to_vec(),
            progid: progid.map(String::from),
            ..ClassEntry::default()
        }
    }

    fn catalog() -> Catalog {
        let mut needs = entry(4, &[DA20], Some("Needs.1"));
        needs.required = vec![REQ];
        Catalog::merge(vec![
            (
                View::Reg64,
                vec![
                    entry(1, &[DA20, DA30], Some("Ours.App.1")),
                    entry(2, &[DA10], None),
                    needs,
                ],
            ),
            (
                View::Reg32,
                vec![
                    ClassEntry {
                        user_type: Some("from 32".into()),
                        ..entry(2, &[DA20], Some("Old.Server.1"))
                    },
                    entry(3, &[DA10], Some("Only32.Server.1")),
                ],
            ),
        ])
    }

    #[test]
    fn both_views_merge_into_one_entry_per_class() {
        let c = catalog();
        let ids: Vec<u128> = c.entries.iter().map(|e| e.clsid).collect();
        assert_eq!(ids, [1, 2, 4, 3]);
        let two = c.details(2).unwrap();
        assert_eq!(two.implemented, [DA10, DA20]);
        assert_eq!(two.progid.as_deref(), Some("Old.Server.1"));
        assert_eq!(two.user_type.as_deref(), Some("from 32"));
        assert_eq!(
            c.details(3).unwrap().progid.as_deref(),
            Some("Only32.Server.1")
        );
        assert!(c.details(99).is_none());
    }

    #[test]
    fn guids_parse_as_the_registry_spells_them() {
        assert_eq!(
            parse_guid("{CC603642-66D7-48F1-B69A-B625E73652D7}"),
            Some(DA30)
        );
        assert_eq!(
            parse_guid("{63d5f432-cfe4-11d1-b2c8-0060083ba1fb}"),
            Some(DA20)
        );
        let g = crate::guid_string(0x0123_4567_89ab_cdef_0011_2233_4455_6677);
        assert_eq!(
            parse_guid(&g),
            Some(0x0123_4567_89ab_cdef_0011_2233_4455_6677)
        );
        for bad in [
            "",
            "{}",
            "CC603642-66D7-48F1-B69A-B625E73652D7",
            "{CC603642-66D7-48F1-B69A-B625E73652DZ}",
            "{CC60364-266D7-48F1-B69A-B625E73652D7}",
            "{+C603642-66D7-48F1-B69A-B625E73652D7}",
        ] {
            assert_eq!(parse_guid(bad), None, "{bad}");
        }
    }

    #[test]
    fn the_first_view_wins_for_texts() {
        let c = Catalog::merge(vec![
            (View::Reg64, vec![entry(1, &[DA20], Some("A.1"))]),
            (View::Reg32, vec![entry(1, &[DA30], Some("B.1"))]),
        ]);
        assert_eq!(c.entries.len(), 1);
        assert_eq!(c.entries[0].progid.as_deref(), Some("A.1"));
        assert_eq!(c.entries[0].implemented, [DA20, DA30]);
    }

    #[test]
    fn categories_filter_as_icatinformation_does() {
        let c = catalog();
        assert_eq!(c.classes_of_categories(Some(&[DA10]), Some(&[])), [2, 3]);
        assert_eq!(c.classes_of_categories(Some(&[DA20]), Some(&[])), [1, 2]);
        assert_eq!(c.classes_of_categories(Some(&[DA30]), Some(&[])), [1]);
        assert_eq!(
            c.classes_of_categories(Some(&[DA20]), Some(&[REQ])),
            [1, 2, 4],
            "a class requiring REQ is listed when REQ is given"
        );
        assert_eq!(c.classes_of_categories(Some(&[DA20]), None), [1, 2, 4]);
        assert_eq!(c.classes_of_categories(None, Some(&[])), [1, 2, 3]);
        assert!(c.classes_of_categories(Some(&[]), None).is_empty());
        assert!(c.classes_of_categories(Some(&[0x42]), None).is_empty());
    }
}
