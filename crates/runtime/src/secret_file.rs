//! Writing and checking the files that hold secrets (private keys, the OPC UA users file)
//! and their folders: readable only by the account that writes them and administrators.
//!
//! On Unix a file is written with mode 0600 (an existing file is narrowed to it too), a
//! folder narrowed to 0700, and at load a WARN names a file its group or others may read
//! (`ctopc_core::secrets`, which says why a warning and not a refusal). Elsewhere (Windows)
//! the program installs the platform's way at its start ([`install`]: ServerCTOPC and
//! asix-gate install `ctopc_com::com::secret_file::PLATFORM`, protected DACLs): this crate
//! has no `windows` dependency. Without one installed a file is written as it is.

use std::fs::File;
use std::io::Write as _;
use std::path::Path;
use std::sync::OnceLock;

/// How a platform without Unix modes makes and checks private files.
#[derive(Clone, Copy)]
pub struct Platform {
    /// Makes a new file private from its first byte, or narrows an existing one and opens
    /// it truncated; open for writing.
    pub create: fn(&Path) -> std::io::Result<File>,
    /// Makes an existing file (`false`) or folder (`true`: what is made in it after
    /// inherits it) private.
    pub narrow: fn(&Path, bool) -> std::io::Result<()>,
    /// What is wrong with the rights on a file (`None`: private, or absent).
    pub finding: fn(&Path) -> Option<String>,
}

static PLATFORM: OnceLock<Platform> = OnceLock::new();

/// Installs the platform's way (once; a second call is ignored). On Unix the modes are
/// used and an installed platform is not asked.
pub fn install(platform: Platform) {
    let _ = PLATFORM.set(platform);
}

fn platform() -> Option<&'static Platform> {
    if cfg!(unix) {
        None
    } else {
        PLATFORM.get()
    }
}

/// Writes `bytes` to `path` (created or truncated) readable and writable by the owner only.
pub fn write(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let mut f = match platform() {
        Some(p) => (p.create)(path)?,
        None => {
            let mut options = std::fs::OpenOptions::new();
            options.write(true).create(true).truncate(true);
            #[cfg(unix)]
            {
                use std::os::unix::fs::OpenOptionsExt as _;
                options.mode(ctopc_core::secrets::PRIVATE_MODE);
            }
            let f = options.open(path)?;
            // The mode of open() applies only to a new file: narrow an existing one.
            narrow(path)?;
            f
        }
    };
    f.write_all(bytes)?;
    f.sync_all()
}

/// Sets an existing file (or folder: then 0700) to owner-only.
pub fn narrow(path: &Path) -> std::io::Result<()> {
    let dir = std::fs::metadata(path)?.is_dir();
    if let Some(p) = platform() {
        return (p.narrow)(path, dir);
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt as _;
        let mode = if dir {
            0o700
        } else {
            ctopc_core::secrets::PRIVATE_MODE
        };
        std::fs::set_permissions(path, std::fs::Permissions::from_mode(mode))?;
    }
    Ok(())
}

/// What is wrong with the rights on the secret file `path` (`None`: fine, absent, or no
/// way to tell on this platform).
pub fn finding(path: &Path) -> Option<String> {
    if let Some(p) = platform() {
        return (p.finding)(path);
    }
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
/// to anyone but its owner, the service and administrators; returns whether it did.
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
