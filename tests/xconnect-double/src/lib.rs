//! A test double of AsixConnect's in-process Automation server `XConnect.ServerCT`
//! (AsixConnect digest §11), for the tests of the late-bound client
//! (`ctopc_com::automation`) and of the asix gateway: a 32-bit DLL with a type library
//! (`xconnect.idl`, "AsixConnect 4 Type Library", compiled by widl beside the DLL as
//! `xconnect_double.tlb`), ProgID `XConnect.ServerCT`, apartment-threaded. Never shipped.
//!
//! - `plant`: the scriptable plant (pure, tested natively): variables, the switches that
//!   make calls fail or hang and set ServerState.
//! - `server` (Windows): the COM object: `IDispatch` by the type library's names and a
//!   hand dispatcher by DISPID, `IProvideClassInfo`, the `DataChange` connection point,
//!   the plant's timer (a thread timer of the creating thread: events arrive while it
//!   pumps messages, as with the original).
//! - `dll` (Windows): DllGetClassObject, DllCanUnloadNow, DllRegisterServer (the class,
//!   the ProgID and the type library), DllUnregisterServer.

pub mod plant;

#[cfg(windows)]
mod dll;
#[cfg(windows)]
mod server;
