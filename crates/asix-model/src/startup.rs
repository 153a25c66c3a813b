//! The configuration a server starts with: an `ASIXConnect.ini` (from a file, or from its
//! bytes) with every channel's variable database loaded, or the **embedded default**, the
//! Wytwornia_Kwasu demo plant in channel `*`, simulated.
//!
//! Where the file comes from (the environment variable, the install folder) is the server
//! binary's business (`crates/server`); this module only turns a configuration into a
//! [`Loaded`] namespace. [`embedded_demo`] and [`load`] of a configuration without
//! `ItemsDatabase` touch no file; [`load_file`] reads the file it is given and the
//! databases it names.

use crate::config::{load_config_file, parse_config, AsixConfig, BASIC_CHANNEL};
use crate::namespace::{AsixNamespace, ChannelDatabase};
use crate::text::Warning;
use crate::vardb::{parse_attribute_table, parse_var_set, VarDatabase};
use std::path::Path;
use std::sync::Arc;

/// The embedded default configuration (`ASIXConnect.ini` text).
pub const DEMO_INI: &str = "\
; The embedded default: the Wytwornia_Kwasu demo plant, simulated.
[Server]
SimulateCurrentData = tak
[Channel:*]
CheckLimits = tak
CheckControlVariables = tak
";
/// The demo plant's attribute table (`demo/wytwornia_kwasu/atrybuty.csv`).
pub const DEMO_TABLE: &[u8] = include_bytes!("../../../demo/wytwornia_kwasu/atrybuty.csv");
/// The demo plant's variable set (`demo/wytwornia_kwasu/wytwornia_kwasu.zez`).
pub const DEMO_SET: &[u8] = include_bytes!("../../../demo/wytwornia_kwasu/wytwornia_kwasu.zez");

/// A loaded configuration, before the server starts.
#[derive(Debug)]
pub struct Loaded {
    pub namespace: AsixNamespace,
    /// Lines to log (unknown options, database warnings).
    pub warnings: Vec<String>,
}

/// The embedded default: the demo plant database in channel `*`, simulated. Pure.
pub fn embedded_demo() -> Result<Loaded, String> {
    let (cfg, _) = parse_config(DEMO_INI.as_bytes(), "<embedded>").map_err(|e| e.to_string())?;
    let table =
        parse_attribute_table(DEMO_TABLE, "<embedded>/atrybuty.csv").map_err(|e| e.to_string())?;
    let (set, mut warnings) =
        parse_var_set(DEMO_SET, "<embedded>/wytwornia_kwasu.zez").map_err(|e| e.to_string())?;
    let (db, w2) = VarDatabase::build(&table, Some(&set), None).map_err(|e| e.to_string())?;
    warnings.extend(w2);
    let mut ns = AsixNamespace::new(cfg);
    ns.set_database(BASIC_CHANNEL, ChannelDatabase::Loaded(Arc::new(db)));
    Ok(Loaded {
        namespace: ns,
        warnings: warnings.iter().map(ToString::to_string).collect(),
    })
}

/// A configuration from the bytes of an `ASIXConnect.ini`; `file` names it in messages and
/// `base_dir` is the folder relative paths in it are taken from (the file's folder). The
/// databases it names are loaded (a failure is kept per channel, see
/// [`AsixNamespace::load`]). An invalid configuration is an error naming file, line and
/// option.
pub fn load(bytes: &[u8], file: &str, base_dir: Option<&Path>) -> Result<Loaded, String> {
    let (mut cfg, w) = parse_config(bytes, file).map_err(|e| e.to_string())?;
    cfg.base_dir = base_dir.map(Path::to_path_buf);
    Ok(with_databases(cfg, &w))
}

/// [`load`] of the file at `path` (an error also when it is missing or unreadable).
pub fn load_file(path: &Path) -> Result<Loaded, String> {
    let (cfg, w) = load_config_file(path).map_err(|e| e.to_string())?;
    Ok(with_databases(cfg, &w))
}

fn with_databases(cfg: AsixConfig, config_warnings: &[Warning]) -> Loaded {
    let (ns, dbw) = AsixNamespace::load(cfg);
    let warnings = config_warnings
        .iter()
        .chain(dbw.iter())
        .map(ToString::to_string)
        .collect();
    Loaded {
        namespace: ns,
        warnings,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ctopc_core::namespace::Namespace;

    #[test]
    fn the_embedded_demo_is_the_simulated_demo_plant_in_the_basic_channel() {
        let loaded = embedded_demo().unwrap();
        assert!(loaded.warnings.is_empty(), "{:?}", loaded.warnings);
        let ns = &loaded.namespace;
        assert!(ns.config().server.simulate_current_data);
        assert_eq!(ns.no_config_reason(), None);
        let db = ns.database(BASIC_CHANNEL).expect("the demo database");
        assert_eq!(db.variables.len(), 228);
        assert_eq!(db.visible_count(), 228);
        let channel = &ns.config().channels[BASIC_CHANNEL];
        assert!(channel.check_limits);
        assert!(channel.check_control_variables);
    }

    #[test]
    fn the_embedded_demo_resolves_demo_variables() {
        let loaded = embedded_demo().unwrap();
        let name = loaded
            .namespace
            .database(BASIC_CHANNEL)
            .and_then(|db| db.variables.first().map(|v| v.public_name.clone()))
            .unwrap();
        assert!(loaded.namespace.resolve(&name, "").is_ok());
    }

    #[test]
    fn load_from_text_keeps_the_base_dir_and_reports_a_missing_database_per_channel() {
        let ini = b"[Server]\nSimulateCurrentData = tak\nNoSuchOption = 1\n[Channel:*]\nItemsDatabase = missing.zez\n";
        let dir = Path::new("/nonexistent/asix");
        let loaded = load(ini, "test.ini", Some(dir)).unwrap();
        let ns = &loaded.namespace;
        assert_eq!(ns.config().base_dir.as_deref(), Some(dir));
        assert!(ns.config().server.simulate_current_data);
        assert!(
            loaded.warnings.iter().any(|w| w.contains("NoSuchOption")),
            "{:?}",
            loaded.warnings
        );
        assert!(matches!(
            ns.database_state(BASIC_CHANNEL),
            ChannelDatabase::Failed(_)
        ));
        assert!(ns.no_config_reason().is_some());
    }

    #[test]
    fn load_from_text_without_a_database_is_no_config() {
        let loaded = load(b"[Server]\n", "test.ini", None).unwrap();
        assert_eq!(
            loaded.namespace.no_config_reason().as_deref(),
            Some("no ItemsDatabase is configured for channel *")
        );
    }

    #[test]
    fn an_invalid_value_is_an_error_naming_the_file() {
        let e = load(b"[Server]\nMinUpdateRate = abc\n", "bad.ini", None).unwrap_err();
        assert!(e.contains("bad.ini"), "{e}");
        assert!(e.contains("MinUpdateRate"), "{e}");
    }

    #[test]
    fn a_missing_file_is_an_error() {
        let e = load_file(Path::new("/nonexistent/ASIXConnect.ini")).unwrap_err();
        assert!(e.contains("/nonexistent/ASIXConnect.ini"), "{e}");
    }
}
