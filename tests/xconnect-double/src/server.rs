//! The `XConnect.ServerCT` object: `IDispatch` over the plant (names from the type
//! library, a hand dispatcher by DISPID), `IProvideClassInfo` (the coclass, so that a
//! client finds the event interface), and one connection point for `_IServerCTEvents`.
//!
//! Apartment-threaded: every call comes on the creating thread, and so does the plant's
//! timer (a thread timer, `SetTimer` with a callback), which fires `DataChange` on the
//! connected sinks while that thread pumps messages.

use crate::plant::{self, Fault, Plant, Reading};
use ctopc_com::comdef::{RawConnectionPointContainer, RawConnectionPointContainer_Impl};
use ctopc_com::connpoint::{self, Slot};
use ctopc_com::variant;
use ctopc_core::Value;
use std::cell::RefCell;
use std::collections::HashMap;
use std::ffi::c_void;
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::{Arc, Mutex, Weak};
use windows::core::{implement, IUnknown, IUnknownImpl, Interface, BSTR, GUID, HRESULT, PCWSTR};
use windows::Win32::Foundation::DISP_E_BADINDEX;
use windows::Win32::Foundation::{
    DISP_E_BADPARAMCOUNT, DISP_E_EXCEPTION, DISP_E_MEMBERNOTFOUND, DISP_E_PARAMNOTFOUND,
    DISP_E_TYPEMISMATCH, E_POINTER, HWND, SYSTEMTIME,
};
use windows::Win32::System::Com::{
    IConnectionPoint, IDispatch, IDispatch_Impl, IEnumConnectionPoints, ITypeInfo, ITypeLib,
    DISPATCH_FLAGS, DISPATCH_METHOD, DISPATCH_PROPERTYGET, DISPATCH_PROPERTYPUT,
    DISPATCH_PROPERTYPUTREF, DISPPARAMS, EXCEPINFO,
};
use windows::Win32::System::Ole::{
    IProvideClassInfo, IProvideClassInfo_Impl, CONNECT_E_ADVISELIMIT, CONNECT_E_NOCONNECTION,
    DISPID_PROPERTYPUT,
};
use windows::Win32::System::SystemInformation::GetLocalTime;
use windows::Win32::System::Variant::{
    SystemTimeToVariantTime, VARIANT, VT_BYREF, VT_ERROR, VT_VARIANT,
};
use windows::Win32::UI::WindowsAndMessaging::{KillTimer, SetTimer};

/// The type library's identities (`xconnect.idl`).
pub const CLSID: GUID = GUID::from_u128(0x89e6e506_b35c_47b3_80c3_ddb322e9e45a);
pub const LIBID: GUID = GUID::from_u128(0xf0d57827_616c_45a7_89c5_4c9382d9d42c);
pub const DIID_SERVER: GUID = GUID::from_u128(0xe36f19ee_a72d_471b_8ed4_bf599521e623);
pub const DIID_EVENTS: GUID = GUID::from_u128(0x4ffbc8cd_e0a0_4d1e_9c66_8e32c4b72499);

// The DISPIDs of `xconnect.idl`.
const LOAD_CHANNEL: i32 = 1;
const INIT: i32 = 2;
const READ: i32 = 3;
const SET_ITEM_ACTIVE: i32 = 4;
const WRITE: i32 = 5;
const WRITE_EX: i32 = 6;
const ACTIVE: i32 = 10;
const SERVER_STATE: i32 = 11;
const START_TIME: i32 = 12;
const DATA_CHANGE: i32 = 1;

/// The environment variable whose option string `LoadChannel` applies (plant.rs).
pub const OPTIONS_ENV: &str = "XCONNECT_DOUBLE_OPTIONS";

/// Now, local time, as an OLE Automation date (what the original stamps).
fn now() -> f64 {
    // SAFETY: plain calls with our locals.
    unsafe {
        let st: SYSTEMTIME = GetLocalTime();
        let mut date = 0.0;
        SystemTimeToVariantTime(&st, &mut date);
        date
    }
}

/// The sinks of the `_IServerCTEvents` point: each connection QueryInterfaces the sink for
/// the event interface's IID, as ATL's points do, and keeps it as the IDispatch it is.
#[derive(Default)]
pub struct EventSlot {
    sinks: Mutex<Vec<(u32, IDispatch)>>,
}

/// At most this many connections (CONNECT_E_ADVISELIMIT beyond).
const MAX_SINKS: usize = 8;
static NEXT_COOKIE: AtomicU32 = AtomicU32::new(1);

// SAFETY: the object is apartment-threaded: COM calls it, and its timer fires, only on
// the creating thread; the mutex guards the list anyway.
unsafe impl Send for EventSlot {}
// SAFETY: as above.
unsafe impl Sync for EventSlot {}

impl EventSlot {
    fn lock(&self) -> std::sync::MutexGuard<'_, Vec<(u32, IDispatch)>> {
        self.sinks.lock().unwrap_or_else(|p| p.into_inner())
    }
    fn sinks(&self) -> Vec<IDispatch> {
        self.lock().iter().map(|(_, s)| s.clone()).collect()
    }
}

impl Slot for EventSlot {
    fn advise(&self, unk: &IUnknown) -> windows::core::Result<u32> {
        let mut raw: *mut c_void = std::ptr::null_mut();
        // SAFETY: a live IUnknown; on success `raw` holds one reference to an interface
        // derived from IDispatch (the event dispinterface), which the IDispatch takes over.
        let sink = unsafe {
            unk.query(&DIID_EVENTS, &mut raw).ok()?;
            IDispatch::from_raw(raw)
        };
        let mut sinks = self.lock();
        if sinks.len() >= MAX_SINKS {
            return Err(CONNECT_E_ADVISELIMIT.into());
        }
        let cookie = NEXT_COOKIE.fetch_add(1, Ordering::Relaxed);
        sinks.push((cookie, sink));
        Ok(cookie)
    }
    fn unadvise(&self, cookie: u32) -> windows::core::Result<()> {
        let mut sinks = self.lock();
        let before = sinks.len();
        sinks.retain(|(c, _)| *c != cookie);
        if sinks.len() == before {
            return Err(CONNECT_E_NOCONNECTION.into());
        }
        Ok(())
    }
    fn connections(&self) -> Vec<(u32, IUnknown)> {
        self.lock()
            .iter()
            .map(|(c, s)| (*c, s.cast::<IUnknown>()))
            .filter_map(|(c, u)| u.ok().map(|u| (c, u)))
            .collect()
    }
}

/// What the object and its timer share.
struct Shared {
    plant: Mutex<Plant>,
    events: Arc<EventSlot>,
    timer: Mutex<Option<usize>>,
}

impl Shared {
    fn plant(&self) -> std::sync::MutexGuard<'_, Plant> {
        self.plant.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// One tick: the plant's changes, then DataChange to every sink (no lock held).
    fn tick(&self) {
        let changes = self.plant().tick(now());
        for change in changes {
            for sink in self.events.sinks() {
                fire_data_change(&sink, &change);
            }
        }
    }

    /// Starts or stops the timer to match `Active`.
    fn set_active(self: &Arc<Self>, active: bool) {
        let period = {
            let mut plant = self.plant();
            plant.active = active;
            plant.options().map_or(100, |o| o.period_ms)
        };
        let mut timer = self.timer.lock().unwrap_or_else(|p| p.into_inner());
        match (active, *timer) {
            (true, None) => {
                // SAFETY: a thread timer (no window) with our callback.
                let id = unsafe { SetTimer(None, 0, period, Some(on_timer)) };
                if id != 0 {
                    TIMERS.with(|t| t.borrow_mut().insert(id, Arc::downgrade(self)));
                    *timer = Some(id);
                }
            }
            (false, Some(id)) => {
                stop_timer(id);
                *timer = None;
            }
            _ => {}
        }
    }
}

fn stop_timer(id: usize) {
    // SAFETY: a thread timer this thread made.
    let _ = unsafe { KillTimer(None, id) };
    TIMERS.with(|t| t.borrow_mut().remove(&id));
}

thread_local! {
    /// The running timers of this thread's objects, by timer ID.
    static TIMERS: RefCell<HashMap<usize, Weak<Shared>>> = RefCell::new(HashMap::new());
}

unsafe extern "system" fn on_timer(_hwnd: HWND, _msg: u32, id: usize, _time: u32) {
    let shared = TIMERS.with(|t| t.borrow().get(&id).and_then(Weak::upgrade));
    if let Some(shared) = shared {
        let _ = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| shared.tick()));
    }
}

/// `DataChange ItemID, Value, Quality, TimeStamp` to one sink (its failure is ignored: a
/// sink that went away does not stop the others).
fn fire_data_change(sink: &IDispatch, r: &Reading) {
    let values = [
        Value::Date(r.timestamp),
        Value::I4(i32::from(r.quality)),
        r.value.clone(),
        Value::Bstr(r.item.clone()),
    ];
    let mut args: Vec<VARIANT> = values
        .iter()
        .map(|v| variant::to_variant(v).unwrap_or_default())
        .collect();
    let params = DISPPARAMS {
        rgvarg: args.as_mut_ptr(),
        rgdispidNamedArgs: std::ptr::null_mut(),
        cArgs: args.len() as u32,
        cNamedArgs: 0,
    };
    // SAFETY: `params` points at `args`, which outlive the call.
    let _ = unsafe {
        sink.Invoke(
            DATA_CHANGE,
            &GUID::zeroed(),
            0,
            DISPATCH_METHOD,
            &params,
            None,
            None,
            None,
        )
    };
}

#[implement(IDispatch, IProvideClassInfo, RawConnectionPointContainer)]
pub struct ServerCT {
    shared: Arc<Shared>,
    library: ITypeLib,
    info: ITypeInfo,
    start_time: f64,
}

impl ServerCT {
    /// A new object over the type library `library`.
    pub fn create(library: ITypeLib) -> windows::core::Result<IUnknown> {
        // SAFETY: a live type library; the GUID is ours.
        let info = unsafe { library.GetTypeInfoOfGuid(&DIID_SERVER)? };
        let object = ServerCT {
            shared: Arc::new(Shared {
                plant: Mutex::new(Plant::new()),
                events: Arc::new(EventSlot::default()),
                timer: Mutex::new(None),
            }),
            library,
            info,
            start_time: now(),
        };
        let dispatch: IDispatch = object.into();
        dispatch.cast()
    }
}

impl Drop for ServerCT {
    fn drop(&mut self) {
        let timer = self
            .shared
            .timer
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .take();
        if let Some(id) = timer {
            stop_timer(id);
        }
    }
}

/// The arguments of one call, in declaration order (DISPPARAMS holds them reversed).
struct Args<'a> {
    args: Vec<&'a VARIANT>,
    /// The index in DISPPARAMS of each argument, for `puArgErr`.
    arg_err: *mut u32,
}

impl<'a> Args<'a> {
    /// # Safety
    /// `params` is the caller's DISPPARAMS (`cArgs` VARIANTs at `rgvarg`), valid for 'a.
    unsafe fn new(params: *const DISPPARAMS, arg_err: *mut u32) -> windows::core::Result<Args<'a>> {
        if params.is_null() {
            return Err(E_POINTER.into());
        }
        // SAFETY: contract of this function.
        let params = unsafe { &*params };
        let n = params.cArgs as usize;
        if n > 0 && params.rgvarg.is_null() {
            return Err(E_POINTER.into());
        }
        // SAFETY: as above; `i` < cArgs.
        let args = (0..n)
            .rev()
            .map(|i| unsafe { &*params.rgvarg.add(i) })
            .collect();
        Ok(Args { args, arg_err })
    }

    fn len(&self) -> usize {
        self.args.len()
    }

    fn fail(&self, i: usize, code: HRESULT) -> windows::core::Error {
        if !self.arg_err.is_null() {
            // SAFETY: the caller's puArgErr, non-null.
            unsafe { *self.arg_err = (self.args.len() - 1 - i) as u32 };
        }
        code.into()
    }

    /// Argument `i` as a value (by-reference ones read through).
    fn value(&self, i: usize) -> windows::core::Result<Value> {
        variant::from_variant(self.args[i]).map_err(|_| self.fail(i, DISP_E_TYPEMISMATCH))
    }

    /// Whether optional argument `i` was left out.
    fn missing(&self, i: usize) -> bool {
        i >= self.args.len() || {
            let v = self.args[i];
            // SAFETY: the VARTYPE, then the union member it names.
            unsafe {
                v.Anonymous.Anonymous.vt == VT_ERROR
                    && v.Anonymous.Anonymous.Anonymous.scode == DISP_E_PARAMNOTFOUND.0
            }
        }
    }

    /// Writes `value` into `[in, out]` argument `i`, which must be VT_BYREF|VT_VARIANT.
    fn put(&self, i: usize, value: &Value) -> windows::core::Result<()> {
        let v = self.args[i];
        // SAFETY: the VARTYPE, then the union member it names.
        let target = unsafe {
            if v.Anonymous.Anonymous.vt.0 != VT_BYREF.0 | VT_VARIANT.0 {
                return Err(self.fail(i, DISP_E_TYPEMISMATCH));
            }
            v.Anonymous.Anonymous.Anonymous.pvarVal
        };
        if target.is_null() {
            return Err(self.fail(i, E_POINTER));
        }
        let new = variant::to_variant(value)?;
        // SAFETY: the caller's VARIANT behind the reference: the old content is cleared
        // (VARIANT's drop) and the new one moved in.
        unsafe { *target = new };
        Ok(())
    }
}

/// A plant fault as the call's error: DISP_E_EXCEPTION with the EXCEPINFO filled (when
/// the caller passed one), and the text also as the thread's IErrorInfo.
fn raise(f: Fault, excep: *mut EXCEPINFO) -> windows::core::Error {
    if excep.is_null() {
        return ctopc_com::error::error(HRESULT(f.code), &f.text);
    }
    let info = EXCEPINFO {
        scode: f.code,
        bstrSource: std::mem::ManuallyDrop::new(BSTR::from("XConnect.ServerCT")),
        bstrDescription: std::mem::ManuallyDrop::new(BSTR::from(f.text.as_str())),
        ..Default::default()
    };
    // SAFETY: the caller's EXCEPINFO, non-null; its BSTRs are the caller's to free.
    unsafe { excep.write(info) };
    ctopc_com::error::error(DISP_E_EXCEPTION, &f.text)
}

impl ServerCT_Impl {
    fn hang(&self, method: &str) {
        let hang = self.shared.plant().hang_ms(method);
        if let Some(ms) = hang {
            std::thread::sleep(std::time::Duration::from_millis(u64::from(ms)));
        }
    }

    fn call(
        &self,
        dispid: i32,
        flags: DISPATCH_FLAGS,
        a: &Args,
        result: *mut VARIANT,
        excep: *mut EXCEPINFO,
    ) -> windows::core::Result<()> {
        let method = flags.0 & DISPATCH_METHOD.0 != 0;
        let get = flags.0 & DISPATCH_PROPERTYGET.0 != 0;
        let put = flags.0 & (DISPATCH_PROPERTYPUT.0 | DISPATCH_PROPERTYPUTREF.0) != 0;
        let count = |min: usize, max: usize| {
            if (min..=max).contains(&a.len()) {
                Ok(())
            } else {
                Err(windows::core::Error::from(DISP_E_BADPARAMCOUNT))
            }
        };
        let ret = |v: Value| -> windows::core::Result<()> {
            if !result.is_null() {
                let new = variant::to_variant(&v)?;
                // SAFETY: the caller's result VARIANT (initialised, per the contract):
                // the old content is cleared and the new one moved in.
                unsafe { *result = new };
            }
            Ok(())
        };
        let fault = |f: Fault| raise(f, excep);
        let now = now();
        match dispid {
            LOAD_CHANNEL if method => {
                count(1, 1)?;
                let options = std::env::var(OPTIONS_ENV).unwrap_or_default();
                self.shared
                    .plant()
                    .load_channel(&a.value(0)?, &options, now)
                    .map_err(fault)
            }
            INIT if method => {
                count(1, 1)?;
                self.shared.plant().init(&a.value(0)?, now).map_err(fault)
            }
            READ if method => {
                count(4, 5)?;
                self.hang("Read");
                let (source, item) = (a.value(0)?, a.value(1)?);
                let r = self
                    .shared
                    .plant()
                    .read(&source, &item, now)
                    .map_err(fault)?;
                a.put(2, &r.value)?;
                a.put(3, &Value::I4(i32::from(r.quality)))?;
                if !a.missing(4) {
                    a.put(4, &Value::Date(r.timestamp))?;
                }
                Ok(())
            }
            SET_ITEM_ACTIVE if method => {
                count(2, 2)?;
                self.hang("SetItemActive");
                let (item, state) = (a.value(0)?, a.value(1)?);
                self.shared
                    .plant()
                    .set_item_active(&item, &state)
                    .map_err(fault)
            }
            WRITE if method => {
                count(2, 2)?;
                self.hang("Write");
                let (item, value) = (a.value(0)?, a.value(1)?);
                self.shared.plant().write(&item, &value, now).map_err(fault)
            }
            WRITE_EX if method => {
                count(4, 4)?;
                self.hang("WriteEx");
                let (item, value, quality, ts) =
                    (a.value(0)?, a.value(1)?, a.value(2)?, a.value(3)?);
                self.shared
                    .plant()
                    .write_ex(&item, &value, &quality, &ts)
                    .map_err(fault)
            }
            ACTIVE if put => {
                count(1, 1)?;
                let active =
                    plant::boolean(&a.value(0)?).ok_or_else(|| a.fail(0, DISP_E_TYPEMISMATCH))?;
                self.shared.set_active(active);
                Ok(())
            }
            ACTIVE if get => {
                count(0, 0)?;
                ret(Value::Bool(self.shared.plant().active))
            }
            SERVER_STATE if get => {
                count(0, 0)?;
                ret(Value::I4(self.shared.plant().server_state()))
            }
            START_TIME if get => {
                count(0, 0)?;
                ret(Value::Date(self.start_time))
            }
            _ => Err(DISP_E_MEMBERNOTFOUND.into()),
        }
    }
}

impl IDispatch_Impl for ServerCT_Impl {
    fn GetTypeInfoCount(&self) -> windows::core::Result<u32> {
        Ok(1)
    }

    fn GetTypeInfo(&self, index: u32, _lcid: u32) -> windows::core::Result<ITypeInfo> {
        if index != 0 {
            return Err(DISP_E_BADINDEX.into());
        }
        Ok(self.info.clone())
    }

    fn GetIDsOfNames(
        &self,
        _riid: *const GUID,
        names: *const PCWSTR,
        count: u32,
        _lcid: u32,
        ids: *mut i32,
    ) -> windows::core::Result<()> {
        // SAFETY: the caller's arrays of `count` names and DISPIDs, passed on unchanged
        // to the type information of the same interface.
        unsafe { self.info.GetIDsOfNames(names, count, ids) }
    }

    fn Invoke(
        &self,
        dispid: i32,
        _riid: *const GUID,
        _lcid: u32,
        flags: DISPATCH_FLAGS,
        params: *const DISPPARAMS,
        result: *mut VARIANT,
        excep: *mut EXCEPINFO,
        arg_err: *mut u32,
    ) -> windows::core::Result<()> {
        // SAFETY: the caller's DISPPARAMS, valid for the call.
        let args = unsafe { Args::new(params, arg_err)? };
        if flags.0 & (DISPATCH_PROPERTYPUT.0 | DISPATCH_PROPERTYPUTREF.0) != 0 {
            // A property put names its one argument DISPID_PROPERTYPUT.
            // SAFETY: checked non-null in Args::new.
            let p = unsafe { &*params };
            let named = p.cNamedArgs == 1
                && !p.rgdispidNamedArgs.is_null()
                // SAFETY: one named DISPID, non-null.
                && unsafe { *p.rgdispidNamedArgs } == DISPID_PROPERTYPUT;
            if !named {
                return Err(DISP_E_PARAMNOTFOUND.into());
            }
        }
        self.call(dispid, flags, &args, result, excep)
    }
}

impl IProvideClassInfo_Impl for ServerCT_Impl {
    fn GetClassInfo(&self) -> windows::core::Result<ITypeInfo> {
        // SAFETY: a live type library; the GUID is ours.
        unsafe { self.library.GetTypeInfoOfGuid(&CLSID) }
    }
}

impl ServerCT_Impl {
    fn points(&self) -> [(GUID, Arc<dyn Slot>); 1] {
        [(
            DIID_EVENTS,
            Arc::clone(&self.shared.events) as Arc<dyn Slot>,
        )]
    }
}

impl RawConnectionPointContainer_Impl for ServerCT_Impl {
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
