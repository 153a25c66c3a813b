//! The server's log files: `ServerCTOPC.<YYYYMMDD>.log` in the log directory, one per day
//! (the local date), continued in `ServerCTOPC.<YYYYMMDD>.<n>.log` when a file exceeds
//! the size cap, and the oldest files deleted beyond a configured count. Plain std, so
//! the rotation rules are tested natively; the server wraps it in
//! `tracing_appender::non_blocking` so that logging never blocks a COM call.

use std::fs::{self, File, OpenOptions};
use std::io::{self, Write};
use std::path::{Path, PathBuf};

pub const PREFIX: &str = "ServerCTOPC.";
pub const SUFFIX: &str = ".log";

/// A calendar date (year, month, day).
pub type Date = (i32, u32, u32);

/// The log directory: `LogDirectory` (relative to the install folder), else `<install>\Log`.
pub fn log_dir(install_dir: &Path, configured: Option<&str>) -> PathBuf {
    match configured.map(str::trim).filter(|s| !s.is_empty()) {
        Some(d) => install_dir.join(d),
        None => install_dir.join("Log"),
    }
}

/// Sets up tracing into the log files, written on a background thread (never blocking a
/// COM call). Keep the returned guard alive: dropping it flushes and ends the writer.
#[cfg(windows)]
pub fn init(
    install_dir: &Path,
    opts: &asix_model::ServerOptions,
) -> Option<tracing_appender::non_blocking::WorkerGuard> {
    use asix_model::LogLevel;
    let dir = log_dir(install_dir, opts.log_directory.as_deref());
    let max = u64::from(opts.log_max_file_size_mb) * 1024 * 1024;
    let files = match LogFiles::new(
        &dir,
        max,
        opts.log_keep_files as usize,
        Box::new(ctopc_com::clock::local_date),
    ) {
        Ok(f) => f,
        Err(e) => {
            eprintln!("ServerCTOPC: cannot write logs to {}: {e}", dir.display());
            return None;
        }
    };
    let (writer, guard) = tracing_appender::non_blocking(files);
    let level = match opts.log_level {
        LogLevel::Error => tracing::Level::ERROR,
        LogLevel::Warn => tracing::Level::WARN,
        LogLevel::Info => tracing::Level::INFO,
        LogLevel::Debug => tracing::Level::DEBUG,
    };
    let subscriber = tracing_subscriber::fmt()
        .with_writer(writer)
        .with_ansi(false)
        .with_max_level(level)
        .with_thread_names(true)
        .finish();
    if tracing::subscriber::set_global_default(subscriber).is_err() {
        eprintln!("ServerCTOPC: logging was already set up");
    }
    Some(guard)
}

/// A last-resort log line when the configuration could not be read (no log settings known).
pub fn emergency(install_dir: &Path, message: &str) {
    let dir = log_dir(install_dir, None);
    if let Ok(mut f) = LogFiles::new(&dir, 10 * 1024 * 1024, 30, Box::new(today_utc)) {
        let _ = writeln!(f, "ERROR ServerCTOPC cannot start: {message}");
    }
}

/// The UTC date (used only when the local date is not available).
pub fn today_utc() -> Date {
    let since = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap_or_default();
    let c = ctopc_core::Timestamp::from_unix_micros(since.as_micros()).civil();
    (c.year as i32, c.month, c.day)
}

/// `ServerCTOPC.20261122.log`, or `ServerCTOPC.20261122.3.log` for `index` 3.
pub fn file_name(date: Date, index: u32) -> String {
    let (y, m, d) = date;
    if index == 0 {
        format!("{PREFIX}{y:04}{m:02}{d:02}{SUFFIX}")
    } else {
        format!("{PREFIX}{y:04}{m:02}{d:02}.{index}{SUFFIX}")
    }
}

/// The (date, index) of one of our log file names.
pub fn parse_name(name: &str) -> Option<(u32, u32)> {
    let core = name.strip_prefix(PREFIX)?.strip_suffix(SUFFIX)?;
    let (date, index) = match core.split_once('.') {
        Some((d, i)) => (d, i.parse().ok()?),
        None => (core, 0),
    };
    if date.len() != 8 || !date.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    Some((date.parse().ok()?, index))
}

/// A `Write` that appends to the day's log file and rotates by date and size.
pub struct LogFiles {
    dir: PathBuf,
    max_bytes: u64,
    keep: usize,
    today: Box<dyn Fn() -> Date + Send>,
    open: Option<Open>,
}

impl LogFiles {
    /// Creates the directory if needed. `today` gives the local date (injected for tests).
    pub fn new(
        dir: &Path,
        max_bytes: u64,
        keep: usize,
        today: Box<dyn Fn() -> Date + Send>,
    ) -> io::Result<LogFiles> {
        fs::create_dir_all(dir)?;
        Ok(LogFiles {
            dir: dir.to_path_buf(),
            max_bytes: max_bytes.max(1),
            keep: keep.max(1),
            today,
            open: None,
        })
    }

    fn open_file(&mut self, date: Date, mut index: u32) -> io::Result<()> {
        // Continue today's file after a restart, unless it is already full.
        loop {
            let path = self.dir.join(file_name(date, index));
            let len = fs::metadata(&path).map(|m| m.len()).unwrap_or(0);
            if len < self.max_bytes {
                let file = OpenOptions::new().create(true).append(true).open(&path)?;
                self.open = Some(Open {
                    date,
                    index,
                    file,
                    written: len,
                });
                break;
            }
            index += 1;
        }
        self.cleanup();
        Ok(())
    }

    /// Deletes the oldest of our files beyond `keep` (other files are never touched).
    pub fn cleanup(&self) {
        let Ok(entries) = fs::read_dir(&self.dir) else {
            return;
        };
        let mut ours: Vec<((u32, u32), PathBuf)> = entries
            .flatten()
            .filter_map(|e| {
                let name = e.file_name().into_string().ok()?;
                Some((parse_name(&name)?, e.path()))
            })
            .collect();
        if ours.len() <= self.keep {
            return;
        }
        ours.sort();
        let excess = ours.len() - self.keep;
        for (_, path) in ours.into_iter().take(excess) {
            let _ = fs::remove_file(path);
        }
    }
}

impl Write for LogFiles {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        let today = (self.today)();
        let rotate = match &self.open {
            None => Some((today, 0)),
            Some(o) if o.date != today => Some((today, 0)),
            Some(o) if o.written > 0 && o.written + buf.len() as u64 > self.max_bytes => {
                Some((today, o.index + 1))
            }
            Some(_) => None,
        };
        if let Some((date, index)) = rotate {
            self.open_file(date, index)?;
        }
        let Some(o) = self.open.as_mut() else {
            return Err(io::Error::other("no log file"));
        };
        o.file.write_all(buf)?;
        o.written += buf.len() as u64;
        Ok(buf.len())
    }

    fn flush(&mut self) -> io::Result<()> {
        match self.open.as_mut() {
            Some(o) => o.file.flush(),
            None => Ok(()),
        }
    }
}

/// The file being written: its date and index, and the bytes it holds.
struct Open {
    date: Date,
    index: u32,
    file: File,
    written: u64,
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::{Arc, Mutex};

    fn temp_dir(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("ctopc-log-test-{name}-{}", std::process::id()));
        let _ = fs::remove_dir_all(&d);
        d
    }

    fn names(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> = fs::read_dir(dir)
            .unwrap()
            .flatten()
            .map(|e| e.file_name().into_string().unwrap())
            .collect();
        v.sort();
        v
    }

    #[test]
    fn file_names_carry_the_date_and_round_trip() {
        assert_eq!(file_name((2026, 11, 22), 0), "ServerCTOPC.20261122.log");
        assert_eq!(file_name((2026, 1, 2), 3), "ServerCTOPC.20260102.3.log");
        assert_eq!(parse_name("ServerCTOPC.20261122.log"), Some((20261122, 0)));
        assert_eq!(
            parse_name("ServerCTOPC.20261122.12.log"),
            Some((20261122, 12))
        );
        assert_eq!(parse_name("ServerCTOPC.2026112.log"), None);
        assert_eq!(parse_name("other.20261122.log"), None);
    }

    #[test]
    fn a_new_day_starts_a_new_file_and_a_full_file_continues_in_the_next_index() {
        let dir = temp_dir("rotate");
        let day = Arc::new(Mutex::new((2026, 11, 22)));
        let d = Arc::clone(&day);
        let mut log = LogFiles::new(&dir, 100, 10, Box::new(move || *d.lock().unwrap())).unwrap();
        log.write_all(&[b'a'; 60]).unwrap();
        log.write_all(&[b'b'; 60]).unwrap(); // would exceed 100 bytes: next index
        *day.lock().unwrap() = (2026, 11, 23);
        log.write_all(b"next day\n").unwrap();
        log.flush().unwrap();
        assert_eq!(
            names(&dir),
            vec![
                "ServerCTOPC.20261122.1.log",
                "ServerCTOPC.20261122.log",
                "ServerCTOPC.20261123.log"
            ]
        );
        assert_eq!(
            fs::read(dir.join("ServerCTOPC.20261122.log"))
                .unwrap()
                .len(),
            60
        );
        let _ = fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_restart_appends_to_todays_file_and_old_files_beyond_the_count_are_deleted() {
        let dir = temp_dir("keep");
        fs::create_dir_all(&dir).unwrap();
        for day in 1..=5 {
            fs::write(dir.join(file_name((2026, 10, day), 0)), b"old\n").unwrap();
        }
        fs::write(dir.join("unrelated.txt"), b"keep me").unwrap();
        fs::write(dir.join(file_name((2026, 11, 22), 0)), b"before restart\n").unwrap();
        let mut log = LogFiles::new(&dir, 1 << 20, 3, Box::new(|| (2026, 11, 22))).unwrap();
        log.write_all(b"after restart\n").unwrap();
        log.flush().unwrap();
        assert_eq!(
            names(&dir),
            vec![
                "ServerCTOPC.20261004.log",
                "ServerCTOPC.20261005.log",
                "ServerCTOPC.20261122.log",
                "unrelated.txt"
            ]
        );
        assert_eq!(
            fs::read_to_string(dir.join("ServerCTOPC.20261122.log")).unwrap(),
            "before restart\nafter restart\n"
        );
        let _ = fs::remove_dir_all(&dir);
    }

    #[test]
    fn the_log_directory_defaults_to_log_under_the_install_folder() {
        let base = std::path::Path::new("/opt/ctopc");
        assert_eq!(super::log_dir(base, None), base.join("Log"));
        assert_eq!(super::log_dir(base, Some("  ")), base.join("Log"));
        assert_eq!(super::log_dir(base, Some("logs/x")), base.join("logs/x"));
    }
}
