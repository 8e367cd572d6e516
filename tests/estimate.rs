//! The work estimate that admission control uses: an upper bound of what
//! the engine counts for the same request from a cold cache, not far above
//! it for axis slices and bricks, and under the default budget for what
//! the viewer, the load test and the benchmarks ask for.

use solidtex_core::{
    AnalysisParams, Axis, CutPlane, ExemplarSet, Filter, Region, Request, SynthParams, Texture,
    TileCache, bundled,
};
use solidtex_server::ServeArgs;
use std::sync::Arc;

/// The bundled texture (128², four levels), as served by default.
fn bundled_texture(params: SynthParams) -> Texture {
    let set = ExemplarSet::single(bundled::exemplar());
    let c = bundled::candidates_for(&set, &AnalysisParams::default()).unwrap();
    Texture::new(Arc::new(c), params, Arc::new(TileCache::new(1 << 20))).unwrap()
}

/// How far above the engine's count the estimate of an axis slice or a
/// brick may lie (docs/server.md).
const ORDINARY_FACTOR: f64 = 2.0;

fn cut(origin: [f64; 3], u: [f64; 3], v: [f64; 3], side: u32) -> CutPlane {
    CutPlane {
        origin,
        u,
        v,
        width: side,
        height: side,
    }
}

/// A unit vector along `d`.
fn unit(d: [f64; 3]) -> [f64; 3] {
    let n = d.iter().map(|x| x * x).sum::<f64>().sqrt();
    d.map(|x| x / n)
}

#[test]
fn the_estimate_bounds_the_engine_count() {
    let s = std::f64::consts::FRAC_1_SQRT_2;
    let diag = unit([-1.0, 2.0, 1.0]);
    for params in [SynthParams::default(), SynthParams::preview()] {
        let t = bundled_texture(params.clone());
        let ordinary = [
            (Region::slice(Axis::Z, 0, 0, 0, 256, 256), 0),
            (Region::slice(Axis::Z, 5, 3, -7, 256, 256), 0),
            (Region::slice(Axis::X, 3, 0, 0, 256, 256), 1),
            (Region::slice(Axis::Y, -3, 1, 2, 256, 256), 2),
            (Region::slice(Axis::Z, 3, 0, 0, 256, 256), 3),
            (Region::slice(Axis::Z, 17, -40, 9, 128, 128), 0),
            (Region::slice(Axis::X, -17, 0, 0, 128, 128), 2),
            (Region::slice(Axis::Z, 1, 0, 0, 512, 512), 0),
            (Region::slice(Axis::Y, 1, 0, 0, 333, 75), 1),
            (
                Region {
                    origin: [64, -64, 0],
                    size: [64; 3],
                },
                0,
            ),
            (
                Region {
                    origin: [64, -64, 0],
                    size: [64; 3],
                },
                1,
            ),
            (
                Region {
                    origin: [-32, 0, 96],
                    size: [32; 3],
                },
                2,
            ),
        ];
        let other = [
            (
                Region {
                    origin: [0; 3],
                    size: [100; 3],
                },
                0,
            ),
            (
                Region {
                    origin: [3, 5, 7],
                    size: [16, 9, 2],
                },
                0,
            ),
            (
                Region {
                    origin: [0; 3],
                    size: [1, 1, 512],
                },
                0,
            ),
            (
                Region {
                    origin: [5, 6, 7],
                    size: [1; 3],
                },
                1,
            ),
        ];
        for (i, (r, lod)) in ordinary.iter().chain(&other).enumerate() {
            let e = t
                .estimate(&Request::region(*r).unwrap(), *lod, u64::MAX)
                .unwrap();
            let plan: u64 = t
                .plan(&Request::region(*r).unwrap(), *lod)
                .unwrap()
                .voxels_per_level
                .iter()
                .sum();
            assert!(e.complete);
            assert!(e.total >= plan, "{r:?} lod {lod}: {} < {plan}", e.total);
            if i < ordinary.len() {
                let factor = e.total as f64 / plan as f64;
                assert!(factor <= ORDINARY_FACTOR, "{r:?} lod {lod}: {factor:.2}×");
            }
        }
        let cuts = [
            (
                cut([0.0, 0.0, 0.5], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], 256),
                0,
            ),
            (cut([0.0; 3], [s, s, 0.0], [0.0, 0.0, 1.0], 256), 0),
            (cut([3.3, 1.2, 0.0], [s, 0.0, s], diag, 128), 0),
            (cut([3.3, 1.2, 0.0], [s, 0.0, s], diag, 128), 1),
            (cut([-7.0, 2.0, 9.0], [0.0, s, -s], diag, 100), 2),
            (cut([0.0; 3], [3.0, 0.0, 0.0], [0.0, 1.0, 0.0], 64), 0),
            (cut([0.0; 3], [40.0, 0.0, 1.0], [0.0, 1.0, 0.0], 32), 0),
            (cut([0.0; 3], [100.0, 0.0, 0.0], [0.0, 100.0, 3.0], 16), 0),
            (cut([0.0; 3], [0.3, 0.0, 0.1], [0.0, 0.25, 0.0], 80), 1),
        ];
        for (plane, lod) in cuts {
            for filter in [Filter::Nearest, Filter::Trilinear] {
                let e = t
                    .estimate(&Request::cut(plane, filter).unwrap(), lod, u64::MAX)
                    .unwrap();
                let plan: u64 = t
                    .plan(&Request::cut(plane, filter).unwrap(), lod)
                    .unwrap()
                    .voxels_per_level
                    .iter()
                    .sum();
                assert!(
                    e.total >= plan,
                    "{plane:?} lod {lod} {filter:?}: {} < {plan}",
                    e.total
                );
            }
        }
    }
}

#[test]
fn the_default_budget_admits_what_clients_ask_for() {
    let budget = ServeArgs::for_data_dir(".").max_request_work;
    let t = bundled_texture(SynthParams::default());
    let directions = [
        [1.0, 0.0, 0.0],
        [1.0, 1.0, 0.0],
        [1.0, 1.0, 1.0],
        [0.3, -0.9, 0.2],
    ];
    for lod in 0..=t.max_lod() {
        // The viewer's tiles (128², every lod) and the load test's and
        // benchmarks' slices and cuts (256², lod 0 and 1 there), on every
        // axis and oblique; bricks and regions of 64³.
        for side in [128, 256] {
            if side == 256 && lod > 1 {
                continue;
            }
            for axis in [Axis::X, Axis::Y, Axis::Z] {
                let r = Region::slice(axis, 7, -3, 5, side, side);
                let e = t
                    .estimate(&Request::region(r).unwrap(), lod, budget)
                    .unwrap();
                assert!(e.complete && e.total <= budget, "{r:?} lod {lod}: {e:?}");
            }
            for d in directions {
                let n = unit(d);
                let u = unit([n[1], -n[0], 0.0].map(|x| x + 1e-3));
                let v = [
                    n[1] * u[2] - n[2] * u[1],
                    n[2] * u[0] - n[0] * u[2],
                    n[0] * u[1] - n[1] * u[0],
                ];
                let plane = cut([10.5, -3.25, 7.0], u, v, side);
                for filter in [Filter::Nearest, Filter::Trilinear] {
                    let e = t
                        .estimate(&Request::cut(plane, filter).unwrap(), lod, budget)
                        .unwrap();
                    assert!(
                        e.complete && e.total <= budget,
                        "{plane:?} lod {lod}: {e:?}"
                    );
                }
            }
        }
        let brick = Region {
            origin: [64, 0, -128],
            size: [64; 3],
        };
        let e = t
            .estimate(&Request::region(brick).unwrap(), lod, budget)
            .unwrap();
        assert!(e.complete && e.total <= budget, "brick lod {lod}: {e:?}");
    }
}
