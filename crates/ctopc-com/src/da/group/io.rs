//! Sync and async I/O of the group: IOPCSyncIO, IOPCSyncIO2, IOPCAsyncIO2, IOPCAsyncIO3
//! (DA 1.0a's IOPCAsyncIO, over the same helpers and transactions: `async1.rs`).
//!
//! Every method has the same shape: check the arguments (NULL required pointers and a
//! zero count are E_INVALIDARG; out-pointers are set to NULL first), one engine call
//! through `Runtime::with_engine` (the engine is locked once per call), `?` on the
//! whole-call error (mapped in `error::to_com`), then the out-parameters are filled
//! all-or-nothing: CoTaskMem arrays are owned by `TaskMem` / `OwnedArray` until every
//! allocation of the call has succeeded, and VARIANTs already written are cleared when a
//! later allocation fails. Per-item failures are written to `ppErrors` and the call
//! returns S_FALSE.
//!
//! Synchronous calls that need the data source (DEVICE reads, MaxAge reads of stale
//! items, every write) get `SyncOutcome::Pending` from the engine and wait, with the
//! engine unlocked, for the driver thread to complete them: at most the engine's own
//! source timeout plus [`SYNC_WAIT_MARGIN`]. The engine answers a silent source with
//! ASKOM_E_NetAnswerTimeout per item at its source timeout; should even that not come
//! (the driver stuck), the call abandons the transaction and answers the same code per
//! item.
//!
//! Writes: the value is converted to the item's canonical type by the engine as
//! VariantChangeTypeEx with the group's LCID would (`ctopc_core::convert::convert_for_write`:
//! numeric text, BOOL as 1/0, CY, every number; OPC_E_BADTYPE for DATE and other text,
//! OPC_E_RANGE on overflow), read-only items answer OPC_E_BADRIGHTS; a VT_EMPTY value
//! with a quality or timestamp (WriteVQT) is OPC_E_NOTSUPPORTED.
//! A 1-D array of 3 elements written to a scalar item is the asix extended write
//! `[value, quality, timestamp]` (AsixConnect §6.6); the engine sends it to the data
//! source as a value-quality-timestamp write.

use super::Group_Impl;
use crate::com::abi::{
    self, in_array, item_hr, s_false_if, write_out, ComResult, OutArray, OwnedArray, TaskMem,
};
use crate::com::interfaces::*;
use crate::com::variant;
use crate::com::{clock, error};
use ctopc_core::metrics::Method;
use ctopc_core::model::{
    AsyncStarted, DataSource, Engine, ItemState, ItemVqt, ReadResults, SyncId, SyncOutcome,
    SyncResult, WriteResults,
};
use ctopc_core::{OpcError, Quality, Timestamp, Value};
use ctopc_runtime::SYNC_WAIT_MARGIN;
use std::time::Duration;
use windows::core::{BOOL, HRESULT};
use windows::Win32::Foundation::{E_FAIL, E_INVALIDARG, E_OUTOFMEMORY, FILETIME};
use windows::Win32::System::Variant::VARIANT;

// ---- argument checks --------------------------------------------------------------

pub(super) fn data_source(s: OPCDATASOURCE) -> ComResult<DataSource> {
    match s {
        OPC_DS_CACHE => Ok(DataSource::Cache),
        OPC_DS_DEVICE => Ok(DataSource::Device),
        _ => Err(E_INVALIDARG.into()),
    }
}

/// The VARIANT for a value read. A value that cannot be represented (an array element
/// type VARIANTs cannot hold) becomes a per-item error; only memory exhaustion fails the
/// whole call.
fn value_variant(v: &Value) -> ComResult<Result<VARIANT, OpcError>> {
    match variant::to_variant(v) {
        Ok(var) => Ok(Ok(var)),
        Err(e) if e.code() == E_OUTOFMEMORY => Err(e),
        Err(e) => Ok(Err(
            OpcError::from_hresult(e.code().0).unwrap_or(OpcError::BadType)
        )),
    }
}

// ---- synchronous completion ---------------------------------------------------------

/// Waits for a pending synchronous operation (engine unlocked while waiting).
fn complete<T>(
    g: &Group_Impl,
    outcome: SyncOutcome<T>,
    source_timeout_ms: u32,
    n: usize,
    pick: fn(SyncResult) -> Option<T>,
    timed_out: fn(usize) -> T,
) -> ComResult<T> {
    let id: SyncId = match outcome {
        SyncOutcome::Ready(r) => return Ok(r),
        SyncOutcome::Pending(id) => id,
    };
    let limit = Duration::from_millis(u64::from(source_timeout_ms)) + SYNC_WAIT_MARGIN;
    match g.ctx.runtime.wait_for(limit, |e| e.take_sync_result(id)) {
        Some(r) => {
            pick(r).ok_or_else(|| error::error(E_FAIL, "synchronous result of the wrong kind"))
        }
        None => {
            g.ctx.runtime.with_engine(|e, _| e.abandon_sync(id));
            tracing::warn!(
                "group {}: a synchronous operation got no answer in {} ms; abandoned",
                g.handle.0,
                limit.as_millis()
            );
            Ok(timed_out(n))
        }
    }
}

fn pick_read(r: SyncResult) -> Option<ReadResults> {
    match r {
        SyncResult::Read(r) => Some(r),
        SyncResult::Write(_) => None,
    }
}

fn pick_write(r: SyncResult) -> Option<WriteResults> {
    match r {
        SyncResult::Write(r) => Some(r),
        SyncResult::Read(_) => None,
    }
}

fn read_timed_out(n: usize) -> ReadResults {
    vec![Err(OpcError::NetAnswerTimeout); n]
}

fn write_timed_out(n: usize) -> WriteResults {
    vec![Err(OpcError::NetAnswerTimeout); n]
}

// ---- shared bodies ---------------------------------------------------------------------

/// What the write audit takes of the engine for one write call.
struct AuditNames {
    group: String,
    /// Per item: its ID (`None`: not an item of the group).
    ids: Vec<Option<String>>,
    /// Per item: the write-rights policy refused it.
    denied: Vec<bool>,
}

/// Per-item conversion failures of the values to write, recorded before the engine call
/// (the engine gets VT_EMPTY for them, which it rejects after checking the handle and the
/// access rights, with OPC_E_BADTYPE, or OPC_E_NOTSUPPORTED when a quality or timestamp
/// came with it; the handle and rights errors, more basic, win).
#[derive(Default)]
pub(super) struct PreErrors(Vec<(usize, OpcError)>);

impl PreErrors {
    fn value(&mut self, i: usize, v: &VARIANT) -> Value {
        match variant::from_variant(v) {
            Ok(v) => v,
            Err(e) => {
                let e = if e == OpcError::Overflow {
                    OpcError::Range
                } else {
                    e
                };
                self.0.push((i, e));
                Value::Empty
            }
        }
    }
    pub(super) fn apply(&self, results: &mut WriteResults) {
        for &(i, e) in &self.0 {
            if let Some(r) = results.get_mut(i) {
                if matches!(r, Err(OpcError::BadType | OpcError::NotSupported)) {
                    *r = Err(e);
                }
            }
        }
    }
}

fn vqt_timestamp(ft: FILETIME) -> Timestamp {
    Timestamp::from_filetime_parts(ft.dwLowDateTime, ft.dwHighDateTime)
}

/// The items of a WriteVQT call.
fn vqt_items(handles: &[u32], vqts: &[OPCITEMVQT], pre: &mut PreErrors) -> Vec<(u32, ItemVqt)> {
    handles
        .iter()
        .zip(vqts)
        .enumerate()
        .map(|(i, (&h, q))| {
            let value = pre.value(i, &q.vDataValue);
            let quality = q.bQualitySpecified.as_bool().then_some(Quality(q.wQuality));
            let timestamp = q
                .bTimeStampSpecified
                .as_bool()
                .then(|| vqt_timestamp(q.ftTimeStamp));
            (
                h,
                ItemVqt {
                    value,
                    quality,
                    timestamp,
                },
            )
        })
        .collect()
}

/// The items of a Write call (value only; a 3-element array is the extended write).
pub(super) fn value_items(
    handles: &[u32],
    values: &[VARIANT],
    pre: &mut PreErrors,
) -> Vec<(u32, ItemVqt)> {
    handles
        .iter()
        .zip(values)
        .enumerate()
        .map(|(i, (&h, v))| (h, ItemVqt::value(pre.value(i, v))))
        .collect()
}

/// Fills ppErrors from per-item results; returns S_OK or S_FALSE.
pub(super) fn errors_out<R>(
    pp_errors: OutArray<HRESULT>,
    results: &[Result<R, OpcError>],
) -> ComResult<HRESULT> {
    let mut errors = TaskMem::<HRESULT>::zeroed(results.len())?;
    let mut failed = false;
    for (dst, r) in errors.as_mut_slice().iter_mut().zip(results) {
        *dst = item_hr(r);
        failed |= r.is_err();
    }
    pp_errors.set(errors);
    Ok(s_false_if(failed))
}

impl Group_Impl {
    /// A synchronous write (Write, WriteVQT): one engine call, then the wait.
    fn sync_write(
        &self,
        method: &str,
        items: Vec<(u32, ItemVqt)>,
        pre: PreErrors,
        pp_errors: OutArray<HRESULT>,
    ) -> ComResult<HRESULT> {
        let n = items.len();
        self.tell_caller();
        let (outcome, timeout, names) = self.ctx.runtime.with_engine(|e, now| {
            (
                e.write_vqt(now, self.handle, &items),
                e.config().source_timeout_ms,
                self.audit_names(e, &items),
            )
        });
        let mut results = complete(
            self,
            outcome.map_err(error::to_com)?,
            timeout,
            n,
            pick_write,
            write_timed_out,
        )?;
        pre.apply(&mut results);
        self.ctx.runtime.metrics.written(items.len() as u64);
        self.audit(method, names, &items, None, &results);
        self.warn_refused(&items, &results);
        errors_out(pp_errors, &results)
    }

    /// A WARN for the items the namespace refuses to write by design (read-only sources).
    fn warn_refused(&self, items: &[(u32, ItemVqt)], results: &[Result<(), OpcError>]) {
        if !results.contains(&Err(OpcError::BadRights)) {
            return;
        }
        let handles: Vec<u32> = items.iter().map(|(h, _)| *h).collect();
        self.ctx
            .runtime
            .warn_refused_writes(self.handle, &handles, results);
    }

    /// Tells the runtime who is calling before a write: the write-rights policy decides by
    /// it, the audit shows it (`crate::com::caller`; unknown, with the reason, where the
    /// platform cannot tell).
    pub(super) fn tell_caller(&self) {
        self.ctx
            .runtime
            .set_caller(self.session, crate::com::caller::current());
    }

    /// What the write audit needs of the engine (`None` when auditing is off): the group's
    /// name, the item IDs, and which items the write-rights policy refuses.
    fn audit_names(&self, e: &Engine, items: &[(u32, ItemVqt)]) -> Option<AuditNames> {
        if !self.ctx.runtime.clients.auditing() {
            return None;
        }
        let handles: Vec<u32> = items.iter().map(|(h, _)| *h).collect();
        let (group, ids) = e.audit_names(self.handle, &handles).ok()?;
        let denied = e.denied_by_policy(self.handle, &handles);
        Some(AuditNames { group, ids, denied })
    }

    /// The write audit's lines for a write of this group (`ctopc_runtime::clients`).
    fn audit(
        &self,
        method: &str,
        names: Option<AuditNames>,
        items: &[(u32, ItemVqt)],
        cancel_id: Option<u32>,
        results: &[Result<(), OpcError>],
    ) {
        let Some(AuditNames { group, ids, denied }) = names else {
            return;
        };
        let keys: Vec<(Option<&str>, Option<u32>)> = items
            .iter()
            .zip(&ids)
            .map(|((h, _), id)| (id.as_deref(), Some(*h)))
            .collect();
        let values: Vec<ItemVqt> = items.iter().map(|(_, v)| v.clone()).collect();
        let call = ctopc_runtime::clients::WriteCall {
            session: self.session,
            method,
            group: Some(&group),
            items: &keys,
            values: &values,
            cancel_id,
            denied: &denied,
        };
        self.ctx
            .runtime
            .clients
            .audit_write(clock::now(), &call, results);
    }

    /// A synchronous read (Read, ReadMaxAge): one engine call, then the wait.
    fn sync_read(
        &self,
        n: usize,
        call: impl FnOnce(&mut Engine, Timestamp) -> Result<SyncOutcome<ReadResults>, OpcError>,
    ) -> ComResult<ReadResults> {
        let (outcome, timeout) = self
            .ctx
            .runtime
            .with_engine(|e, now| (call(e, now), e.config().source_timeout_ms));
        complete(
            self,
            outcome.map_err(error::to_com)?,
            timeout,
            n,
            pick_read,
            read_timed_out,
        )
    }

    /// An asynchronous call: writes the cancel ID and the per-item errors.
    ///
    /// # Safety
    /// `p_cancel` was checked non-null and zeroed by [`cancel_out`] (the method's `[out]`
    /// parameter).
    /// Starts an asynchronous write of `items` (IOPCAsyncIO2::Write, IOPCAsyncIO3::WriteVQT)
    /// and hands out its results merged with the errors found before the engine call.
    ///
    /// # Safety
    /// `p_cancel` is the method's non-null `[out]` cancel ID (checked by the caller).
    unsafe fn async_write(
        &self,
        method: &str,
        transaction: u32,
        items: Vec<(u32, ItemVqt)>,
        pre: PreErrors,
        p_cancel: *mut u32,
        pp_errors: OutArray<HRESULT>,
    ) -> ComResult<HRESULT> {
        self.tell_caller();
        let (started, names) = self.ctx.runtime.with_engine(|e, now| {
            let started = self
                .data_callback_connected(e)
                .and_then(|()| e.async_write_vqt(now, self.handle, transaction, &items));
            (started, self.audit_names(e, &items))
        });
        let started = started.map(|mut s| {
            pre.apply(&mut s.results);
            s
        });
        if let Ok(s) = &started {
            self.ctx.runtime.metrics.written(items.len() as u64);
            self.audit(method, names, &items, Some(s.cancel_id), &s.results);
            self.warn_refused(&items, &s.results);
        }
        // SAFETY: the caller's contract.
        unsafe { self.async_out(started, p_cancel, pp_errors) }
    }

    unsafe fn async_out(
        &self,
        started: Result<AsyncStarted, OpcError>,
        p_cancel: *mut u32,
        pp_errors: OutArray<HRESULT>,
    ) -> ComResult<HRESULT> {
        let started = started.map_err(error::to_com)?;
        let hr = errors_out(pp_errors, &started.results)?;
        // SAFETY: checked non-null by the caller before the engine call.
        unsafe { p_cancel.write(started.cancel_id) };
        Ok(hr)
    }
}

/// Checks the cancel-ID out-pointer of an asynchronous call and zeroes it.
///
/// # Safety
/// As [`abi::write_out`]: `p` is the method's `[out]` parameter.
pub(super) unsafe fn cancel_out(p: *mut u32) -> ComResult<()> {
    // SAFETY: contract of this function.
    unsafe { write_out(p, 0) }
}

// ---- IOPCSyncIO -------------------------------------------------------------------------

impl Group_Impl {
    /// # Safety
    /// The pointers are the COM method's parameters, valid as its IDL says (checked here).
    unsafe fn read_impl(
        &self,
        source: OPCDATASOURCE,
        count: u32,
        ph_server: *const OPCHANDLE,
        pp_values: *mut *mut OPCITEMSTATE,
        pp_errors: *mut *mut HRESULT,
    ) -> ComResult<HRESULT> {
        // SAFETY: the method's [out] parameters.
        unsafe { abi::clear_outs((pp_values, pp_errors)) };
        let pp_values = OutArray::new(pp_values)?;
        let pp_errors = OutArray::new(pp_errors)?;
        let handles = in_array(ph_server, count)?;
        let source = data_source(source)?;
        let results = self.sync_read(handles.len(), |e, now| {
            e.read(now, self.handle, source, handles)
        })?;

        let mut states = OwnedArray::<OPCITEMSTATE>::zeroed(results.len())?;
        let mut errors = TaskMem::<HRESULT>::zeroed(results.len())?;
        let mut failed = false;
        for ((st, err), r) in states
            .as_mut_slice()
            .iter_mut()
            .zip(errors.as_mut_slice())
            .zip(&results)
        {
            let outcome = match r {
                Ok(ItemState {
                    client_handle,
                    value,
                    quality,
                    timestamp,
                }) => value_variant(value)?.map(|v| {
                    st.hClient = *client_handle;
                    st.ftTimeStamp = clock::filetime(*timestamp);
                    st.wQuality = quality.0;
                    st.vDataValue = v;
                }),
                Err(e) => Err(*e),
            };
            if let Err(e) = outcome {
                *err = error::hresult(e);
                failed = true;
            }
        }
        pp_values.set(states);
        pp_errors.set(errors);
        Ok(s_false_if(failed))
    }

    /// # Safety
    /// The pointers are the COM method's parameters, valid as its IDL says (checked here).
    unsafe fn write_impl(
        &self,
        count: u32,
        ph_server: *const OPCHANDLE,
        p_values: *const VARIANT,
        pp_errors: *mut *mut HRESULT,
    ) -> ComResult<HRESULT> {
        let pp_errors = OutArray::new(pp_errors)?;
        let handles = in_array(ph_server, count)?;
        let values = in_array(p_values, count)?;
        let mut pre = PreErrors::default();
        let items = value_items(handles, values, &mut pre);
        self.sync_write("IOPCSyncIO::Write", items, pre, pp_errors)
    }
}

impl IOPCSyncIO_Impl for Group_Impl {
    unsafe fn Read(
        &self,
        source: OPCDATASOURCE,
        count: u32,
        ph_server: *const OPCHANDLE,
        pp_values: *mut *mut OPCITEMSTATE,
        pp_errors: *mut *mut HRESULT,
    ) -> HRESULT {
        let _t = self.ctx.timed(Method::SyncRead);
        abi::hresult(self.read_impl(source, count, ph_server, pp_values, pp_errors))
    }

    unsafe fn Write(
        &self,
        count: u32,
        ph_server: *const OPCHANDLE,
        p_values: *const VARIANT,
        pp_errors: *mut *mut HRESULT,
    ) -> HRESULT {
        let _t = self.ctx.timed(Method::SyncWrite);
        abi::hresult(self.write_impl(count, ph_server, p_values, pp_errors))
    }
}

// ---- IOPCSyncIO2 ------------------------------------------------------------------------

impl Group_Impl {
    #[allow(clippy::too_many_arguments)]
    /// # Safety
    /// The pointers are the COM method's parameters, valid as its IDL says (checked here).
    unsafe fn read_max_age_impl(
        &self,
        count: u32,
        ph_server: *const OPCHANDLE,
        p_max_age: *const u32,
        pp_values: *mut *mut VARIANT,
        pp_qualities: *mut *mut u16,
        pp_times: *mut *mut FILETIME,
        pp_errors: *mut *mut HRESULT,
    ) -> ComResult<HRESULT> {
        // SAFETY: the method's [out] parameters.
        unsafe { abi::clear_outs((pp_values, pp_qualities, pp_times, pp_errors)) };
        let pp_values = OutArray::new(pp_values)?;
        let pp_qualities = OutArray::new(pp_qualities)?;
        let pp_times = OutArray::new(pp_times)?;
        let pp_errors = OutArray::new(pp_errors)?;
        let handles = in_array(ph_server, count)?;
        let ages = in_array(p_max_age, count)?;
        let items: Vec<(u32, u32)> = handles.iter().copied().zip(ages.iter().copied()).collect();
        let results = self.sync_read(items.len(), |e, now| {
            e.read_max_age(now, self.handle, &items)
        })?;
        drop(items);

        let n = results.len();
        let mut values = OwnedArray::<VARIANT>::zeroed(n)?;
        let mut qualities = TaskMem::<u16>::zeroed(n)?;
        let mut times = TaskMem::<FILETIME>::zeroed(n)?;
        let mut errors = TaskMem::<HRESULT>::zeroed(n)?;
        let mut failed = false;
        let outs = values
            .as_mut_slice()
            .iter_mut()
            .zip(qualities.as_mut_slice())
            .zip(times.as_mut_slice())
            .zip(errors.as_mut_slice());
        for ((((v, q), t), err), r) in outs.zip(&results) {
            let outcome = match r {
                Ok(s) => value_variant(&s.value)?.map(|var| {
                    *v = var;
                    *q = s.quality.0;
                    *t = clock::filetime(s.timestamp);
                }),
                Err(e) => Err(*e),
            };
            if let Err(e) = outcome {
                // A failed item reads VT_EMPTY with quality BAD (OPC DA 3.0 ReadMaxAge).
                *q = Quality::BAD.0;
                *err = error::hresult(e);
                failed = true;
            }
        }
        pp_values.set(values);
        pp_qualities.set(qualities);
        pp_times.set(times);
        pp_errors.set(errors);
        Ok(s_false_if(failed))
    }

    /// # Safety
    /// The pointers are the COM method's parameters, valid as its IDL says (checked here).
    unsafe fn write_vqt_impl(
        &self,
        count: u32,
        ph_server: *const OPCHANDLE,
        p_vqt: *const OPCITEMVQT,
        pp_errors: *mut *mut HRESULT,
    ) -> ComResult<HRESULT> {
        let pp_errors = OutArray::new(pp_errors)?;
        let handles = in_array(ph_server, count)?;
        let vqts = in_array(p_vqt, count)?;
        let mut pre = PreErrors::default();
        let items = vqt_items(handles, vqts, &mut pre);
        self.sync_write("IOPCSyncIO2::WriteVQT", items, pre, pp_errors)
    }
}

impl IOPCSyncIO2_Impl for Group_Impl {
    unsafe fn ReadMaxAge(
        &self,
        count: u32,
        ph_server: *const OPCHANDLE,
        p_max_age: *const u32,
        pp_values: *mut *mut VARIANT,
        pp_qualities: *mut *mut u16,
        pp_times: *mut *mut FILETIME,
        pp_errors: *mut *mut HRESULT,
    ) -> HRESULT {
        let _t = self.ctx.timed(Method::ReadMaxAge);
        abi::hresult(self.read_max_age_impl(
            count,
            ph_server,
            p_max_age,
            pp_values,
            pp_qualities,
            pp_times,
            pp_errors,
        ))
    }

    unsafe fn WriteVQT(
        &self,
        count: u32,
        ph_server: *const OPCHANDLE,
        p_vqt: *const OPCITEMVQT,
        pp_errors: *mut *mut HRESULT,
    ) -> HRESULT {
        let _t = self.ctx.timed(Method::WriteVqt);
        abi::hresult(self.write_vqt_impl(count, ph_server, p_vqt, pp_errors))
    }
}

// ---- IOPCAsyncIO2 -----------------------------------------------------------------------

impl Group_Impl {
    /// IOPCAsyncIO2/3 complete through IOPCDataCallback only: CONNECT_E_NOCONNECTION
    /// without one, also while DA 1.0a sinks keep the engine's group connected (checked
    /// under the engine lock after the group itself: a removed group stays E_FAIL).
    fn data_callback_connected(&self, e: &Engine) -> Result<(), OpcError> {
        e.callback_connected(self.handle)?;
        if self.sink.is_connected() {
            Ok(())
        } else {
            Err(OpcError::NoConnection)
        }
    }

    /// # Safety
    /// The pointers are the COM method's parameters, valid as its IDL says (checked here).
    unsafe fn async_read_impl(
        &self,
        count: u32,
        ph_server: *const OPCHANDLE,
        transaction: u32,
        p_cancel: *mut u32,
        pp_errors: *mut *mut HRESULT,
    ) -> ComResult<HRESULT> {
        // SAFETY: the method's [out] parameters.
        unsafe { abi::clear_outs((p_cancel, pp_errors)) };
        let pp_errors = OutArray::new(pp_errors)?;
        cancel_out(p_cancel)?;
        let handles = in_array(ph_server, count)?;
        let started = self.ctx.runtime.with_engine(|e, now| {
            self.data_callback_connected(e)?;
            e.async_read(now, self.handle, transaction, handles)
        });
        self.async_out(started, p_cancel, pp_errors)
    }

    /// # Safety
    /// The pointers are the COM method's parameters, valid as its IDL says (checked here).
    unsafe fn async_write_impl(
        &self,
        count: u32,
        ph_server: *const OPCHANDLE,
        p_values: *const VARIANT,
        transaction: u32,
        p_cancel: *mut u32,
        pp_errors: *mut *mut HRESULT,
    ) -> ComResult<HRESULT> {
        // SAFETY: the method's [out] parameters.
        unsafe { abi::clear_outs((p_cancel, pp_errors)) };
        let pp_errors = OutArray::new(pp_errors)?;
        cancel_out(p_cancel)?;
        let handles = in_array(ph_server, count)?;
        let values = in_array(p_values, count)?;
        let mut pre = PreErrors::default();
        let items = value_items(handles, values, &mut pre);
        // SAFETY: p_cancel was checked non-null by cancel_out above.
        unsafe {
            self.async_write(
                "IOPCAsyncIO2::Write",
                transaction,
                items,
                pre,
                p_cancel,
                pp_errors,
            )
        }
    }

    /// # Safety
    /// The pointers are the COM method's parameters, valid as its IDL says (checked here).
    unsafe fn refresh_impl(
        &self,
        p_cancel: *mut u32,
        call: impl FnOnce(&mut Engine, Timestamp) -> Result<u32, OpcError>,
    ) -> ComResult<()> {
        cancel_out(p_cancel)?;
        let cancel_id = self
            .ctx
            .runtime
            .with_engine(|e, now| {
                self.data_callback_connected(e)?;
                call(e, now)
            })
            .map_err(error::to_com)?;
        write_out(p_cancel, cancel_id)
    }
}

impl IOPCAsyncIO2_Impl for Group_Impl {
    unsafe fn Read(
        &self,
        count: u32,
        ph_server: *const OPCHANDLE,
        transaction: u32,
        p_cancel: *mut u32,
        pp_errors: *mut *mut HRESULT,
    ) -> HRESULT {
        let _t = self.ctx.timed(Method::AsyncRead);
        abi::hresult(self.async_read_impl(count, ph_server, transaction, p_cancel, pp_errors))
    }

    unsafe fn Write(
        &self,
        count: u32,
        ph_server: *const OPCHANDLE,
        p_values: *const VARIANT,
        transaction: u32,
        p_cancel: *mut u32,
        pp_errors: *mut *mut HRESULT,
    ) -> HRESULT {
        let _t = self.ctx.timed(Method::AsyncWrite);
        abi::hresult(self.async_write_impl(
            count,
            ph_server,
            p_values,
            transaction,
            p_cancel,
            pp_errors,
        ))
    }

    unsafe fn Refresh2(
        &self,
        source: OPCDATASOURCE,
        transaction: u32,
        p_cancel: *mut u32,
    ) -> windows::core::Result<()> {
        let _t = self.ctx.timed(Method::Refresh2);
        // SAFETY: the method's [out] parameter.
        unsafe { abi::clear_outs((p_cancel,)) };
        let source = data_source(source)?;
        self.refresh_impl(p_cancel, |e, now| {
            e.refresh2(now, self.handle, source, transaction)
        })
    }

    unsafe fn Cancel2(&self, cancel_id: u32) -> windows::core::Result<()> {
        self.ctx
            .runtime
            .with_engine(|e, _| e.cancel2(self.handle, cancel_id))
            .map_err(error::to_com)
    }

    unsafe fn SetEnable(&self, enable: BOOL) -> windows::core::Result<()> {
        self.ctx
            .runtime
            .with_engine(|e, now| e.set_enable(now, self.handle, enable.as_bool()))
            .map_err(error::to_com)
    }

    unsafe fn GetEnable(&self, p_enable: *mut BOOL) -> windows::core::Result<()> {
        // SAFETY: the method's [out] parameter.
        unsafe { abi::clear_outs((p_enable,)) };
        if p_enable.is_null() {
            return Err(E_INVALIDARG.into());
        }
        let enabled = self
            .ctx
            .runtime
            .with_engine(|e, _| e.get_enable(self.handle))
            .map_err(error::to_com)?;
        write_out(p_enable, BOOL::from(enabled))
    }
}

// ---- IOPCAsyncIO3 -----------------------------------------------------------------------

impl Group_Impl {
    /// # Safety
    /// The pointers are the COM method's parameters, valid as its IDL says (checked here).
    unsafe fn async_read_max_age_impl(
        &self,
        count: u32,
        ph_server: *const OPCHANDLE,
        p_max_age: *const u32,
        transaction: u32,
        p_cancel: *mut u32,
        pp_errors: *mut *mut HRESULT,
    ) -> ComResult<HRESULT> {
        // SAFETY: the method's [out] parameters.
        unsafe { abi::clear_outs((p_cancel, pp_errors)) };
        let pp_errors = OutArray::new(pp_errors)?;
        cancel_out(p_cancel)?;
        let handles = in_array(ph_server, count)?;
        let ages = in_array(p_max_age, count)?;
        let items: Vec<(u32, u32)> = handles.iter().copied().zip(ages.iter().copied()).collect();
        let started = self.ctx.runtime.with_engine(|e, now| {
            self.data_callback_connected(e)?;
            e.async_read_max_age(now, self.handle, transaction, &items)
        });
        self.async_out(started, p_cancel, pp_errors)
    }

    /// # Safety
    /// The pointers are the COM method's parameters, valid as its IDL says (checked here).
    unsafe fn async_write_vqt_impl(
        &self,
        count: u32,
        ph_server: *const OPCHANDLE,
        p_vqt: *const OPCITEMVQT,
        transaction: u32,
        p_cancel: *mut u32,
        pp_errors: *mut *mut HRESULT,
    ) -> ComResult<HRESULT> {
        // SAFETY: the method's [out] parameters.
        unsafe { abi::clear_outs((p_cancel, pp_errors)) };
        let pp_errors = OutArray::new(pp_errors)?;
        cancel_out(p_cancel)?;
        let handles = in_array(ph_server, count)?;
        let vqts = in_array(p_vqt, count)?;
        let mut pre = PreErrors::default();
        let items = vqt_items(handles, vqts, &mut pre);
        // SAFETY: p_cancel was checked non-null by cancel_out above.
        unsafe {
            self.async_write(
                "IOPCAsyncIO3::WriteVQT",
                transaction,
                items,
                pre,
                p_cancel,
                pp_errors,
            )
        }
    }
}

impl IOPCAsyncIO3_Impl for Group_Impl {
    unsafe fn ReadMaxAge(
        &self,
        count: u32,
        ph_server: *const OPCHANDLE,
        p_max_age: *const u32,
        transaction: u32,
        p_cancel: *mut u32,
        pp_errors: *mut *mut HRESULT,
    ) -> HRESULT {
        let _t = self.ctx.timed(Method::AsyncReadMaxAge);
        abi::hresult(self.async_read_max_age_impl(
            count,
            ph_server,
            p_max_age,
            transaction,
            p_cancel,
            pp_errors,
        ))
    }

    unsafe fn WriteVQT(
        &self,
        count: u32,
        ph_server: *const OPCHANDLE,
        p_vqt: *const OPCITEMVQT,
        transaction: u32,
        p_cancel: *mut u32,
        pp_errors: *mut *mut HRESULT,
    ) -> HRESULT {
        let _t = self.ctx.timed(Method::AsyncWriteVqt);
        abi::hresult(self.async_write_vqt_impl(
            count,
            ph_server,
            p_vqt,
            transaction,
            p_cancel,
            pp_errors,
        ))
    }

    unsafe fn RefreshMaxAge(
        &self,
        max_age: u32,
        transaction: u32,
        p_cancel: *mut u32,
    ) -> windows::core::Result<()> {
        self.refresh_impl(p_cancel, |e, now| {
            e.refresh_max_age(now, self.handle, max_age, transaction)
        })
    }
}
