//! What a bench measures about its own process (asix-net's benches, asix-model's
//! `vardb`): the live heap of the counting global allocator the bench declares, the
//! resident memory and the CPU time (Linux's `/proc`; 0 where it is not there).

use stats_alloc::StatsAlloc;
use std::alloc::System;

/// Bytes allocated and not yet freed through `alloc`.
pub fn live(alloc: &StatsAlloc<System>) -> isize {
    let s = alloc.stats();
    s.bytes_allocated as isize - s.bytes_deallocated as isize
}

/// Resident memory of this process, bytes (`/proc/self/statm`).
pub fn resident() -> isize {
    std::fs::read_to_string("/proc/self/statm")
        .ok()
        .and_then(|s| s.split_whitespace().nth(1)?.parse::<isize>().ok())
        .map_or(0, |pages| pages * 4096)
}

/// The process's CPU time (user + system, `/proc/self/stat`, 100 ticks a second).
pub fn cpu_seconds() -> f64 {
    std::fs::read_to_string("/proc/self/stat")
        .ok()
        .and_then(|s| {
            let rest = &s[s.rfind(')')? + 2..];
            let f: Vec<&str> = rest.split_whitespace().collect();
            let ticks = f.get(11)?.parse::<f64>().ok()? + f.get(12)?.parse::<f64>().ok()?;
            Some(ticks / 100.0)
        })
        .unwrap_or(0.0)
}
