//! asix-sim: a simulated asix data server speaking the asix network protocol.
//!
//! Runs until `quit` on stdin, `--run-for-ms` elapses, or the process is killed. Other stdin
//! lines are control commands (`drop-links`, `stop-answering`, `answer`, `fail-source`,
//! `restore-source`, `status`, and with `--rest` `rest-mode SWITCHES`); each is answered
//! with one line on stdout.
//!
//! `--rest ADDR` also serves the plant through the Asix.Evo REST API
//! (`asix_net::sim::rest`), with its misbehaviour switches from `--rest-mode`, stdin or
//! `POST /sim/mode?...`.

use std::io::BufRead;
use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::path::Path;
use std::process::ExitCode;
use std::time::Duration;

use asix_net::proto::{DEFAULT_DISCOVERY_PORT, DEFAULT_TCP_PORT};
use asix_net::secure::ServerTls;
use asix_net::sim::plant::{
    acid_plant, channels_from_database, ChannelDef, VarSpec, ACID_PLANT_CHANNEL,
};
use asix_net::sim::rights::WriteRights;
use asix_net::sim::{self, SimConfig};
use asix_net::tls::{self, Fingerprint, Identity, Trust};
use ctopc_core::VarType;

const USAGE: &str = "\
usage: asix-sim [options]
  --name NAME             server name (default ASIX-SIM)
  --host NAME             computer name; clients reporting it are local (default: this computer)
  --udp ADDR|PORT         discovery address (default 0.0.0.0:48100)
  --tcp ADDR|PORT         link address (default 0.0.0.0:48101)
  --channel NAME[=FILE]   serve a channel: the built-in acid plant variables, or those listed
                          in FILE (lines: NAME TYPE LOW HIGH [rw]; TYPE R4 I2 UI2 I4 UI4 UI1 R8)
                          (default: one channel Demo_Wytwornia_Kwasu)
  --demo-db FILE          serve an asix variable database (the demo: demo/wytwornia_kwasu/
                          wytwornia_kwasu.zez), one channel per `Channel` attribute
  --noisy NAME:COUNT      serve a channel of COUNT noisy R4 variables V00000.. (benchmarks)
  --archive NAME          announce an archive resource
  --seed N                simulation seed (default 1)
  --tick-ms N             simulation step (default 100)
  --app-ini FILE          asix application ini with write rights ([ASMEN] ZEZWOLENIE_ZAPISU ...)
  --bridge                announce as a bridge
  --source-failed         start with the data source failed
  --extra-clients N       add N to the announced client count
  --driver-delay-ms N     delay of reads from the driver (default 20)
  --run-for-ms N          exit after N ms
  --cert FILE --key FILE  TLS identity, PEM (default: a self-signed one made at start); the
                          certificate's SHA-256 fingerprint is printed on the ready line
  --allow-client FP       accept only clients with this certificate fingerprint (repeatable;
                          default: any client certificate, still required)
  --client-ca FILE        accept only clients whose certificate a CA of FILE (PEM) issued
  --allow-writer FP       only these client identities may write (repeatable; default: the
                          --app-ini rule with the identity cert:<FP> as the client's name)
  --plaintext             also accept plaintext links (closed test network only; warned)
  --max-handshakes N      handshakes under way at once, more are refused as busy (default 64)
  --handshake-timeout-ms N  the longest a handshake may take (default 5000)
  --gen-cert DIR          write a key pair and self-signed certificate for --name to
                          DIR/asix-cert.pem and DIR/asix-key.pem, print the fingerprint, exit
  --rest ADDR             also serve the Asix.Evo REST API on ADDR (e.g. 127.0.0.1:0); the
                          asix ports then default to ephemeral loopback ports
  --rest-mode SWITCHES    REST misbehaviour: fail=1 slow_ms=N single=1 malformed=1 huge=1
                          slow_body_ms=N redirect=1 (joined with &)
stdin commands: drop-links stop-answering answer fail-source restore-source status
                rest-mode SWITCHES quit
";

/// What the command line asks besides the simulator's settings.
#[derive(Default)]
struct Extra {
    run_for: Option<u64>,
    cert: Option<String>,
    key: Option<String>,
    allow_clients: Vec<Fingerprint>,
    client_ca: Option<String>,
    gen_cert: Option<String>,
    rest: Option<SocketAddr>,
    rest_mode: Option<String>,
}

fn addr(s: &str) -> Result<SocketAddr, String> {
    if let Ok(p) = s.parse::<u16>() {
        return Ok(SocketAddr::new(IpAddr::V4(Ipv4Addr::UNSPECIFIED), p));
    }
    s.parse().map_err(|_| format!("bad address {s:?}"))
}

fn parse_type(s: &str) -> Option<VarType> {
    Some(match s.to_ascii_uppercase().as_str() {
        "R4" => VarType::R4,
        "R8" => VarType::R8,
        "I2" => VarType::I2,
        "UI2" => VarType::UI2,
        "I4" => VarType::I4,
        "UI4" => VarType::UI4,
        "UI1" => VarType::UI1,
        "BOOL" => VarType::BOOL,
        _ => return None,
    })
}

/// Reads a simple variable list: `NAME TYPE LOW HIGH [rw]` per line (separators: blanks,
/// commas or semicolons; `#` or `;` starts a comment line).
fn read_var_list(text: &str) -> Result<Vec<VarSpec>, String> {
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') || line.starts_with(';') {
            continue;
        }
        let f: Vec<&str> = line
            .split(|c: char| c.is_whitespace() || c == ',' || c == ';')
            .filter(|x| !x.is_empty())
            .collect();
        let bad = || format!("line {}: expected NAME TYPE LOW HIGH [rw]", n + 1);
        if f.len() < 4 {
            return Err(bad());
        }
        let t = parse_type(f[1]).ok_or_else(bad)?;
        let lo: f64 = f[2].parse().map_err(|_| bad())?;
        let hi: f64 = f[3].parse().map_err(|_| bad())?;
        let rw = f
            .get(4)
            .is_some_and(|x| x.eq_ignore_ascii_case("rw") || x.eq_ignore_ascii_case("w"));
        out.push(VarSpec::new(f[0], t, lo, hi, rw));
    }
    Ok(out)
}

fn parse(args: Vec<String>) -> Result<(SimConfig, Extra), String> {
    let mut cfg = SimConfig::new("ASIX-SIM");
    cfg.host_name = asix_net::computer_name();
    cfg.discovery_addr = SocketAddr::new(IpAddr::V4(Ipv4Addr::UNSPECIFIED), DEFAULT_DISCOVERY_PORT);
    cfg.tcp_addr = SocketAddr::new(IpAddr::V4(Ipv4Addr::UNSPECIFIED), DEFAULT_TCP_PORT);
    cfg.channels.clear();
    let mut extra = Extra::default();
    let (mut udp_set, mut tcp_set) = (false, false);
    let mut it = args.into_iter();
    while let Some(a) = it.next() {
        let mut val = || it.next().ok_or_else(|| format!("{a} needs a value"));
        let num = |s: String| s.parse::<u64>().map_err(|_| format!("bad number {s:?}"));
        match a.as_str() {
            "--name" => cfg.server_name = val()?,
            "--host" => cfg.host_name = val()?,
            "--udp" => {
                cfg.discovery_addr = addr(&val()?)?;
                udp_set = true;
            }
            "--tcp" => {
                cfg.tcp_addr = addr(&val()?)?;
                tcp_set = true;
            }
            "--rest" => extra.rest = Some(addr(&val()?)?),
            "--rest-mode" => extra.rest_mode = Some(val()?),
            "--channel" => {
                let v = val()?;
                match v.split_once('=') {
                    Some((name, file)) => {
                        let text =
                            std::fs::read_to_string(file).map_err(|e| format!("{file}: {e}"))?;
                        cfg.channels.push(ChannelDef::from_specs(
                            name,
                            read_var_list(&text).map_err(|e| format!("{file}: {e}"))?,
                        ));
                    }
                    None => {
                        let mut c = acid_plant();
                        c.name = v;
                        cfg.channels.push(c);
                    }
                }
            }
            "--demo-db" => {
                let f = val()?;
                let (db, warnings) = asix_model::load_database_file(std::path::Path::new(&f), None)
                    .map_err(|e| e.to_string())?;
                for w in warnings {
                    eprintln!("asix-sim: {w}");
                }
                cfg.channels
                    .extend(channels_from_database(&db, ACID_PLANT_CHANNEL));
            }
            "--noisy" => {
                let v = val()?;
                let (name, n) = v.split_once(':').ok_or("--noisy needs NAME:COUNT")?;
                cfg.channels
                    .push(ChannelDef::noisy(name, num(n.to_owned())? as usize));
            }
            "--archive" => cfg.archives.push(val()?),
            "--seed" => cfg.seed = num(val()?)?,
            "--tick-ms" => cfg.tick_ms = num(val()?)?,
            "--app-ini" => {
                let f = val()?;
                let bytes = std::fs::read(&f).map_err(|e| format!("{f}: {e}"))?;
                let (rights, warnings) = WriteRights::from_app_ini(&bytes, &f);
                for w in warnings {
                    eprintln!("asix-sim: {w}");
                }
                cfg.write_rights = rights;
            }
            "--bridge" => cfg.bridge = true,
            "--source-failed" => cfg.source_failed = true,
            "--extra-clients" => cfg.extra_clients = num(val()?)? as u32,
            "--driver-delay-ms" => cfg.driver_delay = Duration::from_millis(num(val()?)?),
            "--run-for-ms" => extra.run_for = Some(num(val()?)?),
            "--cert" => extra.cert = Some(val()?),
            "--key" => extra.key = Some(val()?),
            "--allow-client" => extra.allow_clients.push(tls::parse_fingerprint(&val()?)?),
            "--client-ca" => extra.client_ca = Some(val()?),
            "--allow-writer" => {
                let fp = tls::parse_fingerprint(&val()?)?;
                cfg.allow_writers
                    .get_or_insert_with(Vec::new)
                    .push(tls::identity_of(&fp));
            }
            "--plaintext" => cfg.security.allow_plaintext = true,
            "--max-handshakes" => cfg.security.max_handshakes = num(val()?)?.max(1) as usize,
            "--handshake-timeout-ms" => {
                cfg.security.handshake_timeout = Duration::from_millis(num(val()?)?)
            }
            "--gen-cert" => extra.gen_cert = Some(val()?),
            "-h" | "--help" => return Err(String::new()),
            other => return Err(format!("unknown option {other}")),
        }
    }
    if cfg.channels.is_empty() {
        let mut c = acid_plant();
        c.name = ACID_PLANT_CHANNEL.to_owned();
        cfg.channels.push(c);
    }
    // The TLS identity and the clients accepted.
    if extra.gen_cert.is_none() {
        let trust = match (&extra.client_ca, extra.allow_clients.is_empty()) {
            (Some(_), false) => return Err("--allow-client and --client-ca: give one".into()),
            (Some(ca), true) => Trust::ca_file(Path::new(ca)).map_err(|e| e.to_string())?,
            (None, false) => Trust::Fingerprints(extra.allow_clients.clone()),
            (None, true) => Trust::AnyCertificate,
        };
        let identity = match (&extra.cert, &extra.key) {
            (Some(c), Some(k)) => {
                Identity::load(Path::new(c), Path::new(k)).map_err(|e| e.to_string())?
            }
            (None, None) => {
                tls::generate(&cfg.server_name, None)
                    .map_err(|e| e.to_string())?
                    .identity
            }
            _ => return Err("--cert and --key go together".into()),
        };
        cfg.security.tls = Some(ServerTls::new(&identity, trust).map_err(|e| e.to_string())?);
    }
    if extra.rest.is_some() {
        // Several REST stations on one computer: their asix ports must not collide.
        let lo = SocketAddr::new(IpAddr::V4(Ipv4Addr::LOCALHOST), 0);
        if !udp_set {
            cfg.discovery_addr = lo;
        }
        if !tcp_set {
            cfg.tcp_addr = lo;
        }
    }
    Ok((cfg, extra))
}

/// `--gen-cert DIR`: the key pair and certificate files, and the fingerprint to paste into
/// the other side (`AsixNetServerFingerprint` of ServerCTOPC's channel).
fn gen_cert(dir: &str, name: &str) -> Result<String, String> {
    let g = tls::generate(name, None).map_err(|e| e.to_string())?;
    let dir = Path::new(dir);
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let cert = dir.join("asix-cert.pem");
    let key = dir.join("asix-key.pem");
    std::fs::write(&cert, &g.cert_pem).map_err(|e| format!("{}: {e}", cert.display()))?;
    // The key owner-only (0600 on Unix).
    ctopc_runtime::secret_file::write(&key, g.key_pem.as_bytes())
        .map_err(|e| format!("{}: {e}", key.display()))?;
    Ok(format!(
        "certificate {}\nprivate key {} (keep it secret)\nfingerprint {}",
        cert.display(),
        key.display(),
        tls::fingerprint_hex(&g.identity.fingerprint())
    ))
}

fn main() -> ExitCode {
    let (cfg, extra) = match parse(std::env::args().skip(1).collect()) {
        Ok(x) => x,
        Err(e) if e.is_empty() => {
            print!("{USAGE}");
            return ExitCode::SUCCESS;
        }
        Err(e) => {
            eprintln!("asix-sim: {e}\n\n{USAGE}");
            return ExitCode::from(2);
        }
    };
    if let Some(dir) = &extra.gen_cert {
        return match gen_cert(dir, &cfg.server_name) {
            Ok(text) => {
                println!("{text}");
                ExitCode::SUCCESS
            }
            Err(e) => {
                eprintln!("asix-sim: --gen-cert: {e}");
                ExitCode::FAILURE
            }
        };
    }
    let rt = match tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
    {
        Ok(rt) => rt,
        Err(e) => {
            eprintln!("asix-sim: {e}");
            return ExitCode::FAILURE;
        }
    };
    rt.block_on(async move {
        let sim = match sim::start(cfg).await {
            Ok(s) => s,
            Err(e) => {
                eprintln!("asix-sim: {e}");
                return ExitCode::FAILURE;
            }
        };
        let rest = match extra.rest {
            Some(a) => match sim.serve_rest(a).await {
                Ok(r) => Some(r),
                Err(e) => {
                    eprintln!("asix-sim: REST server on {a}: {e}");
                    return ExitCode::FAILURE;
                }
            },
            None => None,
        };
        if let (Some(r), Some(m)) = (&rest, &extra.rest_mode) {
            if let Err(e) = r.mode().apply(m) {
                eprintln!("asix-sim: --rest-mode: {e}");
                return ExitCode::from(2);
            }
        }
        let rest_text = rest
            .as_ref()
            .map(|r| format!(" rest={}", r.url()))
            .unwrap_or_default();
        let fp = sim
            .fingerprint()
            .map(|f| tls::fingerprint_hex(&f))
            .unwrap_or_else(|| "none".into());
        println!(
            "asix-sim {} udp={} tcp={} fingerprint={fp}{rest_text}",
            sim.server_name(),
            sim.discovery_addr(),
            sim.tcp_addr()
        );
        // stdin is read on a plain thread (no tokio io-std needed); EOF just ends control.
        let (tx, mut rx) = tokio::sync::mpsc::unbounded_channel::<String>();
        std::thread::spawn(move || {
            for line in std::io::stdin().lock().lines() {
                let Ok(line) = line else { break };
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
        let deadline = extra
            .run_for
            .map(|ms| tokio::time::Instant::now() + Duration::from_millis(ms));
        let mut stdin_open = true;
        loop {
            let sleep = async {
                match deadline {
                    Some(d) => tokio::time::sleep_until(d).await,
                    None => std::future::pending().await,
                }
            };
            tokio::select! {
                line = rx.recv(), if stdin_open => match line {
                    Some(l) if l.trim() == "quit" => break,
                    Some(l) if l.trim_start().starts_with("rest-mode") => {
                        let q = l.trim_start()["rest-mode".len()..].trim();
                        match rest.as_ref().map(|r| r.mode().apply(q)) {
                            Some(Ok(())) => println!("ok rest-mode {q}"),
                            Some(Err(e)) => println!("error: {e}"),
                            None => println!("error: no --rest"),
                        }
                    }
                    Some(l) => match sim.control(&l) {
                        Ok(s) => println!("{s}"),
                        Err(e) => println!("error: {e}"),
                    },
                    None => stdin_open = false,
                },
                () = sleep => break,
            }
        }
        sim.shutdown().await;
        ExitCode::SUCCESS
    })
}
