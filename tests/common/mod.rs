//! Exemplars for every test: real ones from `tests/fixtures/exemplars`
//! (precomputed once per test binary) and small generated ones.
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

/// A small PNG with structure (blobs and stripes), different per seed.
pub fn exemplar_png(side: u32, seed: u32) -> Vec<u8> {
    let mut rgb = Vec::with_capacity((side * side * 3) as usize);
    let mut state = seed.wrapping_mul(2654435761).wrapping_add(12345);
    for y in 0..side {
        for x in 0..side {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            let stripe = ((x + y * 2 + seed * 3) % 8 < 4) as u32;
            let blob =
                (((x as f32 * 0.4 + seed as f32).sin() * (y as f32 * 0.3).cos()) * 60.0) as i32;
            rgb.push((60 + stripe * 120 + (state % 16)) as u8);
            rgb.push((120 + blob).clamp(0, 255) as u8);
            rgb.push((40 + (state >> 8) % 64 + seed * 20 % 100) as u8);
        }
    }
    encode_png(side, side, &rgb)
}

/// Encodes RGB8 as PNG.
pub fn encode_png(w: u32, h: u32, rgb: &[u8]) -> Vec<u8> {
    solidtex_core::png::encode(w, h, rgb).unwrap()
}

/// An image file of `tests/fixtures/images` (see its README).
pub fn image_fixture(name: &str) -> Vec<u8> {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/images")
        .join(name);
    std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Encodes RGB8 as a baseline JPEG.
pub fn encode_jpeg(w: u32, h: u32, rgb: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, 90)
        .encode(rgb, w, h, image::ExtendedColorType::Rgb8)
        .unwrap();
    out
}

/// Rewrites the size in a JPEG's frame header without touching the data.
pub fn claim_jpeg_size(mut jpeg: Vec<u8>, w: u16, h: u16) -> Vec<u8> {
    let sof = jpeg
        .windows(2)
        .position(|m| m[0] == 0xff && matches!(m[1], 0xc0..=0xc2))
        .expect("a frame header");
    jpeg[sof + 5..sof + 7].copy_from_slice(&h.to_be_bytes());
    jpeg[sof + 7..sof + 9].copy_from_slice(&w.to_be_bytes());
    jpeg
}

/// A photo of `w`×`h` pixels in large flat blocks, as RGB8: its PNG is
/// about a thousandth of its pixels' bytes.
pub fn blocky_rgb(w: u32, h: u32) -> Vec<u8> {
    (0..w * h)
        .flat_map(|i| {
            let (x, y) = (i % w / 500, i / w / 500);
            [(x * 20) as u8, (y * 20) as u8, ((x + y) * 10) as u8]
        })
        .collect()
}

/// Decodes a PNG to (width, height, RGB8).
pub fn decode_png(bytes: &[u8]) -> (u32, u32, Vec<u8>) {
    let img = image::load_from_memory(bytes).unwrap().to_rgb8();
    (img.width(), img.height(), img.into_raw())
}

/// Horizontal stripes with a little noise: grain along u.
pub fn grain_png(w: u32, h: u32) -> Vec<u8> {
    let rgb: Vec<u8> = (0..w * h)
        .flat_map(|i| {
            let (u, v) = (i % w, i / w);
            let l = ((v % 6) * 35 + (u * 7 + v * 3) % 11) as u8;
            [l, l / 2 + 60, 90]
        })
        .collect();
    encode_png(w, h, &rgb)
}

/// A generated exemplar ([`exemplar_png`]).
pub fn generated_exemplar(side: u32, seed: u32) -> Exemplar {
    Exemplar::decode(&exemplar_png(side, seed)).unwrap()
}

/// One colour all over.
pub fn flat_png(w: u32, h: u32) -> Vec<u8> {
    encode_png(w, h, &[10, 20, 30].repeat((w * h) as usize))
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

/// The fixture's candidates for Dong et al.'s slab initialisation, for
/// the tests of the slab itself.
pub fn slab_candidates() -> Arc<Candidates> {
    static C: OnceLock<Arc<Candidates>> = OnceLock::new();
    C.get_or_init(|| {
        let params = AnalysisParams {
            initialisation: solidtex_core::Initialisation::Slab,
            ..small_params()
        };
        let set = ExemplarSet::single(small_exemplar());
        Arc::new(Candidates::compute(&set, &params, &|_, _| {}).unwrap())
    })
    .clone()
}

/// [`texture_with`] over [`slab_candidates`].
pub fn slab_texture_with(params: SynthParams, cache_bytes: usize) -> Texture {
    Texture::new(
        slab_candidates(),
        params,
        Arc::new(TileCache::new(cache_bytes)),
    )
    .unwrap()
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

/// `tests/fixtures/exemplars/animal_leather.png` precomputed by the
/// binary once per test program, into cargo's temporary directory for
/// tests: commands given the PNG would precompute it on every call.
pub fn leather_stx() -> &'static std::path::Path {
    static STX: OnceLock<PathBuf> = OnceLock::new();
    STX.get_or_init(|| {
        let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR"));
        // Written aside and renamed, so a program running at the same
        // time never reads half a file (both write the same bytes).
        let part = dir.join(format!("animal_leather.stx.{}", std::process::id()));
        let exemplar = exemplar_path("animal_leather.png");
        solidtex(&[
            "precompute".as_ref(),
            exemplar.as_os_str(),
            "-o".as_ref(),
            part.as_os_str(),
        ]);
        let path = dir.join("animal_leather.stx");
        std::fs::rename(&part, &path).unwrap();
        path
    })
}

/// Runs the `solidtex` binary with `args`, expects success, and returns
/// what it prints.
pub fn solidtex<S: AsRef<std::ffi::OsStr>>(args: &[S]) -> Vec<u8> {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_solidtex"))
        .args(args)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    out.stdout
}

/// [`solidtex`], parsing what it prints as JSON.
pub fn solidtex_json<S: AsRef<std::ffi::OsStr>>(args: &[S]) -> serde_json::Value {
    serde_json::from_slice(&solidtex(args)).unwrap()
}
