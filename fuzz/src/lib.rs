//! Fuzz targets for every decoder of outside input, and a stable runner for them.
//!
//! Each target is a `fn(&[u8])` that must not panic, hang or allocate without bound for
//! any input ([`targets`]). They run two ways:
//!
//! - **libFuzzer** (`cargo fuzz run <target>`, nightly, coverage-guided): the binaries of
//!   `fuzz_targets/` (feature `libfuzzer`), seeded from `corpus/<target>/` when present;
//! - **the random runner** (`cargo xtask fuzz --seconds N` without cargo-fuzz, and CI on
//!   stable): [`run`] mutates the [`seeds`] and random bytes with a seeded PRNG for a
//!   time budget, catching panics; a failing input is written to
//!   `target/fuzz-failures/<target>-<hash>.bin` and named in the error.
//!
//! Inputs that once failed are kept in `regressions/<target>/` and replayed by
//! `tests/regressions.rs`.
#![forbid(unsafe_code)]

use std::time::{Duration, Instant};

pub mod targets;

/// A fuzz target: takes any bytes, must not panic.
pub type Target = fn(&[u8]);

/// Every target: its name and its function.
pub const TARGETS: &[(&str, Target)] = &[
    ("asix_frame", targets::asix_frame),
    ("asix_datagram", targets::asix_datagram),
    ("ini", targets::ini),
    ("csv_attributes", targets::csv_attributes),
    ("paradox", targets::paradox),
    ("zez_varset", targets::zez_varset),
    ("item_id", targets::item_id),
    ("match_pattern", targets::match_pattern),
    ("format", targets::format),
    ("value_convert", targets::value_convert),
    ("asix_rest_answer", targets::asix_rest_answer),
    ("ua_request", targets::ua_request),
    ("ua_variant", targets::ua_variant),
    ("ua_users", targets::ua_users),
    ("ua_node_id", targets::ua_node_id),
];

/// The target called `name`.
pub fn target(name: &str) -> Option<Target> {
    TARGETS.iter().find(|(n, _)| *n == name).map(|(_, f)| *f)
}

/// Valid inputs to start mutating from: the demo plant's files and typical values.
pub fn seeds(name: &str) -> Vec<Vec<u8>> {
    use asix_model::startup::{DEMO_INI, DEMO_SET, DEMO_TABLE};
    let text = |v: &[&str]| v.iter().map(|s| s.as_bytes().to_vec()).collect();
    match name {
        "asix_frame" => targets::sample_frames(),
        "asix_datagram" => targets::sample_datagrams(),
        "asix_rest_answer" => targets::sample_rest_answers(),
        "ua_request" => targets::sample_ua_requests(),
        // Variants: Double 12.5, String "12", Boolean true, Int32 array [1, 2].
        "ua_variant" => vec![
            [vec![11], 12.5f64.to_le_bytes().to_vec()].concat(),
            vec![12, 2, 0, 0, 0, b'1', b'2'],
            vec![1, 1],
            vec![0x86, 2, 0, 0, 0, 1, 0, 0, 0, 2, 0, 0, 0],
        ],
        "ua_users" => text(&[
            "# name:role:scheme:iterations:salt:hash\njan:writer:pbkdf2-sha256:100000:00ff:a1b2\n",
            "ola:reader:pbkdf2-sha256:1:x:y\n::\n",
        ]),
        "ua_node_id" => text(&["KW_A000", "ns=2;s=KW_A000", "i=85", "ns=2;b=AQAAAEtXX0EwMDA="]),
        "ini" => vec![
            DEMO_INI.as_bytes().to_vec(),
            b"[Server]\r\nMinUpdateRate = 250\r\nLogLevel = debug\r\n[Channel:K1]\r\nItemsDatabase = a.csv\r\n[AsixCTServers]\r\nS1 = 10.0.0.1\r\n".to_vec(),
            // The OPC UA front end's section, every option.
            b"[UA]\nEndpoint = opc.tcp://0.0.0.0:4840\nAllowNone = nie\nAllowAnonymous = tak\nPkiDirectory = pki\nUsersFile = u.txt\nMaxSessions = 5\nMaxSubscriptionsPerSession = 4\nMaxMonitoredItemsPerSubscription = 5\nMaxMonitoredItems = 8\nMaxBrowseContinuationPoints = 2\nMaxOperationsPerRequest = 50\nMaxMessageSize = 65536\nMaxChunkCount = 8\nMaxArrayLength = 100\nMaxStringLength = 8192\nMaxRequestsPerSecond = 100\n".to_vec(),
        ],
        "csv_attributes" => vec![DEMO_TABLE.to_vec(), DEMO_TABLE[..DEMO_TABLE.len().min(600)].to_vec()],
        "paradox" => {
            let db: &[u8] = include_bytes!("../../crates/asix-model/tests/paradox/types.DB");
            vec![db.to_vec(), db[..db.len().min(0x800)].to_vec()]
        }
        "zez_varset" => vec![DEMO_SET.to_vec(), DEMO_SET[..DEMO_SET.len().min(600)].to_vec()],
        "item_id" => text(&[
            "KW_A000",
            "asmen.K1.KW_A000.R4",
            "KW_A000.Opis",
            "KW_A000#Format",
            "KW_A000.Procent",
        ]),
        "match_pattern" => text(&["KW_A0*\0KW_A000", "[!a-c]#?*\0x1yz", "*a*a*a*b\0aaaaaaaaaaaaaaaaaaaac"]),
        "format" => text(&["%5.2f", "%d", "%x", "%-8.3e", "%s"]),
        "value_convert" => vec![vec![4, 0, 0, 0xC0, 0x3F, 3], vec![8, 5, b'1', b'2', b'.', b'5', 1], vec![13, 2, 3, 1, 2, 3, 4, 5, 6, 7, 8]],
        _ => Vec::new(),
    }
}

/// A small, fast, seeded PRNG (xorshift64*): the runner must be reproducible from its
/// seed and needs no dependency.
#[derive(Debug, Clone)]
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Rng {
        Rng(seed.max(1))
    }
    pub fn next_u64(&mut self) -> u64 {
        let mut x = self.0;
        x ^= x >> 12;
        x ^= x << 25;
        x ^= x >> 27;
        self.0 = x;
        x.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    /// Uniform in `0..n` (n > 0).
    pub fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n.max(1) as u64) as usize
    }
}

/// Bytes that make decoders take their edge branches.
const INTERESTING: &[u8] = &[
    0, 1, 0x7F, 0x80, 0xFF, b'\n', b'\r', b';', b'=', b'[', b']', b'"', b',', b'*', b'?', b'#',
    b'%', b'.',
];

/// One mutation of `input` (bit flips, byte edits, inserts, deletes, splices with
/// `other`, duplicated blocks, interesting bytes and lengths).
pub fn mutate(rng: &mut Rng, input: &[u8], other: &[u8]) -> Vec<u8> {
    let mut v = input.to_vec();
    for _ in 0..=rng.below(4) {
        let len = v.len();
        match rng.below(9) {
            0 if len > 0 => {
                let i = rng.below(len);
                v[i] ^= 1 << rng.below(8);
            }
            1 if len > 0 => {
                let i = rng.below(len);
                v[i] = INTERESTING[rng.below(INTERESTING.len())];
            }
            2 => {
                let i = rng.below(len + 1);
                v.insert(i, rng.next_u64() as u8);
            }
            3 if len > 0 => {
                let i = rng.below(len);
                let n = rng.below((len - i).min(64)) + 1;
                v.drain(i..i + n);
            }
            4 if !other.is_empty() => {
                let i = rng.below(len + 1);
                let j = rng.below(other.len());
                let n = rng.below((other.len() - j).min(256)) + 1;
                v.splice(i..i, other[j..j + n].iter().copied());
            }
            5 if len > 0 => {
                let i = rng.below(len);
                let n = rng.below((len - i).min(128)) + 1;
                let block: Vec<u8> = v[i..i + n].to_vec();
                let at = rng.below(v.len() + 1);
                v.splice(at..at, block);
            }
            6 if len >= 4 => {
                // A length-like field: 0, small, huge.
                let i = rng.below(len - 3);
                let x: u32 = [0, 1, 0xFF, 0xFFFF, 0x7FFF_FFFF, u32::MAX][rng.below(6)];
                v[i..i + 4].copy_from_slice(&x.to_le_bytes());
            }
            7 if len > 0 => v.truncate(rng.below(len)),
            _ => v.push(rng.next_u64() as u8),
        }
    }
    v
}

/// A failing input of [`run`].
#[derive(Debug)]
pub struct Failure {
    pub target: &'static str,
    pub input: Vec<u8>,
    pub message: String,
}

/// Runs target `name` on mutated seeds and random bytes for `budget` (at least one pass
/// over the seeds); the number of inputs tried, or the first failing input.
pub fn run(name: &'static str, budget: Duration, seed: u64) -> Result<u64, Failure> {
    let f = target(name).ok_or_else(|| Failure {
        target: name,
        input: Vec::new(),
        message: format!("no target {name}"),
    })?;
    let seeds = seeds(name);
    let mut rng = Rng::new(seed ^ name.len() as u64 ^ 0x9E37_79B9_7F4A_7C15);
    let mut pool: Vec<Vec<u8>> = seeds.clone();
    pool.push(Vec::new());
    let started = Instant::now();
    let mut n = 0u64;
    let try_one = |input: &[u8]| -> Result<(), Failure> {
        let slow = Instant::now();
        let r = std::panic::catch_unwind(|| f(input));
        if let Err(e) = r {
            let message = e
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| e.downcast_ref::<&str>().map(|s| (*s).to_owned()))
                .unwrap_or_else(|| "panic".into());
            return Err(Failure {
                target: name,
                input: input.to_vec(),
                message,
            });
        }
        // A decoder that takes a second on one small input is a hang in the making.
        if slow.elapsed() > Duration::from_secs(2) && input.len() < 1 << 20 {
            return Err(Failure {
                target: name,
                input: input.to_vec(),
                message: format!("one input took {:?}", slow.elapsed()),
            });
        }
        Ok(())
    };
    for s in &seeds {
        try_one(s)?;
        n += 1;
    }
    while started.elapsed() < budget {
        let input = if rng.below(8) == 0 {
            let len = rng.below(512);
            (0..len).map(|_| rng.next_u64() as u8).collect()
        } else {
            let a = &pool[rng.below(pool.len())];
            let b = &pool[rng.below(pool.len())];
            mutate(&mut rng, a, b)
        };
        try_one(&input)?;
        n += 1;
        // Keep some mutants as new starting points (a crude corpus), bounded in size.
        if rng.below(16) == 0 && input.len() < 1 << 16 {
            if pool.len() < 256 {
                pool.push(input);
            } else {
                let i = rng.below(pool.len());
                pool[i] = input;
            }
        }
    }
    Ok(n)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_target_survives_its_seeds_and_a_short_random_run() {
        // Quiet: a caught panic would print its message for every failing input.
        for (name, _) in TARGETS {
            match run(name, Duration::from_millis(200), 1) {
                Ok(n) => assert!(n > 0, "{name}"),
                Err(f) => panic!("{}: {} on {:02x?}", f.target, f.message, f.input),
            }
        }
    }

    #[test]
    fn the_rng_is_reproducible() {
        let (mut a, mut b) = (Rng::new(7), Rng::new(7));
        for _ in 0..100 {
            assert_eq!(a.next_u64(), b.next_u64());
        }
        let mut r = Rng::new(3);
        let x = mutate(&mut r, b"abcdef", b"xyz");
        let mut r = Rng::new(3);
        assert_eq!(x, mutate(&mut r, b"abcdef", b"xyz"));
    }
}
