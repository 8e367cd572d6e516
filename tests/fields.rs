//! Fields of local frames: the texture follows them, and stays a pure
//! function of position.

mod common;

use common::*;
use solidtex_core::eval::{RgbView, grain_map, line_angle};
use solidtex_core::{
    AnalysisParams, Axis, Candidates, ExemplarSet, Field, Region, Request, SynthParams, Texture,
    TileCache, Window,
};
use std::sync::{Arc, OnceLock};

/// Candidates of a striped exemplar (grain along u), laid out as the
/// analysis chooses for it.
fn grain_candidates() -> Arc<Candidates> {
    static C: OnceLock<Arc<Candidates>> = OnceLock::new();
    C.get_or_init(|| {
        let (w, h, rgb) = decode_png(&grain_png(64, 64));
        let e = solidtex_core::Exemplar::from_rgb(w, h, &rgb).unwrap();
        let params = AnalysisParams {
            levels: 3,
            ..AnalysisParams::default()
        };
        Arc::new(Candidates::compute(&ExemplarSet::single(e), &params, &|_, _| {}).unwrap())
    })
    .clone()
}

fn grain_texture(field: Option<Field>) -> Texture {
    let params = SynthParams {
        field,
        ..SynthParams::default()
    };
    Texture::new(
        grain_candidates(),
        params,
        Arc::new(TileCache::new(256 << 20)),
    )
    .unwrap()
}

const SIDE: u32 = 160;
const WINDOW: u32 = 32;

/// Median angle between the grain of `measured`'s z slice (per 32²
/// window) and the local x axis of `guide`'s field projected into the
/// slice, with the windows' angles.
fn alignment_error(measured: &Texture, guide: &Texture) -> f64 {
    let (rgb, _) = measured
        .render(
            &Request::slice(Axis::Z, 0, Window::new(0, 0, SIDE, SIDE)).unwrap(),
            0,
        )
        .unwrap();
    let image = RgbView {
        width: SIDE,
        height: SIDE,
        rgb: &rgb,
    };
    let mut errors: Vec<f64> = grain_map(image, WINDOW)
        .iter()
        .map(|w| {
            let x = guide.frame(0, [w.centre[0], w.centre[1], 0.0])[0];
            let want = x[1].atan2(x[0]).to_degrees();
            line_angle(w.grain.degrees as f64, want)
        })
        .collect();
    errors.sort_by(f64::total_cmp);
    errors[errors.len() / 2]
}

/// Two steep curves across the slice on the xy plane, leaning opposite
/// ways, one of them bent.
fn two_curves() -> Field {
    serde_json::from_str(
        r#"{"kind": "sketch", "curves": [
            {"points": [[20, 0, 0], [40, 80, 0], [50, 160, 0]], "normal": [0, 0, 1]},
            {"points": [[110, 160, 0], [140, 0, 0]], "normal": [0, 0, 1]}
        ]}"#,
    )
    .unwrap()
}

#[test]
fn slices_follow_the_slant_and_circular_presets_and_a_sketch() {
    let unguided = grain_texture(None);
    for field in [
        Field::Slant { angle: 60.0 },
        Field::Circular {
            centre: [SIDE as f64 / 2.0, SIDE as f64 / 2.0, 0.0],
            axis: [0.0, 0.0, 1.0],
        },
        two_curves(),
    ] {
        let guided = grain_texture(Some(field.clone()));
        let follows = alignment_error(&guided, &guided);
        let ignores = alignment_error(&unguided, &guided);
        println!("{field:?}: median error {follows:.1}° guided, {ignores:.1}° unguided");
        assert!(follows <= 15.0, "{field:?}: {follows:.1}°");
        assert!(ignores >= 40.0, "{field:?}: unguided {ignores:.1}°");
    }
}

fn region(t: &Texture, origin: [i64; 3], size: [u32; 3]) -> Vec<u8> {
    t.render(&Request::region(Region { origin, size }).unwrap(), 0)
        .unwrap()
        .0
}

/// The determinism of unguided textures holds with a field: a region is
/// the same voxels cut from a larger one and from slices, on any thread
/// count and cache state.
#[test]
fn a_field_keeps_voxels_a_function_of_position() {
    let field = Field::Circular {
        centre: [5.0, -3.0, 0.0],
        axis: [1.0, 2.0, 3.0],
    };
    let t = grain_texture(Some(field.clone()));
    let (o, s) = ([3, -5, 7], [9u32, 6, 5]);
    let alone = region(&t, o, s);
    let big_o = [-6, -14, 2];
    let big = region(&grain_texture(Some(field.clone())), big_o, [24, 20, 14]);
    for z in 0..s[2] as i64 {
        for y in 0..s[1] as i64 {
            for x in 0..s[0] as i64 {
                let i = ((z * s[1] as i64 + y) * s[0] as i64 + x) as usize * 3;
                let p = [
                    o[0] + x - big_o[0],
                    o[1] + y - big_o[1],
                    o[2] + z - big_o[2],
                ];
                let j = ((p[2] * 20 + p[1]) * 24 + p[0]) as usize * 3;
                assert_eq!(alone[i..i + 3], big[j..j + 3], "voxel {x} {y} {z}");
            }
        }
    }
    let fresh = grain_texture(Some(field.clone()));
    for z in 0..s[2] as i64 {
        let (slice, _) = fresh
            .render(
                &Request::slice(Axis::Z, o[2] + z, Window::new(o[0], o[1], s[0], s[1])).unwrap(),
                0,
            )
            .unwrap();
        let n = (s[0] * s[1] * 3) as usize;
        assert_eq!(slice, alone[z as usize * n..(z as usize + 1) * n]);
    }
    let threads = with_threads(1, || region(&grain_texture(Some(field.clone())), o, s));
    assert_eq!(threads, alone);
    let tiny = Texture::new(
        grain_candidates(),
        SynthParams {
            field: Some(field),
            ..SynthParams::default()
        },
        Arc::new(TileCache::new(16 << 10)),
    )
    .unwrap();
    assert_eq!(region(&tiny, o, s), alone);
    // And the field changes the voxels.
    assert_ne!(region(&grain_texture(None), o, s), alone);
}

/// The planner marks the whole 3×3×3 neighbourhood a turned correction
/// reads: a plan still counts exactly what cold synthesis computes, and
/// the dual grid bounds the set (a small box is mostly halo, where the
/// cube's corners add the most; a 256² slice's set grows by a few per
/// cent).
#[test]
fn plans_count_what_a_field_texture_computes() {
    let region = Region {
        origin: [-7, 3, 11],
        size: [20, 9, 5],
    };
    let guided = grain_texture(Some(Field::Slant3d {
        direction: [1.0, 2.0, 2.0],
    }));
    let planned = guided.plan(&Request::region(region).unwrap(), 0).unwrap();
    let (_, done) = guided.render(&Request::region(region).unwrap(), 0).unwrap();
    assert_eq!(planned.voxels_per_level, done.voxels_per_level);
    assert_eq!(planned.corrections_per_level, done.corrections_per_level);
    let unguided = grain_texture(None)
        .plan(&Request::region(region).unwrap(), 0)
        .unwrap();
    let total = |v: &[u64]| v.iter().sum::<u64>() as f64;
    let ratio = total(&planned.corrections_per_level) / total(&unguided.corrections_per_level);
    assert!((1.0..1.6).contains(&ratio), "{ratio}");
}
