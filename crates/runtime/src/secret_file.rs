//! Writing and checking the files that hold secrets (private keys, the OPC UA users file):
//! on Unix written with mode 0600 (an existing file is narrowed to it too), and at load a
//! WARN naming a file its group or others may read (`ctopc_core::secrets`, which says why
//! a warning and not a refusal). On Windows the file is written as it is; its DACL is the
//! installer's and the administrator's (`docs/deployment.md`).

use std::io::Write as _;
use std::path::Path;

/// Writes `bytes` to `path` (created or truncated) readable and writable by the owner only.
pub fn write(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let mut options = std::fs::OpenOptions::new();
    options.write(true).create(true).truncate(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt as _;
        options.mode(ctopc_core::secrets::PRIVATE_MODE);
    }
    let mut f = options.open(path)?;
    // The mode of open() applies only to a new file: narrow an existing one.
    narrow(path)?;
    f.write_all(bytes)?;
    f.sync_all()
}

/// Sets an existing file (or folder: then 0700) to owner-only on Unix; nothing elsewhere.
pub fn narrow(path: &Path) -> std::io::Result<()> {
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt as _;
        let dir = std::fs::metadata(path)?.is_dir();
        let mode = if dir {
            0o700
        } else {
            ctopc_core::secrets::PRIVATE_MODE
        };
        std::fs::set_permissions(path, std::fs::Permissions::from_mode(mode))?;
    }
    #[cfg(not(unix))]
    let _ = path;
    Ok(())
}

/// What is wrong with the rights on the secret file `path` (`None`: fine, absent, or not
/// a Unix system).
pub fn finding(path: &Path) -> Option<String> {
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt as _;
        let mode = std::fs::metadata(path).ok()?.permissions().mode();
        ctopc_core::secrets::mode_finding(mode)
    }
    #[cfg(not(unix))]
    {
        let _ = path;
        None
    }
}

/// Logs a WARN when the secret file `path` (`what`: e.g. "the OPC UA private key") is open
/// to its group or others; returns whether it did.
pub fn warn_if_exposed(path: &Path, what: &str) -> bool {
    match finding(path) {
        Some(f) => {
            tracing::warn!("{what} {} is not private: {f}", path.display());
            true
        }
        None => false,
    }
}

#[cfg(all(test, unix))]
mod tests {
    use super::*;
    use std::os::unix::fs::PermissionsExt as _;

    fn mode(p: &Path) -> u32 {
        std::fs::metadata(p).unwrap().permissions().mode() & 0o777
    }

    #[test]
    fn secrets_are_written_owner_only_and_open_ones_are_found() {
        let dir = std::env::temp_dir().join(format!("ctopc-secret-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let new = dir.join("new.pem");
        write(&new, b"secret").unwrap();
        assert_eq!(mode(&new), 0o600);
        assert_eq!(std::fs::read(&new).unwrap(), b"secret");
        assert_eq!(finding(&new), None);
        assert!(!warn_if_exposed(&new, "the key"));
        // An existing world-readable file: found, then narrowed by a write.
        let old = dir.join("old.txt");
        std::fs::write(&old, b"x").unwrap();
        std::fs::set_permissions(&old, std::fs::Permissions::from_mode(0o644)).unwrap();
        assert_eq!(
            finding(&old).as_deref(),
            Some("mode 0644: its group and others may read it (chmod 600)")
        );
        assert!(warn_if_exposed(&old, "the users file"));
        write(&old, b"y").unwrap();
        assert_eq!(mode(&old), 0o600);
        assert_eq!(finding(&dir.join("absent")), None);
        narrow(&dir).unwrap();
        assert_eq!(mode(&dir), 0o700);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
