//! Region textures (Zhang et al. 2011, Fig. 15): a second solid inside a
//! region, the first outside, mixed across a band. Away from the band a
//! voxel is exactly the outer or the inner solid's; the band mixes them
//! monotonically; every request shape and thread count gives the same
//! bytes; a request away from the region synthesizes nothing of the inner
//! solid; a baked mesh with a shell region shows the outer solid on its
//! surface and the inner one in its caps below the shell (Zhang's bark
//! and wood); over HTTP a region texture is created, served by the voxel
//! routes, kept across a restart, and protects what it is made of.

mod common;
mod server_support;

use common::*;
use serde_json::json;
use server_support::*;
use solidtex_core::mesh::{Bake, BakeOptions, Mesh, Plane};
use solidtex_core::region::{Shape, Split};
use solidtex_core::{
    Axis, CutPlane, Error, Filter, Region, Request, SynthParams, Texture, TileCache, Window,
};
use std::sync::Arc;

/// The outer solid, and an inner one (another seed) over a cache of its
/// own, so that what it synthesized can be counted.
fn solids() -> (Texture, Texture, Arc<TileCache>) {
    let outer = texture();
    let cache = Arc::new(TileCache::new(256 << 20));
    let params = SynthParams {
        seed: 77,
        ..SynthParams::default()
    };
    let inner = Texture::new(small_candidates(), params, cache.clone()).unwrap();
    (outer, inner, cache)
}

fn sphere(radius: f64, band: f64) -> Split {
    Split {
        region: format!("sphere:0,0,0,{radius}").parse().unwrap(),
        band,
    }
}

fn slice(tex: &Texture, at: i64, u0: i64, side: u32) -> Vec<u8> {
    let r = Request::slice(Axis::Z, at, Window::new(u0, u0, side, side)).unwrap();
    tex.render(&r, 0).unwrap().0
}

#[test]
fn away_from_the_band_a_voxel_is_one_solid_and_the_band_mixes_monotonically() {
    let (outer, inner, _) = solids();
    let (radius, band) = (24.0, 8.0);
    let tex = Texture::with_region(outer.clone(), inner.clone(), sphere(radius, band)).unwrap();
    let side = 64u32;
    let (o, i, t) = (
        slice(&outer, 0, -32, side),
        slice(&inner, 0, -32, side),
        slice(&tex, 0, -32, side),
    );
    let (mut outside, mut inside, mut mixed) = (0, 0, 0);
    // Weight of the inner solid, estimated per band pixel, by distance.
    let mut by_distance: Vec<(f64, f64)> = Vec::new();
    for y in 0..side as i64 {
        for x in 0..side as i64 {
            let k = ((y * side as i64 + x) * 3) as usize;
            let p = [(x - 32) as f64, (y - 32) as f64];
            let d = (p[0] * p[0] + p[1] * p[1]).sqrt() - radius;
            let (a, b, c) = (&o[k..k + 3], &i[k..k + 3], &t[k..k + 3]);
            if d >= band / 2.0 {
                assert_eq!(c, a, "outside at {p:?}");
                outside += 1;
            } else if d <= -band / 2.0 {
                assert_eq!(c, b, "inside at {p:?}");
                inside += 1;
            } else {
                mixed += 1;
                for ch in 0..3 {
                    let (lo, hi) = (a[ch].min(b[ch]), a[ch].max(b[ch]));
                    assert!(lo.saturating_sub(1) <= c[ch] && c[ch] <= hi.saturating_add(1));
                }
                let diff: Vec<f64> = (0..3)
                    .map(|ch| f64::from(b[ch]) - f64::from(a[ch]))
                    .collect();
                let len2: f64 = diff.iter().map(|v| v * v).sum();
                if len2 > 60.0 * 60.0 {
                    let along: f64 = (0..3)
                        .map(|ch| (f64::from(c[ch]) - f64::from(a[ch])) * diff[ch])
                        .sum();
                    by_distance.push((d, along / len2));
                }
            }
        }
    }
    assert!(
        outside > 1000 && inside > 1000 && mixed > 100,
        "{outside} {inside} {mixed}"
    );
    // Deeper in the band, more of the inner solid: the mean weight of each
    // quarter of the band grows inwards.
    let mut means = Vec::new();
    for q in 0..4 {
        let lo = band / 2.0 - f64::from(q + 1) * band / 4.0;
        let ws: Vec<f64> = by_distance
            .iter()
            .filter(|(d, _)| *d >= lo && *d < lo + band / 4.0)
            .map(|&(_, w)| w)
            .collect();
        assert!(ws.len() > 5, "quarter {q}: {} pixels", ws.len());
        means.push(ws.iter().sum::<f64>() / ws.len() as f64);
    }
    assert!(means.windows(2).all(|m| m[0] < m[1]), "{means:?}");
    assert!(means[0] < 0.25 && means[3] > 0.75, "{means:?}");
}

#[test]
fn a_hard_boundary_takes_each_voxel_from_one_solid() {
    let (outer, inner, _) = solids();
    let split = Split {
        region: "half_space:0,0,0,1,0,0".parse().unwrap(),
        band: 0.0,
    };
    let tex = Texture::with_region(outer.clone(), inner.clone(), split).unwrap();
    let (o, i, t) = (
        slice(&outer, 3, -16, 32),
        slice(&inner, 3, -16, 32),
        slice(&tex, 3, -16, 32),
    );
    for k in 0..32 * 32 {
        let x = (k % 32) as i64 - 16;
        let want = if x < 0 { &i } else { &o };
        assert_eq!(&t[k * 3..k * 3 + 3], &want[k * 3..k * 3 + 3], "x = {x}");
    }
}

#[test]
fn every_request_shape_and_thread_count_gives_the_same_bytes() {
    let (outer, inner, _) = solids();
    let split = Split {
        region: "box:4,0,0,10,12,30,4".parse().unwrap(),
        band: 6.0,
    };
    let region = Region {
        origin: [-12, -16, -2],
        size: [32, 32, 4],
    };
    let run = |threads| {
        with_threads(threads, || {
            // A fresh pair each time: nothing cached in between.
            let (outer, inner, _) = solids();
            let tex = Texture::with_region(outer, inner, split.clone()).unwrap();
            tex.render(&Request::region(region).unwrap(), 0).unwrap().0
        })
    };
    let one = run(1);
    assert_eq!(one, run(2));
    let tex = Texture::with_region(outer, inner, split).unwrap();
    let n = 32 * 32 * 3;
    for z in 0..4 {
        let s = tex
            .render(
                &Request::slice(Axis::Z, z - 2, Window::new(-12, -16, 32, 32)).unwrap(),
                0,
            )
            .unwrap()
            .0;
        assert_eq!(s, one[z as usize * n..(z as usize + 1) * n], "slice {z}");
    }
    let mut points: Vec<[i64; 3]> = region.voxels().collect();
    points.reverse();
    let p = tex
        .render(&Request::points(points.clone()).unwrap(), 0)
        .unwrap()
        .0;
    let n_all = points.len();
    for j in 0..n_all {
        let i = n_all - 1 - j;
        assert_eq!(p[j * 3..j * 3 + 3], one[i * 3..i * 3 + 3]);
    }
    // An axis-aligned cut through voxel centres reads them, nearest or
    // trilinear.
    for filter in [Filter::Nearest, Filter::Trilinear] {
        let plane = CutPlane {
            origin: [-12.0, -16.0, 1.0],
            u: [1.0, 0.0, 0.0],
            v: [0.0, 1.0, 0.0],
            width: 32,
            height: 32,
        };
        let c = tex
            .render(&Request::cut(plane, filter).unwrap(), 0)
            .unwrap()
            .0;
        assert_eq!(c, one[3 * n..4 * n], "{filter:?}");
    }
    // A coarser level mixes at the level's own voxel centres.
    let coarse = Request::slice(Axis::Z, 0, Window::new(-8, -8, 16, 16)).unwrap();
    assert_eq!(
        tex.render(&coarse, 1).unwrap().0,
        tex.render(&coarse, 1).unwrap().0
    );
}

#[test]
fn a_request_away_from_the_region_synthesizes_nothing_of_the_inner_solid() {
    let (outer, inner, inner_cache) = solids();
    let tex = Texture::with_region(outer.clone(), inner, sphere(10.0, 4.0)).unwrap();
    // Far outside: not one inner tile, and the outer solid's bytes.
    let far = Request::slice(Axis::Z, 0, Window::new(40, 40, 64, 64)).unwrap();
    let (rgb, stats) = tex.render(&far, 0).unwrap();
    assert_eq!(inner_cache.stats().entries, 0);
    assert!(stats.tiles_computed > 0);
    assert_eq!(rgb, outer.render(&far, 0).unwrap().0);
    // The plan and the estimate count the outer solid alone.
    let alone = texture_with(SynthParams::default(), 1 << 20);
    assert_eq!(
        tex.plan(&far, 0).unwrap().voxels_per_level,
        alone.plan(&far, 0).unwrap().voxels_per_level
    );
    // Across the sphere, the inner solid is synthesized only near it: far
    // fewer of its voxels than the slice alone would need.
    let across = Request::slice(Axis::Z, 0, Window::new(-64, -64, 128, 128)).unwrap();
    let mixed = tex.plan(&across, 0).unwrap();
    let whole = alone.plan(&across, 0).unwrap();
    let finest = |s: &solidtex_core::SynthStats| s.voxels_per_level[0];
    assert!(finest(&mixed) > finest(&whole), "both solids are read");
    assert!(
        finest(&mixed) < finest(&whole) * 3 / 2,
        "{mixed:?} {whole:?}"
    );
    tex.render(&across, 0).unwrap();
    assert!(inner_cache.stats().entries > 0);
}

#[test]
fn bad_regions_and_nesting_are_refused() {
    let (outer, inner, _) = solids();
    let shell = Split {
        region: "shell:4".parse().unwrap(),
        band: 2.0,
    };
    let tex = Texture::with_region(outer.clone(), inner.clone(), shell).unwrap();
    let s = Request::slice(Axis::Z, 0, Window::new(0, 0, 8, 8)).unwrap();
    assert!(matches!(tex.render(&s, 0), Err(Error::InvalidRequest(_))));
    assert!(matches!(
        tex.estimate(&s, 0, 1 << 30),
        Err(Error::InvalidRequest(_))
    ));
    let bad = Split {
        region: Shape::Sphere {
            centre: [0.0; 3],
            radius: 4.0,
        },
        band: -1.0,
    };
    assert!(matches!(
        Texture::with_region(outer.clone(), inner.clone(), bad),
        Err(Error::InvalidRange { name: "band", .. })
    ));
    // Nested up to the limit, not beyond.
    let mut t = outer.clone();
    for depth in 1..=solidtex_core::region::MAX_DEPTH + 1 {
        let next = Texture::with_region(t.clone(), inner.clone(), sphere(8.0 * depth as f64, 2.0));
        if depth > solidtex_core::region::MAX_DEPTH {
            assert!(next.is_err());
        } else {
            t = next.unwrap();
        }
    }
    // A nested texture reads like any other.
    let (rgb, _) = t.render(&s, 0).unwrap();
    assert_eq!(rgb.len(), 8 * 8 * 3);
    let periodic = texture_with(
        SynthParams {
            period: Some([64; 3]),
            ..SynthParams::default()
        },
        1 << 20,
    );
    assert!(Texture::with_region(periodic, inner, sphere(8.0, 0.0)).is_err());
}

fn cut_torus(resolution: u32) -> Bake {
    let obj = std::fs::read(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/fixtures/meshes/torus.obj"
    ))
    .unwrap();
    let cut = Mesh::parse(&obj, None)
        .unwrap()
        .cut(&[Plane::new([0.0, 0.0, 1.0], 0.0).unwrap()])
        .unwrap();
    let mut options = BakeOptions::new(resolution);
    options.texture_size = Some(1024);
    Bake::new(Arc::new(cut), options).unwrap()
}

/// Zhang et al.'s Fig. 15 as a test: the surface of a cut torus shows the
/// outer solid exactly, its caps the inner one deeper than the shell and
/// the outer one above it.
#[test]
fn a_shell_region_shows_the_inner_solid_in_the_caps_below_its_depth() {
    let (outer, inner, _) = solids();
    let (thickness, band) = (4.0, 2.0);
    let split = Split {
        region: Shape::Shell { thickness },
        band,
    };
    let tex = Texture::with_region(outer.clone(), inner.clone(), split).unwrap();
    let bake = cut_torus(96);
    let request = Request::bake(bake.clone()).unwrap();
    let rgb = tex.render(&request, 0).unwrap().0;
    let plain = outer.render(&request, 0).unwrap().0;
    let within = inner.render(&request, 0).unwrap().0;
    let (mut surface, mut caps) = (Vec::new(), Vec::new());
    for i in 0..bake.items() {
        let (Some(t), Some(p)) = (bake.texel_triangle(i), bake.sample(i)) else {
            continue;
        };
        if bake.mesh().is_cap(t) {
            caps.push((i, p));
        } else {
            // The surface is the outer solid's, byte for byte.
            assert_eq!(rgb[i * 3..i * 3 + 3], plain[i * 3..i * 3 + 3], "texel {i}");
            surface.push(p);
        }
    }
    // A cap texel's depth, from the surface's own sample points (dense:
    // about a texel apart, so within a voxel of the true depth).
    let depth = |p: [f64; 3]| {
        surface
            .iter()
            .map(|q| (0..3).map(|a| (p[a] - q[a]).powi(2)).sum::<f64>())
            .fold(f64::MAX, f64::min)
            .sqrt()
    };
    let (mut deep, mut shallow) = (0, 0);
    for &(i, p) in caps.iter().step_by(13) {
        let d = depth(p);
        let got = &rgb[i * 3..i * 3 + 3];
        if d > thickness + band / 2.0 + 1.5 {
            assert_eq!(
                got,
                &within[i * 3..i * 3 + 3],
                "deep cap texel {i} at {p:?}"
            );
            deep += 1;
        } else if d < thickness - band / 2.0 - 1.5 {
            assert_eq!(
                got,
                &plain[i * 3..i * 3 + 3],
                "shallow cap texel {i} at {p:?}"
            );
            shallow += 1;
        }
    }
    assert!(
        deep > 100 && shallow > 100,
        "{deep} deep, {shallow} shallow"
    );
    // The plan counts both solids, each only where it is read.
    let planned = tex.plan(&request, 0).unwrap();
    assert!(planned.voxels_per_level[0] > outer.plan(&request, 0).unwrap().voxels_per_level[0]);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn region_textures_over_http() {
    let dir = tempfile::tempdir().unwrap();
    let s = TestServer::start(test_args(dir.path())).await;
    let c = client();
    let a = ready_texture(&c, &s, 1).await;
    let b = ready_texture(&c, &s, 2).await;
    let textures = s.url("/v1/textures");
    let def = json!({
        "outer": a, "inner": b, "band": 4,
        "region": {"shape": "sphere", "centre": [0, 0, 0], "radius": 12},
    });
    let (status, v) = post_body(&c, &textures, "application/json", def.to_string()).await;
    assert_eq!(status, 201, "{v}");
    let id = v["id"].as_str().unwrap().to_string();
    assert!(id.starts_with("region-"), "{id}");
    assert_eq!(v["kind"], "region");
    // The same definition spelled otherwise is the same texture.
    let again = format!(
        r#"{{"region":{{"radius":12.0,"centre":[0,-0.0,0],"shape":"sphere"}},"band":4.0,"inner":"{b}","outer":"{a}"}}"#
    );
    let (status, v) = post_body(&c, &textures, "application/json", again).await;
    assert_eq!((status, v["id"].as_str()), (201, Some(id.as_str())));
    assert_eq!(
        get_json(&c, &s, &format!("/v1/textures/{id}")).await["outer"],
        a
    );
    let listed = get_json(&c, &s, "/v1/textures").await;
    assert_eq!(listed["regions"][0]["id"], id.as_str());

    // Far from the sphere the slice is the outer texture's, inside the
    // inner's; across it, neither.
    let slice = |t: &str, u0: i64| {
        s.url(&format!(
            "/v1/textures/{t}/slices/z/0.png?u0={u0}&v0={u0}&w=8&h=8"
        ))
    };
    let png = |url: String| {
        let c = c.clone();
        async move {
            let (status, _, body) = get(&c, &url).await;
            assert_eq!(status, 200, "{url}: {}", String::from_utf8_lossy(&body));
            body
        }
    };
    assert_eq!(png(slice(&id, 40)).await, png(slice(&a, 40)).await);
    assert_eq!(png(slice(&id, -4)).await, png(slice(&b, -4)).await);
    let across = png(slice(&id, 6)).await;
    assert_ne!(across, png(slice(&a, 6)).await);
    assert_ne!(across, png(slice(&b, 6)).await);
    let raw = |t: &str| {
        s.url(&format!(
            "/v1/textures/{t}/region.raw?x=-2&y=-2&z=-2&w=4&h=4&d=4"
        ))
    };
    let (status, _, inside) = get(&c, &raw(&id)).await;
    assert_eq!(status, 200);
    assert_eq!(inside, get(&c, &raw(&b)).await.2);
    let brick = s.url(&format!("/v1/textures/{id}/bricks/0/4_4_4.raw"));
    assert_eq!(get(&c, &brick).await.0, 200, "{brick}");

    // Bad definitions get 4xx, and nothing is stored for them.
    let bad = |body: serde_json::Value| {
        let c = c.clone();
        let url = textures.clone();
        async move { post_body(&c, &url, "application/json", body.to_string()).await }
    };
    let sphere = json!({"shape": "sphere", "centre": [0, 0, 0], "radius": 4});
    for (body, want, code) in [
        (
            json!({"outer": "nope", "inner": b, "region": sphere}),
            404,
            "unknown_texture",
        ),
        (
            json!({"outer": a, "inner": b, "region": sphere, "band": -1}),
            400,
            "out_of_range",
        ),
        (
            json!({"outer": a, "inner": b, "region": {"shape": "sphere", "centre": [0, 0, 0], "radius": 0}}),
            400,
            "out_of_range",
        ),
        (
            json!({"outer": a, "inner": b, "region": {"shape": "cube", "side": 3}}),
            400,
            "invalid_region",
        ),
        (
            json!({"outer": a, "inner": b, "region": sphere, "colour": 1}),
            400,
            "invalid_region",
        ),
        (
            json!({"outer": a, "inner": b, "region": {"shape": "half_space", "point": [0, 0, 0], "normal": [0, 0, 0]}}),
            400,
            "invalid_parameter",
        ),
    ] {
        let (status, v) = bad(body.clone()).await;
        assert_eq!(
            (status, v["error"]["code"].as_str()),
            (want, Some(code)),
            "{body}: {v}"
        );
    }
    assert_eq!(
        get_json(&c, &s, "/v1/textures").await["regions"]
            .as_array()
            .unwrap()
            .len(),
        1
    );
    // A shell needs a mesh: the slice routes say so.
    let shell = json!({"outer": a, "inner": b, "region": {"shape": "shell", "thickness": 3}});
    let (status, v) = bad(shell).await;
    assert_eq!(status, 201, "{v}");
    let shell_id = v["id"].as_str().unwrap().to_string();
    let (status, headers, body) = get(&c, &slice(&shell_id, 0)).await;
    assert_error(status, &headers, &body, 400, "invalid_request");
    // Nested: a region texture made of a region texture.
    let nested = json!({"outer": id, "inner": a, "region": {"shape": "half_space", "point": [0, 0, 0], "normal": [1, 0, 0]}});
    let (status, v) = bad(nested).await;
    assert_eq!(status, 201, "{v}");
    let nested_id = v["id"].as_str().unwrap().to_string();
    assert_eq!(png(slice(&nested_id, 40)).await, png(slice(&a, 40)).await);

    // What a region texture uses cannot go before it does.
    let (status, headers, body) = {
        let r = c
            .delete(s.url(&format!("/v1/textures/{b}")))
            .send()
            .await
            .unwrap();
        let status = r.status().as_u16();
        let headers = r.headers().clone();
        (status, headers, r.bytes().await.unwrap().to_vec())
    };
    assert_error(status, &headers, &body, 409, "texture_in_use");
    assert!(String::from_utf8_lossy(&body).contains(&id));
    assert_eq!(delete(&c, &s.url(&format!("/v1/textures/{id}"))).await, 409);
    assert_eq!(
        delete(&c, &s.url(&format!("/v1/textures/{shell_id}"))).await,
        204
    );

    // A restart keeps the region textures, and their bytes.
    let before = png(slice(&nested_id, 6)).await;
    s.stop().await;
    let s = TestServer::start(test_args(dir.path())).await;
    let after = {
        let url = s.url(&format!(
            "/v1/textures/{nested_id}/slices/z/0.png?u0=6&v0=6&w=8&h=8"
        ));
        get(&c, &url).await
    };
    assert_eq!((after.0, after.2), (200, before));
    let listed = get_json(&c, &s, "/v1/textures").await;
    assert_eq!(listed["regions"].as_array().unwrap().len(), 2, "{listed}");
    for t in [&nested_id, &id, &b] {
        assert_eq!(
            delete(&c, &s.url(&format!("/v1/textures/{t}"))).await,
            204,
            "{t}"
        );
    }
    assert_eq!(get(&c, &s.url(&format!("/v1/textures/{id}"))).await.0, 404);
    s.stop().await;
}
