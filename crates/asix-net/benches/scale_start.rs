//! What a server start costs natively for a large database, the in-process simulation
//! included: `cargo bench -p asix-net --bench scale_start` (`-- --quick`: 100,000
//! variables only; `-- --runs N`: N runs of each size).
//!
//! Std only (harness = false). As asix-model's `vardb` bench (the same synthetic database,
//! written once to `target/vardb-bench/`, each run a child process of its own), plus the
//! simulation's plant built over the loaded database the way the server builds it
//! (`PlantSource::new`, i.e. `Plant::from_databases`). Prints medians of the CPU time of
//! load, tree and plant; the live heap per variable (counting global allocator) of the
//! database, the browse tree and the plant, and their sum; and the resident memory per
//! variable of the three (`/proc/self/statm` growth over the run's start).
//!
//! The baseline of the same run is the demo plant (228 variables) loaded the same way.

use std::path::{Path, PathBuf};

use asix_model::address_space::build_address_space;
use asix_model::synthetic::synthetic_database;
use asix_model::{parse_config, AsixNamespace, ChannelDatabase, BASIC_CHANNEL};
use asix_net::inproc::PlantSource;
use ctopc_core::Timestamp;

#[global_allocator]
static GLOBAL: &stats_alloc::StatsAlloc<std::alloc::System> = &stats_alloc::INSTRUMENTED_SYSTEM;

use test_support::measure as support;

fn live() -> isize {
    support::live(GLOBAL)
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.partial_cmp(b).unwrap_or(std::cmp::Ordering::Equal));
    v[v.len() / 2]
}

/// One run: variables, CPU s of load, tree and plant, heap bytes of the database, the tree
/// and the plant, resident growth bytes.
fn run_once(zez: &Path) -> [f64; 8] {
    let ini = format!("[Channel:*]\nItemsDatabase = {}\n", zez.display());
    let (cfg, _) = parse_config(ini.as_bytes(), "bench.ini").expect("config");
    let (heap0, rss0, cpu0) = (live(), support::resident(), support::cpu_seconds());
    let (ns, _warnings) = AsixNamespace::load(cfg);
    let (heap1, cpu1) = (live(), support::cpu_seconds());
    let count = match ns.database_state(BASIC_CHANNEL) {
        ChannelDatabase::Loaded(db) => db.variables.len(),
        other => panic!("{zez:?} not loaded: {other:?}"),
    };
    let space = build_address_space(&ns).expect("address space");
    let (heap2, cpu2) = (live(), support::cpu_seconds());
    let plant = PlantSource::new(&ns, 1, Timestamp::from_filetime_parts(0, 0x01DC_0000));
    let (heap3, cpu3) = (live(), support::cpu_seconds());
    let resident = support::resident() - rss0;
    assert!(space.len() > count, "{} nodes", space.len());
    assert_eq!(plant.plant().vars().len(), count);
    [
        count as f64,
        cpu1 - cpu0,
        cpu2 - cpu1,
        cpu3 - cpu2,
        (heap1 - heap0) as f64,
        (heap2 - heap1) as f64,
        (heap3 - heap2) as f64,
        resident as f64,
    ]
}

fn run_child(zez: &Path) -> [f64; 8] {
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
    f.try_into()
        .unwrap_or_else(|f| panic!("child printed {text:?}: {f:?}"))
}

fn report(label: &str, zez: &Path, runs: usize) {
    let all: Vec<[f64; 8]> = (0..runs).map(|_| run_child(zez)).collect();
    let n = all[0][0];
    let med = |k: usize| median(all.iter().map(|r| r[k]).collect());
    let per = |k: usize| median(all.iter().map(|r| r[k] / n).collect());
    let ms = |k: usize| med(k) * 1e3;
    let cpu_sum = median(all.iter().map(|r| (r[1] + r[2] + r[3]) * 1e3).collect());
    let heap_sum = median(all.iter().map(|r| (r[4] + r[5] + r[6]) / n).collect());
    println!("{label} ({n} variables, {runs} runs, medians):");
    println!(
        "  CPU: load {:7.0} ms   tree {:6.0} ms   plant {:6.0} ms   load+tree {:7.0} ms   all {cpu_sum:7.0} ms",
        ms(1),
        ms(2),
        ms(3),
        median(all.iter().map(|r| (r[1] + r[2]) * 1e3).collect()),
    );
    println!(
        "  heap per variable: database {:6.1} B   tree {:5.1} B   plant {:6.1} B   sum {heap_sum:6.1} B",
        per(4),
        per(5),
        per(6)
    );
    println!("  resident per variable (all three) {:6.1} B", per(7));
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

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if let Some(i) = args.iter().position(|a| a == "--child") {
        let r = run_once(Path::new(&args[i + 1]));
        let line: Vec<String> = r.iter().map(|x| x.to_string()).collect();
        println!("{}", line.join(" "));
        return;
    }
    let quick = args.iter().any(|a| a == "--quick");
    let runs = args
        .iter()
        .position(|a| a == "--runs")
        .and_then(|i| args.get(i + 1)?.parse().ok());
    let target = std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../../target"));
    let dir = target.join("vardb-bench");
    let demo = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../demo/wytwornia_kwasu/wytwornia_kwasu.zez");
    println!("start benchmark: database + browse tree + plant (medians; goals: <= 300 B resident per variable, 1,000,000 started in <= 3 s)");
    report("baseline: demo plant", &demo, runs.unwrap_or(5));
    let sizes: &[(usize, usize)] = if quick {
        &[(100_000, 3)]
    } else {
        &[(1_000_000, 5)]
    };
    for &(n, r) in sizes {
        let zez = write_db(&dir, n);
        report(&format!("synthetic {n}"), &zez, runs.unwrap_or(r));
    }
}
