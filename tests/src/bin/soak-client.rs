//! soak-client.exe: one client of the memory soak (`cargo xtask soak`, under Wine).
//!
//! `soak-client --hold --seconds S`: connects and holds the server for S seconds (so that
//! it stays up between rounds). `soak-client --seconds S --items N`: churns for S
//! seconds: connect, AddGroup, AddItems of N items, IOPCSyncIO::Read, Write of every
//! writable item, a subscription for about a second, RemoveGroup, disconnect; again.
//! Prints one line with the rounds done and the failures seen.

#[cfg(not(windows))]
fn main() -> std::process::ExitCode {
    eprintln!("soak-client: a Windows program (run it under Wine: cargo xtask soak)");
    std::process::ExitCode::FAILURE
}

#[cfg(windows)]
fn main() -> std::process::ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let value = |name: &str, default: u64| {
        args.iter()
            .position(|a| a == name)
            .and_then(|i| args.get(i + 1))
            .and_then(|v| v.parse().ok())
            .unwrap_or(default)
    };
    let seconds = value("--seconds", 60);
    let items = value("--items", 1000) as usize;
    let r = if args.iter().any(|a| a == "--hold") {
        soak::hold(seconds)
    } else {
        soak::churn(seconds, items)
    };
    match r {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("soak-client: error: {e}");
            std::process::ExitCode::FAILURE
        }
    }
}

#[cfg(windows)]
mod soak {
    use ctopc_com::client::{self, ComThread, GroupSpec, ItemDef, OpcGroup, Server};
    use ctopc_core::Value;
    use e2e_tests::io_support::{Recorder, TestSink};
    use e2e_tests::PROGID;
    use std::time::{Duration, Instant};
    use windows::core::Interface;

    /// Items of the demo plant (read-only levels and writable setpoints), repeated.
    const IDS: [&str; 4] = ["KW_A000", "KW_A001", "KW_A110", "KW_D201"];
    /// The writable R4 among them.
    const SETPOINT: &str = "KW_A110";

    pub fn hold(seconds: u64) -> Result<(), String> {
        let _com = ComThread::mta().map_err(|e| e.to_string())?;
        let server = Server::connect(PROGID).map_err(|e| format!("connect: {e}"))?;
        let deadline = Instant::now() + Duration::from_secs(seconds);
        while Instant::now() < deadline {
            std::thread::sleep(Duration::from_secs(1));
            server.status().map_err(|e| format!("GetStatus: {e}"))?;
        }
        println!("soak-client: held the server for {seconds} s");
        Ok(())
    }

    pub fn churn(seconds: u64, items: usize) -> Result<(), String> {
        let _com = ComThread::mta().map_err(|e| e.to_string())?;
        let deadline = Instant::now() + Duration::from_secs(seconds);
        let (mut rounds, mut failures) = (0u32, 0u32);
        while Instant::now() < deadline {
            match one_round(items) {
                Ok(()) => rounds += 1,
                Err(e) => {
                    failures += 1;
                    eprintln!("soak-client: {e}");
                    std::thread::sleep(Duration::from_millis(500));
                }
            }
        }
        println!("soak-client: {rounds} rounds, {failures} failures");
        Ok(())
    }

    fn one_round(items: usize) -> Result<(), String> {
        let server = Server::connect(PROGID).map_err(|e| format!("connect: {e}"))?;
        let g = server
            .add_group(&GroupSpec::new(""))
            .map_err(|e| format!("AddGroup: {e}"))?;
        let group = OpcGroup::from_unknown(g.object).map_err(|e| e.to_string())?;
        let defs: Vec<ItemDef> = (0..items)
            .map(|i| ItemDef::new(IDS[i % IDS.len()], i as u32))
            .collect();
        let (_, added) = group
            .add_items(&defs)
            .map_err(|e| format!("AddItems: {e}"))?;
        let handles: Vec<u32> = added.iter().map(|a| a.server_handle).collect();
        let io = group
            .unknown
            .cast::<ctopc_com::interfaces::IOPCSyncIO>()
            .map_err(|e| e.to_string())?;
        let _ = client::sync_read(&io, ctopc_com::interfaces::OPC_DS_CACHE, &handles)
            .map_err(|e| format!("Read: {e}"))?;
        let writes: Vec<(u32, Value)> = defs
            .iter()
            .zip(&handles)
            .filter(|(d, _)| d.item_id == SETPOINT)
            .map(|(_, h)| (*h, Value::R4(5.0)))
            .collect();
        let _ = client::sync_write(&io, &writes).map_err(|e| format!("Write: {e}"))?;
        let rec = Recorder::recording();
        let sink = TestSink::create(&rec);
        let cookie = client::advise_data_callback(&group.unknown, &sink)
            .map_err(|e| format!("Advise: {e}"))?;
        let _ = rec.wait_for(Duration::from_secs(2), |_| true);
        client::unadvise_data_callback(&group.unknown, cookie)
            .map_err(|e| format!("Unadvise: {e}"))?;
        drop(group);
        let _ = server
            .remove_group(g.server_handle, true)
            .map_err(|e| format!("RemoveGroup: {e}"))?;
        Ok(())
    }
}
