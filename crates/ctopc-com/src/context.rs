//! The process context every COM object works in: the runtime (engine + data source), the
//! asix namespace, the browse address space, the server state and the default language.
//!
//! Configuration: the file the environment variable `SERVERCTOPC_INI` names (full path;
//! for tests and special installations), else `ASIXConnect.ini` in the folder of
//! ServerCTOPC.exe (as the original AsixConnect kept it in its install folder). Without
//! either the server runs the **embedded default**: the Wytwornia_Kwasu demo plant,
//! simulated (OPC_STATUS_TEST). A COM-activated server gets the environment of whoever
//! starts it: under Wine the activating client process (so a test can set the variable
//! before CoCreateInstance), on Windows the DCOM service control manager, i.e. the
//! user's or the system's environment variables.

use crate::interfaces::{OPCSERVERSTATE, OPC_STATUS_NOCONFIG, OPC_STATUS_RUNNING, OPC_STATUS_TEST};
use crate::runtime::Runtime;
use asix_model::address_space::build_address_space;
use asix_model::vardb::{parse_attribute_table, parse_var_set};
use asix_model::{parse_config, AsixNamespace, ChannelDatabase, VarDatabase};
use ctopc_core::browse::AddressSpace;
use ctopc_core::Lang;
use std::path::{Path, PathBuf};
use std::sync::{Arc, OnceLock};

/// The configuration file's name, looked up next to the executable.
pub const CONFIG_FILE: &str = "ASIXConnect.ini";
/// The environment variable naming a configuration file to use instead of
/// [`CONFIG_FILE`] next to the executable.
pub const CONFIG_ENV: &str = "SERVERCTOPC_INI";

const DEMO_INI: &str = "\
; The embedded default: the Wytwornia_Kwasu demo plant, simulated.
[Server]
SimulateCurrentData = tak
[Channel:*]
CheckLimits = tak
CheckControlVariables = tak
";
const DEMO_TABLE: &[u8] = include_bytes!("../../../demo/wytwornia_kwasu/atrybuty.csv");
const DEMO_SET: &[u8] = include_bytes!("../../../demo/wytwornia_kwasu/wytwornia_kwasu.zez");

/// Where the configuration came from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ConfigSource {
    /// `ASIXConnect.ini` next to the executable.
    File(PathBuf),
    /// The file named by `SERVERCTOPC_INI`.
    FromEnv(PathBuf),
    EmbeddedDemo,
}

/// The loaded configuration, before the runtime starts.
pub struct Loaded {
    pub namespace: AsixNamespace,
    pub source: ConfigSource,
    /// Lines to log (unknown options, database warnings).
    pub warnings: Vec<String>,
}

/// Reads the file `SERVERCTOPC_INI` names, else `dir\ASIXConnect.ini`, else the embedded
/// demo. An invalid file is an error (naming file, line and option): the server must not
/// silently run without the configuration the engineer wrote; so is a file named by
/// `SERVERCTOPC_INI` that does not exist. An empty `SERVERCTOPC_INI` counts as not set.
pub fn load(dir: &Path) -> Result<Loaded, String> {
    let from_env = std::env::var_os(CONFIG_ENV)
        .filter(|v| !v.is_empty())
        .map(PathBuf::from);
    if let Some(path) = from_env {
        let loaded = load_file(&path, ConfigSource::FromEnv(path.clone()));
        return loaded.map_err(|e| format!("{CONFIG_ENV}: {e}"));
    }
    let path = dir.join(CONFIG_FILE);
    if path.exists() {
        return load_file(&path, ConfigSource::File(path.clone()));
    }
    embedded_demo()
}

fn load_file(path: &Path, source: ConfigSource) -> Result<Loaded, String> {
    let (cfg, w) = asix_model::load_config_file(path).map_err(|e| e.to_string())?;
    let (ns, dbw) = AsixNamespace::load(cfg);
    let warnings = w
        .iter()
        .chain(dbw.iter())
        .map(ToString::to_string)
        .collect();
    Ok(Loaded {
        namespace: ns,
        source,
        warnings,
    })
}

/// The embedded default configuration: the demo plant database in channel `*`, simulated.
pub fn embedded_demo() -> Result<Loaded, String> {
    let (cfg, _) = parse_config(DEMO_INI.as_bytes(), "<embedded>").map_err(|e| e.to_string())?;
    let table =
        parse_attribute_table(DEMO_TABLE, "<embedded>/atrybuty.csv").map_err(|e| e.to_string())?;
    let (set, mut warnings) =
        parse_var_set(DEMO_SET, "<embedded>/wytwornia_kwasu.zez").map_err(|e| e.to_string())?;
    let (db, w2) = VarDatabase::build(&table, Some(&set), None).map_err(|e| e.to_string())?;
    warnings.extend(w2);
    let mut ns = AsixNamespace::new(cfg);
    ns.set_database(
        asix_model::BASIC_CHANNEL,
        ChannelDatabase::Loaded(Arc::new(db)),
    );
    Ok(Loaded {
        namespace: ns,
        source: ConfigSource::EmbeddedDemo,
        warnings: warnings.iter().map(ToString::to_string).collect(),
    })
}

/// Everything COM objects share.
pub struct Context {
    pub runtime: Arc<Runtime>,
    pub namespace: Arc<AsixNamespace>,
    pub address_space: Arc<AddressSpace>,
    pub state: OPCSERVERSTATE,
    /// Why the state is OPC_STATUS_NOCONFIG, if it is.
    pub no_config_reason: Option<String>,
    pub default_lang: Lang,
    pub source: ConfigSource,
}

impl Context {
    /// The state a namespace and backend imply: NOCONFIG when channel `*`'s database is
    /// missing or failed, TEST when simulating, else RUNNING.
    pub fn state_for(ns: &AsixNamespace, simulation: bool) -> (OPCSERVERSTATE, Option<String>) {
        if let Some(reason) = ns.no_config_reason() {
            return (OPC_STATUS_NOCONFIG, Some(reason));
        }
        if simulation {
            (OPC_STATUS_TEST, None)
        } else {
            (OPC_STATUS_RUNNING, None)
        }
    }

    pub fn address_space_for(ns: &AsixNamespace) -> Arc<AddressSpace> {
        match build_address_space(ns) {
            Ok(a) => Arc::new(a),
            Err(e) => {
                tracing::error!(
                    "cannot build the browse tree: {e:?}; browsing shows an empty tree"
                );
                Arc::new(AddressSpace::empty())
            }
        }
    }
}

static CONTEXT: OnceLock<Context> = OnceLock::new();

/// Installs the process context (once per process).
pub fn install(ctx: Context) -> Result<&'static Context, String> {
    CONTEXT
        .set(ctx)
        .map_err(|_| "the server context is already installed".to_string())?;
    CONTEXT
        .get()
        .ok_or_else(|| "the server context is missing".to_string())
}

/// The process context, once the server has started.
pub fn get() -> Option<&'static Context> {
    CONTEXT.get()
}
