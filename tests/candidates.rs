//! Exemplar analysis and candidate precomputation on real exemplars.

mod common;

use common::*;
use solidtex_core::{AnalysisParams, Candidates, CorruptKind, Error, Exemplar, ExemplarSet};

#[test]
fn selected_triples_beat_random_ones_by_a_wide_margin() {
    let c = Candidates::compute(
        &ExemplarSet::single(exemplar("animal_leather.png")),
        &AnalysisParams::default(),
        &|_, _| {},
    )
    .unwrap();
    for (k, l) in c.report().levels.iter().enumerate() {
        assert!(
            l.mean_best_error * 4.0 < l.mean_random_error,
            "level {k}: best {} vs random {}",
            l.mean_best_error,
            l.mean_random_error
        );
    }
    // Recomputing the error of stored triples agrees with the report.
    let t = c.level(0).candidates(0).triples[0];
    assert!(c.crossbar_error(0, t).is_finite());
}

#[test]
fn coherence_filter_leaves_at_most_twelve_per_pixel() {
    let c = small_candidates();
    for k in 0..c.level_count() {
        for p in 0..3 {
            let pc = c.level(k).candidates(p);
            for px in 0..c.dims().len() as u32 {
                let n = pc.range(px).len();
                assert!((1..=12).contains(&n), "level {k} plane {p} pixel {px}: {n}");
            }
        }
    }
}

#[test]
fn stx_bytes_do_not_depend_on_thread_count() {
    let set = ExemplarSet::single(small_exemplar());
    let one = with_threads(1, || {
        Candidates::compute(&set, &small_params(), &|_, _| {}).unwrap()
    });
    let four = with_threads(4, || {
        Candidates::compute(&set, &small_params(), &|_, _| {}).unwrap()
    });
    assert_eq!(one.to_bytes(), four.to_bytes());
}

#[test]
fn three_distinct_exemplars_are_supported() {
    let e = small_exemplar();
    let flip = |e: &Exemplar| {
        let mut rgb = e.to_rgb_bytes();
        rgb.reverse();
        Exemplar::from_rgb(e.width(), e.height(), &rgb).unwrap()
    };
    let set = ExemplarSet::triple(e.clone(), flip(&e), e.clone()).unwrap();
    assert!(!set.is_single());
    let c = Candidates::compute(&set, &small_params(), &|_, _| {}).unwrap();
    let back = Candidates::load(&c.to_bytes()).unwrap();
    assert_eq!(back.to_bytes(), c.to_bytes());
}

#[test]
fn save_load_round_trip_is_exact() {
    let c = small_candidates();
    let mut bytes = Vec::new();
    c.save(&mut bytes).unwrap();
    let back = Candidates::load(&bytes).unwrap();
    assert_eq!(back.to_bytes(), bytes);
    for k in 0..c.level_count() {
        for p in 0..3 {
            assert_eq!(back.level(k).appearance[p], c.level(k).appearance[p]);
        }
    }
}

#[test]
fn corrupt_and_truncated_files_are_errors() {
    let bytes = small_candidates().to_bytes();
    let kind = |b: &[u8]| match Candidates::load(b) {
        Err(Error::CorruptFile(k)) => k,
        other => panic!("expected corrupt-file error, got {other:?}"),
    };
    assert_eq!(kind(b"not an stx file at all"), CorruptKind::BadMagic);
    assert_eq!(kind(&bytes[..bytes.len() / 2]), CorruptKind::Truncated);
    assert_eq!(kind(&bytes[..10]), CorruptKind::Truncated);
    let mut flipped = bytes.clone();
    let i = flipped.len() - 100;
    flipped[i] ^= 0x40;
    assert_eq!(kind(&flipped), CorruptKind::Checksum);
    let mut version = bytes.clone();
    version[8] = 99;
    assert_eq!(kind(&version), CorruptKind::Version(99));
    let mut longer = bytes.clone();
    longer.push(0);
    assert!(matches!(kind(&longer), CorruptKind::Invalid(_)));
    // Every truncation point is an error, never a panic.
    for cut in (0..bytes.len()).step_by(bytes.len() / 97 + 1) {
        assert!(Candidates::load(&bytes[..cut]).is_err());
    }
}

/// Rewrites a PNG's IHDR size (and its CRC) without touching the data.
fn claim_size(mut png: Vec<u8>, w: u32, h: u32) -> Vec<u8> {
    png[16..20].copy_from_slice(&w.to_be_bytes());
    png[20..24].copy_from_slice(&h.to_be_bytes());
    let crc = crc32fast::hash(&png[12..29]);
    png[29..33].copy_from_slice(&crc.to_be_bytes());
    png
}

#[test]
fn bad_images_give_clear_errors() {
    assert!(matches!(
        Exemplar::decode(&flat_png(1, 1)),
        Err(Error::ImageSize {
            width: 1,
            height: 1,
            ..
        })
    ));
    assert!(matches!(
        Exemplar::decode(&flat_png(16, 600)),
        Err(Error::ImageSize { .. })
    ));
    let bomb = claim_size(flat_png(16, 16), 10000, 10000);
    assert!(matches!(
        Exemplar::decode(&bomb),
        Err(Error::ImageSize { width: 10000, .. })
    ));
    let zero = claim_size(flat_png(16, 16), 0, 0);
    assert!(Exemplar::decode(&zero).is_err());
    assert!(matches!(
        Exemplar::decode(b"GIF89a not really"),
        Err(Error::MalformedImage(_))
    ));
    assert!(matches!(
        Exemplar::decode(b""),
        Err(Error::MalformedImage(_))
    ));
    let truncated = flat_png(32, 32);
    assert!(Exemplar::decode(&truncated[..truncated.len() - 20]).is_err());
    assert!(Exemplar::decode(&flat_png(16, 16)).is_ok());
    let a = Exemplar::decode(&flat_png(16, 16)).unwrap();
    let b = Exemplar::decode(&flat_png(32, 32)).unwrap();
    assert!(matches!(
        ExemplarSet::triple(a.clone(), b, a),
        Err(Error::SizeMismatch(_))
    ));
}
