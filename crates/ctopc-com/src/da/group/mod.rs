//! The OPC group object: IOPCItemMgt, IOPCGroupStateMgt/2, IOPCItemDeadbandMgt,
//! IOPCItemSamplingMgt, IConnectionPointContainer (one point, IOPCDataCallback), in
//! [`io`] the sync and async I/O interfaces, and DA 1.0a's IOPCAsyncIO (`async1.rs`) and
//! IDataObject ([`dataobject`]).
//!
//! **One COM identity per engine group**: the context's group table ([`GroupTable`], one
//! per runtime, `Context::groups`) maps each engine group to a weak reference to its live COM
//! object and to the object's callback slot.
//! [`lookup_or_create`] hands out the live object or makes a new one; [`create`] always
//! makes a new one (AddGroup, CloneGroup). Each object holds one engine reference
//! (`group_add_ref`), released by `Drop` (`group_release`): a group removed with
//! OPC_S_INUSE is freed there. The object's IOPCDataCallback slot is registered with the
//! runtime while the object lives, so that the callback workers deliver to it; dropping
//! the object unregisters it (and disconnects a sink the client did not unadvise).
//!
//! Lock order: the group table, then the runtime's locks. No strong reference to a group
//! object is ever dropped while the group table is locked (its `Drop` takes the lock).

mod async1;
pub mod dataobject;
mod io;
mod items;

use crate::com::abi::{self, item_hr, s_false_if_any, OutArray, TaskMem};
use crate::com::comdef::{
    RawConnectionPointContainer, RawConnectionPointContainer_Impl, RawDataObject,
};
use crate::com::connpoint::{self, SinkSlot, Slot};
use crate::com::error;
use crate::com::interfaces::*;
use crate::com::lifetime::ObjectGuard;
use crate::da::context::{Context, Entry};
use ctopc_core::limits;
use ctopc_core::model::{Engine, GroupHandle, SessionHandle, SetGroupState};
use ctopc_core::{OpcError, Timestamp};
use std::collections::BTreeMap;
use std::sync::Arc;
use windows::core::{
    implement, IUnknown, IUnknownImpl, Interface, BOOL, GUID, HRESULT, PCWSTR, PWSTR,
};
use windows::Win32::Foundation::{E_FAIL, E_INVALIDARG, E_OUTOFMEMORY, S_OK};
use windows::Win32::System::Com::{IConnectionPoint, IEnumConnectionPoints};
use windows_core::Weak;

pub use items::ItemAttributesEnum;

#[implement(
    IOPCItemMgt,
    IOPCGroupStateMgt,
    IOPCGroupStateMgt2,
    IOPCSyncIO,
    IOPCSyncIO2,
    IOPCAsyncIO2,
    IOPCAsyncIO3,
    IOPCItemDeadbandMgt,
    IOPCItemSamplingMgt,
    RawConnectionPointContainer,
    IOPCAsyncIO,
    RawDataObject
)]
pub struct Group {
    pub(crate) ctx: Arc<Context>,
    pub(crate) session: SessionHandle,
    pub(crate) handle: GroupHandle,
    /// The IOPCDataCallback connection (registered with the runtime while the object lives).
    pub(crate) sink: Arc<SinkSlot<IOPCDataCallback>>,
    /// The DA 1.0a IDataObject advise connections (registered with the runtime too).
    pub(crate) da10: Arc<dataobject::Da10Sinks>,
    /// The connection point's view of `sink`: tells the engine about Advise/Unadvise.
    point: Arc<dyn Slot>,
    _guard: ObjectGuard,
}

/// A new COM object for the engine group `group` (AddGroup, CloneGroup): takes an engine
/// reference, registers the object's callback slot with the runtime and makes it the
/// group's identity for [`lookup_or_create`].
pub fn create(
    ctx: &Arc<Context>,
    session: SessionHandle,
    group: GroupHandle,
) -> windows::core::Result<IUnknown> {
    let mut reg = ctx.groups.lock();
    create_locked(&mut reg, ctx, session, group)
}

/// The COM object of the engine group `group`: the live one if there is one (same
/// identity for every caller), else a new one as [`create`] makes.
pub fn lookup_or_create(
    ctx: &Arc<Context>,
    session: SessionHandle,
    group: GroupHandle,
) -> windows::core::Result<IUnknown> {
    let mut reg = ctx.groups.lock();
    if let Some(live) = reg.get(&group).and_then(|e| e.object.upgrade()) {
        // Returned to the caller: not dropped under the lock.
        return Ok(live);
    }
    create_locked(&mut reg, ctx, session, group)
}

fn create_locked(
    reg: &mut BTreeMap<GroupHandle, Entry>,
    ctx: &Arc<Context>,
    session: SessionHandle,
    group: GroupHandle,
) -> windows::core::Result<IUnknown> {
    ctx.runtime
        .with_engine(|e, _| e.group_add_ref(group))
        .map_err(error::to_com)?;
    let sink = Arc::new(SinkSlot::<IOPCDataCallback>::default());
    let da10 = Arc::new(dataobject::Da10Sinks::default());
    let point: Arc<dyn Slot> = Arc::new(DataCallbackPoint {
        ctx: Arc::clone(ctx),
        group,
        slot: Arc::clone(&sink),
        da10: Arc::clone(&da10),
    });
    let object = Group {
        ctx: Arc::clone(ctx),
        session,
        handle: group,
        sink: Arc::clone(&sink),
        da10: Arc::clone(&da10),
        point,
        _guard: ObjectGuard::new(&ctx.lifetime),
    };
    let unknown: IUnknown = object.into();
    // Nothing below may fail: dropping `unknown` here would run `Drop`, which locks the
    // registry. Without a weak reference (not expected: every #[implement] object has
    // one) the entry still tracks the slot, and the next lookup makes a new object.
    let weak = match unknown.downgrade() {
        Ok(w) => w,
        Err(e) => {
            tracing::error!(
                "group {}: no weak reference ({e}); its COM identity is not shared",
                group.0
            );
            Weak::new()
        }
    };
    // A previous entry's object is dead, or dying (its `Drop` waits for the lock and then
    // leaves the new entry alone). Dropping its weak reference releases only the weak
    // tear-off, never a group object.
    reg.insert(
        group,
        Entry {
            object: weak,
            slot: Arc::clone(&sink),
        },
    );
    ctx.runtime
        .set_group_sink(group, Arc::new(dataobject::GroupSinks { slot: sink, da10 }));
    Ok(unknown)
}

impl Drop for Group {
    fn drop(&mut self) {
        let handle = self.handle;
        // Unregister only if this object is still the group's identity (a new object may
        // have replaced it between its last Release and this Drop).
        let (mine, old) = {
            let mut reg = self.ctx.groups.lock();
            if reg
                .get(&handle)
                .is_some_and(|e| Arc::ptr_eq(&e.slot, &self.sink))
            {
                self.ctx.runtime.remove_group_sink(handle);
                (true, reg.remove(&handle))
            } else {
                (false, None)
            }
        };
        drop(old);
        // A sink the client did not unadvise: release it (no lock held) and tell the engine.
        let cookie = self.sink.cookie();
        if let Some(c) = cookie {
            self.sink.drop_if(c);
        }
        let da10 = self.da10.clear();
        let disconnect = mine && (cookie.is_some() || da10);
        let _ = self.ctx.runtime.with_engine(|e, now| {
            if disconnect {
                let _ = e.set_callback_connected(now, handle, false);
            }
            e.group_release(now, handle)
        });
    }
}

// ---------------------------------------------------------------------------------------
// The per-item shape of the group's COM methods (argument helpers: `crate::com::abi`)
// ---------------------------------------------------------------------------------------

impl Group_Impl {
    /// Runs one core call on the engine.
    pub(crate) fn engine<R>(&self, f: impl FnOnce(&mut Engine, Timestamp, GroupHandle) -> R) -> R {
        let handle = self.handle;
        self.ctx.runtime.with_engine(|e, now| f(e, now, handle))
    }

    /// The shape of every per-item call with a value array and an error array: output
    /// arrays allocated before the core call (so that nothing can fail after it), one
    /// core call, per-item results mapped by `map` to (value, HRESULT), S_FALSE when any
    /// item failed. `n` is the call's item count (checked non-zero by the caller).
    pub(crate) fn per_item_values<R, V>(
        &self,
        n: usize,
        values: OutArray<V>,
        errors: OutArray<HRESULT>,
        call: impl FnOnce(
            &mut Engine,
            Timestamp,
            GroupHandle,
        ) -> Result<Vec<Result<R, OpcError>>, OpcError>,
        map: impl Fn(Result<R, OpcError>) -> (V, HRESULT),
    ) -> HRESULT {
        let (Ok(mut vals), Ok(mut errs)) = (TaskMem::<V>::zeroed(n), TaskMem::<HRESULT>::zeroed(n))
        else {
            return E_OUTOFMEMORY;
        };
        let results = match self.engine(call) {
            Ok(r) => r,
            Err(e) => return error::hresult(e),
        };
        if results.len() != n {
            return E_FAIL;
        }
        for ((r, v), e) in results
            .into_iter()
            .zip(vals.as_mut_slice().iter_mut())
            .zip(errs.as_mut_slice().iter_mut())
        {
            let (value, hr) = map(r);
            *v = value;
            *e = hr;
        }
        let hr = s_false_if_any(errs.as_mut_slice());
        values.set(vals);
        errors.set(errs);
        hr
    }

    /// As [`Self::per_item_values`] for calls that return only the error array.
    pub(crate) fn per_item(
        &self,
        n: usize,
        errors: OutArray<HRESULT>,
        call: impl FnOnce(
            &mut Engine,
            Timestamp,
            GroupHandle,
        ) -> Result<Vec<Result<(), OpcError>>, OpcError>,
    ) -> HRESULT {
        let Ok(mut errs) = TaskMem::<HRESULT>::zeroed(n) else {
            return E_OUTOFMEMORY;
        };
        let results = match self.engine(call) {
            Ok(r) => r,
            Err(e) => return error::hresult(e),
        };
        if results.len() != n {
            return E_FAIL;
        }
        for (r, e) in results.iter().zip(errs.as_mut_slice().iter_mut()) {
            *e = item_hr(r);
        }
        let hr = s_false_if_any(errs.as_mut_slice());
        errors.set(errs);
        hr
    }
}

// ---------------------------------------------------------------------------------------
// IOPCGroupStateMgt / IOPCGroupStateMgt2
// ---------------------------------------------------------------------------------------

impl IOPCGroupStateMgt_Impl for Group_Impl {
    /// Every out-parameter is required (`[out]` in the IDL, so a remote client cannot pass
    /// NULL; an in-process one gets E_INVALIDARG and nothing is written).
    unsafe fn GetState(
        &self,
        pupdaterate: *mut u32,
        pactive: *mut BOOL,
        ppname: *mut PWSTR,
        ptimebias: *mut i32,
        ppercentdeadband: *mut f32,
        plcid: *mut LCID,
        phclientgroup: *mut OPCHANDLE,
        phservergroup: *mut OPCHANDLE,
    ) -> windows::core::Result<()> {
        if pupdaterate.is_null()
            || pactive.is_null()
            || ppname.is_null()
            || ptimebias.is_null()
            || ppercentdeadband.is_null()
            || plcid.is_null()
            || phclientgroup.is_null()
            || phservergroup.is_null()
        {
            return Err(E_INVALIDARG.into());
        }
        // SAFETY: checked non-null above.
        unsafe { ppname.write(PWSTR::null()) };
        let s = self
            .engine(|e, _, g| e.group_state(g))
            .map_err(error::to_com)?;
        let name = abi::alloc_wstr(&s.name)?;
        // SAFETY: every pointer was checked non-null above; all allocation has succeeded.
        unsafe {
            pupdaterate.write(s.update_rate);
            pactive.write(BOOL::from(s.active));
            ppname.write(name);
            ptimebias.write(s.time_bias);
            ppercentdeadband.write(s.percent_deadband);
            plcid.write(s.lcid);
            phclientgroup.write(s.client_handle);
            phservergroup.write(s.server_handle.0);
        }
        Ok(())
    }

    unsafe fn SetState(
        &self,
        prequestedupdaterate: *const u32,
        previsedupdaterate: *mut u32,
        pactive: *const BOOL,
        ptimebias: *const i32,
        ppercentdeadband: *const f32,
        plcid: *const LCID,
        phclientgroup: *const OPCHANDLE,
    ) -> HRESULT {
        // SAFETY: this method's [out] parameter.
        unsafe { abi::clear_outs((previsedupdaterate,)) };
        if previsedupdaterate.is_null() {
            return E_INVALIDARG;
        }
        // The LCID rule of AddGroup (E_INVALIDARG, nothing changed).
        if let Some(lcid) = abi::in_opt(plcid) {
            if !crate::da::context::lcid_accepted(lcid) {
                return E_INVALIDARG;
            }
        }
        let state = SetGroupState {
            update_rate: abi::in_opt(prequestedupdaterate),
            active: abi::in_opt(pactive).map(|b| b.as_bool()),
            time_bias: abi::in_opt(ptimebias),
            percent_deadband: abi::in_opt(ppercentdeadband),
            lcid: abi::in_opt(plcid),
            client_handle: abi::in_opt(phclientgroup),
        };
        match self.engine(|e, now, g| e.set_group_state(now, g, &state)) {
            Ok(rate) => {
                // SAFETY: checked non-null above.
                unsafe { previsedupdaterate.write(rate.value) };
                rate.code().map_or(S_OK, error::hresult)
            }
            Err(e) => error::hresult(e),
        }
    }

    unsafe fn SetName(&self, szname: PCWSTR) -> windows::core::Result<()> {
        let name = abi::in_string(szname, limits::GROUP_NAME)?;
        self.engine(|e, _, g| e.set_group_name(g, &name))
            .map_err(error::to_com)
    }

    unsafe fn CloneGroup(
        &self,
        szname: PCWSTR,
        riid: *const GUID,
        ppunk: *mut Option<IUnknown>,
    ) -> windows::core::Result<()> {
        // SAFETY: this method's [out] interface pointer.
        unsafe { abi::clear_outs((ppunk,)) };
        if riid.is_null() || ppunk.is_null() {
            return Err(E_INVALIDARG.into());
        }
        let name = abi::in_string(szname, limits::GROUP_NAME)?;
        // SAFETY: checked non-null; an [in] REFIID.
        let iid = unsafe { *riid };
        let new = self
            .engine(|e, now, g| e.clone_group(now, g, &name))
            .map_err(error::to_com)?;
        let session = self.session;
        let undo = || {
            let _ = self
                .ctx
                .runtime
                .with_engine(|e, now| e.remove_group(now, session, new, true));
        };
        let object = match create(&self.ctx, session, new) {
            Ok(o) => o,
            Err(e) => {
                undo();
                return Err(e);
            }
        };
        let mut out: *mut std::ffi::c_void = std::ptr::null_mut();
        // SAFETY: `iid` is a valid GUID and `out` a valid out-pointer for the interface.
        let hr = unsafe { object.query(&iid, &mut out) };
        if hr.is_err() || out.is_null() {
            // All-or-nothing: the new object goes (its Drop releases the engine
            // reference) and so does its group.
            drop(object);
            undo();
            return Err(if hr.is_err() { hr } else { E_FAIL }.into());
        }
        // SAFETY: QueryInterface succeeded: `out` is an AddRef'd pointer of interface
        // `iid`, which the [iid_is(riid)] out-parameter carries as an IUnknown.
        unsafe { ppunk.write(Some(IUnknown::from_raw(out))) };
        Ok(())
    }
}

impl IOPCGroupStateMgt2_Impl for Group_Impl {
    unsafe fn SetKeepAlive(
        &self,
        dwkeepalivetime: u32,
        pdwrevisedkeepalivetime: *mut u32,
    ) -> HRESULT {
        // SAFETY: this method's [out] parameter.
        unsafe { abi::clear_outs((pdwrevisedkeepalivetime,)) };
        if pdwrevisedkeepalivetime.is_null() {
            return E_INVALIDARG;
        }
        match self.engine(|e, now, g| e.set_keep_alive(now, g, dwkeepalivetime)) {
            Ok(r) => {
                // SAFETY: checked non-null above.
                unsafe { pdwrevisedkeepalivetime.write(r.value) };
                r.code().map_or(S_OK, error::hresult)
            }
            Err(e) => error::hresult(e),
        }
    }

    unsafe fn GetKeepAlive(&self, pdwkeepalivetime: *mut u32) -> windows::core::Result<()> {
        if pdwkeepalivetime.is_null() {
            return Err(E_INVALIDARG.into());
        }
        let t = self
            .engine(|e, _, g| e.keep_alive(g))
            .map_err(error::to_com)?;
        abi::write_out(pdwkeepalivetime, t)
    }
}

// ---------------------------------------------------------------------------------------
// IConnectionPointContainer: one point, IOPCDataCallback
// ---------------------------------------------------------------------------------------

/// The group's IOPCDataCallback point: the slot, plus telling the engine whether a sink is
/// connected (callbacks are only scheduled for connected groups).
struct DataCallbackPoint {
    ctx: Arc<Context>,
    group: GroupHandle,
    slot: Arc<SinkSlot<IOPCDataCallback>>,
    /// The group's DA 1.0a sinks: the engine stays connected while one is advised.
    da10: Arc<dataobject::Da10Sinks>,
}

impl Slot for DataCallbackPoint {
    fn advise(&self, unk: &IUnknown) -> windows::core::Result<u32> {
        let cookie = Slot::advise(&*self.slot, unk)?;
        let group = self.group;
        if let Err(e) = self
            .ctx
            .runtime
            .with_engine(|e, now| e.set_callback_connected(now, group, true))
        {
            // The group was removed: no connection (the sink is released, no lock held).
            let _ = Slot::unadvise(&*self.slot, cookie);
            return Err(error::to_com(e));
        }
        Ok(cookie)
    }

    fn unadvise(&self, cookie: u32) -> windows::core::Result<()> {
        Slot::unadvise(&*self.slot, cookie)?;
        let group = self.group;
        let connected = self.da10.any();
        let _ = self
            .ctx
            .runtime
            .with_engine(|e, now| e.set_callback_connected(now, group, connected));
        Ok(())
    }

    fn connections(&self) -> Vec<(u32, IUnknown)> {
        Slot::connections(&*self.slot)
    }
}

impl Group_Impl {
    fn points(&self) -> [(GUID, Arc<dyn Slot>); 1] {
        [(IOPCDataCallback::IID, Arc::clone(&self.point))]
    }
}

impl RawConnectionPointContainer_Impl for Group_Impl {
    unsafe fn EnumConnectionPoints(&self, ppenum: *mut Option<IEnumConnectionPoints>) -> HRESULT {
        let container = self.to_interface::<RawConnectionPointContainer>().into();
        // SAFETY: `ppenum` is this method's [out] interface pointer.
        unsafe { connpoint::enumerate(container, &self.points(), ppenum) }
    }

    unsafe fn FindConnectionPoint(
        &self,
        riid: *const GUID,
        ppcp: *mut Option<IConnectionPoint>,
    ) -> HRESULT {
        let container = self.to_interface::<RawConnectionPointContainer>().into();
        // SAFETY: `riid` is this method's [in] REFIID, `ppcp` its [out] interface pointer.
        unsafe { connpoint::find(container, &self.points(), riid, ppcp) }
    }
}
