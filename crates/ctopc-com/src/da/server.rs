//! The OPC server object: one per client (CreateInstance of the multiple-use class object).
//!
//! Interfaces: IOPCCommon, IOPCServer (groups, status, error strings),
//! IOPCBrowseServerAddressSpace and IOPCBrowse (`server/browse.rs`), IOPCItemProperties
//! (`server/props.rs`), IOPCItemIO (`server/itemio.rs`) and IConnectionPointContainer with
//! the IOPCShutdown connection point (`server/shutdown.rs`).
//!
//! # Argument rules (every method)
//!
//! - **NULL pointers are E_INVALIDARG**: out-parameters, required `[in]` pointers (strings,
//!   arrays with a non-zero count, REFIIDs) alike. The OPC specifications list E_INVALIDARG
//!   for bad arguments of every method and the OPC Foundation sample server answers NULLs
//!   with it; E_POINTER is kept for the COM-defined methods whose contracts name it
//!   (QueryInterface, IEnum*::Next and Clone, IConnectionPointContainer and
//!   IConnectionPoint, which the objects implement through our own definitions in
//!   `crate::com::comdef`, so that the NULL checks are ours and not windows-rs' shims'). Through the proxy a NULL `[ref]`
//!   pointer mostly never reaches the server: the proxy answers RPC_X_NULL_REF_POINTER
//!   (Wine's proxy lets some NULL `[out]` pointers through; the stub then hands the server
//!   storage of its own and the proxy fails on the way back). `[in, unique]` pointers
//!   (AddGroup's pTimeBias and pPercentDeadband) may be NULL and mean "the default".
//! - A count of 0 is E_INVALIDARG; enumeration values outside the IDL's are E_INVALIDARG.
//! - Out-parameters are cleared first (NULL / 0, `abi::clear_outs` before any check), then
//!   filled only after everything of the call has succeeded (`crate::com::abi`): all or nothing.
//! - Per-item operations return S_FALSE when any item failed, with per-item codes.
//! - Core errors become COM errors only through `crate::com::error::to_com` (the crate's one
//!   mapping, shared with the group objects; its message object is made with
//!   `CreateErrorInfo`, never with `RoOriginateErrorW`, which aborts under Wine 8), and
//!   per-item codes through `crate::com::error::hresult`.
//! - No client is called and no COM object is created while the engine lock is held
//!   (`ctx.runtime.with_engine` sections are short, pure engine calls).

mod browse;
mod groups;
mod itemio;
mod props;
mod shutdown;

use crate::com::abi::{self, write_out, OutArray, TaskMem};
use crate::com::clock;
use crate::com::comdef::RawConnectionPointContainer;
use crate::com::connpoint::SinkSlot;
use crate::com::interfaces::*;
use crate::com::lifetime::ObjectGuard;
use crate::da::callbacks::ShutdownSink;
use crate::da::context::Context;
use ctopc_core::diagnostics::browse::Cursor;
use ctopc_core::lang::Lang;
use ctopc_core::limits;
use ctopc_core::metrics::Method;
use ctopc_core::model::SessionHandle;
use ctopc_core::OpcError;
use std::sync::{Arc, Mutex, MutexGuard};
use windows::core::{implement, IUnknown, BOOL, GUID, HRESULT, PCWSTR, PWSTR};
use windows::Win32::Foundation::E_INVALIDARG;

/// OPCSERVERSTATUS.szVendorInfo, and the `Vendor` value of the legacy `OPC` key (defined
/// with the registration, which an installer builds natively).
pub const VENDOR_INFO: &str = ctopc_registration::VENDOR_INFO;

struct Session {
    lcid: u32,
    client_name: Option<String>,
}

#[implement(
    IOPCServer,
    IOPCCommon,
    IOPCBrowseServerAddressSpace,
    IOPCItemProperties,
    IOPCBrowse,
    IOPCItemIO,
    RawConnectionPointContainer
)]
pub struct OpcServer {
    ctx: Arc<Context>,
    handle: SessionHandle,
    session: Mutex<Session>,
    /// IOPCBrowseServerAddressSpace's position (per client, as the spec requires).
    browse: Mutex<Cursor>,
    /// The IOPCShutdown connection (registered with the runtime, which calls it on a stop).
    shutdown: Arc<SinkSlot<IOPCShutdown>>,
    _guard: ObjectGuard,
}

/// The class object of the server for `ctx`: every CreateInstance makes a new server
/// object of that context ([`create_instance`]); LockServer counts in its lifetime.
pub fn class_factory(ctx: &Arc<Context>) -> windows::Win32::System::Com::IClassFactory {
    let for_factory = Arc::clone(ctx);
    crate::com::factory::ClassFactory::new(Arc::clone(&ctx.lifetime), move || {
        create_instance(&for_factory)
    })
}

/// The class factory's constructor: a new server object (and engine session) of `ctx` for
/// one client.
pub fn create_instance(ctx: &Arc<Context>) -> windows::core::Result<IUnknown> {
    let handle = ctx.runtime.open_session();
    ctx.runtime
        .set_caller(handle, crate::com::caller::current());
    let shutdown = Arc::new(SinkSlot::<IOPCShutdown>::default());
    ctx.runtime
        .set_session_sink(handle, Arc::new(ShutdownSink(Arc::clone(&shutdown))));
    let server = OpcServer {
        ctx: Arc::clone(ctx),
        handle,
        session: Mutex::new(Session {
            lcid: ctx.default_lang.lcid(),
            client_name: None,
        }),
        browse: Mutex::new(Cursor::new(Arc::clone(&ctx.address_space))),
        shutdown,
        _guard: ObjectGuard::new(&ctx.lifetime),
    };
    Ok(server.into())
}

impl Drop for OpcServer {
    fn drop(&mut self) {
        self.ctx.runtime.close_session(self.handle);
    }
}

impl OpcServer {
    fn session(&self) -> MutexGuard<'_, Session> {
        self.session.lock().unwrap_or_else(|p| p.into_inner())
    }

    fn cursor(&self) -> MutexGuard<'_, Cursor> {
        self.browse.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// The language for an LCID a client passes: Polish, any English, or the system/user
    /// default and neutral locales (the server's default language). Others are not
    /// available.
    fn lang_for(&self, lcid: u32) -> Option<Lang> {
        Lang::from_lcid(lcid, self.ctx.default_lang)
    }
}

/// The text of `code` in `lang`: our own codes from the core table, else the system's.
fn error_text(code: HRESULT, lang: Lang) -> windows::core::Result<String> {
    if let Some(e) = OpcError::from_hresult(code.0) {
        return Ok(e.text(lang).to_string());
    }
    let msg = code.message();
    if msg.trim().is_empty() {
        Err(E_INVALIDARG.into())
    } else {
        Ok(msg.trim_end().to_string())
    }
}

impl IOPCCommon_Impl for OpcServer_Impl {
    /// The LCID is the language of GetErrorString's texts and, in the engine, the
    /// conversion locale of this session's IOPCItemIO writes (which have no group LCID).
    unsafe fn SetLocaleID(&self, lcid: u32) -> windows::core::Result<()> {
        self.lang_for(lcid)
            .ok_or_else(|| windows::core::Error::from(E_INVALIDARG))?;
        let handle = self.handle;
        self.ctx
            .runtime
            .with_engine(|e, _| e.set_session_lcid(handle, lcid))
            .map_err(crate::com::error::to_com)?;
        self.session().lcid = lcid;
        Ok(())
    }

    unsafe fn GetLocaleID(&self, plcid: *mut u32) -> windows::core::Result<()> {
        let lcid = self.session().lcid;
        // SAFETY: `plcid` is this method's [out] parameter.
        unsafe { write_out(plcid, lcid) }
    }

    unsafe fn QueryAvailableLocaleIDs(
        &self,
        pcount: *mut u32,
        plcids: *mut *mut u32,
    ) -> windows::core::Result<()> {
        // SAFETY: this method's [out] parameters.
        unsafe { abi::clear_outs((pcount, plcids)) };
        if pcount.is_null() || plcids.is_null() {
            return Err(E_INVALIDARG.into());
        }
        let ids = Lang::available_lcids();
        let mut arr = TaskMem::<u32>::zeroed(ids.len())?;
        arr.as_mut_slice().copy_from_slice(ids);
        // SAFETY: both checked non-null above; all allocation has succeeded.
        unsafe {
            *pcount = ids.len() as u32;
            *plcids = arr.into_raw();
        }
        Ok(())
    }

    unsafe fn GetErrorString(
        &self,
        code: HRESULT,
        pstring: *mut PWSTR,
    ) -> windows::core::Result<()> {
        // SAFETY: this method's [out] parameter.
        unsafe { abi::clear_outs((pstring,)) };
        if pstring.is_null() {
            return Err(E_INVALIDARG.into());
        }
        let lang = self
            .lang_for(self.session().lcid)
            .unwrap_or(self.ctx.default_lang);
        let text = abi::OwnedWstr::new(&error_text(code, lang)?)?;
        // SAFETY: `pstring` is this method's [out] parameter (checked non-null above).
        unsafe { write_out(pstring, text.into_raw()) }
    }

    unsafe fn SetClientName(&self, name: PCWSTR) -> windows::core::Result<()> {
        // SAFETY: `name` is this method's [in, string] parameter.
        let name = unsafe { abi::in_string(name, limits::CLIENT_NAME) }?;
        self.ctx.runtime.clients.set_client_name(self.handle, &name);
        self.session().client_name = Some(name);
        Ok(())
    }
}

impl IOPCServer_Impl for OpcServer_Impl {
    unsafe fn AddGroup(
        &self,
        name: PCWSTR,
        active: BOOL,
        rate: u32,
        client: u32,
        bias: *const i32,
        deadband: *const f32,
        lcid: u32,
        server: *mut u32,
        revised: *mut u32,
        riid: *const GUID,
        unk: *mut Option<IUnknown>,
    ) -> HRESULT {
        let _t = self.ctx.timed(Method::AddGroup);
        let args = groups::AddGroupArgs {
            name,
            active,
            rate,
            client,
            bias,
            deadband,
            lcid,
        };
        abi::hresult(self.add_group(&args, server, revised, riid, unk))
    }

    unsafe fn GetErrorString(
        &self,
        code: HRESULT,
        lcid: u32,
        pstring: *mut PWSTR,
    ) -> windows::core::Result<()> {
        // SAFETY: this method's [out] parameter.
        unsafe { abi::clear_outs((pstring,)) };
        if pstring.is_null() {
            return Err(E_INVALIDARG.into());
        }
        let lang = self
            .lang_for(lcid)
            .ok_or_else(|| windows::core::Error::from(E_INVALIDARG))?;
        let text = abi::OwnedWstr::new(&error_text(code, lang)?)?;
        // SAFETY: `pstring` is this method's [out] parameter (checked non-null above).
        unsafe { write_out(pstring, text.into_raw()) }
    }

    unsafe fn GetGroupByName(
        &self,
        name: PCWSTR,
        riid: *const GUID,
        unk: *mut Option<IUnknown>,
    ) -> windows::core::Result<()> {
        self.group_by_name(name, riid, unk)
    }

    unsafe fn GetStatus(&self, pstatus: *mut *mut OPCSERVERSTATUS) -> windows::core::Result<()> {
        let _t = self.ctx.timed(Method::GetStatus);
        // Cleared first (NULL), before any allocation can fail.
        // SAFETY: `pstatus` is this method's [out] parameter.
        let out = unsafe { OutArray::new(pstatus) }?;
        let ctx = &self.ctx;
        let (groups, last_update) = ctx.runtime.with_engine(|e, _| {
            (
                e.groups(self.handle).map(|g| g.len()).unwrap_or(0),
                e.last_update_time(self.handle).ok(),
            )
        });
        let version = |i: usize| {
            env!("CARGO_PKG_VERSION")
                .split('.')
                .nth(i)
                .and_then(|s| s.parse::<u16>().ok())
                .unwrap_or(0)
        };
        let now = clock::now();
        let mut block = TaskMem::<OPCSERVERSTATUS>::zeroed(1)?;
        let vendor = abi::alloc_wstr(VENDOR_INFO)?;
        block.as_mut_slice()[0] = OPCSERVERSTATUS {
            ftStartTime: clock::filetime(ctx.runtime.start_time),
            ftCurrentTime: clock::filetime(now),
            // The last data callback sent to this client (the start time before the first).
            ftLastUpdateTime: clock::filetime(
                last_update
                    .filter(|t| t.0 > 0)
                    .unwrap_or(ctx.runtime.start_time),
            ),
            dwServerState: ctx.state,
            dwGroupCount: groups as u32,
            dwBandWidth: u32::MAX,
            wMajorVersion: version(0),
            wMinorVersion: version(1),
            wBuildNumber: version(2),
            wReserved: 0,
            szVendorInfo: vendor,
        };
        // Every allocation has succeeded.
        out.set(block);
        Ok(())
    }

    unsafe fn RemoveGroup(&self, server_group: u32, force: BOOL) -> HRESULT {
        let _t = self.ctx.timed(Method::RemoveGroup);
        abi::hresult(self.remove_group(server_group, force))
    }

    unsafe fn CreateGroupEnumerator(
        &self,
        scope: OPCENUMSCOPE,
        riid: *const GUID,
        unk: *mut Option<IUnknown>,
    ) -> HRESULT {
        abi::hresult(self.group_enumerator(scope, riid, unk))
    }
}
