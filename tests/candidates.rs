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

#[test]
fn pngs_and_jpegs_of_every_kind_decode_as_the_image_crate_reads_them() {
    for name in [
        "baseline.jpg",
        "progressive.jpg",
        "restarts.jpg",
        "grey.jpg",
        "cmyk.jpg",
        "palette.png",
        "rgba.png",
        "interlaced.png",
        "grey16.png",
    ] {
        let bytes = image_fixture(name);
        let e = Exemplar::decode(&bytes).unwrap_or_else(|e| panic!("{name}: {e}"));
        let reference = image::load_from_memory(&bytes).unwrap().to_rgb8();
        assert_eq!((e.width(), e.height()), reference.dimensions(), "{name}");
        // 16-bit samples are cut to their high byte, where the image
        // crate rounds: one level apart at most.
        let most = e
            .to_rgb_bytes()
            .iter()
            .zip(reference.as_raw())
            .map(|(a, b)| a.abs_diff(*b))
            .max()
            .unwrap();
        assert!(most <= u8::from(name == "grey16.png"), "{name}: {most}");
    }
}

#[test]
fn images_that_end_early_or_claim_more_than_they_hold_are_refused() {
    // The first half of a 128² JPEG, which a lenient decoder fills with
    // grey, and of each kind of file.
    let rgb = decode_png(&exemplar_png(128, 5)).2;
    let jpeg = encode_jpeg(128, 128, &rgb);
    assert!(Exemplar::decode(&jpeg).is_ok());
    let mut files = vec![("128².jpg", jpeg.clone())];
    for name in [
        "baseline.jpg",
        "progressive.jpg",
        "interlaced.png",
        "palette.png",
    ] {
        files.push((name, image_fixture(name)));
    }
    for (name, bytes) in files {
        let half = &bytes[..bytes.len() / 2];
        for r in [
            Exemplar::decode(half),
            Exemplar::decode_fitting(half).map(|r| r.0),
        ] {
            assert!(matches!(r, Err(Error::MalformedImage(_))), "{name}: {r:?}");
        }
    }
    // A header claiming 6000² in a file of a few kilobytes is refused
    // before anything is decoded or allocated.
    let lying = claim_jpeg_size(jpeg.clone(), 6000, 6000);
    for r in [
        Exemplar::decode_fitting(&lying).map(|_| ()),
        Exemplar::decode_peak_bytes(&lying).map(|_| ()),
    ] {
        match r {
            Err(Error::MalformedImage(m)) => assert!(m.contains("claims 6000x6000"), "{m}"),
            other => panic!("{other:?}"),
        }
    }
    // One claiming a little more than it holds is decoded, and found short.
    let taller = claim_jpeg_size(jpeg, 128, 200);
    assert!(matches!(
        Exemplar::decode(&taller),
        Err(Error::MalformedImage(_))
    ));
}

#[test]
fn an_exif_orientation_is_applied() {
    for (plain, turned) in [
        ("baseline.jpg", "rotated.jpg"),
        ("interlaced.png", "rotated.png"),
    ] {
        let plain = Exemplar::decode(&image_fixture(plain)).unwrap();
        let turned = Exemplar::decode(&image_fixture(turned)).unwrap();
        assert_eq!((plain.width(), plain.height()), (80, 48));
        // Orientation 6: displayed turned a quarter clockwise.
        assert_eq!(turned, plain.rotated(90));
    }
}

#[test]
fn a_large_photo_is_downscaled_close_to_a_full_size_resize() {
    let (w, h) = (1800u32, 1200u32);
    let rgb: Vec<u8> = (0..w * h)
        .flat_map(|i| {
            let (x, y) = (i % w, i / w);
            let stripe = ((x / 7 + y / 11) % 2) as u8 * 90;
            [(x / 8) as u8, (y / 6) as u8, stripe + ((x ^ y) % 40) as u8]
        })
        .collect();
    let full = image::RgbImage::from_raw(w, h, rgb.clone()).unwrap();
    let reference = image::imageops::resize(&full, 512, 341, image::imageops::FilterType::Lanczos3);
    for (name, bytes) in [
        ("png", encode_png(w, h, &rgb)),
        ("jpeg", encode_jpeg(w, h, &rgb)),
    ] {
        let (e, original) = Exemplar::decode_fitting(&bytes).unwrap();
        assert_eq!(original, Some((w, h)));
        assert_eq!((e.width(), e.height()), (512, 341));
        let got = e.to_rgb_bytes();
        let mean = got
            .iter()
            .zip(reference.as_raw())
            .map(|(a, b)| f64::from(a.abs_diff(*b)))
            .sum::<f64>()
            / got.len() as f64;
        assert!(mean < 4.0, "{name}: mean difference {mean}");
    }
}
