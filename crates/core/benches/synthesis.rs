//! Kernels a developer iterates on, measured by criterion on the bundled
//! exemplar: a cold region (every level synthesized through its
//! corrections), a cold axis slice (the lazy dependency set of one plane),
//! a warm region (tiles from the cache) and the estimate that admits a
//! request before any work. `cargo bench -p solidtex-core`; `solidtex
//! bench` stays the report for users (BENCHMARKS.md).

use criterion::{Criterion, criterion_group, criterion_main};
use solidtex_core::{
    Axis, Candidates, ExemplarSet, Region, Request, SynthParams, Texture, TileCache, Window,
    bundled,
};
use std::hint::black_box;
use std::sync::Arc;
use std::time::Duration;

fn candidates() -> Arc<Candidates> {
    let set = ExemplarSet::single(bundled::exemplar());
    Arc::new(bundled::candidates_for(&set, &Default::default()).expect("bundled candidates"))
}

/// A texture with an empty cache of its own.
fn cold(c: &Arc<Candidates>) -> Texture {
    Texture::new(
        c.clone(),
        SynthParams::default(),
        Arc::new(TileCache::new(256 << 20)),
    )
    .expect("default parameters")
}

fn region(side: u32) -> Request {
    Request::region(Region {
        origin: [0; 3],
        size: [side; 3],
    })
    .expect("a valid region")
}

/// The `side`² window from the plane's origin.
fn window(side: u32) -> Window {
    Window {
        u0: 0,
        v0: 0,
        width: side,
        height: side,
    }
}

fn synthesis(c: &mut Criterion) {
    let candidates = candidates();
    let mut g = c.benchmark_group("synthesis");
    g.sample_size(10)
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(5));
    let r32 = region(32);
    g.bench_function("cold region 32³", |b| {
        b.iter(|| black_box(cold(&candidates).render(&r32, 0).expect("renders")))
    });
    let slice = Request::slice(Axis::Z, 0, window(128)).expect("a valid slice");
    g.bench_function("cold slice 128²", |b| {
        b.iter(|| black_box(cold(&candidates).render(&slice, 0).expect("renders")))
    });
    let warm = cold(&candidates);
    warm.render(&r32, 0).expect("renders");
    g.bench_function("warm region 32³", |b| {
        b.iter(|| black_box(warm.render(&r32, 0).expect("renders")))
    });
    let big = Request::slice(Axis::Z, 0, window(1024)).expect("a valid slice");
    g.bench_function("estimate of a slice 1024²", |b| {
        b.iter(|| {
            black_box(
                cold(&candidates)
                    .estimate(&big, 0, u64::MAX)
                    .expect("estimates"),
            )
        })
    });
    g.finish();
}

criterion_group!(benches, synthesis);
criterion_main!(benches);
