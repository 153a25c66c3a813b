//! The client's name in the asix network.

use crate::ini::Ini;

/// The client's asix name (manual §3.6.1.1 and §6.3.1): `[ASLINK] Nazwa` from `aslink.ini`
/// when that file exists and the line is set (non-empty), else the Windows computer name
/// plus a dot (`CLI` -> `CLI.`).
///
/// When an asix application runs on the same computer, its application ini carries the
/// name instead: pass that file's text as `aslink_ini`.
pub fn asix_client_name(aslink_ini: Option<&str>, computer_name: &str) -> String {
    if let Some(text) = aslink_ini {
        if let Some(name) = Ini::parse(text).get("ASLINK", "Nazwa") {
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
        assert_eq!(asix_client_name(None, "CLI"), "CLI.");
        assert_eq!(asix_client_name(Some(""), "CLI"), "CLI.");
        assert_eq!(
            asix_client_name(Some("[ASLINK]\nInne = 1\n"), "CLI"),
            "CLI."
        );
        assert_eq!(asix_client_name(Some("[ASLINK]\nNazwa =\n"), "CLI"), "CLI.");
        assert_eq!(
            asix_client_name(Some("[OTHER]\nNazwa = X\n"), "CLI"),
            "CLI."
        );
        assert_eq!(
            asix_client_name(Some("[aslink]\nnazwa = KE2\n"), "CLI"),
            "KE2"
        );
    }
}
