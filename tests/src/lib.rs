//! Helpers shared by the end-to-end tests (Windows only; run under Wine by `cargo xtask test`).
//!
//! The tests drive the real ServerCTOPC.exe out of process through COM, through the
//! project's own proxy/stub DLL, both registered in the test Wine prefix by xtask. Tests
//! that pass deliberately invalid raw pointers call the interfaces directly (`unsafe`):
//! that is what they test.
#![cfg(windows)]

pub use ctopc_com::client::{ComThread, Server};
pub use ctopc_com::interfaces;
use std::path::PathBuf;
use windows::core::HRESULT;

pub const PROGID: &str = "ServerCTOPC.App";

/// Joins the MTA and connects to a new ServerCTOPC server object.
pub fn connect() -> (ComThread, Server) {
    let com = ComThread::mta().expect("CoInitializeEx");
    let server = Server::connect(PROGID).expect("CoCreateInstance(ServerCTOPC.App)");
    (com, server)
}

/// A Windows build artifact next to the test binaries (target/<triple>/release/<name>).
pub fn artifact(name: &str) -> PathBuf {
    let exe = std::env::current_exe().expect("current_exe");
    // .../release/deps/test-xxxx.exe -> .../release/<name>
    exe.parent().and_then(|d| d.parent()).expect("artifact dir").join(name)
}

/// The HRESULT of a failed call, or S_OK.
pub fn code<T>(r: &windows::core::Result<T>) -> HRESULT {
    match r {
        Ok(_) => HRESULT(0),
        Err(e) => e.code(),
    }
}

/// Asserts the server still answers (after a failure path).
pub fn assert_alive(server: &Server) {
    let status = server.status().expect("server still answers GetStatus");
    assert!(status.vendor_info.is_some());
}
