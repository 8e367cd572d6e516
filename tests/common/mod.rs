//! Shared fixtures: real exemplars from `tests/fixtures/exemplars`,
//! precomputed once per test binary.
#![allow(dead_code)]

use solidtex_core::{
    AnalysisParams, Candidates, Exemplar, ExemplarSet, SynthParams, Texture, TileCache,
};
use std::path::PathBuf;
use std::sync::{Arc, OnceLock};

pub fn exemplar_path(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests")
        .join("fixtures")
        .join("exemplars")
        .join(name)
}

pub fn exemplar(name: &str) -> Exemplar {
    Exemplar::open(exemplar_path(name)).expect("test exemplar readable")
}

/// A 32×32 crop of a real exemplar: small enough for fast tests, real
/// enough to have structure.
pub fn small_exemplar() -> Exemplar {
    let e = exemplar("animal_leopard.png");
    let mut rgb = Vec::new();
    for y in 0..32 {
        for x in 0..32 {
            rgb.extend_from_slice(&e.pixels()[y * e.width() as usize + x]);
        }
    }
    Exemplar::from_rgb(32, 32, &rgb).unwrap()
}

pub fn small_params() -> AnalysisParams {
    AnalysisParams {
        levels: 3,
        ..AnalysisParams::default()
    }
}

pub fn small_candidates() -> Arc<Candidates> {
    static C: OnceLock<Arc<Candidates>> = OnceLock::new();
    C.get_or_init(|| {
        Arc::new(
            Candidates::compute(
                &ExemplarSet::single(small_exemplar()),
                &small_params(),
                &|_, _| {},
            )
            .unwrap(),
        )
    })
    .clone()
}

pub fn texture_with(params: SynthParams, cache_bytes: usize) -> Texture {
    Texture::new(
        small_candidates(),
        params,
        Arc::new(TileCache::new(cache_bytes)),
    )
    .unwrap()
}

pub fn texture() -> Texture {
    texture_with(SynthParams::default(), 256 << 20)
}

/// Runs `f` on a pool of `n` threads.
pub fn with_threads<T: Send>(n: usize, f: impl FnOnce() -> T + Send) -> T {
    rayon::ThreadPoolBuilder::new()
        .num_threads(n)
        .build()
        .unwrap()
        .install(f)
}

/// FNV-1a, for pinning golden outputs.
pub fn fnv(bytes: &[u8]) -> u64 {
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    for &b in bytes {
        h = (h ^ b as u64).wrapping_mul(0x100_0000_01b3);
    }
    h
}

/// Runs the `solidtex` binary with `args`, expects success, and parses
/// what it prints as JSON.
pub fn solidtex_json<S: AsRef<std::ffi::OsStr>>(args: &[S]) -> serde_json::Value {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_solidtex"))
        .args(args)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}
