//! `cargo xtask dist`: target/dist/ServerCTOPC-<version>.zip with the server, the
//! proxy/stub DLL, the diagnostic client (the last two also 32-bit, in `x86/`), the example configuration, the demo database
//! and the documentation (the deployment guide first), and in `asix-gate/` the gateway
//! for the asix station (32-bit) with its example configuration.
//!
//! The executables ship **stripped**: the release profile keeps line tables for the
//! project's own crates (`debug = 1`, so that the tests and panics name our lines), which
//! are much of ServerCTOPC.exe's size. Each `.exe`/`.dll` with
//! `.debug_*` sections is split with the mingw binutils of its bitness, as for ELF:
//! `objcopy --only-keep-debug` into `<name>.debug`, then `objcopy --strip-debug
//! --add-gnu-debuglink=<name>.debug` (the COFF symbol table stays, so a panic's backtrace
//! still names functions). The `.debug` files go into a second archive,
//! `ServerCTOPC-<version>-debug.zip`, with the same folder layout: unzipped over an
//! installation they lie beside their executables, where gdb and winedbg look for a
//! debug link. The split is checked (no `.debug_*` section left in the shipped file, a
//! `.gnu_debuglink`; DWARF in the debug file) before anything is written. The tests
//! run the unstripped build; only the archive is stripped (in `target/dist/stage/`).
//!
//! The ZIP is written here (entries stored, CRC-32 checked by every unzip tool), so that
//! packaging needs no extra system package.

use crate::arch::Arch;
use crate::{build, util};
use std::path::{Path, PathBuf};
use std::process::Command;

pub fn run(_args: &[String]) -> Result<(), String> {
    let root = util::root();
    let a = build::run(&[])?;
    let version = env!("CARGO_PKG_VERSION");
    let base = format!("ServerCTOPC-{version}");
    let mut files: Vec<(String, PathBuf)> = vec![
        ("ServerCTOPC.exe".into(), a.server.clone()),
        ("OpcServerList.exe".into(), a.server_list.clone()),
        ("opc_ps.dll".into(), a.proxy.clone()),
        ("opcdiag.exe".into(), a.dir.join("opcdiag.exe")),
        // For 32-bit OPC clients (docs/deployment.md: the 32-bit regsvr32 registers it).
        ("x86/opc_ps.dll".into(), a.proxy32.clone()),
        ("x86/opcdiag.exe".into(), a.dir32.join("opcdiag.exe")),
        // The gateway for the asix station (32-bit), with its example configuration.
        (GATE_EXE.into(), a.dir32.join("asix-gate.exe")),
        (GATE_INI.into(), root.join("asix-gate.ini.example")),
        (
            "asixconnect.ini.example".into(),
            root.join("asixconnect.ini.example"),
        ),
        ("README.md".into(), root.join("README.md")),
        ("docs/deployment.md".into(), root.join("docs/deployment.md")),
        (
            "docs/variable-database.md".into(),
            root.join("docs/variable-database.md"),
        ),
        (
            "docs/asix-net-protocol.md".into(),
            root.join("docs/asix-net-protocol.md"),
        ),
        (
            "docs/configuration.md".into(),
            root.join("docs/configuration.md"),
        ),
        ("docs/operations.md".into(), root.join("docs/operations.md")),
        ("docs/asix-gate.md".into(), root.join("docs/asix-gate.md")),
    ];
    for f in ["atrybuty.csv", "wytwornia_kwasu.zez"] {
        files.push((
            format!("demo/wytwornia_kwasu/{f}"),
            root.join("demo/wytwornia_kwasu").join(f),
        ));
    }
    let out_dir = root.join("target/dist");
    let debug_files = strip_binaries(&mut files, &out_dir.join("stage"))?;
    let mut entries = Vec::new();
    for (name, path) in &files {
        let data = std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))?;
        entries.push((format!("{base}/{name}"), data));
    }
    let mut debug_entries = Vec::new();
    for (name, path) in &debug_files {
        let data = std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))?;
        debug_entries.push((format!("{base}/{name}"), data));
    }
    std::fs::create_dir_all(&out_dir).map_err(|e| e.to_string())?;
    let out = out_dir.join(format!("{base}.zip"));
    std::fs::write(&out, zip(&entries)).map_err(|e| format!("{}: {e}", out.display()))?;
    println!("dist: {} ({} files)", out.display(), entries.len());
    let out = out_dir.join(format!("{base}-debug.zip"));
    std::fs::write(&out, zip(&debug_entries)).map_err(|e| format!("{}: {e}", out.display()))?;
    println!(
        "dist: {} ({} debug files, beside their executables when unzipped over the install)",
        out.display(),
        debug_entries.len()
    );
    crate::msi::dist(&files, version).map(|_| ())
}

/// asix-gate in the archive and the install folder: a folder of its own, since it runs
/// on another computer (the asix station) and reads `asix-gate.ini` beside itself.
pub const GATE_DIR: &str = "asix-gate";
pub const GATE_EXE: &str = "asix-gate/asix-gate.exe";
pub const GATE_INI: &str = "asix-gate/asix-gate.ini.example";

/// The bitness of a file of the archive: `x86/...` and asix-gate are 32-bit, the rest
/// 64-bit.
fn arch_of(name: &str) -> Arch {
    if name.starts_with(&format!("{GATE_DIR}/")) {
        return Arch::X86;
    }
    Arch::ALL
        .into_iter()
        .find(|a| {
            a.dist_subdir()
                .is_some_and(|d| name.starts_with(&format!("{d}/")))
        })
        .unwrap_or(Arch::X64)
}

/// Replaces every `.exe`/`.dll` of `files` that has debug information by its stripped copy
/// under `stage` ([`split_debug`]); returns the debug files as `(archive name, path)`.
/// Prints the sizes before and after.
fn strip_binaries(
    files: &mut [(String, PathBuf)],
    stage: &Path,
) -> Result<Vec<(String, PathBuf)>, String> {
    let mut debug = Vec::new();
    for (name, path) in files.iter_mut() {
        if !(name.ends_with(".exe") || name.ends_with(".dll")) {
            continue;
        }
        let before = std::fs::metadata(&*path)
            .map_err(|e| format!("{}: {e}", path.display()))?
            .len();
        let out = stage.join(&*name);
        let Some(debug_file) = split_debug(arch_of(name), path, &out)? else {
            println!("dist: {name}: {} (no debug information)", mb(before));
            continue;
        };
        let after = std::fs::metadata(&out).map_err(|e| e.to_string())?.len();
        let dbg = std::fs::metadata(&debug_file)
            .map_err(|e| e.to_string())?
            .len();
        println!(
            "dist: {name}: {} -> {} stripped, {} in {name}.debug",
            mb(before),
            mb(after),
            mb(dbg)
        );
        *path = out;
        debug.push((format!("{name}.debug"), debug_file));
    }
    Ok(debug)
}

fn mb(bytes: u64) -> String {
    format!("{:.1} MB", bytes as f64 / 1e6)
}

/// mingw's objcopy for `arch` (beside its gcc: `x86_64-w64-mingw32-objcopy`).
fn objcopy(arch: Arch) -> String {
    format!("{}objcopy", arch.gcc().trim_end_matches("gcc"))
}

/// Splits the DWARF of the PE file `src` off: `out` is the stripped copy with a
/// `.gnu_debuglink` to `out` + `.debug`, which holds the debug information. `None` (and
/// nothing written) when `src` has no `.debug_*` section. Checks both results.
fn split_debug(arch: Arch, src: &Path, out: &Path) -> Result<Option<PathBuf>, String> {
    let read = |p: &Path| std::fs::read(p).map_err(|e| format!("{}: {e}", p.display()));
    let is_debug = |n: &String| n.starts_with(".debug_");
    let sections = pe_section_names(&read(src)?).map_err(|e| format!("{}: {e}", src.display()))?;
    if !sections.iter().any(is_debug) {
        return Ok(None);
    }
    if let Some(dir) = out.parent() {
        std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    }
    let mut debug_name = out.as_os_str().to_owned();
    debug_name.push(".debug");
    let debug = PathBuf::from(debug_name);
    let tool = objcopy(arch);
    util::output(
        Command::new(&tool)
            .arg("--only-keep-debug")
            .arg(src)
            .arg(&debug),
    )?;
    util::output(
        Command::new(&tool)
            .arg("--strip-debug")
            .arg(format!("--add-gnu-debuglink={}", debug.display()))
            .arg(src)
            .arg(out),
    )?;
    let stripped = pe_section_names(&read(out)?)?;
    if stripped.iter().any(is_debug) || !stripped.iter().any(|n| n == ".gnu_debuglink") {
        return Err(format!(
            "{}: not stripped as expected, sections {stripped:?}",
            out.display()
        ));
    }
    let kept = pe_section_names(&read(&debug)?)?;
    if !kept.iter().any(|n| n == ".debug_info") {
        return Err(format!(
            "{}: no .debug_info in the debug file, sections {kept:?}",
            debug.display()
        ));
    }
    Ok(Some(debug))
}

/// The section names of a PE image (long names, `/<offset>`, resolved through the COFF
/// string table as binutils writes them).
pub fn pe_section_names(data: &[u8]) -> Result<Vec<String>, String> {
    let u16_at = |o: usize| -> Result<u16, String> {
        data.get(o..o + 2)
            .map(|b| u16::from_le_bytes([b[0], b[1]]))
            .ok_or_else(|| format!("truncated PE at {o}"))
    };
    let u32_at = |o: usize| -> Result<u32, String> {
        data.get(o..o + 4)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .ok_or_else(|| format!("truncated PE at {o}"))
    };
    if data.get(0..2) != Some(b"MZ") {
        return Err("not a PE file (no MZ)".into());
    }
    let pe = u32_at(0x3C)? as usize;
    if data.get(pe..pe + 4) != Some(b"PE\0\0") {
        return Err("not a PE file (no PE signature)".into());
    }
    let coff = pe + 4;
    let count = usize::from(u16_at(coff + 2)?);
    let symtab = u32_at(coff + 8)? as usize;
    let nsyms = u32_at(coff + 12)? as usize;
    let strtab = symtab + nsyms * 18;
    let first = coff + 20 + usize::from(u16_at(coff + 16)?);
    let mut names = Vec::with_capacity(count);
    for i in 0..count {
        let o = first + i * 40;
        let raw = data
            .get(o..o + 8)
            .ok_or_else(|| format!("truncated section table at {o}"))?;
        let short = String::from_utf8_lossy(raw.split(|&b| b == 0).next().unwrap_or(raw));
        let name = match short.strip_prefix('/') {
            Some(off) if symtab != 0 => {
                let off: usize = off
                    .parse()
                    .map_err(|_| format!("bad long section name {short:?}"))?;
                let start = strtab + off;
                let rest = data
                    .get(start..)
                    .ok_or_else(|| format!("section name {short:?} outside the file"))?;
                let end = rest.iter().position(|&b| b == 0).unwrap_or(rest.len());
                String::from_utf8_lossy(&rest[..end]).into_owned()
            }
            _ => short.into_owned(),
        };
        names.push(name);
    }
    Ok(names)
}

fn crc32(data: &[u8]) -> u32 {
    let mut table = [0u32; 256];
    for (i, t) in table.iter_mut().enumerate() {
        let mut c = i as u32;
        for _ in 0..8 {
            c = if c & 1 != 0 {
                0xEDB8_8320 ^ (c >> 1)
            } else {
                c >> 1
            };
        }
        *t = c;
    }
    !data.iter().fold(!0u32, |c, &b| {
        table[((c ^ u32::from(b)) & 0xFF) as usize] ^ (c >> 8)
    })
}

/// A ZIP archive of `(name, data)` entries, stored (no compression), UTF-8 names,
/// a fixed timestamp (2026-01-01) so that the same inputs give the same bytes.
pub fn zip(entries: &[(String, Vec<u8>)]) -> Vec<u8> {
    const DOS_TIME: u16 = 0;
    const DOS_DATE: u16 = ((2026 - 1980) << 9) | (1 << 5) | 1;
    const UTF8: u16 = 1 << 11;
    let mut out = Vec::new();
    let mut central = Vec::new();
    for (name, data) in entries {
        let offset = out.len() as u32;
        let crc = crc32(data);
        let n = name.as_bytes();
        let header = |sig: u32, central: bool| {
            let mut h = Vec::new();
            h.extend_from_slice(&sig.to_le_bytes());
            if central {
                h.extend_from_slice(&20u16.to_le_bytes()); // made by
            }
            h.extend_from_slice(&20u16.to_le_bytes()); // needed to extract
            h.extend_from_slice(&UTF8.to_le_bytes());
            h.extend_from_slice(&0u16.to_le_bytes()); // stored
            h.extend_from_slice(&DOS_TIME.to_le_bytes());
            h.extend_from_slice(&DOS_DATE.to_le_bytes());
            h.extend_from_slice(&crc.to_le_bytes());
            h.extend_from_slice(&(data.len() as u32).to_le_bytes());
            h.extend_from_slice(&(data.len() as u32).to_le_bytes());
            h.extend_from_slice(&(n.len() as u16).to_le_bytes());
            h.extend_from_slice(&0u16.to_le_bytes()); // extra
            if central {
                h.extend_from_slice(&0u16.to_le_bytes()); // comment
                h.extend_from_slice(&0u16.to_le_bytes()); // disk
                h.extend_from_slice(&0u16.to_le_bytes()); // internal attributes
                h.extend_from_slice(&0u32.to_le_bytes()); // external attributes
                h.extend_from_slice(&offset.to_le_bytes());
            }
            h.extend_from_slice(n);
            h
        };
        out.extend(header(0x0403_4b50, false));
        out.extend_from_slice(data);
        central.extend(header(0x0201_4b50, true));
    }
    let cd_offset = out.len() as u32;
    out.extend_from_slice(&central);
    out.extend_from_slice(&0x0605_4b50u32.to_le_bytes());
    out.extend_from_slice(&[0, 0, 0, 0]); // disk numbers
    out.extend_from_slice(&(entries.len() as u16).to_le_bytes());
    out.extend_from_slice(&(entries.len() as u16).to_le_bytes());
    out.extend_from_slice(&(central.len() as u32).to_le_bytes());
    out.extend_from_slice(&cd_offset.to_le_bytes());
    out.extend_from_slice(&0u16.to_le_bytes());
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A minimal PE image: `names` as section headers (a name longer than 8 bytes goes
    /// to the COFF string table as `/<offset>`, as binutils writes it).
    fn fake_pe(names: &[&str]) -> Vec<u8> {
        let mut d = vec![0u8; 0x40];
        d[0..2].copy_from_slice(b"MZ");
        d[0x3C..0x40].copy_from_slice(&0x40u32.to_le_bytes());
        d.extend_from_slice(b"PE\0\0");
        let opt = 16u16;
        let sections_at = 0x40 + 4 + 20 + usize::from(opt);
        let symtab = sections_at + names.len() * 40;
        let mut coff = vec![0u8; 20];
        coff[2..4].copy_from_slice(&(names.len() as u16).to_le_bytes());
        coff[8..12].copy_from_slice(&(symtab as u32).to_le_bytes());
        coff[12..16].copy_from_slice(&1u32.to_le_bytes());
        coff[16..18].copy_from_slice(&opt.to_le_bytes());
        d.extend_from_slice(&coff);
        d.extend_from_slice(&[0u8; 16]);
        let mut strtab = vec![0u8; 4];
        for n in names {
            let mut h = [0u8; 40];
            if n.len() <= 8 {
                h[..n.len()].copy_from_slice(n.as_bytes());
            } else {
                let r = format!("/{}", strtab.len());
                h[..r.len()].copy_from_slice(r.as_bytes());
                strtab.extend_from_slice(n.as_bytes());
                strtab.push(0);
            }
            d.extend_from_slice(&h);
        }
        d.extend_from_slice(&[0u8; 18]); // one symbol
        let len = strtab.len() as u32;
        strtab[..4].copy_from_slice(&len.to_le_bytes());
        d.extend_from_slice(&strtab);
        d
    }

    #[test]
    fn pe_section_names_resolve_long_names() {
        let names = [".text", ".debug_info", ".rdata", ".gnu_debuglink"];
        assert_eq!(pe_section_names(&fake_pe(&names)).unwrap(), names);
        assert!(pe_section_names(b"MZ").is_err(), "truncated");
        assert!(pe_section_names(b"not a PE file at all, no").is_err());
        let mut bad = fake_pe(&[".text"]);
        bad[0x40] = b'X';
        assert!(pe_section_names(&bad).is_err(), "no PE signature");
    }

    #[test]
    fn a_split_pe_ships_without_dwarf_and_its_debug_file_keeps_it() {
        let gcc = Arch::X64.gcc();
        let dir = std::env::temp_dir().join(format!("xtask-dist-split-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let c = dir.join("hello.c");
        std::fs::write(&c, "int main(void) { return 0; }\n").unwrap();
        let exe = dir.join("hello.exe");
        match Command::new(gcc)
            .arg("-g")
            .arg("-o")
            .arg(&exe)
            .arg(&c)
            .status()
        {
            Ok(s) if s.success() => {}
            other => {
                // `cargo xtask setup` installs mingw; without it there is nothing to split.
                eprintln!("skipped: {gcc} not usable ({other:?}); run `cargo xtask setup`");
                let _ = std::fs::remove_dir_all(&dir);
                return;
            }
        }
        let before = pe_section_names(&std::fs::read(&exe).unwrap()).unwrap();
        assert!(before.iter().any(|n| n == ".debug_info"), "{before:?}");
        let out = dir.join("stage/hello.exe");
        let debug = split_debug(Arch::X64, &exe, &out).unwrap().unwrap();
        assert_eq!(debug, dir.join("stage/hello.exe.debug"));
        let after = pe_section_names(&std::fs::read(&out).unwrap()).unwrap();
        assert!(!after.iter().any(|n| n.starts_with(".debug_")), "{after:?}");
        assert!(after.iter().any(|n| n == ".gnu_debuglink"), "{after:?}");
        let kept = pe_section_names(&std::fs::read(&debug).unwrap()).unwrap();
        assert!(kept.iter().any(|n| n == ".debug_info"), "{kept:?}");
        // A stripped file has nothing more to split.
        assert_eq!(
            split_debug(Arch::X64, &out, &dir.join("again.exe")).unwrap(),
            None
        );
        assert!(!dir.join("again.exe").exists());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn files_under_x86_are_32_bit() {
        assert_eq!(arch_of("x86/opcdiag.exe"), Arch::X86);
        assert_eq!(arch_of("ServerCTOPC.exe"), Arch::X64);
        assert_eq!(arch_of(GATE_EXE), Arch::X86);
        assert_eq!(objcopy(Arch::X86), "i686-w64-mingw32-objcopy");
        assert_eq!(objcopy(Arch::X64), "x86_64-w64-mingw32-objcopy");
    }

    #[test]
    fn crc32_matches_the_standard_check_value() {
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
        assert_eq!(crc32(b""), 0);
    }

    #[test]
    fn the_archive_lists_every_entry_with_its_size_and_offset() {
        let entries = vec![
            ("a/x.txt".to_string(), b"hello".to_vec()),
            ("a/żółć.md".to_string(), vec![7u8; 300]),
        ];
        let z = zip(&entries);
        // End of central directory: two entries.
        let eocd = z.len() - 22;
        assert_eq!(&z[eocd..eocd + 4], &0x0605_4b50u32.to_le_bytes());
        assert_eq!(u16::from_le_bytes([z[eocd + 10], z[eocd + 11]]), 2);
        // The second local header starts right after the first entry's data.
        let second = 30 + "a/x.txt".len() + 5;
        assert_eq!(&z[second..second + 4], &0x0403_4b50u32.to_le_bytes());
        assert_eq!(zip(&entries), z, "deterministic");
    }
}
