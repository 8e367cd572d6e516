//! Where textures are kept: their exemplars, metadata and `.stx`
//! candidates, so that a restart — or another replica — serves the same
//! textures without recomputing them.
//!
//! ```text
//! textures/<id>/meta.json       status, params, exemplar size
//!              /exemplar.png    (or xy.png, yz.png, zx.png, and *.mask.png)
//!              /candidates.stx  written once the precompute ends
//! ```
//!
//! Two backends lay that out behind [`Storage`]:
//!
//! - [`local::DataDir`], the default: a directory of this machine, locked
//!   against a second server, written atomically and durably.
//! - [`s3::ObjectStorage`]: a bucket (and prefix) of an S3-compatible object
//!   store shared by any number of replicas. Every object but `meta.json`
//!   is named by the content hash in its key, so two replicas writing the
//!   same texture write the same bytes; they write them conditionally
//!   (`If-None-Match: *`), and `meta.json` is updated only while it is the
//!   version last read (`If-Match`), so that a delete is never undone.
//!
//! On both, `meta.json` is written last on creation (a texture without it
//! does not exist) and removed first on deletion.

pub(crate) mod local;
pub(crate) mod s3;

use super::spec::{ExemplarInfo, Planes};
use parking_lot::MutexGuard;
use serde::{Deserialize, Serialize};
use serde_json::{Map, Value};
use solidtex_core::{Candidates, Exemplar};
use std::io;

/// Version of the metadata layout.
pub const META_VERSION: u32 = 1;

/// The files the server writes for a texture: only these are ever
/// removed.
pub(crate) const WRITTEN: [&str; 10] = [
    "meta.json",
    "exemplar.png",
    "xy.png",
    "yz.png",
    "zx.png",
    "exemplar.mask.png",
    "xy.mask.png",
    "yz.mask.png",
    "zx.mask.png",
    "candidates.stx",
];

/// Status as persisted.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum StoredStatus {
    /// Precompute not finished (or interrupted).
    Pending,
    /// `candidates.stx` is complete.
    Ready,
    /// Precompute failed for good.
    Failed,
}

/// The persisted `meta.json` of a texture.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct StoredMeta {
    /// Layout version.
    pub version: u32,
    /// Texture id (the content hash, or `default`).
    pub id: String,
    /// The uploaded file's name.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// Content hash of exemplars and parameters.
    pub content_hash: String,
    /// Creation time, seconds since the Unix epoch.
    pub created: u64,
    /// Exemplar size and plane count.
    pub exemplar: ExemplarInfo,
    /// Complete flat parameters.
    pub params: Map<String, Value>,
    /// Status.
    pub status: StoredStatus,
    /// Why the precompute failed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
    /// Seconds the precompute took.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub precompute_seconds: Option<f64>,
    /// Heap bytes the precompute peaked at, when measured.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub precompute_peak_bytes: Option<u64>,
}

/// A texture found in the storage.
pub struct Found {
    /// Its metadata.
    pub meta: StoredMeta,
    /// Where it is, for people.
    pub location: String,
}

/// Where textures are kept. Every method blocks: callers run them on
/// blocking threads, never on the async ones.
pub(crate) trait Storage: Send + Sync {
    /// Where, for people (a directory, `s3://bucket/prefix`).
    fn location(&self) -> String;

    /// True when other servers read and write the same textures, so that
    /// a texture this server has not seen may be there, and one it holds
    /// may be deleted by another.
    fn shared(&self) -> bool;

    /// Serialises this server's changes of a texture (create, delete,
    /// final writes), so that a delete racing a re-upload of the same
    /// content cannot remove the new files.
    fn lock(&self) -> MutexGuard<'_, ()>;

    /// Bytes of every texture's files.
    fn bytes(&self) -> io::Result<u64>;

    /// Writes a new texture's exemplars then its metadata. Caller holds
    /// [`Storage::lock`].
    fn create(&self, meta: &StoredMeta, planes: &Planes) -> io::Result<()>;

    /// Replaces a texture's metadata. Fails with [`io::ErrorKind::NotFound`]
    /// when the texture was deleted meanwhile (by another server).
    fn write_meta(&self, meta: &StoredMeta) -> io::Result<()>;

    /// Writes `candidates.stx`.
    fn write_candidates(&self, id: &str, c: &Candidates) -> io::Result<()>;

    /// Reads `candidates.stx` (verified by [`Candidates::load`]).
    fn read_candidates(&self, id: &str) -> io::Result<Vec<u8>>;

    /// Reads a texture's exemplars back, each with its feature mask if one
    /// was stored.
    fn read_planes(&self, meta: &StoredMeta) -> solidtex_core::Result<Planes>;

    /// Removes a texture. Caller holds [`Storage::lock`]. Once this returns
    /// `Ok` the texture is gone; on an error it is still there.
    fn remove(&self, id: &str) -> io::Result<()>;

    /// Every texture with readable metadata, oldest first. One whose
    /// metadata cannot be read is reported and skipped.
    fn scan(&self) -> io::Result<Vec<Found>>;

    /// Texture `id`, when it is stored with readable metadata.
    fn find(&self, id: &str) -> io::Result<Option<Found>>;

    /// Ids of the textures stored now (those with metadata).
    fn ids(&self) -> io::Result<Vec<String>>;

    /// Writes region texture `id`'s definition (`regions/ID.json`): a few
    /// hundred bytes naming the textures it is made of.
    fn write_region(&self, id: &str, json: &[u8]) -> io::Result<()>;

    /// Region texture `id`'s definition, `None` when there is none.
    fn read_region(&self, id: &str) -> io::Result<Option<Vec<u8>>>;

    /// Removes region texture `id`'s definition (none there is no error).
    fn remove_region(&self, id: &str) -> io::Result<()>;

    /// Ids of the region textures stored now.
    fn region_ids(&self) -> io::Result<Vec<String>>;
}

/// The files of a texture's exemplars: `(name, PNG bytes)`, masks
/// included.
pub(crate) fn plane_files(planes: &Planes) -> io::Result<Vec<(String, Vec<u8>)>> {
    let png = |e: &Exemplar| {
        solidtex_core::png::encode(e.width(), e.height(), &e.to_rgb_bytes())
            .map_err(io::Error::other)
    };
    let mut out = Vec::new();
    for (name, e) in planes.named() {
        out.push((format!("{name}.png"), png(e)?));
        if let Some(mask) = e.feature_mask_image() {
            out.push((format!("{name}.mask.png"), png(&mask)?));
        }
    }
    Ok(out)
}

/// A texture's exemplars from its files, read by `read` (`None` for a file
/// that is not there).
pub(crate) fn planes_from(
    meta: &StoredMeta,
    read: impl Fn(&str) -> io::Result<Option<Vec<u8>>>,
) -> solidtex_core::Result<Planes> {
    let open = |n: &str| {
        let name = format!("{n}.png");
        let bytes = read(&name)?
            .ok_or_else(|| io::Error::new(io::ErrorKind::NotFound, format!("{name} is missing")))?;
        let e = Exemplar::decode(&bytes)?;
        match read(&format!("{n}.mask.png"))? {
            Some(mask) => e.with_mask_image(&Exemplar::decode(&mask)?),
            None => Ok(e),
        }
    };
    if meta.exemplar.planes == 1 {
        Ok(Planes::Single(open("exemplar")?))
    } else {
        Ok(Planes::Triple(Box::new([
            open("xy")?,
            open("yz")?,
            open("zx")?,
        ])))
    }
}

/// Parses `meta.json` of the texture stored as `id`: refused when of
/// another layout version or naming another texture.
pub(crate) fn parse_meta(id: &str, bytes: &[u8]) -> Result<StoredMeta, String> {
    let meta = serde_json::from_slice::<StoredMeta>(bytes).map_err(|e| e.to_string())?;
    if meta.version != META_VERSION {
        return Err(format!("foreign metadata version {}", meta.version));
    }
    if meta.id != id {
        return Err(format!("metadata names texture `{}`", meta.id));
    }
    Ok(meta)
}

/// Sorts textures oldest first.
pub(crate) fn oldest_first(found: &mut [Found]) {
    found.sort_by(|a, b| (a.meta.created, &a.meta.id).cmp(&(b.meta.created, &b.meta.id)));
}

/// `candidates.stx` in memory.
pub(crate) fn candidates_bytes(c: &Candidates) -> io::Result<Vec<u8>> {
    let mut out = Vec::new();
    save_candidates(c, &mut out)?;
    Ok(out)
}

/// Writes `candidates.stx` to `w`.
pub(crate) fn save_candidates(c: &Candidates, w: &mut dyn io::Write) -> io::Result<()> {
    c.save(w).map_err(|e| match e {
        solidtex_core::Error::Io(e) => e,
        other => io::Error::other(other.to_string()),
    })
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    pub(crate) fn meta(id: &str, status: StoredStatus) -> StoredMeta {
        StoredMeta {
            version: META_VERSION,
            id: id.into(),
            name: Some("marble.png".into()),
            content_hash: id.into(),
            created: 5,
            exemplar: ExemplarInfo {
                width: 16,
                height: 16,
                planes: 1,
                feature_masks: 0,
            },
            params: Map::new(),
            status,
            reason: None,
            precompute_seconds: None,
            precompute_peak_bytes: None,
        }
    }

    pub(crate) fn planes() -> Planes {
        let rgb: Vec<u8> = (0..16 * 16 * 3).map(|i| (i * 7) as u8).collect();
        Planes::Single(Exemplar::from_rgb(16, 16, &rgb).unwrap())
    }

    #[test]
    fn meta_of_another_texture_is_refused() {
        let m = meta("abc", StoredStatus::Ready);
        let bytes = serde_json::to_vec(&m).unwrap();
        assert_eq!(parse_meta("abc", &bytes).unwrap(), m);
        assert!(parse_meta("abd", &bytes).is_err());
        let old = StoredMeta { version: 0, ..m };
        assert!(parse_meta("abc", &serde_json::to_vec(&old).unwrap()).is_err());
    }
}
