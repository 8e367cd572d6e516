//! Precompute memory: the estimate bounds what a precompute allocates,
//! the server refuses uploads whose estimate is over its bound, runs
//! precomputes only while their estimates fit in it together, and reports
//! each one's measured peak. This binary counts its allocations as the
//! server binary does.

mod common;
mod server_support;

use common::{encode_jpeg, generated_exemplar, image_fixture};
use serde_json::Value;
use server_support::*;

use solidtex_core::{AnalysisParams, Candidates, Exemplar, ExemplarSet};
use solidtex_server::peak_alloc::{Meter, PeakAlloc};

#[global_allocator]
static ALLOC: PeakAlloc = PeakAlloc;

#[test]
fn the_estimate_bounds_the_measured_peak() {
    // Measured as the server does: on the threads of a pool of their own,
    // apart from the other tests of this binary.
    let meter = Meter::leaked();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .start_handler(move |_| meter.attach())
        .build()
        .unwrap();
    let three = ExemplarSet::triple(
        generated_exemplar(40, 1),
        generated_exemplar(40, 2),
        generated_exemplar(40, 3),
    )
    .unwrap();
    let cases = [
        (
            ExemplarSet::single(generated_exemplar(48, 4)),
            AnalysisParams::default(),
        ),
        (
            ExemplarSet::single(generated_exemplar(40, 5)),
            AnalysisParams {
                triples: 300,
                ..AnalysisParams::default()
            },
        ),
        (
            ExemplarSet::single(generated_exemplar(40, 6)),
            AnalysisParams {
                triples: 8,
                levels: 2,
                ..AnalysisParams::default()
            },
        ),
        (
            ExemplarSet::single(generated_exemplar(40, 7)),
            AnalysisParams {
                neighbourhood: 9,
                max_candidates: 32,
                levels: 5,
                ..AnalysisParams::default()
            },
        ),
        (
            // The feature-distance channel widens every neighbourhood.
            ExemplarSet::single(generated_exemplar(48, 8)),
            AnalysisParams {
                feature_weight: 4.0,
                ..AnalysisParams::default()
            },
        ),
        (three, AnalysisParams::default()),
    ];
    for (set, params) in cases {
        let estimate =
            Candidates::estimated_peak_bytes(set.width(), set.height(), !set.is_single(), &params);
        let baseline = meter.reset();
        pool.install(|| Candidates::compute(&set, &params, &|_, _| {}).unwrap());
        let peak = meter.peak_above(baseline);
        println!("{params:?}: estimated {estimate}, measured {peak}");
        assert!(peak > 0);
        assert!(
            estimate >= peak && estimate <= 3 * peak,
            "{params:?}: estimated {estimate}, measured {peak}"
        );
    }
}

/// Decodes `bytes` as an upload is decoded, on a thread of its own whose
/// allocations `meter` counts; returns the peak.
fn decode_peak(meter: &'static Meter, bytes: &[u8]) -> u64 {
    std::thread::scope(|s| {
        s.spawn(|| {
            meter.attach();
            let baseline = meter.reset();
            Exemplar::decode_fitting(bytes).unwrap();
            meter.peak_above(baseline)
        })
        .join()
        .unwrap()
    })
}

#[test]
fn the_decode_estimate_bounds_the_measured_peak_and_a_png_is_never_held_whole() {
    let meter = Meter::leaked();
    let (w, h) = (6000u32, 4000u32);
    let rgb: Vec<u8> = (0..w * h)
        .flat_map(|i| {
            let (x, y) = (i % w, i / w);
            [(x / 24) as u8, (y / 16) as u8, ((x ^ y) % 97) as u8]
        })
        .collect();
    let full = u64::from(w) * u64::from(h) * 3;
    let jpeg = encode_jpeg(w, h, &rgb);
    let png = encode_png(w, h, &rgb);
    drop(rgb);
    let cases = [
        ("6000x4000.png", png),
        ("6000x4000.jpg", jpeg),
        ("progressive.jpg", image_fixture("progressive.jpg")),
        ("interlaced.png", image_fixture("interlaced.png")),
        ("cmyk.jpg", image_fixture("cmyk.jpg")),
    ];
    for (name, bytes) in cases {
        let estimate = Exemplar::decode_peak_bytes(&bytes).unwrap();
        let peak = decode_peak(meter, &bytes);
        println!("{name}: estimated {estimate}, measured {peak}");
        assert!(
            peak > 0 && estimate >= peak,
            "{name}: estimated {estimate}, measured {peak}"
        );
        assert!(
            estimate <= 2 * peak + (8 << 20),
            "{name}: estimated {estimate}, measured {peak}"
        );
        if name == "6000x4000.png" {
            // Read row by row: far below the image at full size.
            assert!(peak < full / 4, "{name}: {peak} of {full}");
        }
    }
}

fn scrape(text: &str, name: &str) -> f64 {
    text.lines()
        .filter(|l| l.starts_with(name))
        .filter_map(|l| l.rsplit(' ').next()?.parse::<f64>().ok())
        .sum()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn uploads_over_the_bound_are_refused_and_peaks_are_reported() {
    let dir = tempfile::tempdir().unwrap();
    let mut args = test_args(dir.path());
    let small = Candidates::estimated_peak_bytes(32, 32, false, &AnalysisParams::default());
    args.max_precompute_bytes = small + (small >> 1);
    let s = TestServer::start(args).await;
    let c = client();
    // 64² needs about four times what 32² does: refused before anything
    // is stored.
    let (st, v) = upload(&c, &s, exemplar_png(64, 1), "").await;
    assert_eq!(st, 413, "{v}");
    assert_eq!(v["error"]["code"], "precompute_too_large");
    let listed: Value = get_json(&c, &s, "/v1/textures").await;
    assert_eq!(listed["textures"].as_array().unwrap().len(), 0);
    // A 32² fits; its peak is measured and reported, below the estimate.
    let (st, v) = upload(&c, &s, exemplar_png(32, 2), "").await;
    assert_eq!(st, 202, "{v}");
    assert_eq!(v["precompute_estimated_bytes"].as_u64(), Some(small));
    let id = v["id"].as_str().unwrap().to_string();
    let v = wait_ready(&c, &s, &id).await;
    let peak = v["precompute_peak_bytes"]
        .as_u64()
        .expect("a measured peak");
    assert!(peak > 0 && peak <= small, "{v}");
    let text = metrics(&c, &s).await;
    assert_eq!(scrape(&text, "solidtex_precompute_peak_bytes_count"), 1.0);
    assert_eq!(scrape(&text, "solidtex_precompute_reserved_bytes"), 0.0);
    s.stop().await;
    // The peak is kept with the texture.
    let s = TestServer::start(test_args(dir.path())).await;
    let v = wait_ready(&c, &s, &id).await;
    assert_eq!(v["precompute_peak_bytes"].as_u64(), Some(peak));
    s.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn precomputes_run_together_only_within_the_bound() {
    let dir = tempfile::tempdir().unwrap();
    let mut args = test_args(dir.path());
    let one = Candidates::estimated_peak_bytes(32, 32, false, &AnalysisParams::default());
    args.max_precomputes = 3;
    args.max_precompute_bytes = one + (one >> 1);
    let s = TestServer::start(args).await;
    let c = client();
    let mut ids = Vec::new();
    for seed in 10..13 {
        let (st, v) = upload(&c, &s, exemplar_png(32, seed), "").await;
        assert_eq!(st, 202, "{v}");
        ids.push(v["id"].as_str().unwrap().to_string());
    }
    for id in &ids {
        wait_ready(&c, &s, id).await;
    }
    // Three slots, room for one: they ran one after another.
    let (now, most) = s.state.registry.precompute_reserved();
    assert_eq!((now, most), (0, one));
    s.stop().await;
}
