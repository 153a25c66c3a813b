//! One served channel as AsixConnect's Automation server `XConnect.ServerCT` offers it
//! (digest §11): the boundary between the gate's engine and the late-bound object.
//!
//! The trait mirrors the object's members one to one, in the types a late-binding adapter
//! gets from VARIANTs: values as [`Value`] (the VARIANT's content), the full 16-bit OPC
//! quality as `u16`, timestamps as VT_DATE in the station's **local** time (`f64`, OLE
//! days; the engine converts to UTC, [`crate::tz`]). Every call may fail with an HRESULT
//! and its text (`IErrorInfo`), [`CallError`].
//!
//! Threading: the engine makes the object, and calls every method, on the one worker
//! thread of its channel (an apartment-threaded in-process server lives on the thread that
//! created it). Events arrive only while the worker pumps ([`XConnectChannel::pump`]), so
//! an implementation over COM queues the DataChange events its sink receives during the
//! message pump and hands them out there. A call that hangs stalls only its channel.

use std::time::Duration;

use ctopc_core::{OpcError, Value};

/// `DataSource` of `Read` (digest §11).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DataSource {
    /// `dsCache` = 1: the object's own cache (active items only).
    Cache = 1,
    /// `dsDevice` = 2: the asix system's cache.
    Device = 2,
    /// `dsDriver` = 3: the PLC itself.
    Driver = 3,
}

/// `ServerState` (digest §7, §11).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ServerState {
    Running,
    Failed,
    NoConfig,
    Suspended,
    /// Simulation of current data.
    Test,
    /// A value the manual does not list.
    Other(i32),
}

impl ServerState {
    pub fn from_i32(v: i32) -> ServerState {
        match v {
            1 => ServerState::Running,
            2 => ServerState::Failed,
            3 => ServerState::NoConfig,
            4 => ServerState::Suspended,
            5 => ServerState::Test,
            x => ServerState::Other(x),
        }
    }
    /// Data flows: running or test. Anything else is announced as SOURCE_FAILED.
    pub fn serves(self) -> bool {
        matches!(self, ServerState::Running | ServerState::Test)
    }
}

/// A value, its 16-bit OPC quality and its local timestamp, as `Read` and `DataChange`
/// give them.
#[derive(Debug, Clone, PartialEq)]
pub struct ItemValue {
    pub value: Value,
    pub quality: u16,
    /// VT_DATE, local time; `None` when the server left it empty (the gate then stamps
    /// the time of reception).
    pub local_time: Option<f64>,
}

/// A `DataChange` event.
#[derive(Debug, Clone, PartialEq)]
pub struct DataChange {
    pub item: String,
    pub value: ItemValue,
}

/// A failed call: the HRESULT (an `ASKOM_E_*` code of digest §8, or a COM error) and
/// the text of its `IErrorInfo`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("0x{:08X}: {text}", *hresult as u32)]
pub struct CallError {
    pub hresult: i32,
    pub text: String,
}

impl CallError {
    pub fn new(code: OpcError, text: impl Into<String>) -> CallError {
        CallError {
            hresult: code.hresult(),
            text: text.into(),
        }
    }
}

/// One `XConnect.ServerCT` object (see the module doc).
pub trait XConnectChannel {
    /// `LoadChannel ChannelName`.
    fn load_channel(&mut self, name: &str) -> Result<(), CallError>;
    /// `Init InitString`.
    fn init(&mut self, init: &str) -> Result<(), CallError>;
    /// `Read DataSource, ItemID, Value, Quality, TimeStamp`.
    fn read(&mut self, source: DataSource, item: &str) -> Result<ItemValue, CallError>;
    /// `SetItemActive ItemID, ActiveState`.
    fn set_item_active(&mut self, item: &str, active: bool) -> Result<(), CallError>;
    /// `Write ItemID, Value`.
    fn write(&mut self, item: &str, value: &Value) -> Result<(), CallError>;
    /// `WriteEx ItemID, Value, Quality, TimeStamp` (`local_time`: VT_DATE, local time).
    fn write_ex(
        &mut self,
        item: &str,
        value: &Value,
        quality: u16,
        local_time: f64,
    ) -> Result<(), CallError>;
    /// `Active = …`.
    fn set_active(&mut self, active: bool) -> Result<(), CallError>;
    /// `ServerState`.
    fn server_state(&mut self) -> Result<ServerState, CallError>;
    /// `StartTime` (VT_DATE, local time).
    fn start_time(&mut self) -> Result<f64, CallError>;
    /// Waits at most `wait` for events (a COM adapter pumps the thread's messages) and
    /// hands every `DataChange` received to `events`.
    fn pump(&mut self, wait: Duration, events: &mut dyn FnMut(DataChange));
}

/// Makes a channel's object; called on the channel's worker thread (see the module doc).
pub type ChannelFactory =
    std::sync::Arc<dyn Fn(&str) -> Result<Box<dyn XConnectChannel>, CallError> + Send + Sync>;
