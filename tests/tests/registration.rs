//! /RegServer and /UnregServer: every key in both registry views, idempotence, switch
//! spellings, usage errors; the AppID's security values (AccessPermission,
//! LaunchPermission, AuthenticationLevel) written where absent in both views, an
//! administrator's change kept by registering again; `/RegServer /CreateGroup` (the
//! MSI's) granting the clients' group or saying why it cannot; `/ProtectSecrets` making a
//! configuration's secrets private; and that this process (the suite runs as a 64-bit and as a
//! 32-bit client, `cargo xtask test`) finds the server the ways OPC clients look for it:
//! by category (ICatInformation::EnumClassesOfCategories, DA 2.0 and 3.0) and by ProgID.
//!
//! Spec: OPC DA 2.05a §5.1 Component Categories (CATID_OPCDAServer20 and 30) and §5.2
//! Registry Entries for Custom Interface (CLSID, ProgID, version-independent ProgID,
//! LocalServer32, AppID); COM's /RegServer and /UnregServer.
#![cfg(windows)]
#![allow(clippy::unwrap_used, clippy::expect_used)]

use e2e_tests::artifact;
use e2e_tests::start::StartRetrying;
use windows::core::{GUID, PCWSTR};
use windows::Win32::System::Com::{
    CLSIDFromProgID, CoCreateInstance, ICatInformation, CLSCTX_INPROC_SERVER,
};
use windows::Win32::System::Registry::{
    RegCloseKey, RegGetValueW, RegOpenKeyExW, RegSetValueExW, HKEY, HKEY_CLASSES_ROOT, KEY_READ,
    KEY_WOW64_32KEY, KEY_WOW64_64KEY, KEY_WRITE, REG_DWORD, REG_ROUTINE_FLAGS, REG_SAM_FLAGS,
    RRF_RT_REG_BINARY, RRF_RT_REG_DWORD, RRF_RT_REG_SZ, RRF_SUBKEY_WOW6432KEY,
    RRF_SUBKEY_WOW6464KEY,
};

const CLSID: &str = "{3277B556-BA68-4BDE-8687-8EE4E4B46336}";
const CATID_DA20: &str = "{63D5F432-CFE4-11D1-B2C8-0060083BA1FB}";
const CATID_DA30: &str = "{CC603642-66D7-48F1-B69A-B625E73652D7}";

fn run(args: &[&str]) -> std::process::Output {
    std::process::Command::new(artifact("ServerCTOPC.exe"))
        .args(args)
        .output_retrying()
        .expect("run ServerCTOPC.exe")
}

struct Restore;
impl Drop for Restore {
    fn drop(&mut self) {
        let _ = run(&["/RegServer"]);
    }
}

fn wide(s: &str) -> Vec<u16> {
    s.encode_utf16().chain([0]).collect()
}

/// The registry views: what 64-bit and what 32-bit processes see.
const VIEWS: [(&str, REG_SAM_FLAGS, REG_ROUTINE_FLAGS); 2] = [
    ("64-bit view", KEY_WOW64_64KEY, RRF_SUBKEY_WOW6464KEY),
    ("32-bit view", KEY_WOW64_32KEY, RRF_SUBKEY_WOW6432KEY),
];

fn key_exists(path: &str) -> bool {
    key_exists_in(REG_SAM_FLAGS(0), path)
}

fn key_exists_in(view: REG_SAM_FLAGS, path: &str) -> bool {
    let p = wide(path);
    let mut k = HKEY::default();
    // SAFETY: valid strings and out handle.
    let ok = unsafe {
        RegOpenKeyExW(
            HKEY_CLASSES_ROOT,
            PCWSTR(p.as_ptr()),
            None,
            KEY_READ | view,
            &mut k,
        )
    }
    .is_ok();
    if ok {
        // SAFETY: opened above.
        let _ = unsafe { RegCloseKey(k) };
    }
    ok
}

fn default_value(path: &str) -> Option<String> {
    value(path, "")
}

fn value(path: &str, name: &str) -> Option<String> {
    value_in(REG_ROUTINE_FLAGS(0), path, name)
}

fn value_in(view: REG_ROUTINE_FLAGS, path: &str, name: &str) -> Option<String> {
    let p = wide(path);
    let n = wide(name);
    let mut buf = vec![0u16; 1024];
    let mut len = (buf.len() * 2) as u32;
    let name_ptr = if name.is_empty() {
        PCWSTR::null()
    } else {
        PCWSTR(n.as_ptr())
    };
    // SAFETY: valid strings and buffer.
    let r = unsafe {
        RegGetValueW(
            HKEY_CLASSES_ROOT,
            PCWSTR(p.as_ptr()),
            name_ptr,
            RRF_RT_REG_SZ | view,
            None,
            Some(buf.as_mut_ptr().cast()),
            Some(&mut len),
        )
    };
    r.is_ok()
        .then(|| String::from_utf16_lossy(&buf[..(len as usize / 2).saturating_sub(1)]))
}

#[test]
fn regserver_writes_every_key_and_unregserver_removes_them_idempotently() {
    let _restore = Restore;
    for args in [["/UnregServer"], ["-unregserver"]] {
        let out = run(&args);
        assert!(out.status.success(), "{args:?}: {out:?}");
    }
    assert!(!key_exists("ServerCTOPC.App"));
    assert!(!key_exists(&format!("CLSID\\{CLSID}")));
    assert!(!key_exists(&format!("AppID\\{CLSID}")));
    for (what, view, _) in VIEWS {
        for key in [
            format!("CLSID\\{CLSID}"),
            "ServerCTOPC.App".into(),
            "ServerCTOPC.App.1".into(),
            format!("AppID\\{CLSID}"),
            "AppID\\ServerCTOPC.exe".into(),
        ] {
            assert!(!key_exists_in(view, &key), "{what}: {key} left");
        }
    }

    for args in [["/RegServer"], ["-REGSERVER"]] {
        assert!(run(&args).status.success(), "{args:?}");
    }
    let exe = default_value(&format!("CLSID\\{CLSID}\\LocalServer32")).expect("LocalServer32");
    assert!(exe.contains("ServerCTOPC.exe"), "{exe}");
    // The class's ProgID is the original's (what a browsing client matches by name).
    assert_eq!(
        default_value(&format!("CLSID\\{CLSID}\\ProgID")).as_deref(),
        Some("ServerCTOPC.App")
    );
    assert_eq!(
        default_value(&format!("CLSID\\{CLSID}\\VersionIndependentProgID")).as_deref(),
        Some("ServerCTOPC.App")
    );
    assert_eq!(
        value(&format!("CLSID\\{CLSID}"), "AppID").as_deref(),
        Some(CLSID)
    );
    assert_eq!(
        default_value("ServerCTOPC.App\\CLSID").as_deref(),
        Some(CLSID)
    );
    assert_eq!(
        default_value("ServerCTOPC.App\\CurVer").as_deref(),
        Some("ServerCTOPC.App.1")
    );
    assert_eq!(
        default_value("ServerCTOPC.App.1\\CLSID").as_deref(),
        Some(CLSID)
    );
    assert!(key_exists("ServerCTOPC.App\\OPC"), "legacy OPC key");
    assert!(default_value("ServerCTOPC.App\\OPC\\Vendor").is_some());
    assert!(key_exists(&format!("AppID\\{CLSID}")));
    assert_eq!(
        value("AppID\\ServerCTOPC.exe", "AppID").as_deref(),
        Some(CLSID)
    );
    for cat in [CATID_DA20, CATID_DA30] {
        assert!(
            key_exists(&format!("CLSID\\{CLSID}\\Implemented Categories\\{cat}")),
            "{cat}"
        );
        assert!(
            key_exists(&format!("Component Categories\\{cat}")),
            "category {cat} registered"
        );
    }
    // The same in both views, so that 32-bit clients find the (64-bit) server.
    for (what, view, rrf) in VIEWS {
        let exe32 = value_in(rrf, &format!("CLSID\\{CLSID}\\LocalServer32"), "");
        assert_eq!(exe32.as_deref(), Some(exe.as_str()), "{what}");
        assert_eq!(
            value_in(rrf, &format!("CLSID\\{CLSID}"), "AppID").as_deref(),
            Some(CLSID),
            "{what}"
        );
        assert_eq!(
            value_in(rrf, &format!("CLSID\\{CLSID}\\ProgID"), "").as_deref(),
            Some("ServerCTOPC.App"),
            "{what}"
        );
        for (path, expect) in [
            ("ServerCTOPC.App\\CLSID", CLSID),
            ("ServerCTOPC.App\\CurVer", "ServerCTOPC.App.1"),
            ("ServerCTOPC.App.1\\CLSID", CLSID),
        ] {
            assert_eq!(
                value_in(rrf, path, "").as_deref(),
                Some(expect),
                "{what}: {path}"
            );
        }
        assert!(
            value_in(rrf, "ServerCTOPC.App\\OPC\\Vendor", "").is_some(),
            "{what}: legacy OPC key"
        );
        assert!(key_exists_in(view, &format!("AppID\\{CLSID}")), "{what}");
        for cat in [CATID_DA20, CATID_DA30] {
            assert!(
                key_exists_in(
                    view,
                    &format!("CLSID\\{CLSID}\\Implemented Categories\\{cat}")
                ),
                "{what}: {cat}"
            );
            assert!(
                key_exists_in(view, &format!("Component Categories\\{cat}")),
                "{what}: category {cat} registered"
            );
        }
    }
}

/// A value's bytes in one view: the AppID's `AuthenticationLevel` a `REG_DWORD`, the
/// others `REG_BINARY` (one type per read: `REG_BINARY | REG_DWORD` together would mean
/// RRF_RT_DWORD, a 4-byte number).
fn raw_in(view: REG_ROUTINE_FLAGS, path: &str, name: &str) -> Option<Vec<u8>> {
    let kind = if name == ctopc_registration::security::AUTHENTICATION_LEVEL {
        RRF_RT_REG_DWORD
    } else {
        RRF_RT_REG_BINARY
    };
    let p = wide(path);
    let n = wide(name);
    let mut buf = vec![0u8; 4096];
    let mut len = buf.len() as u32;
    // SAFETY: valid strings and buffer.
    let r = unsafe {
        RegGetValueW(
            HKEY_CLASSES_ROOT,
            PCWSTR(p.as_ptr()),
            PCWSTR(n.as_ptr()),
            kind | view,
            None,
            Some(buf.as_mut_ptr().cast()),
            Some(&mut len),
        )
    };
    r.is_ok().then(|| buf[..len as usize].to_vec())
}

/// Sets a `REG_DWORD` of `HKCR\path` in one view (as an administrator with regedit).
fn set_dword_in(view: REG_SAM_FLAGS, path: &str, name: &str, data: u32) {
    let p = wide(path);
    let n = wide(name);
    let mut k = HKEY::default();
    // SAFETY: valid strings and out handle.
    let r = unsafe {
        RegOpenKeyExW(
            HKEY_CLASSES_ROOT,
            PCWSTR(p.as_ptr()),
            None,
            KEY_WRITE | view,
            &mut k,
        )
    };
    assert!(r.is_ok(), "open {path}: {r:?}");
    // SAFETY: `k` is open; the data outlives the call.
    let r = unsafe {
        RegSetValueExW(
            k,
            PCWSTR(n.as_ptr()),
            None,
            REG_DWORD,
            Some(&data.to_le_bytes()),
        )
    };
    // SAFETY: opened above, closed once.
    unsafe {
        let _ = RegCloseKey(k);
    }
    assert!(r.is_ok(), "set {path} {name}: {r:?}");
}

/// Puts the default AppID security back (unregister, register) after a test changed it.
struct RestoreDefaults;
impl Drop for RestoreDefaults {
    fn drop(&mut self) {
        let _ = run(&["/UnregServer"]);
        let _ = run(&["/RegServer"]);
    }
}

#[test]
fn regserver_writes_the_appid_security_where_absent_and_keeps_an_administrators_change() {
    use ctopc_registration::security;
    let _restore = RestoreDefaults;
    assert!(run(&["/UnregServer"]).status.success());
    let out = run(&["/RegServer"]);
    assert!(out.status.success(), "{out:?}");
    let appid = format!("AppID\\{CLSID}");
    let clients = ctopc_com::caller::account_sid(security::CLIENTS_GROUP)
        .and_then(|b| security::Sid::from_bytes(&b));
    let access = security::default_access(false, clients.as_ref()).to_bytes();
    let launch = security::default_launch(false, clients.as_ref()).to_bytes();
    for (what, _, rrf) in VIEWS {
        assert_eq!(
            raw_in(rrf, &appid, security::ACCESS_PERMISSION).as_deref(),
            Some(access.as_slice()),
            "{what}: AccessPermission"
        );
        assert_eq!(
            raw_in(rrf, &appid, security::LAUNCH_PERMISSION).as_deref(),
            Some(launch.as_slice()),
            "{what}: LaunchPermission"
        );
        assert_eq!(
            raw_in(rrf, &appid, security::AUTHENTICATION_LEVEL).as_deref(),
            Some(&5u32.to_le_bytes()[..]),
            "{what}: AuthenticationLevel = packet integrity"
        );
        let d = security::Descriptor::from_bytes(&access).expect("a descriptor");
        assert!(security::weaker_than_default(&d, clients.as_ref()).is_empty());
    }
    // An administrator lowers the level (dcomcnfg); registering again keeps it.
    for (_, view, _) in VIEWS {
        set_dword_in(view, &appid, security::AUTHENTICATION_LEVEL, 2);
    }
    let out = run(&["/RegServer"]);
    assert!(out.status.success(), "{out:?}");
    assert!(
        String::from_utf8_lossy(&out.stdout).contains("AppID security: 0 of 6 values written"),
        "{out:?}"
    );
    for (what, _, rrf) in VIEWS {
        assert_eq!(
            raw_in(rrf, &appid, security::AUTHENTICATION_LEVEL).as_deref(),
            Some(&2u32.to_le_bytes()[..]),
            "{what}: the administrator's change stays"
        );
        assert_eq!(
            raw_in(rrf, &appid, security::ACCESS_PERMISSION).as_deref(),
            Some(access.as_slice()),
            "{what}"
        );
    }
}

/// What the MSI runs without SERVICE=1, `/RegServer /CreateGroup`, on a fresh
/// registration: the AppID's values in both views grant the clients' group when it exists
/// afterwards (remote access only through it), and the output says which: the group made
/// or found, or, where it cannot exist (Wine: `NetLocalGroupAdd` is a stub), the WARN
/// naming why and the descriptors without it.
#[test]
fn a_fresh_regserver_creategroup_grants_the_clients_group_or_says_why_not() {
    use ctopc_registration::security;
    let _restore = RestoreDefaults;
    assert!(run(&["/UnregServer"]).status.success());
    let out = run(&["/RegServer", "/CreateGroup"]);
    assert!(out.status.success(), "{out:?}");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let group = security::CLIENTS_GROUP;
    let clients = ctopc_com::caller::account_sid(group).and_then(|b| security::Sid::from_bytes(&b));
    match &clients {
        Some(sid) => {
            assert!(
                stdout.contains(&format!("created the local group \"{group}\""))
                    || stdout.contains(&format!("the local group \"{group}\" exists")),
                "{stdout}"
            );
            assert!(
                stdout.contains(&format!(
                    "the local group \"{group}\" ({sid}) may use the server"
                )),
                "{stdout}"
            );
        }
        None => {
            let why = ctopc_com::com::platform::local_group_missing_reason(group);
            assert!(stdout.contains(&format!("WARN: {why}")), "{stdout}");
            assert!(
                stdout.contains(&format!("WARN: no local group \"{group}\"")),
                "{stdout}"
            );
        }
    }
    let appid = format!("AppID\\{CLSID}");
    let access = security::default_access(false, clients.as_ref());
    let launch = security::default_launch(false, clients.as_ref());
    for (what, _, rrf) in VIEWS {
        for (name, want) in [
            (security::ACCESS_PERMISSION, &access),
            (security::LAUNCH_PERMISSION, &launch),
        ] {
            assert_eq!(
                raw_in(rrf, &appid, name).as_deref(),
                Some(want.to_bytes().as_slice()),
                "{what}: {name}"
            );
        }
        assert_eq!(
            raw_in(rrf, &appid, security::AUTHENTICATION_LEVEL).as_deref(),
            Some(&5u32.to_le_bytes()[..]),
            "{what}"
        );
    }
    // Remote access only through the group, when there is one.
    let remote: Vec<&security::Sid> = access
        .dacl
        .iter()
        .flatten()
        .filter(|a| a.allow && a.mask & security::COM_RIGHTS_EXECUTE_REMOTE != 0)
        .map(|a| &a.sid)
        .collect();
    assert_eq!(
        remote,
        clients.iter().collect::<Vec<_>>(),
        "{}",
        access.sddl()
    );
}

/// `/ProtectSecrets --config FILE` (what the MSI runs, without `--config`): a key the
/// configuration names, readable by Everyone, is private afterwards, the certificate store
/// and its private key folder are made; one line per path, exit 0; again, the same. Under
/// Wine a DACL read back is the one Wine makes from the Unix mode (`secret_file`), which
/// still shows who besides the owner may read.
#[test]
fn protect_secrets_makes_the_configurations_secrets_private() {
    use ctopc_com::com::secret_file::findings;
    let dir = std::env::temp_dir().join(format!("ctopc-protect-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(dir.join("certs")).unwrap();
    let ini = dir.join("ASIXConnect.ini");
    std::fs::write(
        &ini,
        "[Server]\r\nSimulateCurrentData = tak\r\n[Channel:K1]\r\nAsixNetCertFile = certs\\k1-cert.pem\r\nAsixNetKeyFile = certs\\k1.pem\r\n",
    )
    .unwrap();
    let key = dir.join("certs").join("k1.pem");
    std::fs::write(&key, b"-----BEGIN PRIVATE KEY-----\n").unwrap();
    // Opened to Everyone (under Wine: the others' bits).
    let mut open = ctopc_com::com::secret_file::read(&key).unwrap();
    open.dacl
        .get_or_insert_with(Vec::new)
        .push(security_ace_everyone());
    open.protected = false;
    ctopc_com::com::secret_file::set_dacl(&key, &open).unwrap();
    let before = findings(&key, &[]).unwrap_or_default();
    assert!(
        before.contains("Everyone (S-1-1-0) may read it"),
        "{before}"
    );
    for round in 0..2 {
        let out = run(&["/ProtectSecrets", "--config", ini.to_str().unwrap()]);
        let stdout = String::from_utf8_lossy(&out.stdout);
        assert!(out.status.success(), "round {round}: {out:?}");
        for line in [
            format!("asix link key [Channel:K1] {}: private", key.display()),
            format!(
                "OPC UA private key folder {}",
                dir.join("pki").join("private").display()
            ),
            "ProtectSecrets: 4 paths private, 2 not there yet, 0 failed".to_owned(),
        ] {
            assert!(stdout.contains(&line), "round {round}: {line} in {stdout}");
        }
        assert_eq!(findings(&key, &[]), None, "round {round}");
        for folder in [
            dir.join("pki"),
            dir.join("pki").join("private"),
            dir.join("certs"),
        ] {
            assert!(folder.is_dir(), "{}", folder.display());
            assert_eq!(findings(&folder, &[]), None, "{}", folder.display());
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// An allow ACE reading a file for Everyone.
fn security_ace_everyone() -> ctopc_registration::security::Ace {
    use ctopc_registration::security::{Ace, Sid, EVERYONE};
    Ace::allow(Sid::parse(EVERYONE).unwrap(), 0x0012_00A9)
}

/// `CLSID_StdComponentCategoriesMgr`.
const CLSID_STD_COMPONENT_CATEGORIES_MGR: GUID =
    GUID::from_u128(0x0002e005_0000_0000_c000_000000000046);

fn guid(s: &str) -> GUID {
    GUID::try_from(s.trim_matches(|c| c == '{' || c == '}')).expect("GUID")
}

#[test]
fn this_process_finds_the_server_by_category_and_by_progid() {
    let bits = 8 * std::mem::size_of::<usize>();
    let _com = e2e_tests::Apartment::mta().expect("CoInitializeEx");
    let clsid = guid(CLSID);
    // SAFETY: a valid NUL-terminated string.
    let found = unsafe { CLSIDFromProgID(windows::core::w!("ServerCTOPC.App")) };
    assert_eq!(found.ok(), Some(clsid), "{bits}-bit CLSIDFromProgID");
    // SAFETY: COM is initialised on this thread; the manager is an in-process system class.
    let cats: ICatInformation = unsafe {
        CoCreateInstance(
            &CLSID_STD_COMPONENT_CATEGORIES_MGR,
            None,
            CLSCTX_INPROC_SERVER,
        )
    }
    .expect("StdComponentCategoriesMgr");
    for cat in [CATID_DA20, CATID_DA30] {
        // SAFETY: a one-element slice valid for the call.
        let e = unsafe { cats.EnumClassesOfCategories(&[guid(cat)], &[]) }
            .expect("EnumClassesOfCategories");
        let mut classes = Vec::new();
        loop {
            let mut buf = [GUID::zeroed(); 16];
            let mut n = 0u32;
            // SAFETY: `buf` and `n` are valid for the call.
            let hr = unsafe { e.Next(&mut buf, Some(&mut n)) };
            classes.extend_from_slice(&buf[..n as usize]);
            if hr.0 != 0 || n == 0 {
                break;
            }
        }
        assert!(
            classes.contains(&clsid),
            "{bits}-bit EnumClassesOfCategories({cat}): {classes:?}"
        );
    }
}

#[test]
fn no_or_unknown_arguments_print_usage_and_fail() {
    for args in [&[][..], &["/Bogus"][..], &["RegServer"][..]] {
        let out = run(args);
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        assert!(
            String::from_utf8_lossy(&out.stderr).contains("usage: ServerCTOPC.exe"),
            "{args:?}"
        );
    }
    let help = run(&["/?"]);
    assert!(help.status.success() && String::from_utf8_lossy(&help.stdout).contains("/RegServer"));
}
