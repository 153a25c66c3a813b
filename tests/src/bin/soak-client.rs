//! soak-client.exe: one client of the memory soak (`cargo xtask soak`, under Wine).
//!
//! `soak-client --hold --seconds S`: connects and holds the server for S seconds (so that
//! it stays up between rounds). `soak-client --seconds S --items N [--calls LIST]`:
//! churns for S seconds, each round on a new connection: connect, GetStatus, AddGroup,
//! then the calls of LIST on N items, RemoveGroup, disconnect; again. LIST (comma
//! separated, default `add,validate,read,write,itemio,subscribe,remove`):
//!
//! - `add`: IOPCItemMgt::AddItems of N items (an `[in]` array of N OPCITEMDEF);
//! - `validate`: ValidateItems of the N (N OPCITEMDEF);
//! - `read`: IOPCSyncIO::Read by handle (an array of DWORD handles);
//! - `device`: IOPCSyncIO::Read by handle from the device; an answer other than S_OK is
//!   a failed device read, and its items' codes are printed (`soak-client: device
//!   failure ...`, the first few of the process);
//! - `write`: IOPCSyncIO::Write of every writable item (one VARIANT each, N/4);
//! - `itemio`: IOPCItemIO::Read of the N item IDs (N string pointers);
//! - `subscribe`: IOPCDataCallback advised for about a second, callbacks, Unadvise;
//! - `remove`: RemoveItems by handle.
//!
//! Without `add`, the items are added once, when the process starts, to a group of a
//! connection the process keeps; `read`, `subscribe` and `remove` then use that group
//! (`remove` with handles the server never issued, so that the items stay): the rounds
//! make only calls that carry no array the stub allocates.
//!
//! `--ids all`: the N items cycle through every item ID the server's flat browse lists
//! (but `_Diagnostics`), not through the four default ones.
//!
//! After each round it prints `soak-client: round N` (or `soak-client: failure N`): the
//! soak's sign of progress. `--stall-after S` (the soak's `--simulate-stall`) stops after
//! S seconds without a word, as a hung call would.
//!
//! At the end it prints one line `soak-client: counts rounds=R failures=F additems=A
//! validateitems=V writes=W itemio=I devicereads=D devicefailed=X` (items sent in each
//! kind of allocated `[in]` array, summed over the process; device reads made and how
//! many failed), which `cargo xtask soak` reads.

#[cfg(not(windows))]
fn main() -> std::process::ExitCode {
    eprintln!("soak-client: a Windows program (run it under Wine: cargo xtask soak)");
    std::process::ExitCode::FAILURE
}

#[cfg(windows)]
fn main() -> std::process::ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let arg = |name: &str| {
        args.iter()
            .position(|a| a == name)
            .and_then(|i| args.get(i + 1))
    };
    let value =
        |name: &str, default: u64| arg(name).and_then(|v| v.parse().ok()).unwrap_or(default);
    let seconds = value("--seconds", 60);
    let items = value("--items", 1000) as usize;
    let r = if args.iter().any(|a| a == "--hold") {
        soak::hold(seconds)
    } else {
        let calls = arg("--calls").map_or(soak::ALL_CALLS, |s| s.as_str());
        let stall_after = arg("--stall-after").and_then(|v| v.parse().ok());
        let all_ids = arg("--ids").is_some_and(|v| v == "all");
        soak::Calls::parse(calls)
            .and_then(|c| soak::churn(seconds, items, &c, stall_after, all_ids))
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
    use ctopc_com::apartment::Apartment;
    use ctopc_com::interfaces::{IOPCSyncIO, OPC_DS_CACHE, OPC_DS_DEVICE, OPC_FLAT};
    use ctopc_core::Value;
    use e2e_tests::io_support::{Recording, RecordingSink};
    use e2e_tests::PROGID;
    use opc_client::{self as client, GroupSpec, ItemDef, OpcGroup, Server};
    use std::time::{Duration, Instant};
    use windows::core::Interface;

    /// Items of the demo plant (read-only levels and writable setpoints), repeated.
    const IDS: [&str; 4] = ["KW_A000", "KW_A001", "KW_A110", "KW_D201"];
    /// The writable R4 among them.
    const SETPOINT: &str = "KW_A110";
    /// The default call list.
    pub const ALL_CALLS: &str = "add,validate,read,write,itemio,subscribe,remove";

    /// The calls of one round (`--calls`).
    #[derive(Default)]
    pub struct Calls {
        add: bool,
        validate: bool,
        read: bool,
        write: bool,
        itemio: bool,
        device: bool,
        subscribe: bool,
        remove: bool,
    }

    impl Calls {
        pub fn parse(list: &str) -> Result<Calls, String> {
            let mut c = Calls::default();
            for name in list.split(',').map(str::trim).filter(|s| !s.is_empty()) {
                match name {
                    "add" => c.add = true,
                    "validate" => c.validate = true,
                    "read" => c.read = true,
                    "write" => c.write = true,
                    "itemio" => c.itemio = true,
                    "device" => c.device = true,
                    "subscribe" => c.subscribe = true,
                    "remove" => c.remove = true,
                    _ => return Err(format!("unknown call `{name}` in --calls")),
                }
            }
            if c.write && !c.add {
                return Err("--calls: `write` needs `add` (it writes the items just added)".into());
            }
            Ok(c)
        }
    }

    /// Items sent in allocated `[in]` arrays (what Wine's stub keeps, docs/wine-ndr-leak.md).
    #[derive(Default)]
    struct Counts {
        rounds: u64,
        failures: u64,
        add_items: u64,
        validate_items: u64,
        writes: u64,
        item_io: u64,
        device_reads: u64,
        device_failed: u64,
    }

    /// The most failed device reads whose item codes a process prints.
    const DEVICE_FAILURES_SHOWN: u64 = 3;

    pub fn hold(seconds: u64) -> Result<(), String> {
        let _com = Apartment::mta().map_err(|e| e.to_string())?;
        let server = Server::connect(PROGID).map_err(|e| format!("connect: {e}"))?;
        let deadline = Instant::now() + Duration::from_secs(seconds);
        while Instant::now() < deadline {
            std::thread::sleep(Duration::from_secs(1));
            server.status().map_err(|e| format!("GetStatus: {e}"))?;
        }
        println!("soak-client: held the server for {seconds} s");
        Ok(())
    }

    /// A connection and group the process keeps, with the items added once.
    struct Kept {
        _server: Server,
        group: OpcGroup,
        handles: Vec<u32>,
    }

    fn defs(items: usize, ids: &[String]) -> Vec<ItemDef> {
        (0..items)
            .map(|i| ItemDef::new(&ids[i % ids.len()], i as u32))
            .collect()
    }

    /// Every item ID of the server's flat browse but `_Diagnostics`, sorted.
    fn browsed_ids() -> Result<Vec<String>, String> {
        let server = Server::connect(PROGID).map_err(|e| format!("connect: {e}"))?;
        let (_, mut ids) = server
            .browse_item_ids(OPC_FLAT, "", 0, 0)
            .map_err(|e| format!("BrowseOPCItemIDs: {e}"))?;
        ids.retain(|id| !id.starts_with('_'));
        ids.sort();
        if ids.is_empty() {
            return Err("the flat browse listed no item".into());
        }
        Ok(ids)
    }

    fn add_group(server: &Server) -> Result<(OpcGroup, u32), String> {
        let g = server
            .add_group(&GroupSpec::new(""))
            .map_err(|e| format!("AddGroup: {e}"))?;
        let group = OpcGroup::from_unknown(g.object).map_err(|e| e.to_string())?;
        Ok((group, g.server_handle))
    }

    /// Churns for `seconds`, printing `soak-client: round N` after each round (the soak's
    /// progress signal). `stall_after`: the soak's `--simulate-stall`: after that many
    /// seconds stop making progress (sleep, printing nothing) so the soak's stall capture
    /// can be seen to work.
    pub fn churn(
        seconds: u64,
        items: usize,
        calls: &Calls,
        stall_after: Option<u64>,
        all_ids: bool,
    ) -> Result<(), String> {
        let _com = Apartment::mta().map_err(|e| e.to_string())?;
        let mut counts = Counts::default();
        let ids: Vec<String> = if all_ids {
            browsed_ids()?
        } else {
            IDS.iter().map(|s| (*s).to_owned()).collect()
        };
        let kept = if calls.add {
            None
        } else {
            let server = Server::connect(PROGID).map_err(|e| format!("connect: {e}"))?;
            let (group, _) = add_group(&server)?;
            let (_, added) = group
                .add_items(&defs(items, &ids))
                .map_err(|e| format!("AddItems: {e}"))?;
            counts.add_items += items as u64;
            let handles = added.iter().map(|a| a.server_handle).collect();
            Some(Kept {
                _server: server,
                group,
                handles,
            })
        };
        let start = Instant::now();
        let deadline = start + Duration::from_secs(seconds);
        while Instant::now() < deadline {
            if stall_after.is_some_and(|s| start.elapsed() >= Duration::from_secs(s)) {
                eprintln!("soak-client: --stall-after: a simulated stall (sleeping)");
                loop {
                    std::thread::sleep(Duration::from_secs(3600));
                }
            }
            match one_round(items, &ids, calls, kept.as_ref(), &mut counts) {
                Ok(()) => {
                    counts.rounds += 1;
                    println!("soak-client: round {}", counts.rounds);
                }
                Err(e) => {
                    counts.failures += 1;
                    eprintln!("soak-client: {e}");
                    // A failed call returned: progress too.
                    println!("soak-client: failure {}", counts.failures);
                    std::thread::sleep(Duration::from_millis(500));
                }
            }
        }
        println!(
            "soak-client: counts rounds={} failures={} additems={} validateitems={} writes={} itemio={} devicereads={} devicefailed={}",
            counts.rounds,
            counts.failures,
            counts.add_items,
            counts.validate_items,
            counts.writes,
            counts.item_io,
            counts.device_reads,
            counts.device_failed
        );
        Ok(())
    }

    fn one_round(
        items: usize,
        ids: &[String],
        calls: &Calls,
        kept: Option<&Kept>,
        counts: &mut Counts,
    ) -> Result<(), String> {
        let server = Server::connect(PROGID).map_err(|e| format!("connect: {e}"))?;
        server.status().map_err(|e| format!("GetStatus: {e}"))?;
        let (own, own_handle) = add_group(&server)?;
        let defs = defs(items, ids);
        let mut handles: Vec<u32> = Vec::new();
        if calls.add {
            counts.add_items += items as u64;
            let (_, added) = own.add_items(&defs).map_err(|e| format!("AddItems: {e}"))?;
            handles = added.iter().map(|a| a.server_handle).collect();
        }
        let (group, handles) = match kept {
            Some(k) => (&k.group, &k.handles),
            None => (&own, &handles),
        };
        if calls.validate {
            counts.validate_items += items as u64;
            let _ = own
                .validate_items(&defs)
                .map_err(|e| format!("ValidateItems: {e}"))?;
        }
        let io = group
            .unknown
            .cast::<IOPCSyncIO>()
            .map_err(|e| e.to_string())?;
        if calls.read {
            let _ =
                client::sync_read(&io, OPC_DS_CACHE, handles).map_err(|e| format!("Read: {e}"))?;
        }
        if calls.device {
            let (hr, got) = client::sync_read(&io, OPC_DS_DEVICE, handles)
                .map_err(|e| format!("Read (device): {e}"))?;
            counts.device_reads += 1;
            if hr.is_ok() && hr != windows::Win32::Foundation::S_OK {
                counts.device_failed += 1;
                if counts.device_failed <= DEVICE_FAILURES_SHOWN {
                    let mut codes: std::collections::BTreeMap<(String, u32), u32> =
                        Default::default();
                    for (i, r) in got.iter().enumerate() {
                        if r.error.is_err() {
                            let id = defs.get(i).map_or("?", |d| d.item_id.as_str());
                            *codes.entry((id.to_owned(), r.error.0 as u32)).or_default() += 1;
                        }
                    }
                    let list: Vec<String> = codes
                        .iter()
                        .map(|((id, c), n)| format!("{id}:0x{c:08X}x{n}"))
                        .collect();
                    println!(
                        "soak-client: device failure {} of {}: {hr:?} items {}",
                        counts.device_failed,
                        counts.device_reads,
                        list.join(" ")
                    );
                }
            }
        }
        if calls.write {
            let writes: Vec<(u32, Value)> = defs
                .iter()
                .zip(handles)
                .filter(|(d, _)| d.item_id == SETPOINT)
                .map(|(_, h)| (*h, Value::R4(5.0)))
                .collect();
            counts.writes += writes.len() as u64;
            let _ = client::sync_write(&io, &writes).map_err(|e| format!("Write: {e}"))?;
        }
        if calls.itemio {
            let ids: Vec<(&str, u32)> = (0..items)
                .map(|i| (ids[i % ids.len()].as_str(), u32::MAX))
                .collect();
            counts.item_io += items as u64;
            let _ = server
                .item_read(&ids)
                .map_err(|e| format!("IOPCItemIO::Read: {e}"))?;
        }
        if calls.subscribe {
            let rec = Recording::new();
            let sink = RecordingSink::create(&rec);
            let cookie = client::advise_data_callback(&group.unknown, &sink)
                .map_err(|e| format!("Advise: {e}"))?;
            let _ = rec.wait_for(Duration::from_secs(2), |_| true);
            client::unadvise_data_callback(&group.unknown, cookie)
                .map_err(|e| format!("Unadvise: {e}"))?;
        }
        if calls.remove {
            // With kept items: handles the server never issued, so that they stay.
            let gone: Vec<u32> = match kept {
                Some(_) => handles
                    .iter()
                    .map(|h| h.wrapping_add(0x4000_0000))
                    .collect(),
                None => handles.clone(),
            };
            let _ = group
                .remove_items(&gone)
                .map_err(|e| format!("RemoveItems: {e}"))?;
        }
        drop(io);
        drop(own);
        let _ = server
            .remove_group(own_handle, true)
            .map_err(|e| format!("RemoveGroup: {e}"))?;
        Ok(())
    }
}
