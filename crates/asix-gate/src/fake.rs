//! A scriptable [`XConnectChannel`] for tests: a small plant of named items behind the
//! Automation server's members, with switches to make any member fail or hang and to
//! report each `ServerState`. Never shipped as a data source: the binary does not use it.

use std::collections::{HashMap, HashSet};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::time::Duration;

use ctopc_core::{OpcError, Value};

use crate::channel::{
    CallError, ChannelFactory, DataChange, DataSource, ItemValue, ServerState, XConnectChannel,
};

/// The members a switch can name.
pub const MEMBERS: [&str; 9] = [
    "LoadChannel",
    "Init",
    "Read",
    "SetItemActive",
    "Write",
    "WriteEx",
    "Active",
    "ServerState",
    "StartTime",
];

#[derive(Default)]
struct State {
    items: HashMap<String, ItemValue>,
    read_only: HashSet<String>,
    active_items: HashSet<String>,
    active: bool,
    events: Vec<DataChange>,
    state: Option<ServerState>,
    failing: HashMap<&'static str, CallError>,
    hanging: HashSet<&'static str>,
    /// Calls, as `Member arg…` lines.
    calls: Vec<String>,
    /// The local VT_DATE that `Write` stamps.
    clock: f64,
    opened: Option<String>,
}

/// The plant and the switches, shared by the test and the channel objects.
#[derive(Clone, Default)]
pub struct FakePlant {
    inner: Arc<(Mutex<State>, Condvar)>,
}

fn key(item: &str) -> String {
    item.to_ascii_uppercase()
}

fn member(name: &str) -> &'static str {
    MEMBERS
        .iter()
        .find(|m| m.eq_ignore_ascii_case(name))
        .copied()
        .unwrap_or("?")
}

impl FakePlant {
    /// A plant with the given items (good quality, value 0, writable), running.
    pub fn new(items: &[&str]) -> FakePlant {
        let p = FakePlant::default();
        {
            let mut s = p.lock();
            s.state = Some(ServerState::Running);
            s.clock = 46_000.5;
            for i in items {
                s.items.insert(
                    key(i),
                    ItemValue {
                        value: Value::R8(0.0),
                        quality: 0xC0,
                        local_time: Some(46_000.5),
                    },
                );
            }
        }
        p
    }

    fn lock(&self) -> MutexGuard<'_, State> {
        self.inner.0.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// A factory of channel objects over this plant.
    pub fn factory(&self) -> ChannelFactory {
        let p = self.clone();
        Arc::new(move |_name: &str| Ok(Box::new(FakeChannel { plant: p.clone() }) as _))
    }

    /// The process changes an item: a DataChange follows if the item is active and the
    /// object's `Active` is True.
    pub fn set(&self, item: &str, value: Value, quality: u16, local_time: Option<f64>) {
        let v = ItemValue {
            value,
            quality,
            local_time,
        };
        let mut s = self.lock();
        s.items.insert(key(item), v.clone());
        if s.active && s.active_items.contains(&key(item)) {
            s.events.push(DataChange {
                item: item.to_owned(),
                value: v,
            });
        }
        drop(s);
        self.inner.1.notify_all();
    }

    /// The item's current value.
    pub fn value(&self, item: &str) -> Option<ItemValue> {
        self.lock().items.get(&key(item)).cloned()
    }

    pub fn set_read_only(&self, item: &str) {
        self.lock().read_only.insert(key(item));
    }

    /// The local VT_DATE `Write` stamps.
    pub fn set_clock(&self, local: f64) {
        self.lock().clock = local;
    }

    /// `member` fails with this error from now on (`None`: works again).
    pub fn fail(&self, member_name: &str, error: Option<CallError>) {
        let m = member(member_name);
        let mut s = self.lock();
        match error {
            Some(e) => s.failing.insert(m, e),
            None => s.failing.remove(m),
        };
    }

    /// `member` blocks from its next call until released (`false`).
    pub fn hang(&self, member_name: &str, on: bool) {
        let m = member(member_name);
        {
            let mut s = self.lock();
            if on {
                s.hanging.insert(m);
            } else {
                s.hanging.remove(m);
            }
        }
        self.inner.1.notify_all();
    }

    /// What `ServerState` reports.
    pub fn set_state(&self, state: ServerState) {
        self.lock().state = Some(state);
    }

    /// Is the item in the refreshed set?
    pub fn is_item_active(&self, item: &str) -> bool {
        self.lock().active_items.contains(&key(item))
    }

    /// The object's `Active`.
    pub fn is_active(&self) -> bool {
        self.lock().active
    }

    /// How the object was initialised (`LoadChannel X` or `Init X`).
    pub fn opened(&self) -> Option<String> {
        self.lock().opened.clone()
    }

    /// Every call so far, as `Member args` lines.
    pub fn calls(&self) -> Vec<String> {
        self.lock().calls.clone()
    }

    /// Records the call, waits while the member hangs, then fails if switched so.
    fn enter(&self, name: &'static str, args: String) -> Result<MutexGuard<'_, State>, CallError> {
        let mut s = self.lock();
        s.calls.push(format!("{name} {args}").trim_end().to_owned());
        while s.hanging.contains(name) {
            s = self.inner.1.wait(s).unwrap_or_else(|e| e.into_inner());
        }
        match s.failing.get(name) {
            Some(e) => Err(e.clone()),
            None => Ok(s),
        }
    }
}

/// One object over a [`FakePlant`].
pub struct FakeChannel {
    plant: FakePlant,
}

fn unknown(item: &str) -> CallError {
    CallError::new(OpcError::ItemUnknown, format!("unknown variable {item}"))
}

impl XConnectChannel for FakeChannel {
    fn load_channel(&mut self, name: &str) -> Result<(), CallError> {
        let mut s = self.plant.enter("LoadChannel", name.to_owned())?;
        s.opened = Some(format!("LoadChannel {name}"));
        Ok(())
    }

    fn init(&mut self, init: &str) -> Result<(), CallError> {
        let mut s = self.plant.enter("Init", init.to_owned())?;
        s.opened = Some(format!("Init {init}"));
        Ok(())
    }

    fn read(&mut self, source: DataSource, item: &str) -> Result<ItemValue, CallError> {
        let s = self
            .plant
            .enter("Read", format!("{} {item}", source as i32))?;
        if source == DataSource::Cache && !s.active_items.contains(&key(item)) {
            return Err(CallError::new(OpcError::Fail, "item not active"));
        }
        s.items
            .get(&key(item))
            .cloned()
            .ok_or_else(|| unknown(item))
    }

    fn set_item_active(&mut self, item: &str, active: bool) -> Result<(), CallError> {
        let mut s = self
            .plant
            .enter("SetItemActive", format!("{item} {active}"))?;
        if !s.items.contains_key(&key(item)) {
            return Err(unknown(item));
        }
        if active {
            s.active_items.insert(key(item));
        } else {
            s.active_items.remove(&key(item));
        }
        Ok(())
    }

    fn write(&mut self, item: &str, value: &Value) -> Result<(), CallError> {
        let s = self.plant.enter("Write", format!("{item} {value:?}"))?;
        if !s.items.contains_key(&key(item)) {
            return Err(unknown(item));
        }
        if s.read_only.contains(&key(item)) {
            return Err(CallError::new(
                OpcError::WriteErrorDeviceRequestIllegal,
                "read-only",
            ));
        }
        let clock = s.clock;
        drop(s);
        self.plant.set(item, value.clone(), 0xC0, Some(clock));
        Ok(())
    }

    fn write_ex(
        &mut self,
        item: &str,
        value: &Value,
        quality: u16,
        local_time: f64,
    ) -> Result<(), CallError> {
        let s = self.plant.enter(
            "WriteEx",
            format!("{item} {value:?} {quality:#06x} {local_time}"),
        )?;
        if !s.items.contains_key(&key(item)) {
            return Err(unknown(item));
        }
        drop(s);
        self.plant
            .set(item, value.clone(), quality, Some(local_time));
        Ok(())
    }

    fn set_active(&mut self, active: bool) -> Result<(), CallError> {
        let mut s = self.plant.enter("Active", active.to_string())?;
        s.active = active;
        Ok(())
    }

    fn server_state(&mut self) -> Result<ServerState, CallError> {
        let s = self.plant.enter("ServerState", String::new())?;
        Ok(s.state.unwrap_or(ServerState::Running))
    }

    fn start_time(&mut self) -> Result<f64, CallError> {
        let s = self.plant.enter("StartTime", String::new())?;
        Ok(s.clock)
    }

    fn pump(&mut self, wait: Duration, events: &mut dyn FnMut(DataChange)) {
        let mut s = self.plant.lock();
        if s.events.is_empty() {
            s = self
                .plant
                .inner
                .1
                .wait_timeout(s, wait)
                .map(|(g, _)| g)
                .unwrap_or_else(|e| e.into_inner().0);
        }
        let batch = std::mem::take(&mut s.events);
        drop(s);
        for e in batch {
            events(e);
        }
    }
}
