//! The [`XConnectChannel`] of the real Automation server: an `XConnect.ServerCT` object
//! made by ProgID and driven late-bound, by member names (digest §11), through the COM
//! crate's safe client ([`ctopc_com::automation`]).
//!
//! [`factory`] runs on the channel's worker thread: it makes that thread a
//! single-threaded apartment ([`Apartment::sta`], uninitialised when the channel is
//! dropped), creates the object in process and connects a sink to its events. The sink
//! queues each `DataChange` (at most [`EVENT_QUEUE`]; the oldest are dropped beyond) and
//! [`XConnectChannel::pump`] pumps the thread's messages, which is when an
//! apartment-threaded object delivers them, then hands the queue out.
//!
//! Conversions: values cross as the VARIANT's content ([`Value`]); the quality as the
//! integer VARIANT it comes in (`VT_I2`, `VT_I4`, …) truncated to its 16 bits; times as
//! `VT_DATE` (local time). A failed call is a [`CallError`] with the server's code
//! (`EXCEPINFO::scode` for `DISP_E_EXCEPTION`, an `ASKOM_E_*` code as it is) and text.

use std::collections::VecDeque;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;

use ctopc_com::apartment::Apartment;
use ctopc_com::automation::{self, pump_messages_until, Arg, Event, EventConnection, Object};
use ctopc_core::{OpcError, Value};
use tracing::warn;

use crate::channel::{
    CallError, ChannelFactory, DataChange, DataSource, ItemValue, ServerState, XConnectChannel,
};

/// The ProgID of AsixConnect's Automation server.
pub const PROGID: &str = "XConnect.ServerCT";
/// `DataChange` events queued between two pumps at most.
pub const EVENT_QUEUE: usize = 10_000;

type Queue = Arc<Mutex<VecDeque<DataChange>>>;

fn lock(q: &Queue) -> MutexGuard<'_, VecDeque<DataChange>> {
    q.lock().unwrap_or_else(|e| e.into_inner())
}

/// One `XConnect.ServerCT` object of the worker thread that made it.
///
/// Dropped in field order: the event connection (`Unadvise`), the object, then the
/// thread's apartment.
pub struct AutomationChannel {
    _events: EventConnection,
    object: Object,
    queue: Queue,
    _apartment: Apartment,
}

/// Makes the channel's objects with [`AutomationChannel::create`].
pub fn factory() -> ChannelFactory {
    Arc::new(|name: &str| {
        AutomationChannel::create(PROGID)
            .map(|c| Box::new(c) as Box<dyn XConnectChannel>)
            .map_err(|e| CallError {
                hresult: e.hresult,
                text: format!("channel {name}: {}", e.text),
            })
    })
}

fn call_error(e: automation::Error) -> CallError {
    let text = if e.description.is_empty() {
        e.to_string()
    } else {
        format!("{}: {}", e.member, e.description)
    };
    CallError {
        hresult: e.code,
        text,
    }
}

fn mismatch(what: &str, v: &Value) -> CallError {
    CallError::new(
        OpcError::BadType,
        format!("{what}: unexpected VARIANT {v:?}"),
    )
}

/// The 16-bit OPC quality from the integer VARIANT the server gives.
fn quality(v: &Value) -> Result<u16, CallError> {
    Ok(match *v {
        Value::I2(q) => q as u16,
        Value::UI2(q) => q,
        Value::I4(q) => q as u16,
        Value::UI4(q) => q as u16,
        Value::UI1(q) => u16::from(q),
        Value::I1(q) => q as u16,
        Value::I8(q) => q as u16,
        Value::UI8(q) => q as u16,
        _ => return Err(mismatch("quality", v)),
    })
}

/// A VT_DATE (`None` when the server left it empty).
fn local_time(v: &Value) -> Result<Option<f64>, CallError> {
    match *v {
        Value::Date(d) => Ok(Some(d)),
        Value::Empty => Ok(None),
        Value::R8(d) => Ok(Some(d)),
        _ => Err(mismatch("time stamp", v)),
    }
}

/// A `DataChange ItemID, Value, Quality, TimeStamp` event.
fn data_change(e: &Event) -> Result<DataChange, String> {
    let [item, value, q, t] = e.args.as_slice() else {
        return Err(format!("{} arguments, 4 expected", e.args.len()));
    };
    let Value::Bstr(item) = item else {
        return Err(format!("ItemID {item:?}"));
    };
    Ok(DataChange {
        item: item.clone(),
        value: ItemValue {
            value: value.clone(),
            quality: quality(q).map_err(|e| e.text)?,
            local_time: local_time(t).map_err(|e| e.text)?,
        },
    })
}

impl AutomationChannel {
    /// Makes this thread a single-threaded apartment, the object `progid` in it, and
    /// connects to its events.
    pub fn create(progid: &str) -> Result<AutomationChannel, CallError> {
        let apartment = Apartment::sta().map_err(|e| CallError {
            hresult: e.code().0,
            text: format!("CoInitializeEx: {}", e.message()),
        })?;
        let object = Object::create(progid).map_err(call_error)?;
        let queue: Queue = Arc::default();
        let sink = Arc::clone(&queue);
        let events = object
            .advise_events(move |e| {
                if !e.name.eq_ignore_ascii_case("DataChange") {
                    return;
                }
                match data_change(e) {
                    Ok(change) => {
                        let mut q = lock(&sink);
                        if q.len() >= EVENT_QUEUE {
                            q.pop_front();
                            warn!("XConnect.ServerCT: DataChange queue full, the oldest event dropped");
                        }
                        q.push_back(change);
                    }
                    Err(why) => warn!("XConnect.ServerCT: DataChange ignored: {why}"),
                }
            })
            .map_err(call_error)?;
        Ok(AutomationChannel {
            _events: events,
            object,
            queue,
            _apartment: apartment,
        })
    }

    fn call(&self, member: &str, args: &[Value]) -> Result<Value, CallError> {
        self.object.call(member, args).map_err(call_error)
    }

    fn get(&self, member: &str) -> Result<Value, CallError> {
        self.object.get(member).map_err(call_error)
    }
}

fn bstr(s: &str) -> Value {
    Value::Bstr(s.to_owned())
}

impl XConnectChannel for AutomationChannel {
    fn load_channel(&mut self, name: &str) -> Result<(), CallError> {
        self.call("LoadChannel", &[bstr(name)]).map(drop)
    }

    fn init(&mut self, init: &str) -> Result<(), CallError> {
        self.call("Init", &[bstr(init)]).map(drop)
    }

    fn read(&mut self, source: DataSource, item: &str) -> Result<ItemValue, CallError> {
        let mut args = [
            Arg::In(Value::I4(source as i32)),
            Arg::In(bstr(item)),
            Arg::InOut(Value::Empty),
            Arg::InOut(Value::Empty),
            Arg::InOut(Value::Empty),
        ];
        self.object.invoke("Read", &mut args).map_err(call_error)?;
        Ok(ItemValue {
            value: args[2].value().clone(),
            quality: quality(args[3].value())?,
            local_time: local_time(args[4].value())?,
        })
    }

    fn set_item_active(&mut self, item: &str, active: bool) -> Result<(), CallError> {
        self.call("SetItemActive", &[bstr(item), Value::Bool(active)])
            .map(drop)
    }

    fn write(&mut self, item: &str, value: &Value) -> Result<(), CallError> {
        self.call("Write", &[bstr(item), value.clone()]).map(drop)
    }

    fn write_ex(
        &mut self,
        item: &str,
        value: &Value,
        quality: u16,
        local_time: f64,
    ) -> Result<(), CallError> {
        self.call(
            "WriteEx",
            &[
                bstr(item),
                value.clone(),
                Value::I4(i32::from(quality)),
                Value::Date(local_time),
            ],
        )
        .map(drop)
    }

    fn set_active(&mut self, active: bool) -> Result<(), CallError> {
        self.object
            .put("Active", &Value::Bool(active))
            .map_err(call_error)
    }

    fn server_state(&mut self) -> Result<ServerState, CallError> {
        match self.get("ServerState")? {
            Value::I4(s) => Ok(ServerState::from_i32(s)),
            Value::I2(s) => Ok(ServerState::from_i32(i32::from(s))),
            Value::UI1(s) => Ok(ServerState::from_i32(i32::from(s))),
            v => Err(mismatch("ServerState", &v)),
        }
    }

    fn start_time(&mut self) -> Result<f64, CallError> {
        let v = self.get("StartTime")?;
        local_time(&v)?.ok_or_else(|| mismatch("StartTime", &v))
    }

    fn pump(&mut self, wait: Duration, events: &mut dyn FnMut(DataChange)) {
        pump_messages_until(wait, || !lock(&self.queue).is_empty());
        let batch = std::mem::take(&mut *lock(&self.queue));
        for e in batch {
            events(e);
        }
    }
}
