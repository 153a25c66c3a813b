//! /RegServer and /UnregServer: every key, idempotence, switch spellings, usage errors.
#![cfg(windows)]

use e2e_tests::artifact;
use windows::core::PCWSTR;
use windows::Win32::System::Registry::{
    RegCloseKey, RegGetValueW, RegOpenKeyExW, HKEY, HKEY_CLASSES_ROOT, KEY_READ, RRF_RT_REG_SZ,
};

const CLSID: &str = "{3277B556-BA68-4BDE-8687-8EE4E4B46336}";
const CATID_DA20: &str = "{63D5F432-CFE4-11D1-B2C8-0060083BA1FB}";
const CATID_DA30: &str = "{CC603642-66D7-48F1-B69A-B625E73652D7}";

fn run(args: &[&str]) -> std::process::Output {
    std::process::Command::new(artifact("ServerCTOPC.exe"))
        .args(args)
        .output()
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

fn key_exists(path: &str) -> bool {
    let p = wide(path);
    let mut k = HKEY::default();
    // SAFETY: valid strings and out handle.
    let ok = unsafe {
        RegOpenKeyExW(
            HKEY_CLASSES_ROOT,
            PCWSTR(p.as_ptr()),
            None,
            KEY_READ,
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
            RRF_RT_REG_SZ,
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

    for args in [["/RegServer"], ["-REGSERVER"]] {
        assert!(run(&args).status.success(), "{args:?}");
    }
    let exe = default_value(&format!("CLSID\\{CLSID}\\LocalServer32")).expect("LocalServer32");
    assert!(exe.contains("ServerCTOPC.exe"), "{exe}");
    assert_eq!(
        default_value(&format!("CLSID\\{CLSID}\\ProgID")).as_deref(),
        Some("ServerCTOPC.App.1")
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
