//! scale-client.exe: one client of the scale measurements, under Wine. A runner
//! (`cargo xtask bench --scale`, or a script) starts it, reads one `ready` line per stage
//! on its stdout, measures the server from outside (VmRSS of ServerCTOPC.exe) and writes
//! one line on its stdin to go on to the next stage.
//!
//! `scale-client [--items N] [--active] [--rate MS] [--ids-from-browse | --synthetic N]
//! [--no-warm-up]`
//!
//! - `--items N` (default 1000): the items of the one group, all added in ONE AddItems.
//! - `--active`: the client subscribes after adding the items: it advises
//!   IOPCDataCallback and makes the group active (SetState) in stage 3. The items are
//!   always added to an inactive group (they are active items either way), so that stage 2
//!   has no subscription in it: with an active group the server subscribes the items at
//!   the source on its driver thread right after AddItems returns, and the runner's
//!   memory reading after stage 2 came before or after that work by chance (the first
//!   bench runs read +2 MB for the subscription on one database and +19 MB on another).
//! - `--rate MS` (default 1000): the group's requested update rate.
//! - `--ids-from-browse` (the default): the item IDs are the first N leaves of a flat
//!   `BrowseOPCItemIDs` listing that do not start with `_` (repeated if there are fewer);
//!   `--synthetic N`: the names of `asix_model::synthetic` for a database of N variables
//!   (`SC_0000000`…, item `i` is variable `i mod N`), with no browse.
//!
//! Stages, each one line on stdout, then one line read from stdin before the next:
//!
//! 1. `ready connected <ms>`: CoCreateInstance of `ServerCTOPC.App` in the MTA and
//!    SetClientName (the browse of `--ids-from-browse` follows, its time on stderr), then
//!    the warm-up (not with `--no-warm-up`): the calls of the later stages once, with one
//!    item in a group of its own, removed again. Under Wine the server serves a client's
//!    calls through several connections, each with an I/O thread of its own
//!    (`wine_rpcrt4_io`), which keeps about 1 MB resident and stays for the client's
//!    life (they start as the client makes new kinds of calls): a cost per client, which the warm-up pays before the measured stages, so that
//!    they show what the items cost (the runner shows the thread stacks of each stage);
//! 2. `ready added <N> items <ms> ms errors <E>`: AddGroup and AddItems of the N;
//! 3. with `--active`: Advise and SetState(active); `ready subscribed first-callback <ms>
//!    ms values <V>` once the OnDataChange calls since then have covered every item (V: the values they
//!    carried); then on each stdin line `ready tick <callbacks> <values>` (OnDataChange
//!    calls and values since the Advise), until the line `remove`;
//! 4. `ready removed <ms>`: Unadvise, RemoveItems of every handle and RemoveGroup; the next
//!    line ends the process.
//!
//! At any stage, end of input or the line `quit` ends it cleanly (everything released,
//! exit code 0). No stage waits forever: each has a timeout (`--stage-timeout S`, default
//! 600 s, for the server's calls and for the first callbacks; input is awaited at most
//! `--input-timeout S`, default 7200 s) after which it prints `error <stage> <reason>` and
//! exits with code 2; a failed call prints the same with the call's error, code 1.

#[cfg(not(windows))]
fn main() -> std::process::ExitCode {
    eprintln!("scale-client: a Windows program (run it under Wine)");
    std::process::ExitCode::FAILURE
}

#[cfg(windows)]
fn main() -> std::process::ExitCode {
    match scale::Options::parse(std::env::args().skip(1).collect()) {
        Ok(o) => scale::run(&o),
        Err(e) => {
            eprintln!("scale-client: {e}");
            std::process::ExitCode::FAILURE
        }
    }
}

#[cfg(windows)]
mod scale {
    use ctopc_com::apartment::Apartment;
    use ctopc_com::interfaces::*;
    use e2e_tests::PROGID;
    use opc_client::{GroupSpec, GroupStateChange, ItemDef, OpcGroup, Server};
    use std::io::{BufRead, Write};
    use std::process::ExitCode;
    use std::sync::mpsc::{self, Receiver, RecvTimeoutError};
    use std::sync::{Arc, Condvar, Mutex};
    use std::time::{Duration, Instant};
    use windows::core::{implement, HRESULT};
    use windows::Win32::Foundation::FILETIME;
    use windows::Win32::System::Variant::VARIANT;

    pub struct Options {
        items: usize,
        active: bool,
        rate: u32,
        synthetic: Option<usize>,
        warm_up: bool,
        stage_timeout: Duration,
        input_timeout: Duration,
    }

    impl Options {
        pub fn parse(args: Vec<String>) -> Result<Options, String> {
            let mut o = Options {
                items: 1000,
                active: false,
                rate: 1000,
                synthetic: None,
                warm_up: true,
                stage_timeout: Duration::from_secs(600),
                input_timeout: Duration::from_secs(7200),
            };
            let mut it = args.into_iter();
            while let Some(a) = it.next() {
                let mut number = |name: &str| -> Result<u64, String> {
                    let v = it.next().ok_or(format!("{name} needs a value"))?;
                    v.replace([',', '_'], "")
                        .parse()
                        .map_err(|e| format!("{name} {v}: {e}"))
                };
                match a.as_str() {
                    "--items" => o.items = number("--items")? as usize,
                    "--active" => o.active = true,
                    "--no-warm-up" => o.warm_up = false,
                    "--rate" => o.rate = number("--rate")? as u32,
                    "--ids-from-browse" => o.synthetic = None,
                    "--synthetic" => o.synthetic = Some(number("--synthetic")?.max(1) as usize),
                    "--stage-timeout" => {
                        o.stage_timeout = Duration::from_secs(number("--stage-timeout")?)
                    }
                    "--input-timeout" => {
                        o.input_timeout = Duration::from_secs(number("--input-timeout")?)
                    }
                    _ => return Err(format!("unknown argument `{a}` (see the binary's doc)")),
                }
            }
            Ok(o)
        }
    }

    /// How a stage ended other than by going on.
    enum Stop {
        /// End of input or `quit`: release everything, exit 0.
        Quit,
        /// `error <stage> <reason>`, exit 1.
        Failed(&'static str, String),
    }

    /// The stage deadline a watchdog thread enforces: COM calls cannot be given a timeout,
    /// so a hung one ends the process from beside it.
    struct Watchdog {
        stage: Mutex<Option<(&'static str, Instant)>>,
    }

    impl Watchdog {
        fn start() -> Arc<Watchdog> {
            let w = Arc::new(Watchdog {
                stage: Mutex::new(None),
            });
            let watched = Arc::clone(&w);
            std::thread::spawn(move || loop {
                std::thread::sleep(Duration::from_millis(200));
                let due = *watched.stage.lock().unwrap_or_else(|p| p.into_inner());
                if let Some((stage, deadline)) = due {
                    if Instant::now() >= deadline {
                        println!("error {stage} timeout");
                        let _ = std::io::stdout().flush();
                        std::process::exit(2);
                    }
                }
            });
            w
        }
        fn arm(&self, stage: &'static str, limit: Duration) {
            *self.stage.lock().unwrap_or_else(|p| p.into_inner()) =
                Some((stage, Instant::now() + limit));
        }
        fn disarm(&self) {
            *self.stage.lock().unwrap_or_else(|p| p.into_inner()) = None;
        }
    }

    /// The lines of stdin, read on a thread of their own so that waiting for one can time out.
    fn stdin_lines() -> Receiver<String> {
        let (tx, rx) = mpsc::channel();
        std::thread::spawn(move || {
            for line in std::io::stdin().lock().lines() {
                let Ok(line) = line else { break };
                if tx.send(line.trim().to_owned()).is_err() {
                    break;
                }
            }
        });
        rx
    }

    fn ready(line: &str) {
        println!("ready {line}");
        let _ = std::io::stdout().flush();
    }

    fn ms(since: Instant) -> u128 {
        since.elapsed().as_millis()
    }

    struct Input {
        lines: Receiver<String>,
        limit: Duration,
    }

    impl Input {
        /// The next line; `Quit` at end of input or `quit`.
        fn next(&self, stage: &'static str) -> Result<String, Stop> {
            match self.lines.recv_timeout(self.limit) {
                Ok(l) if l == "quit" => Err(Stop::Quit),
                Ok(l) => Ok(l),
                Err(RecvTimeoutError::Disconnected) => Err(Stop::Quit),
                Err(RecvTimeoutError::Timeout) => {
                    Err(Stop::Failed(stage, "no input line in time".into()))
                }
            }
        }
    }

    /// What the sink saw since the Advise: OnDataChange calls, values, and which items
    /// (client handle `i` is item `i`) at least one of them carried.
    #[derive(Default)]
    struct Seen {
        callbacks: u64,
        values: u64,
        covered: Vec<bool>,
        distinct: usize,
    }

    #[derive(Default)]
    struct Coverage {
        seen: Mutex<Seen>,
        cv: Condvar,
    }

    impl Coverage {
        fn new(items: usize) -> Arc<Coverage> {
            let c = Coverage::default();
            c.seen.lock().unwrap_or_else(|p| p.into_inner()).covered = vec![false; items];
            Arc::new(c)
        }
        fn counts(&self) -> (u64, u64) {
            let s = self.seen.lock().unwrap_or_else(|p| p.into_inner());
            (s.callbacks, s.values)
        }
        /// Waits until every item was carried at least once: the values so far.
        fn wait_all(&self, limit: Duration) -> Option<u64> {
            let deadline = Instant::now() + limit;
            let mut s = self.seen.lock().unwrap_or_else(|p| p.into_inner());
            loop {
                if s.distinct == s.covered.len() {
                    return Some(s.values);
                }
                let left = deadline.saturating_duration_since(Instant::now());
                if left.is_zero() {
                    return None;
                }
                s = self
                    .cv
                    .wait_timeout(s, left)
                    .unwrap_or_else(|p| p.into_inner())
                    .0;
            }
        }
    }

    /// The client's IOPCDataCallback: counts, and marks the client handles it is given.
    #[implement(IOPCDataCallback)]
    struct Sink(Arc<Coverage>);

    impl IOPCDataCallback_Impl for Sink_Impl {
        unsafe fn OnDataChange(
            &self,
            transaction: u32,
            _group: u32,
            _master_quality: HRESULT,
            _master_error: HRESULT,
            n: u32,
            h: *const u32,
            _v: *const VARIANT,
            _q: *const u16,
            _t: *const FILETIME,
            _e: *const HRESULT,
        ) -> windows::core::Result<()> {
            if transaction != 0 {
                return Ok(());
            }
            let handles: &[u32] = if h.is_null() || n == 0 {
                &[]
            } else {
                // SAFETY: the stub passes `n`-element arrays, valid for the call.
                unsafe { std::slice::from_raw_parts(h, n as usize) }
            };
            let mut s = self.0.seen.lock().unwrap_or_else(|p| p.into_inner());
            s.callbacks += 1;
            s.values += u64::from(n);
            for &c in handles {
                if let Some(seen) = s.covered.get_mut(c as usize) {
                    if !*seen {
                        *seen = true;
                        s.distinct += 1;
                    }
                }
            }
            drop(s);
            self.0.cv.notify_all();
            Ok(())
        }

        unsafe fn OnReadComplete(
            &self,
            _: u32,
            _: u32,
            _: HRESULT,
            _: HRESULT,
            _: u32,
            _: *const u32,
            _: *const VARIANT,
            _: *const u16,
            _: *const FILETIME,
            _: *const HRESULT,
        ) -> windows::core::Result<()> {
            Ok(())
        }

        unsafe fn OnWriteComplete(
            &self,
            _: u32,
            _: u32,
            _: HRESULT,
            _: u32,
            _: *const u32,
            _: *const HRESULT,
        ) -> windows::core::Result<()> {
            Ok(())
        }

        unsafe fn OnCancelComplete(&self, _: u32, _: u32) -> windows::core::Result<()> {
            Ok(())
        }
    }

    /// The item IDs: the first `n` browsed leaves not starting with `_` (repeated when
    /// there are fewer), or the synthetic database's names.
    fn item_ids(server: &Server, o: &Options) -> Result<Vec<String>, String> {
        if let Some(size) = o.synthetic {
            return Ok((0..o.items)
                .map(|i| asix_model::synthetic::variable_name(i % size))
                .collect());
        }
        let started = Instant::now();
        let mut leaves: Vec<String> = Vec::with_capacity(o.items);
        let _ = server
            .browse_item_ids_each(OPC_FLAT, "", 0, 0, |batch| {
                let room = o.items - leaves.len();
                leaves.extend(batch.into_iter().filter(|s| !s.starts_with('_')).take(room));
            })
            .map_err(|e| format!("BrowseOPCItemIDs: {e}"))?;
        eprintln!(
            "scale-client: browsed {} item IDs in {} ms",
            leaves.len(),
            ms(started)
        );
        if leaves.is_empty() {
            return Err("BrowseOPCItemIDs: no item IDs".into());
        }
        if leaves.len() < o.items {
            eprintln!(
                "scale-client: only {} leaves: repeating them for {} items",
                leaves.len(),
                o.items
            );
        }
        Ok((0..o.items)
            .map(|i| leaves[i % leaves.len()].clone())
            .collect())
    }

    /// What the client holds, released by [`Held::release`] or on drop.
    struct Held {
        server: Server,
        group: Option<(OpcGroup, u32)>,
        handles: Vec<u32>,
        advise: Option<u32>,
    }

    impl Held {
        /// Unadvise, RemoveItems, RemoveGroup.
        fn release(&mut self) -> Result<(), String> {
            let Some((group, handle)) = self.group.take() else {
                return Ok(());
            };
            let handles = std::mem::take(&mut self.handles);
            remove_group(&self.server, group, handle, &handles, self.advise.take())
        }
    }

    /// Unadvise (with a cookie), RemoveItems of `handles` (if any) and RemoveGroup.
    fn remove_group(
        server: &Server,
        group: OpcGroup,
        handle: u32,
        handles: &[u32],
        advise: Option<u32>,
    ) -> Result<(), String> {
        if let Some(cookie) = advise {
            opc_client::unadvise_data_callback(&group.unknown, cookie)
                .map_err(|e| format!("Unadvise: {e}"))?;
        }
        if !handles.is_empty() {
            let _ = group
                .remove_items(handles)
                .map_err(|e| format!("RemoveItems: {e}"))?;
        }
        drop(group);
        let _ = server
            .remove_group(handle, true)
            .map_err(|e| format!("RemoveGroup: {e}"))?;
        Ok(())
    }

    /// The later stages' calls once, with item `id` in a group of its own, removed again
    /// (see the module doc: the connections they open are the client's, not the items').
    fn warm_up(server: &Server, id: &str, o: &Options) -> Result<(), String> {
        let spec = GroupSpec {
            active: false,
            rate_ms: o.rate,
            ..GroupSpec::new("warm-up")
        };
        let g = server
            .add_group(&spec)
            .map_err(|e| format!("warm-up AddGroup: {e}"))?;
        let group = OpcGroup::from_unknown(g.object).map_err(|e| e.to_string())?;
        let (_, added) = group
            .add_items(&[ItemDef::new(id, 0)])
            .map_err(|e| format!("warm-up AddItems: {e}"))?;
        let handles: Vec<u32> = added
            .iter()
            .filter(|a| a.error.is_ok())
            .map(|a| a.server_handle)
            .collect();
        let mut advise = None;
        if o.active {
            let sink: IOPCDataCallback = Sink(Coverage::new(1)).into();
            advise = Some(
                opc_client::advise_data_callback(&group.unknown, &sink)
                    .map_err(|e| format!("warm-up Advise: {e}"))?,
            );
            for active in [true, false] {
                let _ = group
                    .set_state(&GroupStateChange {
                        active: Some(active),
                        ..GroupStateChange::default()
                    })
                    .map_err(|e| format!("warm-up SetState: {e}"))?;
            }
        }
        remove_group(server, group, g.server_handle, &handles, advise)
            .map_err(|e| format!("warm-up {e}"))
    }

    pub fn run(o: &Options) -> ExitCode {
        let watchdog = Watchdog::start();
        let input = Input {
            lines: stdin_lines(),
            limit: o.input_timeout,
        };
        let Ok(_com) = Apartment::mta() else {
            println!("error connected CoInitializeEx failed");
            return ExitCode::FAILURE;
        };
        watchdog.arm("connected", o.stage_timeout);
        let started = Instant::now();
        let server = match Server::connect(PROGID)
            .and_then(|s| s.set_client_name("scale-client").map(|()| s))
        {
            Ok(s) => s,
            Err(e) => {
                println!("error connected {e}");
                return ExitCode::FAILURE;
            }
        };
        let connected = ms(started);
        let mut held = Held {
            server,
            group: None,
            handles: Vec::new(),
            advise: None,
        };
        let r = stages(o, &watchdog, &input, &mut held, connected);
        watchdog.arm("release", o.stage_timeout);
        let released = held.release();
        watchdog.disarm();
        match (r, released) {
            (Ok(()) | Err(Stop::Quit), Ok(())) => ExitCode::SUCCESS,
            (Ok(()) | Err(Stop::Quit), Err(e)) => {
                println!("error release {e}");
                ExitCode::FAILURE
            }
            (Err(Stop::Failed(stage, reason)), _) => {
                println!("error {stage} {reason}");
                ExitCode::FAILURE
            }
        }
    }

    fn stages(
        o: &Options,
        watchdog: &Watchdog,
        input: &Input,
        held: &mut Held,
        connected_ms: u128,
    ) -> Result<(), Stop> {
        let fail = |stage: &'static str| move |e: String| Stop::Failed(stage, e);
        let ids = item_ids(&held.server, o).map_err(fail("connected"))?;
        if let Some(id) = ids.first().filter(|_| o.warm_up) {
            warm_up(&held.server, id, o).map_err(fail("connected"))?;
        }
        watchdog.disarm();
        ready(&format!("connected {connected_ms}"));
        input.next("connected")?;

        watchdog.arm("added", o.stage_timeout);
        let defs: Vec<ItemDef> = ids
            .iter()
            .enumerate()
            .map(|(i, id)| ItemDef::new(id, i as u32))
            .collect();
        drop(ids);
        let started = Instant::now();
        let spec = GroupSpec {
            active: false,
            rate_ms: o.rate,
            ..GroupSpec::new("scale")
        };
        let g = held
            .server
            .add_group(&spec)
            .map_err(|e| format!("AddGroup: {e}"))
            .map_err(fail("added"))?;
        let group = OpcGroup::from_unknown(g.object)
            .map_err(|e| e.to_string())
            .map_err(fail("added"))?;
        let added = group.add_items(&defs).map(|(_, r)| r);
        held.group = Some((group, g.server_handle));
        let added = added
            .map_err(|e| format!("AddItems: {e}"))
            .map_err(fail("added"))?;
        let add_ms = ms(started);
        drop(defs);
        let errors = added.iter().filter(|a| a.error.is_err()).count();
        held.handles = added
            .iter()
            .filter(|a| a.error.is_ok())
            .map(|a| a.server_handle)
            .collect();
        drop(added);
        watchdog.disarm();
        ready(&format!(
            "added {} items {add_ms} ms errors {errors}",
            o.items
        ));
        input.next("added")?;

        if o.active {
            watchdog.arm("subscribed", o.stage_timeout);
            let coverage = Coverage::new(o.items);
            let sink: IOPCDataCallback = Sink(Arc::clone(&coverage)).into();
            let started = Instant::now();
            let Some((group, _)) = held.group.as_ref() else {
                return Err(Stop::Failed("subscribed", "no group".into()));
            };
            let cookie = opc_client::advise_data_callback(&group.unknown, &sink)
                .map_err(|e| format!("Advise: {e}"))
                .map_err(fail("subscribed"))?;
            held.advise = Some(cookie);
            // S_OK, or OPC_S_UNSUPPORTEDRATE with the rate revised: either subscribes.
            let _ = group
                .set_state(&GroupStateChange {
                    active: Some(true),
                    ..GroupStateChange::default()
                })
                .map_err(|e| format!("SetState(active): {e}"))
                .map_err(fail("subscribed"))?;
            // Items whose AddItems failed are never called back: count them as covered.
            if errors > 0 {
                let mut s = coverage.seen.lock().unwrap_or_else(|p| p.into_inner());
                s.distinct += errors;
            }
            let values = coverage.wait_all(o.stage_timeout).ok_or(Stop::Failed(
                "subscribed",
                "the callbacks did not cover every item in time".into(),
            ))?;
            watchdog.disarm();
            ready(&format!(
                "subscribed first-callback {} ms values {values}",
                ms(started)
            ));
            loop {
                let line = input.next("tick")?;
                if line == "remove" {
                    break;
                }
                let (callbacks, values) = coverage.counts();
                ready(&format!("tick {callbacks} {values}"));
            }
        }

        watchdog.arm("removed", o.stage_timeout);
        let started = Instant::now();
        held.release().map_err(fail("removed"))?;
        watchdog.disarm();
        ready(&format!("removed {}", ms(started)));
        input.next("removed")?;
        Ok(())
    }
}
