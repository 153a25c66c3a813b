//! `opcdiag --url opc.tcp://HOST:PORT browse|read|write|subscribe`: the same commands over
//! OPC UA, with async-opcua's client, on every host but 32-bit Windows; and `opcdiag cert`.
//!
//! One session per run: GetEndpoints, the endpoint of `--security`/`--policy`, the
//! server's certificate checked against opcdiag's PKI folder (`trusted/`; an unknown one is
//! refused and saved in `rejected/` unless `--trust-server` pins its thumbprint or accepts
//! it), then CreateSession/ActivateSession with the user or anonymously. No reconnects: a
//! refused or lost session ends the run with exit code 3 and the reason. What is shown is
//! formatted in [`show`] (pure, tested natively); the output goes through `out` as the DA
//! commands' does.

pub mod show;

use crate::cli::{
    Command, Global, Security, TrustServer, UaOptions, EXIT_FAILED, EXIT_NO_SESSION, EXIT_OK,
    EXIT_USAGE,
};
use crate::{out, text};
use opcua::client::{
    Client, ClientBuilder, DataChangeCallback, IdentityToken, MonitoredItem, Session,
};
use opcua::crypto::{CertificateStore, SecurityPolicy, X509};
use opcua::types::{
    AttributeId, BrowseDescription, BrowseDirection, BrowseResultMask, ByteString, DataValue,
    EndpointDescription, ExtensionObject, MessageSecurityMode, MonitoredItemCreateRequest,
    MonitoringMode, MonitoringParameters, NodeClassMask, NodeId, ObjectId, ReadValueId,
    ReferenceTypeId, StatusCode, TimestampsToReturn, WriteValue,
};
use show::NodeArg;
use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// `say!` over the same closed-pipe-safe output as the DA commands.
macro_rules! say {
    () => { out::line(format_args!("")) };
    ($($t:tt)*) => { out::line(format_args!($($t)*)) };
}

/// opcdiag's application URI (in its certificate and its session).
const APPLICATION_URI: &str = "urn:askom:opcdiag";
/// Every request's timeout: no call can hang.
const REQUEST_TIMEOUT: Duration = Duration::from_secs(10);
/// How long the connection (GetEndpoints, the secure channel, the session) may take.
const CONNECT_TIMEOUT: Duration = Duration::from_secs(20);
/// `read`'s MaxAge without `--device` (ms).
const CACHE_MAX_AGE_MS: f64 = 1000.0;
/// How long `read` asks again while a value is Bad_WaitingForInitialData.
const WAIT_FIRST_VALUE: Duration = Duration::from_secs(3);
/// Changes the subscription may hold before they are printed; more are counted as lost.
const CHANGE_BUFFER: usize = 4096;
/// The largest browse tree walked (nodes): a bound on memory against any server.
const MAX_BROWSED: usize = 1_000_000;

/// Why a command ended early: the exit code and the message.
struct Failure {
    code: u8,
    message: String,
}

fn failed(message: impl Into<String>) -> Failure {
    Failure {
        code: EXIT_FAILED,
        message: message.into(),
    }
}

fn no_session(message: impl Into<String>) -> Failure {
    Failure {
        code: EXIT_NO_SESSION,
        message: message.into(),
    }
}

/// Runs an OPC UA command; the exit code.
pub fn run(global: &Global, command: Command) -> u8 {
    let runtime = match tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
    {
        Ok(r) => r,
        Err(e) => {
            eprintln!("opcdiag: cannot start the async runtime: {e}");
            return EXIT_FAILED;
        }
    };
    let result = runtime.block_on(async {
        match command {
            Command::Cert => cert(&global.ua),
            command => {
                let mut conn = Connection::open(&global.ua).await?;
                let result = conn.command(command).await;
                conn.close().await;
                result
            }
        }
    });
    // The session's tasks end with the runtime; none may keep the process alive.
    runtime.shutdown_timeout(Duration::from_secs(2));
    match result {
        Ok(code) => code,
        Err(f) => {
            eprintln!("opcdiag: {}", f.message);
            f.code
        }
    }
}

/// opcdiag's PKI folder: `--pki`, else `<configuration folder>/opcdiag/pki`.
fn pki_dir(o: &UaOptions) -> Result<PathBuf, Failure> {
    if let Some(dir) = &o.pki {
        return Ok(PathBuf::from(dir));
    }
    let env = |k: &str| {
        std::env::var_os(k)
            .filter(|v| !v.is_empty())
            .map(PathBuf::from)
    };
    let base = if cfg!(windows) {
        env("APPDATA")
    } else {
        env("XDG_CONFIG_HOME").or_else(|| env("HOME").map(|h| h.join(".config")))
    };
    base.map(|b| b.join("opcdiag").join("pki"))
        .ok_or_else(|| failed("no configuration folder (HOME/APPDATA unset): give --pki DIR"))
}

/// The client with its certificate (made at first use, said on stderr).
fn client(o: &UaOptions) -> Result<(Client, PathBuf), Failure> {
    let pki = pki_dir(o)?;
    let own = pki.join("own").join("cert.der");
    let fresh = !own.exists();
    let client = ClientBuilder::new()
        .application_name("opcdiag")
        .application_uri(APPLICATION_URI)
        .product_uri(APPLICATION_URI)
        .pki_dir(&pki)
        .create_sample_keypair(true)
        .trust_server_certs(false)
        .verify_server_certs(true)
        .session_retry_limit(0)
        .request_timeout(REQUEST_TIMEOUT)
        .session_name("opcdiag")
        .client()
        .map_err(|e| failed(format!("the OPC UA client: {}", e.join("; "))))?;
    let thumbprint = own_thumbprint(&own)?;
    if fresh {
        eprintln!(
            "opcdiag: made the client certificate {} (SHA-1 thumbprint {thumbprint}); a server \
             refuses it until trusted: on ServerCTOPC, `ServerCTOPC pki trust {}`",
            own.display(),
            own.display()
        );
    }
    Ok((client, pki))
}

/// The SHA-1 thumbprint of opcdiag's own certificate.
fn own_thumbprint(own: &Path) -> Result<String, Failure> {
    let cert = CertificateStore::read_cert(own).map_err(|e| {
        failed(format!(
            "cannot read the client certificate {}: {e}",
            own.display()
        ))
    })?;
    Ok(cert.thumbprint().as_hex_string())
}

/// `opcdiag cert`.
fn cert(o: &UaOptions) -> Result<u8, Failure> {
    let (_client, pki) = client(o)?;
    let own = pki.join("own").join("cert.der");
    let thumbprint = own_thumbprint(&own)?;
    say!("Certificate   {}", own.display());
    say!("Thumbprint    {thumbprint} (SHA-1)");
    say!("Application   {APPLICATION_URI}");
    say!("Trusted       {}", pki.join("trusted").display());
    say!("Rejected      {}", pki.join("rejected").display());
    say!("On ServerCTOPC: ServerCTOPC pki trust {}", own.display());
    Ok(EXIT_OK)
}

fn mode_of(s: Security) -> MessageSecurityMode {
    match s {
        Security::None => MessageSecurityMode::None,
        Security::Sign => MessageSecurityMode::Sign,
        Security::Encrypt => MessageSecurityMode::SignAndEncrypt,
    }
}

/// The user's identity: anonymous, or the user with the password from the first line of
/// standard input (`--password-stdin`) or asked on the terminal without echo.
fn identity(o: &UaOptions) -> Result<IdentityToken, Failure> {
    use std::io::IsTerminal;
    let Some(user) = &o.user else {
        return Ok(IdentityToken::Anonymous);
    };
    let line = if o.password_stdin {
        let mut line = String::new();
        std::io::stdin()
            .read_line(&mut line)
            .map_err(|e| failed(format!("cannot read the password: {e}")))?;
        line
    } else if std::io::stdin().is_terminal() {
        rpassword::prompt_password(format!("Password for {user}: "))
            .map_err(|e| failed(format!("cannot read the password: {e}")))?
    } else {
        return Err(Failure {
            code: EXIT_USAGE,
            message: format!(
                "standard input is not a terminal: cannot ask for the password of {user}; \
                 pipe it with --password-stdin"
            ),
        });
    };
    let password = line.trim_end_matches(['\n', '\r']);
    if password.is_empty() {
        return Err(Failure {
            code: EXIT_USAGE,
            message: format!("no password for {user} (the first line of standard input)"),
        });
    }
    Ok(IdentityToken::new_user_name(user.clone(), password))
}

/// The server's certificate against opcdiag's `trusted/`: known, or trusted now as
/// `--trust-server` says, or refused (and saved in `rejected/`).
fn check_server_certificate(
    pki: &Path,
    endpoint: &EndpointDescription,
    trust: Option<&TrustServer>,
) -> Result<(), Failure> {
    let cert = X509::from_byte_string(&endpoint.server_certificate).map_err(|e| {
        no_session(format!(
            "the server's certificate cannot be read: {}",
            show::status_error(e.status())
        ))
    })?;
    let name = CertificateStore::cert_file_name(&cert);
    let thumbprint = cert.thumbprint().as_hex_string();
    let trusted = pki.join("trusted").join(&name);
    let rejected = pki.join("rejected").join(&name);
    if trusted.exists() {
        return Ok(());
    }
    let der = cert
        .to_der()
        .map_err(|e| no_session(format!("the server's certificate cannot be encoded: {e:?}")))?;
    let subject = cert.subject_name();
    let accept = match trust {
        Some(TrustServer::Accept) => true,
        Some(TrustServer::Pin(pin)) if *pin == thumbprint => true,
        Some(TrustServer::Pin(pin)) => {
            return Err(no_session(format!(
                "the server's certificate ({subject}, SHA-1 thumbprint {thumbprint}) is not the \
                 one pinned with --trust-server ({pin}): refused"
            )))
        }
        None => false,
    };
    let save = |path: &Path| -> Result<(), Failure> {
        let dir = path.parent().unwrap_or(pki);
        std::fs::create_dir_all(dir)
            .and_then(|()| std::fs::write(path, &der))
            .map_err(|e| failed(format!("cannot write {}: {e}", path.display())))
    };
    if accept {
        save(&trusted)?;
        let _ = std::fs::remove_file(&rejected);
        eprintln!(
            "opcdiag: trusted the server's certificate {subject} (SHA-1 thumbprint {thumbprint}): \
             saved as {}",
            trusted.display()
        );
        return Ok(());
    }
    save(&rejected)?;
    Err(no_session(format!(
        "the server's certificate is not trusted: {subject}, SHA-1 thumbprint {thumbprint}; \
         saved as {}. Compare the thumbprint with the server's (ServerCTOPC: its pki/own/cert.der), \
         then run again with --trust-server {thumbprint} (or move the file to {})",
        rejected.display(),
        pki.join("trusted").display()
    )))
}

/// Why the server ended or refused the session, for people.
fn refused(code: StatusCode, o: &UaOptions, pki: &Path) -> Failure {
    use opcua::types::SubStatusCode as S;
    let own = pki.join("own").join("cert.der");
    let why = match code.sub_code() {
        S::BadUserAccessDenied | S::BadIdentityTokenRejected | S::BadIdentityTokenInvalid => {
            match &o.user {
                Some(user) => {
                    format!("the server refused user {user}: wrong user name or password")
                }
                None => "the server refused an anonymous session: give --user NAME".into(),
            }
        }
        S::BadSecurityChecksFailed | S::BadCertificateUntrusted | S::BadCertificateInvalid => {
            let thumbprint = own_thumbprint(&own).unwrap_or_else(|f| f.message);
            format!(
                "the server refused opcdiag's certificate (SHA-1 thumbprint {thumbprint}): trust it \
                 on the server, on ServerCTOPC `ServerCTOPC pki trust {}`",
                own.display()
            )
        }
        S::BadCertificateHostNameInvalid => {
            "the server's certificate does not name the host of --url: use the host name it \
             announces"
                .into()
        }
        S::BadSecurityPolicyRejected | S::BadSecurityModeRejected => {
            "the server does not offer this security: see --security and --policy".into()
        }
        _ => "the session could not be opened".into(),
    };
    no_session(format!("{why} ({})", show::status_text(code)))
}

/// One OPC UA session.
struct Connection {
    session: Arc<Session>,
    event_loop: tokio::task::JoinHandle<StatusCode>,
    /// The index of ServerCTOPC's namespace, once looked up.
    ns: Option<u16>,
}

impl Connection {
    async fn open(o: &UaOptions) -> Result<Connection, Failure> {
        let url = o.url.clone().unwrap_or_default();
        let identity = identity(o)?;
        let (client, pki) = client(o)?;
        let endpoints = tokio::time::timeout(
            CONNECT_TIMEOUT,
            client.get_server_endpoints_from_url(url.as_str()),
        )
        .await
        .map_err(|_| {
            no_session(format!(
                "{url} did not answer GetEndpoints in {} s",
                CONNECT_TIMEOUT.as_secs()
            ))
        })?
        .map_err(|e| {
            no_session(format!(
                "cannot reach {url}: {}",
                show::status_error(e.status())
            ))
        })?;
        let mode = mode_of(o.security);
        let policy = if o.security == Security::None {
            SecurityPolicy::None
        } else {
            SecurityPolicy::from_uri(&format!(
                "http://opcfoundation.org/UA/SecurityPolicy#{}",
                o.policy
            ))
        };
        let Some(endpoint) = Client::find_matching_endpoint(&endpoints, &url, policy, mode) else {
            let offered: Vec<String> = endpoints
                .iter()
                .map(|e| {
                    let p = e.security_policy_uri.as_ref();
                    format!(
                        "{} {:?}",
                        p.rsplit('#').next().unwrap_or(p),
                        e.security_mode
                    )
                })
                .collect();
            return Err(no_session(format!(
                "{url} offers no endpoint with {policy} {mode:?}; it offers: {}",
                offered.join(", ")
            )));
        };
        let anonymous_allowed = endpoint
            .user_identity_tokens
            .iter()
            .flatten()
            .any(|t| t.token_type == opcua::types::UserTokenType::Anonymous);
        if o.user.is_none() && !anonymous_allowed {
            return Err(no_session(
                "the server does not allow anonymous sessions on this endpoint: give --user NAME",
            ));
        }
        if policy != SecurityPolicy::None {
            check_server_certificate(&pki, &endpoint, o.trust_server.as_ref())?;
        }
        let (session, event_loop) = client
            .session_builder()
            .with_endpoints(endpoints)
            .connect_to_matching_endpoint(endpoint)
            .and_then(|b| {
                b.user_identity_token(identity)
                    .build(client.certificate_store().clone())
            })
            .map_err(|e| {
                no_session(format!(
                    "cannot open a session: {}",
                    show::status_error(e.status())
                ))
            })?;
        let mut event_loop = event_loop.spawn();
        let connected = tokio::select! {
            connected = session.wait_for_connection() => Ok(connected),
            code = &mut event_loop => Err(code.unwrap_or(StatusCode::BadUnexpectedError)),
            () = tokio::time::sleep(CONNECT_TIMEOUT) => Err(StatusCode::BadTimeout),
        };
        match connected {
            Ok(true) => Ok(Connection {
                session,
                event_loop,
                ns: None,
            }),
            Ok(false) => Err(refused(StatusCode::BadConnectionClosed, o, &pki)),
            Err(code) => {
                event_loop.abort();
                Err(refused(code, o, &pki))
            }
        }
    }

    async fn close(self) {
        let _ = tokio::time::timeout(REQUEST_TIMEOUT, self.session.disconnect()).await;
        let mut event_loop = self.event_loop;
        if tokio::time::timeout(Duration::from_secs(2), &mut event_loop)
            .await
            .is_err()
        {
            event_loop.abort();
        }
    }

    async fn command(&mut self, command: Command) -> Result<u8, Failure> {
        match command {
            Command::Browse {
                flat,
                branch,
                depth,
                page,
            } => self.browse(flat, branch.as_deref(), depth, page).await,
            Command::Read { items, device, .. } => self.read(&items, device).await,
            Command::Write {
                item, value, vt, ..
            } => self.write(&item, &value, vt).await,
            Command::Subscribe {
                items,
                rate_ms,
                for_secs,
                count,
                ..
            } => self.subscribe(&items, rate_ms, for_secs, count).await,
            _ => Err(Failure {
                code: EXIT_USAGE,
                message: "with --url: browse, read, write and subscribe (the other commands are OPC DA's)".into(),
            }),
        }
    }

    /// A request that failed as a whole (the session is gone, the server said Bad_...).
    fn request_failed(&self, what: &str, e: &opcua::types::Error) -> Failure {
        let code = e.status();
        if self.event_loop.is_finished() {
            return no_session(format!("the session ended: {}", show::status_error(code)));
        }
        failed(format!("{what} failed: {}", show::status_error(code)))
    }

    /// The index of ServerCTOPC's namespace (read once from the namespace array).
    async fn namespace(&mut self) -> Result<u16, Failure> {
        if let Some(ns) = self.ns {
            return Ok(ns);
        }
        let ns = self
            .session
            .get_namespace_index(show::NAMESPACE_URI)
            .await
            .map_err(|e| {
                failed(format!(
                    "the server has no namespace {} ({}): name nodes by their full NodeId (ns=N;s=...)",
                    show::NAMESPACE_URI,
                    show::status_text(e.status())
                ))
            })?;
        self.ns = Some(ns);
        Ok(ns)
    }

    /// The NodeId of a command-line argument.
    async fn node(&mut self, arg: &str) -> Result<NodeId, Failure> {
        match show::node_arg(arg) {
            NodeArg::Id(id) => Ok(id),
            NodeArg::Item(item) => Ok(NodeId::new(self.namespace().await?, item)),
        }
    }

    async fn nodes(&mut self, args: &[String]) -> Result<Vec<NodeId>, Failure> {
        let mut ids = Vec::with_capacity(args.len());
        for a in args {
            ids.push(self.node(a).await?);
        }
        Ok(ids)
    }

    /// How a node is shown (its DA item ID when it is ServerCTOPC's).
    fn label(&self, id: &NodeId) -> String {
        show::node_label(id, self.ns)
    }

    // ---- browse ------------------------------------------------------------------------

    /// Every forward hierarchical reference of `node` to an object or variable, page by page
    /// (at most `page` a request; the rest through BrowseNext and its continuation points).
    async fn children(
        &self,
        node: &NodeId,
        page: u32,
    ) -> Result<Vec<opcua::types::ReferenceDescription>, Failure> {
        let desc = BrowseDescription {
            node_id: node.clone(),
            browse_direction: BrowseDirection::Forward,
            reference_type_id: ReferenceTypeId::HierarchicalReferences.into(),
            include_subtypes: true,
            node_class_mask: (NodeClassMask::OBJECT | NodeClassMask::VARIABLE).bits(),
            result_mask: BrowseResultMask::All as u32,
        };
        let mut result = self
            .session
            .browse(&[desc], page, None)
            .await
            .map_err(|e| self.request_failed("Browse", &e))?
            .into_iter()
            .next()
            .ok_or_else(|| failed("Browse returned no result"))?;
        let mut refs = Vec::new();
        loop {
            if result.status_code.is_bad() {
                return Err(failed(format!(
                    "Browse of {} failed: {}",
                    self.label(node),
                    show::status_error(result.status_code)
                )));
            }
            refs.extend(result.references.take().unwrap_or_default());
            if refs.len() > MAX_BROWSED {
                return Err(failed(format!(
                    "{} has more than {MAX_BROWSED} children",
                    self.label(node)
                )));
            }
            let cp: ByteString = result.continuation_point.clone();
            if cp.is_null() || cp.is_empty() {
                return Ok(refs);
            }
            result = self
                .session
                .browse_next(false, &[cp])
                .await
                .map_err(|e| self.request_failed("BrowseNext", &e))?
                .into_iter()
                .next()
                .ok_or_else(|| failed("BrowseNext returned no result"))?;
        }
    }

    /// Where browse starts: `--branch` (a NodeId or item ID), else the ServerCTOPC object
    /// under Objects when there is one, else Objects.
    async fn browse_start(&mut self, branch: Option<&str>, page: u32) -> Result<NodeId, Failure> {
        if let Some(b) = branch {
            return self.node(b).await;
        }
        let objects: NodeId = ObjectId::ObjectsFolder.into();
        let ns = self.namespace().await.ok();
        let children = self.children(&objects, page).await?;
        Ok(children
            .into_iter()
            .find(|r| {
                Some(r.browse_name.namespace_index) == ns
                    && r.browse_name.name.as_ref() == "ServerCTOPC"
            })
            .map_or(objects, |r| r.node_id.node_id))
    }

    async fn browse(
        &mut self,
        flat: bool,
        branch: Option<&str>,
        depth: Option<usize>,
        page: u32,
    ) -> Result<u8, Failure> {
        let start = self.browse_start(branch, page).await?;
        // Depth-first in the server's order, each node's line printed when it is reached;
        // objects are branches, variables leaves (their properties and child variables are
        // not walked); a node met twice is walked once.
        let mut stack: Vec<(usize, Entry)> = Vec::new();
        let mut seen: HashSet<NodeId> = HashSet::from([start.clone()]);
        self.push_children(&mut stack, 0, &start, page).await?;
        let mut listing = String::new();
        while let Some((level, e)) = stack.pop() {
            if flat {
                if !e.object {
                    listing.push_str(&self.label(&e.id));
                    listing.push('\n');
                }
            } else {
                listing.push_str(&text::render_tree(&[text::TreeLine {
                    depth: level,
                    name: e.name.clone(),
                    item_id: (!e.object).then(|| self.label(&e.id)),
                    branch: e.object,
                }]));
            }
            if listing.len() > 64 * 1024 {
                out::text(&listing);
                listing.clear();
                if out::closed() {
                    return Ok(EXIT_OK);
                }
            }
            let deeper = depth.is_none_or(|d| level + 1 < d);
            if e.object && deeper && seen.insert(e.id.clone()) {
                if seen.len() > MAX_BROWSED {
                    return Err(failed(format!(
                        "the tree has more than {MAX_BROWSED} nodes"
                    )));
                }
                self.push_children(&mut stack, level + 1, &e.id, page)
                    .await?;
            }
        }
        out::text(&listing);
        Ok(EXIT_OK)
    }

    /// Pushes `node`'s children at `level`, the first on top.
    async fn push_children(
        &self,
        stack: &mut Vec<(usize, Entry)>,
        level: usize,
        node: &NodeId,
        page: u32,
    ) -> Result<(), Failure> {
        let children = self.children(node, page).await?;
        for r in children.into_iter().rev() {
            stack.push((
                level,
                Entry {
                    object: r.node_class == opcua::types::NodeClass::Object,
                    name: r.browse_name.name.to_string(),
                    id: r.node_id.node_id,
                },
            ));
        }
        Ok(())
    }

    // ---- read --------------------------------------------------------------------------

    async fn read(&mut self, items: &[String], device: bool) -> Result<u8, Failure> {
        let ids = self.nodes(items).await?;
        let to_read: Vec<ReadValueId> = ids.iter().cloned().map(ReadValueId::from).collect();
        // MaxAge 0: from the device; else the server's cache when it is at most
        // CACHE_MAX_AGE old (a server whose cache holds nothing for the node reads the
        // device).
        let max_age = if device { 0.0 } else { CACHE_MAX_AGE_MS };
        // A server that subscribes its source at the first read answers
        // Bad_WaitingForInitialData for a moment: asked again (as the DA `read` waits for
        // the first value) for up to WAIT_FIRST_VALUE.
        let deadline = Instant::now() + WAIT_FIRST_VALUE;
        let values = loop {
            let values = self
                .session
                .read(&to_read, TimestampsToReturn::Both, max_age)
                .await
                .map_err(|e| self.request_failed("Read", &e))?;
            let waiting = values
                .iter()
                .any(|dv| dv.status == Some(StatusCode::BadWaitingForInitialData));
            if !waiting || Instant::now() >= deadline {
                break values;
            }
            tokio::time::sleep(Duration::from_millis(100)).await;
        };
        let width = items.iter().map(|i| i.chars().count()).max().unwrap_or(0);
        let mut code = EXIT_OK;
        for (i, item) in items.iter().enumerate() {
            let name = text::pad(item, width);
            let Some(dv) = values.get(i) else {
                code = EXIT_FAILED;
                say!("{name}  error: no result");
                continue;
            };
            let status = dv.status.unwrap_or(StatusCode::Good);
            if status.is_bad() && dv.value.is_none() {
                code = EXIT_FAILED;
                say!("{name}  error {}", error_with_hint(status));
                continue;
            }
            if status.is_bad() {
                code = EXIT_FAILED;
            }
            let v = dv.value.clone().unwrap_or_default();
            say!(
                "{name}  {}  {}  {}  {}  (server {})",
                show::value_text(&v),
                show::type_text(&v),
                show::status_text(status),
                show::time_text(dv.source_timestamp.as_ref()),
                show::time_text(dv.server_timestamp.as_ref())
            );
        }
        Ok(code)
    }

    // ---- write -------------------------------------------------------------------------

    async fn write(
        &mut self,
        item: &str,
        value: &str,
        vt: Option<ctopc_core::VarType>,
    ) -> Result<u8, Failure> {
        let id = self.node(item).await?;
        let vt = match vt {
            Some(vt) => vt,
            None => self.data_type(item, &id).await?,
        };
        let v = match show::parse_value(value, vt) {
            Ok(v) => v,
            Err(e) => {
                return Err(Failure {
                    code: EXIT_USAGE,
                    message: format!("{item}: {e}"),
                })
            }
        };
        let shown = format!("{} ({})", show::value_text(&v), show::type_text(&v));
        let write = WriteValue {
            node_id: id,
            attribute_id: AttributeId::Value as u32,
            index_range: Default::default(),
            value: DataValue::value_only(v),
        };
        let results = self
            .session
            .write(&[write])
            .await
            .map_err(|e| self.request_failed("Write", &e))?;
        let result = results
            .first()
            .copied()
            .unwrap_or(StatusCode::BadUnexpectedError);
        if result.is_bad() {
            say!("{item}: write {shown} failed: {}", error_with_hint(result));
            Ok(EXIT_FAILED)
        } else if result.bits() != 0 {
            say!("{item}: written {shown}: {}", show::status_text(result));
            Ok(EXIT_OK)
        } else {
            say!("{item}: written {shown}: OK");
            Ok(EXIT_OK)
        }
    }

    /// The DA type standing for the variable's DataType (read from the server).
    async fn data_type(&self, item: &str, id: &NodeId) -> Result<ctopc_core::VarType, Failure> {
        let read = ReadValueId {
            attribute_id: AttributeId::DataType as u32,
            ..ReadValueId::from(id.clone())
        };
        let dv = self
            .session
            .read(&[read], TimestampsToReturn::Neither, 0.0)
            .await
            .map_err(|e| self.request_failed("Read (DataType)", &e))?
            .into_iter()
            .next()
            .unwrap_or_default();
        let status = dv.status.unwrap_or(StatusCode::Good);
        if status.is_bad() {
            return Err(failed(format!("{item}: {}", error_with_hint(status))));
        }
        match dv.value {
            Some(opcua::types::Variant::NodeId(t)) => show::vartype_of(&t).ok_or_else(|| {
                failed(format!(
                    "{item}: its data type {t} cannot be written from text: give --type"
                ))
            }),
            other => Err(failed(format!(
                "{item}: the server gave no data type ({other:?}): give --type"
            ))),
        }
    }

    // ---- subscribe ---------------------------------------------------------------------

    async fn subscribe(
        &mut self,
        items: &[String],
        rate_ms: u32,
        for_secs: Option<f64>,
        count: Option<usize>,
    ) -> Result<u8, Failure> {
        let ids = self.nodes(items).await?;
        let labels: HashMap<NodeId, String> =
            ids.iter().cloned().zip(items.iter().cloned()).collect();
        let (tx, mut rx) = tokio::sync::mpsc::channel::<(String, DataValue)>(CHANGE_BUFFER);
        let lost = Arc::new(AtomicUsize::new(0));
        let lost_in_callback = lost.clone();
        let callback = DataChangeCallback::new(move |dv: DataValue, item: &MonitoredItem| {
            let node = &item.item_to_monitor().node_id;
            let name = labels
                .get(node)
                .cloned()
                .unwrap_or_else(|| node.to_string());
            if tx.try_send((name, dv)).is_err() {
                lost_in_callback.fetch_add(1, Ordering::Relaxed);
            }
        });
        let interval = Duration::from_millis(u64::from(rate_ms.max(1)));
        let subscription = self
            .session
            .create_subscription(interval, 60, 10, 0, 0, true, callback)
            .await
            .map_err(|e| self.request_failed("CreateSubscription", &e))?;
        let requests: Vec<MonitoredItemCreateRequest> = ids
            .iter()
            .map(|id| {
                MonitoredItemCreateRequest::new(
                    ReadValueId::from(id.clone()),
                    MonitoringMode::Reporting,
                    MonitoringParameters {
                        client_handle: 0,
                        sampling_interval: f64::from(rate_ms),
                        filter: ExtensionObject::null(),
                        queue_size: 10,
                        discard_oldest: true,
                    },
                )
            })
            .collect();
        let created = self
            .session
            .create_monitored_items(subscription, TimestampsToReturn::Both, requests)
            .await
            .map_err(|e| self.request_failed("CreateMonitoredItems", &e))?;
        let mut code = EXIT_OK;
        let width = items.iter().map(|i| i.chars().count()).max().unwrap_or(0);
        let mut ok = 0usize;
        for (i, item) in items.iter().enumerate() {
            match created.get(i).map(|c| c.result.status_code) {
                Some(s) if s.is_good() => ok += 1,
                Some(s) => {
                    code = EXIT_FAILED;
                    say!("{}  error {}", text::pad(item, width), error_with_hint(s));
                }
                None => {
                    code = EXIT_FAILED;
                    say!("{}  error: no result", text::pad(item, width));
                }
            }
        }
        let until = match (for_secs, count) {
            (Some(s), Some(c)) => format!("for {c} change(s) or {s} s"),
            (None, Some(c)) => format!("for {c} change(s)"),
            (Some(s), None) => format!("for {s} s"),
            (None, None) => "until Ctrl+C".into(),
        };
        say!("Subscribed to {ok} item(s), publishing interval {rate_ms} ms, {until} (times UTC):");
        let started = Instant::now();
        let deadline = for_secs.map(|s| tokio::time::Instant::now() + Duration::from_secs_f64(s));
        let mut n = 0usize;
        let mut ended = None;
        if ok > 0 {
            loop {
                if count.is_some_and(|c| n >= c) || out::closed() {
                    break;
                }
                let timeout = async {
                    match deadline {
                        Some(d) => tokio::time::sleep_until(d).await,
                        None => std::future::pending().await,
                    }
                };
                tokio::select! {
                    change = rx.recv() => match change {
                        Some((name, dv)) => {
                            n += 1;
                            let v = dv.value.clone().unwrap_or_default();
                            say!(
                                "{}  {}  {}  {}",
                                text::local_time_of_day(show::timestamp(dv.source_timestamp.as_ref()), 0),
                                text::pad(&name, width),
                                show::value_text(&v),
                                show::status_text(dv.status.unwrap_or(StatusCode::Good))
                            );
                        }
                        None => break,
                    },
                    () = timeout => break,
                    _ = tokio::signal::ctrl_c() => break,
                    end = &mut self.event_loop => {
                        ended = Some(end.unwrap_or(StatusCode::BadUnexpectedError));
                        break;
                    }
                }
            }
        }
        if let Some(end) = ended {
            return Err(no_session(format!(
                "the session ended: {} (after {n} change(s))",
                show::status_error(end)
            )));
        }
        let _ = tokio::time::timeout(
            REQUEST_TIMEOUT,
            self.session.delete_subscription(subscription),
        )
        .await;
        let lost = lost.load(Ordering::Relaxed);
        if lost > 0 {
            say!("opcdiag: {lost} change(s) arrived faster than they could be printed and were dropped");
        }
        say!("{n} change(s) in {:.1} s", started.elapsed().as_secs_f64());
        Ok(match count {
            Some(c) if n < c => {
                say!("opcdiag: {n} of the {c} change(s) asked for with --count arrived");
                EXIT_FAILED
            }
            _ => code,
        })
    }
}

/// A node met while browsing.
struct Entry {
    object: bool,
    name: String,
    id: NodeId,
}

/// An error StatusCode with its meaning and, where opcdiag knows one, what to do.
fn error_with_hint(s: StatusCode) -> String {
    match show::status_hint(s) {
        Some(hint) => format!("{} ({hint})", show::status_error(s)),
        None => show::status_error(s),
    }
}
