//! The client's name in the asix network.

use asix_model::ini::parse_ini_tolerant;
use tracing::warn;

/// The client's asix name (manual §3.6.1.1 and §6.3.1): `[ASLINK] Nazwa` from `aslink.ini`
/// when that file exists and the line is set (non-empty), else the Windows computer name
/// plus a dot (`CLI` -> `CLI.`).
///
/// `aslink_ini` is the file's bytes, read as the asix side writes them
/// ([`parse_ini_tolerant`]: any encoding it decodes; unreadable lines are logged and
/// skipped). When an asix application runs on the same computer, its application ini
/// carries the name instead: pass that file's bytes.
pub fn asix_client_name(aslink_ini: Option<&[u8]>, computer_name: &str) -> String {
    if let Some(bytes) = aslink_ini {
        let (ini, warnings) = parse_ini_tolerant(bytes, "aslink.ini");
        for w in &warnings {
            warn!("{w}");
        }
        if let Some(name) = ini.get("ASLINK", "Nazwa") {
            if !name.is_empty() {
                return name.to_owned();
            }
        }
    }
    format!("{}.", computer_name.trim())
}

/// This computer's name: `COMPUTERNAME` (Windows), else `HOSTNAME`, else `/etc/hostname`,
/// else "LOCALHOST".
pub fn computer_name() -> String {
    for var in ["COMPUTERNAME", "HOSTNAME"] {
        if let Ok(v) = std::env::var(var) {
            if !v.trim().is_empty() {
                return v.trim().to_owned();
            }
        }
    }
    if let Ok(v) = std::fs::read_to_string("/etc/hostname") {
        if !v.trim().is_empty() {
            return v.trim().to_owned();
        }
    }
    "LOCALHOST".to_owned()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn name_comes_from_aslink_ini_else_computer_name_plus_dot() {
        let name = |ini: &str| asix_client_name(Some(ini.as_bytes()), "CLI");
        assert_eq!(asix_client_name(None, "CLI"), "CLI.");
        assert_eq!(name(""), "CLI.");
        assert_eq!(name("[ASLINK]\nInne = 1\n"), "CLI.");
        assert_eq!(name("[ASLINK]\nNazwa =\n"), "CLI.");
        assert_eq!(name("[OTHER]\nNazwa = X\n"), "CLI.");
        assert_eq!(name("[aslink]\nnazwa = KE2\n"), "KE2");
    }

    #[test]
    fn aslink_ini_is_decoded_and_read_tolerantly() {
        // Windows-1250 bytes, a line that is not `key = value`, an unterminated header.
        let ini = b"[ASLINK]\n???\nNazwa = STACJA_\xA3\xD3D\xCF\n[X\n";
        assert_eq!(asix_client_name(Some(&ini[..]), "CLI"), "STACJA_ŁÓDĎ");
    }
}
