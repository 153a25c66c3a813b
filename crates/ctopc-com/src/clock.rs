//! The COM layer's clock: the current UTC time, today's local date, and FILETIME.

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

/// The current UTC time (the only clock read of the COM layer's data path).
pub fn now() -> Timestamp {
    let since = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap_or_default();
    Timestamp::from_unix_micros(since.as_micros())
}

/// Today's local date (year, month, day), for the names of the log files.
pub fn local_date() -> (i32, u32, u32) {
    // SAFETY: no arguments; fills and returns a SYSTEMTIME.
    let t = unsafe { windows::Win32::System::SystemInformation::GetLocalTime() };
    (i32::from(t.wYear), u32::from(t.wMonth), u32::from(t.wDay))
}
