//! Where the configuration comes from: the file the environment variable
//! `SERVERCTOPC_INI` names (full path; for tests and special installations), else
//! `ASIXConnect.ini` in the folder of ServerCTOPC.exe (as the original AsixConnect kept it
//! in its install folder). Without either the server runs the **embedded default**: the
//! Wytwornia_Kwasu demo plant, simulated (OPC_STATUS_TEST). A COM-activated server gets
//! the environment of whoever starts it: under Wine the activating client process (so a
//! test can set the variable before CoCreateInstance), on Windows the DCOM service control
//! manager, i.e. the user's or the system's environment variables.
//!
//! Loading itself (parsing, the databases, the embedded demo) is `asix_model::startup`.

use asix_model::startup::{self, Loaded};
use std::ffi::OsString;
use std::path::{Path, PathBuf};

/// The configuration file's name, looked up next to the executable.
pub const CONFIG_FILE: &str = "ASIXConnect.ini";
/// The environment variable naming a configuration file to use instead of
/// [`CONFIG_FILE`] next to the executable.
pub const CONFIG_ENV: &str = "SERVERCTOPC_INI";

/// Where the configuration came from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ConfigSource {
    /// `ASIXConnect.ini` next to the executable.
    File(PathBuf),
    /// The file named by `SERVERCTOPC_INI`.
    FromEnv(PathBuf),
    EmbeddedDemo,
}

impl ConfigSource {
    /// The log line saying which configuration is used.
    pub fn log_line(&self) -> String {
        match self {
            ConfigSource::File(p) => format!("configuration: {}", p.display()),
            ConfigSource::FromEnv(p) => {
                format!("configuration: {} (from {CONFIG_ENV})", p.display())
            }
            ConfigSource::EmbeddedDemo => "configuration: none found next to the executable; running the embedded demo plant (simulated)".to_owned(),
        }
    }
}

/// Reads the file `SERVERCTOPC_INI` names, else `dir\ASIXConnect.ini`, else the embedded
/// demo (see [`load_with`]).
pub fn load(dir: &Path) -> Result<(ConfigSource, Loaded), String> {
    load_with(std::env::var_os(CONFIG_ENV), dir)
}

/// [`load`] with the value of `SERVERCTOPC_INI` given. An invalid file is an error (naming
/// file, line and option): the server must not silently run without the configuration
/// the engineer wrote; so is a file named by `SERVERCTOPC_INI` that does not exist. An
/// empty `SERVERCTOPC_INI` counts as not set.
pub fn load_with(env: Option<OsString>, dir: &Path) -> Result<(ConfigSource, Loaded), String> {
    let from_env = env.filter(|v| !v.is_empty()).map(PathBuf::from);
    if let Some(path) = from_env {
        let loaded = startup::load_file(&path).map_err(|e| format!("{CONFIG_ENV}: {e}"))?;
        return Ok((ConfigSource::FromEnv(path), loaded));
    }
    let path = dir.join(CONFIG_FILE);
    if path.exists() {
        let loaded = startup::load_file(&path)?;
        return Ok((ConfigSource::File(path), loaded));
    }
    Ok((ConfigSource::EmbeddedDemo, startup::embedded_demo()?))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A fresh, empty folder of this test.
    fn temp_dir(name: &str) -> PathBuf {
        let dir =
            std::env::temp_dir().join(format!("serverctopc-config-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    #[test]
    fn without_a_file_the_embedded_demo_runs() {
        let dir = temp_dir("none");
        let (source, loaded) = load_with(None, &dir).unwrap();
        assert_eq!(source, ConfigSource::EmbeddedDemo);
        assert!(loaded.namespace.config().server.simulate_current_data);
        assert_eq!(loaded.namespace.no_config_reason(), None);
        // An empty variable counts as not set.
        let (source, _) = load_with(Some(OsString::new()), &dir).unwrap();
        assert_eq!(source, ConfigSource::EmbeddedDemo);
        assert_eq!(
            source.log_line(),
            "configuration: none found next to the executable; running the embedded demo plant (simulated)"
        );
    }

    #[test]
    fn the_file_next_to_the_executable_is_used_with_its_folder_as_base() {
        let dir = temp_dir("file");
        let path = dir.join(CONFIG_FILE);
        std::fs::write(&path, "[Server]\nMinUpdateRate = 250\n").unwrap();
        let (source, loaded) = load_with(None, &dir).unwrap();
        assert_eq!(source, ConfigSource::File(path.clone()));
        let config = loaded.namespace.config();
        assert_eq!(config.server.min_update_rate_ms, 250);
        assert_eq!(config.base_dir.as_deref(), Some(dir.as_path()));
        assert_eq!(
            source.log_line(),
            format!("configuration: {}", path.display())
        );
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn serverctopc_ini_wins_over_the_file_next_to_the_executable() {
        let dir = temp_dir("env");
        std::fs::write(dir.join(CONFIG_FILE), "[Server]\nMinUpdateRate = 250\n").unwrap();
        let other = dir.join("other.ini");
        std::fs::write(&other, "[Server]\nMinUpdateRate = 500\n").unwrap();
        let (source, loaded) = load_with(Some(other.clone().into()), &dir).unwrap();
        assert_eq!(source, ConfigSource::FromEnv(other.clone()));
        assert_eq!(loaded.namespace.config().server.min_update_rate_ms, 500);
        assert_eq!(
            source.log_line(),
            format!("configuration: {} (from SERVERCTOPC_INI)", other.display())
        );
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_missing_serverctopc_ini_file_is_an_error_naming_the_variable_and_file() {
        let dir = temp_dir("missing");
        let missing = dir.join("missing.ini");
        let e = load_with(Some(missing.clone().into()), &dir).unwrap_err();
        assert!(
            e.starts_with(&format!("SERVERCTOPC_INI: {}", missing.display())),
            "{e}"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn an_invalid_file_is_an_error_naming_file_line_and_option() {
        let dir = temp_dir("invalid");
        let path = dir.join(CONFIG_FILE);
        std::fs::write(&path, "[Server]\nMinUpdateRate = 0\n").unwrap();
        let e = load_with(None, &dir).unwrap_err();
        assert!(e.contains(&path.display().to_string()), "{e}");
        assert!(e.contains("MinUpdateRate"), "{e}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
