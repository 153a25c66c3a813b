//! The variable database at scale, natively: `cargo bench -p asix-model --bench vardb`
//! (`-- --quick`: 100,000 variables only, 3 runs).
//!
//! Std only (harness = false). For 100,000 and 1,000,000 variables of the synthetic
//! database (`asix_model::synthetic`: the documented CSV + `.zez` format, 17 attributes a
//! row, about 90 B, branches of 100 variables), written once to `target/vardb-bench/`, it
//! prints the medians over the runs of:
//! - the load time (`AsixNamespace::load`: the files read, parsed and indexed) and the time
//!   to build the browse tree (`build_address_space`), and their sum, the start's share,
//!   with the CPU time of both (on a shared machine the wall time overstates the work);
//! - the live heap bytes per variable (counting global allocator) of the namespace and of
//!   the browse tree after loading;
//! - the resident memory per variable (`/proc/self/statm`, growth over the run's start;
//!   each run is a child process of its own, so this is what a server would hold).
//!
//! The baseline of the same run is the demo plant (228 variables) loaded the same way.
//!
//! `-- --paradox` also loads the same tables as Paradox `.DB` files (the original's
//! format), written from the synthetic CSV by pxlib (`tests/paradox/mkpx.c`, compiled
//! with `cc -lpx`; Debian's `pxlib-dev`) and reported beside the CSV.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use asix_model::address_space::build_address_space;
use asix_model::synthetic::synthetic_database;
use asix_model::{parse_config, AsixNamespace, ChannelDatabase, BASIC_CHANNEL};

#[global_allocator]
static GLOBAL: &stats_alloc::StatsAlloc<std::alloc::System> = &stats_alloc::INSTRUMENTED_SYSTEM;

// The live heap, resident memory and CPU readers the benches share.
use test_support::measure as support;

fn live() -> isize {
    support::live(GLOBAL)
}

fn peak_resident() -> usize {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            let l = s.lines().find(|l| l.starts_with("VmHWM:"))?;
            l.split_whitespace().nth(1)?.parse::<usize>().ok()
        })
        .map_or(0, |kb| kb * 1024)
}

fn median<T: Copy + PartialOrd>(mut v: Vec<T>) -> T {
    v.sort_by(|a, b| a.partial_cmp(b).unwrap_or(std::cmp::Ordering::Equal));
    v[v.len() / 2]
}

struct Run {
    load: Duration,
    tree: Duration,
    heap_db: isize,
    heap_tree: isize,
    resident: isize,
    /// The child process's peak resident memory (VmHWM), start to end.
    peak: isize,
    /// CPU seconds of load and tree.
    cpu: f64,
}

fn run_once(zez: &Path) -> (Run, usize) {
    let ini = format!("[Channel:*]\nItemsDatabase = {}\n", zez.display());
    let (cfg, _) = parse_config(ini.as_bytes(), "bench.ini").expect("config");
    let (heap0, rss0, cpu0) = (live(), support::resident(), support::cpu_seconds());
    let t0 = Instant::now();
    let (ns, _warnings) = AsixNamespace::load(cfg);
    let load = t0.elapsed();
    let heap1 = live();
    let count = match ns.database_state(BASIC_CHANNEL) {
        ChannelDatabase::Loaded(db) => db.variables.len(),
        other => panic!("{zez:?} not loaded: {other:?}"),
    };
    let t1 = Instant::now();
    let space = build_address_space(&ns).expect("address space");
    let tree = t1.elapsed();
    let heap2 = live();
    let resident = support::resident() - rss0;
    assert!(space.len() > count, "{} nodes", space.len());
    (
        Run {
            load,
            tree,
            heap_db: heap1 - heap0,
            heap_tree: heap2 - heap1,
            resident,
            peak: peak_resident() as isize,
            cpu: support::cpu_seconds() - cpu0,
        },
        count,
    )
}

/// One run in a child process of its own (this bench with `--child ZEZ`), so that the
/// resident memory of each run starts from a fresh process.
fn run_child(zez: &Path) -> (Run, usize) {
    let exe = std::env::current_exe().expect("bench exe");
    let out = std::process::Command::new(exe)
        .arg("--child")
        .arg(zez)
        .output()
        .expect("child run");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8_lossy(&out.stdout);
    let f: Vec<f64> = text
        .split_whitespace()
        .filter_map(|w| w.parse().ok())
        .collect();
    assert_eq!(f.len(), 8, "child printed {text:?}");
    (
        Run {
            load: Duration::from_secs_f64(f[0]),
            tree: Duration::from_secs_f64(f[1]),
            heap_db: f[2] as isize,
            heap_tree: f[3] as isize,
            resident: f[4] as isize,
            peak: f[6] as isize,
            cpu: f[7],
        },
        f[5] as usize,
    )
}

fn report(label: &str, zez: &Path, runs: usize) {
    let mut all = Vec::new();
    let mut count = 0;
    for _ in 0..runs {
        let (r, n) = run_child(zez);
        count = n;
        all.push(r);
    }
    let per = |x: isize| x as f64 / count as f64;
    let ms = |d: Duration| d.as_secs_f64() * 1e3;
    let load = median(all.iter().map(|r| ms(r.load)).collect());
    let tree = median(all.iter().map(|r| ms(r.tree)).collect());
    let start = median(all.iter().map(|r| ms(r.load + r.tree)).collect());
    let heap_db = median(all.iter().map(|r| per(r.heap_db)).collect());
    let heap_tree = median(all.iter().map(|r| per(r.heap_tree)).collect());
    let resident = median(all.iter().map(|r| per(r.resident)).collect());
    let cpu = median(all.iter().map(|r| r.cpu * 1e3).collect());
    let peak = median(all.iter().map(|r| r.peak as f64 / 1e6).collect());
    println!("{label} ({count} variables, {runs} runs, medians):");
    println!("  load {load:9.1} ms   tree {tree:8.1} ms   start (both) {start:9.1} ms   CPU {cpu:9.1} ms");
    println!(
        "  heap per variable: database {heap_db:7.1} B   tree {heap_tree:6.1} B   sum {:7.1} B",
        heap_db + heap_tree
    );
    println!(
        "  resident per variable {resident:7.1} B   peak resident of the process {peak:8.1} MB"
    );
}

fn write_db(dir: &Path, n: usize) -> PathBuf {
    let d = dir.join(format!("n{n}"));
    let zez = d.join("synthetic.zez");
    if !zez.exists() {
        std::fs::create_dir_all(&d).expect("bench dir");
        let g = synthetic_database(n);
        std::fs::write(d.join("atrybuty.csv"), g.csv).expect("csv");
        std::fs::write(&zez, g.zez).expect("zez");
    }
    zez
}

/// The synthetic table of `zez`'s folder as a Paradox table (numbers as `N`, `Writable`
/// as a logical) and a variable set naming it, written once.
fn write_paradox(dir: &Path, zez: &Path) -> PathBuf {
    let d = zez.parent().expect("folder").join("paradox");
    let db = d.join("atrybuty.DB");
    let set = d.join("synthetic.zez");
    if !set.exists() {
        std::fs::create_dir_all(&d).expect("paradox dir");
        let mkpx = dir.join("mkpx");
        let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/paradox/mkpx.c");
        let ok = std::process::Command::new("cc")
            .args(["-O2", "-o"])
            .arg(&mkpx)
            .arg(src)
            .arg("-lpx")
            .status()
            .is_ok_and(|s| s.success());
        assert!(ok, "cc mkpx.c -lpx failed: is pxlib-dev installed?");
        let csv = zez.with_file_name("atrybuty.csv");
        let status = std::process::Command::new(&mkpx)
            .arg("csv")
            .arg(&csv)
            .arg(&db)
            .args([
                "1250",
                "RangeFrom=N",
                "RangeTo=N",
                "WarnLow=N",
                "WarnHigh=N",
            ])
            .args(["AlarmLow=N", "AlarmHigh=N", "Writable=L"])
            .status()
            .expect("mkpx");
        assert!(status.success(), "mkpx failed");
        let text = std::fs::read_to_string(zez).expect("zez");
        std::fs::write(
            &set,
            text.replace("Attributes = atrybuty.csv", "Attributes = atrybuty.DB"),
        )
        .expect("zez");
    }
    let size = |p: &Path| std::fs::metadata(p).map_or(0, |m| m.len()) as f64 / 1e6;
    println!(
        "  (files: CSV {:.1} MB, Paradox .DB {:.1} MB)",
        size(&zez.with_file_name("atrybuty.csv")),
        size(&db)
    );
    set
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if let Some(i) = args.iter().position(|a| a == "--child") {
        let (r, n) = run_once(Path::new(&args[i + 1]));
        println!(
            "{} {} {} {} {} {} {} {}",
            r.load.as_secs_f64(),
            r.tree.as_secs_f64(),
            r.heap_db,
            r.heap_tree,
            r.resident,
            n,
            r.peak,
            r.cpu
        );
        return;
    }
    let quick = std::env::args().any(|a| a == "--quick");
    let target = std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../../target"));
    let dir = target.join("vardb-bench");
    let demo = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../demo/wytwornia_kwasu/wytwornia_kwasu.zez");
    println!("variable database benchmark (medians; goal: <= 300 B resident per variable, 1,000,000 started in <= 3 s)");
    report("baseline: demo plant", &demo, 5);
    let sizes: &[(usize, usize)] = if quick {
        &[(100_000, 3)]
    } else {
        &[(100_000, 5), (1_000_000, 3)]
    };
    let paradox = std::env::args().any(|a| a == "--paradox");
    for &(n, runs) in sizes {
        let zez = write_db(&dir, n);
        report(&format!("synthetic {n}"), &zez, runs);
        if paradox {
            let set = write_paradox(&dir, &zez);
            report(&format!("synthetic {n} as Paradox"), &set, runs);
        }
    }
}
