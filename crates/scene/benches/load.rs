//! Load time of the large PLY files, reported as throughput (MB/s of file parsed).
//!
//! `cargo bench -p hybrid-scene --bench load`; the assets live in `shared/assets` beside the repo.
//!
//! Peak memory of one load, in a fresh process:
//! `LOAD_PEAK_MEMORY=dragon|tree|pine cargo bench -p hybrid-scene --bench load` prints the growth
//! of the peak resident set (VmHWM) during the load next to the size of the loaded arrays.

use std::path::{Path, PathBuf};
use std::time::Duration;

use criterion::{Criterion, Throughput, criterion_group};

fn asset(rel: &str) -> PathBuf {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/assets")).join(rel)
}

fn bench(c: &mut Criterion) {
    let mut g = c.benchmark_group("load");
    g.sample_size(20).measurement_time(Duration::from_secs(8));
    let dragon = asset("stanford-dragon/dragon_vrip.ply");
    let tree = asset("tree-pointcloud/rtls_tls_scan_1m.ply");
    let las = asset("tree-pointcloud/treels_pine.laz");
    for (name, path) in [("dragon_ply_mesh", &dragon)] {
        let Ok(meta) = std::fs::metadata(path) else { continue };
        g.throughput(Throughput::Bytes(meta.len()));
        g.bench_function(name, |b| {
            b.iter(|| {
                let (mut m, mut t) = (Vec::new(), Vec::new());
                hybrid_scene::load::load_model(path, &mut m, &mut t).expect("dragon loads")
            })
        });
    }
    for (name, path) in [("tree_ply_points", &tree), ("pine_laz_points", &las)] {
        let Ok(meta) = std::fs::metadata(path) else { continue };
        g.throughput(Throughput::Bytes(meta.len()));
        g.bench_function(name, |b| b.iter(|| hybrid_scene::load::load_point_cloud(path).expect("cloud loads")));
    }
    g.finish();
}

/// A field of `/proc/self/status` in bytes (Linux only; 0 elsewhere).
fn proc_status_bytes(field: &str) -> u64 {
    let text = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    text.lines()
        .find_map(|l| {
            l.strip_prefix(field)
                .and_then(|r| r.trim_start_matches(':').trim().strip_suffix("kB"))
                .and_then(|v| v.trim().parse::<u64>().ok())
        })
        .map_or(0, |kb| kb * 1024)
}

fn peak_memory(which: &str) {
    let path = match which {
        "dragon" => asset("stanford-dragon/dragon_vrip.ply"),
        "tree" => asset("tree-pointcloud/rtls_tls_scan_1m.ply"),
        "pine" => asset("tree-pointcloud/treels_pine.laz"),
        other => panic!("LOAD_PEAK_MEMORY={other}: expected dragon, tree or pine"),
    };
    let file = std::fs::metadata(&path).map(|m| m.len()).unwrap_or(0);
    let before = proc_status_bytes("VmRSS");
    let t = std::time::Instant::now();
    let arrays: u64 = if which == "dragon" {
        let meshes = hybrid_scene::load::load_model(&path, &mut Vec::new(), &mut Vec::new()).expect("loads");
        meshes
            .iter()
            .map(|m| {
                (m.positions.capacity() * 12 + m.normals.capacity() * 12 + m.uvs.capacity() * 8 + m.tangents.capacity() * 16) as u64
                    + (m.colors.capacity() * 12 + m.indices.capacity() * 12) as u64
            })
            .sum()
    } else {
        let (p, c) = hybrid_scene::load::load_point_cloud(&path).expect("loads");
        (p.capacity() * 12 + c.capacity() * 3) as u64
    };
    let secs = t.elapsed().as_secs_f64();
    let peak = proc_status_bytes("VmHWM");
    let grow = peak.saturating_sub(before);
    let mb = |b: u64| b as f64 / 1e6;
    println!(
        "{which}: file {:.2} MB, load {:.1} ms ({:.0} MB/s), loaded arrays {:.2} MB, peak RSS growth {:.2} MB = {:.2}x the arrays",
        mb(file),
        secs * 1e3,
        mb(file) / secs,
        mb(arrays),
        mb(grow),
        grow as f64 / arrays.max(1) as f64
    );
}

criterion_group!(benches, bench);

fn main() {
    if let Ok(which) = std::env::var("LOAD_PEAK_MEMORY") {
        peak_memory(&which);
        return;
    }
    benches();
    Criterion::default().configure_from_args().final_summary();
}
