//! What an out-of-process COM server writes into the registry, as data: the list of keys
//! and values ([`ServerRegistration::keys`]) and of the trees to delete
//! ([`ServerRegistration::trees`]), computed without Windows and tested natively.
//! ctopc-com's `winreg.rs` applies them with the Win32 registry calls (`/RegServer`,
//! `/Service`, `/UnregServer`); the MSI build (`xtask/src/msi.rs`) generates its Registry
//! table from the same list, and `opcdiag doctor` checks the machine against it.
//!
//! Every key is written in **both registry views** ([`View::Reg64`] with
//! `KEY_WOW64_64KEY`, [`View::Reg32`] with `KEY_WOW64_32KEY`): the server is 64-bit, but
//! most OPC clients are 32-bit, and 32-bit processes see `HKCR\CLSID` (and on Wine more)
//! through `Wow6432Node`. Both views name the same 64-bit exe as `LocalServer32`; COM
//! starts it for clients of either bitness. Where Windows shares a key between the views
//! (ProgIDs, `AppID`, `Component Categories` since Windows 7), the second write lands on
//! the same key and changes nothing.
//!
//! Paths are relative to `HKEY_CLASSES_ROOT` (machine-wide: `HKLM\Software\Classes`).
//! [`catalog`] is the server browser's view of the machine's classes, as data too. The
//! crate is plain Rust (no `windows`), compiled and tested on every host.
#![forbid(unsafe_code)]

pub mod catalog;
pub mod security;

/// A registry view of 64-bit Windows.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum View {
    /// What 64-bit processes see (`KEY_WOW64_64KEY`).
    Reg64,
    /// What 32-bit processes see (`KEY_WOW64_32KEY`: `HKCR\Wow6432Node\CLSID`, ...).
    Reg32,
}

/// Both views, in the order they are written and removed.
pub const VIEWS: [View; 2] = [View::Reg64, View::Reg32];

/// One key to create, with its string (`REG_SZ`) values; a name of `""` is the key's
/// default value. A key without values is created empty (e.g. `Implemented Categories`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Key {
    pub view: View,
    /// Below `HKEY_CLASSES_ROOT`, `\`-separated.
    pub path: String,
    pub values: Vec<(String, String)>,
}

/// A component category the server implements, with the description it is defined
/// under (`Component Categories\{catid}`, value `409`).
#[derive(Clone, Copy, Debug)]
pub struct Category<'a> {
    pub catid: u128,
    pub description: &'a str,
}

/// What one out-of-process server registers.
#[derive(Clone, Debug)]
pub struct ServerRegistration<'a> {
    pub clsid: u128,
    pub appid: u128,
    /// Version-independent ProgID, e.g. `ServerCTOPC.App`.
    pub progid: &'a str,
    /// Version-dependent ProgID, e.g. `ServerCTOPC.App.1`.
    pub progid_versioned: &'a str,
    /// The class's own ProgID (`CLSID\{..}\ProgID`): what `ProgIDFromCLSID` and a server
    /// browser's `GetClassDetails` answer, so what a client that browses and matches by
    /// name finds. One of the two above.
    pub class_progid: &'a str,
    pub description: &'a str,
    /// Full path of the server executable.
    pub exe_path: &'a str,
    /// The exe's file name, for `HKCR\AppID\<exe>`.
    pub exe_name: &'a str,
    /// `AppID\{..}\LocalService` when installed as an NT service.
    pub service_name: Option<&'a str>,
    pub categories: &'a [Category<'a>],
    /// Write `HKCR\<ProgID>\OPC` (with `Vendor`) for OPC 1.0-era clients.
    pub opc_key_vendor: Option<&'a str>,
}

// ---------------------------------------------------------------------------------------
// ServerCTOPC.App itself

/// CLSID of ServerCTOPC.App (ours; the AppID is the same GUID, as is customary).
pub const CLSID_SERVERCTOPC: u128 = 0x3277b556_ba68_4bde_8687_8ee4e4b46336;
pub const PROGID: &str = "ServerCTOPC.App";
pub const PROGID_VERSIONED: &str = "ServerCTOPC.App.1";
pub const DESCRIPTION: &str = "ServerCTOPC OPC DA Server for asix";
pub const EXE_NAME: &str = "ServerCTOPC.exe";
/// OPCSERVERSTATUS.szVendorInfo, and the `Vendor` value of the legacy `OPC` key.
pub const VENDOR_INFO: &str =
    "ServerCTOPC: OPC DA 2.05a/3.0 server for asix (Rust rewrite of AsixConnect ServerCTOPC)";
/// `CATID_OPCDAServer20` (opcda.idl).
pub const CATID_OPC_DA_SERVER_20: u128 = 0x63d5f432_cfe4_11d1_b2c8_0060083ba1fb;
/// `CATID_OPCDAServer30` (opcda.idl).
pub const CATID_OPC_DA_SERVER_30: u128 = 0xcc603642_66d7_48f1_b69a_b625e73652d7;
/// The categories ServerCTOPC implements, with the OPC Foundation's descriptions.
pub const SERVERCTOPC_CATEGORIES: &[Category<'static>] = &[
    Category {
        catid: CATID_OPC_DA_SERVER_20,
        description: "OPC Data Access Servers Version 2.0",
    },
    Category {
        catid: CATID_OPC_DA_SERVER_30,
        description: "OPC Data Access Servers Version 3.0",
    },
];

/// The registration of ServerCTOPC.App for the exe at `exe_path` (a full Windows path),
/// with `service` the NT service's name when installed by `/Service`. `/RegServer`,
/// `/Service` and `/UnregServer` use it; an installer gets its registry entries from
/// `serverctopc(path, service).keys()`.
pub fn serverctopc<'a>(exe_path: &'a str, service: Option<&'a str>) -> ServerRegistration<'a> {
    ServerRegistration {
        clsid: CLSID_SERVERCTOPC,
        appid: CLSID_SERVERCTOPC,
        progid: PROGID,
        progid_versioned: PROGID_VERSIONED,
        // The original's ProgID, which plants' client configurations hold.
        class_progid: PROGID,
        description: DESCRIPTION,
        exe_path,
        exe_name: EXE_NAME,
        service_name: service,
        categories: SERVERCTOPC_CATEGORIES,
        opc_key_vendor: Some(VENDOR_INFO),
    }
}

// ---------------------------------------------------------------------------------------
// OPC.ServerList.1: our own server browser (OpcEnum-compatible), OpcServerList.exe

/// CLSID of `OPC.ServerList.1`, the OPC Foundation's OpcEnum's: clients create the server
/// browser by this CLSID, so ours has to answer to it too.
pub const CLSID_OPC_SERVER_LIST: u128 = 0x13486d51_4821_11d2_a494_3cb306c10000;
/// Our browser's AppID (ours, not OpcEnum's {13486D44-...}, so that removing one never
/// removes the other's DCOM settings).
pub const APPID_SERVER_LIST: u128 = 0x8878ae78_5f7d_47ef_8a3d_48868bb8e22b;
pub const SERVER_LIST_PROGID: &str = "OPC.ServerList";
pub const SERVER_LIST_PROGID_VERSIONED: &str = "OPC.ServerList.1";
pub const SERVER_LIST_DESCRIPTION: &str = "OPC Server List (ServerCTOPC)";
/// The browser's exe (not `OpcEnum.exe`: `AppID\OpcEnum.exe` is the OPC Foundation's).
pub const SERVER_LIST_EXE_NAME: &str = "OpcServerList.exe";
/// `CATID_OPCDAServer10` (opcda.idl).
pub const CATID_OPC_DA_SERVER_10: u128 = 0x63d5f430_cfe4_11d1_b2c8_0060083ba1fb;

/// The NT service of the browser (`OpcServerList.exe /Service`), for remote clients: the
/// name in `AppID\{..}\LocalService`.
pub const SERVER_LIST_SERVICE_NAME: &str = "OpcServerList";

/// The registration of our `OPC.ServerList.1` for the exe at `exe_path` (no categories, no
/// legacy `OPC` key). Apply it with [`server_list_keys`] / [`server_list_trees`], which
/// leave a server browser that is not ours alone.
pub fn server_list(exe_path: &str) -> ServerRegistration<'_> {
    server_list_as(exe_path, None)
}

/// [`server_list`], with `service` the NT service's name when installed by `/Service`
/// (then the AppID names it in `LocalService`: COM starts the service).
pub fn server_list_as<'a>(exe_path: &'a str, service: Option<&'a str>) -> ServerRegistration<'a> {
    ServerRegistration {
        clsid: CLSID_OPC_SERVER_LIST,
        appid: APPID_SERVER_LIST,
        progid: SERVER_LIST_PROGID,
        progid_versioned: SERVER_LIST_PROGID_VERSIONED,
        // OpcEnum's, which clients create the browser by.
        class_progid: SERVER_LIST_PROGID_VERSIONED,
        description: SERVER_LIST_DESCRIPTION,
        exe_path,
        exe_name: SERVER_LIST_EXE_NAME,
        service_name: service,
        categories: &[],
        opc_key_vendor: None,
    }
}

/// `CLSID\{13486D51-...}\LocalServer32` below `HKEY_CLASSES_ROOT`: what tells whose
/// server browser a view has.
pub fn server_list_local_server_key() -> String {
    format!(
        "CLSID\\{}\\LocalServer32",
        guid_string(CLSID_OPC_SERVER_LIST)
    )
}

/// Whether a `LocalServer32` command line of `{13486D51-...}` names our browser (its
/// file name is [`SERVER_LIST_EXE_NAME`], wherever it is installed; the OPC Foundation's
/// is `OpcEnum.exe`). Quotes and arguments are ignored; case-insensitive.
pub fn is_our_server_list(local_server32: &str) -> bool {
    let s = local_server32.trim();
    let path = match s.strip_prefix('"') {
        Some(rest) => rest.split('"').next().unwrap_or(rest),
        None => s
            .split(" -")
            .next()
            .unwrap_or(s)
            .split(" /")
            .next()
            .unwrap_or(s),
    };
    let file = path.rsplit(['\\', '/']).next().unwrap_or(path).trim();
    file.eq_ignore_ascii_case(SERVER_LIST_EXE_NAME)
}

/// Whose server browser each view has, from its `LocalServer32` (`None`: none).
pub fn foreign_server_list_views(local_servers: &[(View, Option<String>)]) -> Vec<View> {
    local_servers
        .iter()
        .filter(|(_, ls)| ls.as_deref().is_some_and(|l| !is_our_server_list(l)))
        .map(|(v, _)| *v)
        .collect()
}

fn is_progid_path(r: &ServerRegistration, path: &str) -> bool {
    [r.progid, r.progid_versioned]
        .iter()
        .any(|p| path == *p || path.starts_with(&format!("{p}\\")))
}

/// The keys `/RegServer` of the browser writes: every key of `r` in the views without a
/// foreign browser (`foreign`, from [`foreign_server_list_views`]), and the ProgID keys
/// only when no view has one (Windows shares ProgID keys between the views: they would
/// land on the OPC Foundation's).
pub fn server_list_keys(r: &ServerRegistration, foreign: &[View]) -> Vec<Key> {
    r.keys()
        .into_iter()
        .filter(|k| !foreign.contains(&k.view))
        .filter(|k| foreign.is_empty() || !is_progid_path(r, &k.path))
        .collect()
}

/// The trees `/UnregServer` of the browser deletes: the CLSID in the views where the
/// browser is ours (`ours`), the ProgIDs only when no view has a foreign one, our AppIDs
/// always (they are ours by GUID and exe name).
pub fn server_list_trees(
    r: &ServerRegistration,
    ours: &[View],
    foreign: &[View],
) -> Vec<(View, String)> {
    let clsid = format!("CLSID\\{}", guid_string(r.clsid));
    r.trees()
        .into_iter()
        .filter(|(v, p)| *p != clsid || ours.contains(v))
        .filter(|(_, p)| foreign.is_empty() || !is_progid_path(r, p))
        .collect()
}

/// `{XXXXXXXX-XXXX-XXXX-XXXX-XXXXXXXXXXXX}`, upper case, as the registry spells GUIDs.
pub fn guid_string(g: u128) -> String {
    format!(
        "{{{:08X}-{:04X}-{:04X}-{:04X}-{:012X}}}",
        (g >> 96) as u32,
        (g >> 80) as u16,
        (g >> 64) as u16,
        (g >> 48) as u16,
        g & 0xFFFF_FFFF_FFFF
    )
}

/// The LCID value name of a category description (`409`: English).
pub const CATEGORY_LCID: &str = "409";

impl ServerRegistration<'_> {
    /// Every key and value to write, both views (64-bit first), parents before children.
    pub fn keys(&self) -> Vec<Key> {
        VIEWS.iter().flat_map(|&v| self.keys_in(v)).collect()
    }

    /// The keys of one view.
    pub fn keys_in(&self, view: View) -> Vec<Key> {
        let clsid = guid_string(self.clsid);
        let appid = guid_string(self.appid);
        let clsid_key = format!("CLSID\\{clsid}");
        let mut out = Vec::new();
        let mut key = |path: String, values: &[(&str, &str)]| {
            out.push(Key {
                view,
                path,
                values: values
                    .iter()
                    .map(|(n, d)| ((*n).to_owned(), (*d).to_owned()))
                    .collect(),
            });
        };
        key(
            clsid_key.clone(),
            &[("", self.description), ("AppID", &appid)],
        );
        key(
            format!("{clsid_key}\\LocalServer32"),
            &[("", &format!("\"{}\"", self.exe_path))],
        );
        key(format!("{clsid_key}\\ProgID"), &[("", self.class_progid)]);
        key(
            format!("{clsid_key}\\VersionIndependentProgID"),
            &[("", self.progid)],
        );
        if !self.categories.is_empty() {
            key(format!("{clsid_key}\\Implemented Categories"), &[]);
        }
        for c in self.categories {
            let catid = guid_string(c.catid);
            key(format!("{clsid_key}\\Implemented Categories\\{catid}"), &[]);
            key(
                format!("Component Categories\\{catid}"),
                &[(CATEGORY_LCID, c.description)],
            );
        }
        key(self.progid.to_owned(), &[("", self.description)]);
        key(format!("{}\\CLSID", self.progid), &[("", &clsid)]);
        key(
            format!("{}\\CurVer", self.progid),
            &[("", self.progid_versioned)],
        );
        key(self.progid_versioned.to_owned(), &[("", self.description)]);
        key(format!("{}\\CLSID", self.progid_versioned), &[("", &clsid)]);
        if let Some(vendor) = self.opc_key_vendor {
            for p in [self.progid, self.progid_versioned] {
                key(format!("{p}\\OPC"), &[]);
                key(format!("{p}\\OPC\\Vendor"), &[("", vendor)]);
            }
        }
        let mut appid_values = vec![("", self.description)];
        if let Some(svc) = self.service_name {
            appid_values.push(("LocalService", svc));
        }
        key(format!("AppID\\{appid}"), &appid_values);
        key(format!("AppID\\{}", self.exe_name), &[("AppID", &appid)]);
        out
    }

    /// The trees `/UnregServer` deletes, both views: everything [`Self::keys`] writes
    /// except the category definitions (`Component Categories\{catid}`), which other
    /// servers implement too.
    pub fn trees(&self) -> Vec<(View, String)> {
        let paths = [
            format!("CLSID\\{}", guid_string(self.clsid)),
            self.progid.to_owned(),
            self.progid_versioned.to_owned(),
            format!("AppID\\{}", guid_string(self.appid)),
            format!("AppID\\{}", self.exe_name),
        ];
        VIEWS
            .iter()
            .flat_map(|&v| paths.iter().map(move |p| (v, p.clone())))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const CLSID: u128 = 0x3277b556_ba68_4bde_8687_8ee4e4b46336;
    const DA20: u128 = 0x63d5f432_cfe4_11d1_b2c8_0060083ba1fb;
    const DA30: u128 = 0xcc603642_66d7_48f1_b69a_b625e73652d7;

    fn reg(service: Option<&'static str>) -> ServerRegistration<'static> {
        serverctopc("C:\\Program Files\\ServerCTOPC\\ServerCTOPC.exe", service)
    }

    #[test]
    fn serverctopc_is_registered_as_the_readme_says() {
        assert_eq!(CLSID_SERVERCTOPC, CLSID);
        assert_eq!(CATID_OPC_DA_SERVER_20, DA20);
        assert_eq!(CATID_OPC_DA_SERVER_30, DA30);
        let r = reg(None);
        assert_eq!(r.progid, "ServerCTOPC.App");
        assert_eq!(r.progid_versioned, "ServerCTOPC.App.1");
        assert_eq!(r.opc_key_vendor, Some(VENDOR_INFO));
        assert_eq!(r.categories.len(), 2);
    }

    fn value<'k>(keys: &'k [Key], view: View, path: &str, name: &str) -> Option<&'k str> {
        keys.iter()
            .find(|k| k.view == view && k.path == path)?
            .values
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, d)| d.as_str())
    }

    fn has(keys: &[Key], view: View, path: &str) -> bool {
        keys.iter().any(|k| k.view == view && k.path == path)
    }

    #[test]
    fn guids_are_spelled_as_the_registry_spells_them() {
        assert_eq!(guid_string(CLSID), "{3277B556-BA68-4BDE-8687-8EE4E4B46336}");
        assert_eq!(guid_string(DA30), "{CC603642-66D7-48F1-B69A-B625E73652D7}");
        assert_eq!(
            guid_string(0x0002e005_0000_0000_c000_000000000046),
            "{0002E005-0000-0000-C000-000000000046}"
        );
    }

    #[test]
    fn both_views_get_the_same_keys_naming_the_one_64_bit_exe() {
        let r = reg(None);
        let keys = r.keys();
        let k64 = r.keys_in(View::Reg64);
        let k32 = r.keys_in(View::Reg32);
        assert_eq!(keys.len(), k64.len() + k32.len());
        assert_eq!(keys[..k64.len()], k64[..], "64-bit view first");
        let strip = |ks: &[Key]| -> Vec<(String, Vec<(String, String)>)> {
            ks.iter()
                .map(|k| (k.path.clone(), k.values.clone()))
                .collect()
        };
        assert_eq!(strip(&k64), strip(&k32));
        let clsid = "CLSID\\{3277B556-BA68-4BDE-8687-8EE4E4B46336}";
        for v in VIEWS {
            assert_eq!(
                value(&keys, v, &format!("{clsid}\\LocalServer32"), ""),
                Some("\"C:\\Program Files\\ServerCTOPC\\ServerCTOPC.exe\"")
            );
            assert_eq!(
                value(&keys, v, clsid, "AppID"),
                Some("{3277B556-BA68-4BDE-8687-8EE4E4B46336}")
            );
            assert_eq!(
                value(&keys, v, &format!("{clsid}\\ProgID"), ""),
                Some("ServerCTOPC.App")
            );
            assert_eq!(
                value(&keys, v, &format!("{clsid}\\VersionIndependentProgID"), ""),
                Some("ServerCTOPC.App")
            );
            for cat in [
                "{63D5F432-CFE4-11D1-B2C8-0060083BA1FB}",
                "{CC603642-66D7-48F1-B69A-B625E73652D7}",
            ] {
                assert!(has(
                    &keys,
                    v,
                    &format!("{clsid}\\Implemented Categories\\{cat}")
                ));
                assert!(
                    value(&keys, v, &format!("Component Categories\\{cat}"), "409")
                        .is_some_and(|d| d.starts_with("OPC Data Access Servers Version"))
                );
            }
            assert_eq!(
                value(&keys, v, "ServerCTOPC.App\\CLSID", ""),
                Some("{3277B556-BA68-4BDE-8687-8EE4E4B46336}")
            );
            assert_eq!(
                value(&keys, v, "ServerCTOPC.App\\CurVer", ""),
                Some("ServerCTOPC.App.1")
            );
            assert_eq!(
                value(&keys, v, "ServerCTOPC.App.1\\CLSID", ""),
                Some("{3277B556-BA68-4BDE-8687-8EE4E4B46336}")
            );
            for p in ["ServerCTOPC.App", "ServerCTOPC.App.1"] {
                assert!(has(&keys, v, &format!("{p}\\OPC")));
                assert_eq!(
                    value(&keys, v, &format!("{p}\\OPC\\Vendor"), ""),
                    Some(VENDOR_INFO)
                );
            }
            assert_eq!(
                value(&keys, v, "AppID\\ServerCTOPC.exe", "AppID"),
                Some("{3277B556-BA68-4BDE-8687-8EE4E4B46336}")
            );
            assert_eq!(
                value(
                    &keys,
                    v,
                    "AppID\\{3277B556-BA68-4BDE-8687-8EE4E4B46336}",
                    "LocalService"
                ),
                None
            );
        }
    }

    #[test]
    fn parents_come_before_their_children() {
        let keys = reg(None).keys();
        for (i, k) in keys.iter().enumerate() {
            if let Some((parent, _)) = k.path.rsplit_once('\\') {
                let first_parent = keys
                    .iter()
                    .position(|p| p.view == k.view && p.path == parent);
                if let Some(p) = first_parent {
                    assert!(p < i, "{} before {}", parent, k.path);
                }
            }
        }
    }

    #[test]
    fn a_service_adds_local_service_to_the_appid() {
        let keys = reg(Some("ServerCTOPC")).keys();
        for v in VIEWS {
            assert_eq!(
                value(
                    &keys,
                    v,
                    "AppID\\{3277B556-BA68-4BDE-8687-8EE4E4B46336}",
                    "LocalService"
                ),
                Some("ServerCTOPC")
            );
        }
    }

    #[test]
    fn unregistration_removes_every_written_tree_but_the_category_definitions() {
        let r = reg(Some("ServerCTOPC"));
        let trees = r.trees();
        for k in r.keys() {
            let covered = trees.iter().any(|(v, t)| {
                *v == k.view && (k.path == *t || k.path.starts_with(&format!("{t}\\")))
            });
            assert_eq!(
                covered,
                !k.path.starts_with("Component Categories\\"),
                "{:?} {}",
                k.view,
                k.path
            );
        }
        assert_eq!(trees.len(), 10);
    }

    #[test]
    fn no_categories_no_vendor_no_such_keys() {
        let r = ServerRegistration {
            categories: &[],
            opc_key_vendor: None,
            ..reg(None)
        };
        let keys = r.keys();
        assert!(!keys.iter().any(|k| k.path.contains("Categor")));
        assert!(!keys.iter().any(|k| k.path.contains("\\OPC")));
    }

    #[test]
    fn the_server_list_answers_to_opcenums_clsid_under_our_own_appid_and_exe() {
        let r = server_list("C:\\Program Files\\ServerCTOPC\\OpcServerList.exe");
        assert_eq!(
            guid_string(r.clsid),
            "{13486D51-4821-11D2-A494-3CB306C10000}"
        );
        assert_ne!(r.appid, 0x13486d44_4821_11d2_a494_3cb306c10000);
        let keys = r.keys();
        for v in VIEWS {
            assert_eq!(
                value(&keys, v, &server_list_local_server_key(), ""),
                Some("\"C:\\Program Files\\ServerCTOPC\\OpcServerList.exe\"")
            );
            assert_eq!(
                value(&keys, v, "OPC.ServerList.1\\CLSID", ""),
                Some("{13486D51-4821-11D2-A494-3CB306C10000}")
            );
            assert!(!keys.iter().any(|k| k.path.contains("Categor")));
        }
    }

    #[test]
    fn the_browser_as_a_service_names_it_in_its_appid_and_keeps_local_server32() {
        let exe = "C:\\Program Files\\ServerCTOPC\\OpcServerList.exe";
        let appid = format!("AppID\\{}", guid_string(APPID_SERVER_LIST));
        let plain = server_list(exe).keys();
        let keys = server_list_as(exe, Some(SERVER_LIST_SERVICE_NAME)).keys();
        for v in VIEWS {
            assert_eq!(value(&plain, v, &appid, "LocalService"), None);
            assert_eq!(
                value(&keys, v, &appid, "LocalService"),
                Some("OpcServerList")
            );
            assert!(value(&keys, v, &server_list_local_server_key(), "").is_some());
        }
        // /UnregServer of the plain registration removes the service's AppID too.
        let r = server_list_as(exe, Some(SERVER_LIST_SERVICE_NAME));
        let trees = server_list_trees(&r, &VIEWS, &[]);
        assert!(trees.iter().any(|(_, t)| *t == appid));
        assert_eq!(trees, server_list_trees(&server_list(exe), &VIEWS, &[]));
    }

    #[test]
    fn a_browser_is_ours_by_its_exe_name() {
        for ours in [
            "\"C:\\Program Files\\ServerCTOPC\\OpcServerList.exe\"",
            "C:\\x\\opcserverlist.EXE -Embedding",
            "\"D:\\other place\\OpcServerList.exe\" /x",
        ] {
            assert!(is_our_server_list(ours), "{ours}");
        }
        for theirs in [
            "C:\\Windows\\system32\\OpcEnum.exe",
            "\"C:\\Windows\\SysWOW64\\OpcEnum.exe\"",
            "",
        ] {
            assert!(!is_our_server_list(theirs), "{theirs}");
        }
    }

    #[test]
    fn registration_leaves_the_opc_foundations_browser_alone() {
        let r = server_list("C:\\S\\OpcServerList.exe");
        let none = server_list_keys(&r, &[]);
        assert_eq!(none, r.keys());
        let foreign = foreign_server_list_views(&[
            (View::Reg64, None),
            (
                View::Reg32,
                Some("C:\\Windows\\SysWOW64\\OpcEnum.exe".into()),
            ),
        ]);
        assert_eq!(foreign, [View::Reg32]);
        let keys = server_list_keys(&r, &foreign);
        assert!(keys.iter().all(|k| k.view == View::Reg64));
        assert!(has(&keys, View::Reg64, &server_list_local_server_key()));
        assert!(!keys.iter().any(|k| k.path.starts_with("OPC.ServerList")));
        let both = [View::Reg64, View::Reg32];
        assert!(server_list_keys(&r, &both).is_empty());
        let ours_again = foreign_server_list_views(&[
            (View::Reg64, Some("\"C:\\Old\\OpcServerList.exe\"".into())),
            (View::Reg32, Some("\"C:\\Old\\OpcServerList.exe\"".into())),
        ]);
        assert!(ours_again.is_empty(), "re-registering ours replaces it");
    }

    #[test]
    fn unregistration_removes_only_our_browser() {
        let r = server_list("C:\\S\\OpcServerList.exe");
        let clsid = "CLSID\\{13486D51-4821-11D2-A494-3CB306C10000}";
        let all = server_list_trees(&r, &VIEWS, &[]);
        assert_eq!(all, r.trees());
        let t = server_list_trees(&r, &[View::Reg64], &[View::Reg32]);
        assert!(t.contains(&(View::Reg64, clsid.to_owned())));
        assert!(!t.contains(&(View::Reg32, clsid.to_owned())));
        assert!(!t.iter().any(|(_, p)| p.starts_with("OPC.ServerList")));
        assert!(t.contains(&(View::Reg32, "AppID\\OpcServerList.exe".to_owned())));
        let nothing_ours = server_list_trees(&r, &[], &[View::Reg64, View::Reg32]);
        assert!(!nothing_ours.iter().any(|(_, p)| p.starts_with("CLSID")));
    }
}
