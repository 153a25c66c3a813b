//! What a console OPC client (the `opcdiag` diagnostic tool) needs beyond the interface
//! wrappers: an IOPCDataCallback sink that forwards OnDataChange into a channel, a Ctrl+C
//! flag, and the local time zone offset for printing timestamps. Works with any OPC DA
//! server.

use super::{timestamp, ReadItem};
use ctopc_com::interfaces::*;
use ctopc_core::{Timestamp, Value};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::Sender;
use std::sync::Mutex;
use windows::core::{implement, BOOL, HRESULT};
use windows::Win32::Foundation::{FILETIME, SYSTEMTIME};
use windows::Win32::System::Console::SetConsoleCtrlHandler;
use windows::Win32::System::Time::{
    FileTimeToSystemTime, SystemTimeToFileTime, SystemTimeToTzSpecificLocalTime,
};
use windows::Win32::System::Variant::VARIANT;

/// One OnDataChange, owned. `items[i].client_handle` is the item's client handle.
#[derive(Debug, Clone, PartialEq)]
pub struct DataChange {
    pub transaction: u32,
    pub group: u32,
    pub master_quality: HRESULT,
    pub master_error: HRESULT,
    pub items: Vec<ReadItem>,
}

/// An IOPCDataCallback that sends every OnDataChange into a channel (the other callbacks
/// are accepted and ignored). Create it with [`data_change_sink`].
#[implement(IOPCDataCallback)]
struct ChangeSink {
    tx: Mutex<Sender<DataChange>>,
}

/// A sink to advise on a group (`advise_data_callback`); changes arrive on `tx`, from
/// whatever thread the callback comes in on. A closed receiver is not an error.
pub fn data_change_sink(tx: Sender<DataChange>) -> IOPCDataCallback {
    ChangeSink { tx: Mutex::new(tx) }.into()
}

/// Copies the `[in, size_is(n)]` arrays of an OnWriteComplete into (client handle, error)
/// pairs; empty when either pointer is NULL.
///
/// # Safety
/// Each non-null pointer must point at `n` elements, as the stub passes them.
pub unsafe fn write_results(n: u32, h: *const u32, e: *const HRESULT) -> Vec<(u32, HRESULT)> {
    if n == 0 || h.is_null() || e.is_null() {
        return Vec::new();
    }
    let n = n as usize;
    // SAFETY: the caller guarantees `n`-element arrays (checked non-null above); they are
    // only read here and copied out.
    let (h, e) = unsafe {
        (
            std::slice::from_raw_parts(h, n),
            std::slice::from_raw_parts(e, n),
        )
    };
    h.iter().copied().zip(e.iter().copied()).collect()
}

/// Copies the `[in, size_is(n)]` arrays of an OnDataChange / OnReadComplete into owned
/// items (for any IOPCDataCallback implementation: opcdiag's sink, the tests' sink).
///
/// # Safety
/// Each non-null pointer must point at `n` elements, as the stub passes them.
pub unsafe fn callback_items(
    n: u32,
    h: *const u32,
    v: *const VARIANT,
    q: *const u16,
    t: *const FILETIME,
    e: *const HRESULT,
) -> Vec<ReadItem> {
    if n == 0 || h.is_null() || v.is_null() || q.is_null() || t.is_null() || e.is_null() {
        return Vec::new();
    }
    let n = n as usize;
    // SAFETY: the caller guarantees `n`-element arrays (checked non-null above); they are
    // only read here and copied out.
    let (h, v, q, t, e) = unsafe {
        (
            std::slice::from_raw_parts(h, n),
            std::slice::from_raw_parts(v, n),
            std::slice::from_raw_parts(q, n),
            std::slice::from_raw_parts(t, n),
            std::slice::from_raw_parts(e, n),
        )
    };
    (0..n)
        .map(|i| ReadItem {
            client_handle: h[i],
            vt: ctopc_com::variant::var_type(&v[i]).0,
            value: ctopc_com::variant::from_variant(&v[i]).unwrap_or(Value::Empty),
            quality: q[i],
            timestamp: timestamp(t[i]),
            error: e[i],
        })
        .collect()
}

impl IOPCDataCallback_Impl for ChangeSink_Impl {
    unsafe fn OnDataChange(
        &self,
        transaction: u32,
        group: u32,
        master_quality: HRESULT,
        master_error: HRESULT,
        n: u32,
        h: *const u32,
        v: *const VARIANT,
        q: *const u16,
        t: *const FILETIME,
        e: *const HRESULT,
    ) -> windows::core::Result<()> {
        // SAFETY: the stub passes `n`-element arrays for the duration of the call.
        let items = unsafe { callback_items(n, h, v, q, t, e) };
        let change = DataChange {
            transaction,
            group,
            master_quality,
            master_error,
            items,
        };
        if let Ok(tx) = self.tx.lock() {
            let _ = tx.send(change);
        }
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

// ---- Ctrl+C -----------------------------------------------------------------------------

static CTRL_C: AtomicBool = AtomicBool::new(false);

extern "system" fn on_console_ctrl(_ctrl_type: u32) -> BOOL {
    // Ctrl+C, Ctrl+Break, closing the console: ask the program to stop; handled.
    CTRL_C.store(true, Ordering::SeqCst);
    BOOL(1)
}

/// Makes Ctrl+C (and Ctrl+Break, closing the console) set the flag [`ctrl_c_pressed`]
/// reads instead of ending the process, so that a client can leave cleanly (unadvise,
/// remove its groups, release the server).
pub fn catch_ctrl_c() -> windows::core::Result<()> {
    // SAFETY: registers a plain function that only stores into a static atomic.
    unsafe { SetConsoleCtrlHandler(Some(on_console_ctrl), true) }
}

/// True once Ctrl+C was pressed (after [`catch_ctrl_c`]).
pub fn ctrl_c_pressed() -> bool {
    CTRL_C.load(Ordering::SeqCst)
}

// ---- local time -------------------------------------------------------------------------

/// The offset of local time from UTC at `t` in minutes (east positive: +60 in Warsaw in
/// winter), from the Windows time zone settings including daylight saving time.
pub fn utc_offset_minutes(t: Timestamp) -> windows::core::Result<i32> {
    let (lo, hi) = t.filetime_parts();
    let ft = FILETIME {
        dwLowDateTime: lo,
        dwHighDateTime: hi,
    };
    let mut utc = SYSTEMTIME::default();
    let mut local = SYSTEMTIME::default();
    let mut local_ft = FILETIME::default();
    // SAFETY: valid in and out pointers to locals for each call.
    unsafe {
        FileTimeToSystemTime(&ft, &mut utc)?;
        SystemTimeToTzSpecificLocalTime(None, &utc, &mut local)?;
        SystemTimeToFileTime(&local, &mut local_ft)?;
    }
    let local_ticks = timestamp(local_ft).filetime();
    // SYSTEMTIME has millisecond resolution: round the difference to whole minutes.
    let diff_ms = (local_ticks - t.filetime()) / Timestamp::TICKS_PER_MS;
    Ok(((diff_ms as f64) / 60_000.0).round() as i32)
}
