//! The synthesis commands end to end on the bundled exemplar (its
//! candidates ship with the binary, so nothing is precomputed here but
//! by `solidtex eval`, which analyses every exemplar it scores).

mod common;

use std::path::Path;
use std::process::Command;

fn solidtex(args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_solidtex"))
        .args(args)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "{args:?}: {stderr}");
    stderr
}

fn rgb(path: &Path) -> (u32, u32, Vec<u8>) {
    let img = image::open(path).unwrap().to_rgb8();
    (img.width(), img.height(), img.into_raw())
}

#[test]
fn a_cut_along_the_axes_is_the_axis_slice() {
    let dir = tempfile::tempdir().unwrap();
    let slice = dir.path().join("slice.png");
    let cut = dir.path().join("cut.png");
    let said = solidtex(&[
        "slice",
        "--axis",
        "z",
        "--at",
        "7",
        "--u0",
        "-5",
        "--v0",
        "3",
        "--width",
        "40",
        "--height",
        "24",
        "-o",
        slice.to_str().unwrap(),
    ]);
    assert!(said.starts_with("wrote a 40×24 z slice at z = 7"), "{said}");
    assert!(!said.contains("precomputing"), "{said}");
    let said = solidtex(&[
        "cut",
        "--origin",
        "-5,3,7",
        "--u",
        "1,0,0",
        "--v",
        "0,1,0",
        "--width",
        "40",
        "--height",
        "24",
        "-o",
        cut.to_str().unwrap(),
    ]);
    assert!(said.starts_with("wrote a 40×24 oblique cut"), "{said}");
    let (w, h, a) = rgb(&slice);
    assert_eq!((w, h), (40, 24));
    assert_eq!(rgb(&cut), (w, h, a));
}

#[test]
fn short_size_options_are_aliases_of_the_long_ones() {
    let dir = tempfile::tempdir().unwrap();
    let long = dir.path().join("long.raw");
    let short = dir.path().join("short.raw");
    let corner = ["--x", "3", "--y", "-2", "--z", "9"];
    let run = |sizes: [&str; 6], out: &Path| {
        let mut args = vec!["region"];
        args.extend(corner);
        args.extend(sizes);
        args.extend(["-o", out.to_str().unwrap()]);
        solidtex(&args)
    };
    run(["--width", "6", "--height", "5", "--depth", "4"], &long);
    run(["--w", "6", "--h", "5", "--d", "4"], &short);
    let bytes = std::fs::read(&long).unwrap();
    assert_eq!(bytes.len(), 6 * 5 * 4 * 3);
    assert_eq!(bytes, std::fs::read(&short).unwrap());
}

#[test]
fn a_bad_vector_is_refused_with_its_reason() {
    let out = Command::new(env!("CARGO_BIN_EXE_solidtex"))
        .args(["cut", "--u", "1,0", "-o", "/nonexistent/cut.png"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("is not three numbers"), "{err}");
}

#[test]
fn precompute_takes_a_feature_mask_and_keeps_it_in_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let side = 32u32;
    let exemplar: Vec<u8> = (0..side * side * 3).map(|i| (i * 37 % 251) as u8).collect();
    let mask: Vec<u8> = (0..side * side)
        .flat_map(|i| {
            let l = if (i / side) % 8 < 2 { 255 } else { 0 };
            [l, l, l]
        })
        .collect();
    let (e, m) = (dir.path().join("e.png"), dir.path().join("m.png"));
    image::save_buffer(&e, &exemplar, side, side, image::ColorType::Rgb8).unwrap();
    image::save_buffer(&m, &mask, side, side, image::ColorType::Rgb8).unwrap();
    let stx = dir.path().join("e.stx");
    let args = |weight: &str| {
        [
            "precompute",
            e.to_str().unwrap(),
            "-o",
            stx.to_str().unwrap(),
            "--levels",
            "2",
            "--feature-mask",
            m.to_str().unwrap(),
            "--feature-weight",
            weight,
        ]
        .map(String::from)
    };
    solidtex(&args("1").each_ref().map(String::as_str));
    let c = solidtex_core::Candidates::load(&std::fs::read(&stx).unwrap()).unwrap();
    let kept = c.exemplars().plane(0).feature_mask().unwrap();
    assert_eq!(
        kept.iter().filter(|&&f| f).count(),
        (side * side / 4) as usize
    );
    assert!(kept[0] && !kept[(3 * side) as usize]);
    // Without the channel the mask would do nothing: refused, saying why.
    let out = Command::new(env!("CARGO_BIN_EXE_solidtex"))
        .args(args("0"))
        .output()
        .unwrap();
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("feature_weight"), "{stderr}");
}

/// `solidtex eval`, the quality check CI runs: on the bundled marble and
/// the three test exemplars, the corrected slices' texture statistics
/// (band spectrum, gradient directions and connected-feature sizes, each
/// a mean over the slices) are closer to the exemplar than those of the
/// slab initialisation they started from. Where the exemplar has large
/// features (marble's veins, leopard's spots), they are also less than
/// half as far as a shuffle of its pixels; the fine-grained leather and
/// wood5 shuffle into specks of their own sizes, so a shuffle is no
/// baseline for them.
#[test]
fn corrected_slices_are_closer_in_structure_than_the_slab_and_a_shuffle() {
    let marble = Path::new(env!("CARGO_MANIFEST_DIR")).join("crates/core/assets/default.png");
    let mut args = vec!["eval".into(), "--json".into(), marble.into_os_string()];
    for name in ["animal_leopard.png", "animal_leather.png", "wood_wood5.png"] {
        args.push(common::exemplar_path(name).into_os_string());
    }
    let rows = common::solidtex_json(&args);
    let rows = rows.as_array().expect("a list of scores");
    let structure = |exemplar: &str, method: &str| {
        let rows: Vec<&serde_json::Value> = rows
            .iter()
            .filter(|r| r["exemplar"] == exemplar && r["method"] == method)
            .collect();
        assert!(!rows.is_empty(), "no {method} rows for {exemplar}");
        let mean = |key: &str| {
            let v: Vec<f64> = rows.iter().filter_map(|r| r[key].as_f64()).collect();
            assert!(!v.is_empty(), "{exemplar} {method}: no {key}");
            v.iter().sum::<f64>() / v.len() as f64
        };
        mean("spectrum") + mean("directions") + mean("components")
    };
    for (name, large_features) in [
        ("default.png", true),
        ("animal_leopard.png", true),
        ("animal_leather.png", false),
        ("wood_wood5.png", false),
    ] {
        let corrected = structure(name, "dual-grid");
        let slab = structure(name, "slab-only");
        assert!(
            corrected < slab,
            "{name}: corrected {corrected:.3}, slab {slab:.3}"
        );
        if large_features {
            let shuffled = structure(name, "shuffled");
            assert!(
                corrected < 0.5 * shuffled,
                "{name}: corrected {corrected:.3}, shuffled {shuffled:.3}"
            );
        }
    }
}

/// The parameter flags are the knobs of crates/core/src/params/knobs.rs:
/// every knob that has a flag is an option of the synthesis commands or
/// of `precompute`, a value out of its range is refused as the server refuses it,
/// and the flags set exactly the parameters the same keys set.
#[test]
fn synthesis_flags_are_the_knobs() {
    use solidtex_core::knobs::{Part, knobs_of};
    use solidtex_core::{
        AnalysisParams, Axis, ExemplarSet, Request, SynthParams, Texture, TileCache, Window,
    };
    use std::sync::Arc;

    for (command, part) in [("slice", Part::Synthesis), ("precompute", Part::Analysis)] {
        let help = Command::new(env!("CARGO_BIN_EXE_solidtex"))
            .args([command, "--help"])
            .output()
            .unwrap();
        let help = String::from_utf8_lossy(&help.stdout);
        for k in knobs_of(part).filter(|k| k.flag) {
            assert!(
                help.contains(&format!("--{} <", k.flag_name())),
                "no --{} in `{command} --help`",
                k.flag_name()
            );
        }
    }
    let out = Command::new(env!("CARGO_BIN_EXE_solidtex"))
        .args([
            "slice", "--axis", "z", "--at", "0", "--passes", "7", "-o", "x.png",
        ])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && stderr.contains("`passes`"),
        "{stderr}"
    );

    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("slice.png");
    solidtex(&[
        "slice",
        "--axis",
        "z",
        "--at",
        "3",
        "--width",
        "24",
        "--height",
        "16",
        "--seed",
        "7",
        "--correct-init-level",
        "false",
        "--scheme",
        "standard",
        "--jitter",
        "0.5",
        "--period",
        "32",
        "-o",
        png.to_str().unwrap(),
    ]);
    let set = ExemplarSet::single(solidtex_core::bundled::exemplar());
    let candidates = solidtex_core::bundled::candidates_for(&set, &AnalysisParams::default())
        .expect("the bundled candidates");
    let params: SynthParams = serde_json::from_str(
        r#"{"seed": 7, "correct_init_level": false, "scheme": "standard", "jitter": 0.5,
            "period": "32"}"#,
    )
    .unwrap();
    let texture = Texture::new(
        Arc::new(candidates),
        params,
        Arc::new(TileCache::new(64 << 20)),
    )
    .unwrap();
    let (want, _) = texture
        .render(
            &Request::slice(Axis::Z, 3, Window::new(0, 0, 24, 16)).unwrap(),
            0,
        )
        .unwrap();
    assert_eq!(rgb(&png), (24, 16, want));
}
