//! OPC UA beside OPC DA from one ServerCTOPC.exe: a server of the test's own
//! (`SERVERCTOPC_INI`) with a `[UA]` section on a free loopback port, started by COM for
//! a DA client (`-Embedding`), serves an OPC UA client (async-opcua's, over
//! Basic256Sha256 SignAndEncrypt as a user of role `writer`) at the same time, from the
//! same engine: both see the same value, quality and source timestamp of the same
//! variable (one that the simulation changes all the time, and a setpoint), a write
//! through DA is what UA reads, and a write through UA is what DA reads. The user and the
//! client's certificate are set up with the Windows build's own commands
//! (`ServerCTOPC.exe user add ... --password-stdin`, `pki trust FILE`) before the server
//! starts; the log has the OPC UA start line with its endpoint and security, and the
//! stop.
//!
//! As `ops_metrics.rs`: waits until no other ServerCTOPC.exe runs, sets
//! `SERVERCTOPC_INI` before activating, and waits at the end until its server has exited.
//! 64-bit only (the OPC UA client is built for the server's target).
//!
//! Spec: OPC DA 2.05a §4.5.4 IOPCSyncIO::Read (OPC_DS_CACHE), §4.5.4.2 IOPCSyncIO::Write;
//! OPC UA Part 4 §5.10.2 Read (MaxAge), §5.10.4 Write; Part 8 Annex A (quality as
//! StatusCode); the server's `[UA]` (docs/configuration.md).
#![cfg(all(windows, target_pointer_width = "64"))]
#![allow(clippy::unwrap_used, clippy::expect_used)]

use ctopc_core::{Timestamp, Value};
use e2e_tests::interfaces::OPC_DS_CACHE as CACHE;
use e2e_tests::io_support::*;
use e2e_tests::server_config::{read_log, wait_until_no_server, write_demo_config};
use e2e_tests::{artifact, other_servers, wait_for_no_other_server, Apartment, PROGID};
use opc_client::{self as client, ReadItem, Server};
use opcua::client::{ClientBuilder, IdentityToken, Password, Session};
use opcua::types::{
    AttributeId, DataValue, MessageSecurityMode, NodeId, ReadValueId, TimestampsToReturn,
    UserTokenPolicy, Variant, WriteValue,
};
use std::io::Write as _;
use std::path::Path;
use std::process::{Command, Stdio};
use std::sync::Arc;
use std::time::{Duration, Instant};
use windows::Win32::Foundation::S_OK;

/// A variable the simulation changes all the time.
const CHANGING: &str = "KW_A000";
/// A writable setpoint (R4, 0..20 t/h).
const SETPOINT: &str = "KW_A110";
const USER: &str = "operator";
const PASSWORD: &str = "hasło-operatora-1";
const NAMESPACE_URI: &str = "urn:askom:ServerCTOPC";
/// How long any one condition may take.
const LIMIT: Duration = Duration::from_secs(30);

/// Runs `ServerCTOPC.exe` with `args` (the test's configuration through the inherited
/// `SERVERCTOPC_INI`), `stdin` on its standard input; panics unless it succeeds.
fn server_command(args: &[&str], stdin: &str) -> String {
    let exe = artifact("ServerCTOPC.exe");
    let out = e2e_tests::start::retrying("ServerCTOPC.exe", || {
        let mut child = Command::new(&exe)
            .args(args)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()?;
        if let Some(mut input) = child.stdin.take() {
            input.write_all(stdin.as_bytes())?;
        }
        child.wait_with_output()
    })
    .expect("start ServerCTOPC.exe");
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(out.status.success(), "ServerCTOPC.exe {args:?}: {text}");
    text
}

/// `path` has no finding, and where the platform keeps file DACLs exactly the secrets'
/// DACL (`security::secret_descriptor` for this account: the server's, under Wine the same
/// user), protected. Under Wine (no file DACL kept: `platform::keeps_file_dacls`) that
/// means its Unix mode gives others nothing.
fn assert_private(path: &Path, folder: bool) {
    use ctopc_com::com::{platform, secret_file};
    let d = secret_file::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    if platform::keeps_file_dacls() {
        let want = secret_file::descriptor_to_write(folder).expect("this process's account");
        assert!(d.protected, "{}: {}", path.display(), d.sddl());
        assert_eq!(d.dacl, want.dacl, "{}: {}", path.display(), d.sddl());
    }
    assert_eq!(
        secret_file::findings(path, &[]),
        None,
        "{}: {}",
        path.display(),
        d.sddl()
    );
}

/// A free loopback port (Wine's sockets are the host's).
fn free_port() -> u16 {
    let l = std::net::TcpListener::bind("127.0.0.1:0").expect("bind");
    l.local_addr().expect("local_addr").port()
}

/// The UA client's one session and the runtime it runs on.
struct UaClient {
    rt: tokio::runtime::Runtime,
    session: Arc<Session>,
    ns: u16,
}

impl UaClient {
    /// Connects over Basic256Sha256 SignAndEncrypt as the writer; its certificate was
    /// made (and trusted by the server) beforehand in `pki`.
    fn connect(url: &str, pki: &Path) -> UaClient {
        let rt = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .enable_all()
            .build()
            .expect("tokio");
        let mut client = ua_client(pki);
        let session = rt.block_on(async {
            let endpoint = (
                url,
                "http://opcfoundation.org/UA/SecurityPolicy#Basic256Sha256",
                MessageSecurityMode::SignAndEncrypt,
                UserTokenPolicy::anonymous(),
            );
            let (session, event_loop) = client
                .connect_to_matching_endpoint(
                    endpoint,
                    IdentityToken::UserName(USER.into(), Password::new(PASSWORD)),
                )
                .await
                .expect("OPC UA connect");
            event_loop.spawn();
            assert!(
                tokio::time::timeout(LIMIT, session.wait_for_connection())
                    .await
                    .expect("OPC UA session within the limit"),
                "the OPC UA session did not come up"
            );
            session
        });
        let mut ua = UaClient { rt, session, ns: 0 };
        let namespaces = ua.read_node(&NodeId::new(0, 2255u32), 0.0);
        let Some(Variant::Array(array)) = namespaces.value else {
            panic!("NamespaceArray: {namespaces:?}");
        };
        ua.ns = array
            .values
            .iter()
            .position(|v| matches!(v, Variant::String(s) if s.as_ref() == NAMESPACE_URI))
            .unwrap_or_else(|| panic!("no {NAMESPACE_URI} in {array:?}")) as u16;
        ua
    }

    fn node(&self, item: &str) -> NodeId {
        NodeId::new(self.ns, item)
    }

    fn read_node(&self, node: &NodeId, max_age: f64) -> DataValue {
        let read = ReadValueId {
            node_id: node.clone(),
            attribute_id: AttributeId::Value as u32,
            ..Default::default()
        };
        let mut values = self
            .rt
            .block_on(
                self.session
                    .read(&[read], TimestampsToReturn::Both, max_age),
            )
            .expect("OPC UA Read");
        assert_eq!(values.len(), 1);
        values.remove(0)
    }

    /// The value from the server's cache (MaxAge as long as it gets).
    fn read_cache(&self, item: &str) -> DataValue {
        self.read_node(&self.node(item), f64::from(u32::MAX))
    }

    fn write(&self, item: &str, value: f32) {
        let write = WriteValue {
            node_id: self.node(item),
            attribute_id: AttributeId::Value as u32,
            value: DataValue::value_only(value),
            ..Default::default()
        };
        let results = self
            .rt
            .block_on(self.session.write(&[write]))
            .expect("OPC UA Write");
        assert!(results[0].is_good(), "OPC UA Write: {results:?}");
    }

    fn close(self) {
        let session = &self.session;
        let _ = self.rt.block_on(async {
            tokio::time::timeout(Duration::from_secs(10), session.disconnect()).await
        });
        self.rt.shutdown_timeout(Duration::from_secs(5));
    }
}

/// The test's OPC UA client: its certificate and key in `pki` (made when missing), the
/// server's certificate accepted (the test trusts the server it started).
fn ua_client(pki: &Path) -> opcua::client::Client {
    ClientBuilder::new()
        .application_name("ua_beside_da")
        .application_uri("urn:ctopc:e2e:ua_beside_da")
        .product_uri("urn:ctopc:e2e")
        .create_sample_keypair(true)
        .certificate_path("own/cert.der")
        .private_key_path("private/private.pem")
        .pki_dir(pki)
        .trust_server_certs(true)
        .session_retry_limit(3)
        .request_timeout(LIMIT)
        .client()
        .expect("OPC UA client")
}

/// One cache read through DA whose sample did not change while `ua_read` ran, and the
/// UA read: both saw the one sample.
fn same_sample(
    group: &TestGroup,
    handle: u32,
    mut ua_read: impl FnMut() -> DataValue,
) -> (ReadItem, DataValue) {
    let read_da = || {
        let (hr, mut items) = client::sync_read(&group.sync(), CACHE, &[handle]).expect("Read");
        assert_eq!(hr, S_OK, "{items:?}");
        items.remove(0)
    };
    let deadline = Instant::now() + LIMIT;
    loop {
        let before = read_da();
        let ua = ua_read();
        let after = read_da();
        if before.timestamp == after.timestamp && before.value == after.value {
            return (before, ua);
        }
        assert!(
            Instant::now() < deadline,
            "the DA sample changed during every UA read for {LIMIT:?}"
        );
    }
}

/// DA and UA saw the same value, quality and source timestamp.
fn assert_same(item: &str, da: &ReadItem, ua: &DataValue) {
    let ua_value = match &ua.value {
        Some(Variant::Float(f)) => Value::R4(*f),
        other => panic!("{item}: UA value {other:?}"),
    };
    assert_eq!(da.value, ua_value, "{item}: DA {da:?}, UA {ua:?}");
    // Good in DA (0xC0) is Good in UA, as OPC UA Part 8 Annex A maps it.
    assert_eq!(da.quality & 0xC0, 0xC0, "{item}: DA {da:?}");
    let status = ua.status.unwrap_or_default();
    assert!(status.is_good(), "{item}: UA {ua:?}");
    let ua_time = ua
        .source_timestamp
        .as_ref()
        .map(|t| Timestamp::from_filetime(t.checked_ticks()));
    assert_eq!(Some(da.timestamp), ua_time, "{item}: DA {da:?}, UA {ua:?}");
}

/// Waits until `read` sees `value` through DA.
fn wait_da_value(group: &TestGroup, handle: u32, value: f32) -> ReadItem {
    let mut last = None;
    test_support::wait::wait_for(LIMIT, || {
        let (_, mut items) = client::sync_read(&group.sync(), CACHE, &[handle]).expect("Read");
        let item = items.remove(0);
        let seen = item.value == Value::R4(value);
        last = Some(item.clone());
        seen.then_some(item)
    })
    .unwrap_or_else(|| panic!("DA never saw {value}: last {last:?}"))
}

#[test]
fn a_da_client_and_a_ua_client_see_the_same_values_from_one_server() {
    wait_for_no_other_server();
    let port = free_port();
    let url = format!("opc.tcp://127.0.0.1:{port}/");
    let (dir, ini) = write_demo_config(
        "ua-beside",
        "ASIXConnect-ua.ini",
        "FirstSampleWait = 0",
        &format!("\r\n[UA]\r\nEndpoint = opc.tcp://127.0.0.1:{port}\r\n"),
    );
    std::env::set_var("SERVERCTOPC_INI", &ini);
    // The writer user, and the client's certificate trusted, with the server's commands
    // (the users file and the PKI folder beside the configuration by default).
    let said = server_command(
        &["user", "add", USER, "--role", "writer", "--password-stdin"],
        &format!("{PASSWORD}\r\n"),
    );
    assert!(said.contains("saved in"), "{said}");
    let client_pki = dir.join("client-pki");
    drop(ua_client(&client_pki));
    let client_cert = client_pki.join("own").join("cert.der");
    let said = server_command(&["pki", "trust", client_cert.to_str().unwrap()], "");
    assert!(said.contains("trusted:"), "{said}");

    // The DA client starts the server (COM, -Embedding); OPC UA is up before the class
    // object is registered.
    let com = Apartment::mta().expect("MTA");
    let server = Server::connect(PROGID).expect("connect");
    std::env::remove_var("SERVERCTOPC_INI");
    assert_eq!(other_servers(0).len(), 1, "only the test's server runs");
    let group = add_group(&server, "beside", true, 1000, 1).expect("AddGroup");
    let (changing, setpoint) = (1u32, 2u32);
    let handles = add_ok(
        &group,
        &[
            ItemSpec {
                id: CHANGING,
                client: changing,
                vt: 0,
                active: true,
            },
            ItemSpec {
                id: SETPOINT,
                client: setpoint,
                vt: 0,
                active: true,
            },
        ],
    );

    let ua = UaClient::connect(&url, &client_pki);

    // Secrets at rest: the users file `user add` wrote, and the private key and its folder
    // the first start made, each with the protected DACL, read back from Wine's store.
    let private = dir.join("pki").join("private");
    assert_private(&dir.join("ua-users.txt"), false);
    assert_private(&private, true);
    assert_private(&private.join("private.pem"), false);

    // A value the simulation changes: the same sample through both.
    let (da, ua_seen) = same_sample(&group, handles[0], || ua.read_cache(CHANGING));
    assert_eq!(da.client_handle, changing);
    assert_same(CHANGING, &da, &ua_seen);

    // A write through DA is what UA reads.
    let (hr, errors) =
        client::sync_write(&group.sync(), &[(handles[1], Value::R4(7.5))]).expect("DA Write");
    assert_eq!((hr, errors), (S_OK, vec![S_OK]));
    wait_da_value(&group, handles[1], 7.5);
    let (da, ua_seen) = same_sample(&group, handles[1], || ua.read_cache(SETPOINT));
    assert_eq!(da.client_handle, setpoint);
    assert_same(SETPOINT, &da, &ua_seen);
    assert_eq!(da.value, Value::R4(7.5));

    // A write through UA is what DA reads.
    ua.write(SETPOINT, 12.25);
    wait_da_value(&group, handles[1], 12.25);
    let (da, ua_seen) = same_sample(&group, handles[1], || ua.read_cache(SETPOINT));
    assert_same(SETPOINT, &da, &ua_seen);
    assert_eq!(da.value, Value::R4(12.25));

    ua.close();
    drop((group, server));
    drop(com);
    assert!(
        wait_until_no_server(Duration::from_secs(60)),
        "the test's server did not exit"
    );
    let log = read_log(&dir);
    assert!(
        log.contains(&format!("OPC UA: listening on 127.0.0.1:{port}; endpoint opc.tcp://127.0.0.1:{port}/ with Basic256Sha256")),
        "{log}"
    );
    assert!(log.contains("None off; anonymous off"), "{log}");
    assert!(log.contains("OPC UA: stopped"), "{log}");
    assert!(
        log.contains(&format!("method=\"OPC UA Write (user {USER})\""))
            || log.contains(&format!("OPC UA Write (user {USER})")),
        "no audit line of the UA write: {log}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
