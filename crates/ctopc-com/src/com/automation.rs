//! A late-bound Automation client: an object made by ProgID and driven through
//! `IDispatch` by member names, as VB or VBScript drive one, with no header, IID or DISPID
//! known in advance.
//!
//! - [`Object::create`] makes the object (`CLSIDFromProgID` + `CoCreateInstance`,
//!   in-process); [`Object::from_dispatch`] wraps one made elsewhere.
//! - Each member name is looked up once with `IDispatch::GetIDsOfNames` and cached.
//! - [`Object::invoke`] calls a method with [`Arg`]s: `Arg::In` by value, `Arg::InOut`
//!   passed as `VT_BYREF|VT_VARIANT` (a typed by-ref is not reliably written back) and
//!   holding what the server wrote when the call returns, `Arg::Missing` an omitted
//!   optional parameter. [`Object::get`] and [`Object::put`] read and write properties.
//! - A failed call is an [`Error`] with the server's code and text, from the call's
//!   `EXCEPINFO` (`DISP_E_EXCEPTION`) or else the thread's `IErrorInfo`.
//! - [`Object::advise_events`] finds the object's default source interface from its type
//!   information (`IProvideClassInfo::GetClassInfo`, the coclass's implemented type with
//!   `IMPLTYPEFLAG_FSOURCE | IMPLTYPEFLAG_FDEFAULT`), connects a sink of ours to its
//!   connection point and hands each event to a Rust callback as an [`Event`]: the
//!   member's name (from the source interface's type information, read once when
//!   connecting) and its arguments in declaration order.
//!
//! Values cross as `ctopc_core::Value` through the crate's VARIANT conversion
//! (`com::variant`). The object follows COM's apartment rules: use it on the thread that
//! made it ([`Object`] is not `Send`). An apartment-threaded in-process object made on a
//! single-threaded apartment delivers its events only while that thread pumps messages:
//! [`pump_messages_until`] does that while waiting for a condition.
//!
//! ```no_run
//! use ctopc_com::automation::{pump_messages_until, Arg, Object};
//! use ctopc_core::Value;
//! use std::sync::{Arc, Mutex};
//! use std::time::Duration;
//!
//! # fn main() -> Result<(), ctopc_com::automation::Error> {
//! let _apartment = ctopc_com::apartment::Apartment::sta().expect("COM");
//! let server = Object::create("XConnect.ServerCT")?;
//! server.call("Init", &[Value::Bstr("Vars=TI101".into())])?;
//! // Read DataSource, ItemID, Value, Quality, TimeStamp: the last three are [in, out].
//! let mut args = [
//!     Arg::In(Value::I4(2)),
//!     Arg::In(Value::Bstr("TI101".into())),
//!     Arg::InOut(Value::Empty),
//!     Arg::InOut(Value::Empty),
//!     Arg::InOut(Value::Empty),
//! ];
//! server.invoke("Read", &mut args)?;
//! println!("value {:?}, quality {:?}", args[2].value(), args[3].value());
//! // Events: DataChange ItemID, Value, Quality, TimeStamp.
//! let seen = Arc::new(Mutex::new(Vec::new()));
//! let sink = Arc::clone(&seen);
//! let _connection = server.advise_events(move |event| {
//!     if event.name == "DataChange" {
//!         sink.lock().unwrap().push(event.args.clone());
//!     }
//! })?;
//! server.call("SetItemActive", &[Value::Bstr("TI101".into()), Value::Bool(true)])?;
//! server.put("Active", &Value::Bool(true))?;
//! pump_messages_until(Duration::from_secs(5), || !seen.lock().unwrap().is_empty());
//! # Ok(())
//! # }
//! ```

use crate::com::variant;
use ctopc_core::Value;
use std::cell::RefCell;
use std::collections::HashMap;
use std::ffi::c_void;
use std::marker::PhantomData;
use std::mem::ManuallyDrop;
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::{Duration, Instant};
use windows::core::{IUnknown, Interface, BSTR, GUID, HRESULT, PCWSTR};
use windows::Win32::Foundation::{
    DISP_E_EXCEPTION, DISP_E_PARAMNOTFOUND, DISP_E_UNKNOWNNAME, E_NOINTERFACE, E_NOTIMPL,
    E_POINTER, S_OK,
};
use windows::Win32::System::Com::{
    CLSIDFromProgID, CoCreateInstance, GetErrorInfo, IConnectionPoint, IConnectionPointContainer,
    IDispatch, IDispatch_Vtbl, ITypeInfo, CLSCTX_INPROC_SERVER, DISPATCH_FLAGS, DISPATCH_METHOD,
    DISPATCH_PROPERTYGET, DISPATCH_PROPERTYPUT, DISPPARAMS, EXCEPINFO, IMPLTYPEFLAG_FDEFAULT,
    IMPLTYPEFLAG_FSOURCE,
};
use windows::Win32::System::Ole::{IProvideClassInfo, DISPID_PROPERTYPUT};
use windows::Win32::System::Variant::{VARIANT, VARIANT_0_0, VT_BYREF, VT_ERROR, VT_VARIANT};
use windows::Win32::UI::WindowsAndMessaging::{
    DispatchMessageW, MsgWaitForMultipleObjectsEx, PeekMessageW, TranslateMessage, MSG,
    MWMO_INPUTAVAILABLE, PM_REMOVE, QS_ALLINPUT,
};

/// A failed late-bound call.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Error {
    /// The member called (or the step that failed, e.g. `CoCreateInstance`).
    pub member: String,
    /// The HRESULT the call returned (`DISP_E_EXCEPTION` when the server raised an error).
    pub hresult: i32,
    /// The server's error code: `EXCEPINFO::scode` for `DISP_E_EXCEPTION` (or its
    /// `wCode`), else the HRESULT.
    pub code: i32,
    /// The error's text (`EXCEPINFO::bstrDescription` or `IErrorInfo`), possibly empty.
    pub description: String,
}

impl std::fmt::Display for Error {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}: 0x{:08X}", self.member, self.code as u32)?;
        if !self.description.is_empty() {
            write!(f, " {}", self.description)?;
        }
        Ok(())
    }
}

impl std::error::Error for Error {}

impl Error {
    fn com(member: &str, e: &windows::core::Error) -> Error {
        Error {
            member: member.to_owned(),
            hresult: e.code().0,
            code: e.code().0,
            description: e.message().trim().to_owned(),
        }
    }
}

/// One argument of [`Object::invoke`].
#[derive(Debug, Clone, PartialEq)]
pub enum Arg {
    /// Passed by value.
    In(Value),
    /// An `[in, out]` parameter, passed as `VT_BYREF|VT_VARIANT`; after a successful call
    /// it holds what the server wrote.
    InOut(Value),
    /// An omitted optional parameter (`VT_ERROR`, `DISP_E_PARAMNOTFOUND`).
    Missing,
}

impl Arg {
    /// The argument's value (`Value::Empty` for [`Arg::Missing`]).
    pub fn value(&self) -> &Value {
        static EMPTY: Value = Value::Empty;
        match self {
            Arg::In(v) | Arg::InOut(v) => v,
            Arg::Missing => &EMPTY,
        }
    }
}

/// An event of the object's default source interface.
#[derive(Debug, Clone, PartialEq)]
pub struct Event {
    /// The member's name in the source interface's type information (the DISPID as
    /// decimal text when the type information does not name it).
    pub name: String,
    pub dispid: i32,
    /// The arguments in declaration order; by-reference ones are read through, and one
    /// that is no plain value (an object, a multi-dimensional array) is `Value::Empty`.
    pub args: Vec<Value>,
}

/// A late-bound Automation object: an `IDispatch` and its cache of member DISPIDs.
pub struct Object {
    dispatch: IDispatch,
    ids: RefCell<HashMap<String, i32>>,
    /// COM's apartment rules: used on the thread that made it.
    _not_send: PhantomData<*const ()>,
}

impl Object {
    /// Makes the object registered as `progid`, in process (`CLSCTX_INPROC_SERVER`).
    pub fn create(progid: &str) -> Result<Object, Error> {
        let wide = windows::core::HSTRING::from(progid);
        // SAFETY: `wide` is a NUL-terminated UTF-16 string that lives for the call.
        let clsid = unsafe { CLSIDFromProgID(PCWSTR(wide.as_ptr())) }
            .map_err(|e| Error::com(&format!("CLSIDFromProgID({progid})"), &e))?;
        // SAFETY: a valid CLSID; no aggregation.
        let dispatch: IDispatch =
            unsafe { CoCreateInstance(&clsid, None, CLSCTX_INPROC_SERVER) }
                .map_err(|e| Error::com(&format!("CoCreateInstance({progid})"), &e))?;
        Ok(Object::from_dispatch(dispatch))
    }

    /// Wraps an `IDispatch` made elsewhere.
    pub fn from_dispatch(dispatch: IDispatch) -> Object {
        Object {
            dispatch,
            ids: RefCell::new(HashMap::new()),
            _not_send: PhantomData,
        }
    }

    /// The underlying `IDispatch`.
    pub fn dispatch(&self) -> &IDispatch {
        &self.dispatch
    }

    /// The DISPID of member `name` (looked up once, then cached).
    pub fn dispid(&self, name: &str) -> Result<i32, Error> {
        if let Some(id) = self.ids.borrow().get(name) {
            return Ok(*id);
        }
        let wide = windows::core::HSTRING::from(name);
        let names = [PCWSTR(wide.as_ptr())];
        let mut id = 0i32;
        // SAFETY: one name, one DISPID slot; IID_NULL as the contract requires.
        unsafe {
            self.dispatch
                .GetIDsOfNames(&GUID::zeroed(), names.as_ptr(), 1, 0, &mut id)
        }
        .map_err(|e| Error::com(&format!("GetIDsOfNames({name})"), &e))?;
        self.ids.borrow_mut().insert(name.to_owned(), id);
        Ok(id)
    }

    /// Calls method `name` with `args`; `Arg::InOut` arguments receive what the server
    /// wrote. Returns the method's result (`Value::Empty` for none).
    pub fn invoke(&self, name: &str, args: &mut [Arg]) -> Result<Value, Error> {
        self.raw_invoke(name, DISPATCH_METHOD, args, false)
    }

    /// Calls method `name` with in-arguments only.
    pub fn call(&self, name: &str, args: &[Value]) -> Result<Value, Error> {
        let mut args: Vec<Arg> = args.iter().cloned().map(Arg::In).collect();
        self.invoke(name, &mut args)
    }

    /// Reads property `name`.
    pub fn get(&self, name: &str) -> Result<Value, Error> {
        self.raw_invoke(name, DISPATCH_PROPERTYGET, &mut [], false)
    }

    /// Writes property `name`.
    pub fn put(&self, name: &str, value: &Value) -> Result<(), Error> {
        self.raw_invoke(
            name,
            DISPATCH_PROPERTYPUT,
            &mut [Arg::In(value.clone())],
            true,
        )
        .map(|_| ())
    }

    fn raw_invoke(
        &self,
        name: &str,
        flags: DISPATCH_FLAGS,
        args: &mut [Arg],
        put: bool,
    ) -> Result<Value, Error> {
        let id = self.dispid(name)?;
        let n = args.len();
        let to_variant = |v: &Value| {
            variant::to_variant(v).map_err(|e| Error::com(&format!("{name}: argument"), &e))
        };
        // The referents of the by-reference arguments, then the arguments themselves in
        // reverse order (DISPPARAMS' convention). Both are allocated in full before any
        // pointer into `targets` is taken.
        let mut targets: Vec<VARIANT> = (0..n).map(|_| VARIANT::default()).collect();
        let mut argv: Vec<VARIANT> = (0..n).map(|_| VARIANT::default()).collect();
        for (i, arg) in args.iter().enumerate() {
            let slot = n - 1 - i;
            match arg {
                Arg::In(v) => argv[slot] = to_variant(v)?,
                Arg::InOut(v) => {
                    targets[i] = to_variant(v)?;
                    let referent: *mut VARIANT = &mut targets[i];
                    let mut inner = VARIANT_0_0 {
                        vt: windows::Win32::System::Variant::VARENUM(VT_BYREF.0 | VT_VARIANT.0),
                        ..Default::default()
                    };
                    inner.Anonymous.pvarVal = referent;
                    argv[slot].Anonymous.Anonymous = ManuallyDrop::new(inner);
                }
                Arg::Missing => {
                    let mut inner = VARIANT_0_0 {
                        vt: VT_ERROR,
                        ..Default::default()
                    };
                    inner.Anonymous.scode = DISP_E_PARAMNOTFOUND.0;
                    argv[slot].Anonymous.Anonymous = ManuallyDrop::new(inner);
                }
            }
        }
        let mut named = DISPID_PROPERTYPUT;
        let params = DISPPARAMS {
            rgvarg: if n == 0 {
                std::ptr::null_mut()
            } else {
                argv.as_mut_ptr()
            },
            rgdispidNamedArgs: if put {
                &mut named
            } else {
                std::ptr::null_mut()
            },
            cArgs: n as u32,
            cNamedArgs: u32::from(put),
        };
        let mut result = VARIANT::default();
        let mut excep = EXCEPINFO::default();
        let mut arg_err = 0u32;
        // SAFETY: `params` points at `argv` (and `named`), whose by-reference entries
        // point at `targets`; all outlive the call. The out-parameters are our locals.
        let outcome = unsafe {
            self.dispatch.Invoke(
                id,
                &GUID::zeroed(),
                0,
                flags,
                &params,
                if put { None } else { Some(&mut result) },
                Some(&mut excep),
                Some(&mut arg_err),
            )
        };
        // The by-reference argument VARIANTs only point at `targets`: they are forgotten,
        // not cleared, so that only `targets` is cleared.
        for a in argv.iter_mut() {
            // SAFETY: reading the VARTYPE of an initialised VARIANT.
            if unsafe { a.Anonymous.Anonymous.vt.0 } & VT_BYREF.0 != 0 {
                std::mem::forget(std::mem::take(a));
            }
        }
        if let Err(e) = outcome {
            return Err(invoke_error(name, &e, &mut excep));
        }
        free_excepinfo(&mut excep);
        for (i, arg) in args.iter_mut().enumerate() {
            if let Arg::InOut(v) = arg {
                *v = variant::from_variant(&targets[i]).map_err(|_| Error {
                    member: name.to_owned(),
                    hresult: 0,
                    code: E_NOTIMPL.0,
                    description: format!(
                        "argument {}: the server wrote VARTYPE {} (no plain value)",
                        i + 1,
                        variant::var_type(&targets[i]).0
                    ),
                })?;
            }
        }
        variant::from_variant(&result).map_err(|_| Error {
            member: name.to_owned(),
            hresult: 0,
            code: E_NOTIMPL.0,
            description: format!(
                "the result has VARTYPE {} (no plain value)",
                variant::var_type(&result).0
            ),
        })
    }

    /// Connects `handler` to the object's default source interface (found from its type
    /// information); the connection lasts until the returned value is dropped.
    ///
    /// `handler` runs on the thread COM delivers the event on (for an apartment-threaded
    /// object made on a single-threaded apartment: that thread, while it pumps messages);
    /// a panic in it is caught and logged.
    pub fn advise_events(
        &self,
        handler: impl Fn(&Event) + Send + Sync + 'static,
    ) -> Result<EventConnection, Error> {
        let source = self.source_type_info()?;
        let (iid, names) = describe_source(&source)?;
        let container: IConnectionPointContainer = self
            .dispatch
            .cast()
            .map_err(|e| Error::com("IConnectionPointContainer", &e))?;
        // SAFETY: a valid IID.
        let point = unsafe { container.FindConnectionPoint(&iid) }
            .map_err(|e| Error::com("FindConnectionPoint", &e))?;
        let sink = Sink::create(iid, names, Box::new(handler));
        // SAFETY: `sink` is a valid IUnknown of a live object.
        let cookie = unsafe { point.Advise(&sink) }
            .map_err(|e| Error::com("IConnectionPoint::Advise", &e))?;
        Ok(EventConnection {
            point,
            cookie,
            _not_send: PhantomData,
        })
    }

    /// The type information of the coclass's `[default, source]` interface.
    fn source_type_info(&self) -> Result<ITypeInfo, Error> {
        let provide: IProvideClassInfo = self
            .dispatch
            .cast()
            .map_err(|e| Error::com("IProvideClassInfo", &e))?;
        // SAFETY: plain COM calls on live interfaces.
        let class =
            unsafe { provide.GetClassInfo() }.map_err(|e| Error::com("GetClassInfo", &e))?;
        let count = with_type_attr(&class, |a| a.cImplTypes)?;
        for i in 0..u32::from(count) {
            // SAFETY: `i` is below the coclass's count of implemented types.
            let flags = unsafe { class.GetImplTypeFlags(i) }
                .map_err(|e| Error::com("GetImplTypeFlags", &e))?;
            let wanted = IMPLTYPEFLAG_FSOURCE.0 | IMPLTYPEFLAG_FDEFAULT.0;
            if flags.0 & wanted != wanted {
                continue;
            }
            // SAFETY: as above; the handle comes from this type information.
            let info = unsafe {
                class
                    .GetRefTypeOfImplType(i)
                    .and_then(|href| class.GetRefTypeInfo(href))
            }
            .map_err(|e| Error::com("GetRefTypeInfo", &e))?;
            return Ok(info);
        }
        Err(Error {
            member: "advise_events".to_owned(),
            hresult: E_NOINTERFACE.0,
            code: E_NOINTERFACE.0,
            description: "the object's coclass has no [default, source] interface".to_owned(),
        })
    }
}

/// `f` applied to the TYPEATTR of `info` (released afterwards).
fn with_type_attr<T>(
    info: &ITypeInfo,
    f: impl FnOnce(&windows::Win32::System::Com::TYPEATTR) -> T,
) -> Result<T, Error> {
    // SAFETY: GetTypeAttr returns a TYPEATTR owned by `info`, valid until released, which
    // happens once below.
    unsafe {
        let attr = info
            .GetTypeAttr()
            .map_err(|e| Error::com("GetTypeAttr", &e))?;
        if attr.is_null() {
            return Err(Error::com("GetTypeAttr", &E_POINTER.into()));
        }
        let out = f(&*attr);
        info.ReleaseTypeAttr(attr);
        Ok(out)
    }
}

/// The IID of a source interface and the names of its members by DISPID, read by walking
/// its FUNCDESCs (`ITypeInfo::GetIDsOfNames` fails through a cross-apartment proxy under
/// Wine; `GetFuncDesc` and `GetDocumentation` work).
fn describe_source(info: &ITypeInfo) -> Result<(GUID, HashMap<i32, String>), Error> {
    let (iid, count) = with_type_attr(info, |a| (a.guid, a.cFuncs))?;
    let mut names = HashMap::new();
    for i in 0..u32::from(count) {
        // SAFETY: `i` is below the type's count of functions; the FUNCDESC is released once.
        let memid = unsafe {
            let desc = info
                .GetFuncDesc(i)
                .map_err(|e| Error::com("GetFuncDesc", &e))?;
            if desc.is_null() {
                continue;
            }
            let memid = (*desc).memid;
            info.ReleaseFuncDesc(desc);
            memid
        };
        let mut name = BSTR::new();
        // SAFETY: the member ID comes from this type information; only the name is asked.
        let named = unsafe {
            info.GetDocumentation(memid, Some(&mut name), None, std::ptr::null_mut(), None)
        };
        if named.is_ok() {
            names.insert(memid, name.to_string());
        }
    }
    Ok((iid, names))
}

/// The error of a failed `Invoke`: the EXCEPINFO of `DISP_E_EXCEPTION` (after its
/// deferred fill-in), else the COM error's own text (the thread's `IErrorInfo`).
fn invoke_error(name: &str, e: &windows::core::Error, excep: &mut EXCEPINFO) -> Error {
    let mut err = Error::com(name, e);
    if e.code() == DISP_E_EXCEPTION {
        if let Some(fill) = excep.pfnDeferredFillIn {
            // SAFETY: the server's deferred fill-in for this EXCEPINFO, as the contract
            // of DISP_E_EXCEPTION says.
            let _ = unsafe { fill(excep) };
        }
        err.code = if excep.scode != 0 {
            excep.scode
        } else {
            i32::from(excep.wCode)
        };
        let text = excep.bstrDescription.to_string();
        if !text.trim().is_empty() {
            err.description = text.trim().to_owned();
        }
    } else if err.description.is_empty() {
        // SAFETY: takes the thread's error object, if any.
        if let Ok(info) = unsafe { GetErrorInfo(0) } {
            // SAFETY: a live IErrorInfo.
            if let Ok(text) = unsafe { info.GetDescription() } {
                err.description = text.to_string().trim().to_owned();
            }
        }
    }
    free_excepinfo(excep);
    err
}

fn free_excepinfo(excep: &mut EXCEPINFO) {
    // SAFETY: each BSTR is freed once and replaced by an empty one.
    unsafe {
        ManuallyDrop::drop(&mut excep.bstrSource);
        ManuallyDrop::drop(&mut excep.bstrDescription);
        ManuallyDrop::drop(&mut excep.bstrHelpFile);
    }
    excep.bstrSource = ManuallyDrop::new(BSTR::new());
    excep.bstrDescription = ManuallyDrop::new(BSTR::new());
    excep.bstrHelpFile = ManuallyDrop::new(BSTR::new());
}

/// A connection of an event handler; dropping it disconnects (`Unadvise`).
pub struct EventConnection {
    point: IConnectionPoint,
    cookie: u32,
    _not_send: PhantomData<*const ()>,
}

impl EventConnection {
    /// The connection point's cookie.
    pub fn cookie(&self) -> u32 {
        self.cookie
    }
}

impl Drop for EventConnection {
    fn drop(&mut self) {
        // SAFETY: the cookie Advise returned on this point.
        if let Err(e) = unsafe { self.point.Unadvise(self.cookie) } {
            tracing::warn!("automation: Unadvise failed: {e}");
        }
    }
}

/// Pumps this thread's messages until `done()` holds or `timeout` passes; returns whether
/// `done()` held. For a single-threaded apartment waiting for the events of an
/// apartment-threaded object (they arrive as messages to this thread).
pub fn pump_messages_until(timeout: Duration, mut done: impl FnMut() -> bool) -> bool {
    let deadline = Instant::now() + timeout;
    loop {
        let mut msg = MSG::default();
        // SAFETY: `msg` is our local; messages of this thread are dispatched to their
        // window procedures (or timer callbacks) as a message loop does.
        while unsafe { PeekMessageW(&mut msg, None, 0, 0, PM_REMOVE) }.as_bool() {
            // SAFETY: as above.
            unsafe {
                let _ = TranslateMessage(&msg);
                DispatchMessageW(&msg);
            }
        }
        if done() {
            return true;
        }
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return false;
        }
        let wait = left.min(Duration::from_millis(50)).as_millis() as u32;
        // SAFETY: no handles; waits for any message to this thread, or the time.
        unsafe { MsgWaitForMultipleObjectsEx(None, wait, QS_ALLINPUT, MWMO_INPUTAVAILABLE) };
    }
}

// ---------------------------------------------------------------------------------------
// The event sink: an IDispatch written out by hand, because it must also answer
// QueryInterface for the source interface's IID, which is known only at run time (a
// connection point may ask the sink for it, as ATL's do).

type Handler = Box<dyn Fn(&Event) + Send + Sync>;

#[repr(C)]
struct Sink {
    vtable: *const IDispatch_Vtbl,
    refs: AtomicU32,
    iid: GUID,
    names: HashMap<i32, String>,
    handler: Handler,
}

static SINK_VTABLE: IDispatch_Vtbl = IDispatch_Vtbl {
    base__: windows::core::IUnknown_Vtbl {
        QueryInterface: sink_query_interface,
        AddRef: sink_add_ref,
        Release: sink_release,
    },
    GetTypeInfoCount: sink_get_type_info_count,
    GetTypeInfo: sink_get_type_info,
    GetIDsOfNames: sink_get_ids_of_names,
    Invoke: sink_invoke,
};

impl Sink {
    /// A new sink with one reference, owned by the returned IUnknown.
    fn create(iid: GUID, names: HashMap<i32, String>, handler: Handler) -> IUnknown {
        let sink = Box::new(Sink {
            vtable: &SINK_VTABLE,
            refs: AtomicU32::new(1),
            iid,
            names,
            handler,
        });
        let raw = Box::into_raw(sink).cast::<c_void>();
        // SAFETY: `raw` is a COM object (its first field the vtable pointer) with one
        // reference, which the IUnknown takes over.
        unsafe { IUnknown::from_raw(raw) }
    }
}

unsafe extern "system" fn sink_query_interface(
    this: *mut c_void,
    iid: *const GUID,
    out: *mut *mut c_void,
) -> HRESULT {
    if out.is_null() {
        return E_POINTER;
    }
    // SAFETY: `out` is non-null caller storage; cleared first.
    unsafe { *out = std::ptr::null_mut() };
    if iid.is_null() {
        return E_POINTER;
    }
    // SAFETY: `this` is a Sink (the vtable is only reachable through one); `iid` non-null.
    let (sink, iid) = unsafe { (&*this.cast::<Sink>(), *iid) };
    if iid == IUnknown::IID || iid == IDispatch::IID || iid == sink.iid {
        sink.refs.fetch_add(1, Ordering::Relaxed);
        // SAFETY: as above.
        unsafe { *out = this };
        S_OK
    } else {
        E_NOINTERFACE
    }
}

unsafe extern "system" fn sink_add_ref(this: *mut c_void) -> u32 {
    // SAFETY: `this` is a live Sink.
    let sink = unsafe { &*this.cast::<Sink>() };
    sink.refs.fetch_add(1, Ordering::Relaxed) + 1
}

unsafe extern "system" fn sink_release(this: *mut c_void) -> u32 {
    // SAFETY: `this` is a live Sink.
    let left = unsafe { &*this.cast::<Sink>() }
        .refs
        .fetch_sub(1, Ordering::AcqRel)
        - 1;
    if left == 0 {
        // SAFETY: the last reference is gone: the Box made in `Sink::create` is freed once.
        drop(unsafe { Box::from_raw(this.cast::<Sink>()) });
    }
    left
}

unsafe extern "system" fn sink_get_type_info_count(_this: *mut c_void, count: *mut u32) -> HRESULT {
    if count.is_null() {
        return E_POINTER;
    }
    // SAFETY: non-null caller storage.
    unsafe { *count = 0 };
    S_OK
}

unsafe extern "system" fn sink_get_type_info(
    _this: *mut c_void,
    _index: u32,
    _lcid: u32,
    out: *mut *mut c_void,
) -> HRESULT {
    if !out.is_null() {
        // SAFETY: non-null caller storage.
        unsafe { *out = std::ptr::null_mut() };
    }
    E_NOTIMPL
}

unsafe extern "system" fn sink_get_ids_of_names(
    _this: *mut c_void,
    _iid: *const GUID,
    _names: *const PCWSTR,
    _count: u32,
    _lcid: u32,
    _ids: *mut i32,
) -> HRESULT {
    DISP_E_UNKNOWNNAME
}

unsafe extern "system" fn sink_invoke(
    this: *mut c_void,
    dispid: i32,
    _iid: *const GUID,
    _lcid: u32,
    _flags: DISPATCH_FLAGS,
    params: *const DISPPARAMS,
    _result: *mut VARIANT,
    _excep: *mut EXCEPINFO,
    _arg_err: *mut u32,
) -> HRESULT {
    // SAFETY: `this` is a live Sink.
    let sink = unsafe { &*this.cast::<Sink>() };
    let mut args = Vec::new();
    if !params.is_null() {
        // SAFETY: the caller's DISPPARAMS: `cArgs` VARIANTs at `rgvarg`, in reverse order.
        let params = unsafe { &*params };
        if params.cArgs > 0 && params.rgvarg.is_null() {
            return E_POINTER;
        }
        for i in (0..params.cArgs as usize).rev() {
            // SAFETY: `i` < cArgs, within the caller's array.
            let v = unsafe { &*params.rgvarg.add(i) };
            args.push(variant::from_variant(v).unwrap_or(Value::Empty));
        }
    }
    let name = match sink.names.get(&dispid) {
        Some(name) => name.clone(),
        None => dispid.to_string(),
    };
    let event = Event { name, dispid, args };
    let handled = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| (sink.handler)(&event)));
    if handled.is_err() {
        tracing::error!("automation: the handler of event {} panicked", event.name);
    }
    S_OK
}
