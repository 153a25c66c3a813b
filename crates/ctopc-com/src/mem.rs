//! Short-lived re-exports of what `mem` held before it was split by content: CoTaskMem
//! and strings are in [`crate::abi`], the error mapping in [`crate::error`], the clock in
//! [`crate::clock`]. Kept for the callers that other work is changing at the same time
//! (runtime.rs, host.rs, registry.rs, the server binary's backend.rs and logging.rs)
//! until they import the new modules; then this module goes.

pub use crate::abi::{alloc_wstr, free_wstr, TaskMem};
pub use crate::clock::{filetime, local_date, now};
pub use crate::error::{error, hresult, to_com};
