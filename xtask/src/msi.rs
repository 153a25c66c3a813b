//! The MSI installer: `target/dist/ServerCTOPC-<version>-x64.msi`, built by
//! `cargo xtask dist` with Debian's `wixl` from the template `installer/ServerCTOPC.wxs.in`.
//!
//! The server's registration is declarative (Registry table rows), generated from the
//! list `/RegServer` writes, `ctopc_registration::serverctopc(exe, service).keys()`,
//! with the exe `[INSTALLDIR]ServerCTOPC.exe`: one Win64 component for the 64-bit view,
//! one 32-bit component for the 32-bit view (Windows Installer writes a 32-bit
//! component's HKLM\Software\Classes keys through Wow6432Node), so the MSI and the exe
//! cannot drift (a test compares the built MSI's Registry table with the list).
//! `SERVICE=1` runs `ServerCTOPC.exe /Service /CreateGroup` as a deferred custom action,
//! without it `/RegServer /CreateGroup` (both with `/UnregServer` for rollback and
//! removal; a major upgrade's removal of the older version `/UnregServer /KeepSecurity`):
//! wixl 0.101 has no Component/Condition, so a conditional ServiceInstall component (and
//! AppID `LocalService` row) cannot be built, and no util:Group; and a Registry table can
//! neither know the clients' group's SID nor write the AppID's security values only where
//! absent. After them, at install and upgrade, the deferred `ServerCTOPC.exe
//! /ProtectSecrets` makes the files of secrets of the configuration the server finds (the
//! OPC UA certificate store, made when missing, its private key, the users file, the asix
//! link's keys) private (wixl has no LockPermissions, and a Registry-like table could not
//! follow the configuration's paths).
//!
//! The feature `Gate` (level 2, so off by default: `ADDLOCAL=ALL`) installs asix-gate, the
//! 32-bit gateway for the asix station, in `asix-gate\` with its example configuration
//! and its NT service (ServiceInstall/ServiceControl rows of the gate's component: on
//! demand, `asix-gate.exe -ServiceRun`, stopped and removed with the component).
//!
//! The proxy/stubs register themselves (deferred regsvr32 custom actions of the right
//! bitness in the template, with rollback and uninstall counterparts): their keys are
//! what widl generates from idl/ into DllRegisterServer, so the DLL itself stays the one
//! source of them.
//!
//! `cargo xtask msi-test` (also the last step of `cargo xtask test`): each part in a fresh
//! prefix, a `cp -a` of `target/wine/msi-template`, a prefix wineboot made and nothing
//! ran in (made once, about 65 s, then kept: a copy of it is as fresh). Each client
//! check starts the server once: a 64-bit and a 32-bit `opcdiag subscribe --count 3`
//! hold it while each bitness's opcdiag runs status, write, read back (from the device)
//! and servers, and must see the first value and both writes; the server's command line
//! (/proc) shows COM started `-Embedding`, after `SERVICE=1` the service (`-ServiceRun`).
//! The default install has no gate; the upgrade adds it (`ADDLOCAL=ALL`: the files and
//! the service are checked); the uninstall removes it. `/ProtectSecrets` is checked by
//! its lines in the server's log (one run at install, one more at the upgrade, nothing
//! failed) and by what Wine shows of a DACL, the Unix mode it maps it onto: the
//! certificate store, its private key folder and a users file copied in world-readable
//! before the upgrade have no others' bits (Everyone's) afterwards.
//! The three MSIs are built at once; a prefix copy is 1.3 GB. The time of each step, as
//! measured: docs/benchmarks.md (about 2 minutes with the template kept and the Windows
//! build up to date, about 3 from a clean target/wine, as in CI).
//!
//! Measured under Wine 8: `[SystemFolder]` is syswow64
//! (the 32-bit regsvr32), `[System64Folder]` system32; `icacls.exe` exists; removing a
//! Registry row's last value removes the emptied key; a failed `/qn` install exits with
//! the low byte of 1627 (91); `HKCR\AppID` is one key for both views (WOW64 shares it);
//! `NetLocalGroupAdd` is a stub (no group is made); a major upgrade removes the older
//! version without `UPGRADINGPRODUCTCODE`. Wine runs rollback custom actions only after its own
//! rollback removed the files, hence the 32-bit proxy/stub's registration comes first
//! (the template says why).

use ctopc_registration::{self as registration, Key, View};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;

/// The exe path the registration names: formatted by Windows Installer at install time.
pub const EXE_PATH: &str = "[INSTALLDIR]ServerCTOPC.exe";
/// Where the Registry rows live: HKEY_CLASSES_ROOT of a per-machine install.
pub const CLASSES: &str = "Software\\Classes";

/// The files of the package, in the zip's layout (`/`-separated, below the install
/// folder); `dist` passes its list, which holds these and may hold more.
pub const FILES: &[&str] = &[
    "ServerCTOPC.exe",
    "OpcServerList.exe",
    "opc_ps.dll",
    "opcdiag.exe",
    "x86/opc_ps.dll",
    "x86/opcdiag.exe",
    crate::dist::GATE_EXE,
    crate::dist::GATE_INI,
    "asixconnect.ini.example",
    "README.md",
    "docs/deployment.md",
    "docs/variable-database.md",
    "docs/asix-net-protocol.md",
    "docs/configuration.md",
    "docs/operations.md",
    "docs/asix-gate.md",
    "demo/wytwornia_kwasu/atrybuty.csv",
    "demo/wytwornia_kwasu/wytwornia_kwasu.zez",
];

/// The template.
pub fn template() -> PathBuf {
    crate::util::root().join("installer/ServerCTOPC.wxs.in")
}

fn xml(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// A stable component GUID per generated component (the component's identity across
/// versions: Windows Installer reference-counts by it).
fn component(view: View) -> (&'static str, &'static str, &'static str) {
    match view {
        View::Reg64 => ("Reg64", "9B0C5E21-3D5A-4F0B-8E7A-1B2C3D4E5F21", "yes"),
        View::Reg32 => ("Reg32", "9B0C5E21-3D5A-4F0B-8E7A-1B2C3D4E5F22", "no"),
    }
}

fn view_name(view: View) -> &'static str {
    match view {
        View::Reg64 => "64-bit view",
        View::Reg32 => "32-bit view (Wow6432Node)",
    }
}

/// The `<Component>` of one view's keys; the first value is its key path.
fn registry_component(view: View, keys: &[Key]) -> String {
    let (cid, guid, win64) = component(view);
    let mut s = String::new();
    let _ = writeln!(
        s,
        "      <!-- generated by xtask/src/msi.rs: {} -->\n      <Component Id=\"{cid}\" Guid=\"{guid}\" Win64=\"{win64}\">",
        view_name(view)
    );
    let mut key_path = true;
    for k in keys.iter().filter(|k| k.view == view) {
        let path = xml(&format!("{CLASSES}\\{}", k.path));
        if k.values.is_empty() {
            // Name `*`: the key is created, and removed on uninstall (wixl has no
            // RegistryKey/@Action).
            let _ = writeln!(
                s,
                "        <RegistryValue Root=\"HKLM\" Key=\"{path}\" Name=\"*\" Type=\"string\" Value=\"\"/>"
            );
        }
        for (name, value) in &k.values {
            let name_attr = if name.is_empty() {
                String::new()
            } else {
                format!(" Name=\"{}\"", xml(name))
            };
            let kp = if key_path { " KeyPath=\"yes\"" } else { "" };
            key_path = false;
            let _ = writeln!(
                s,
                "        <RegistryValue Root=\"HKLM\" Key=\"{path}\"{name_attr} Type=\"string\" Value=\"{}\"{kp}/>",
                xml(value)
            );
        }
    }
    s.push_str("      </Component>\n");
    s
}

/// The WiX source: the template with the version, the staging folder and the generated
/// registration filled in.
pub fn wxs(template: &str, version: &str, stage: &Path) -> String {
    let keys = registration::serverctopc(EXE_PATH, None).keys();
    let mut reg = String::new();
    let mut refs = String::new();
    for view in registration::VIEWS {
        reg.push_str(&registry_component(view, &keys));
        let _ = writeln!(refs, "      <ComponentRef Id=\"{}\"/>", component(view).0);
    }
    template
        .replace("@VERSION@", version)
        .replace("@STAGE@", &stage.display().to_string().replace('\\', "/"))
        .replace("@REGISTRY@", reg.trim_end())
        .replace("@COMPONENT_REFS@", refs.trim_end())
}

/// Stages `files` (`(name in the package, source)`) under `stage`, checks that every file
/// the package needs is there (a clear message, not wixl's), writes the WiX source and
/// builds `out` with wixl.
pub fn build(
    files: &[(String, PathBuf)],
    version: &str,
    stage: &Path,
    out: &Path,
) -> Result<PathBuf, String> {
    if stage.exists() {
        std::fs::remove_dir_all(stage).map_err(|e| format!("{}: {e}", stage.display()))?;
    }
    for (name, src) in files {
        let dest = stage.join(name);
        if let Some(d) = dest.parent() {
            std::fs::create_dir_all(d).map_err(|e| format!("{}: {e}", d.display()))?;
        }
        std::fs::copy(src, &dest).map_err(|e| {
            format!(
                "msi: cannot stage {name} from {}: {e} (run `cargo xtask build` first?)",
                src.display()
            )
        })?;
    }
    let missing: Vec<&str> = FILES
        .iter()
        .copied()
        .filter(|f| !stage.join(f).is_file())
        .collect();
    if !missing.is_empty() {
        return Err(format!(
            "msi: the package lacks {} (not in the staged files under {})",
            missing.join(", "),
            stage.display()
        ));
    }
    let tpl = std::fs::read_to_string(template())
        .map_err(|e| format!("{}: {e}", template().display()))?;
    let src = out.with_extension("wxs");
    // wixl takes File/@Source relative to its working directory (an absolute one
    // fails): the sources name files below `.`, wixl runs in the staging folder.
    std::fs::write(&src, wxs(&tpl, version, Path::new(".")))
        .map_err(|e| format!("{}: {e}", src.display()))?;
    wixl(&src, out, stage)?;
    mark_rollback_actions(out)?;
    Ok(out.to_path_buf())
}

/// `msidbCustomActionTypeRollback`: wixl 0.101 ignores `Execute="rollback"` (it writes
/// such an action as an immediate one, which would run while the script is made), so
/// the actions named `Rollback*` get the bit here, through msitools' msibuild.
const ROLLBACK: u32 = 0x100;
/// `msidbCustomActionTypeInScript`: a rollback action is one of the script's (deferred
/// with the rollback bit); with the rollback bit alone (an immediate type, as wixl
/// writes it) Windows Installer and Wine never schedule it, and a failed install left
/// the 64-bit proxy/stub registered (msi-test's broken package).
const IN_SCRIPT: u32 = 0x400;

fn mark_rollback_actions(msi: &Path) -> Result<(), String> {
    let text = crate::util::output(
        Command::new("msiinfo")
            .arg("export")
            .arg(msi)
            .arg("CustomAction"),
    )?;
    let mut out = String::new();
    for (i, line) in text.lines().enumerate() {
        let mut cols: Vec<String> = line.split('\t').map(str::to_owned).collect();
        if i >= 3 && cols[0].starts_with("Rollback") {
            let t: u32 = cols[1]
                .parse()
                .map_err(|e| format!("CustomAction type {:?}: {e}", cols[1]))?;
            cols[1] = (t | IN_SCRIPT | ROLLBACK).to_string();
        }
        out.push_str(&cols.join("\t"));
        out.push_str("\r\n");
    }
    let idt = msi.with_extension("CustomAction.idt");
    std::fs::write(&idt, out).map_err(|e| format!("{}: {e}", idt.display()))?;
    crate::util::output(Command::new("msibuild").arg(msi).arg("-i").arg(&idt)).map(|_| ())
}

/// `wixl -a x64 -o out src`, with what to do when wixl is missing.
pub fn wixl(src: &Path, out: &Path, dir: &Path) -> Result<(), String> {
    let abs = |p: &Path| std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf());
    let mut c = Command::new("wixl");
    c.current_dir(dir)
        .args(["-a", "x64", "-o"])
        .arg(abs(out))
        .arg(abs(src));
    match c.output() {
        Err(e) => Err(format!(
            "cannot run wixl ({e}): install it with `cargo xtask setup` (Debian package wixl)"
        )),
        Ok(o) if !o.status.success() => Err(format!(
            "wixl failed on {}: {}\n{}",
            src.display(),
            o.status,
            String::from_utf8_lossy(&o.stderr)
        )),
        Ok(_) => Ok(()),
    }
}

/// The MSI's name for `version`.
pub fn file_name(version: &str) -> String {
    format!("ServerCTOPC-{version}-x64.msi")
}

/// `cargo xtask dist`'s call: the MSI next to the zip, from the zip's file list.
pub fn dist(files: &[(String, PathBuf)], version: &str) -> Result<PathBuf, String> {
    let dir = crate::util::root().join("target/dist");
    let out = build(
        files,
        version,
        &dir.join("msi-stage"),
        &dir.join(file_name(version)),
    )?;
    println!("dist: {}", out.display());
    Ok(out)
}

// ---------------------------------------------------------------------------------------
// The AppID's security values in a Wine prefix's `system.reg` (lowercased text), for
// `msi-test`: pure, tested below.

/// The `[head]` section of a Wine registry file (its value lines, up to the blank line).
pub fn reg_section<'a>(reg: &'a str, head: &str) -> Option<&'a str> {
    let start = reg
        .lines()
        .position(|l| l.starts_with(head))
        .map(|i| reg.lines().take(i).map(|l| l.len() + 1).sum::<usize>())?;
    let body = &reg[start..];
    let end = body.find("\n\n").unwrap_or(body.len());
    Some(&body[..end])
}

/// The `"name"=hex:..` value of a section (Wine continues long ones with `\` and an
/// indented line).
pub fn reg_hex(section: &str, name: &str) -> Option<Vec<u8>> {
    let key = format!("\"{name}\"=hex:");
    let at = section.find(&key)? + key.len();
    let mut out = Vec::new();
    for line in section[at..].lines() {
        let l = line.trim();
        let (bytes, more) = match l.strip_suffix('\\') {
            Some(b) => (b, true),
            None => (l, false),
        };
        for b in bytes.split(',').filter(|b| !b.is_empty()) {
            out.push(u8::from_str_radix(b, 16).ok()?);
        }
        if !more {
            break;
        }
    }
    Some(out)
}

/// The `"name"=dword:..` value of a section.
pub fn reg_dword(section: &str, name: &str) -> Option<u32> {
    let key = format!("\"{name}\"=dword:");
    let at = section.find(&key)? + key.len();
    u32::from_str_radix(section[at..].get(..8)?, 16).ok()
}

/// The AppID key's head of `view` in a lowercased `system.reg`.
pub fn appid_head(view: View) -> String {
    let guid = registration::guid_string(registration::CLSID_SERVERCTOPC).to_ascii_lowercase();
    match view {
        View::Reg64 => format!("[software\\\\classes\\\\appid\\\\{guid}]"),
        View::Reg32 => {
            format!("[software\\\\classes\\\\wow6432node\\\\appid\\\\{guid}]")
        }
    }
}

/// Checks the AppID's `AccessPermission`, `LaunchPermission` (the defaults for `service`,
/// granting the clients' group when `clients` is its SID) and `AuthenticationLevel`
/// (`level`) in both views; one line per view, or what differs.
pub fn appid_security(
    reg: &str,
    service: bool,
    clients: Option<&registration::security::Sid>,
    level: u32,
) -> Result<Vec<String>, String> {
    use registration::security::{self as sec, Descriptor};
    let mut out = Vec::new();
    for view in registration::VIEWS {
        let head = appid_head(view);
        let section = match reg_section(reg, &head) {
            Some(s) => s,
            // `HKLM\Software\Classes\AppID` is a key WOW64 shares (not redirected) since
            // Windows 7, and so in Wine: both views are the one key checked already.
            None if view == View::Reg32 && !out.is_empty() => {
                out.push(format!(
                    "{view:?}: the same key (HKCR\\AppID is shared by both registry views)"
                ));
                continue;
            }
            None => return Err(format!("no key {head}")),
        };
        for (name, want) in [
            ("accesspermission", sec::default_access(service, clients)),
            ("launchpermission", sec::default_launch(service, clients)),
        ] {
            let got = reg_hex(section, name).ok_or_else(|| format!("{head}: no {name}"))?;
            if got != want.to_bytes() {
                let text =
                    Descriptor::from_bytes(&got).map_or("not a descriptor".into(), |d| d.sddl());
                return Err(format!(
                    "{head}: {name} is {text}, not the default {}",
                    want.sddl()
                ));
            }
        }
        match reg_dword(section, "authenticationlevel") {
            Some(l) if l == level => {}
            other => {
                return Err(format!(
                    "{head}: authenticationlevel is {other:?}, not {level}"
                ))
            }
        }
        out.push(format!(
            "{view:?}: AccessPermission {}, LaunchPermission {}, AuthenticationLevel {level}",
            sec::default_access(service, clients).sddl(),
            sec::default_launch(service, clients).sddl()
        ));
    }
    Ok(out)
}

/// Whether the msiexec log `log` (`/l*v`) has the action `name` ending with success:
/// `Action ended <time>: <name>. Return value 1.` (Windows Installer's format, and Wine's
/// msi's, which logs a deferred action when it is scheduled and again when it runs).
pub fn action_succeeded(log: &str, name: &str) -> bool {
    let tail = format!(": {name}. Return value 1.");
    log.lines()
        .any(|l| l.starts_with("Action ended ") && l.trim_end().ends_with(&tail))
}

/// Whether the msiexec log `log` has the action `name` at all (started or ended).
pub fn action_ran(log: &str, name: &str) -> bool {
    let tail = format!(": {name}.");
    log.lines().any(|l| {
        (l.starts_with("Action ended ") || l.starts_with("Action start "))
            && (l.trim_end().ends_with(&tail) || l.contains(&format!("{tail} Return value")))
    })
}

#[cfg(test)]
/// The rows of an MSI table as `msiinfo export` prints them (tab-separated, after three
/// header lines).
pub fn table(msi: &Path, name: &str) -> Result<Vec<Vec<String>>, String> {
    let text = crate::util::output(Command::new("msiinfo").arg("export").arg(msi).arg(name))?;
    Ok(text
        .lines()
        .skip(3)
        .filter(|l| !l.is_empty())
        .map(|l| l.split('\t').map(str::to_owned).collect())
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeSet;

    /// A staging folder of placeholder files (the MSI's registration does not depend on
    /// their contents), the MSI built from it.
    fn built_msi(tag: &str) -> PathBuf {
        let dir = crate::util::root().join(format!("target/msi-unit-{tag}"));
        let src = dir.join("src");
        std::fs::create_dir_all(&src).unwrap();
        let files: Vec<(String, PathBuf)> = FILES
            .iter()
            .map(|f| {
                let p = src.join(f.replace('/', "_"));
                std::fs::write(&p, f.as_bytes()).unwrap();
                ((*f).to_owned(), p)
            })
            .collect();
        build(&files, "0.1.0", &dir.join("stage"), &dir.join("t.msi")).unwrap()
    }

    type Row = (bool, String, String, String);

    /// The Registry table as (64-bit component?, key, name, value); empty keys as "*".
    fn registry_rows(msi: &Path) -> Vec<Row> {
        let comps = table(msi, "Component").unwrap();
        let win64 = |c: &str| {
            let row = comps.iter().find(|r| r[0] == c).unwrap();
            row[3].parse::<u32>().unwrap() & 256 != 0
        };
        let reg = table(msi, "Registry").unwrap();
        reg.iter()
            .filter(|r| r[2].starts_with(CLASSES))
            .map(|r| {
                assert_eq!(r[1], "2", "HKLM: {r:?}");
                (
                    win64(&r[5]),
                    r[2].clone(),
                    r.get(3).cloned().unwrap_or_default(),
                    r.get(4).cloned().unwrap_or_default(),
                )
            })
            .collect()
    }

    fn expected(keys: &[Key]) -> Vec<Row> {
        keys.iter()
            .flat_map(|k| {
                let path = format!("{CLASSES}\\{}", k.path);
                let w64 = k.view == View::Reg64;
                if k.values.is_empty() {
                    vec![(w64, path, "*".to_owned(), String::new())]
                } else {
                    k.values
                        .iter()
                        .map(|(n, v)| (w64, path.clone(), n.clone(), v.clone()))
                        .collect()
                }
            })
            .collect()
    }

    #[test]
    fn the_msi_registers_exactly_what_regserver_writes() {
        let msi = built_msi("reg");
        let rows = registry_rows(&msi);
        let keys = registration::serverctopc(EXE_PATH, None).keys();
        let as_set = |v: Vec<Row>| v.into_iter().collect::<BTreeSet<_>>();
        let want = expected(&keys);
        assert_eq!(rows.len(), want.len(), "no row twice");
        assert_eq!(as_set(rows.clone()), as_set(want));
        // Both views, and the exe is the installed one.
        assert!(rows.iter().any(|r| r.0) && rows.iter().any(|r| !r.0));
        assert!(rows
            .iter()
            .any(|r| r.1.ends_with("LocalServer32") && r.3 == "\"[INSTALLDIR]ServerCTOPC.exe\""));
    }

    #[test]
    fn the_package_holds_every_file_and_the_upgrade_code_is_stable() {
        let msi = built_msi("files");
        let files: BTreeSet<String> = table(&msi, "File")
            .unwrap()
            .iter()
            .map(|r| r[2].rsplit('|').next().unwrap_or_default().to_owned())
            .collect();
        for f in FILES {
            let name = f.rsplit('/').next().unwrap();
            assert!(files.contains(name), "{name} in {files:?}");
        }
        assert!(!files
            .iter()
            .any(|f| f.eq_ignore_ascii_case("ASIXConnect.ini")));
        let props = table(&msi, "Property").unwrap();
        let upgrade = props.iter().find(|r| r[0] == "UpgradeCode").unwrap();
        assert_eq!(upgrade[1], "{6F1D3B2A-7C44-4E8B-9A5D-2C0E8B7F4A11}");
        // Per machine: wixl turns Package/@InstallScope into ALLUSERS.
        assert!(
            props.iter().any(|r| r[0] == "ALLUSERS" && r[1] == "1"),
            "{props:?}"
        );
        let actions = table(&msi, "CustomAction").unwrap();
        let service = actions.iter().find(|r| r[0] == "InstallService").unwrap();
        assert_eq!(service[3], "/Service /CreateGroup");
        let security = actions.iter().find(|r| r[0] == "InstallSecurity").unwrap();
        assert_eq!(security[3], "/RegServer /CreateGroup");
        let upgrade = actions
            .iter()
            .find(|r| r[0] == "UpgradeUninstallServer")
            .unwrap();
        assert_eq!(upgrade[3], "/UnregServer /KeepSecurity");
        // The files of secrets: deferred (0x400), not impersonated (0x800), its exit code
        // checked (no 0x40), at install and upgrade, after the registration.
        let protect = actions.iter().find(|r| r[0] == "LockSecrets").unwrap();
        assert_eq!(protect[3], "/ProtectSecrets");
        let t = protect[1].parse::<u32>().unwrap();
        assert_eq!(t & (0x400 | 0x800 | 0x40), 0x400 | 0x800, "{protect:?}");
        let sequence = table(&msi, "InstallExecuteSequence").unwrap();
        let at = |a: &str| sequence.iter().find(|r| r[0] == a).unwrap().clone();
        assert_eq!(at("LockSecrets")[1], "NOT REMOVE=\"ALL\"");
        let seq = |a: &str| at(a)[2].parse::<u32>().unwrap();
        assert!(seq("LockSecrets") > seq("InstallSecurity").max(seq("InstallService")));
        // A major upgrade removes the older version before this one is installed (wixl
        // sequences it after InstallFinalize for some action names: the template says so).
        assert_eq!(
            seq("RemoveExistingProducts"),
            seq("InstallValidate") + 1,
            "{sequence:?}"
        );
        for a in actions.iter().filter(|r| r[0].starts_with("Rollback")) {
            let t = a[1].parse::<u32>().unwrap();
            assert_eq!(t & (IN_SCRIPT | ROLLBACK), IN_SCRIPT | ROLLBACK, "{a:?}");
        }
    }

    /// asix-gate is a feature of its own, off by default, whose component carries the
    /// gate's service (installed on demand, stopped and removed with the component).
    #[test]
    fn the_gate_is_a_feature_off_by_default_with_its_service() {
        let msi = built_msi("gate");
        let features = table(&msi, "Feature").unwrap();
        let level = |id: &str| -> u32 {
            let row = features.iter().find(|r| r[0] == id).unwrap();
            // Feature, Feature_Parent, Title, Description, Display, Level, ...
            row[5].parse().unwrap()
        };
        assert_eq!(level("Complete"), 1);
        assert!(level("Gate") > 1, "INSTALLLEVEL is 1: {features:?}");
        let in_feature = table(&msi, "FeatureComponents").unwrap();
        for c in ["Gate", "GateIniExample"] {
            assert!(
                in_feature.iter().any(|r| r[0] == "Gate" && r[1] == c),
                "{c} in {in_feature:?}"
            );
            assert!(!in_feature.iter().any(|r| r[0] == "Complete" && r[1] == c));
        }
        let files = table(&msi, "File").unwrap();
        let gate_exe = files.iter().find(|r| r[0] == "GateExe").unwrap();
        assert_eq!(gate_exe[1], "Gate");
        let install = table(&msi, "ServiceInstall").unwrap();
        // ServiceInstall, Name, DisplayName, ServiceType, StartType, ErrorControl,
        // LoadOrderGroup, Dependencies, StartName, Password, Arguments, Component_, ...
        let svc = install.iter().find(|r| r[1] == "AsixGate").unwrap();
        assert_eq!(svc[3], "16", "SERVICE_WIN32_OWN_PROCESS");
        assert_eq!(svc[4], "3", "SERVICE_DEMAND_START");
        assert_eq!(svc[10], "-ServiceRun");
        assert_eq!(svc[11], "Gate");
        let control = table(&msi, "ServiceControl").unwrap();
        let ctl = control.iter().find(|r| r[1] == "AsixGate").unwrap();
        // Event: stop on install and uninstall (0x2 | 0x20), delete on uninstall (0x80).
        assert_eq!(ctl[2].parse::<u32>().unwrap(), 0x2 | 0x20 | 0x80);
        assert_eq!(ctl[5], "Gate");
    }

    /// A `system.reg` as Wine writes it: the AppID key in both views, a long binary value
    /// continued over lines.
    #[test]
    fn the_appid_security_values_are_read_from_a_wine_registry() {
        use registration::security::{default_access, default_launch};
        let hex = |b: &[u8]| -> String {
            let all: Vec<String> = b.iter().map(|x| format!("{x:02x}")).collect();
            all.chunks(20)
                .map(|c| c.join(","))
                .collect::<Vec<_>>()
                .join(",\\\n  ")
        };
        let key = |view: View, level: u32| {
            format!(
                "{} 1733450000\n#time=1db47\n@=\"ServerCTOPC\"\n\"accesspermission\"=hex:{}\n\"authenticationlevel\"=dword:{level:08x}\n\"launchpermission\"=hex:{}\n\n",
                appid_head(view),
                hex(&default_access(false, None).to_bytes()),
                hex(&default_launch(false, None).to_bytes())
            )
        };
        let reg = format!(
            "WINE REGISTRY Version 2\n\n[software\\\\classes\\\\clsid] 1\n\n{}{}",
            key(View::Reg64, 5),
            key(View::Reg32, 5)
        );
        let lines = appid_security(&reg, false, None, 5).unwrap();
        assert_eq!(lines.len(), 2);
        assert!(
            lines[0].starts_with("Reg64: AccessPermission O:S-1-5-32-544"),
            "{lines:?}"
        );
        // Another level, the service's descriptor, a missing view: each named.
        let e = appid_security(&reg, false, None, 6).unwrap_err();
        assert!(e.contains("authenticationlevel is Some(5), not 6"), "{e}");
        let e = appid_security(&reg, true, None, 5).unwrap_err();
        assert!(e.contains("accesspermission is O:S-1-5-32-544"), "{e}");
        // The AppID key is shared by both views (what Wine's registry holds): one key.
        let shared = key(View::Reg64, 5);
        let lines = appid_security(&shared, false, None, 5).unwrap();
        assert!(lines[1].starts_with("Reg32: the same key"), "{lines:?}");
        let only32 = key(View::Reg32, 5);
        let e = appid_security(&only32, false, None, 5).unwrap_err();
        assert!(e.starts_with("no key [software\\\\classes\\\\appid"), "{e}");
        assert_eq!(reg_dword("\"x\"=dword:0000000a", "x"), Some(10));
        assert_eq!(
            reg_hex("\"x\"=hex:01,ff,\\\n  02\n\"y\"=hex:03", "x"),
            Some(vec![1, 255, 2])
        );
        assert_eq!(reg_hex("\"x\"=hex:zz", "x"), None);
    }

    /// Lines as Wine 8's msi writes them (measured): an action ran and succeeded; one
    /// with a name that only starts the same (`InstallService` / `InstallServices`) is
    /// another.
    #[test]
    fn the_actions_are_read_from_an_msiexec_log() {
        let log = "Action start 7:31:02: InstallServices.\n\
                   Action ended 7:31:02: InstallServices. Return value 1.\n\
                   Action start 7:31:20: InstallSecurity.\n\
                   Action ended 7:31:21: InstallSecurity. Return value 1.\n\
                   Action start 7:31:21: ProtectSecrets.\n\
                   Action ended 7:31:23: ProtectSecrets. Return value 3.\n";
        assert!(action_succeeded(log, "InstallSecurity"));
        assert!(!action_succeeded(log, "ProtectSecrets"));
        assert!(action_ran(log, "ProtectSecrets"));
        assert!(!action_succeeded(log, "InstallService"));
        assert!(!action_ran(log, "InstallService"));
        assert!(action_ran(log, "InstallServices"));
    }

    #[test]
    fn a_missing_file_stops_the_build_with_its_name() {
        let dir = crate::util::root().join("target/msi-unit-missing");
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("x");
        std::fs::write(&p, b"x").unwrap();
        let files = vec![("ServerCTOPC.exe".to_owned(), p)];
        let e = build(&files, "0.1.0", &dir.join("stage"), &dir.join("t.msi")).unwrap_err();
        assert!(e.contains("lacks OpcServerList.exe, opc_ps.dll"), "{e}");
    }

    #[test]
    fn a_failed_subscribers_output_is_its_error_without_our_first_line() {
        // The start-failure rule it feeds: `wine::start::silent_start_failure`.
        use wine_test::subscriber_output;
        assert_eq!(
            subscriber_output("opcdiag subscribe (X64): exit status: 1\n"),
            ""
        );
        assert_eq!(
            subscriber_output("opcdiag subscribe (X64): exit status: 1\nSubscribed"),
            "Subscribed"
        );
        assert_eq!(subscriber_output("one line"), "");
    }
}

// ---------------------------------------------------------------------------------------
// `cargo xtask msi-test`: the MSI under Wine, in a fresh prefix of its own.

mod wine_test {
    use super::*;
    use crate::arch::Arch;
    use crate::wine::{self, forgiven, start};
    use crate::{build, util};
    use std::io::BufRead as _;
    use std::process::{Child, Stdio};
    use std::sync::mpsc::{self, Receiver, RecvTimeoutError};
    use std::time::{Duration, Instant};

    const CLSID: &str = "3277B556-BA68-4BDE-8687-8EE4E4B46336";
    const INSTALL: &str = "drive_c/Program Files/ServerCTOPC";
    /// The Start-menu folder: Windows Installer puts a per-machine (ALLUSERS=1) install's
    /// into the common one, Wine 8's msi into the installing user's (measured).
    fn menus() -> [String; 2] {
        let user = std::env::var("USER").unwrap_or_else(|_| "root".into());
        [
            "drive_c/ProgramData/Microsoft/Windows/Start Menu/Programs/ServerCTOPC".into(),
            format!(
                "drive_c/users/{user}/AppData/Roaming/Microsoft/Windows/Start Menu/Programs/ServerCTOPC"
            ),
        ]
    }
    /// A log of the user's, which no install, upgrade or removal may touch.
    const USER_LOG: &str = "Log/ServerCTOPC.20260101.log";
    /// The writable demo set point the clients write, read back and subscribe to.
    const SETPOINT: &str = "KW_A110";
    /// What each client writes to it (exact in R4, unlike the demo's own values).
    fn written(arch: Arch) -> &'static str {
        match arch {
            Arch::X64 => "11.25",
            Arch::X86 => "12.75",
        }
    }

    /// Prints each step with the seconds since the start (docs/benchmarks.md lists a run's).
    struct Clock(Instant);

    impl Clock {
        fn lap(&self, what: &str) {
            println!("msi-test: [{:>4} s] {what}", self.0.elapsed().as_secs());
        }
    }

    /// What a failed [`Subscriber::finish`] printed: its error without the first line
    /// (`opcdiag subscribe (..): exit status: N`), which is ours.
    pub(crate) fn subscriber_output(err: &str) -> &str {
        err.split_once('\n').map_or("", |(_, rest)| rest)
    }

    /// A background `opcdiag subscribe`: its stdout lines arrive on `rx`.
    struct Subscriber {
        arch: Arch,
        child: Child,
        rx: Receiver<String>,
        lines: Vec<String>,
    }

    impl Subscriber {
        /// Waits for a line containing `needle` (or the end of the output).
        fn wait_for(&mut self, needle: &str, limit: Duration) -> bool {
            let deadline = Instant::now() + limit;
            loop {
                if self.lines.iter().any(|l| l.contains(needle)) {
                    return true;
                }
                let left = deadline.saturating_duration_since(Instant::now());
                match self.rx.recv_timeout(left) {
                    Ok(l) => self.lines.push(l),
                    Err(_) => return false,
                }
            }
        }

        /// Its whole output once it ended by itself (`--count` or `--for`).
        fn finish(mut self, limit: Duration) -> Result<String, String> {
            let deadline = Instant::now() + limit;
            loop {
                let left = deadline.saturating_duration_since(Instant::now());
                match self.rx.recv_timeout(left) {
                    Ok(l) => self.lines.push(l),
                    Err(RecvTimeoutError::Disconnected) => break,
                    Err(RecvTimeoutError::Timeout) => {
                        let _ = self.child.kill();
                        break;
                    }
                }
            }
            let status = self
                .child
                .wait()
                .map_err(|e| format!("opcdiag subscribe: {e}"))?;
            let out = self.lines.join("\n");
            if status.success() {
                Ok(out)
            } else {
                Err(format!(
                    "opcdiag subscribe ({:?}): {status}\n{out}",
                    self.arch
                ))
            }
        }
    }

    struct Ctx {
        pfx: PathBuf,
        dir: PathBuf,
    }

    fn winpath(p: &Path) -> String {
        format!(
            "Z:{}",
            std::path::absolute(p)
                .unwrap_or_else(|_| p.to_path_buf())
                .display()
                .to_string()
                .replace('/', "\\")
        )
    }

    impl Ctx {
        /// Wine's environment for the test prefix; no winemenubuilder, which would put
        /// the package's Start-menu entries into this machine's desktop menus.
        fn env(&self, c: &mut Command) {
            wine::env(c);
            c.env("WINEPREFIX", &self.pfx)
                .env("WINEDLLOVERRIDES", "mscoree,mshtml=;winemenubuilder.exe=d");
        }

        /// What the install put in place besides the files: the Start-menu entries, and
        /// each proxy/stub registered in its own view only (the 32-bit one, in x86\, in
        /// Wow6432Node).
        fn installed(&self, what: &str) -> Result<(), String> {
            for lnk in [
                "Deployment guide.lnk",
                "ServerCTOPC status (opcdiag status).lnk",
            ] {
                if !menus().iter().any(|m| self.pfx.join(m).join(lnk).is_file()) {
                    return Err(format!("{what}: no Start-menu entry {lnk}"));
                }
            }
            let reg = self.system_reg();
            let mut header = "";
            let (mut ps64, mut ps32) = (false, false);
            for line in reg.lines() {
                if line.starts_with('[') {
                    header = line;
                } else if header.contains("\\\\clsid\\\\")
                    && line.contains("serverctopc\\\\")
                    && line.contains("opc_ps.dll")
                {
                    let wow = header.contains("wow6432node");
                    let x86 = line.contains("\\\\x86\\\\opc_ps.dll");
                    if wow != x86 {
                        return Err(format!(
                            "{what}: a proxy/stub in the wrong view: {header} {line}"
                        ));
                    }
                    ps64 |= !x86;
                    ps32 |= x86;
                }
            }
            if !(ps64 && ps32) {
                return Err(format!(
                    "{what}: proxy/stubs registered: 64-bit {ps64}, 32-bit {ps32}"
                ));
            }
            println!("msi-test: {what}: both Start-menu entries; each proxy/stub in its own view");
            Ok(())
        }

        /// Runs `program args` under Wine in the test prefix (`arch`'s loader), bounded
        /// by `limit`, and returns (exit code, stdout + stderr).
        fn run(&self, arch: Arch, program: &str, args: &[&str], limit: u64) -> (i32, String) {
            let mut c = Command::new("timeout");
            self.env(&mut c);
            c.arg(limit.to_string())
                .arg(arch.loader())
                .arg(program)
                .args(args);
            match c.output() {
                Ok(o) => (
                    o.status.code().unwrap_or(-1),
                    format!(
                        "{}{}",
                        String::from_utf8_lossy(&o.stdout),
                        String::from_utf8_lossy(&o.stderr)
                    ),
                ),
                Err(e) => (-1, format!("cannot start wine: {e}")),
            }
        }

        fn msiexec(&self, op: &str, msi: &Path, extra: &[&str], log: &str) -> i32 {
            let log = self.dir.join(log);
            let (m, l) = (winpath(msi), winpath(&log));
            let mut args = vec![op, m.as_str(), "/qn", "/l*v", l.as_str()];
            args.extend_from_slice(extra);
            let (code, _) = self.run(Arch::X64, "msiexec", &args, 300);
            self.settle();
            code
        }

        /// Ends every process of the prefix and waits for the registry to be written.
        fn settle(&self) {
            wine::wineserver_in(&self.pfx, "-k", Duration::from_secs(20));
            wine::wineserver_in(&self.pfx, "-w", Duration::from_secs(60));
        }

        fn install_dir(&self) -> PathBuf {
            self.pfx.join(INSTALL)
        }

        /// The AppID's security values in both views: the defaults of a plain install
        /// (without the clients' group, which Wine cannot create: [`Self::clients_group`]),
        /// authentication level `level`.
        fn security(&self, what: &str, service: bool, level: u32) -> Result<(), String> {
            let lines = appid_security(&self.system_reg(), service, None, level)
                .map_err(|e| format!("msi-test: {what}: AppID security: {e}"))?;
            for l in lines {
                println!("msi-test: {what}: AppID {l}");
            }
            Ok(())
        }

        /// The clients' group under Wine: `NetLocalGroupAdd` is a stub (success, no group),
        /// so the MSI's `/RegServer /CreateGroup` says so and the descriptors leave the
        /// group out ([`Self::security`]). Asserted as that limitation: the same command,
        /// run again here, prints the WARN naming it.
        fn clients_group(&self) -> Result<(), String> {
            let exe = "C:\\Program Files\\ServerCTOPC\\ServerCTOPC.exe";
            let (code, out) = self.run(Arch::X64, exe, &["/RegServer", "/CreateGroup"], 120);
            self.settle();
            let warn = out
                .lines()
                .find(|l| l.contains("Wine's NetLocalGroupAdd is a stub"))
                .map(str::to_owned);
            match (code, warn) {
                (0, Some(w)) => {
                    println!("msi-test: the clients' group (Wine limitation, as documented): {w}");
                    Ok(())
                }
                _ => Err(format!(
                    "msi-test: `ServerCTOPC.exe /RegServer /CreateGroup`: exit {code}, no WARN about Wine's NetLocalGroupAdd:\n{out}"
                )),
            }
        }

        /// The msiexec log `log` (in the test's folder): each of `ran` succeeded, none of
        /// `not` ran (its condition false). The deferred actions' own output goes nowhere
        /// (no console): this is how the test knows the MSI ran them.
        fn actions(&self, log: &str, ran: &[&str], not: &[&str]) -> Result<(), String> {
            let path = self.dir.join(log);
            let raw = std::fs::read(&path).map_err(|e| format!("{}: {e}", path.display()))?;
            // Windows Installer may write UTF-16; Wine writes ASCII.
            let text: String = String::from_utf8_lossy(&raw).replace('\0', "");
            for a in ran {
                if !action_succeeded(&text, a) {
                    return Err(format!(
                        "msi-test: {log}: the action {a} did not end with success ({})",
                        path.display()
                    ));
                }
            }
            for a in not {
                if action_ran(&text, a) {
                    return Err(format!("msi-test: {log}: the action {a} ran"));
                }
            }
            println!(
                "msi-test: {log}: {} ran and succeeded; {} did not run",
                ran.join(", "),
                not.join(", ")
            );
            Ok(())
        }

        /// `/ProtectSecrets`, the MSI's deferred action at install and upgrade: by now
        /// `runs` times, each a summary line with nothing failed in the server's log
        /// (`Log\ServerCTOPC.<date>.log`: the action's output has no console), with the
        /// OPC UA certificate store and its private key folder made private, and each of
        /// `files` (below the install folder) named private. What Wine can show of the
        /// DACLs: it keeps none, but maps one set onto the Unix mode (an allow ACE for
        /// Everyone becomes the others' bits; the holders', measured, the user's and the
        /// group's: a folder made private is 0770), so each path made private has no
        /// others' bits, where Wine made the folders 0755 and the users file was 0644.
        fn secrets(&self, what: &str, runs: usize, files: &[&str]) -> Result<(), String> {
            let log_dir = self.install_dir().join("Log");
            let mut lines = Vec::new();
            for f in walk(&log_dir) {
                let name = f.file_name().map(|n| n.to_string_lossy().into_owned());
                if name.is_some_and(|n| n.starts_with("ServerCTOPC.") && n.ends_with(".log")) {
                    let text = std::fs::read(&f).unwrap_or_default();
                    lines.extend(
                        String::from_utf8_lossy(&text)
                            .lines()
                            .filter(|l| l.contains("ProtectSecrets: "))
                            .map(str::to_owned),
                    );
                }
            }
            let summaries: Vec<&String> = lines
                .iter()
                .filter(|l| l.contains(" not there yet, "))
                .collect();
            let fail = |why: String| {
                Err(format!(
                    "msi-test: {what}: /ProtectSecrets: {why}; its lines in {}:\n{}",
                    log_dir.display(),
                    lines.join("\n")
                ))
            };
            if summaries.len() != runs {
                return fail(format!("{} runs logged, not {runs}", summaries.len()));
            }
            if let Some(s) = summaries.iter().find(|l| !l.contains(", 0 failed (")) {
                return fail(format!("a run failed: {s}"));
            }
            let mut wanted: Vec<String> = vec![
                "OPC UA certificate store".into(),
                "OPC UA private key folder".into(),
            ];
            wanted.extend(
                files
                    .iter()
                    .map(|f| format!("{}: private", f.replace('/', "\\"))),
            );
            for w in &wanted {
                if !lines.iter().any(|l| l.contains(w.as_str())) {
                    return fail(format!("no line naming {w}"));
                }
            }
            use std::os::unix::fs::PermissionsExt as _;
            let mut modes = Vec::new();
            for rel in ["pki", "pki/private"].iter().chain(files) {
                let p = self.install_dir().join(rel);
                let mode = std::fs::metadata(&p)
                    .map_err(|e| format!("msi-test: {what}: {}: {e}", p.display()))?
                    .permissions()
                    .mode()
                    & 0o777;
                if mode & 0o007 != 0 {
                    return fail(format!(
                        "{rel} is mode {mode:o}: others (Everyone, under Wine) may use it"
                    ));
                }
                modes.push(format!("{rel} {mode:o}"));
            }
            println!(
                "msi-test: {what}: /ProtectSecrets ran {runs} time(s), nothing failed; under Wine (DACL as Unix mode): {}",
                modes.join(", ")
            );
            Ok(())
        }

        /// `/UnregServer /KeepSecurity` (the MSI's upgrade removal) after an administrator's
        /// change: the registration goes, the AppID's three values stay as they were; then
        /// `/Service /CreateGroup` registers again and writes none of them.
        fn keep_security(&self) -> Result<(), String> {
            let exe = "C:\\Program Files\\ServerCTOPC\\ServerCTOPC.exe";
            self.set_authentication_level(6)?;
            for args in [
                &["/UnregServer", "/KeepSecurity"][..],
                &["/Service", "/CreateGroup"],
            ] {
                let (code, out) = self.run(Arch::X64, exe, args, 120);
                self.settle();
                if code != 0 {
                    return Err(format!(
                        "msi-test: ServerCTOPC.exe {}: exit {code}\n{out}",
                        args.join(" ")
                    ));
                }
                if args[0] == "/UnregServer" {
                    let reg = self.system_reg();
                    // The key itself (Windows Installer's component data names its path
                    // in values).
                    let head = format!(
                        "[software\\\\classes\\\\clsid\\\\{{{}}}]",
                        CLSID.to_ascii_lowercase()
                    );
                    if reg.contains(&head) {
                        return Err(
                            "msi-test: /UnregServer /KeepSecurity left the CLSID key".into()
                        );
                    }
                    self.security("after /UnregServer /KeepSecurity (kept)", true, 6)?;
                }
            }
            self.security("after /Service again (nothing overwritten)", true, 6)
        }

        /// Whether the feature Gate is in place (`want`): asix-gate.exe and its example in
        /// `asix-gate\`, and its service registered (on demand, `-ServiceRun`); or none of
        /// them.
        fn gate(&self, what: &str, want: bool) -> Result<(), String> {
            let dir = self.install_dir().join(crate::dist::GATE_DIR);
            let files = [crate::dist::GATE_EXE, crate::dist::GATE_INI]
                .map(|f| self.install_dir().join(f).is_file());
            let reg = self.system_reg();
            let head = "[system\\\\currentcontrolset\\\\services\\\\asixgate]";
            let svc = reg.find(head).map(|start| {
                let body = &reg[start..];
                body[..body.find("\n\n").unwrap_or(body.len())].to_owned()
            });
            if !want {
                if dir.exists() || svc.is_some() {
                    return Err(format!(
                        "msi-test: {what}: the gate is installed without being asked for: folder {}, service {svc:?}",
                        dir.exists()
                    ));
                }
                println!("msi-test: {what}: no asix-gate (the feature is off by default)");
                return Ok(());
            }
            if files != [true, true] {
                return Err(format!(
                    "msi-test: {what}: asix-gate.exe, asix-gate.ini.example installed: {files:?}"
                ));
            }
            let svc = svc.ok_or_else(|| format!("msi-test: {what}: no asix-gate service"))?;
            for want in [
                "\"start\"=dword:00000003",
                "asix-gate\\\\asix-gate.exe",
                "-servicerun",
            ] {
                if !svc.contains(want) {
                    return Err(format!(
                        "msi-test: {what}: the asix-gate service's key lacks {want}:\n{svc}"
                    ));
                }
            }
            println!("msi-test: {what}: asix-gate.exe, its example ini and its service (on demand) installed");
            Ok(())
        }

        /// `AuthenticationLevel` = `level` in both views, as an administrator would set it.
        fn set_authentication_level(&self, level: u32) -> Result<(), String> {
            let key = format!("HKLM\\Software\\Classes\\AppID\\{{{CLSID}}}");
            let d = level.to_string();
            for view in ["/reg:64", "/reg:32"] {
                let args = [
                    "add",
                    key.as_str(),
                    "/v",
                    "AuthenticationLevel",
                    "/t",
                    "REG_DWORD",
                    "/d",
                    d.as_str(),
                    "/f",
                    view,
                ];
                let (code, out) = self.run(Arch::X64, "reg", &args, 60);
                if code != 0 {
                    return Err(format!("msi-test: reg add {view}: exit {code}: {out}"));
                }
            }
            self.settle();
            Ok(())
        }

        /// The registry of the prefix (both views: Wow6432Node is in system.reg too).
        fn system_reg(&self) -> String {
            let raw = std::fs::read(self.pfx.join("system.reg")).unwrap_or_default();
            String::from_utf8_lossy(&raw).to_ascii_lowercase()
        }

        /// `opcdiag ARGS` of `arch`; started again when it failed having printed nothing
        /// (Wine's start failure, [`start::retrying`]).
        fn opcdiag(&self, arch: Arch, args: &[&str]) -> Result<String, String> {
            let exe = opcdiag_exe(arch);
            let what = format!("msi-test: {arch:?} opcdiag {}", args.join(" "));
            start::retrying(&what, || {
                let (code, out) = self.run(arch, exe, args, 120);
                if code == 0 {
                    Ok(out)
                } else {
                    let silent = start::silent_start_failure(code, &out);
                    Err((
                        format!("{exe} {}: exit {code}\n{out}", args.join(" ")),
                        silent,
                    ))
                }
            })
        }

        /// `opcdiag subscribe` in the background, once the subscription is made; started
        /// again when it ended having printed nothing ([`start::retrying`]).
        fn subscriber(&self, arch: Arch, args: &[&str]) -> Result<Subscriber, String> {
            let what = format!("msi-test: {arch:?} opcdiag subscribe");
            start::retrying(&what, || self.subscriber_once(arch, args))
        }

        /// One start of [`Self::subscriber`]; on failure the error and whether the program
        /// printed nothing, on stdout or stderr.
        fn subscriber_once(&self, arch: Arch, args: &[&str]) -> Result<Subscriber, (String, bool)> {
            let err_path = self.dir.join(format!("subscribe-{arch:?}.stderr"));
            let err = err_path.clone();
            let err = std::fs::File::create(&err)
                .map_err(|e| (format!("{}: {e}", err.display()), false))?;
            let mut c = Command::new("timeout");
            self.env(&mut c);
            c.arg("180")
                .arg(arch.loader())
                .arg(opcdiag_exe(arch))
                .args(args)
                .stdin(Stdio::null())
                .stdout(Stdio::piped())
                .stderr(err);
            let mut child = c
                .spawn()
                .map_err(|e| (format!("cannot start wine: {e}"), false))?;
            let stdout = child
                .stdout
                .take()
                .ok_or(("opcdiag subscribe: no stdout".to_owned(), false))?;
            let (tx, rx) = mpsc::channel();
            std::thread::spawn(move || {
                for line in std::io::BufReader::new(stdout)
                    .lines()
                    .map_while(Result::ok)
                {
                    if tx.send(line).is_err() {
                        break;
                    }
                }
            });
            let mut sub = Subscriber {
                arch,
                child,
                rx,
                lines: Vec::new(),
            };
            if sub.wait_for("Subscribed to", Duration::from_secs(120)) {
                return Ok(sub);
            }
            let (code, out) = match sub.finish(Duration::from_secs(5)) {
                Ok(out) => (0, out),
                Err(e) => (1, e),
            };
            let stderr = std::fs::read_to_string(&err_path).unwrap_or_default();
            let silent = code != 0
                && start::silent_start_failure(
                    code,
                    &format!("{}{stderr}", subscriber_output(&out)),
                );
            Err((
                format!("opcdiag subscribe ({arch:?}) did not subscribe:\n{out}\n{stderr}"),
                silent,
            ))
        }

        /// A client of each bitness: status, a write of the demo set point, a read of it
        /// and of a demo variable, the server browser, and a subscription that receives
        /// the first value and both writes. The two subscribers keep one server process
        /// up for all of it (a value written is read back from the same process), and are
        /// the only server start of the check.
        /// The command lines of the prefix's running ServerCTOPC.exe processes (Wine
        /// shows a process's Windows command line in /proc; other prefixes' servers are
        /// told apart by WINEPREFIX).
        fn servers_running(&self) -> Vec<String> {
            let mut out = Vec::new();
            for e in std::fs::read_dir("/proc").into_iter().flatten().flatten() {
                let p = e.path();
                let cmd = std::fs::read(p.join("cmdline")).unwrap_or_default();
                let cmd = String::from_utf8_lossy(&cmd).replace('\0', " ");
                if !cmd.to_ascii_lowercase().contains("serverctopc.exe") {
                    continue;
                }
                let env = std::fs::read(p.join("environ")).unwrap_or_default();
                if crate::soak::environ_names_prefix(&env, &self.pfx) {
                    out.push(cmd.trim().to_owned());
                }
            }
            out
        }

        fn serves(&self, what: &str, switch: &str) -> Result<(), String> {
            // The first value and each client's write: three changes.
            let sub_args = [
                "subscribe",
                SETPOINT,
                "--rate",
                "200",
                "--count",
                "3",
                "--for",
                "150",
            ];
            let mut subs = Vec::new();
            for arch in Arch::ALL {
                subs.push(self.subscriber(arch, &sub_args)?);
            }
            // One server process, started by COM as asked (`-Embedding`, or by the service
            // control manager: `-ServiceRun`).
            let running = self.servers_running();
            if running.len() != 1 || !running[0].contains(switch) {
                return Err(format!(
                    "{what}: expected one ServerCTOPC.exe {switch}, running: {running:?}"
                ));
            }
            println!("msi-test: {what}: the server runs as {:?}", running[0]);
            for arch in Arch::ALL {
                let status = self.opcdiag(arch, &["status"])?;
                if !status.contains("ServerCTOPC") || !status.contains("State") {
                    return Err(format!("{what}: status ({arch:?}):\n{status}"));
                }
                let value = written(arch);
                let w = self.opcdiag(arch, &["write", SETPOINT, value])?;
                if !w.contains(&format!("{SETPOINT}: written {value} (R4): OK")) {
                    return Err(format!("{what}: write ({arch:?}):\n{w}"));
                }
                // From the device: the cache has the written value only after the next
                // sample (MinUpdateRate), a read from the cache right away may not.
                let read = self.opcdiag(arch, &["read", "KW_A000", SETPOINT, "--device"])?;
                if !read.lines().any(|l| l.starts_with("KW_A000")) {
                    return Err(format!("{what}: read ({arch:?}):\n{read}"));
                }
                let back = read
                    .lines()
                    .find(|l| l.starts_with(SETPOINT))
                    .map(|l| l.split_whitespace().collect::<Vec<_>>());
                if !back.is_some_and(|f| f.len() > 3 && f[1] == value && f[3] == "GOOD") {
                    return Err(format!(
                        "{what}: {SETPOINT} read back ({arch:?}), expected {value} GOOD:\n{read}"
                    ));
                }
                // The packaged server browser answers (no fallback to the categories).
                let servers = self.opcdiag(arch, &["servers"])?;
                // Listed under the original's ProgID, as a client matching by name needs.
                let listed = servers
                    .lines()
                    .any(|l| l.split_whitespace().next() == Some("ServerCTOPC.App"));
                if !listed || servers.contains("no server browser") {
                    return Err(format!("{what}: servers ({arch:?}):\n{servers}"));
                }
                println!(
                    "msi-test: {what}: {arch:?} opcdiag status, write {SETPOINT} = {value}, read back, read and servers: ok"
                );
            }
            for sub in subs {
                let arch = sub.arch;
                let out = sub.finish(Duration::from_secs(60))?;
                let values: Vec<&str> = out
                    .lines()
                    .filter_map(|l| {
                        let f: Vec<&str> = l.split_whitespace().collect();
                        (f.len() > 3 && f[1] == SETPOINT).then_some(f[2])
                    })
                    .collect();
                for a in Arch::ALL {
                    if !values.contains(&written(a)) {
                        return Err(format!(
                            "{what}: the {arch:?} subscriber missed the {a:?} write of {}: {values:?}\n{out}",
                            written(a)
                        ));
                    }
                }
                println!(
                    "msi-test: {what}: {arch:?} opcdiag subscribe: {} callback value(s) {values:?}: ok",
                    values.len()
                );
            }
            self.settle();
            Ok(())
        }

        /// Nothing of ours in the registry (both views), no service, no files but the
        /// user's.
        fn nothing_left(&self, what: &str, user_files: &[&str]) -> Result<(), String> {
            let reg = self.system_reg();
            for needle in [
                CLSID.to_ascii_lowercase().as_str(),
                "serverctopc.app",
                "opc_ps.dll",
                "services\\\\serverctopc",
                "services\\\\asix-gate",
                "appid\\\\serverctopc.exe",
                "13486d51-4821-11d2-a494-3cb306c10000",
                "opc.serverlist",
                "opcserverlist.exe",
            ] {
                if reg.contains(needle) {
                    let line = reg.lines().find(|l| l.contains(needle)).unwrap_or("");
                    return Err(format!("{what}: the registry still holds {needle}: {line}"));
                }
            }
            let dir = self.install_dir();
            let mut left = Vec::new();
            if dir.exists() {
                for e in walk(&dir) {
                    let rel = e
                        .strip_prefix(&dir)
                        .map(|p| p.display().to_string())
                        .unwrap_or_default();
                    if !user_files.contains(&rel.as_str()) {
                        left.push(rel);
                    }
                }
            }
            for m in menus() {
                if self.pfx.join(&m).exists() {
                    left.push(m);
                }
            }
            if !left.is_empty() {
                return Err(format!("{what}: files left: {left:?}"));
            }
            println!("msi-test: {what}: no keys (both views), service or files left");
            Ok(())
        }
    }

    fn opcdiag_exe(arch: Arch) -> &'static str {
        match arch {
            Arch::X64 => "C:\\Program Files\\ServerCTOPC\\opcdiag.exe",
            Arch::X86 => "C:\\Program Files\\ServerCTOPC\\x86\\opcdiag.exe",
        }
    }

    fn walk(dir: &Path) -> Vec<PathBuf> {
        let mut out = Vec::new();
        if let Ok(rd) = std::fs::read_dir(dir) {
            for e in rd.flatten() {
                let p = e.path();
                if p.is_dir() {
                    out.extend(walk(&p));
                } else {
                    out.push(p);
                }
            }
        }
        out
    }

    /// `a.b.c` with c + 1: a version Windows Installer sees as newer (it compares the
    /// first three fields only).
    fn newer(version: &str) -> String {
        let mut f: Vec<u32> = version.split('.').filter_map(|x| x.parse().ok()).collect();
        f.resize(3, 0);
        f[2] += 1;
        format!("{}.{}.{}", f[0], f[1], f[2])
    }

    /// A freshly made prefix, never run in: `target/wine/msi-template`, made by wineboot
    /// when missing (or unable to run 32-bit programs), with the shims. Each test prefix
    /// is a `cp -a` of it: a fresh prefix for a few seconds instead of a wineboot.
    fn template(clock: &Clock) -> Result<PathBuf, String> {
        let tpl = util::root().join("target/wine/msi-template");
        if tpl.exists() && !(tpl.join("system.reg").is_file() && wine::has_wow64(&tpl)) {
            std::fs::remove_dir_all(&tpl).map_err(|e| format!("{}: {e}", tpl.display()))?;
        }
        // The prefix gets the bcryptprimitives shims of both bitnesses: build them when
        // target/ lacks one (ensure_prefix only copies them).
        for arch in Arch::ALL {
            crate::setup::build_shim(arch)?;
        }
        wine::ensure_prefix(&tpl)?;
        wine::wineserver_in(&tpl, "-k", Duration::from_secs(20));
        wine::wineserver_in(&tpl, "-w", Duration::from_secs(60));
        clock.lap("template prefix ready");
        Ok(tpl)
    }

    /// A fresh test prefix `name`: a copy of the template.
    fn fresh_prefix(tpl: &Path, name: &str, clock: &Clock) -> Result<PathBuf, String> {
        let pfx = util::root().join("target/wine").join(name);
        wine::wineserver_in(&pfx, "-k", Duration::from_secs(20));
        if pfx.exists() {
            std::fs::remove_dir_all(&pfx).map_err(|e| format!("{}: {e}", pfx.display()))?;
        }
        util::run(Command::new("cp").arg("-a").arg(tpl).arg(&pfx))?;
        clock.lap(&format!("fresh prefix {}", pfx.display()));
        Ok(pfx)
    }

    /// The service `SERVICE=1` installed: as `/Service` does (on demand, LocalService,
    /// `-ServiceRun`), and the AppID naming it (COM starts the service).
    fn service_installed(reg: &str) -> Result<(), String> {
        let section = |head: &str| -> Option<String> {
            let start = reg.find(head)?;
            let body = &reg[start..];
            let end = body.find("\n\n").unwrap_or(body.len());
            Some(body[..end].to_owned())
        };
        let svc = section("[system\\\\currentcontrolset\\\\services\\\\serverctopc]")
            .ok_or("msi-test: SERVICE=1 did not install the service")?;
        for want in [
            "\"objectname\"=\"nt authority\\\\localservice\"",
            "\"start\"=dword:00000003",
            "serverctopc.exe",
            "-servicerun",
        ] {
            if !svc.contains(want) {
                return Err(format!("msi-test: the service's key lacks {want}:\n{svc}"));
            }
        }
        let appid = section(&format!(
            "[software\\\\classes\\\\appid\\\\{{{}}}]",
            CLSID.to_ascii_lowercase()
        ))
        .ok_or("msi-test: no AppID key")?;
        if !appid.contains("\"localservice\"=\"serverctopc\"") {
            return Err(format!(
                "msi-test: the AppID does not name the service:\n{appid}"
            ));
        }
        Ok(())
    }

    /// `--built`: the Windows artifacts are built already (`cargo xtask test` runs this in
    /// the background while its end-to-end tests hold cargo's build lock, and counts its
    /// opcdiag retries in its own log; run alone, it counts them in a log of its own and
    /// ends with their count).
    pub fn run(args: &[String]) -> Result<(), String> {
        let ledger = forgiven::Ledger::begin(&util::root().join("target/msi-test/forgiven.log"))?;
        ledger.end(run_all(args))
    }

    fn run_all(args: &[String]) -> Result<(), String> {
        let started = Instant::now();
        let clock = Clock(started);
        let root = util::root();
        let a = if args.iter().any(|a| a == "--built") {
            build::built()
        } else {
            build::run(&[])?
        };
        clock.lap("Windows build");
        let version = env!("CARGO_PKG_VERSION");
        let dir = root.join("target/msi-test");
        std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
        let files: Vec<(String, PathBuf)> = FILES
            .iter()
            .map(|f| {
                let src = match *f {
                    "ServerCTOPC.exe" => a.server.clone(),
                    "OpcServerList.exe" => a.server_list.clone(),
                    "opc_ps.dll" => a.proxy.clone(),
                    "opcdiag.exe" => a.dir.join("opcdiag.exe"),
                    "x86/opc_ps.dll" => a.proxy32.clone(),
                    "x86/opcdiag.exe" => a.dir32.join("opcdiag.exe"),
                    crate::dist::GATE_EXE => a.dir32.join("asix-gate.exe"),
                    crate::dist::GATE_INI => root.join("asix-gate.ini.example"),
                    // The example, the README, the docs and the demo database.
                    other => root.join(other),
                };
                ((*f).to_owned(), src)
            })
            .collect();
        let new_version = newer(version);
        // A broken package: its 32-bit proxy/stub is not a DLL, so its registration
        // (RegisterPs32) fails after the files and keys are in place.
        let broken_files: Vec<(String, PathBuf)> = files
            .iter()
            .map(|(n, p)| {
                if n == "x86/opc_ps.dll" {
                    (n.clone(), root.join("README.md"))
                } else {
                    (n.clone(), p.clone())
                }
            })
            .collect();
        // The three at once (wixl compresses on one core; each has its own folders).
        let (old, new, broken) = std::thread::scope(|s| {
            let old = s.spawn(|| {
                build(
                    &files,
                    version,
                    &dir.join("stage-old"),
                    &dir.join("old.msi"),
                )
            });
            let new = s.spawn(|| {
                build(
                    &files,
                    &new_version,
                    &dir.join("stage-new"),
                    &dir.join("new.msi"),
                )
            });
            let broken = s.spawn(|| {
                build(
                    &broken_files,
                    version,
                    &dir.join("stage-broken"),
                    &dir.join("broken.msi"),
                )
            });
            let join = |h: std::thread::ScopedJoinHandle<'_, Result<PathBuf, String>>| {
                h.join()
                    .map_err(|_| "msi-test: an MSI build panicked".to_string())?
            };
            Ok::<_, String>((join(old)?, join(new)?, join(broken)?))
        })?;

        clock.lap("three MSIs built (wixl)");

        let tpl = template(&clock)?;
        // 1. A broken install, in a fresh prefix of its own, fails and leaves nothing.
        let bctx = Ctx {
            pfx: fresh_prefix(&tpl, "msi-prefix-broken", &clock)?,
            dir: dir.clone(),
        };
        let code = bctx.msiexec("/i", &broken, &[], "broken.log");
        if code == 0 {
            return Err("msi-test: the broken package installed (exit 0)".into());
        }
        // The Unix exit status is the low byte of msiexec's: 91 is 1627 (0x65B,
        // ERROR_FUNCTION_FAILED: a custom action failed), 67 is 1603.
        println!(
            "msi-test: broken package: msiexec failed (exit {code}, the low byte of its Windows code), as it must"
        );
        bctx.nothing_left("after the failed install", &[])?;
        clock.lap("broken package checked");
        // Its 1.3 GB are not needed any more.
        let _ = std::fs::remove_dir_all(&bctx.pfx);

        // 2. Silent install in a fresh prefix, both clients.
        let ctx = Ctx {
            pfx: fresh_prefix(&tpl, "msi-prefix", &clock)?,
            dir,
        };
        let code = ctx.msiexec("/i", &old, &[], "install.log");
        if code != 0 {
            return Err(format!(
                "msi-test: install of {} failed: exit {code} (log {})",
                old.display(),
                ctx.dir.join("install.log").display()
            ));
        }
        clock.lap("installed");
        ctx.installed("after install")?;
        ctx.security("after install", false, 5)?;
        // The plain install's own `/RegServer /CreateGroup` (the clients' group, the AppID's
        // security) and `/ProtectSecrets` ran and succeeded; not the service's.
        ctx.actions(
            "install.log",
            &[
                "RegisterPs64",
                "RegisterPs32",
                "InstallSecurity",
                "LockSecrets",
            ],
            &["InstallService"],
        )?;
        ctx.secrets("after install", 1, &[])?;
        ctx.clients_group()?;
        ctx.serves("after install", "-Embedding")?;
        clock.lap("both clients served after the install");
        ctx.gate("after install", false)?;

        // 3. The user's configuration survives a major upgrade (which installs the
        //    service too).
        let ini = ctx.install_dir().join("ASIXConnect.ini");
        // A working configuration, the user's: the example with a changed value (an ini
        // without the channel's ItemsDatabase serves no demo variable), simulated (no
        // asix network here).
        let example = std::fs::read_to_string(root.join("asixconnect.ini.example"))
            .map_err(|e| format!("asixconnect.ini.example: {e}"))?;
        let user_ini = format!(
            "; the user's configuration (msi-test)\r\n{}",
            example
                .replace("MinUpdateRate = 1000", "MinUpdateRate = 500")
                .replace("SimulateCurrentData = nie", "SimulateCurrentData = tak")
        );
        if !user_ini.contains("SimulateCurrentData = tak") {
            return Err(
                "msi-test: asixconnect.ini.example has no SimulateCurrentData = nie".into(),
            );
        }
        std::fs::write(&ini, &user_ini).map_err(|e| format!("{}: {e}", ini.display()))?;
        let log = ctx.install_dir().join(USER_LOG);
        let user_log = "2026-01-01 00:00:00.000 INFO the user's log (msi-test)\r\n";
        std::fs::write(&log, user_log).map_err(|e| format!("{}: {e}", log.display()))?;
        let log_kept = |when: &str| {
            if std::fs::read_to_string(&log).unwrap_or_default() == user_log {
                Ok(())
            } else {
                Err(format!("msi-test: {when} removed or changed {USER_LOG}"))
            }
        };
        // A users file someone copied in, readable by all (0644 here: Everyone under
        // Wine): the upgrade's /ProtectSecrets narrows it.
        let users = ctx.install_dir().join("ua-users.txt");
        let users_text = "operator:writer:pbkdf2-sha256:1:c2FsdA:aGFzaA\r\n";
        std::fs::write(&users, users_text).map_err(|e| format!("{}: {e}", users.display()))?;
        {
            use std::os::unix::fs::PermissionsExt as _;
            std::fs::set_permissions(&users, std::fs::Permissions::from_mode(0o644))
                .map_err(|e| format!("{}: {e}", users.display()))?;
        }
        // An administrator's change (dcomcnfg's "Authentication Level" raised to packet
        // privacy, 6) in both views: the upgrade must keep it.
        ctx.set_authentication_level(6)?;
        // The upgrade adds the feature Gate (with the default one: ADDLOCAL=ALL).
        let code = ctx.msiexec("/i", &new, &["SERVICE=1", "ADDLOCAL=ALL"], "upgrade.log");
        if code != 0 {
            return Err(format!(
                "msi-test: upgrade to {new_version} failed: exit {code} (log {})",
                ctx.dir.join("upgrade.log").display()
            ));
        }
        let kept = std::fs::read_to_string(&ini).unwrap_or_default();
        if kept != user_ini {
            return Err(format!(
                "msi-test: the upgrade changed ASIXConnect.ini: {kept:?}"
            ));
        }
        log_kept("the upgrade")?;
        if std::fs::read_to_string(&users).unwrap_or_default() != users_text {
            return Err("msi-test: the upgrade changed ua-users.txt".into());
        }
        ctx.actions(
            "upgrade.log",
            &["InstallService", "LockSecrets"],
            &["InstallSecurity"],
        )?;
        ctx.secrets("after upgrade", 2, &["ua-users.txt"])?;
        clock.lap(&format!(
            "upgraded to {new_version}: ASIXConnect.ini and {USER_LOG} kept"
        ));
        ctx.installed("after upgrade")?;
        service_installed(&ctx.system_reg())?;
        ctx.gate("after upgrade with ADDLOCAL=ALL", true)?;
        // Measured under Wine 8: its RemoveExistingProducts removes the older version
        // without setting UPGRADINGPRODUCTCODE, so the older version's `/UnregServer` (not
        // `/UnregServer /KeepSecurity`, which Windows Installer's upgrade runs) removed the
        // administrator's level, and `/Service` wrote the service's defaults.
        ctx.security("after upgrade (Wine: UPGRADINGPRODUCTCODE unset)", true, 5)?;
        // What Windows Installer's upgrade runs keeps an administrator's values.
        ctx.keep_security()?;
        println!("msi-test: SERVICE=1: the service is installed (on demand, NT AUTHORITY\\LocalService), the AppID names it");
        ctx.serves("after upgrade", "-ServiceRun")?;
        clock.lap("both clients served after the upgrade (through the service)");

        // 4. Silent uninstall of the newer product: only the user's file stays.
        let code = ctx.msiexec("/x", &new, &[], "uninstall.log");
        if code != 0 {
            return Err(format!(
                "msi-test: uninstall failed: exit {code} (log {})",
                ctx.dir.join("uninstall.log").display()
            ));
        }
        let mut user_files = vec!["ASIXConnect.ini".to_owned(), "ua-users.txt".to_owned()];
        user_files.extend(
            walk(&ctx.install_dir().join("Log"))
                .iter()
                .filter_map(|p| p.strip_prefix(ctx.install_dir()).ok())
                .map(|p| p.display().to_string()),
        );
        let uf: Vec<&str> = user_files.iter().map(String::as_str).collect();
        ctx.nothing_left("after uninstall", &uf)?;
        clock.lap("uninstalled");
        if std::fs::read_to_string(&ini).unwrap_or_default() != user_ini {
            return Err("msi-test: the uninstall removed or changed ASIXConnect.ini".into());
        }
        log_kept("the uninstall")?;
        println!("msi-test: after uninstall: ASIXConnect.ini and {USER_LOG} kept");
        println!("msi-test: ok ({} s)", started.elapsed().as_secs());
        Ok(())
    }
}

pub use wine_test::run as test;
