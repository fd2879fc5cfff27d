//! Load time of the large PLY files, reported as throughput (MB/s of file parsed).
//!
//! `cargo bench -p hybrid-scene --bench load`; the assets live in `shared/assets` beside the repo.

use std::path::{Path, PathBuf};
use std::time::Duration;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};

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

criterion_group!(benches, bench);
criterion_main!(benches);
