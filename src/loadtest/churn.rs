//! What a soak adds to the voxel load: textures uploaded, read and deleted
//! while the load runs, clients that hang up mid-request, and a check that
//! every answer sampled during the run is byte for byte what a fresh
//! server gives for the same request.

use super::workload::Rng;
use serde::Serialize;
use std::collections::BTreeMap;
use std::time::{Duration, Instant};

/// What the churn did and how the server answered it.
#[derive(Clone, Debug, Default, Serialize)]
pub struct ChurnReport {
    /// Uploads sent.
    pub uploads: u64,
    /// Uploaded textures that became ready and answered a slice.
    pub served: u64,
    /// Deletions sent.
    pub deletes: u64,
    /// Requests abandoned on purpose before their answer.
    pub hangups: u64,
    /// Status codes of the churn's own requests (hang-ups excluded).
    pub statuses: BTreeMap<u16, u64>,
}

impl ChurnReport {
    /// Answers 500 or above other than a deliberate 503.
    pub fn server_errors(&self) -> u64 {
        self.statuses
            .iter()
            .filter(|(s, _)| **s >= 500 && **s != 503)
            .map(|(_, n)| n)
            .sum()
    }
}

/// Sampled answers compared with a fresh server's.
#[derive(Clone, Debug, Default, Serialize)]
pub struct VerifyReport {
    /// Requests compared.
    pub checked: u64,
    /// Of those, answers whose bytes differ.
    pub mismatched: u64,
    /// Requests the fresh server did not answer 200.
    pub failed: u64,
}

/// FNV-1a of an answer, to compare it without keeping it.
pub fn fingerprint(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, &b| {
        (h ^ b as u64).wrapping_mul(0x100_0000_01b3)
    })
}

/// A small exemplar with structure, one of four, so that uploads repeat.
fn exemplar_png(variant: u64) -> Vec<u8> {
    let side = 24u32;
    let mut rgb = Vec::with_capacity((side * side * 3) as usize);
    for y in 0..side as u64 {
        for x in 0..side as u64 {
            let stripe = ((x + 2 * y + 3 * variant) % 6 < 3) as u64;
            let dot = ((x * x + y * y + variant * 7) % 11) * 9;
            rgb.push((40 + stripe * 150 + dot) as u8);
            rgb.push((90 + variant * 30 + dot) as u8);
            rgb.push((200 - stripe * 120) as u8);
        }
    }
    solidtex_core::png::encode(side, side, &rgb).expect("a small PNG encodes")
}

/// Uploads, reads and deletes textures and abandons voxel requests until
/// `deadline`.
pub async fn churn(
    client: reqwest::Client,
    base: String,
    texture_url: String,
    seed: u64,
    deadline: Instant,
) -> ChurnReport {
    let mut rep = ChurnReport::default();
    let mut rng = Rng::new(seed ^ 0xc4_0a4e, 0);
    let count = |rep: &mut ChurnReport, status: u16| {
        *rep.statuses.entry(status).or_default() += 1;
    };
    while Instant::now() < deadline {
        // A client that gives up on a cold slice far away.
        let (x, y) = (rng.range(-1 << 20, 1 << 20), rng.range(-1 << 20, 1 << 20));
        let url = format!("{texture_url}/slices/z/{x}.png?u0={y}&v0={x}&w=256&h=256");
        let gone = client
            .get(&url)
            .timeout(Duration::from_millis(20 + rng.range(0, 200) as u64))
            .send()
            .await;
        if gone.is_err() {
            rep.hangups += 1;
        }
        // An upload, its first slice, its deletion.
        let variant = rng.next_u64() % 4;
        rep.uploads += 1;
        let created = client
            .post(format!("{base}/v1/textures?levels=3&seed={}", variant + 1))
            .header("content-type", "image/png")
            .body(exemplar_png(variant))
            .send()
            .await;
        let id = match created {
            Ok(r) => {
                count(&mut rep, r.status().as_u16());
                let ok = r.status().is_success();
                match r.json::<serde_json::Value>().await {
                    Ok(v) if ok => v["id"].as_str().map(String::from),
                    _ => None,
                }
            }
            Err(_) => None,
        };
        let Some(id) = id else {
            tokio::time::sleep(Duration::from_millis(500)).await;
            continue;
        };
        // Ready before its slice is asked for (a server with
        // --pending-wait would also wait by itself).
        let t0 = Instant::now();
        while t0.elapsed() < Duration::from_secs(60) {
            let status = match client.get(format!("{base}/v1/textures/{id}")).send().await {
                Ok(r) => r.json::<serde_json::Value>().await.ok(),
                Err(_) => None,
            };
            match status.as_ref().and_then(|v| v["status"].as_str()) {
                Some("pending") => tokio::time::sleep(Duration::from_millis(100)).await,
                _ => break,
            }
        }
        let slice = format!("{base}/v1/textures/{id}/slices/y/3.png?w=16&h=16");
        if let Ok(r) = client.get(&slice).send().await {
            let status = r.status().as_u16();
            count(&mut rep, status);
            if status == 200 && r.bytes().await.is_ok_and(|b| !b.is_empty()) {
                rep.served += 1;
            }
        }
        rep.deletes += 1;
        if let Ok(r) = client
            .delete(format!("{base}/v1/textures/{id}"))
            .send()
            .await
        {
            count(&mut rep, r.status().as_u16());
        }
    }
    rep
}

/// Asks `fresh` (the base URL of a server that saw nothing else) for every
/// sampled request and compares fingerprints.
pub async fn verify(
    client: &reqwest::Client,
    fresh_texture_url: &str,
    samples: &[(String, u64)],
) -> VerifyReport {
    let mut rep = VerifyReport::default();
    for (path, print) in samples {
        rep.checked += 1;
        match client
            .get(format!("{fresh_texture_url}{path}"))
            .send()
            .await
        {
            Ok(r) if r.status().as_u16() == 200 => match r.bytes().await {
                Ok(b) if fingerprint(&b) == *print => {}
                Ok(_) => rep.mismatched += 1,
                Err(_) => rep.failed += 1,
            },
            _ => rep.failed += 1,
        }
    }
    rep
}
