//! The data directory: locked against a second server, verified at load,
//! never emptied of what the server did not write, and changed on disk
//! before in memory.

use crate::server_support::*;
use serde_json::Value;
use sha2::{Digest, Sha256};
use solidtex_server::{ServeArgs, Server};
use std::fs;
use std::path::Path;

fn meta_of(dir: &Path, id: &str) -> Value {
    serde_json::from_slice(&fs::read(dir.join("textures").join(id).join("meta.json")).unwrap())
        .unwrap()
}

fn write_meta(dir: &Path, id: &str, meta: &Value) {
    fs::write(
        dir.join("textures").join(id).join("meta.json"),
        serde_json::to_vec_pretty(meta).unwrap(),
    )
    .unwrap();
}

async fn status_of(c: &reqwest::Client, s: &TestServer, id: &str) -> u16 {
    get(c, &s.url(&format!("/v1/textures/{id}"))).await.0
}

fn refused(s: &TestServer) -> f64 {
    metric(&s.state.metrics.encode(), "solidtex_textures_refused_total")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn tampered_textures_are_not_served_and_share_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let c = client();
    let s = TestServer::start(test_args(dir.path())).await;
    // a and b: the same pixels, other seeds (they share candidates); e: an
    // exemplar to tamper with; m: metadata to tamper with.
    let png = exemplar_png(32, 21);
    let (_, v) = upload(&c, &s, png.clone(), "levels=3&seed=1").await;
    let a = v["id"].as_str().unwrap().to_string();
    wait_ready(&c, &s, &a).await;
    let (_, v) = upload(&c, &s, png, "levels=3&seed=2").await;
    let b = v["id"].as_str().unwrap().to_string();
    wait_ready(&c, &s, &b).await;
    let m = ready_texture(&c, &s, 22).await;
    let slice = |id: &str| s.url(&format!("/v1/textures/{id}/slices/z/0.png?w=16&h=16"));
    let (_, _, b_before) = get(&c, &slice(&b)).await;
    s.stop().await;

    // a's exemplar replaced by another image; m's seed edited.
    fs::write(
        dir.path().join("textures").join(&a).join("exemplar.png"),
        exemplar_png(32, 23),
    )
    .unwrap();
    let mut meta = meta_of(dir.path(), &m);
    meta["params"]["seed"] = Value::from(99);
    write_meta(dir.path(), &m, &meta);

    let s = TestServer::start(test_args(dir.path())).await;
    assert_eq!(status_of(&c, &s, &a).await, 404);
    assert_eq!(status_of(&c, &s, &m).await, 404);
    assert_eq!(refused(&s), 2.0);
    // b is intact and serves the same bytes (it was not handed a's
    // candidates, which were never loaded).
    let v = wait_ready(&c, &s, &b).await;
    assert_eq!(v["status"], "ready");
    let (st, _, b_after) = get(
        &c,
        &s.url(&format!("/v1/textures/{b}/slices/z/0.png?w=16&h=16")),
    )
    .await;
    assert_eq!(st, 200);
    assert_eq!(b_before, b_after);
    // Refused, not deleted: the files are still there to inspect.
    assert!(
        dir.path()
            .join("textures")
            .join(&a)
            .join("meta.json")
            .exists()
    );
    assert!(
        dir.path()
            .join("textures")
            .join(&m)
            .join("meta.json")
            .exists()
    );
    s.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn candidates_of_other_exemplars_are_not_loaded() {
    let (dir, s, c, a) = server_with_texture(24).await;
    let b = ready_texture(&c, &s, 25).await;
    let slice = |s: &TestServer| s.url(&format!("/v1/textures/{a}/slices/z/0.png?w=16&h=16"));
    let (_, _, before) = get(&c, &slice(&s)).await;
    s.stop().await;
    // a's candidates swapped for b's (same parameters, other pixels).
    let tex = dir.path().join("textures");
    fs::copy(
        tex.join(&b).join("candidates.stx"),
        tex.join(&a).join("candidates.stx"),
    )
    .unwrap();
    let s = TestServer::start(test_args(dir.path())).await;
    wait_ready(&c, &s, &a).await;
    let (_, _, after) = get(&c, &slice(&s)).await;
    assert_eq!(before, after, "a is recomputed from its own exemplar");
    let text = s.state.metrics.encode();
    assert_eq!(
        metric(&text, "solidtex_textures_loaded_total"),
        1.0,
        "{text}"
    );
    s.stop().await;
}

/// The synthesis parameters of the first stored layout, in their order.
#[derive(serde::Serialize)]
struct SynthParamsVersion1 {
    seed: u64,
    passes: u32,
    subpass_side: u32,
    scheme: Value,
    grid: u32,
    jitter: f32,
    correct_init_level: bool,
    contrast: f32,
}

/// Textures of the first layout matched colour neighbourhoods, a correction
/// that is gone: they are not served (their bytes cannot be made again),
/// and their files are left for an older server.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn data_directories_of_the_first_layout_are_kept_but_not_served() {
    let (dir, s, c, new_id) = server_with_texture(26).await;
    s.stop().await;

    // Rewrite it as the first layout stored it: without the keys added
    // since, under the id computed then.
    let tex = dir.path().join("textures");
    let mut meta = meta_of(dir.path(), &new_id);
    let params = meta["params"].as_object_mut().unwrap();
    for k in [
        "slices",
        "consistency",
        "fine_levels",
        "correction",
        "finest_passes",
        "slab_thickness",
        "slab_tiling",
        "parity_levels",
    ] {
        params.remove(k).unwrap();
    }
    let stored = solidtex_server::spec::TextureParams::from_flat(params).unwrap();
    let then = SynthParamsVersion1 {
        seed: stored.synth.seed,
        passes: stored.synth.passes,
        subpass_side: stored.synth.subpass_side,
        scheme: params["scheme"].clone(),
        grid: stored.synth.grid,
        jitter: stored.synth.jitter,
        correct_init_level: stored.synth.correct_init_level,
        contrast: stored.synth.contrast,
    };
    let e = solidtex_core::Exemplar::open(tex.join(&new_id).join("exemplar.png")).unwrap();
    let mut h = Sha256::new();
    h.update(b"solidtex texture v1\0");
    for _ in 0..3 {
        h.update(e.width().to_le_bytes());
        h.update(e.height().to_le_bytes());
        for p in e.pixels() {
            h.update(p);
        }
    }
    for json in [
        serde_json::to_string(&stored.analysis).unwrap(),
        serde_json::to_string(&then).unwrap(),
    ] {
        h.update((json.len() as u64).to_le_bytes());
        h.update(json.as_bytes());
    }
    let old_id: String = h.finalize()[..16]
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect();
    assert_ne!(old_id, new_id);
    meta["id"] = old_id.clone().into();
    meta["content_hash"] = old_id.clone().into();
    fs::rename(tex.join(&new_id), tex.join(&old_id)).unwrap();
    write_meta(dir.path(), &old_id, &meta);

    let s = TestServer::start(test_args(dir.path())).await;
    assert_eq!(status_of(&c, &s, &old_id).await, 404);
    let text = s.state.metrics.encode();
    assert_eq!(
        metric(&text, "solidtex_textures_loaded_total"),
        0.0,
        "{text}"
    );
    assert!(tex.join(&old_id).join("exemplar.png").exists());
    // The same exemplar uploaded again is a texture of today's layout.
    let (status, v) = upload(
        &c,
        &s,
        fs::read(tex.join(&old_id).join("exemplar.png")).unwrap(),
        "levels=3&seed=26",
    )
    .await;
    assert!((200..300).contains(&status), "{status} {v}");
    assert_ne!(v["id"], old_id.as_str());
    s.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_second_server_on_the_same_data_directory_is_refused() {
    let (dir, s, c, id) = server_with_texture(27).await;
    let err = Server::bind(&test_args(dir.path()))
        .await
        .err()
        .expect("the data directory is locked");
    let text = format!("{err:#}");
    assert!(text.contains("in use by another solidtex server"), "{text}");
    // The first one goes on undisturbed.
    assert_eq!(status_of(&c, &s, &id).await, 200);
    s.stop().await;
    // Once it has stopped, the directory is free again.
    let s = TestServer::start(test_args(dir.path())).await;
    assert_eq!(status_of(&c, &s, &id).await, 200);
    s.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_server_that_cannot_listen_touches_no_data() {
    let dir = tempfile::tempdir().unwrap();
    let s = TestServer::start(test_args(dir.path())).await;
    let fresh = dir.path().join("never-created");
    let mut args: ServeArgs = test_args(&fresh);
    args.addr = s.addr;
    let err = Server::bind(&args).await.err().expect("the port is taken");
    assert!(format!("{err:#}").contains("binding"), "{err:#}");
    assert!(
        !fresh.exists(),
        "a server that could not listen created its data directory"
    );
    s.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn entries_the_server_did_not_write_are_left_alone() {
    let dir = tempfile::tempdir().unwrap();
    let tex = dir.path().join("textures");
    let keep = [
        tex.join("notes.txt"),
        tex.join("My Photos").join("cat.png"),
        tex.join("userdir").join("report.txt"),
        tex.join("abc.deleting.tmp").join("keep.txt"),
        tex.join("nometa").join("exemplar.png"),
    ];
    for f in &keep[..4] {
        fs::create_dir_all(f.parent().unwrap()).unwrap();
        fs::write(f, b"mine").unwrap();
    }
    fs::create_dir_all(tex.join("nometa")).unwrap();
    fs::write(&keep[4], b"half").unwrap();
    fs::write(tex.join("nometa").join("diary.txt"), b"mine").unwrap();
    let c = client();
    let s = TestServer::start(test_args(dir.path())).await;
    let (st, _, body) = get(&c, &s.url("/v1/textures")).await;
    assert_eq!(st, 200);
    let v: Value = serde_json::from_slice(&body).unwrap();
    assert_eq!(v["textures"].as_array().unwrap().len(), 0);
    s.stop().await;
    for f in &keep {
        assert!(f.exists(), "{} was removed", f.display());
    }
    // The server's own debris still goes: an empty texture directory.
    fs::create_dir_all(tex.join("feedfeed")).unwrap();
    let s = TestServer::start(test_args(dir.path())).await;
    assert!(!tex.join("feedfeed").exists());
    s.stop().await;
}

/// Running as root, permissions would not make the removal fail; a
/// directory already in the way of the rename that starts it does.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_delete_that_fails_on_disk_leaves_the_texture_served() {
    let (dir, s, c, id) = server_with_texture(28).await;
    let blocker = dir
        .path()
        .join("textures")
        .join(format!("{id}.deleting.tmp"));
    fs::create_dir_all(&blocker).unwrap();
    fs::write(blocker.join("keep.txt"), b"mine").unwrap();
    let url = s.url(&format!("/v1/textures/{id}"));
    let r = c.delete(&url).send().await.unwrap();
    assert_eq!(r.status().as_u16(), 500);
    // Still listed, still served, still on disk.
    assert_eq!(status_of(&c, &s, &id).await, 200);
    let (st, _, _) = get(
        &c,
        &s.url(&format!("/v1/textures/{id}/slices/z/0.png?w=8&h=8")),
    )
    .await;
    assert_eq!(st, 200);
    assert!(
        dir.path()
            .join("textures")
            .join(&id)
            .join("meta.json")
            .exists()
    );
    assert!(blocker.join("keep.txt").exists());
    // Out of the way, the delete goes through.
    fs::remove_dir_all(&blocker).unwrap();
    let r = c.delete(&url).send().await.unwrap();
    assert_eq!(r.status().as_u16(), 204);
    assert_eq!(status_of(&c, &s, &id).await, 404);
    assert!(!dir.path().join("textures").join(&id).exists());
    let r = c.delete(&url).send().await.unwrap();
    assert_eq!(r.status().as_u16(), 404);
    s.stop().await;
}
