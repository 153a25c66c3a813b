//! `/ProtectSecrets [--config FILE]`: the files of secrets a configuration names made
//! private, and their folders prepared, through `ctopc_runtime::secret_file` (on Windows
//! a protected DACL: full control for SYSTEM, Administrators, LOCAL SERVICE and the
//! account running it, nothing inherited; on Unix 0600, folders 0700). The MSI runs it as
//! a deferred custom action (as SYSTEM) at install and upgrade.
//!
//! What is protected ([`plan`], pure): the OPC UA certificate store (`PkiDirectory`,
//! default `pki`), made when missing and narrowed with everything already in it, its
//! `private` folder and private key; the users file (`UsersFile`, default
//! `ua-users.txt`); each channel's `AsixNetKeyFile`. The OPC UA paths are there also
//! without a `[UA]` section, so that the service's account can make the key in them once
//! OPC UA is turned on. The folder of a users or key file is prepared (made when missing,
//! narrowed) only when it is one of its own strictly below the configuration's folder:
//! never the configuration's folder itself (it holds the program) nor a folder elsewhere.
//! A file not there yet is no error: what ServerCTOPC writes later (`user add`, the key)
//! is private from its first byte, and a file copied into a prepared folder inherits
//! nothing wider. Every path gets one line ([`Outcome::line`]).

use asix_model::config::AsixConfig;
use std::path::{Component, Path, PathBuf};

/// The prefix of every line `/ProtectSecrets` prints and logs (the MSI test looks for it).
pub const PREFIX: &str = "ProtectSecrets:";

/// How many entries of the certificate store are narrowed at most, and how deep.
const MAX_ENTRIES: usize = 10_000;
const MAX_DEPTH: usize = 8;

/// A file or a folder.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// Narrowed when it exists; a missing one is no error.
    File,
    /// Made when missing, then narrowed (what is made in it later inherits it).
    Folder,
    /// A folder as [`Kind::Folder`], and everything already in it narrowed too.
    Tree,
}

/// One path to make private.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Target {
    /// What it is, for the line ("OPC UA private key", ...).
    pub what: String,
    pub path: PathBuf,
    pub kind: Kind,
}

/// `p` with `.` and `..` resolved lexically (so that `..\x` is not taken as below the
/// configuration's folder).
fn lexical(p: &Path) -> PathBuf {
    let mut out = PathBuf::new();
    for c in p.components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir => {
                if !out.pop() {
                    out.push(c);
                }
            }
            other => out.push(other),
        }
    }
    out
}

/// Whether `folder` is strictly below `dir` (a folder of its own, not the configuration's).
fn own_folder(folder: &Path, dir: &Path) -> bool {
    folder != dir && folder.starts_with(dir)
}

/// The paths `/ProtectSecrets` makes private for the configuration `cfg` in the folder
/// `dir`, in order: folders before what is in them. Relative paths are beside the
/// configuration, as the server resolves them.
pub fn plan(cfg: &AsixConfig, dir: &Path) -> Vec<Target> {
    let paths = cfg.secret_paths(dir);
    let dir = lexical(dir);
    let mut out = Vec::new();
    let target = |what: &str, path: PathBuf, kind| Target {
        what: what.to_owned(),
        path,
        kind,
    };
    // A file, after its folder when that is one of its own below the configuration's.
    let file = |out: &mut Vec<Target>, what: &str, p: PathBuf| {
        if let Some(folder) = p.parent().filter(|f| own_folder(f, &dir)) {
            if !out.iter().any(|t: &Target| t.path == folder) {
                out.push(target(
                    &format!("folder of the {what}"),
                    folder.to_path_buf(),
                    Kind::Folder,
                ));
            }
        }
        out.push(target(what, p, Kind::File));
    };
    let pki = lexical(&paths.ua_pki);
    // Never the configuration's folder or one above it as the store.
    if !dir.starts_with(&pki) {
        out.push(target("OPC UA certificate store", pki.clone(), Kind::Tree));
        out.push(target(
            "OPC UA private key folder",
            pki.join(asix_model::config::UA_PRIVATE_KEY_FOLDER),
            Kind::Folder,
        ));
    }
    out.push(target(
        "OPC UA private key",
        lexical(&paths.ua_private_key),
        Kind::File,
    ));
    file(&mut out, "OPC UA users file", lexical(&paths.ua_users_file));
    for (name, key) in &paths.key_files {
        file(
            &mut out,
            &format!("asix link key [Channel:{name}]"),
            lexical(key),
        );
    }
    out
}

/// What became of one path.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Outcome {
    /// An existing file or folder narrowed (`inside`: entries in it narrowed too).
    Narrowed { inside: usize },
    /// A missing folder made and narrowed.
    Made,
    /// A file not there yet.
    Absent,
    /// It could not be made private.
    Failed(String),
}

impl Outcome {
    /// The line for `t`.
    pub fn line(&self, t: &Target) -> String {
        let p = t.path.display();
        let what = &t.what;
        match self {
            Outcome::Narrowed { inside: 0 } => format!("{PREFIX} {what} {p}: private"),
            Outcome::Narrowed { inside } => {
                format!("{PREFIX} {what} {p}: private, with the {inside} entries in it")
            }
            Outcome::Made => format!(
                "{PREFIX} {what} {p}: made private (what is made in it inherits nothing wider)"
            ),
            Outcome::Absent => {
                format!("{PREFIX} {what} {p}: not there yet (made private when written)")
            }
            Outcome::Failed(e) => format!("{PREFIX} {what} {p}: FAILED: {e}"),
        }
    }
}

/// The last line: how many paths ended how, for `source` (the configuration's log line).
pub fn summary(outcomes: &[Outcome], source: &str) -> String {
    let failed = outcomes
        .iter()
        .filter(|o| matches!(o, Outcome::Failed(_)))
        .count();
    let absent = outcomes.iter().filter(|o| **o == Outcome::Absent).count();
    let private = outcomes.len() - failed - absent;
    format!("{PREFIX} {private} paths private, {absent} not there yet, {failed} failed ({source})")
}

/// Makes `t` private on the disk (`ctopc_runtime::secret_file::narrow`, the platform's
/// way once the program installed it).
pub fn apply(t: &Target) -> Outcome {
    use ctopc_runtime::secret_file::narrow;
    let fail = |e: std::io::Error| Outcome::Failed(e.to_string());
    match t.kind {
        Kind::File => match std::fs::symlink_metadata(&t.path) {
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Outcome::Absent,
            Err(e) => fail(e),
            Ok(m) if !m.is_file() => {
                Outcome::Failed("not a file (a folder or a link): left as it is".into())
            }
            Ok(_) => narrow(&t.path).map_or_else(fail, |()| Outcome::Narrowed { inside: 0 }),
        },
        Kind::Folder | Kind::Tree => {
            let existed = match std::fs::symlink_metadata(&t.path) {
                Ok(m) if m.is_dir() => true,
                Ok(_) => return Outcome::Failed("not a folder: left as it is".into()),
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => false,
                Err(e) => return fail(e),
            };
            if !existed {
                if let Err(e) = std::fs::create_dir_all(&t.path) {
                    return fail(e);
                }
            }
            if let Err(e) = narrow(&t.path) {
                return fail(e);
            }
            let inside = if t.kind == Kind::Tree {
                match narrow_inside(&t.path) {
                    Ok(n) => n,
                    Err(e) => return Outcome::Failed(e),
                }
            } else {
                0
            };
            if existed {
                Outcome::Narrowed { inside }
            } else {
                Outcome::Made
            }
        }
    }
}

/// Narrows every file and folder below `dir` (links are left alone): how many; at most
/// [`MAX_ENTRIES`], [`MAX_DEPTH`] deep.
fn narrow_inside(dir: &Path) -> Result<usize, String> {
    let mut count = 0;
    let mut stack = vec![(dir.to_path_buf(), 0)];
    while let Some((d, depth)) = stack.pop() {
        let entries = std::fs::read_dir(&d).map_err(|e| format!("{}: {e}", d.display()))?;
        for e in entries {
            let e = e.map_err(|e| format!("{}: {e}", d.display()))?;
            let p = e.path();
            let t = e.file_type().map_err(|e| format!("{}: {e}", p.display()))?;
            if t.is_symlink() {
                continue;
            }
            count += 1;
            if count > MAX_ENTRIES {
                return Err(format!("more than {MAX_ENTRIES} entries in it"));
            }
            ctopc_runtime::secret_file::narrow(&p).map_err(|e| format!("{}: {e}", p.display()))?;
            if t.is_dir() {
                if depth + 1 >= MAX_DEPTH {
                    return Err(format!("{}: deeper than {MAX_DEPTH} folders", p.display()));
                }
                stack.push((p, depth + 1));
            }
        }
    }
    Ok(count)
}

/// Applies the plan, `say`ing one line per path and the summary; whether nothing failed.
pub fn run(targets: &[Target], source: &str, mut say: impl FnMut(&str)) -> bool {
    let outcomes: Vec<Outcome> = targets
        .iter()
        .map(|t| {
            let o = apply(t);
            say(&o.line(t));
            o
        })
        .collect();
    say(&summary(&outcomes, source));
    !outcomes.iter().any(|o| matches!(o, Outcome::Failed(_)))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cfg(ini: &str, dir: &Path) -> AsixConfig {
        let mut c = asix_model::config::parse_config(ini.as_bytes(), "ASIXConnect.ini")
            .unwrap()
            .0;
        c.base_dir = Some(dir.to_path_buf());
        c
    }

    fn listed(t: &[Target]) -> Vec<(String, String, Kind)> {
        t.iter()
            .map(|t| (t.what.clone(), t.path.display().to_string(), t.kind))
            .collect()
    }

    #[test]
    fn without_a_configuration_the_default_ua_paths_are_planned() {
        let dir = Path::new("/opt/ctopc");
        let want = [
            ("OPC UA certificate store", "/opt/ctopc/pki", Kind::Tree),
            (
                "OPC UA private key folder",
                "/opt/ctopc/pki/private",
                Kind::Folder,
            ),
            (
                "OPC UA private key",
                "/opt/ctopc/pki/private/private.pem",
                Kind::File,
            ),
            ("OPC UA users file", "/opt/ctopc/ua-users.txt", Kind::File),
        ]
        .map(|(w, p, k)| (w.to_owned(), p.to_owned(), k));
        assert_eq!(listed(&plan(&cfg("[Server]\n", dir), dir)), want);
    }

    #[test]
    fn configured_paths_and_their_own_folders_are_planned() {
        let dir = Path::new("/opt/ctopc");
        let ini = "[UA]\nPkiDirectory = ua/pki\nUsersFile = secret/users.txt\n\
                   [Channel:K1]\nAsixNetKeyFile = certs\\k1.pem\n\
                   [Channel:K2]\nAsixNetKeyFile = certs/k2.pem\n\
                   [Channel:K3]\nAsixNetKeyFile = k3.pem\n\
                   [Channel:K4]\nAsixNetKeyFile = /etc/keys/k4.pem\n\
                   [Channel:K5]\nAsixNetKeyFile = ../outside/k5.pem\n";
        let want = [
            ("OPC UA certificate store", "/opt/ctopc/ua/pki", Kind::Tree),
            (
                "OPC UA private key folder",
                "/opt/ctopc/ua/pki/private",
                Kind::Folder,
            ),
            (
                "OPC UA private key",
                "/opt/ctopc/ua/pki/private/private.pem",
                Kind::File,
            ),
            (
                "folder of the OPC UA users file",
                "/opt/ctopc/secret",
                Kind::Folder,
            ),
            (
                "OPC UA users file",
                "/opt/ctopc/secret/users.txt",
                Kind::File,
            ),
            (
                "folder of the asix link key [Channel:K1]",
                "/opt/ctopc/certs",
                Kind::Folder,
            ),
            (
                "asix link key [Channel:K1]",
                "/opt/ctopc/certs/k1.pem",
                Kind::File,
            ),
            // The same folder once.
            (
                "asix link key [Channel:K2]",
                "/opt/ctopc/certs/k2.pem",
                Kind::File,
            ),
            // Beside the configuration, elsewhere, above: the file, never its folder.
            (
                "asix link key [Channel:K3]",
                "/opt/ctopc/k3.pem",
                Kind::File,
            ),
            ("asix link key [Channel:K4]", "/etc/keys/k4.pem", Kind::File),
            (
                "asix link key [Channel:K5]",
                "/opt/outside/k5.pem",
                Kind::File,
            ),
        ]
        .map(|(w, p, k)| (w.to_owned(), p.to_owned(), k));
        assert_eq!(listed(&plan(&cfg(ini, dir), dir)), want);
    }

    #[test]
    fn the_configurations_folder_is_never_a_store_to_narrow() {
        let dir = Path::new("/opt/ctopc");
        for pki in [".", "..", "/opt"] {
            let t = plan(&cfg(&format!("[UA]\nPkiDirectory = {pki}\n"), dir), dir);
            assert!(
                t.iter()
                    .all(|t| t.kind == Kind::File && !dir.starts_with(&t.path)),
                "{pki}: {t:?}"
            );
        }
    }

    #[test]
    fn each_outcome_has_its_line_and_the_summary_counts_them() {
        let t = Target {
            what: "OPC UA private key".into(),
            path: PathBuf::from("/k.pem"),
            kind: Kind::File,
        };
        let lines: Vec<String> = [
            Outcome::Narrowed { inside: 0 },
            Outcome::Narrowed { inside: 3 },
            Outcome::Made,
            Outcome::Absent,
            Outcome::Failed("access denied".into()),
        ]
        .iter()
        .map(|o| o.line(&t))
        .collect();
        assert_eq!(
            lines,
            [
                "ProtectSecrets: OPC UA private key /k.pem: private",
                "ProtectSecrets: OPC UA private key /k.pem: private, with the 3 entries in it",
                "ProtectSecrets: OPC UA private key /k.pem: made private (what is made in it inherits nothing wider)",
                "ProtectSecrets: OPC UA private key /k.pem: not there yet (made private when written)",
                "ProtectSecrets: OPC UA private key /k.pem: FAILED: access denied",
            ]
        );
        assert_eq!(
            summary(
                &[Outcome::Made, Outcome::Absent, Outcome::Failed("x".into())],
                "configuration: x.ini"
            ),
            "ProtectSecrets: 1 paths private, 1 not there yet, 1 failed (configuration: x.ini)"
        );
    }

    /// On the disk (Unix modes here; the DACLs on Windows through the same toolkit): a
    /// fresh folder is made 0700, an existing store narrowed with what is in it, a
    /// world-readable key 0600, a missing users file no error; running again changes
    /// nothing and says so.
    #[cfg(unix)]
    #[test]
    fn the_plan_is_applied_idempotently() {
        use std::os::unix::fs::PermissionsExt as _;
        let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
        let open = |p: &Path, m: u32| {
            std::fs::set_permissions(p, std::fs::Permissions::from_mode(m)).unwrap()
        };
        let dir = std::env::temp_dir().join(format!("ctopc-protect-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let trusted = dir.join("pki/trusted");
        std::fs::create_dir_all(&trusted).unwrap();
        std::fs::write(trusted.join("client.der"), b"cert").unwrap();
        open(&dir.join("pki"), 0o755);
        open(&trusted, 0o755);
        open(&trusted.join("client.der"), 0o644);
        std::fs::create_dir_all(dir.join("certs")).unwrap();
        std::fs::write(dir.join("certs/k1.pem"), b"key").unwrap();
        open(&dir.join("certs/k1.pem"), 0o644);
        open(&dir.join("certs"), 0o755);
        let c = cfg("[Channel:K1]\nAsixNetKeyFile = certs/k1.pem\n", &dir);
        let targets = plan(&c, &dir);
        let mut lines = Vec::new();
        assert!(run(&targets, "test", |l| lines.push(l.to_owned())));
        let d = dir.display();
        assert_eq!(
            lines,
            [
                format!("ProtectSecrets: OPC UA certificate store {d}/pki: private, with the 2 entries in it"),
                format!("ProtectSecrets: OPC UA private key folder {d}/pki/private: made private (what is made in it inherits nothing wider)"),
                format!("ProtectSecrets: OPC UA private key {d}/pki/private/private.pem: not there yet (made private when written)"),
                format!("ProtectSecrets: OPC UA users file {d}/ua-users.txt: not there yet (made private when written)"),
                format!("ProtectSecrets: folder of the asix link key [Channel:K1] {d}/certs: private"),
                format!("ProtectSecrets: asix link key [Channel:K1] {d}/certs/k1.pem: private"),
                "ProtectSecrets: 4 paths private, 2 not there yet, 0 failed (test)".to_owned(),
            ]
        );
        for (p, m) in [
            ("pki", 0o700),
            ("pki/private", 0o700),
            ("pki/trusted", 0o700),
            ("pki/trusted/client.der", 0o600),
            ("certs", 0o700),
            ("certs/k1.pem", 0o600),
        ] {
            assert_eq!(mode(&dir.join(p)), m, "{p}");
        }
        assert!(!dir.join("ua-users.txt").exists());
        // The configuration's folder is left as it is.
        assert_ne!(mode(&dir) & 0o077, 0);
        // Again: the same paths, the folder made before now found.
        lines.clear();
        assert!(run(&targets, "test", |l| lines.push(l.to_owned())));
        assert_eq!(lines.len(), 7);
        assert!(lines[1].ends_with("pki/private: private"), "{lines:?}");
        assert!(lines[0].ends_with("with the 3 entries in it"), "{lines:?}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// A file where a folder is planned (and the reverse) is a failure with its line, and
    /// the others are still done.
    #[cfg(unix)]
    #[test]
    fn a_path_of_the_wrong_kind_fails_with_its_line() {
        let dir = std::env::temp_dir().join(format!("ctopc-protect-kind-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(dir.join("ua-users.txt")).unwrap();
        std::fs::write(dir.join("pki"), b"not a folder").unwrap();
        let c = cfg("[Server]\n", &dir);
        let mut lines = Vec::new();
        assert!(!run(&plan(&c, &dir), "test", |l| lines.push(l.to_owned())));
        assert!(
            lines[0].ends_with("pki: FAILED: not a folder: left as it is"),
            "{lines:?}"
        );
        assert!(
            lines[3].ends_with("FAILED: not a file (a folder or a link): left as it is"),
            "{lines:?}"
        );
        assert!(lines.last().unwrap().contains("failed (test)"), "{lines:?}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
