//! The gate's engine: one worker thread per served channel owning its
//! [`XConnectChannel`], a bounded command queue to it, the channel's image of subscribed
//! items (filled by DataChange), and a watchdog that turns a hung call into BAD quality
//! and a failed source.
//!
//! - Subscriptions are counted per item: the first one sends `SetItemActive True`, the last
//!   one's end `SetItemActive False`. The worker sets `Active = True` once the object is
//!   open.
//! - A request (read, write) waits at most the call timeout for its worker; a full queue
//!   (the worker is stuck) answers at once. Either way the client gets BAD quality (reads)
//!   or `ASKOM_E_WriteError_DriverTimeout` (writes), and the log says so.
//! - A call running longer than the call timeout marks its channel stalled: its items go
//!   BAD Comm Failure and the server is announced SOURCE_FAILED, until the call returns
//!   (the worker then reads the active items again).

use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, AtomicI32, AtomicU64, Ordering};
use std::sync::mpsc::{sync_channel, Receiver, RecvTimeoutError, SyncSender, TrySendError};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use asix_net::client::wall_now;
use ctopc_core::{OpcError, Quality, Timestamp, Value, Vqt};
use tokio::sync::{oneshot, watch};
use tracing::{debug, info, warn};

use crate::channel::{
    CallError, ChannelFactory, DataChange, DataSource, ItemValue, ServerState, XConnectChannel,
};
use crate::config::{ChannelConfig, GateConfig, Open};
use crate::tz::ZoneRule;

/// Commands queued to a worker at most.
pub const QUEUE: usize = 64;
/// The longest a worker waits for events before looking at its queue.
const PUMP_SLICE: Duration = Duration::from_millis(10);

/// A subscribed item's latest VQT; `version` grows with every change.
#[derive(Debug, Clone)]
pub struct Entry {
    pub vqt: Vqt,
    pub version: u32,
    subscribers: u32,
    /// The name as first subscribed (passed to the Automation server).
    name: String,
}

/// An item to write: its name, the value, and for `WriteEx` the quality and UTC time.
pub type WriteItem = (String, Value, Option<(Quality, Timestamp)>);

type Reply<T> = oneshot::Sender<Vec<Result<T, CallError>>>;

enum Command {
    Activate(String, bool),
    Read(DataSource, Vec<String>, Reply<ItemValue>),
    Write(Vec<(String, Value)>, Reply<()>),
    WriteEx(Vec<(String, Value, u16, f64)>, Reply<()>),
    Refresh,
}

/// One served channel as the network side sees it.
pub struct Channel {
    pub config: ChannelConfig,
    image: Mutex<HashMap<String, Entry>>,
    queue: SyncSender<Command>,
    /// Milliseconds since the engine's start when the running call began; 0: idle.
    busy_since: AtomicU64,
    busy_member: Mutex<&'static str>,
    /// The last `ServerState` (0: not open).
    state: AtomicI32,
    stalled: AtomicBool,
}

/// The engine: every channel, the zone, the status signal.
pub struct Engine {
    pub channels: Vec<Arc<Channel>>,
    zone: ZoneRule,
    call_timeout: Duration,
    start: Instant,
    /// Bumped whenever the source state (SOURCE_FAILED) may have changed.
    pub status: watch::Sender<u64>,
    shutdown: Arc<AtomicBool>,
}

fn key(item: &str) -> String {
    item.to_ascii_uppercase()
}

impl Channel {
    fn lock(&self) -> MutexGuard<'_, HashMap<String, Entry>> {
        self.image.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The entry of a subscribed item.
    pub fn entry(&self, item: &str) -> Option<(Vqt, u32)> {
        self.lock()
            .get(&key(item))
            .map(|e| (e.vqt.clone(), e.version))
    }

    /// Does the channel serve data now (open, state running or test, no hung call)?
    pub fn serves(&self) -> bool {
        let s = self.state.load(Ordering::SeqCst);
        s != 0 && ServerState::from_i32(s).serves() && !self.stalled.load(Ordering::SeqCst)
    }

    fn send(&self, c: Command) -> bool {
        match self.queue.try_send(c) {
            Ok(()) => true,
            Err(TrySendError::Full(_)) => {
                warn!(channel = %self.config.name, "the channel's Automation calls are stuck: request refused (queue full)");
                false
            }
            Err(TrySendError::Disconnected(_)) => false,
        }
    }

    fn mark_all(&self, q: Quality) {
        for e in self.lock().values_mut() {
            e.vqt.quality = q;
            e.version = e.version.wrapping_add(1);
        }
    }
}

impl Engine {
    /// Starts a worker per channel of `cfg`, each making its object with `factory`, and the
    /// watchdog (on the current tokio runtime).
    pub fn start(cfg: &GateConfig, factory: ChannelFactory) -> Arc<Engine> {
        let start = Instant::now();
        let status = watch::channel(0).0;
        let shutdown = Arc::new(AtomicBool::new(false));
        let mut channels = Vec::new();
        let mut receivers = Vec::new();
        for c in &cfg.channels {
            let (tx, rx) = sync_channel(QUEUE);
            channels.push(Arc::new(Channel {
                config: c.clone(),
                image: Mutex::new(HashMap::new()),
                queue: tx,
                busy_since: AtomicU64::new(0),
                busy_member: Mutex::new(""),
                state: AtomicI32::new(0),
                stalled: AtomicBool::new(false),
            }));
            receivers.push(rx);
        }
        let engine = Arc::new(Engine {
            channels,
            zone: cfg.time_zone,
            call_timeout: cfg.call_timeout,
            start,
            status,
            shutdown,
        });
        for (ch, rx) in engine.channels.iter().zip(receivers) {
            let w = Worker {
                engine: Arc::downgrade(&engine),
                channel: ch.clone(),
                rx,
                factory: factory.clone(),
                state_poll: cfg.state_poll,
                shutdown: engine.shutdown.clone(),
                start,
                open_error: Default::default(),
            };
            let name = format!("gate-{}", ch.config.name);
            if let Err(e) = std::thread::Builder::new()
                .name(name)
                .spawn(move || w.run())
            {
                warn!(channel = %ch.config.name, error = %e, "no worker thread");
            }
        }
        tokio::spawn(watchdog(Arc::downgrade(&engine)));
        engine
    }

    /// Stops the workers (each after its current call).
    pub fn stop(&self) {
        self.shutdown.store(true, Ordering::SeqCst);
    }

    pub fn call_timeout(&self) -> Duration {
        self.call_timeout
    }

    /// The channel clients name (ASCII case-insensitive).
    pub fn channel(&self, name: &str) -> Option<&Arc<Channel>> {
        self.channels
            .iter()
            .find(|c| c.config.name.eq_ignore_ascii_case(name))
    }

    /// Announced as SOURCE_FAILED: some channel does not serve.
    pub fn source_failed(&self) -> bool {
        self.channels.iter().any(|c| !c.serves())
    }

    fn now_ms(&self) -> u64 {
        self.start.elapsed().as_millis() as u64 + 1
    }

    /// One subscription more of `item`: the first activates it.
    pub fn subscribe(&self, ch: &Channel, item: &str) {
        let first = {
            let mut img = ch.lock();
            let e = img.entry(key(item)).or_insert_with(|| Entry {
                vqt: Vqt::new(
                    Value::Empty,
                    Quality::BAD_WAITING_FOR_INITIAL_DATA,
                    wall_now(),
                ),
                version: 1,
                subscribers: 0,
                name: item.to_owned(),
            });
            e.subscribers += 1;
            e.subscribers == 1
        };
        if first && !ch.send(Command::Activate(item.to_owned(), true)) {
            if let Some(e) = ch.lock().get_mut(&key(item)) {
                e.vqt.quality = Quality::BAD_COMM_FAILURE;
                e.version = e.version.wrapping_add(1);
            }
        }
    }

    /// One subscription less of `item`: the last deactivates it.
    pub fn unsubscribe(&self, ch: &Channel, item: &str) {
        let last = {
            let mut img = ch.lock();
            let Some(e) = img.get_mut(&key(item)) else {
                return;
            };
            e.subscribers = e.subscribers.saturating_sub(1);
            let last = e.subscribers == 0;
            if last {
                img.remove(&key(item));
            }
            last
        };
        if last {
            ch.send(Command::Activate(item.to_owned(), false));
        }
    }

    async fn ask<T>(
        &self,
        ch: &Channel,
        make: impl FnOnce(Reply<T>) -> Command,
        what: &str,
    ) -> Option<Vec<Result<T, CallError>>> {
        let (tx, rx) = oneshot::channel();
        if !ch.send(make(tx)) {
            return None;
        }
        match tokio::time::timeout(self.call_timeout, rx).await {
            Ok(Ok(r)) => Some(r),
            Ok(Err(_)) => None,
            Err(_) => {
                warn!(channel = %ch.config.name, timeout_ms = self.call_timeout.as_millis() as u64, "{what}: no answer from the Automation server in time");
                None
            }
        }
    }

    /// Reads items from `source`; a call that fails, times out or cannot be queued gives
    /// BAD quality (Comm Failure), an unknown item its error.
    pub async fn read(
        &self,
        ch: &Channel,
        source: DataSource,
        items: Vec<String>,
    ) -> Vec<Result<Vqt, OpcError>> {
        let n = items.len();
        let hint = wall_now();
        let bad = || {
            Ok(Vqt::new(
                Value::Empty,
                Quality::BAD_COMM_FAILURE,
                wall_now(),
            ))
        };
        match self
            .ask(ch, |r| Command::Read(source, items, r), "Read")
            .await
        {
            Some(results) => results
                .into_iter()
                .map(|r| match r {
                    Ok(v) => Ok(self.vqt(v, hint)),
                    Err(e) if e.hresult == OpcError::ItemUnknown.hresult() => {
                        Err(OpcError::ItemUnknown)
                    }
                    Err(e) => {
                        debug!(channel = %ch.config.name, error = %e, "Read failed");
                        bad()
                    }
                })
                .collect(),
            None => (0..n).map(|_| bad()).collect(),
        }
    }

    /// Writes (`Write`), or with quality and time (`WriteEx`, time given in UTC); one
    /// result per item.
    pub async fn write(&self, ch: &Channel, items: Vec<WriteItem>) -> Vec<Result<(), i32>> {
        let n = items.len();
        let extended = items.iter().any(|i| i.2.is_some());
        let answer = if extended {
            let zone = self.zone;
            let items = items
                .into_iter()
                .map(|(i, v, x)| {
                    let (q, t) = x.unwrap_or((Quality::GOOD, wall_now()));
                    (i, v, q.0, zone.utc_to_ole_local(t))
                })
                .collect();
            self.ask(ch, |r| Command::WriteEx(items, r), "WriteEx")
                .await
        } else {
            let items = items.into_iter().map(|(i, v, _)| (i, v)).collect();
            self.ask(ch, |r| Command::Write(items, r), "Write").await
        };
        match answer {
            Some(r) => r.into_iter().map(|r| r.map_err(|e| e.hresult)).collect(),
            None => vec![Err(OpcError::WriteErrorDriverTimeout.hresult()); n],
        }
    }

    fn vqt(&self, v: ItemValue, hint: Timestamp) -> Vqt {
        let t = v
            .local_time
            .and_then(|d| self.zone.ole_local_to_utc(d, Some(hint)))
            .unwrap_or(hint);
        Vqt::new(v.value, Quality(v.quality), t)
    }

    fn on_change(&self, ch: &Channel, c: DataChange) {
        let vqt = self.vqt(c.value, wall_now());
        if let Some(e) = ch.lock().get_mut(&key(&c.item)) {
            e.vqt = vqt;
            e.version = e.version.wrapping_add(1);
        }
    }

    fn bump(&self) {
        self.status.send_modify(|v| *v += 1);
    }
}

/// Marks channels whose call runs past the timeout as stalled, and back.
async fn watchdog(engine: std::sync::Weak<Engine>) {
    loop {
        let Some(e) = engine.upgrade() else { return };
        if e.shutdown.load(Ordering::SeqCst) {
            return;
        }
        let period = (e.call_timeout / 4).max(Duration::from_millis(5));
        let now = e.now_ms();
        for ch in &e.channels {
            let since = ch.busy_since.load(Ordering::SeqCst);
            let hung = since != 0 && now.saturating_sub(since) > e.call_timeout.as_millis() as u64;
            if hung && !ch.stalled.swap(true, Ordering::SeqCst) {
                let member = *ch.busy_member.lock().unwrap_or_else(|p| p.into_inner());
                warn!(channel = %ch.config.name, member, timeout_ms = e.call_timeout.as_millis() as u64, "Automation call hung: the channel's items go BAD and the source is announced failed");
                ch.mark_all(Quality::BAD_COMM_FAILURE);
                e.bump();
            } else if !hung && since == 0 && ch.stalled.swap(false, Ordering::SeqCst) {
                info!(channel = %ch.config.name, "Automation call returned: the channel serves again");
                ch.send(Command::Refresh);
                e.bump();
            }
        }
        drop(e);
        tokio::time::sleep(period).await;
    }
}

struct Worker {
    engine: std::sync::Weak<Engine>,
    channel: Arc<Channel>,
    rx: Receiver<Command>,
    factory: ChannelFactory,
    state_poll: Duration,
    shutdown: Arc<AtomicBool>,
    start: Instant,
    /// The last reason the object could not be opened (logged once, not every retry).
    open_error: std::cell::RefCell<Option<String>>,
}

impl Worker {
    fn stopping(&self) -> bool {
        self.shutdown.load(Ordering::SeqCst) || self.engine.strong_count() == 0
    }

    /// Runs one Automation call, visible to the watchdog while it runs.
    fn call<T>(&self, member: &'static str, f: impl FnOnce() -> T) -> T {
        *self
            .channel
            .busy_member
            .lock()
            .unwrap_or_else(|p| p.into_inner()) = member;
        self.channel.busy_since.store(
            self.start.elapsed().as_millis() as u64 + 1,
            Ordering::SeqCst,
        );
        let r = f();
        self.channel.busy_since.store(0, Ordering::SeqCst);
        r
    }

    fn set_state(&self, s: i32) {
        if self.channel.state.swap(s, Ordering::SeqCst) != s {
            match ServerState::from_i32(s) {
                st if st.serves() => {
                    info!(channel = %self.channel.config.name, state = ?st, "channel serves")
                }
                st => {
                    warn!(channel = %self.channel.config.name, state = ?st, "channel does not serve: announced SOURCE_FAILED")
                }
            }
            if let Some(e) = self.engine.upgrade() {
                e.bump();
            }
        }
    }

    /// Logs why opening failed, once per distinct reason.
    fn open_failed(&self, what: &str, e: &CallError) {
        let text = format!("{what}: {e}");
        if self.open_error.borrow().as_deref() != Some(text.as_str()) {
            warn!(channel = %self.channel.config.name, error = %e, "{what}; tried again every {} ms", self.state_poll.as_millis());
            *self.open_error.borrow_mut() = Some(text);
        }
    }

    fn open(&self) -> Option<Box<dyn XConnectChannel>> {
        let name = &self.channel.config.name;
        let mut obj = match self.call("create", || (self.factory)(name)) {
            Ok(o) => o,
            Err(e) => {
                self.open_failed("cannot create XConnect.ServerCT", &e);
                return None;
            }
        };
        let r = match &self.channel.config.open {
            Open::LoadChannel(c) => self.call("LoadChannel", || obj.load_channel(c)),
            Open::Init(s) => self.call("Init", || obj.init(s)),
        };
        if let Err(e) = r.and_then(|()| self.call("Active", || obj.set_active(true))) {
            self.open_failed("cannot open the channel", &e);
            return None;
        }
        *self.open_error.borrow_mut() = None;
        info!(channel = %name, "channel open");
        Some(obj)
    }

    fn run(self) {
        let mut obj = None;
        let mut next_poll = Instant::now();
        while !self.stopping() {
            let Some(o) = obj.as_mut() else {
                // Not open: (re)try each poll period, refusing requests meanwhile.
                if Instant::now() >= next_poll {
                    next_poll = Instant::now() + self.state_poll;
                    obj = self.open();
                    match obj.as_mut() {
                        Some(o) => {
                            self.activate_all(o.as_mut());
                            next_poll = Instant::now();
                        }
                        None => self.set_state(2),
                    }
                    continue;
                }
                match self.rx.recv_timeout(PUMP_SLICE) {
                    Ok(c) => self.refuse(c),
                    Err(RecvTimeoutError::Disconnected) => return,
                    Err(RecvTimeoutError::Timeout) => {}
                }
                continue;
            };
            let o = o.as_mut();
            loop {
                match self.rx.try_recv() {
                    Ok(c) => self.handle(o, c),
                    Err(std::sync::mpsc::TryRecvError::Empty) => break,
                    Err(std::sync::mpsc::TryRecvError::Disconnected) => return,
                }
            }
            if Instant::now() >= next_poll {
                next_poll = Instant::now() + self.state_poll;
                match self.call("ServerState", || o.server_state()) {
                    Ok(s) => self.set_state(match s {
                        ServerState::Running => 1,
                        ServerState::Failed => 2,
                        ServerState::NoConfig => 3,
                        ServerState::Suspended => 4,
                        ServerState::Test => 5,
                        ServerState::Other(x) => x,
                    }),
                    Err(e) => {
                        warn!(channel = %self.channel.config.name, error = %e, "ServerState failed");
                        self.set_state(2);
                    }
                }
            }
            let Some(engine) = self.engine.upgrade() else {
                return;
            };
            let ch = &self.channel;
            o.pump(PUMP_SLICE, &mut |c| engine.on_change(ch, c));
        }
    }

    /// Activates every subscribed item (after opening, after a stall).
    fn activate_all(&self, o: &mut dyn XConnectChannel) {
        let names: Vec<String> = self
            .channel
            .lock()
            .values()
            .map(|e| e.name.clone())
            .collect();
        for n in names {
            self.activate(o, &n, true);
        }
    }

    fn activate(&self, o: &mut dyn XConnectChannel, item: &str, on: bool) {
        let r = self.call("SetItemActive", || o.set_item_active(item, on));
        if !on {
            return;
        }
        let q = match r {
            Ok(()) => match self.call("Read", || o.read(DataSource::Cache, item)) {
                Ok(v) => {
                    if let Some(e) = self.engine.upgrade() {
                        e.on_change(
                            &self.channel,
                            DataChange {
                                item: item.to_owned(),
                                value: v,
                            },
                        );
                    }
                    return;
                }
                // The first DataChange will bring the value.
                Err(_) => return,
            },
            Err(e) => {
                warn!(channel = %self.channel.config.name, item, error = %e, "SetItemActive failed");
                Quality::BAD_CONFIG_ERROR
            }
        };
        if let Some(e) = self.channel.lock().get_mut(&key(item)) {
            e.vqt.quality = q;
            e.version = e.version.wrapping_add(1);
        }
    }

    fn refuse(&self, c: Command) {
        let down = || CallError::new(OpcError::NetLinkToServer, "the channel is not open");
        match c {
            Command::Activate(..) | Command::Refresh => {}
            Command::Read(_, items, r) => {
                let _ = r.send(items.iter().map(|_| Err(down())).collect());
            }
            Command::Write(items, r) => {
                let _ = r.send(items.iter().map(|_| Err(down())).collect());
            }
            Command::WriteEx(items, r) => {
                let _ = r.send(items.iter().map(|_| Err(down())).collect());
            }
        }
    }

    fn handle(&self, o: &mut dyn XConnectChannel, c: Command) {
        match c {
            Command::Activate(item, on) => self.activate(o, &item, on),
            Command::Refresh => self.activate_all(o),
            Command::Read(source, items, r) => {
                let res = items
                    .iter()
                    .map(|i| self.call("Read", || o.read(source, i)))
                    .collect();
                let _ = r.send(res);
            }
            Command::Write(items, r) => {
                let res = items
                    .iter()
                    .map(|(i, v)| self.call("Write", || o.write(i, v)))
                    .collect();
                let _ = r.send(res);
            }
            Command::WriteEx(items, r) => {
                let res = items
                    .iter()
                    .map(|(i, v, q, t)| self.call("WriteEx", || o.write_ex(i, v, *q, *t)))
                    .collect();
                let _ = r.send(res);
            }
        }
    }
}
