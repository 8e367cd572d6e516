//! Meshes textured from the solid: a baked texel shows exactly the voxel
//! the region route gives at its surface point; the glTF files are
//! well formed and read back; `solidtex bake` writes one; and broken,
//! empty, degenerate, oversized or absurdly placed meshes get a 4xx with a
//! clear message, never a panic. (Khronos' validator reads the files in
//! tests/clients/.)

mod common;
mod server_support;

use common::*;
use server_support::*;
use solidtex_core::mesh::{Bake, BakeOptions, Colours, Mesh, MeshFormat, Uvs};
use solidtex_core::{Filter, Region, Request};
use std::sync::Arc;

fn torus_obj() -> Vec<u8> {
    std::fs::read(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/fixtures/meshes/torus.obj"
    ))
    .unwrap()
}

fn torus() -> Arc<Mesh> {
    Arc::new(Mesh::parse(&torus_obj(), None).unwrap())
}

/// The voxel at integer position `p`, as the region route computes it.
fn voxel(tex: &solidtex_core::Texture, p: [i64; 3]) -> [u8; 3] {
    let r = Request::region(Region {
        origin: p,
        size: [1; 3],
    })
    .unwrap();
    let rgb = tex.render(&r, 0).unwrap().0;
    [rgb[0], rgb[1], rgb[2]]
}

#[test]
fn a_baked_texel_is_the_voxel_at_its_surface_point() {
    let tex = texture();
    for uvs in [Uvs::Atlas, Uvs::Mesh] {
        let mut options = BakeOptions::new(40);
        options.uvs = uvs;
        options.texture_size = Some(256);
        let bake = Bake::new(torus(), options).unwrap();
        assert_eq!(bake.uses_mesh_uvs(), uvs == Uvs::Mesh);
        let (rgb, stats) = tex
            .render(&Request::bake(bake.clone()).unwrap(), 0)
            .unwrap();
        assert_eq!(rgb.len(), 256 * 256 * 3);
        assert!(stats.voxels_per_level[0] > 0);
        let mut checked = 0;
        for i in (0..bake.items()).step_by(97) {
            let Some(p) = bake.sample(i) else { continue };
            // On the torus's surface, inside its box of 40 voxels.
            assert!(p.iter().all(|c| (-1e-9..=40.0 + 1e-9).contains(c)), "{p:?}");
            let v = voxel(&tex, p.map(|c| c.round() as i64));
            assert_eq!(&rgb[i * 3..i * 3 + 3], &v, "{uvs:?} texel {i} at {p:?}");
            checked += 1;
        }
        assert!(checked > 50, "{checked}");
    }
}

/// The guess a bake's progress is measured against stays near the exact
/// count of a cold synthesis, and the bound it is admitted under above it
/// but not far.
#[test]
fn a_bake_is_predicted_close_to_what_a_cold_cache_synthesizes() {
    let tex = texture();
    for resolution in [64, 128, 256] {
        let bake = Bake::new(torus(), BakeOptions::new(resolution)).unwrap();
        let request = Request::bake(bake).unwrap();
        let exact: u64 = tex.plan(&request, 0).unwrap().voxels_per_level.iter().sum();
        let guess = tex.predict(&request, 0).unwrap();
        let bound = tex.estimate(&request, 0, u64::MAX).unwrap().total;
        let ratio = guess as f64 / exact as f64;
        assert!(
            (0.8..=2.0).contains(&ratio),
            "{resolution}: {guess} against {exact}"
        );
        assert!(
            bound >= exact,
            "{resolution}: the bound {bound} under {exact}"
        );
    }
}

#[test]
fn vertex_colours_are_the_voxels_at_the_vertices_and_trilinear_stays_between() {
    let tex = texture();
    let mut options = BakeOptions::new(40);
    options.colours = Colours::Vertex;
    let bake = Bake::new(torus(), options).unwrap();
    let rgb = tex
        .render(&Request::bake(bake.clone()).unwrap(), 0)
        .unwrap()
        .0;
    assert_eq!(rgb.len(), bake.mesh().positions().len() * 3);
    for i in (0..bake.items()).step_by(37) {
        let p = bake.sample(i).unwrap();
        let v = voxel(&tex, p.map(|c| c.round() as i64));
        assert_eq!(&rgb[i * 3..i * 3 + 3], &v);
    }
    // Trilinear: each channel within the range of the eight voxels around.
    options.filter = Filter::Trilinear;
    let bake = Bake::new(torus(), options).unwrap();
    let rgb = tex
        .render(&Request::bake(bake.clone()).unwrap(), 0)
        .unwrap()
        .0;
    for i in (0..bake.items()).step_by(53) {
        let p = bake.sample(i).unwrap();
        let base = p.map(|c| c.floor() as i64);
        let corners: Vec<[u8; 3]> = (0..8)
            .map(|k| voxel(&tex, [0, 1, 2].map(|a| base[a] + ((k >> a) & 1))))
            .collect();
        for ch in 0..3 {
            let lo = corners.iter().map(|c| c[ch]).min().unwrap();
            let hi = corners.iter().map(|c| c[ch]).max().unwrap();
            assert!((lo..=hi).contains(&rgb[i * 3 + ch]), "{i} {ch}");
        }
    }
}

#[test]
fn the_glb_reads_back_with_its_texture_and_uvs() {
    let tex = texture();
    let mut options = BakeOptions::new(32);
    options.uvs = Uvs::Atlas;
    let bake = Bake::new(torus(), options).unwrap();
    let side = bake.texture_side().unwrap();
    let rgb = tex
        .render(&Request::bake(bake.clone()).unwrap(), 0)
        .unwrap()
        .0;
    let glb = bake.glb(&rgb).unwrap();
    // Our own reader takes it back: one vertex per triangle corner.
    let again = Mesh::parse(&glb, Some(MeshFormat::Glb)).unwrap();
    assert_eq!(again.triangles().len(), bake.mesh().triangles().len());
    let uvs = again.uvs().unwrap();
    assert!(uvs.iter().flatten().all(|c| (0.0..=1.0).contains(c)));
    // The embedded PNG is the texture rendered.
    let at = glb
        .windows(8)
        .position(|w| w == b"\x89PNG\r\n\x1a\n")
        .unwrap();
    let (w, h, png_rgb) = decode_png(&glb[at..]);
    assert_eq!((w, h), (side, side));
    assert_eq!(png_rgb, rgb);
    // Baking the baked mesh on its own UVs gives the same texels inside
    // the charts (rounding may move a sample across a voxel border).
    let mut same = BakeOptions::new(32);
    same.uvs = Uvs::Mesh;
    same.texture_size = Some(side);
    let tris: Vec<[[f32; 2]; 3]> = again
        .triangles()
        .iter()
        .map(|t| t.map(|k| uvs[k as usize].map(|c| c * side as f32)))
        .collect();
    let rebake = Bake::new(Arc::new(again), same).unwrap();
    let rgb2 = tex.render(&Request::bake(rebake).unwrap(), 0).unwrap().0;
    let (mut inside, mut equal) = (0, 0);
    for t in &tris {
        let lo = [0, 1].map(|a| t.iter().map(|p| p[a]).fold(f32::MAX, f32::min) as usize);
        let hi = [0, 1].map(|a| t.iter().map(|p| p[a]).fold(f32::MIN, f32::max) as usize);
        for y in lo[1]..=hi[1].min(side as usize - 1) {
            for x in lo[0]..=hi[0].min(side as usize - 1) {
                let c = [x as f32 + 0.5, y as f32 + 0.5];
                let edge = |a: [f32; 2], b: [f32; 2]| {
                    (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
                };
                let e = [edge(t[0], t[1]), edge(t[1], t[2]), edge(t[2], t[0])];
                if e.iter().all(|v| *v > 0.1) || e.iter().all(|v| *v < -0.1) {
                    let i = (y * side as usize + x) * 3;
                    inside += 1;
                    equal += usize::from(rgb[i..i + 3] == rgb2[i..i + 3]);
                }
            }
        }
    }
    assert!(inside > 3000, "{inside}");
    assert!(equal * 100 >= inside * 99, "{equal} of {inside}");
}

#[test]
fn the_command_line_bakes_a_glb() {
    let dir = tempfile::tempdir().unwrap();
    let mesh = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/fixtures/meshes/torus.obj"
    );
    let out = dir.path().join("torus.glb");
    solidtex(&[
        "bake",
        mesh,
        "--resolution",
        "48",
        "--texture-size",
        "256",
        "-o",
        out.to_str().unwrap(),
    ]);
    let glb = std::fs::read(&out).unwrap();
    assert_eq!(&glb[..4], b"glTF");
    let m = Mesh::parse(&glb, None).unwrap();
    assert_eq!(m.triangles().len(), 2304);
    // A fracture of two planes: four pieces, each a node.
    let out = dir.path().join("broken.glb");
    solidtex(&[
        "bake",
        mesh,
        "--resolution",
        "32",
        "--cut",
        "0,0,1,0.05",
        "--cut",
        "1,0,0,-0.2",
        "--spread",
        "0.05",
        "-o",
        out.to_str().unwrap(),
    ]);
    let glb = std::fs::read(&out).unwrap();
    let text = String::from_utf8_lossy(&glb[..4096]);
    assert!(
        text.contains("piece 3") && !text.contains("piece 4"),
        "{text}"
    );
}

/// Every broken mesh and absurd request answers 4xx JSON with a message.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_meshes_get_clear_errors() {
    let (_dir, s, c, id) = server_with_texture(3).await;
    let post = |query: &str, body: Vec<u8>| {
        let url = s.url(&format!("/v1/textures/{id}/bake?{query}"));
        let c = c.clone();
        async move {
            let r = c.post(url).body(body).send().await.unwrap();
            let status = r.status().as_u16();
            let headers = r.headers().clone();
            (status, headers, r.bytes().await.unwrap().to_vec())
        }
    };
    // A good bake first: the file is a glTF binary.
    let (status, headers, body) = post("resolution=24&texture_size=64", torus_obj()).await;
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&body));
    assert_eq!(headers["content-type"], "model/gltf-binary");
    assert!(headers.contains_key("etag"));
    let glb = body;
    let nan = b"v 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 3\n".to_vec();
    let flat = b"v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\nf 1 1 2\n".to_vec();
    let far = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n".to_vec();
    let mut huge = glb.clone();
    // The index accessor claims 30 M indices (10 M triangles).
    let json_len = u32::from_le_bytes(huge[12..16].try_into().unwrap()) as usize;
    let json = String::from_utf8(huge[20..20 + json_len].to_vec()).unwrap();
    let mut doc: serde_json::Value = serde_json::from_str(&json).unwrap();
    let indices = doc["meshes"][0]["primitives"][0]["indices"]
        .as_u64()
        .unwrap() as usize;
    doc["accessors"][indices]["count"] = serde_json::json!(30_000_000);
    let mut text = serde_json::to_vec(&doc).unwrap();
    while !text.len().is_multiple_of(4) {
        text.push(b' ');
    }
    let bin = huge.split_off(20 + json_len);
    let mut claimed = b"glTF".to_vec();
    claimed.extend(2u32.to_le_bytes());
    claimed.extend(((12 + 8 + text.len() + bin.len()) as u32).to_le_bytes());
    claimed.extend((text.len() as u32).to_le_bytes());
    claimed.extend(b"JSON");
    claimed.extend(&text);
    claimed.extend(&bin);
    for (what, query, body, want_status, want_code) in [
        (
            "truncated GLB",
            "",
            glb[..glb.len() / 2].to_vec(),
            400,
            "invalid_request",
        ),
        (
            "GLB header only",
            "",
            glb[..12].to_vec(),
            400,
            "invalid_request",
        ),
        ("empty body", "", Vec::new(), 400, "invalid_request"),
        ("NaN vertex", "", nan, 400, "invalid_request"),
        ("zero-area triangles only", "", flat, 400, "invalid_request"),
        ("index past the vertices", "", far, 400, "invalid_request"),
        (
            "text that is no mesh",
            "",
            b"hello\n".to_vec(),
            400,
            "invalid_request",
        ),
        ("10 M triangles claimed", "", claimed, 400, "too_large"),
        (
            "resolution 0",
            "resolution=0",
            torus_obj(),
            400,
            "out_of_range",
        ),
        (
            "resolution 10⁹",
            "resolution=1000000000",
            torus_obj(),
            400,
            "out_of_range",
        ),
        (
            "resolution 65536",
            "resolution=65536",
            torus_obj(),
            400,
            "over_budget",
        ),
        (
            "texture 8 texels",
            "texture_size=8",
            torus_obj(),
            400,
            "out_of_range",
        ),
        (
            "NaN offset",
            "offset=nan,0,0",
            torus_obj(),
            400,
            "invalid_parameter",
        ),
        (
            "mesh UVs of a mesh without",
            "uvs=mesh&format=obj",
            b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n".to_vec(),
            400,
            "invalid_parameter",
        ),
        (
            "a cut plane that misses the mesh",
            "cut=0,0,1,5",
            torus_obj(),
            400,
            "invalid_parameter",
        ),
        (
            "a cut plane with a zero normal",
            "cut=0,0,0,0",
            torus_obj(),
            400,
            "invalid_parameter",
        ),
        (
            "a cut plane of three numbers",
            "cut=0,0,1",
            torus_obj(),
            400,
            "invalid_parameter",
        ),
        (
            "nine cut planes",
            "cut=0,0,1,0;0,0,1,0;0,0,1,0;0,0,1,0;0,0,1,0;0,0,1,0;0,0,1,0;0,0,1,0;0,0,1,0",
            torus_obj(),
            400,
            "invalid_parameter",
        ),
        (
            "vertex colours of a cut",
            "cut=0,0,1,0&colours=vertex",
            torus_obj(),
            400,
            "invalid_parameter",
        ),
        (
            "spread 2",
            "cut=0,0,1,0&spread=2",
            torus_obj(),
            400,
            "out_of_range",
        ),
        (
            "spread x",
            "cut=0,0,1,0&spread=x",
            torus_obj(),
            400,
            "invalid_parameter",
        ),
    ] {
        let (status, headers, body) = post(query, body).await;
        assert!(
            status == want_status,
            "{what}: {status} {}",
            String::from_utf8_lossy(&body)
        );
        assert_error(status, &headers, &body, want_status, want_code);
        if want_code == "over_budget" {
            // The option that sets a bake's budget, not a slice's.
            let text = String::from_utf8_lossy(&body);
            assert!(text.contains("--max-export-work"), "{what}: {text}");
        }
    }
    // The server is still up and answers, a cut too: two pieces, two nodes.
    let (status, _, _) = post("resolution=16&texture_size=64", torus_obj()).await;
    assert_eq!(status, 200);
    let (status, _, glb) = post("resolution=16&cut=0,0,1,0&spread=0.1", torus_obj()).await;
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&glb));
    let text = String::from_utf8_lossy(&glb[..glb.len().min(4096)]);
    assert!(
        text.contains("piece 1") && !text.contains("piece 2"),
        "{text}"
    );
}

/// A torus cut across its hole (the plane through two of the fixture's
/// vertex rings, with texture seams to weld): two closed pieces with
/// annulus caps, and along the cut line the caps show the very voxels the
/// surface shows there.
#[test]
fn a_cut_caps_the_pieces_with_the_inside_of_the_solid() {
    let tex = texture();
    let cut = torus()
        .cut(&[solidtex_core::mesh::Plane::new([0.0, 0.0, 1.0], 0.0).unwrap()])
        .unwrap();
    assert_eq!(cut.pieces().len(), 2);
    let caps = (0..cut.triangles().len())
        .filter(|&t| cut.is_cap(t))
        .count();
    assert!(caps > 0);
    let mut options = BakeOptions::new(48);
    options.texture_size = Some(1024);
    let bake = Bake::new(Arc::new(cut), options).unwrap();
    assert!(!bake.uses_mesh_uvs());
    let rgb = tex
        .render(&Request::bake(bake.clone()).unwrap(), 0)
        .unwrap()
        .0;
    // The voxel each texel reads, cap texels and surface texels apart.
    let mut surface = std::collections::HashMap::new();
    let mut cap_texels = Vec::new();
    for i in 0..bake.items() {
        let (Some(t), Some(p)) = (bake.texel_triangle(i), bake.sample(i)) else {
            continue;
        };
        let v = p.map(|c| c.round() as i64);
        let colour = [rgb[i * 3], rgb[i * 3 + 1], rgb[i * 3 + 2]];
        if bake.mesh().is_cap(t) {
            // On the plane: half way up the box of 48 × 48 × 12.44 voxels.
            assert!((p[2] - 48.0 * 0.35 / 2.7).abs() < 1e-3, "{p:?}");
            cap_texels.push((v, colour));
        } else {
            surface.insert(v, colour);
        }
    }
    let along: Vec<_> = cap_texels
        .iter()
        .filter_map(|(v, c)| surface.get(v).map(|s| (c, s)))
        .collect();
    assert!(
        along.len() > 200,
        "{} cap texels on the cut line",
        along.len()
    );
    for (cap, surf) in &along {
        assert_eq!(cap, surf);
    }
    // Inside, the caps show the solid too: the voxels the region route gives.
    for (v, c) in cap_texels.iter().step_by(997) {
        assert_eq!(&voxel(&tex, *v), c, "{v:?}");
    }
    // Two nodes, and the pieces read back whole.
    let glb = bake.glb(&rgb).unwrap();
    let again = Mesh::parse(&glb, Some(MeshFormat::Glb)).unwrap();
    assert_eq!(again.triangles().len(), bake.mesh().triangles().len());
    let text = String::from_utf8_lossy(&glb[..4096]);
    assert!(text.contains("piece 1"), "{text}");
    // Vertex colours cannot show a cap, and a cut has no UVs of its own.
    for (colours, uvs) in [(Colours::Vertex, Uvs::Auto), (Colours::Texture, Uvs::Mesh)] {
        let mut o = BakeOptions::new(48);
        (o.colours, o.uvs) = (colours, uvs);
        assert!(Bake::new(Arc::new(bake.mesh().clone()), o).is_err());
    }
}

/// Through HTTP: at the middle of a triangle, the baked texture shows one
/// of the voxels around that point (the texel's own sample lies within a
/// texel of it), as the region route gives them.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_served_bake_agrees_with_the_region_route() {
    let (_dir, s, c, id) = server_with_texture(5).await;
    let r = c
        .post(s.url(&format!(
            "/v1/textures/{id}/bake?resolution=40&texture_size=512&uvs=atlas"
        )))
        .body(torus_obj())
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    let glb = r.bytes().await.unwrap().to_vec();
    let baked = Mesh::parse(&glb, Some(MeshFormat::Glb)).unwrap();
    let at = glb
        .windows(8)
        .position(|w| w == b"\x89PNG\r\n\x1a\n")
        .unwrap();
    let (side, _, rgb) = decode_png(&glb[at..]);
    // Placement: the torus's box [-1.35, 1.35]² × [-0.35, 0.35] scaled so
    // that 2.7 spans 40 voxels, its lowest corner at the origin.
    let p = baked.positions();
    let lo = [0, 1, 2].map(|a| p.iter().map(|v| v[a]).fold(f32::MAX, f32::min) as f64);
    let scale = 40.0
        / (0..3)
            .map(|a| p.iter().map(|v| v[a] as f64).fold(f64::MIN, f64::max) - lo[a])
            .fold(0.0, f64::max);
    let uvs = baked.uvs().unwrap();
    let mut matched = 0;
    let tris = baked.triangles();
    for t in tris.iter().step_by(tris.len() / 24) {
        let centre = [0, 1, 2].map(|a| {
            t.iter()
                .map(|&k| (p[k as usize][a] as f64 - lo[a]) * scale)
                .sum::<f64>()
                / 3.0
        });
        let uv = [0, 1].map(|a| t.iter().map(|&k| uvs[k as usize][a]).sum::<f32>() / 3.0);
        let texel = [0, 1].map(|a| (uv[a] * side as f32) as usize);
        let i = (texel[1] * side as usize + texel[0]) * 3;
        let base = centre.map(|c| c.round() as i64 - 1);
        let url = s.url(&format!(
            "/v1/textures/{id}/region.raw?x={}&y={}&z={}&w=3&h=3&d=3",
            base[0], base[1], base[2]
        ));
        let (status, _, around) = get(&c, &url).await;
        assert_eq!(status, 200);
        if around.chunks_exact(3).any(|v| v == &rgb[i..i + 3]) {
            matched += 1;
        }
    }
    assert!(matched >= 24, "{matched} of 25 triangle centres");
}

/// The torus as a PLY: ASCII, or binary little- or big-endian, with a
/// comment, texture coordinates, an extra element and int or uchar counts.
fn torus_ply(encoding: &str) -> Vec<u8> {
    let m = torus();
    let (p, t, uv) = (m.positions(), m.triangles(), m.uvs().unwrap());
    let mut out = format!(
        "ply\nformat {encoding} 1.0\ncomment torus\nelement vertex {}\n\
         property float x\nproperty float y\nproperty float z\n\
         property float s\nproperty float t\n\
         element face {}\nproperty list uchar int vertex_indices\n\
         element edge 1\nproperty int vertex1\nproperty int vertex2\nend_header\n",
        p.len(),
        t.len()
    )
    .into_bytes();
    let big = encoding == "binary_big_endian";
    let f = |out: &mut Vec<u8>, v: f32| {
        out.extend(if big {
            v.to_be_bytes()
        } else {
            v.to_le_bytes()
        })
    };
    let i = |out: &mut Vec<u8>, v: i32| {
        out.extend(if big {
            v.to_be_bytes()
        } else {
            v.to_le_bytes()
        })
    };
    for (k, q) in p.iter().enumerate() {
        let (s, tt) = (uv[k][0], 1.0 - uv[k][1]);
        if encoding == "ascii" {
            out.extend(format!("{} {} {} {s} {tt}\n", q[0], q[1], q[2]).bytes());
        } else {
            for c in [q[0], q[1], q[2], s, tt] {
                f(&mut out, c);
            }
        }
    }
    for tri in t {
        if encoding == "ascii" {
            out.extend(format!("3 {} {} {}\n", tri[0], tri[1], tri[2]).bytes());
        } else {
            out.push(3);
            for &c in tri {
                i(&mut out, c as i32);
            }
        }
    }
    if encoding == "ascii" {
        out.extend(b"0 1\n");
    } else {
        i(&mut out, 0);
        i(&mut out, 1);
    }
    out
}

#[test]
fn ply_meshes_read_as_their_obj_does_and_bad_ones_are_refused() {
    let obj = torus();
    for encoding in ["ascii", "binary_little_endian", "binary_big_endian"] {
        let bytes = torus_ply(encoding);
        assert_eq!(MeshFormat::sniff(&bytes), MeshFormat::Ply);
        let m = Mesh::parse(&bytes, None).unwrap();
        assert_eq!(m.triangles(), obj.triangles(), "{encoding}");
        assert_eq!(m.positions(), obj.positions(), "{encoding}");
        assert_eq!(m.uvs(), obj.uvs(), "{encoding}");
    }
    let good = torus_ply("binary_little_endian");
    let header_end = good.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
    let ascii = String::from_utf8(torus_ply("ascii")).unwrap();
    let bad: Vec<(&str, Vec<u8>, &str)> = vec![
        ("truncated binary", good[..good.len() / 2].to_vec(), "invalid_request"),
        ("header only", good[..header_end].to_vec(), "invalid_request"),
        (
            "10 M faces claimed",
            String::from_utf8_lossy(&good[..header_end])
                .replace("element face 2304", "element face 10000000")
                .into_bytes(),
            "too_large",
        ),
        (
            "2^60 vertices claimed",
            ascii.replace("element vertex 1225", "element vertex 1152921504606846976").into_bytes(),
            "invalid_request",
        ),
        (
            "NaN vertex",
            ascii.replacen("\n1.35 0 0 ", "\nnan 0 0 ", 1).into_bytes(),
            "invalid_request",
        ),
        (
            "index past the vertices",
            ascii.replacen("\n3 0 ", "\n3 99999 ", 1).into_bytes(),
            "invalid_request",
        ),
        (
            "negative index",
            ascii.replacen("\n3 0 ", "\n3 -1 ", 1).into_bytes(),
            "invalid_request",
        ),
        (
            "no z",
            ascii.replacen("property float z\n", "", 1).into_bytes(),
            "invalid_request",
        ),
        ("no faces", b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n".to_vec(), "invalid_request"),
        ("not PLY at all", b"ply\nhello\n".to_vec(), "invalid_request"),
    ];
    for (what, bytes, code) in bad {
        let e = Mesh::parse(&bytes, None).expect_err(what);
        let got = match e {
            solidtex_core::Error::TooLarge(_) => "too_large",
            solidtex_core::Error::InvalidRequest(_) => "invalid_request",
            ref other => panic!("{what}: {other:?}"),
        };
        assert_eq!(got, code, "{what}: {e}");
    }
}
