//! The asix station's data end to end: a DA client reads (cache and device), writes
//! (IOPCSyncIO::Write, IOPCSyncIO2::WriteVQT, IOPCItemIO::WriteVQT) and subscribes through
//! ServerCTOPC.exe → asix-gate.exe (32-bit) → the test double of AsixConnect's
//! `XConnect.ServerCT`, over TLS with pinned certificates both ways; a write the gate does
//! not grant to ServerCTOPC's certificate gets the original's code; and two gates
//! serving the same channel fail over when the linked one is stopped.
//!
//! Two gate processes (each with its own double objects) announce the same channels, each
//! answering discovery on a port of its own on 127.0.0.1. On a plant they would be two
//! stations on one port, reached by the server's broadcast; on loopback under Wine two
//! processes cannot share a UDP port at two addresses (Wine binds a UDP socket of any
//! local address but 127.0.0.1 to 0.0.0.0 on that address's interface, so that it gets
//! broadcasts: the second bind is `WSAEADDRINUSE`; docs/testing.md). So the test plays
//! the broadcast: [`Broadcast`] listens where the server's discovery goes (`BroadcastAddress`
//! 127.0.0.1, `DiscoveryPort`), sends each FindServer to both gates and their answers back
//! to the server, which links to the gate that answered (its address, the announced port).
//! Each gate accepts only the server's certificate (`AllowClient`) and grants it
//! writes (`ZEZWOLENIE_ZAPISU = <channel>, cert:<fingerprint>`) on two of its three
//! channels; the server pins both gates' certificates (`AsixNetServerFingerprint`).
//! The items come from a variable database of the test's own, whose `Channel` attribute
//! names the gate's channels: `GA`, `GB` on `KANAL` (ticking every 200 ms), `GW` on
//! `WOLNY` (ticking once a minute: writes read back), `GZ` on `ZAKAZ` (no write right).
//!
//! asix-gate.exe is 32-bit (the double is a 32-bit in-process server); the test client is
//! either (the file is in `E2E_32`). As `diagnostics.rs`: waits until no other
//! ServerCTOPC.exe runs and starts a server of its own (`SERVERCTOPC_INI`).
#![cfg(windows)]
#![allow(clippy::unwrap_used, clippy::expect_used)]

use ctopc_core::model::ItemVqt;
use ctopc_core::{Quality, Timestamp, Value};
use e2e_tests::interfaces::*;
use e2e_tests::io_support::*;
use e2e_tests::server_config::{read_log, wait_until_no_server};
use e2e_tests::start::StartRetrying;
use e2e_tests::{artifact, wait_for_no_other_server, Apartment, PROGID};
use opc_client::{self as client, GroupSpec, ItemDef, OpcGroup, Server};
use std::collections::HashMap;
use std::io::{BufRead, BufReader, Write};
use std::net::{Ipv4Addr, SocketAddr, UdpSocket};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;
use test_support::wait::{wait_for, wait_until};
use windows::core::{Interface, HRESULT};
use windows::Win32::Foundation::S_OK;

/// The server's discovery port, where [`Broadcast`] listens (the gates answer on ports of
/// their own).
const DISCOVERY_PORT: u16 = 48_190;
/// `ASKOM_E_WriteError_IllegalCommand`: the gate's refusal of a write it does not grant.
const ILLEGAL_COMMAND: HRESULT = HRESULT(0xC004_812A_u32 as i32);

const CSV: &str = "Name;Alias;Description;DescriptionEn;Unit;RangeFrom;RangeTo;DataType;Format;\
WarnLow;WarnHigh;AlarmLow;AlarmHigh;ControlVariable;BarBase;Writable;Channel;Address;SampleRate\r\n\
GA;;A;A;;0;100000;R4;%.1f;;;;;;;tak;KANAL;;1\r\n\
GB;;B;B;;0;100000;R4;%.1f;;;;;;;tak;KANAL;;1\r\n\
GW;;W;W;;0;100000;R4;%.1f;;;;;;;tak;WOLNY;;1\r\n\
GZ;;Z;Z;;0;100000;R4;%.1f;;;;;;;tak;ZAKAZ;;1\r\n";

/// The 32-bit asix-gate.exe (`cargo xtask build`), whatever the test's bitness.
fn gate_exe() -> PathBuf {
    let server = artifact("ServerCTOPC.exe");
    let target = server
        .parent()
        .and_then(Path::parent)
        .and_then(Path::parent)
        .expect("target dir");
    target.join("i686-pc-windows-gnu/release/asix-gate.exe")
}

struct Identity {
    cert: String,
    key: String,
    fingerprint: String,
}

fn identity(name: &str) -> Identity {
    let g = asix_net::tls::generate(name, None).expect("a TLS identity");
    Identity {
        cert: g.cert_pem.clone(),
        key: g.key_pem.clone(),
        fingerprint: asix_net::tls::fingerprint_hex(&g.identity.fingerprint()),
    }
}

/// The plant network's broadcast on loopback: every FindServer that reaches the server's
/// discovery target (127.0.0.1:[`DISCOVERY_PORT`]) goes to each gate's discovery address,
/// from a socket of that client's own, and every answer back to that client. A gate that
/// is gone answers nothing. Dropping it stops its threads.
struct Broadcast {
    stop: Arc<AtomicBool>,
    threads: Arc<Mutex<Vec<JoinHandle<()>>>>,
}

/// How long a relay thread blocks in a receive before it looks at the stop flag.
const RELAY_POLL: Duration = Duration::from_millis(200);
/// The clients (discovery sockets) relayed at most: the server has one per channel.
const RELAY_CLIENTS: usize = 64;

impl Broadcast {
    fn start(gates: Vec<SocketAddr>) -> Broadcast {
        let front = UdpSocket::bind((Ipv4Addr::LOCALHOST, DISCOVERY_PORT))
            .unwrap_or_else(|e| panic!("the discovery port 127.0.0.1:{DISCOVERY_PORT}: {e}"));
        front.set_read_timeout(Some(RELAY_POLL)).unwrap();
        let stop = Arc::new(AtomicBool::new(false));
        let threads = Arc::new(Mutex::new(Vec::new()));
        let (stop2, threads2) = (stop.clone(), threads.clone());
        let t = std::thread::spawn(move || {
            let mut backs: HashMap<SocketAddr, UdpSocket> = HashMap::new();
            let mut buf = vec![0u8; asix_net::proto::MAX_DATAGRAM + 1];
            while !stop2.load(Ordering::SeqCst) {
                // Errors (a timeout; an ICMP "port unreachable" of a stopped gate, which
                // Windows reports on the next receive) are not the end of the relay.
                let Ok((n, client)) = front.recv_from(&mut buf) else {
                    continue;
                };
                if backs.len() >= RELAY_CLIENTS && !backs.contains_key(&client) {
                    continue;
                }
                let back = backs.entry(client).or_insert_with(|| {
                    let back = UdpSocket::bind((Ipv4Addr::LOCALHOST, 0)).unwrap();
                    back.set_read_timeout(Some(RELAY_POLL)).unwrap();
                    let (answers, reply) = (back.try_clone().unwrap(), front.try_clone().unwrap());
                    let stop = stop2.clone();
                    let t = std::thread::spawn(move || {
                        let mut buf = vec![0u8; asix_net::proto::MAX_DATAGRAM + 1];
                        while !stop.load(Ordering::SeqCst) {
                            if let Ok((n, _)) = answers.recv_from(&mut buf) {
                                let _ = reply.send_to(&buf[..n], client);
                            }
                        }
                    });
                    threads2.lock().unwrap().push(t);
                    back
                });
                for g in &gates {
                    let _ = back.send_to(&buf[..n], g);
                }
            }
        });
        threads.lock().unwrap().push(t);
        Broadcast { stop, threads }
    }
}

impl Drop for Broadcast {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        let threads = std::mem::take(&mut *self.threads.lock().unwrap());
        for t in threads {
            let _ = t.join();
        }
    }
}

/// A running gate; dropping it ends the process.
struct Gate {
    name: &'static str,
    child: Child,
    /// Where it answers discovery (from its ready line).
    discovery: SocketAddr,
}

impl Gate {
    /// Writes the gate's folder (identity, `asix-gate.ini`) and starts it; returns once it
    /// printed its ready line.
    fn start(root: &Path, name: &'static str, id: &Identity, client_fp: &str) -> Gate {
        let dir = root.join(name);
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("gate-cert.pem"), &id.cert).unwrap();
        std::fs::write(dir.join("gate-key.pem"), &id.key).unwrap();
        let ini = dir.join("asix-gate.ini");
        std::fs::write(
            &ini,
            format!(
                "[ASIX-GATE]\r\nServerName = {name}\r\nListen = 127.0.0.1:0\r\n\
                 Discovery = 127.0.0.1:0\r\nCertificate = gate-cert.pem\r\n\
                 PrivateKey = gate-key.pem\r\nAllowClient = {client_fp}\r\nStatePollMs = 200\r\n\
                 TimeZone = UTC\r\nLanguage = EN\r\nLogDir = Log\r\n\
                 ZEZWOLENIE_ZAPISU = KANAL, cert:{client_fp}\r\n\
                 ZEZWOLENIE_ZAPISU = WOLNY, cert:{client_fp}\r\n\r\n\
                 [KANAL]\r\nInit = Vars=GA,GB;PeriodMs=200\r\n\r\n\
                 [WOLNY]\r\nInit = Vars=GW;PeriodMs=60000\r\n\r\n\
                 [ZAKAZ]\r\nInit = Vars=GZ;PeriodMs=60000\r\n"
            ),
        )
        .unwrap();
        let mut child = Command::new(gate_exe())
            .arg("--config")
            .arg(&ini)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(std::fs::File::create(dir.join("stderr.txt")).unwrap())
            .spawn_retrying()
            .expect("start asix-gate.exe");
        let out = child.stdout.take().unwrap();
        let (tx, rx) = mpsc::channel();
        std::thread::spawn(move || {
            // The ready line, then the rest is drained so that the pipe never fills.
            for line in BufReader::new(out).lines() {
                let Ok(line) = line else { break };
                let _ = tx.send(line);
            }
        });
        // Its ready line; a WARN may come first (a key file that the platform cannot make
        // private: Wine keeps no file DACLs).
        let deadline = std::time::Instant::now() + Duration::from_secs(60);
        let ready = loop {
            let left = deadline.saturating_duration_since(std::time::Instant::now());
            match rx.recv_timeout(left) {
                Ok(l) if l.starts_with("asix-gate ") => break Ok(l),
                Ok(_) => continue,
                Err(e) => break Err(e),
            }
        };
        // `asix-gate NAME udp=ADDR tcp=ADDR fingerprint=HEX`
        let discovery = ready.as_ref().ok().and_then(|l| {
            l.split(' ')
                .find_map(|w| w.strip_prefix("udp="))
                .and_then(|a| a.parse::<SocketAddr>().ok())
        });
        let Some(discovery) = discovery else {
            let mut child = child;
            let _ = child.kill();
            let status = child.wait();
            panic!(
                "{name} did not start: {ready:?}, {status:?}; stderr:\n{}\nlog:\n{}",
                std::fs::read_to_string(dir.join("stderr.txt")).unwrap_or_default(),
                read_log(&dir)
            );
        };
        Gate {
            name,
            child,
            discovery,
        }
    }

    fn stop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Drop for Gate {
    fn drop(&mut self) {
        if let Some(stdin) = self.child.stdin.as_mut() {
            let _ = stdin.write_all(b"quit\n");
            let _ = stdin.flush();
        }
        let done = wait_until(Duration::from_secs(10), || {
            matches!(self.child.try_wait(), Ok(Some(_)))
        });
        if !done {
            self.stop();
        }
    }
}

fn read_diag(server: &Server, id: &str) -> client::ReadItem {
    let (_, r) = server.item_read(&[(id, 0)]).expect("IOPCItemIO::Read");
    r.into_iter().next().expect("one result")
}

/// The gate the channel `KANAL` is linked to (`_Diagnostics.Channels.KANAL.Server`).
fn linked_server(server: &Server) -> Option<String> {
    let link = read_diag(server, "_Diagnostics.Channels.KANAL.LinkState");
    if link.value != Value::I4(1) {
        return None;
    }
    match read_diag(server, "_Diagnostics.Channels.KANAL.Server").value {
        Value::Bstr(s) if !s.is_empty() => Some(s),
        _ => None,
    }
}

fn r8(v: &Value) -> Option<f64> {
    match v {
        Value::R8(x) => Some(*x),
        Value::R4(x) => Some(f64::from(*x)),
        _ => None,
    }
}

fn good(q: u16) -> bool {
    q & 0xC0 == 0xC0
}

#[test]
fn read_write_subscribe_and_failover_through_two_gates() {
    wait_for_no_other_server();
    let root = std::env::temp_dir().join(format!("gate-e2e-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    std::fs::create_dir_all(&root).unwrap();
    let opc = identity("SERVERCTOPC");
    let (id_a, id_b) = (identity("GATE-A"), identity("GATE-B"));
    let mut gate_a = Gate::start(&root, "GATE-A", &id_a, &opc.fingerprint);
    let mut gate_b = Gate::start(&root, "GATE-B", &id_b, &opc.fingerprint);
    let broadcast = Broadcast::start(vec![gate_a.discovery, gate_b.discovery]);

    // The server: its certificate, both gates pinned, discovery to the broadcast.
    let dir = root.join("server");
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("opc-cert.pem"), &opc.cert).unwrap();
    std::fs::write(dir.join("opc-key.pem"), &opc.key).unwrap();
    std::fs::write(dir.join("gate.csv"), CSV).unwrap();
    let ini = dir.join("ASIXConnect-gate.ini");
    std::fs::write(
        &ini,
        format!(
            "[Server]\r\nSimulateCurrentData = nie\r\nLogDirectory = Log\r\nReconnectInterval = 500\r\n\
             BroadcastAddress = 127.0.0.1\r\nDiscoveryPort = {DISCOVERY_PORT}\r\n\
             [Channel:*]\r\nItemsDatabase = gate.csv\r\nFindServerTimeout = 1000\r\nNetTimeout = 2000\r\n\
             AsixNetCertFile = opc-cert.pem\r\nAsixNetKeyFile = opc-key.pem\r\n\
             AsixNetServerFingerprint = {}, {}\r\n",
            id_a.fingerprint, id_b.fingerprint
        ),
    )
    .unwrap();
    std::env::set_var("SERVERCTOPC_INI", &ini);
    let com = Apartment::mta().expect("MTA");
    let server = Server::connect(PROGID).expect("connect");
    std::env::remove_var("SERVERCTOPC_INI");
    let logs = || {
        format!(
            "server log:\n{}\nGATE-A log:\n{}\nGATE-B log:\n{}",
            read_log(&dir),
            read_log(&root.join("GATE-A")),
            read_log(&root.join("GATE-B"))
        )
    };

    let g = server.add_group(&GroupSpec::new("gate")).expect("AddGroup");
    let group = OpcGroup::from_unknown(g.object).unwrap();
    let ids = ["GA", "GB", "GW", "GZ"];
    let defs: Vec<ItemDef> = ids
        .iter()
        .enumerate()
        .map(|(i, id)| ItemDef::new(id, i as u32 + 1))
        .collect();
    let (hr, added) = group.add_items(&defs).expect("AddItems");
    assert_eq!(hr, S_OK, "{added:?}");
    let h: Vec<u32> = added.iter().map(|a| a.server_handle).collect();
    let io: IOPCSyncIO = group.unknown.cast().unwrap();

    // Subscribed: GOOD values in the cache and in OnDataChange, from the double's ticks.
    let rec = Recording::new();
    client::advise_data_callback(&group.unknown, &RecordingSink::create(&rec)).expect("Advise");
    let all_good = wait_until(Duration::from_secs(30), || {
        client::sync_read(&io, OPC_DS_CACHE, &h[..3])
            .is_ok_and(|(_, r)| r.iter().all(|i| good(i.quality)))
    });
    assert!(all_good, "no GOOD values in the cache; {}", logs());
    let first = client::sync_read(&io, OPC_DS_CACHE, &h[..1]).unwrap().1[0].clone();
    let later = rec.wait_for(Duration::from_secs(10), |c| {
        matches!(c, Callback::DataChange { items, .. }
            if items.iter().any(|i| i.client_handle == 1 && good(i.quality)
                && r8(&i.value) > r8(&first.value)))
    });
    assert!(
        later.is_some(),
        "no OnDataChange of GA beyond {first:?} (the double ticks every 200 ms)"
    );

    // A device read goes through the gate to the double.
    let (_, r) = client::sync_read(&io, OPC_DS_DEVICE, &h[..3]).expect("device read");
    assert!(r.iter().all(|i| good(i.quality)), "{r:?}");
    assert!(
        r.iter().all(|i| r8(&i.value).is_some_and(|x| x >= 10.0)),
        "{r:?}"
    );

    // A simple write, read back from the device (GW ticks once a minute only).
    let (_, errors) = client::sync_write(&io, &[(h[2], Value::R8(42.0))]).expect("Write");
    assert_eq!(errors, [S_OK], "{}", logs());
    let (_, r) = client::sync_read(&io, OPC_DS_DEVICE, &h[2..3]).unwrap();
    assert_eq!(r8(&r[0].value), Some(42.0), "{r:?}");

    // The extended writes: value, quality and time reach the double (WriteEx) and come back.
    let stamp = Timestamp::from_unix_millis(1_678_881_600_000); // 2023-03-15 12:00Z
    let io2: IOPCSyncIO2 = group.unknown.cast().unwrap();
    let vqt = ItemVqt {
        value: Value::R8(7.5),
        quality: Some(Quality(0x40)),
        timestamp: Some(stamp),
    };
    let (_, errors) = client::write_vqt(&io2, &[(h[2], vqt)]).expect("SyncIO2 WriteVQT");
    assert_eq!(errors, [S_OK], "{}", logs());
    let (_, r) = client::sync_read(&io, OPC_DS_DEVICE, &h[2..3]).unwrap();
    assert_eq!(
        (r8(&r[0].value), r[0].quality, r[0].timestamp),
        (Some(7.5), 0x40, stamp),
        "{r:?}"
    );
    let stamp2 = Timestamp::from_unix_millis(1_698_541_200_000); // 2023-10-29 01:00Z
    let vqt = ItemVqt {
        value: Value::R8(8.25),
        quality: Some(Quality(0xC0)),
        timestamp: Some(stamp2),
    };
    let (_, errors) = server
        .item_write_vqt(&[("GW", vqt)])
        .expect("IOPCItemIO::WriteVQT");
    assert_eq!(errors, [S_OK], "{}", logs());
    let r = read_diag(&server, "GW");
    assert_eq!(
        (r8(&r.value), r.quality, r.timestamp),
        (Some(8.25), 0xC0, stamp2),
        "{r:?}"
    );

    // A write the gate does not grant to the server's certificate: the original's code.
    let (_, errors) = client::sync_write(&io, &[(h[3], Value::R8(1.0))]).expect("Write");
    assert_eq!(errors, [ILLEGAL_COMMAND], "{}", logs());

    // Failover: the gate KANAL is linked to stops; the other serves the items within 30 s.
    let linked = wait_for(Duration::from_secs(10), || linked_server(&server))
        .unwrap_or_else(|| panic!("KANAL not linked; {}", logs()));
    let names = |s: &str, gate: &str| s.to_ascii_uppercase().contains(gate);
    let (stopped, other) = if names(&linked, gate_a.name) {
        (&mut gate_a, "GATE-B")
    } else {
        assert!(names(&linked, gate_b.name), "{linked}");
        (&mut gate_b, "GATE-A")
    };
    stopped.stop();
    let moved = wait_until(Duration::from_secs(30), || {
        linked_server(&server).is_some_and(|s| names(&s, other))
    });
    assert!(moved, "KANAL did not move to {other}; {}", logs());
    rec.clear();
    let fresh = rec.wait_for(Duration::from_secs(15), |c| {
        matches!(c, Callback::DataChange { items, .. }
            if items.iter().any(|i| i.client_handle == 1 && good(i.quality)))
    });
    assert!(fresh.is_some(), "no GOOD OnDataChange of GA from {other}");
    assert!(
        wait_until(Duration::from_secs(15), || {
            client::sync_read(&io, OPC_DS_CACHE, &h[..2])
                .is_ok_and(|(_, r)| r.iter().all(|i| good(i.quality)))
        }),
        "GA, GB GOOD again from {other}"
    );
    let (_, errors) = client::sync_write(&io, &[(h[2], Value::R8(5.0))]).expect("Write");
    assert_eq!(errors, [S_OK], "a write through {other}");

    drop((io, io2, group, server));
    drop(com);
    drop((gate_a, gate_b, broadcast));
    assert!(
        wait_until_no_server(Duration::from_secs(60)),
        "the test's server did not exit"
    );
    let log = read_log(&dir);
    assert!(!log.contains("panicked"), "{log}");
    let _ = std::fs::remove_dir_all(&root);
}
