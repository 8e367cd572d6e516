//! Periodic solids through the public API, the command line and the
//! server: blocks of one period tile without a seam, and periods that do
//! not fit are refused with clear errors. (That the synthesis itself
//! repeats, copies synthesized apart, is the property test in
//! crates/core/src/synth/periodic_tests.rs.)

mod common;
mod server_support;

use common::*;
use server_support::*;
use solidtex_core::eval::{RgbView, tiling_seam};
use solidtex_core::{
    Axis, ExemplarSet, Region, Request, SynthParams, Texture, TileCache, Window, bundled,
};
use std::sync::Arc;

fn bundled_texture(period: Option<[u32; 3]>) -> Texture {
    let set = ExemplarSet::single(bundled::exemplar());
    let cands = bundled::candidates_for(&set, &Default::default()).unwrap();
    let params = SynthParams {
        period,
        ..SynthParams::default()
    };
    Texture::new(Arc::new(cands), params, Arc::new(TileCache::new(256 << 20))).unwrap()
}

/// The seam measure of the issue: a 128³ block of the bundled texture
/// tiled 2×2, through its xy slice at z = 0 and its yz slice at x = 0
/// (between them every axis crosses a border). With period 128 the
/// luminance steps across the borders lie within the steps inside the
/// tile; the same block of the aperiodic texture has steps across its
/// borders above every step inside.
#[test]
fn a_periodic_block_tiles_without_a_seam_and_an_aperiodic_one_does_not() {
    let side = 128u32;
    let measure = |t: &Texture| {
        [Axis::Z, Axis::X].map(|axis| {
            let (rgb, _) = t
                .render(
                    &Request::slice(axis, 0, Window::new(0, 0, side, side)).unwrap(),
                    0,
                )
                .unwrap();
            tiling_seam(RgbView {
                width: side,
                height: side,
                rgb: &rgb,
            })
        })
    };
    for (name, periodic) in [("periodic", true), ("aperiodic", false)] {
        let t = bundled_texture(periodic.then_some([side; 3]));
        for (axis, seam) in ["xy", "yz"].iter().zip(measure(&t)) {
            let inside = &seam.inside;
            println!(
                "{name} {axis}: border steps {:.2} / {:.2}, inside median {:.2}, max {:.2}, rank {:.3}",
                seam.border[0],
                seam.border[1],
                inside[inside.len() / 2],
                inside[inside.len() - 1],
                seam.rank()
            );
            if periodic {
                assert!(seam.within(), "{name} {axis}: {seam:?}");
            } else {
                assert!(seam.rank() == 1.0, "{name} {axis}: {seam:?}");
            }
        }
    }
}

/// A request over two periods is its period repeated, at the finest level
/// and a coarser one (whose period is half as many voxels).
#[test]
fn two_periods_are_one_repeated_at_every_level_of_detail() {
    let t = texture_with(
        SynthParams {
            period: Some([32, 16, 48]),
            ..SynthParams::default()
        },
        64 << 20,
    );
    for lod in [0u32, 1] {
        let p = [32i64 >> lod, 16 >> lod, 48 >> lod];
        let size = [2 * p[0] as u32, 2 * p[1] as u32, 3];
        let (rgb, _) = t
            .render(
                &Request::region(Region {
                    origin: [-7, 5, 100],
                    size,
                })
                .unwrap(),
                lod,
            )
            .unwrap();
        let at = |x: i64, y: i64, z: i64| {
            let i = ((z * size[1] as i64 + y) * size[0] as i64 + x) as usize * 3;
            &rgb[i..i + 3]
        };
        for z in 0..3 {
            for y in 0..p[1] {
                for x in 0..p[0] {
                    assert_eq!(at(x, y, z), at(x + p[0], y, z), "lod {lod} {x},{y},{z}");
                    assert_eq!(at(x, y, z), at(x, y + p[1], z), "lod {lod} {x},{y},{z}");
                }
            }
        }
    }
}

/// `--period` on the command line gives the library's bytes, and a
/// slice of one period wraps onto the slice one period along.
#[test]
fn the_command_line_takes_a_period() {
    let dir = tempfile::tempdir().unwrap();
    let slice = |name: &str, at: &str| {
        let out = dir.path().join(name);
        solidtex(&[
            "slice",
            "--period",
            "64,64,32",
            "--axis",
            "z",
            "--at",
            at,
            "--width",
            "64",
            "--height",
            "32",
            "-o",
            out.to_str().unwrap(),
        ]);
        decode_png(&std::fs::read(out).unwrap()).2
    };
    let a = slice("a.png", "3");
    assert_eq!(a, slice("b.png", "35"));
    let t = bundled_texture(Some([64, 64, 32]));
    assert_eq!(
        a,
        t.render(
            &Request::slice(Axis::Z, 3, Window::new(0, 0, 64, 32)).unwrap(),
            0
        )
        .unwrap()
        .0
    );
}

/// Uploads with a period at and past each limit: the range (1 to 4096),
/// the multiple (16 with three levels), and text that is not a period.
#[tokio::test(flavor = "multi_thread")]
async fn periods_that_do_not_fit_are_refused_at_upload() {
    let dir = tempfile::tempdir().unwrap();
    let s = TestServer::start(test_args(dir.path())).await;
    let c = client();
    for (period, want) in [
        ("16", Ok([16, 16, 16])),
        ("4096,16,32", Ok([4096, 16, 32])),
        ("0016", Ok([16, 16, 16])),
        ("0", Err("out_of_range")),
        ("4097", Err("out_of_range")),
        ("4112", Err("out_of_range")),
        ("16,16,0", Err("out_of_range")),
        ("8", Err("invalid_request")),
        ("24,16,16", Err("invalid_request")),
        ("16,16", Err("invalid_params")),
        ("-16", Err("invalid_params")),
        ("wide", Err("invalid_params")),
        // Outside the one text grammar openapi.yaml documents.
        ("%5B32,48,64%5D", Err("invalid_params")),
        ("32,%2048,%2064", Err("invalid_params")),
        ("%2016", Err("invalid_params")),
        ("null", Err("invalid_params")),
        ("1e2", Err("invalid_params")),
        ("99999999999", Err("out_of_range")),
    ] {
        let (status, v) = upload(
            &c,
            &s,
            exemplar_png(32, 1),
            &format!("{SMALL_PARAMS}&period={period}"),
        )
        .await;
        match want {
            Ok(sides) => {
                assert!(status == 201 || status == 202, "{period}: {status} {v}");
                assert_eq!(v["params"]["period"], serde_json::json!(sides), "{v}");
            }
            Err(code) => {
                assert_eq!(
                    (status, v["error"]["code"].as_str()),
                    (400, Some(code)),
                    "{period}: {v}"
                );
                let message = v["error"]["message"].as_str().unwrap();
                assert!(message.contains("period"), "{message}");
            }
        }
    }
    s.stop().await;
}
