//! `cargo xtask dist`: target/dist/ServerCTOPC-<version>.zip with the server, the
//! proxy/stub DLL, the diagnostic client (the last two also 32-bit, in `x86/`), the example configuration, the demo database
//! and the documentation (the deployment guide first).
//!
//! The ZIP is written here (entries stored, CRC-32 checked by every unzip tool), so that
//! packaging needs no extra system package.

use crate::{build, util};
use std::path::PathBuf;

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
    ];
    for f in ["atrybuty.csv", "wytwornia_kwasu.zez"] {
        files.push((
            format!("demo/wytwornia_kwasu/{f}"),
            root.join("demo/wytwornia_kwasu").join(f),
        ));
    }
    let mut entries = Vec::new();
    for (name, path) in &files {
        let data = std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))?;
        entries.push((format!("{base}/{name}"), data));
    }
    let out_dir = root.join("target/dist");
    std::fs::create_dir_all(&out_dir).map_err(|e| e.to_string())?;
    let out = out_dir.join(format!("{base}.zip"));
    std::fs::write(&out, zip(&entries)).map_err(|e| format!("{}: {e}", out.display()))?;
    println!("dist: {} ({} files)", out.display(), entries.len());
    Ok(())
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
