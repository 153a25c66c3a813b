//! IOPCServer's group methods: AddGroup, GetGroupByName, RemoveGroup,
//! CreateGroupEnumerator. The group objects themselves are `crate::da::group`'s; one engine
//! group keeps one COM identity ([`group_object`]).
//!
//! Choices where the specification leaves room (evidence: OPC DA 2.05a/3.0 method texts;
//! the OPC Foundation sample server `COpcDaServer.cpp`, "sample"):
//! - AddGroup: a NULL pTimeBias is the machine's bias (`GetTimeZoneInformation().Bias`,
//!   as the sample), a NULL pPercentDeadband is 0. The LCID must be one the server speaks
//!   (Polish, any English, the neutral/default locales) or at least a locale Windows knows
//!   (`IsValidLocale(LCID_SUPPORTED)`; texts then come in English and numbers convert in
//!   en-US format); anything else is E_INVALIDARG, the spec's code for invalid
//!   arguments. The sample accepts any value; rejecting unknown locale IDs catches clients
//!   passing garbage without locking out German or French clients that pass their own
//!   locale. The group is created, then queried for `riid`: when that fails it is removed
//!   again (all or nothing) and the call answers E_NOINTERFACE.
//! - GetGroupByName: an unknown name is E_INVALIDARG. The method's code list (S_OK,
//!   E_FAIL, E_INVALIDARG, E_OUTOFMEMORY, E_NOINTERFACE) has no "not found" code
//!   (OPC_E_NOTFOUND belongs to public groups); the sample answers E_INVALIDARG too.
//! - RemoveGroup: a handle that is not a group of this client is E_INVALIDARG (the
//!   method's codes are S_OK, OPC_S_INUSE, E_FAIL, E_INVALIDARG; OPC_E_INVALIDHANDLE is
//!   for item handles; the sample answers E_FAIL). Without bForce, a group
//!   whose COM object is still referenced is marked deleted and the call answers
//!   OPC_S_INUSE; it goes when the last reference is released.
//! - CreateGroupEnumerator: ServerCTOPC has no public groups, so the private and "all"
//!   scopes list this client's groups and the public scopes are empty (S_FALSE with an
//!   empty enumerator, as the sample). IID_IEnumString lists names, IID_IEnumUnknown the
//!   group objects; any other riid is E_NOINTERFACE (sample); a scope outside the IDL's is
//!   E_INVALIDARG.

use super::OpcServer;
use crate::com::abi::{self, clear, clear_outs, in_string, nonnull, put, query_out};
use crate::com::enums::{StringEnum, UnknownEnum};
use crate::com::interfaces::*;
use crate::da::context::Context;
use ctopc_core::limits;
use ctopc_core::model::{GroupHandle, GroupParams, RemoveGroupOutcome, SessionHandle};
use ctopc_core::OpcError;
use std::sync::Arc;
use windows::core::{IUnknown, Interface, BOOL, GUID, HRESULT, PCWSTR};
use windows::Win32::Foundation::{E_NOINTERFACE, S_FALSE, S_OK};
use windows::Win32::System::Com::{IEnumString, IEnumUnknown};
use windows::Win32::System::Time::{GetTimeZoneInformation, TIME_ZONE_INFORMATION};

/// The COM object of an engine group: the existing one while it lives, else a new one
/// (`crate::da::group`'s group table keeps one identity per group).
fn group_object(
    ctx: &Arc<Context>,
    session: SessionHandle,
    group: GroupHandle,
) -> windows::core::Result<IUnknown> {
    crate::da::group::lookup_or_create(ctx, session, group)
}

/// A new COM object for a group just added (it becomes the group's identity).
fn new_group_object(
    ctx: &Arc<Context>,
    session: SessionHandle,
    group: GroupHandle,
) -> windows::core::Result<IUnknown> {
    crate::da::group::create(ctx, session, group)
}

/// AddGroup's `[in]` arguments.
pub struct AddGroupArgs {
    pub name: PCWSTR,
    pub active: BOOL,
    pub rate: u32,
    pub client: u32,
    pub bias: *const i32,
    pub deadband: *const f32,
    pub lcid: u32,
}

/// The machine's time bias in minutes (UTC = local + bias), as AddGroup's default.
pub fn local_time_bias() -> i32 {
    let mut tz = TIME_ZONE_INFORMATION::default();
    // SAFETY: `tz` is a valid, writable TIME_ZONE_INFORMATION.
    let r = unsafe { GetTimeZoneInformation(&mut tz) };
    if r == u32::MAX {
        0
    } else {
        tz.Bias
    }
}

impl OpcServer {
    fn remove_forced(&self, group: GroupHandle) {
        let _ = self
            .ctx
            .runtime
            .with_engine(|e, now| e.remove_group(now, self.handle, group, true));
    }

    /// # Safety
    /// The pointers are the parameters of the COM method (IOPCServer::AddGroup), valid as its IDL
    /// says (each may be NULL: checked here).
    pub(super) unsafe fn add_group(
        &self,
        a: &AddGroupArgs,
        pserver: *mut u32,
        prevised: *mut u32,
        riid: *const GUID,
        ppunk: *mut Option<IUnknown>,
    ) -> windows::core::Result<HRESULT> {
        clear_outs((pserver, prevised, ppunk));
        nonnull(pserver)?;
        nonnull(prevised)?;
        nonnull(riid)?;
        nonnull(ppunk)?;
        let name = in_string(a.name, limits::GROUP_NAME)?;
        if !crate::da::context::lcid_accepted(a.lcid) {
            return Err(abi::invalid_arg());
        }
        let params = GroupParams {
            name: &name,
            active: a.active.as_bool(),
            update_rate: a.rate,
            client_handle: a.client,
            time_bias: abi::in_opt(a.bias).unwrap_or_else(local_time_bias),
            percent_deadband: abi::in_opt(a.deadband).unwrap_or(0.0),
            lcid: a.lcid,
        };
        let added = self
            .ctx
            .runtime
            .with_engine(|e, now| e.add_group(now, self.handle, &params))
            .map_err(crate::com::error::to_com)?;
        let object = match new_group_object(&self.ctx, self.handle, added.group) {
            Ok(o) => o,
            Err(e) => {
                self.remove_forced(added.group);
                return Err(e);
            }
        };
        if query_out(&object, riid, ppunk).is_err() {
            drop(object);
            self.remove_forced(added.group);
            return Err(E_NOINTERFACE.into());
        }
        // SAFETY: both checked non-null above.
        unsafe {
            put(pserver, added.group.0);
            put(prevised, added.update_rate.value);
        }
        Ok(added
            .update_rate
            .code()
            .map_or(S_OK, crate::com::error::hresult))
    }

    /// # Safety
    /// The pointers are the parameters of the COM method (IOPCServer::GetGroupByName), valid as its IDL
    /// says (each may be NULL: checked here).
    pub(super) unsafe fn group_by_name(
        &self,
        pname: PCWSTR,
        riid: *const GUID,
        ppunk: *mut Option<IUnknown>,
    ) -> windows::core::Result<()> {
        clear(ppunk, None);
        nonnull(riid)?;
        nonnull(ppunk)?;
        let name = in_string(pname, limits::GROUP_NAME)?;
        let group = self
            .ctx
            .runtime
            .lock()
            .engine
            .group_by_name(self.handle, &name)
            .map_err(crate::com::error::to_com)?;
        let object = group_object(&self.ctx, self.handle, group)?;
        query_out(&object, riid, ppunk)
    }

    pub(super) fn remove_group(
        &self,
        server_group: u32,
        force: BOOL,
    ) -> windows::core::Result<HRESULT> {
        let outcome = self
            .ctx
            .runtime
            .with_engine(|e, now| {
                e.remove_group(now, self.handle, GroupHandle(server_group), force.as_bool())
            })
            .map_err(crate::com::error::to_com)?;
        Ok(match outcome {
            RemoveGroupOutcome::Removed => S_OK,
            RemoveGroupOutcome::InUse => crate::com::error::hresult(OpcError::InUse),
        })
    }

    /// # Safety
    /// The pointers are the parameters of the COM method (IOPCServer::CreateGroupEnumerator), valid as its IDL
    /// says (each may be NULL: checked here).
    pub(super) unsafe fn group_enumerator(
        &self,
        scope: OPCENUMSCOPE,
        riid: *const GUID,
        ppunk: *mut Option<IUnknown>,
    ) -> windows::core::Result<HRESULT> {
        clear(ppunk, None);
        nonnull(riid)?;
        nonnull(ppunk)?;
        let private = match scope {
            OPC_ENUM_PRIVATE_CONNECTIONS
            | OPC_ENUM_ALL_CONNECTIONS
            | OPC_ENUM_PRIVATE
            | OPC_ENUM_ALL => true,
            OPC_ENUM_PUBLIC_CONNECTIONS | OPC_ENUM_PUBLIC => false,
            _ => return Err(abi::invalid_arg()),
        };
        // SAFETY: checked non-null; an [in] REFIID.
        let iid = unsafe { *riid };
        let groups = if private {
            self.ctx
                .runtime
                .lock()
                .engine
                .groups(self.handle)
                .map_err(crate::com::error::to_com)?
        } else {
            Vec::new()
        };
        let (enumerator, count): (IUnknown, usize) = if iid == IEnumString::IID {
            let names: Vec<String> = groups.into_iter().map(|(_, name)| name).collect();
            let n = names.len();
            (StringEnum::create(names).into(), n)
        } else if iid == IEnumUnknown::IID {
            // Objects are made outside the engine lock; a group removed meanwhile is skipped.
            let objects: Vec<IUnknown> = groups
                .into_iter()
                .filter_map(|(g, _)| group_object(&self.ctx, self.handle, g).ok())
                .collect();
            let n = objects.len();
            (UnknownEnum::create(objects).into(), n)
        } else {
            return Err(E_NOINTERFACE.into());
        };
        query_out(&enumerator, riid, ppunk)?;
        Ok(if count == 0 { S_FALSE } else { S_OK })
    }
}
