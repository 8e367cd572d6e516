//! Periodicity as a property of the synthesis itself: a voxel and its copy
//! a period away are synthesized apart (each tile under its own cache key,
//! each through its own dependency chain) and must come out the same.

use super::Engine;
use crate::params::{Scheme, SlabTiling, SynthParams};
use crate::request::Region;
use crate::synth::cache::TileCache;
use crate::{Candidates, Field, bundled};
use proptest::prelude::*;
use std::sync::{Arc, OnceLock};

fn candidates() -> Arc<Candidates> {
    static C: OnceLock<Arc<Candidates>> = OnceLock::new();
    C.get_or_init(|| {
        let set = crate::ExemplarSet::single(bundled::exemplar());
        Arc::new(bundled::candidates_for(&set, &Default::default()).expect("bundled"))
    })
    .clone()
}

/// An engine whose copies of a tile do not share a key.
fn apart(params: SynthParams) -> Engine {
    let mut e = Engine::new(candidates(), params, Arc::new(TileCache::new(64 << 20))).unwrap();
    e.share_copies = false;
    e
}

fn voxels(e: &Engine, points: &[[i64; 3]], lod: u32) -> Vec<[u8; 3]> {
    let rgb = e.points_rgb(points, lod).unwrap().0;
    rgb.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect()
}

/// The variants whose position-dependent parts differ: slab blocks, the
/// standard scheme, block subpasses at every level, a field, no jitter.
fn variant(i: u8, period: [u32; 3]) -> SynthParams {
    let base = SynthParams {
        period: Some(period),
        seed: 3 + i as u64,
        ..SynthParams::default()
    };
    match i {
        0 => base,
        1 => SynthParams {
            slab_tiling: SlabTiling::Blocks,
            ..base
        },
        2 => SynthParams {
            scheme: Scheme::Standard,
            parity_levels: 0,
            ..base
        },
        3 => SynthParams {
            field: Some(Field::Circular {
                centre: [40.0, 20.0, 0.0],
                axis: [0.0, 0.0, 1.0],
            }),
            ..base
        },
        _ => SynthParams {
            jitter: 0.0,
            grid: 8,
            ..base
        },
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, ..ProptestConfig::default() })]

    /// voxel(p) = voxel(p + m·P_k·eᵢ) at every level k, for random
    /// periods (each side its own multiple of 32), positions, axes and
    /// multiples, under every variant.
    #[test]
    fn a_periodic_solid_repeats_at_every_level(
        sides in prop::array::uniform3(1u32..=8),
        p in prop::array::uniform3(-3000i64..3000),
        axis in 0usize..3,
        m in prop::sample::select(vec![-3i64, -1, 1, 2, 50]),
        lod in 0u32..=3,
        v in 0u8..5,
    ) {
        let period = sides.map(|s| s * 32);
        let e = apart(variant(v, period));
        let mut q = p;
        q[axis] += m * (period[axis] >> lod) as i64;
        let got = voxels(&e, &[p, q], lod);
        prop_assert_eq!(got[0], got[1], "period {:?}, {:?} and {:?} at lod {}", period, p, q, lod);
    }
}

/// The planes of a whole period and of its copy, synthesized apart, are
/// equal voxel for voxel: the seam planes included, and with them every
/// voxel whose chain crosses the period's border.
#[test]
fn a_whole_period_equals_its_copy() {
    let period = [32, 64, 32];
    let e = apart(variant(0, period));
    let slab = |origin: [i64; 3]| {
        let r = Region {
            origin,
            size: [32, 64, 2],
        };
        e.region_rgb(&r, 0).unwrap().0
    };
    let home = slab([0, 0, 31]);
    assert_eq!(home, slab([32, -64, 31 + 32]));
    assert_eq!(home, slab([-96, 128, 31 - 64]));
    // Not a constant: the solid is a texture.
    assert!(home.chunks(3).any(|c| c != &home[..3]));
}

/// With a key shared by copies, a request larger than a period gives the
/// same bytes as one synthesized apart, and a block of two periods is its
/// period repeated.
#[test]
fn shared_copies_give_the_bytes_of_separate_ones() {
    let params = variant(0, [32; 3]);
    let shared = Engine::new(
        candidates(),
        params.clone(),
        Arc::new(TileCache::new(64 << 20)),
    )
    .unwrap();
    let r = Region {
        origin: [-5, 7, 30],
        size: [70, 3, 4],
    };
    let a = shared.region_rgb(&r, 0).unwrap().0;
    assert_eq!(a, apart(params).region_rgb(&r, 0).unwrap().0);
    for (i, rgb) in a.chunks(3).enumerate() {
        let x = i % 70;
        if x + 32 < 70 {
            assert_eq!(rgb, &a[(i + 32) * 3..(i + 32) * 3 + 3], "x {x}");
        }
    }
}

/// An aperiodic solid does not repeat at those distances (the test above
/// would pass for any constant-ish texture otherwise).
#[test]
fn an_aperiodic_solid_does_not_repeat() {
    let e = apart(SynthParams::default());
    let mut differ = 0;
    for i in 0..16i64 {
        let p = [i * 37 - 200, i * 11, -i * 5];
        let got = voxels(&e, &[p, [p[0] + 128, p[1], p[2]]], 0);
        differ += (got[0] != got[1]) as u32;
    }
    assert!(differ > 8, "{differ} of 16 differ");
}

#[test]
fn periods_that_do_not_fit_the_levels_are_refused() {
    for (period, ok) in [
        ([32, 32, 32], true),
        ([48, 32, 32], false),
        ([16, 32, 32], false),
    ] {
        let params = SynthParams {
            period: Some(period),
            ..SynthParams::default()
        };
        let e = Engine::new(candidates(), params, Arc::new(TileCache::new(1 << 20)));
        assert_eq!(e.is_ok(), ok, "{period:?}");
    }
}
