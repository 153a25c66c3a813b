//! Harness of the in-process COM tests of the server and group objects.
//!
//! The tests call the objects' methods **in this process, without the proxy/stub**, so a
//! NULL pointer, a count of 0, an enumeration value outside the IDL's or an unknown handle
//! reaches the server's own checks, and the precise HRESULT and the all-or-nothing rule
//! for out-parameters can be asserted (through the proxy a NULL `[ref]` pointer is
//! answered by RPC_X_NULL_REF_POINTER before the server sees it).
//!
//! All setup is here, in [`start`]: the thread joins the multithreaded apartment, and the
//! test gets **its own server context**, with its own runtime, over the embedded demo
//! plant (`asix_model::embedded_demo()`, loaded once per test process) with the in-process
//! simulation the binary uses (`asix_net::inproc::InProcessSim`, as
//! `crates/server/src/backend.rs`), the way `host::start` does it for `ServerCTOPC.exe`.
//! Each test runs on a thread of its own, and the context is the test thread's: every
//! server a test makes **through the class factory** ([`factory`], [`new_server`],
//! [`server`]) while another of its objects lives is a client of the same server (one
//! engine, one plant), as two clients of one `ServerCTOPC.exe`; no two tests share one.
//! The thread keeps only a weak reference: when the test has released the server's
//! objects and class objects, the context drops and its driver thread ends (on the test's
//! thread, not in a thread-local destructor). [`new_context`] makes a further one.
//!
//! Out-parameter checks: a test pre-fills an out-parameter with [`POISON`] (a pointer
//! value that is never dereferenced) and asserts that a failed call wrote NULL/0 there.
#![allow(dead_code, unused_imports)]

use asix_net::inproc::InProcessSim;
use ctopc_com::context::{self, Context};
use ctopc_com::interfaces::*;
use ctopc_com::{host, server};
use ctopc_core::source::Backend;
// Starting a process through Wine's transient start failure.
use std::cell::{Cell, RefCell};
use std::ffi::c_void;
use std::sync::{Arc, OnceLock, Weak};
use test_support::start::StartRetrying;
pub use windows::core::{IUnknown, Interface, BOOL, GUID, HRESULT, HSTRING, PCWSTR, PWSTR};
use windows::Win32::System::Com::{
    CoInitializeEx, CoTaskMemFree, IClassFactory, COINIT_MULTITHREADED,
};

pub use windows::Win32::Foundation::{
    CLASS_E_NOAGGREGATION, E_FAIL, E_INVALIDARG, E_NOINTERFACE, E_POINTER, S_FALSE, S_OK,
};

/// Seed of the simulated plant (the server binary's, `crates/server/src/backend.rs`).
pub const SIM_SEED: u64 = 0x5EED_A51C;

/// A pointer value written into out-parameters before a call that must clear them. Never
/// dereferenced: a test only compares it.
pub const POISON: usize = 0xDEAD_BEE0;

/// [`POISON`] as a pointer of any type.
pub fn poison<T>() -> *mut T {
    POISON as *mut T
}

/// The HRESULT of a call that returns `Result<()>` (S_OK for success).
pub fn hr(r: windows::core::Result<()>) -> HRESULT {
    match r {
        Ok(()) => S_OK,
        Err(e) => e.code(),
    }
}

/// The HRESULT of any call that returns a `Result`.
pub fn code<T>(r: &windows::core::Result<T>) -> HRESULT {
    match r {
        Ok(_) => S_OK,
        Err(e) => e.code(),
    }
}

fn join_mta() {
    thread_local! {
        static JOINED: Cell<bool> = const { Cell::new(false) };
    }
    JOINED.with(|j| {
        if !j.get() {
            // SAFETY: joins the MTA for this thread; never uninitialised (the thread ends
            // with the test, the process with the test binary).
            let r = unsafe { CoInitializeEx(None, COINIT_MULTITHREADED) };
            assert!(r.is_ok(), "CoInitializeEx(MTA): {r:?}");
            j.set(true);
        }
    });
}

/// The embedded demo plant and its browse tree (immutable: shared by every context).
struct Demo {
    ns: Arc<asix_model::AsixNamespace>,
    address_space: Arc<ctopc_core::browse::AddressSpace>,
}

static DEMO: OnceLock<Result<Demo, String>> = OnceLock::new();

fn demo() -> &'static Demo {
    let demo = DEMO.get_or_init(|| {
        let loaded = asix_model::embedded_demo()?;
        let ns = Arc::new(loaded.namespace);
        let address_space = Arc::new(
            asix_model::address_space::build_address_space(&ns).map_err(|e| format!("{e:?}"))?,
        );
        Ok(Demo { ns, address_space })
    });
    match demo {
        Ok(d) => d,
        Err(e) => panic!("cannot load the embedded demo: {e}"),
    }
}

thread_local! {
    /// This test's context while any of its objects lives (weak: the context drops with
    /// the test's last object, never in a thread-local destructor).
    static TEST_CONTEXT: RefCell<Weak<Context>> = const { RefCell::new(Weak::new()) };
}

/// Joins the MTA (this thread) and gives this test's server context: the live one, else
/// a new one ([`new_context`]).
pub fn start() -> Arc<Context> {
    join_mta();
    if let Some(ctx) = TEST_CONTEXT.with(|c| c.borrow().upgrade()) {
        return ctx;
    }
    let ctx = new_context();
    TEST_CONTEXT.with(|c| *c.borrow_mut() = Arc::downgrade(&ctx));
    ctx
}

/// Joins the MTA (this thread) and starts a new server context, not this test's: its own
/// runtime (engine and simulated plant) over the demo.
pub fn new_context() -> Arc<Context> {
    new_context_with(|_| {})
}

/// [`new_context`] with the demo's engine configuration changed by `tune` (e.g. a shorter
/// `min_update_rate_ms`, as a `MinUpdateRate` in the ini would make it).
pub fn new_context_with(tune: impl FnOnce(&mut ctopc_core::model::EngineConfig)) -> Arc<Context> {
    join_mta();
    let Demo { ns, address_space } = demo();
    // As ServerCTOPC.exe's `setup()` (crates/server/src/main.rs) makes it.
    let server = &ns.config().server;
    let mut engine_config = server.engine_config();
    tune(&mut engine_config);
    let setup = context::Setup {
        legacy_open_access: false,
        namespace: Arc::clone(ns) as Arc<dyn ctopc_core::namespace::Namespace>,
        address_space: Arc::clone(address_space),
        engine_config,
        default_language: server.default_language.fixed(),
        no_config_reason: ns.no_config_reason(),
        ops: server.ops_config(),
    };
    let ns = Arc::clone(ns);
    let started = host::start(
        setup,
        Box::new(move |_wake| {
            let sim = InProcessSim::new(ns, SIM_SEED, ctopc_com::clock::now());
            Ok(Box::new(sim) as Box<dyn Backend>)
        }),
    );
    match started {
        Ok(ctx) => ctx,
        Err(e) => panic!("cannot start the server runtime: {e}"),
    }
}

/// The class object `ServerCTOPC.exe` registers, over this test's context ([`start`]):
/// each CreateInstance makes a new server object of that context.
pub fn factory() -> IClassFactory {
    server::class_factory(&start())
}

/// A new server object through IClassFactory::CreateInstance(NULL, IID_IUnknown), of this
/// test's context.
pub fn new_server() -> IUnknown {
    new_server_of(&factory())
}

/// A new server object of the class object `f` (of `f`'s context).
pub fn new_server_of(f: &IClassFactory) -> IUnknown {
    // SAFETY: a valid class object; no aggregation.
    unsafe { f.CreateInstance::<_, IUnknown>(None) }.expect("CreateInstance(IID_IUnknown)")
}

/// A new server object as interface `T` (through the class factory, then QueryInterface).
pub fn server<T: Interface>() -> T {
    new_server()
        .cast::<T>()
        .expect("the server object implements the interface")
}

/// A new server object as IOPCServer.
pub fn opc_server() -> IOPCServer {
    server::<IOPCServer>()
}

/// A NUL-terminated UTF-16 copy of `s`; use [`pcwstr`] for the pointer.
pub fn wide(s: &str) -> HSTRING {
    HSTRING::from(s)
}

/// The `[in, string]` pointer of a string made by [`wide`] (valid while it lives).
pub fn pcwstr(s: &HSTRING) -> PCWSTR {
    PCWSTR(s.as_ptr())
}

/// Reads a CoTaskMem string handed out by the server and frees it. `None` for NULL.
///
/// # Safety
/// `p` is NULL or a NUL-terminated CoTaskMem string owned by the caller.
pub unsafe fn take_wstr(p: PWSTR) -> Option<String> {
    if p.is_null() {
        return None;
    }
    // SAFETY: contract of this function.
    let s = unsafe { p.to_string() }.expect("valid UTF-16");
    // SAFETY: the string is the caller's CoTaskMem block, not used afterwards.
    unsafe { CoTaskMemFree(Some(p.0 as *const c_void)) };
    Some(s)
}

/// Copies a CoTaskMem array of `n` plain elements handed out by the server and frees it.
/// Empty for NULL.
///
/// # Safety
/// `p` is NULL or a CoTaskMem array of at least `n` initialised `T`s owned by the caller,
/// whose elements own no further memory (or whose memory the caller frees from the copy).
pub unsafe fn take_array<T: Copy>(p: *mut T, n: usize) -> Vec<T> {
    if p.is_null() {
        return Vec::new();
    }
    // SAFETY: contract of this function.
    let v = unsafe { std::slice::from_raw_parts(p, n) }.to_vec();
    // SAFETY: the block is the caller's, not used afterwards.
    unsafe { CoTaskMemFree(Some(p as *const c_void)) };
    v
}

/// Frees a CoTaskMem block (NULL is fine).
///
/// # Safety
/// `p` is NULL or a CoTaskMem block owned by the caller and not used afterwards.
pub unsafe fn task_free<T>(p: *mut T) {
    // SAFETY: contract of this function.
    unsafe { CoTaskMemFree(Some(p as *const c_void)) };
}

/// Frees a CoTaskMem array of `n` CoTaskMem strings (each may be NULL) and returns them.
///
/// # Safety
/// `p` is NULL or a CoTaskMem array of `n` string pointers, all owned by the caller.
pub unsafe fn take_wstr_array(p: *mut PWSTR, n: usize) -> Vec<Option<String>> {
    // SAFETY: contract of this function.
    let ptrs = unsafe { take_array(p, n) };
    // SAFETY: each element is NULL or a CoTaskMem string owned by the caller.
    ptrs.into_iter().map(|s| unsafe { take_wstr(s) }).collect()
}

/// An interface out-parameter slot (`*mut Option<IUnknown>` / `*mut Option<I>`) that can
/// be pre-filled with [`POISON`] without ever being released as if it were an interface.
pub struct OutUnk(pub *mut c_void);

impl OutUnk {
    /// A slot holding [`POISON`].
    pub fn poisoned() -> OutUnk {
        OutUnk(poison())
    }
    /// A slot holding NULL.
    pub fn null() -> OutUnk {
        OutUnk(std::ptr::null_mut())
    }
    /// The slot as an `[out]` interface pointer of any type.
    pub fn as_out<I>(&mut self) -> *mut Option<I> {
        (&mut self.0 as *mut *mut c_void).cast()
    }
    pub fn is_null(&self) -> bool {
        self.0.is_null()
    }
    /// Takes the interface written by a successful call (None for NULL). Panics if the
    /// slot still holds [`POISON`].
    pub fn take(&mut self) -> Option<IUnknown> {
        let p = std::mem::replace(&mut self.0, std::ptr::null_mut());
        assert_ne!(
            p as usize, POISON,
            "the call did not write the out-parameter"
        );
        if p.is_null() {
            None
        } else {
            // SAFETY: a successful call wrote an owned interface pointer (of the requested
            // interface, which is also an IUnknown for AddRef/Release/QueryInterface).
            Some(unsafe { IUnknown::from_raw(p) })
        }
    }
}

impl Drop for OutUnk {
    fn drop(&mut self) {
        if !self.0.is_null() && self.0 as usize != POISON {
            // SAFETY: a non-null, non-poison pointer here was written by a call as an
            // owned interface pointer: release it.
            drop(unsafe { IUnknown::from_raw(self.0) });
        }
    }
}

/// A group added through IOPCServer::AddGroup.
pub struct Group {
    /// AddGroup's HRESULT (S_OK, or OPC_S_UNSUPPORTEDRATE for a revised rate).
    pub code: HRESULT,
    pub server_handle: u32,
    pub revised_rate: u32,
    /// The group object as asked for (IID_IUnknown).
    pub unknown: IUnknown,
    pub item_mgt: IOPCItemMgt,
}

/// What AddGroup is asked for; [`GroupArgs::new`] gives an active group with rate 1000 ms,
/// client handle 1, no time bias, no deadband and LCID 0x0409.
#[derive(Debug, Clone)]
pub struct GroupArgs {
    pub name: String,
    pub active: bool,
    pub rate_ms: u32,
    pub client_handle: u32,
    pub time_bias: Option<i32>,
    pub deadband: Option<f32>,
    pub lcid: u32,
}

impl GroupArgs {
    pub fn new(name: &str) -> GroupArgs {
        GroupArgs {
            name: name.to_string(),
            active: true,
            rate_ms: 1000,
            client_handle: 1,
            time_bias: None,
            deadband: None,
            lcid: 0x0409,
        }
    }
}

/// AddGroup with `args`, asking for IID_IUnknown; panics when it fails.
pub fn add_group_with(server: &IOPCServer, args: &GroupArgs) -> Group {
    let name = wide(&args.name);
    let bias = args.time_bias;
    let deadband = args.deadband;
    let (mut handle, mut revised) = (0u32, 0u32);
    let mut out = OutUnk::null();
    // SAFETY: every pointer is valid for the call; the optional ones are NULL or point to
    // a local value.
    let code = unsafe {
        server.AddGroup(
            pcwstr(&name),
            BOOL::from(args.active),
            args.rate_ms,
            args.client_handle,
            bias.as_ref().map_or(std::ptr::null(), |b| b as *const i32),
            deadband
                .as_ref()
                .map_or(std::ptr::null(), |d| d as *const f32),
            args.lcid,
            &mut handle,
            &mut revised,
            &IUnknown::IID,
            out.as_out(),
        )
    };
    assert!(code.is_ok(), "AddGroup({:?}): {code:?}", args.name);
    let unknown = out.take().expect("AddGroup wrote the group object");
    let item_mgt = unknown
        .cast::<IOPCItemMgt>()
        .expect("the group object implements IOPCItemMgt");
    Group {
        code,
        server_handle: handle,
        revised_rate: revised,
        unknown,
        item_mgt,
    }
}

/// AddGroup of an active group named `name` (rate 1000 ms, client handle 1).
pub fn add_group(server: &IOPCServer, name: &str) -> Group {
    add_group_with(server, &GroupArgs::new(name))
}

/// A new server object and one group on it (keep the server alive as long as the group).
pub fn server_with_group(name: &str) -> (IOPCServer, Group) {
    let s = opc_server();
    let g = add_group(&s, name);
    (s, g)
}

/// The raw vtable call `QueryInterface(riid, ppv)` of any interface, for NULL arguments.
///
/// # Safety
/// `riid` and `ppv` are NULL or valid for the call.
pub unsafe fn raw_query(unk: &IUnknown, riid: *const GUID, ppv: *mut *mut c_void) -> HRESULT {
    // SAFETY: a valid interface pointer; the arguments per this function's contract.
    unsafe { (Interface::vtable(unk).QueryInterface)(unk.as_raw(), riid, ppv) }
}

/// A new server object wrapped in the client library's `Server` (for success paths: its
/// readers copy and free what the server hands out).
pub fn client() -> opc_client::Server {
    client_from(&factory())
}

/// [`client`] over a new server object of the class object `f` (its context).
pub fn client_from(f: &IClassFactory) -> opc_client::Server {
    opc_client::Server::from_unknown(new_server_of(f)).expect("IOPCServer and IOPCCommon")
}

/// The environment variable that tells a child test process which helper test to run.
const CHILD_ENV: &str = "CTOPC_INPROC_CHILD";

/// Runs the test `name` of this test binary in a child process (for a call that may crash
/// the process, e.g. one writing through a NULL out-parameter): `name` must be an
/// `#[ignore]`d test that starts with `if !in_child("name") { return; }`. True when the
/// child ran it and passed; false when it failed or crashed.
pub fn passes_in_child(name: &str) -> bool {
    let exe = std::env::current_exe().expect("current_exe");
    let out = std::process::Command::new(exe)
        .args([name, "--exact", "--ignored", "--test-threads=1"])
        .env(CHILD_ENV, name)
        .output_retrying()
        .expect("run the test binary as a child");
    if !out.status.success() {
        eprintln!(
            "child test {name}: {:?}\n{}{}",
            out.status,
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
    }
    out.status.success()
}

/// Whether this process is the child [`passes_in_child`] started for test `name`.
pub fn in_child(name: &str) -> bool {
    std::env::var(CHILD_ENV).is_ok_and(|v| v == name)
}

/// A NUL-terminated UTF-16 string that is not valid UTF-16 (an unpaired surrogate): the
/// proxy would carry it, and the server must reject it with the method's code.
pub const UNPAIRED_SURROGATE: [u16; 4] = [0x004B, 0xD800, 0x0041, 0];

/// [`UNPAIRED_SURROGATE`] as an `[in, string]` pointer (a static: valid for any call).
pub fn bad_utf16() -> PCWSTR {
    PCWSTR(UNPAIRED_SURROGATE.as_ptr())
}
