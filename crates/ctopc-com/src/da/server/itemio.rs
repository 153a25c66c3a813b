//! IOPCItemIO (DA 3.0): Read with MaxAge and WriteVQT by item ID, without a group; and the
//! wait for the data source that synchronous calls share.
//!
//! A read or write that needs the data source comes back from the engine as
//! `SyncOutcome::Pending`; the calling COM thread then waits (engine unlocked) for the
//! result, at most the engine's source timeout plus [`ctopc_runtime::SYNC_WAIT_MARGIN`]. The
//! engine itself completes such requests with ASKOM_E_NetAnswerTimeout after its source
//! timeout, so the wait normally ends with the engine's answer; if it does not (the driver
//! is stuck), the call abandons the request and answers ASKOM_E_NetAnswerTimeout for the
//! items itself.

use super::{OpcServer, OpcServer_Impl};
use crate::com::abi::TaskMem;
use crate::com::abi::{
    self, clear, clear_outs, in_slice, item_hr, item_id_at, nonnull, put, s_false_if_any,
    OwnedArray,
};
use crate::com::interfaces::*;
use crate::com::variant;
use ctopc_core::metrics::Method;
use ctopc_core::model::{
    ItemState, ItemVqt, ReadResults, SyncId, SyncOutcome, SyncResult, WriteResults,
};
use ctopc_core::{OpcError, Quality};
use std::time::Duration;
use windows::core::{HRESULT, PCWSTR};
use windows::Win32::Foundation::FILETIME;
use windows::Win32::System::Variant::VARIANT;

impl OpcServer {
    /// How long a synchronous call waits for the data source at most.
    fn sync_wait_limit(&self) -> Duration {
        let source_ms = self.ctx.runtime.lock().engine.config().source_timeout_ms;
        Duration::from_millis(u64::from(source_ms)) + ctopc_runtime::SYNC_WAIT_MARGIN
    }

    /// Waits for a pending synchronous operation; `None` after abandoning it on timeout.
    fn wait_sync(&self, id: SyncId) -> Option<SyncResult> {
        let limit = self.sync_wait_limit();
        let r = self.ctx.runtime.wait_for(limit, |e| e.take_sync_result(id));
        if r.is_none() {
            tracing::warn!("a synchronous request got no answer within {limit:?}; abandoned");
            self.ctx.runtime.with_engine(|e, _| e.abandon_sync(id));
        }
        r
    }

    /// IOPCItemIO::Read in the core: per item `(item ID, MaxAge)`, `items` non-empty.
    pub(super) fn item_io_read(&self, items: &[(&str, u32)]) -> ReadResults {
        let n = items.len();
        let started = self
            .ctx
            .runtime
            .with_engine(|e, now| e.item_io_read(now, self.handle, items));
        match started {
            Ok(SyncOutcome::Ready(r)) => r,
            Ok(SyncOutcome::Pending(id)) => match self.wait_sync(id) {
                Some(SyncResult::Read(r)) => r,
                Some(SyncResult::Write(_)) => vec![Err(OpcError::Fail); n],
                None => vec![Err(OpcError::NetAnswerTimeout); n],
            },
            Err(e) => vec![Err(e); n],
        }
    }

    /// IOPCItemIO::WriteVQT in the core, `items` non-empty.
    fn item_io_write(&self, items: &[(&str, ItemVqt)]) -> WriteResults {
        let n = items.len();
        self.ctx
            .runtime
            .set_caller(self.handle, crate::com::caller::current());
        let auditing = self.ctx.runtime.clients.auditing();
        let (started, denied) = self.ctx.runtime.with_engine(|e, now| {
            let started = e.item_io_write_vqt(now, self.handle, items);
            let denied = if auditing {
                let ids: Vec<&str> = items.iter().map(|(id, _)| *id).collect();
                e.item_io_denied_by_policy(self.handle, &ids)
            } else {
                Vec::new()
            };
            (started, denied)
        });
        let results = match started {
            Ok(SyncOutcome::Ready(r)) => r,
            Ok(SyncOutcome::Pending(id)) => match self.wait_sync(id) {
                Some(SyncResult::Write(r)) => r,
                Some(SyncResult::Read(_)) => vec![Err(OpcError::Fail); n],
                None => vec![Err(OpcError::NetAnswerTimeout); n],
            },
            Err(e) => vec![Err(e); n],
        };
        self.ctx.runtime.metrics.written(items.len() as u64);
        self.audit_item_io(items, &results, &denied);
        results
    }

    /// The write audit's lines of an IOPCItemIO::WriteVQT (`ctopc_runtime::clients`).
    fn audit_item_io(
        &self,
        items: &[(&str, ItemVqt)],
        results: &[Result<(), OpcError>],
        denied: &[bool],
    ) {
        let ops = &self.ctx.runtime.clients;
        if !ops.auditing() {
            return;
        }
        let keys: Vec<(Option<&str>, Option<u32>)> =
            items.iter().map(|(id, _)| (Some(*id), None)).collect();
        let values: Vec<ItemVqt> = items.iter().map(|(_, v)| v.clone()).collect();
        let call = ctopc_runtime::clients::WriteCall {
            session: self.handle,
            method: "IOPCItemIO::WriteVQT",
            group: None,
            items: &keys,
            values: &values,
            cancel_id: None,
            denied,
        };
        ops.audit_write(crate::com::clock::now(), &call, results);
    }
}

/// Runs `call` over the items that passed the COM-side checks (`pre[i]` Ok) and merges
/// its results back into input order; items that failed the checks keep their error.
fn merge<I, T>(
    pre: Vec<Result<I, OpcError>>,
    call: impl FnOnce(&[I]) -> Vec<Result<T, OpcError>>,
) -> Vec<Result<T, OpcError>> {
    let mut slots: Vec<Result<Option<T>, OpcError>> = Vec::with_capacity(pre.len());
    let mut valid = Vec::new();
    for p in pre {
        match p {
            Ok(i) => {
                valid.push(i);
                slots.push(Ok(None));
            }
            Err(e) => slots.push(Err(e)),
        }
    }
    let mut results = if valid.is_empty() {
        Vec::new()
    } else {
        call(&valid)
    }
    .into_iter();
    slots
        .into_iter()
        .map(|s| match s {
            Ok(_) => results.next().unwrap_or(Err(OpcError::Fail)),
            Err(e) => Err(e),
        })
        .collect()
}

/// The item IDs of an `[in, size_is(count)] LPWSTR*` array, each checked.
///
/// # Safety
/// As [`crate::com::abi::in_slice`], each non-null element as [`crate::com::abi::item_id_at`].
unsafe fn item_ids(
    p: *const PCWSTR,
    count: u32,
) -> windows::core::Result<Vec<Result<String, OpcError>>> {
    Ok(in_slice(p, count)?.iter().map(|s| item_id_at(*s)).collect())
}

impl IOPCItemIO_Impl for OpcServer_Impl {
    unsafe fn Read(
        &self,
        count: u32,
        pitem_ids: *const PCWSTR,
        pmax_age: *const u32,
        ppvalues: *mut *mut VARIANT,
        ppqualities: *mut *mut u16,
        pptimes: *mut *mut FILETIME,
        pperrors: *mut *mut HRESULT,
    ) -> HRESULT {
        let _t = self.ctx.timed(Method::ItemIoRead);
        clear_outs((ppvalues, ppqualities, pptimes, pperrors));
        abi::hresult((|| {
            nonnull(ppvalues)?;
            nonnull(ppqualities)?;
            nonnull(pptimes)?;
            nonnull(pperrors)?;
            if count == 0 {
                return Err(abi::invalid_arg());
            }
            let ids = item_ids(pitem_ids, count)?;
            let ages = in_slice(pmax_age, count)?;
            let pre: Vec<Result<(String, u32), OpcError>> = ids
                .into_iter()
                .zip(ages)
                .map(|(id, &age)| id.map(|id| (id, age)))
                .collect();
            let results: Vec<Result<ItemState, OpcError>> = merge(pre, |valid| {
                let items: Vec<(&str, u32)> =
                    valid.iter().map(|(id, age)| (id.as_str(), *age)).collect();
                self.item_io_read(&items)
            });
            let n = results.len();
            let mut values = OwnedArray::<VARIANT>::zeroed(n)?;
            let mut qualities = TaskMem::<u16>::zeroed(n)?;
            let mut times = TaskMem::<FILETIME>::zeroed(n)?;
            let mut errors = TaskMem::<HRESULT>::zeroed(n)?;
            for (i, r) in results.iter().enumerate() {
                errors.as_mut_slice()[i] = item_hr(r);
                if let Ok(s) = r {
                    match variant::to_variant(&s.value) {
                        Ok(v) => {
                            values.as_mut_slice()[i] = v;
                            qualities.as_mut_slice()[i] = s.quality.0;
                            times.as_mut_slice()[i] = crate::com::clock::filetime(s.timestamp);
                        }
                        Err(e) => errors.as_mut_slice()[i] = e.code(),
                    }
                }
            }
            let hr = s_false_if_any(errors.as_mut_slice());
            // SAFETY: all four checked non-null; every allocation has succeeded.
            unsafe {
                put(ppvalues, values.into_raw());
                put(ppqualities, qualities.into_raw());
                put(pptimes, times.into_raw());
                put(pperrors, errors.into_raw());
            }
            Ok(hr)
        })())
    }

    unsafe fn WriteVQT(
        &self,
        count: u32,
        pitem_ids: *const PCWSTR,
        pvqt: *const OPCITEMVQT,
        pperrors: *mut *mut HRESULT,
    ) -> HRESULT {
        let _t = self.ctx.timed(Method::ItemIoWriteVqt);
        clear(pperrors, std::ptr::null_mut());
        abi::hresult((|| {
            nonnull(pperrors)?;
            if count == 0 {
                return Err(abi::invalid_arg());
            }
            let ids = item_ids(pitem_ids, count)?;
            let vqts = in_slice(pvqt, count)?;
            let pre: Vec<Result<(String, ItemVqt), OpcError>> = ids
                .into_iter()
                .zip(vqts)
                .map(|(id, v)| {
                    let id = id?;
                    let value = variant::from_variant(&v.vDataValue).map_err(|e| {
                        if e == OpcError::Overflow {
                            OpcError::Range
                        } else {
                            e
                        }
                    })?;
                    let quality = v.bQualitySpecified.as_bool().then_some(Quality(v.wQuality));
                    let timestamp = v.bTimeStampSpecified.as_bool().then(|| {
                        ctopc_core::Timestamp::from_filetime_parts(
                            v.ftTimeStamp.dwLowDateTime,
                            v.ftTimeStamp.dwHighDateTime,
                        )
                    });
                    Ok((
                        id,
                        ItemVqt {
                            value,
                            quality,
                            timestamp,
                        },
                    ))
                })
                .collect();
            let results = merge(pre, |valid| {
                let items: Vec<(&str, ItemVqt)> = valid
                    .iter()
                    .map(|(id, v)| (id.as_str(), v.clone()))
                    .collect();
                self.item_io_write(&items)
            });
            let mut errors = TaskMem::<HRESULT>::zeroed(results.len())?;
            for (slot, r) in errors.as_mut_slice().iter_mut().zip(&results) {
                *slot = item_hr(r);
            }
            let hr = s_false_if_any(errors.as_mut_slice());
            // SAFETY: checked non-null; the only allocation has succeeded.
            unsafe { put(pperrors, errors.into_raw()) };
            Ok(hr)
        })())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn merge_keeps_input_order_and_early_errors() {
        let pre = vec![Ok(1), Err(OpcError::InvalidItemId), Ok(3)];
        let r = merge(pre, |v: &[i32]| v.iter().map(|x| Ok(x * 10)).collect());
        assert_eq!(r, vec![Ok(10), Err(OpcError::InvalidItemId), Ok(30)]);
        let none: Vec<Result<i32, OpcError>> =
            merge(vec![Err(OpcError::InvalidItemId)], |_: &[i32]| {
                panic!("not called")
            });
        assert_eq!(none, vec![Err(OpcError::InvalidItemId)]);
    }
}
