//! The OPC UA server: async-opcua's server with our node manager beside its core
//! namespace, secure by default, run until a stop signal.
//!
//! - Endpoints: Basic256Sha256, Aes128_Sha256_RsaOaep and Aes256_Sha256_RsaPss, each with
//!   Sign and SignAndEncrypt; SecurityPolicy None only with `allow_none`.
//! - The application instance certificate and its key are made at first start in the
//!   PKI folder (`own/cert.der`, `private/private.pem`); a client certificate not in
//!   `trusted/` is refused and saved in `rejected/` (move it to `trusted/`, or
//!   `ServerCTOPC pki trust FILE`).
//! - Users: [`crate::auth::UsersAuth`] (users file; anonymous only with `allow_anonymous`).
//! - The Server object: ServerStatus (State, StartTime, CurrentTime) and the
//!   ServerDiagnosticsSummary counts kept by async-opcua (diagnostics on; every user may
//!   read them, as every DA client may read `_Diagnostics`), BuildInfo ours
//!   ([`build_info`]).
//! - Listening: on the endpoint's host and port; an unspecified host (`0.0.0.0`) listens
//!   on every interface and the endpoints name the machine's host name.

use crate::auth::UsersAuth;
use crate::engine::EngineClient;
use crate::limits::Limits;
use crate::node_manager::{AsixNodeManager, AsixNodeManagerBuilder, Setup};
use ctopc_core::browse::AddressSpace;
use ctopc_core::lang::Lang;
use ctopc_core::namespace::Namespace;
use ctopc_core::Timestamp;
use ctopc_runtime::Runtime;
use opcua::crypto::SecurityPolicy;
use opcua::server::{ServerBuilder, ServerEndpoint};
use opcua::types::{BuildInfo, DateTime, MessageSecurityMode};
use std::future::Future;
use std::path::PathBuf;
use std::sync::Arc;

/// The `[UA]` settings, as plain values (paths resolved).
#[derive(Debug, Clone, PartialEq)]
pub struct Settings {
    /// `opc.tcp://host:port`.
    pub endpoint: String,
    pub allow_none: bool,
    pub allow_anonymous: bool,
    pub pki_dir: PathBuf,
    /// The application instance certificate's private key (made at first start),
    /// relative to `pki_dir`.
    pub private_key: PathBuf,
    pub users_file: PathBuf,
    pub limits: Limits,
}

/// What the server serves: the runtime's namespace and engine, the browse tree.
pub struct Serve {
    pub runtime: Arc<Runtime>,
    pub namespace: Arc<dyn Namespace>,
    pub tree: Arc<AddressSpace>,
    pub lang: Lang,
}

/// The product URI of the server (BuildInfo, the application description).
pub const PRODUCT_URI: &str = "urn:askom:ServerCTOPC";

/// ServerStatus.BuildInfo: the product, its manufacturer (as the installer names it) and
/// version; BuildDate the modification time of the running executable (when the build
/// or its installation wrote it), null when it cannot be read.
pub fn build_info() -> BuildInfo {
    let version = env!("CARGO_PKG_VERSION");
    let built = std::env::current_exe()
        .and_then(std::fs::metadata)
        .and_then(|m| m.modified())
        .ok()
        .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok())
        .and_then(|d| i64::try_from(d.as_nanos() / 100).ok())
        .map(|ticks| DateTime::from(ticks.saturating_add(Timestamp::UNIX_EPOCH_TICKS)))
        .unwrap_or_else(DateTime::null);
    BuildInfo {
        product_uri: PRODUCT_URI.into(),
        manufacturer_name: "ServerCTOPC project".into(),
        product_name: "ServerCTOPC".into(),
        software_version: version.into(),
        build_number: version.into(),
        build_date: built,
    }
}

/// The host and port of an `opc.tcp://host:port[/path]` URL.
pub fn parse_endpoint(url: &str) -> Result<(String, u16), String> {
    let rest = url
        .strip_prefix("opc.tcp://")
        .ok_or_else(|| format!("endpoint `{url}` is not an opc.tcp:// URL"))?;
    let authority = rest.split('/').next().unwrap_or("");
    let (host, port) = match authority.rsplit_once(':') {
        Some((h, p)) if !h.ends_with(']') || h.starts_with('[') => {
            let port = p
                .parse::<u16>()
                .map_err(|_| format!("endpoint `{url}`: bad port `{p}`"))?;
            (h, port)
        }
        _ => (authority, 4840),
    };
    if host.is_empty() {
        return Err(format!("endpoint `{url}` names no host"));
    }
    Ok((host.trim_matches(|c| c == '[' || c == ']').to_owned(), port))
}

/// The machine's host name (for the endpoints of a server listening everywhere).
fn host_name() -> String {
    let from_env = std::env::var("COMPUTERNAME")
        .or_else(|_| std::env::var("HOSTNAME"))
        .ok();
    let from_file = || {
        std::fs::read_to_string("/etc/hostname")
            .ok()
            .map(|s| s.trim().to_owned())
    };
    from_env
        .or_else(from_file)
        .filter(|h| !h.is_empty())
        .unwrap_or_else(|| "localhost".to_owned())
}

const POLICIES: [SecurityPolicy; 3] = [
    SecurityPolicy::Basic256Sha256,
    SecurityPolicy::Aes128Sha256RsaOaep,
    SecurityPolicy::Aes256Sha256RsaPss,
];

/// A running server: stop it with [`Running::stop`].
pub struct Running {
    handle: opcua::server::ServerHandle,
    task: tokio::task::JoinHandle<Result<(), String>>,
    pub node_manager: Arc<AsixNodeManager>,
    /// Where it listens.
    pub address: std::net::SocketAddr,
}

impl Running {
    /// Cancels the server (sessions are closed) and waits for it to end.
    pub async fn stop(self) -> Result<(), String> {
        self.handle.cancel();
        match self.task.await {
            Ok(r) => r,
            Err(e) => Err(format!("the OPC UA server task failed: {e}")),
        }
    }
}

/// Builds the server and starts listening (on the current tokio runtime).
pub async fn start(settings: &Settings, serve: Serve) -> Result<Running, String> {
    let (host, port) = parse_endpoint(&settings.endpoint)?;
    settings.limits.check()?;
    let everywhere = matches!(host.as_str(), "0.0.0.0" | "::");
    let announced = if everywhere {
        host_name()
    } else {
        host.clone()
    };
    std::fs::create_dir_all(&settings.pki_dir).map_err(|e| {
        format!(
            "cannot make the PKI folder {}: {e}",
            settings.pki_dir.display()
        )
    })?;
    // The private key's folder owner-only before async-opcua makes the key in it (it
    // writes the file with the default mode); the key itself is narrowed once made.
    let key_path = settings.pki_dir.join(&settings.private_key);
    let key_existed = key_path.exists();
    if let Some(private) = key_path.parent().filter(|_| !key_existed) {
        std::fs::create_dir_all(private)
            .and_then(|()| ctopc_runtime::secret_file::narrow(private))
            .map_err(|e| format!("cannot make {}: {e}", private.display()))?;
    }
    let auth = Arc::new(UsersAuth::new(
        settings.users_file.clone(),
        settings.allow_anonymous,
    ));
    let engine = Arc::new(EngineClient::open(serve.runtime));
    let (nm_builder, built) = AsixNodeManagerBuilder::new(Setup {
        namespace: serve.namespace,
        tree: serve.tree,
        engine,
        roles: Arc::clone(&auth) as Arc<dyn crate::node_manager::Roles>,
        lang: serve.lang,
    });
    let nm_builder = nm_builder.limits(&settings.limits);
    let mut b = ServerBuilder::new()
        .application_name("ServerCTOPC")
        .application_uri(format!("urn:{announced}:ASKOM:ServerCTOPC"))
        .product_uri(PRODUCT_URI)
        .build_info(build_info())
        .diagnostics_enabled(true)
        .create_sample_keypair(true)
        .certificate_path("own/cert.der")
        .private_key_path(&settings.private_key)
        .pki_dir(settings.pki_dir.clone())
        .trust_client_certs(false)
        .check_cert_time(true)
        .host(announced.clone())
        .port(port)
        .with_authenticator(auth)
        .with_node_manager(nm_builder)
        .discovery_urls(vec!["/".to_owned()]);
    settings.limits.apply(b.limits_mut());
    for policy in POLICIES {
        for mode in [
            MessageSecurityMode::Sign,
            MessageSecurityMode::SignAndEncrypt,
        ] {
            let id = format!("{policy}_{mode:?}");
            b = b.add_endpoint(id, ServerEndpoint::new("/", policy, mode, &[] as &[String]));
        }
    }
    if settings.allow_none {
        b = b.add_endpoint("none", ServerEndpoint::new_none("/", &[] as &[String]));
    }
    let (server, handle) = b.build()?;
    if !key_existed && key_path.exists() {
        ctopc_runtime::secret_file::narrow(&key_path)
            .map_err(|e| format!("cannot make {} private: {e}", key_path.display()))?;
        tracing::info!(
            "OPC UA: made the application instance certificate and its private key {} (owner only)",
            key_path.display()
        );
    }
    ctopc_runtime::secret_file::warn_if_exposed(&key_path, "OPC UA: the private key");
    ctopc_runtime::secret_file::warn_if_exposed(&settings.users_file, "OPC UA: the users file");
    let node_manager = built
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .take()
        .ok_or("the OPC UA node manager was not built")?;
    let listener = tokio::net::TcpListener::bind((host.as_str(), port))
        .await
        .map_err(|e| {
            format!(
                "cannot listen on {host}:{port} ({}): {e}",
                settings.endpoint
            )
        })?;
    let address = listener
        .local_addr()
        .map_err(|e| format!("cannot listen on {host}:{port}: {e}"))?;
    tracing::info!(
        "OPC UA: listening on {address}; {}",
        describe(settings, &announced, port)
    );
    tracing::info!("OPC UA: {}", settings.limits.describe());
    let task = tokio::spawn(server.run_with(listener));
    Ok(Running {
        handle,
        task,
        node_manager,
        address,
    })
}

/// The start line's account of the endpoints and their security.
fn describe(settings: &Settings, announced: &str, port: u16) -> String {
    let policies: Vec<String> = POLICIES.iter().map(ToString::to_string).collect();
    format!(
        "endpoint opc.tcp://{announced}:{port}/ with {} (Sign, SignAndEncrypt){}; anonymous {}; users {}; PKI {}",
        policies.join(", "),
        if settings.allow_none { ", None (AllowNone)" } else { "; None off" },
        if settings.allow_anonymous { "allowed (as readers)" } else { "off" },
        settings.users_file.display(),
        settings.pki_dir.display(),
    )
}

/// Runs the server until `stop` completes.
pub async fn run(
    settings: &Settings,
    serve: Serve,
    stop: impl Future<Output = ()>,
) -> Result<(), String> {
    let running = start(settings, serve).await?;
    stop.await;
    tracing::info!("OPC UA: stopping");
    running.stop().await
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_start_line_names_the_endpoint_and_its_security() {
        let mut s = Settings {
            endpoint: "opc.tcp://0.0.0.0:4840".into(),
            allow_none: false,
            allow_anonymous: false,
            pki_dir: PathBuf::from("pki"),
            private_key: PathBuf::from("private/private.pem"),
            users_file: PathBuf::from("ua-users.txt"),
            limits: Limits::default(),
        };
        assert_eq!(
            describe(&s, "plant", 4840),
            "endpoint opc.tcp://plant:4840/ with Basic256Sha256, Aes128-Sha256-RsaOaep, \
             Aes256-Sha256-RsaPss (Sign, SignAndEncrypt); None off; anonymous off; \
             users ua-users.txt; PKI pki"
        );
        s.allow_none = true;
        s.allow_anonymous = true;
        let line = describe(&s, "plant", 4841);
        assert!(
            line.contains(
                "(Sign, SignAndEncrypt), None (AllowNone); anonymous allowed (as readers)"
            ),
            "{line}"
        );
    }

    #[test]
    fn build_info_names_the_product_and_its_version() {
        let b = build_info();
        assert_eq!(b.product_name.as_ref(), "ServerCTOPC");
        assert_eq!(b.product_uri.as_ref(), PRODUCT_URI);
        assert_eq!(b.software_version.as_ref(), env!("CARGO_PKG_VERSION"));
        // The test executable was written moments ago.
        let age = DateTime::now().checked_ticks() - b.build_date.checked_ticks();
        assert!((0..=86_400 * 10_000_000).contains(&age), "{}", b.build_date);
    }

    #[test]
    fn endpoints_parse_to_host_and_port() {
        assert_eq!(
            parse_endpoint("opc.tcp://0.0.0.0:4840"),
            Ok(("0.0.0.0".into(), 4840))
        );
        assert_eq!(
            parse_endpoint("opc.tcp://plant/"),
            Ok(("plant".into(), 4840))
        );
        assert_eq!(
            parse_endpoint("opc.tcp://[::1]:4841/x"),
            Ok(("::1".into(), 4841))
        );
        assert!(parse_endpoint("http://plant:4840").is_err());
        assert!(parse_endpoint("opc.tcp://:4840").is_err());
        assert!(parse_endpoint("opc.tcp://plant:http").is_err());
    }
}
