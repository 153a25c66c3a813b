//! Short-lived re-exports of what `mem` held before it was split by content: CoTaskMem
//! and strings are in [`crate::abi`], the error mapping in [`crate::error`], the clock in
//! [`crate::clock`]. Kept for the callers outside the COM objects (runtime.rs, host.rs,
//! the server binary, opcdiag, the e2e tests) until they import the new modules.

pub use crate::abi::{alloc_wstr, free_wstr, TaskMem};
pub use crate::clock::{filetime, local_date, now};
pub use crate::error::{error, hresult, to_com};
