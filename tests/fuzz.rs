//! Property tests over what clients and disks hand the service: `.stx`
//! files with corrupted contents (checksum recomputed, so the parser itself
//! is reached), arbitrary query strings, and arbitrary multipart uploads.
//! Each must end in a value or an error, never a panic, an abort or a 5xx.

mod common;
mod server_support;

use proptest::prelude::*;
use solidtex_core::Candidates;
use solidtex_server::query::Query;

/// Offset of the payload in a `.stx` file: magic, version, length, CRC.
const HEADER: usize = 8 + 4 + 8 + 4;

/// Rewrites the length and checksum of a `.stx` whose payload was edited.
fn reseal(mut file: Vec<u8>) -> Vec<u8> {
    let len = (file.len() - HEADER) as u64;
    file[12..20].copy_from_slice(&len.to_le_bytes());
    let crc = crc32fast::hash(&file[HEADER..]);
    file[20..24].copy_from_slice(&crc.to_le_bytes());
    file
}

fn stx() -> &'static [u8] {
    static BYTES: std::sync::OnceLock<Vec<u8>> = std::sync::OnceLock::new();
    BYTES.get_or_init(|| common::small_candidates().to_bytes())
}

/// Byte edits anywhere in the payload (sizes, counts, coordinates,
/// parameters), then maybe a cut or an extension: every file loads or is
/// an error, and both happen (the edits reach past the checksum).
#[test]
fn the_stx_loader_never_panics() {
    let edits = prop::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..8);
    let resize = prop_oneof![
        3 => Just(None),
        1 => any::<prop::sample::Index>().prop_map(Some)
    ];
    let extra = prop_oneof![
        3 => Just(Vec::new()),
        1 => prop::collection::vec(any::<u8>(), 1..16)
    ];
    let (loaded, refused) = (std::cell::Cell::new(0), std::cell::Cell::new(0));
    let mut runner = proptest::test_runner::TestRunner::new(ProptestConfig {
        cases: 256,
        failure_persistence: None,
        ..ProptestConfig::default()
    });
    runner
        .run(&(edits, resize, extra), |(edits, resize, extra)| {
            let mut file = stx().to_vec();
            let payload = file.len() - HEADER;
            for (at, byte) in &edits {
                // The early bytes (parameters, sizes) are the interesting
                // ones: half the edits land in the first 256.
                let i = if byte % 2 == 0 {
                    at.index(256.min(payload))
                } else {
                    at.index(payload)
                };
                file[HEADER + i] = *byte;
            }
            if let Some(cut) = resize {
                file.truncate(HEADER + cut.index(payload));
            }
            file.extend_from_slice(&extra);
            match Candidates::load(&reseal(file)) {
                Ok(_) => loaded.set(loaded.get() + 1),
                Err(_) => refused.set(refused.get() + 1),
            }
            Ok(())
        })
        .unwrap();
    let (loaded, refused) = (loaded.get(), refused.get());
    assert!(
        loaded > 0 && refused > 0,
        "{loaded} loaded, {refused} refused"
    );
}

proptest! {
    #![proptest_config(ProptestConfig {
        cases: 512,
        failure_persistence: None,
        ..ProptestConfig::default()
    })]

    /// Any query string, parsed as an upload's (the voxel routes' typed
    /// queries have their own property test in the server crate).
    #[test]
    fn query_parsing_never_panics(raw in "[a-z0-9=&%+.,eE-]{0,64}|\\PC{0,64}") {
        if let Ok(q) = Query::parse(Some(&raw)) {
            for (k, v) in q.pairs() {
                let _ = (q.raw(k), v);
            }
        }
    }
}

/// Multipart bodies built from pieces of valid and broken parts.
fn multipart_body() -> impl Strategy<Value = Vec<u8>> {
    let part = (
        prop_oneof![
            6 => Just("image"),
            1 => Just("xy"),
            1 => Just("yz"),
            1 => Just("zx"),
            2 => Just("params"),
            1 => Just("bogus"),
            1 => Just("")
        ],
        prop_oneof![
            2 => Just(b"{\"levels\": 3}".to_vec()),
            1 => Just(b"{\"levels\": 3, \"levels\": 2}".to_vec()),
            1 => Just(b"not json".to_vec()),
            6 => Just(server_support::exemplar_png(16, 3)),
            1 => Just(server_support::exemplar_png(16, 3)[..40].to_vec()),
            1 => prop::collection::vec(any::<u8>(), 0..64),
        ],
        any::<bool>(),
    );
    prop::collection::vec(part, 0..4).prop_map(|parts| {
        let mut body = Vec::new();
        for (name, data, with_filename) in parts {
            body.extend_from_slice(b"--XyZ\r\nContent-Disposition: form-data; name=\"");
            body.extend_from_slice(name.as_bytes());
            body.push(b'"');
            if with_filename {
                body.extend_from_slice(b"; filename=\"../dir/e.png\"");
            }
            body.extend_from_slice(b"\r\n\r\n");
            body.extend_from_slice(&data);
            body.extend_from_slice(b"\r\n");
        }
        body.extend_from_slice(b"--XyZ--\r\n");
        body
    })
}

#[test]
fn multipart_uploads_never_answer_5xx() {
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap();
    let dir = tempfile::tempdir().unwrap();
    let server = rt.block_on(server_support::TestServer::start(
        server_support::test_args(dir.path()),
    ));
    let c = server_support::client();
    let url = server.url("/v1/textures");
    let mut runner = proptest::test_runner::TestRunner::new(ProptestConfig {
        cases: 128,
        failure_persistence: None,
        ..ProptestConfig::default()
    });
    let statuses = std::cell::RefCell::new(std::collections::BTreeMap::<u16, usize>::new());
    runner
        .run(&(multipart_body(), any::<bool>()), |(body, cut)| {
            let body = if cut {
                body[..body.len() / 2].to_vec()
            } else {
                body
            };
            let status = rt.block_on(async {
                let r = c
                    .post(&url)
                    .header("content-type", "multipart/form-data; boundary=XyZ")
                    .body(body)
                    .send()
                    .await
                    .unwrap();
                let status = r.status().as_u16();
                let bytes = r.bytes().await.unwrap();
                if status >= 400 && status != 503 {
                    let v: serde_json::Value = serde_json::from_slice(&bytes)
                        .unwrap_or_else(|_| panic!("{status}: body is not JSON: {bytes:?}"));
                    assert!(v["error"]["code"].is_string(), "{v}");
                }
                status
            });
            *statuses.borrow_mut().entry(status).or_default() += 1;
            prop_assert!(status < 500 || status == 503, "status {}", status);
            Ok(())
        })
        .unwrap();
    // Most bodies were refused. Few random bodies are whole uploads (about
    // 3 in 100), so that the same bytes are accepted is checked directly.
    let statuses = statuses.into_inner();
    assert!(statuses.contains_key(&400), "{statuses:?}");
    let mut whole = b"--XyZ\r\nContent-Disposition: form-data; name=\"image\"\r\n\r\n".to_vec();
    whole.extend_from_slice(&server_support::exemplar_png(16, 3));
    whole.extend_from_slice(b"\r\n--XyZ--\r\n");
    let status = rt.block_on(async {
        c.post(&url)
            .header("content-type", "multipart/form-data; boundary=XyZ")
            .body(whole)
            .send()
            .await
            .unwrap()
            .status()
            .as_u16()
    });
    assert!(matches!(status, 201 | 202), "{status}");
    rt.block_on(server.stop());
}
