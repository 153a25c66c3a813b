//! Helpers shared by the end-to-end tests (Windows only; run under Wine by `cargo xtask test`).
//!
//! The tests drive the real ServerCTOPC.exe out of process through COM, through the
//! project's own proxy/stub DLL, both registered in the test Wine prefix by xtask. Tests
//! that pass deliberately invalid raw pointers call the interfaces directly (`unsafe`):
//! that is what they test. [`probe`] is the marshal probe, the test COM server of
//! `marshal-probe.exe` (its `unsafe` blocks carry `// SAFETY:` comments, checked by
//! clippy's `undocumented_unsafe_blocks` as in the COM crate).
#![cfg(windows)]

pub mod da10;
pub mod doctor;
pub mod hostile;
pub mod io_support;
pub mod probe;
pub mod server_config;
pub mod start;

pub use ctopc_com::apartment::Apartment;
pub use ctopc_com::interfaces;
pub use opc_client::Server;
use std::path::PathBuf;
use windows::core::{IUnknown, HRESULT};

pub const PROGID: &str = "ServerCTOPC.App";

/// Joins the MTA and connects to a new ServerCTOPC server object.
pub fn connect() -> (Apartment, Server) {
    let com = Apartment::mta().expect("CoInitializeEx");
    let server = Server::connect(PROGID).expect("CoCreateInstance(ServerCTOPC.App)");
    (com, server)
}

/// The 64-bit target (the server's): where `cargo xtask build` puts ServerCTOPC.exe.
const SERVER_TARGET: &str = "x86_64-pc-windows-gnu";

/// A file of the server's build (`cargo xtask build`: ServerCTOPC.exe, its `Log\\`, the
/// 64-bit opc_ps.dll), in target/x86_64-pc-windows-gnu/release. The server is 64-bit
/// whatever the bitness of the test client: a 32-bit test binary
/// (target/i686-pc-windows-gnu/release/deps) finds it in the 64-bit folder beside its own.
pub fn artifact(name: &str) -> PathBuf {
    let release = own_artifact_dir();
    let triple_dir = release.parent();
    match triple_dir
        .and_then(|t| t.file_name())
        .and_then(|n| n.to_str())
    {
        Some(triple) if triple != SERVER_TARGET && triple.ends_with("-pc-windows-gnu") => {
            triple_dir
                .and_then(|t| t.parent())
                .expect("target dir")
                .join(SERVER_TARGET)
                .join("release")
                .join(name)
        }
        _ => release.join(name),
    }
}

/// A Windows build artifact of the test binary's own bitness, next to it
/// (target/<triple>/release/<name>): opcdiag.exe, marshal-probe.exe.
pub fn own_artifact(name: &str) -> PathBuf {
    own_artifact_dir().join(name)
}

fn own_artifact_dir() -> PathBuf {
    let exe = std::env::current_exe().expect("current_exe");
    // .../release/deps/test-xxxx.exe -> .../release
    exe.parent()
        .and_then(|d| d.parent())
        .expect("artifact dir")
        .to_path_buf()
}

/// The HRESULT of a failed call, or S_OK.
pub fn code<T>(r: &windows::core::Result<T>) -> HRESULT {
    match r {
        Ok(_) => HRESULT(0),
        Err(e) => e.code(),
    }
}

/// Asserts the server still answers (after a failure path).
/// RPC_X_NULL_REF_POINTER: what the proxy answers for a NULL `[ref]` pointer.
pub const RPC_X_NULL_REF_POINTER: HRESULT = HRESULT(0x800706F4u32 as i32);

/// A NULL argument through the proxy: the proxy answers RPC_X_NULL_REF_POINTER before the
/// server sees it for most `[ref]` pointers, and Wine's lets some through to the server,
/// which answers E_INVALIDARG; either is right out of process. The server's own answer is
/// checked exactly by the in-process tests (`crates/ctopc-com/tests/inproc_*.rs`).
pub fn assert_invalid_arg_or_null_ref(hr: HRESULT, what: &str) {
    assert!(
        hr == windows::Win32::Foundation::E_INVALIDARG || hr == RPC_X_NULL_REF_POINTER,
        "{what}: {hr:?}"
    );
}

pub fn assert_alive(server: &Server) {
    let status = server.status().expect("server still answers GetStatus");
    assert!(status.vendor_info.is_some());
}

/// The process IDs of the ServerCTOPC.exe processes of this Wine prefix other than `mine`.
pub fn other_servers(mine: u32) -> Vec<u32> {
    processes_named("ServerCTOPC.exe")
        .into_iter()
        .filter(|p| *p != mine)
        .collect()
}

/// The process IDs of this Wine prefix's processes named `exe` (case-insensitive).
pub fn processes_named(exe: &str) -> Vec<u32> {
    use windows::Win32::Foundation::CloseHandle;
    use windows::Win32::System::Diagnostics::ToolHelp::{
        CreateToolhelp32Snapshot, Process32FirstW, Process32NextW, PROCESSENTRY32W,
        TH32CS_SNAPPROCESS,
    };
    let mut out = Vec::new();
    // SAFETY: a process snapshot, walked with a correctly sized PROCESSENTRY32W and closed.
    unsafe {
        let Ok(snap) = CreateToolhelp32Snapshot(TH32CS_SNAPPROCESS, 0) else {
            return out;
        };
        let mut e = PROCESSENTRY32W {
            dwSize: std::mem::size_of::<PROCESSENTRY32W>() as u32,
            ..Default::default()
        };
        let mut ok = Process32FirstW(snap, &mut e).is_ok();
        while ok {
            let len = e
                .szExeFile
                .iter()
                .position(|&c| c == 0)
                .unwrap_or(e.szExeFile.len());
            let name = String::from_utf16_lossy(&e.szExeFile[..len]);
            if name.eq_ignore_ascii_case(exe) {
                out.push(e.th32ProcessID);
            }
            ok = Process32NextW(snap, &mut e).is_ok();
        }
        let _ = CloseHandle(snap);
    }
    out
}

/// Waits (without connecting: a connection would restart their linger time) until no
/// other ServerCTOPC.exe runs. Wine hands activations to the first server that registered
/// the class, so the test's own server must be the only one. A server that does not go
/// away holds references of a client that died without releasing them (Wine has no DCOM
/// ping): that is a leak in an earlier test, reported here.
pub fn wait_for_no_other_server() {
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(60);
    loop {
        let others = other_servers(0);
        if others.is_empty() {
            return;
        }
        assert!(
            std::time::Instant::now() < deadline,
            "other ServerCTOPC.exe processes {others:?} still run after 60 s (a client leaked references?)"
        );
        std::thread::sleep(std::time::Duration::from_millis(500));
    }
}

/// The next element of an IEnumConnections. (Under Wine the HRESULT of a call that returns
/// an interface is not reliable: look at the element.)
pub fn next_connection(
    e: &windows::Win32::System::Com::IEnumConnections,
) -> Option<(u32, IUnknown)> {
    let mut one = [windows::Win32::System::Com::CONNECTDATA::default()];
    // SAFETY: room for the one element asked for; a NULL pceltFetched is allowed for one.
    let _ = unsafe { e.Next(&mut one, std::ptr::null_mut()) };
    let [cd] = one;
    let unk = std::mem::ManuallyDrop::into_inner(cd.pUnk)?;
    Some((cd.dwCookie, unk))
}

/// Every connection of a point, through EnumConnections.
pub fn connections(cp: &windows::Win32::System::Com::IConnectionPoint) -> Vec<(u32, IUnknown)> {
    // SAFETY: a valid interface pointer.
    let e = unsafe { cp.EnumConnections() }.expect("EnumConnections");
    let mut v = Vec::new();
    while let Some(c) = next_connection(&e) {
        v.push(c);
        assert!(v.len() < 10, "an endless enumeration");
    }
    v
}
