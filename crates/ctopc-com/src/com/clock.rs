//! The COM layer's clock: FILETIME, today's local date, and the runtime's current UTC time.

use ctopc_core::Timestamp;
use windows::Win32::Foundation::FILETIME;

/// A timestamp as a FILETIME.
pub fn filetime(t: Timestamp) -> FILETIME {
    let (lo, hi) = t.filetime_parts();
    FILETIME {
        dwLowDateTime: lo,
        dwHighDateTime: hi,
    }
}

pub use ctopc_runtime::clock::now;

/// Today's local date (year, month, day), for the names of the log files.
pub fn local_date() -> (i32, u32, u32) {
    // SAFETY: no arguments; fills and returns a SYSTEMTIME.
    let t = unsafe { windows::Win32::System::SystemInformation::GetLocalTime() };
    (i32::from(t.wYear), u32::from(t.wMonth), u32::from(t.wDay))
}
