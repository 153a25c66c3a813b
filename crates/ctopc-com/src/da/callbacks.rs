//! The COM front end's callbacks: how an engine event reaches an OPC client. The runtime
//! (`ctopc_runtime::Runtime`) decides when and on which thread (the client session's
//! callback worker); this module makes the call: the VARIANT conversion and
//! `IOPCDataCallback` ([`deliver_one`], which the group's sink calls after its DA 1.0a
//! routing, `crate::da::group::dataobject::GroupSinks`), and
//! `IOPCShutdown::ShutdownRequest`. Every thread the runtime starts joins the MTA first
//! ([`thread_hook`]).

use crate::com::connpoint::SinkSlot;
use crate::com::interfaces::{IOPCDataCallback, IOPCShutdown};
use crate::com::{clock, error, variant};
use ctopc_core::model::{Event, GroupHandle};
use ctopc_core::OpcError;
use ctopc_runtime::{Delivery, SessionSink};
use std::sync::Arc;
use windows::core::{HRESULT, PCWSTR};
use windows::Win32::Foundation::FILETIME;
use windows::Win32::System::Variant::VARIANT;

/// The runtime's [`ThreadHook`](ctopc_runtime::ThreadHook) for the COM server: every
/// thread it starts joins the multithreaded apartment (the sinks are MTA proxies).
pub fn thread_hook() -> Box<dyn std::any::Any> {
    Box::new(crate::com::apartment::Apartment::mta())
}

/// A session's IOPCShutdown connection.
pub struct ShutdownSink(pub Arc<SinkSlot<IOPCShutdown>>);

impl SessionSink for ShutdownSink {
    fn shutdown_request(&self, reason: &str) {
        let Some(sink) = self.0.get() else { return };
        let reason: Vec<u16> = reason.encode_utf16().chain(std::iter::once(0)).collect();
        // SAFETY: `reason` is a NUL-terminated UTF-16 string alive for the call.
        let r = unsafe { sink.ShutdownRequest(PCWSTR(reason.as_ptr())) };
        if let Err(e) = r {
            tracing::warn!("ShutdownRequest failed: {e}");
        }
    }
}

/// True for the errors that mean the client is gone.
pub fn is_disconnected(hr: HRESULT) -> bool {
    const CODES: [u32; 6] = [
        0x80010108, // RPC_E_DISCONNECTED
        0x800706BA, // RPC_S_SERVER_UNAVAILABLE
        0x800706BF, // RPC_S_CALL_FAILED_DNE
        0x80010012, // RPC_E_SERVER_DIED_DNE
        0x80010007, // RPC_E_SERVER_DIED
        0x800401FD, // CO_E_OBJNOTCONNECTED
    ];
    CODES.contains(&(hr.0 as u32))
}

/// The group's client handle an event carries.
pub(crate) fn client_group(event: &Event) -> u32 {
    match event {
        Event::DataChange(e) => e.client_group,
        Event::ReadComplete(e) => e.client_group,
        Event::WriteComplete(e) => e.client_group,
        Event::CancelComplete(e) => e.client_group,
    }
}

fn hr_of(e: Option<OpcError>) -> HRESULT {
    e.map_or(HRESULT(0), error::hresult)
}

/// Delivers one event to a group's IOPCDataCallback on the client's worker thread.
pub(crate) fn deliver_one(
    group: GroupHandle,
    slot: &SinkSlot<IOPCDataCallback>,
    event: Event,
) -> Delivery {
    let Some((cookie, sink)) = slot.connection() else {
        return Delivery::default();
    };
    let result = match &event {
        // A large subscription update goes in calls of at most MAX_ITEMS_PER_CALLBACK
        // items (`DataChange::calls`), one after the other, with the same buffers; a
        // failed call ends it (the client is gone, or refuses).
        Event::DataChange(d) => {
            let mut buffers = CallBuffers::default();
            d.calls()
                .into_iter()
                .try_for_each(|(quality, error, items)| {
                    buffers.call(
                        &sink,
                        true,
                        d.transaction_id,
                        d.client_group,
                        quality,
                        error,
                        items,
                    )
                })
        }
        Event::ReadComplete(d) => CallBuffers::default().call(
            &sink,
            false,
            d.transaction_id,
            d.client_group,
            d.master_quality,
            d.master_error,
            &d.items,
        ),
        Event::WriteComplete(d) => {
            let handles: Vec<u32> = d.items.iter().map(|i| i.client_handle).collect();
            let errors: Vec<HRESULT> = d.items.iter().map(|i| hr_of(i.error)).collect();
            // SAFETY: the arrays hold `handles.len()` elements and live for the call.
            unsafe {
                sink.OnWriteComplete(
                    d.transaction_id,
                    d.client_group,
                    hr_of(d.master_error),
                    handles.len() as u32,
                    handles.as_ptr(),
                    errors.as_ptr(),
                )
            }
        }
        // SAFETY: plain values.
        Event::CancelComplete(d) => unsafe {
            sink.OnCancelComplete(d.transaction_id, d.client_group)
        },
    };
    if let Err(e) = result {
        if is_disconnected(e.code()) {
            tracing::warn!(
                "group {}: the client's IOPCDataCallback is gone ({e}); dropping it",
                group.0
            );
            return Delivery {
                called: true,
                lost: slot.drop_if(cookie),
            };
        }
        tracing::debug!("group {}: callback returned {e}", group.0);
    }
    Delivery {
        called: true,
        lost: false,
    }
}
/// The arrays of one OnDataChange / OnReadComplete call, kept from call to call of a split
/// update so that each call of it reuses them instead of allocating its own.
#[derive(Default)]
struct CallBuffers {
    handles: Vec<u32>,
    qualities: Vec<u16>,
    times: Vec<FILETIME>,
    errors: Vec<HRESULT>,
    values: Vec<VARIANT>,
}

impl CallBuffers {
    #[allow(clippy::too_many_arguments)]
    fn call(
        &mut self,
        sink: &IOPCDataCallback,
        data_change: bool,
        transaction: u32,
        client_group: u32,
        master_quality: Option<OpcError>,
        master_error: Option<OpcError>,
        items: &[ctopc_core::model::ItemValue],
    ) -> windows::core::Result<()> {
        self.handles.clear();
        self.handles.extend(items.iter().map(|i| i.client_handle));
        self.qualities.clear();
        self.qualities.extend(items.iter().map(|i| i.quality.0));
        self.times.clear();
        self.times
            .extend(items.iter().map(|i| clock::filetime(i.timestamp)));
        self.errors.clear();
        self.errors.extend(items.iter().map(|i| hr_of(i.error)));
        self.values.clear();
        self.values.extend(
            items
                .iter()
                .map(|i| variant::to_variant(&i.value).unwrap_or_default()),
        );
        let n = items.len() as u32;
        let (handles, values, qualities, times, errors) = (
            self.handles.as_ptr(),
            self.values.as_ptr(),
            self.qualities.as_ptr(),
            self.times.as_ptr(),
            self.errors.as_ptr(),
        );
        // SAFETY: every array holds `n` elements and lives for the call; the VARIANTs are
        // cleared below.
        let r = unsafe {
            if data_change {
                sink.OnDataChange(
                    transaction,
                    client_group,
                    hr_of(master_quality),
                    hr_of(master_error),
                    n,
                    handles,
                    values,
                    qualities,
                    times,
                    errors,
                )
            } else {
                sink.OnReadComplete(
                    transaction,
                    client_group,
                    hr_of(master_quality),
                    hr_of(master_error),
                    n,
                    handles,
                    values,
                    qualities,
                    times,
                    errors,
                )
            }
        };
        for v in self.values.iter_mut() {
            variant::clear(v);
        }
        r
    }
}
