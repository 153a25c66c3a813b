//! Support for the hostile-client test (`tests/tests/hostile.rs`): a watchdog that fails
//! the test with the name of a call that does not return in time, raw calls that send
//! what the client library cannot (lone surrogates, NULLs, hand-made VARIANTs), and
//! sinks that fail or sleep.

use ctopc_com::interfaces::*;
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::{Arc, Condvar, Mutex, OnceLock};
use std::time::{Duration, Instant};
use windows::core::{implement, BOOL, HRESULT, PWSTR};
use windows::Win32::Foundation::FILETIME;
use windows::Win32::System::Com::CoTaskMemFree;
use windows::Win32::System::Variant::{VARENUM, VARIANT};

// ---- the watchdog ---------------------------------------------------------------------

/// The calls under way (name, deadline), innermost last.
struct Armed {
    calls: Mutex<Vec<(String, Instant)>>,
    cv: Condvar,
}

fn armed() -> &'static Arc<Armed> {
    static WATCHDOG: OnceLock<Arc<Armed>> = OnceLock::new();
    WATCHDOG.get_or_init(|| {
        let a = Arc::new(Armed {
            calls: Mutex::new(Vec::new()),
            cv: Condvar::new(),
        });
        let w = Arc::clone(&a);
        std::thread::spawn(move || watch(&w));
        a
    })
}

fn watch(a: &Armed) {
    let mut calls = a.calls.lock().unwrap_or_else(|p| p.into_inner());
    loop {
        let now = Instant::now();
        let first = calls.iter().min_by_key(|(_, d)| *d).cloned();
        match first {
            Some((name, deadline)) if deadline <= now => {
                // A hung COM call cannot be unwound: end the test process, naming it
                // (written past the test harness's output capture, which exit discards).
                use std::io::Write;
                let _ = writeln!(
                    std::io::stderr(),
                    "watchdog: the call `{name}` did not return in time: the server hangs"
                );
                std::process::exit(70);
            }
            Some((_, deadline)) => {
                calls =
                    a.cv.wait_timeout(calls, deadline - now)
                        .unwrap_or_else(|p| p.into_inner())
                        .0;
            }
            None => calls = a.cv.wait(calls).unwrap_or_else(|p| p.into_inner()),
        }
    }
}

/// Runs `f` (one COM call, or a few named together) under the watchdog: if it has not
/// returned within `limit`, the test process exits with code 70 after printing `name`.
pub fn bounded<T>(name: &str, limit: Duration, f: impl FnOnce() -> T) -> T {
    let a = armed();
    let deadline = Instant::now() + limit;
    a.calls
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .push((name.to_owned(), deadline));
    a.cv.notify_all();
    let r = f();
    let mut calls = a.calls.lock().unwrap_or_else(|p| p.into_inner());
    if let Some(i) = calls.iter().rposition(|(n, d)| n == name && *d == deadline) {
        calls.remove(i);
    }
    drop(calls);
    a.cv.notify_all();
    r
}

/// The bound of one ordinary call in the hostile test (generous for a loaded machine).
pub const CALL_LIMIT: Duration = Duration::from_secs(20);

/// [`bounded`] with [`CALL_LIMIT`].
pub fn call<T>(name: &str, f: impl FnOnce() -> T) -> T {
    bounded(name, CALL_LIMIT, f)
}

// ---- texts ----------------------------------------------------------------------------

/// `units` NUL-terminated.
pub fn wide0(units: &[u16]) -> Vec<u16> {
    units.iter().copied().chain(std::iter::once(0)).collect()
}

/// A text of `n` lone (unpaired) high surrogates, NUL-terminated: not valid UTF-16.
pub fn lone_surrogates(n: usize) -> Vec<u16> {
    wide0(&vec![0xD800; n])
}

/// `s` as NUL-terminated UTF-16.
pub fn utf16(s: &str) -> Vec<u16> {
    s.encode_utf16().chain(std::iter::once(0)).collect()
}

// ---- raw calls --------------------------------------------------------------------------

/// One raw item definition: (item ID, access path, requested type), the texts
/// NUL-terminated UTF-16 or `None` for NULL.
pub type RawDef<'a> = (Option<&'a [u16]>, Option<&'a [u16]>, u16);

/// IOPCItemMgt::AddItems of raw definitions: the call's HRESULT and, when it succeeded,
/// the per-item codes and server handles.
pub fn add_items_raw(mgt: &IOPCItemMgt, defs: &[RawDef]) -> (HRESULT, Vec<(HRESULT, u32)>) {
    let items: Vec<OPCITEMDEF> = defs
        .iter()
        .enumerate()
        .map(|(i, (id, path, vt))| OPCITEMDEF {
            szAccessPath: path.map_or(PWSTR::null(), |p| PWSTR(p.as_ptr() as *mut u16)),
            szItemID: id.map_or(PWSTR::null(), |p| PWSTR(p.as_ptr() as *mut u16)),
            bActive: BOOL::from(true),
            hClient: i as u32 + 1,
            dwBlobSize: 0,
            pBlob: std::ptr::null_mut(),
            vtRequestedDataType: VARENUM(*vt),
            wReserved: 0,
        })
        .collect();
    let mut results: *mut OPCITEMRESULT = std::ptr::null_mut();
    let mut errors: *mut HRESULT = std::ptr::null_mut();
    // SAFETY: `items` holds `len` definitions whose strings (NUL-terminated, owned by the
    // caller) outlive the call; valid out-pointers.
    let hr = unsafe {
        mgt.AddItems(
            items.len() as u32,
            items.as_ptr(),
            &mut results,
            &mut errors,
        )
    };
    if hr.is_err() || results.is_null() || errors.is_null() {
        return (hr, Vec::new());
    }
    let n = items.len();
    // SAFETY: CoTaskMem arrays of `n` elements handed out by the call; each freed once.
    unsafe {
        let r = std::slice::from_raw_parts(results, n);
        let e = std::slice::from_raw_parts(errors, n);
        let out = r.iter().zip(e).map(|(r, e)| (*e, r.hServer)).collect();
        for x in r {
            if !x.pBlob.is_null() {
                CoTaskMemFree(Some(x.pBlob as *const _));
            }
        }
        CoTaskMemFree(Some(results as *const _));
        CoTaskMemFree(Some(errors as *const _));
        (hr, out)
    }
}

/// IOPCSyncIO::Write of hand-made VARIANTs (not cleared here): the HRESULT and the
/// per-item codes.
pub fn write_raw(io: &IOPCSyncIO, handles: &[u32], values: &[VARIANT]) -> (HRESULT, Vec<HRESULT>) {
    assert_eq!(handles.len(), values.len());
    let mut errors: *mut HRESULT = std::ptr::null_mut();
    // SAFETY: both arrays hold `len` elements and live for the call; valid out-pointer.
    let hr = unsafe {
        io.Write(
            handles.len() as u32,
            handles.as_ptr(),
            values.as_ptr(),
            &mut errors,
        )
    };
    if hr.is_err() || errors.is_null() {
        return (hr, Vec::new());
    }
    // SAFETY: a CoTaskMem array of that many elements, just handed out by the call.
    (hr, unsafe { opc_client::take_array(errors, handles.len()) })
}

// ---- sinks ----------------------------------------------------------------------------

/// What a [`RudeSink`] does when called.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Rudeness {
    /// Every callback returns E_FAIL.
    Fail,
    /// Every callback sleeps this long, then returns S_OK.
    Sleep(Duration),
}

/// An IOPCDataCallback that fails or sleeps; counts its calls.
#[implement(IOPCDataCallback)]
pub struct RudeSink {
    pub how: Rudeness,
    pub calls: Arc<AtomicU32>,
}

impl RudeSink {
    pub fn create(how: Rudeness, calls: &Arc<AtomicU32>) -> IOPCDataCallback {
        RudeSink {
            how,
            calls: Arc::clone(calls),
        }
        .into()
    }

    fn answer(&self) -> windows::core::Result<()> {
        self.calls.fetch_add(1, Ordering::SeqCst);
        match self.how {
            Rudeness::Fail => Err(windows::Win32::Foundation::E_FAIL.into()),
            Rudeness::Sleep(d) => {
                std::thread::sleep(d);
                Ok(())
            }
        }
    }
}

impl IOPCDataCallback_Impl for RudeSink_Impl {
    unsafe fn OnDataChange(
        &self,
        _transaction: u32,
        _group: u32,
        _master_quality: HRESULT,
        _master_error: HRESULT,
        _n: u32,
        _h: *const u32,
        _v: *const VARIANT,
        _q: *const u16,
        _t: *const FILETIME,
        _e: *const HRESULT,
    ) -> windows::core::Result<()> {
        self.answer()
    }

    unsafe fn OnReadComplete(
        &self,
        _transaction: u32,
        _group: u32,
        _master_quality: HRESULT,
        _master_error: HRESULT,
        _n: u32,
        _h: *const u32,
        _v: *const VARIANT,
        _q: *const u16,
        _t: *const FILETIME,
        _e: *const HRESULT,
    ) -> windows::core::Result<()> {
        self.answer()
    }

    unsafe fn OnWriteComplete(
        &self,
        _transaction: u32,
        _group: u32,
        _master_error: HRESULT,
        _n: u32,
        _h: *const u32,
        _e: *const HRESULT,
    ) -> windows::core::Result<()> {
        self.answer()
    }

    unsafe fn OnCancelComplete(&self, _transaction: u32, _group: u32) -> windows::core::Result<()> {
        self.answer()
    }
}

// ---- processes ------------------------------------------------------------------------

/// Ends the ServerCTOPC.exe processes of this prefix with TerminateProcess, then its
/// rpcss.exe: after a client died without releasing, its references keep the server
/// alive for ever under Wine (no DCOM ping), and later tests need it gone. A killed
/// server's class registration stays in rpcss (activations then fail with
/// RPC_S_SERVER_UNAVAILABLE), so rpcss goes too; COM starts it again on the next
/// activation.
pub fn terminate_servers() -> usize {
    let servers = terminate("ServerCTOPC.exe");
    terminate("rpcss.exe");
    servers
}

/// Terminates every process of this prefix named `exe`; how many.
fn terminate(exe: &str) -> usize {
    use windows::Win32::Foundation::CloseHandle;
    use windows::Win32::System::Threading::{
        OpenProcess, TerminateProcess, WaitForSingleObject, PROCESS_SYNCHRONIZE, PROCESS_TERMINATE,
    };
    let mut n = 0;
    for pid in crate::processes_named(exe) {
        // SAFETY: a process handle opened, used and closed here.
        unsafe {
            if let Ok(h) = OpenProcess(PROCESS_TERMINATE | PROCESS_SYNCHRONIZE, false, pid) {
                if TerminateProcess(h, 1).is_ok() {
                    n += 1;
                    let _ = WaitForSingleObject(h, 10_000);
                }
                let _ = CloseHandle(h);
            }
        }
    }
    n
}
