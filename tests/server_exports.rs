//! Exports: `solidtex export` and `GET /v1/textures/{id}/export` write the
//! same bytes in every format; the files hold the texture's voxels; the
//! asynchronous form reports progress and serves the same file; and
//! exports past each limit are refused with clear errors, tested at and
//! past the limit. (Tools that are not ours read the files in
//! tests/clients/.)

mod common;
mod server_support;

use common::*;
use serde_json::Value;
use server_support::*;
use std::time::{Duration, Instant};

/// A server whose texture is the bundled exemplar with period 64 (its
/// candidates ship with the binary: ready at once).
async fn periodic_server(
    configure: impl FnOnce(&mut solidtex_server::ServeArgs),
) -> (tempfile::TempDir, TestServer, reqwest::Client, String) {
    let dir = tempfile::tempdir().unwrap();
    let mut args = test_args(dir.path());
    args.max_upload_bytes = 1 << 20;
    configure(&mut args);
    let s = TestServer::start(args).await;
    let c = client();
    let png = solidtex_core::bundled::EXEMPLAR_PNG.to_vec();
    let (status, v) = upload(&c, &s, png, "period=64").await;
    assert!(status == 201 || status == 202, "{status} {v}");
    let id = v["id"].as_str().unwrap().to_string();
    wait_ready(&c, &s, &id).await;
    (dir, s, c, id)
}

fn cli_export(dir: &std::path::Path, args: &[&str]) -> (Vec<u8>, Option<Vec<u8>>) {
    let out = dir.join(format!("cli-{}", args.join("_").replace([',', '/'], "-")));
    let out = out.with_extension("bin");
    let mut all = vec!["export", "--period", "64"];
    all.extend_from_slice(args);
    all.extend_from_slice(&["-o", out.to_str().unwrap()]);
    solidtex(&all);
    let sidecar = std::fs::read(out.with_extension("json")).ok();
    (std::fs::read(&out).unwrap(), sidecar)
}

/// Every format, one period and a box, sRGB and linear, both mip chains:
/// the server's bytes are the command line's, and the sidecars too.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_server_and_the_command_line_write_the_same_files() {
    let (dir, s, c, id) = periodic_server(|_| {}).await;
    for (query, args) in [
        ("format=ktx2", vec!["--format", "ktx2"]),
        (
            "format=ktx2&mips=levels&colour=linear&lod=1",
            vec![
                "--format", "ktx2", "--mips", "levels", "--linear", "--lod", "1",
            ],
        ),
        ("format=atlas", vec!["--format", "atlas"]),
        (
            "format=nrrd&x=-5&y=7&z=100&w=20&h=9&d=3",
            vec!["--format", "nrrd", "--box", "-5,7,100,20,9,3"],
        ),
        (
            "format=raw&box=period&lod=2",
            vec!["--format", "raw", "--lod", "2"],
        ),
    ] {
        let (status, headers, body) =
            get(&c, &s.url(&format!("/v1/textures/{id}/export?{query}"))).await;
        assert_eq!(status, 200, "{query}: {}", String::from_utf8_lossy(&body));
        let (cli, sidecar) = cli_export(dir.path(), &args);
        assert!(
            body == cli,
            "{query}: the server's {} bytes differ from the command line's {}",
            body.len(),
            cli.len()
        );
        let disposition = headers["content-disposition"].to_str().unwrap();
        assert!(
            disposition.starts_with(&format!("attachment; filename=\"{id}-lod")),
            "{disposition}"
        );
        let (_, _, described) = get(
            &c,
            &s.url(&format!("/v1/textures/{id}/export.json?{query}")),
        )
        .await;
        if let Some(sidecar) = sidecar {
            assert_eq!(described, sidecar, "{query}");
        }
        let d: Value = serde_json::from_slice(&described).unwrap();
        assert_eq!(d["media_type"], headers["content-type"].to_str().unwrap());
        // A second request is answered from the finished export, and its
        // validator gives 304 without work.
        let r = c
            .get(s.url(&format!("/v1/textures/{id}/export?{query}")))
            .header("if-none-match", headers["etag"].clone())
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 304);
    }
    s.stop().await;
}

/// The files hold the voxels `region.raw` gives: KTX2 level 0 (RGBA, in
/// the order its level index says), the atlas's tiles, the NRRD's data.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_files_hold_the_textures_voxels() {
    let (_dir, s, c, id) = periodic_server(|_| {}).await;
    let region = |q: &str| {
        let url = s.url(&format!("/v1/textures/{id}/region.raw?{q}"));
        let c = c.clone();
        async move { get(&c, &url).await.2 }
    };
    let want = region("x=0&y=0&z=0&w=64&h=64&d=64").await;
    assert_eq!(want.len(), 64 * 64 * 64 * 3);

    let (_, _, ktx) = get(&c, &s.url(&format!("/v1/textures/{id}/export?format=ktx2"))).await;
    let u32_at = |at: usize| u32::from_le_bytes(ktx[at..at + 4].try_into().unwrap());
    let u64_at = |at: usize| u64::from_le_bytes(ktx[at..at + 8].try_into().unwrap()) as usize;
    assert_eq!([u32_at(20), u32_at(24), u32_at(28)], [64, 64, 64]);
    assert_eq!(u32_at(40), 7, "64, 32, 16, 8, 4, 2, 1");
    let (at, len) = (u64_at(80), u64_at(88));
    let level0 = &ktx[at..at + len];
    let rgb: Vec<u8> = level0
        .chunks(4)
        .flat_map(|t| {
            assert_eq!(t[3], 255);
            [t[0], t[1], t[2]]
        })
        .collect();
    assert_eq!(rgb, want);

    let (_, _, png) = get(
        &c,
        &s.url(&format!("/v1/textures/{id}/export?format=atlas")),
    )
    .await;
    let (w, h, atlas) = decode_png(&png);
    assert_eq!((w, h), (8 * 64, 8 * 64));
    for z in [0usize, 9, 63] {
        for y in [0usize, 31, 63] {
            for x in [0usize, 17, 63] {
                let (ax, ay) = ((z % 8) * 64 + x, (z / 8) * 64 + y);
                let a = (ay * w as usize + ax) * 3;
                let v = ((z * 64 + y) * 64 + x) * 3;
                assert_eq!(atlas[a..a + 3], want[v..v + 3], "{x},{y},{z}");
            }
        }
    }

    let (_, _, nrrd) = get(
        &c,
        &s.url(&format!(
            "/v1/textures/{id}/export?format=nrrd&x=3&y=-4&z=9&w=5&h=6&d=7&lod=1"
        )),
    )
    .await;
    let split = nrrd.windows(2).position(|w| w == b"\n\n").unwrap();
    let header = String::from_utf8_lossy(&nrrd[..split]);
    assert!(header.contains("sizes: 3 5 6 7"), "{header}");
    assert!(
        header.contains("space directions: none (2,0,0) (0,2,0) (0,0,2)"),
        "{header}"
    );
    assert_eq!(
        &nrrd[split + 2..],
        &region("x=3&y=-4&z=9&w=5&h=6&d=7&lod=1").await[..]
    );
    s.stop().await;
}

/// `Prefer: respond-async` answers 202 at once with the export's status
/// URL; its progress rises to 1 and its file is the synchronous answer.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_export_reports_progress_and_serves_its_file() {
    let (_dir, s, c, id) = periodic_server(|_| {}).await;
    let url = s.url(&format!(
        "/v1/textures/{id}/export?format=raw&x=0&y=0&z=0&w=128&h=128&d=128"
    ));
    let r = c
        .get(&url)
        .header("prefer", "respond-async")
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 202);
    let location = r.headers()["location"].to_str().unwrap().to_string();
    let first: Value = r.json().await.unwrap();
    assert_eq!(first["url"], location);
    assert_eq!(first["total"], 128 * 128 * 128);
    assert_eq!(first["unit"], "voxels");
    let mut last = -1.0;
    let t0 = Instant::now();
    let status = loop {
        let v = get_json(&c, &s, &location).await;
        let p = v["progress"].as_f64().unwrap();
        assert!((0.0..=1.0).contains(&p) && p >= last, "{v}");
        last = p;
        if v["state"] == "done" {
            break v;
        }
        assert!(v["state"] == "running" || v["state"] == "queued", "{v}");
        if p < 1.0 {
            // The file is not there yet: 409 with a retry.
            let (st, h, b) = get(&c, &s.url(&format!("{location}/file"))).await;
            if st == 409 {
                assert_error(st, &h, &b, 409, "export_running");
                assert!(h.contains_key("retry-after"));
            }
        }
        assert!(t0.elapsed() < Duration::from_secs(300), "{v}");
        tokio::time::sleep(Duration::from_millis(50)).await;
    };
    assert_eq!(status["progress"], 1.0);
    assert_eq!(status["bytes"], 128 * 128 * 128 * 3);
    let (st, _, file) = get(&c, &s.url(&format!("{location}/file"))).await;
    assert_eq!(st, 200);
    let (_, _, sync) = get(&c, &url).await;
    assert_eq!(file, sync);
    assert_eq!(file.len(), 128 * 128 * 128 * 3);
    let (st, h, b) = get(&c, &s.url("/v1/exports/0123456789abcdef0123456789abcdef")).await;
    assert_error(st, &h, &b, 404, "unknown_export");
    s.stop().await;
}

/// Each limit, at it (accepted) and past it (refused, 4xx with a message
/// that names it): the server's voxel budget, its work budget, a KTX2's
/// side; and parameters that do not fit.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn exports_past_each_limit_are_refused() {
    let budget = 32 * 32 * 32;
    let (_dir, s, c, id) = periodic_server(|a| a.max_export_voxels = budget).await;
    let describe = |q: String| {
        let url = s.url(&format!("/v1/textures/{id}/export.json?{q}"));
        let c = c.clone();
        async move { get(&c, &url).await }
    };
    let (st, h, _) = describe("format=raw&w=32&h=32&d=32".into()).await;
    assert_eq!(st, 200);
    let predicted: u64 = h["x-solidtex-predicted-voxels"]
        .to_str()
        .unwrap()
        .parse()
        .unwrap();
    assert!(predicted >= budget, "{predicted}");
    for (q, code, names) in [
        (
            "format=raw&w=32&h=32&d=33",
            "too_large",
            "--max-export-voxels",
        ),
        (
            "format=raw&w=1&h=1&d=32769",
            "too_large",
            "--max-export-voxels",
        ),
        ("format=ktx2&w=2049&h=1&d=1", "too_large", "2048"),
        ("format=ktx2&w=2048&h=1&d=1", "", ""),
        ("format=gif", "invalid_parameter", "format"),
        ("w=4", "invalid_parameter", "format"),
        ("format=atlas&mips=levels", "invalid_parameter", "mips"),
        ("format=nrrd&colour=linear", "invalid_parameter", "colour"),
        ("format=ktx2&colour=p3", "invalid_parameter", "colour"),
        ("format=ktx2&mips=all", "invalid_parameter", "mips"),
        ("format=ktx2&box=cube", "invalid_parameter", "box"),
        ("format=ktx2&box=period&w=4", "invalid_parameter", "box"),
        ("format=ktx2&lod=4", "out_of_range", "lod"),
        ("format=raw&w=0", "out_of_range", "w"),
        ("format=raw&x=2147483648&w=2", "out_of_range", "`x`"),
    ] {
        let (st, h, b) = describe(q.to_string()).await;
        if code.is_empty() {
            assert_eq!(st, 200, "{q}: {}", String::from_utf8_lossy(&b));
            continue;
        }
        assert_error(st, &h, &b, 400, code);
        let v: Value = serde_json::from_slice(&b).unwrap();
        let message = v["error"]["message"].as_str().unwrap();
        assert!(message.contains(names), "{q}: {message}");
    }
    s.stop().await;

    // The work budget: the predicted synthesis of a 32³ box, exactly, is
    // admitted; one voxel less is refused before any work.
    for (work, ok) in [(predicted, true), (predicted - 1, false)] {
        let (_dir, s, c, id) = periodic_server(|a| a.max_export_work = work).await;
        let (st, h, b) = get(
            &c,
            &s.url(&format!(
                "/v1/textures/{id}/export?format=raw&w=32&h=32&d=32"
            )),
        )
        .await;
        if ok {
            assert_eq!(st, 200, "{}", String::from_utf8_lossy(&b));
            assert_eq!(b.len(), 32 * 32 * 32 * 3);
        } else {
            assert_error(st, &h, &b, 400, "over_budget");
            assert!(String::from_utf8_lossy(&b).contains("--max-export-work"));
        }
        s.stop().await;
    }

    // One period of a texture without one.
    let (_dir, s, c, id) = server_with_texture(1).await;
    let (st, h, b) = get(
        &c,
        &s.url(&format!("/v1/textures/{id}/export?format=ktx2&box=period")),
    )
    .await;
    assert_error(st, &h, &b, 400, "invalid_request");
    assert!(String::from_utf8_lossy(&b).contains("no period"));
    s.stop().await;
}
