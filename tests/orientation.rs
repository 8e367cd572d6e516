//! Anisotropic exemplars: which real exemplars are detected as oriented,
//! and what turning and weighting planes changes and what it leaves alone.

mod common;

use common::*;
use solidtex_core::{
    AnalysisParams, Arrangement, Candidates, Exemplar, ExemplarSet, Orientation, Region, Request,
    SynthParams, Texture, TileCache,
};
use solidtex_core::{Grain, Layout};
use std::sync::Arc;

fn candidates(e: &Exemplar, orientation: Orientation) -> Arc<Candidates> {
    let params = AnalysisParams {
        orientation,
        ..small_params()
    };
    Arc::new(Candidates::compute(&ExemplarSet::single(e.clone()), &params, &|_, _| {}).unwrap())
}

fn voxels(c: &Arc<Candidates>) -> Vec<u8> {
    let t = Texture::new(
        c.clone(),
        SynthParams::default(),
        Arc::new(TileCache::new(64 << 20)),
    )
    .unwrap();
    let region = Region {
        origin: [3, -5, 7],
        size: [12, 10, 6],
    };
    t.render(&Request::region(region).unwrap(), 0).unwrap().0
}

const TURNED: Arrangement = Arrangement {
    rotate: [0, 270, 0],
    weights: [1.0, 1.0, 0.25],
};

#[test]
fn the_grain_of_wood_and_leather_is_detected_and_leopard_and_marble_are_not() {
    for (name, e, grain_along_u) in [
        ("wood_wood5", exemplar("wood_wood5.png"), true),
        ("animal_leather", exemplar("animal_leather.png"), true),
        ("animal_leopard", exemplar("animal_leopard.png"), false),
        (
            "stone_pink_marble",
            solidtex_core::bundled::exemplar(),
            false,
        ),
    ] {
        let g = Grain::measure(&e);
        let layout = Layout::resolve(&ExemplarSet::single(e), &Orientation::Auto).unwrap();
        assert_eq!(g.axis() == Some(0), grain_along_u, "{name}: {g:?}");
        assert_eq!(layout.detected, grain_along_u, "{name}");
        let want = if grain_along_u {
            TURNED
        } else {
            Arrangement::default()
        };
        assert_eq!(layout.arrangement, want, "{name}");
    }
}

#[test]
fn auto_leaves_an_exemplar_without_grain_as_it_is() {
    let e = small_exemplar();
    let auto = candidates(&e, Orientation::Auto);
    assert!(!auto.layout().detected);
    assert!(auto.analysed().is_single());
    assert_eq!(voxels(&auto), voxels(&candidates(&e, Orientation::None)));
}

#[test]
fn turned_planes_synthesize_deterministically_and_differently() {
    let e = small_exemplar();
    let turned = |threads| {
        with_threads(threads, || {
            let c = candidates(&e, Orientation::Given(TURNED));
            (c.to_bytes(), voxels(&c))
        })
    };
    let (bytes, vox) = turned(1);
    assert_eq!(turned(3), (bytes.clone(), vox.clone()));
    let c = Candidates::load(&bytes).unwrap();
    // The plane's own exemplar is turned; the file keeps the one given.
    assert_eq!(c.analysed().plane(1), &e.rotated(270));
    assert_eq!(c.analysed().plane(2), &e);
    assert_eq!(c.exemplars(), &ExemplarSet::single(e.clone()));
    assert_eq!(voxels(&Arc::new(c)), vox);
    assert_ne!(vox, voxels(&candidates(&e, Orientation::None)));
    // The weights alone change the voxels too.
    let even = Arrangement {
        weights: [1.0; 3],
        ..TURNED
    };
    assert_ne!(vox, voxels(&candidates(&e, Orientation::Given(even))));
}
