//! The users file of the OPC UA front end: one user a line,
//! `name:role:pbkdf2-sha256:<iterations>:<salt hex>:<hash hex>`, `#` comments. Roles are
//! `reader` (browse, read, subscribe) and `writer` (also write). Passwords are kept only
//! as salted PBKDF2-HMAC-SHA256 hashes; `ServerCTOPC user add` writes the file.
//!
//! The file is read at each login (a user added while the server runs can log in at
//! once), at most [`MAX_FILE_BYTES`] of it.

use std::path::Path;

/// The largest users file read.
pub const MAX_FILE_BYTES: u64 = 1 << 20;
/// PBKDF2 iterations of new hashes.
pub const ITERATIONS: u32 = 100_000;
const SCHEME: &str = "pbkdf2-sha256";

/// What a user may do.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    Reader,
    Writer,
}

impl Role {
    pub fn parse(s: &str) -> Option<Role> {
        match s {
            "reader" => Some(Role::Reader),
            "writer" => Some(Role::Writer),
            _ => None,
        }
    }
    pub fn name(self) -> &'static str {
        match self {
            Role::Reader => "reader",
            Role::Writer => "writer",
        }
    }
}

/// One user of the file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct User {
    pub name: String,
    pub role: Role,
    iterations: u32,
    salt: Vec<u8>,
    hash: Vec<u8>,
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

fn unhex(s: &str) -> Option<Vec<u8>> {
    if !s.len().is_multiple_of(2) {
        return None;
    }
    (0..s.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(s.get(i..i + 2)?, 16).ok())
        .collect()
}

fn derive(password: &str, salt: &[u8], iterations: u32) -> [u8; 32] {
    let mut out = [0u8; 32];
    pbkdf2::pbkdf2_hmac::<sha2::Sha256>(password.as_bytes(), salt, iterations, &mut out);
    out
}

/// A user name is 1-64 characters, none of them `:`, blank or a control character.
pub fn valid_name(name: &str) -> bool {
    !name.is_empty()
        && name.chars().count() <= 64
        && !name
            .chars()
            .any(|c| c == ':' || c.is_whitespace() || c.is_control())
}

impl User {
    /// A user with a new random salt.
    pub fn new(name: &str, role: Role, password: &str) -> User {
        let mut salt = [0u8; 16];
        opcua::crypto::random::bytes(&mut salt);
        User {
            name: name.to_owned(),
            role,
            iterations: ITERATIONS,
            salt: salt.to_vec(),
            hash: derive(password, &salt, ITERATIONS).to_vec(),
        }
    }

    /// True when `password` is this user's (compared in constant time).
    pub fn verify(&self, password: &str) -> bool {
        let got = derive(password, &self.salt, self.iterations);
        got.len() == self.hash.len()
            && got
                .iter()
                .zip(&self.hash)
                .fold(0u8, |acc, (a, b)| acc | (a ^ b))
                == 0
    }

    fn line(&self) -> String {
        format!(
            "{}:{}:{SCHEME}:{}:{}:{}",
            self.name,
            self.role.name(),
            self.iterations,
            hex(&self.salt),
            hex(&self.hash)
        )
    }

    fn parse(line: &str) -> Option<User> {
        let mut f = line.split(':');
        let name = f.next()?;
        let role = Role::parse(f.next()?)?;
        if f.next()? != SCHEME {
            return None;
        }
        let iterations: u32 = f
            .next()?
            .parse()
            .ok()
            .filter(|&n| (1..=10_000_000).contains(&n))?;
        let salt = unhex(f.next()?)?;
        let hash = unhex(f.next()?)?;
        if f.next().is_some() || !valid_name(name) || hash.len() != 32 {
            return None;
        }
        Some(User {
            name: name.to_owned(),
            role,
            iterations,
            salt,
            hash,
        })
    }
}

/// The users of a file's text; malformed lines are skipped with a warning.
pub fn parse(text: &str, file: &str) -> Vec<User> {
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        match User::parse(line) {
            Some(u) => out.push(u),
            None => tracing::warn!("{file}:{}: not a user line; ignored", n + 1),
        }
    }
    out
}

/// Reads the users file (none when it does not exist).
pub fn load(path: &Path) -> Result<Vec<User>, String> {
    use std::io::Read;
    let f = match std::fs::File::open(path) {
        Ok(f) => f,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => return Err(format!("cannot read {}: {e}", path.display())),
    };
    let mut text = String::new();
    f.take(MAX_FILE_BYTES)
        .read_to_string(&mut text)
        .map_err(|e| format!("cannot read {}: {e}", path.display()))?;
    Ok(parse(&text, &path.display().to_string()))
}

/// Adds a user to the file (replacing one of the same name), keeping the other lines; the
/// file is written owner-only (`ctopc_runtime::secret_file`).
pub fn add(path: &Path, user: &User) -> Result<(), String> {
    let old = match std::fs::read_to_string(path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            "# OPC UA users of ServerCTOPC: name:role:pbkdf2-sha256:iterations:salt:hash\n".into()
        }
        Err(e) => return Err(format!("cannot read {}: {e}", path.display())),
    };
    let mut text = String::new();
    for line in old.lines() {
        let same = line.split(':').next() == Some(user.name.as_str()) && !line.starts_with('#');
        if !same {
            text.push_str(line);
            text.push('\n');
        }
    }
    text.push_str(&user.line());
    text.push('\n');
    // Readable by the server's account only (0600 on Unix): the hashes are offline-guessable.
    ctopc_runtime::secret_file::write(path, text.as_bytes())
        .map_err(|e| format!("cannot write {}: {e}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_user_line_round_trips_and_verifies_only_its_password() {
        let u = User::new("anna", Role::Writer, "tajne hasło");
        let back = parse(&u.line(), "t");
        assert_eq!(back, vec![u.clone()]);
        assert!(back[0].verify("tajne hasło"));
        assert!(!back[0].verify("tajne haslo"));
        assert!(!back[0].verify(""));
        // Two users with one password have different hashes (salted).
        let v = User::new("bob", Role::Reader, "tajne hasło");
        assert_ne!(u.hash, v.hash);
    }

    #[test]
    fn malformed_lines_and_names_are_refused() {
        for line in [
            "anna",
            "anna:admin:pbkdf2-sha256:1:00:00",
            "anna:reader:md5:1:00:00",
            "anna:reader:pbkdf2-sha256:0:00:00",
            "anna:reader:pbkdf2-sha256:10:zz:00",
            "anna:reader:pbkdf2-sha256:10:00:0000",
        ] {
            assert!(parse(line, "t").is_empty(), "{line}");
        }
        assert!(valid_name("operator_1"));
        for bad in ["", "a:b", "a b", "a\tb"] {
            assert!(!valid_name(bad), "{bad:?}");
        }
    }

    #[test]
    fn add_replaces_a_user_and_keeps_the_others() {
        let dir = std::env::temp_dir().join(format!("ctopc-ua-users-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("users.txt");
        let _ = std::fs::remove_file(&path);
        add(&path, &User::new("anna", Role::Reader, "a")).unwrap();
        add(&path, &User::new("bob", Role::Reader, "b")).unwrap();
        add(&path, &User::new("anna", Role::Writer, "c")).unwrap();
        let users = load(&path).unwrap();
        assert_eq!(users.len(), 2);
        let anna = users.iter().find(|u| u.name == "anna").unwrap();
        assert_eq!(anna.role, Role::Writer);
        assert!(anna.verify("c"));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// `ServerCTOPC user add`'s file is owner-only, also one that was open before.
    #[cfg(unix)]
    #[test]
    fn the_users_file_is_written_owner_only() {
        use std::os::unix::fs::PermissionsExt as _;
        let dir = std::env::temp_dir().join(format!("ctopc-ua-mode-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("users.txt");
        let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
        add(&path, &User::new("anna", Role::Reader, "a")).unwrap();
        assert_eq!(mode(&path), 0o600);
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o644)).unwrap();
        add(&path, &User::new("bob", Role::Writer, "b")).unwrap();
        assert_eq!(mode(&path), 0o600);
        assert_eq!(load(&path).unwrap().len(), 2);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
