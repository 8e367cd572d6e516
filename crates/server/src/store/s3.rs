//! An S3-compatible bucket as [`Storage`], shared by any number of
//! replicas (`--store s3://BUCKET/PREFIX`).
//!
//! Objects are laid out as the data directory's files, under
//! `PREFIX/textures/<id>/`. A texture id is the content hash of its
//! exemplars and parameters, and candidates are a deterministic function
//! of both, so replicas that store the same upload write the same bytes:
//! each write is conditional (`If-None-Match: *`), and one that finds the
//! object there already compares it (or, for candidates, verifies its
//! checksum) instead of writing it again. Only `meta.json` changes after
//! creation (its status flips to ready); it is replaced only while it is
//! the version just read (`If-Match` on its ETag), so a replica finishing
//! a precompute never brings back a texture another one deleted.
//!
//! The object store's client is asynchronous; the trait's methods block
//! on the server's runtime, from the blocking threads that call them.

use super::{
    Found, Storage, StoredMeta, WRITTEN, candidates_bytes, oldest_first, parse_meta, plane_files,
    planes_from,
};
use crate::spec::{Planes, valid_id};
use futures_util::TryStreamExt;
use object_store::aws::AmazonS3Builder;
use object_store::path::Path as Key;
use object_store::{
    ObjectStore, ObjectStoreExt, PutMode, PutOptions, PutPayload, RetryConfig, UpdateVersion,
};
use parking_lot::{Mutex, MutexGuard};
use solidtex_core::Candidates;
use std::future::Future;
use std::io;
use std::sync::Arc;
use std::time::Duration;

/// Where the bucket is and how to reach it.
#[derive(Clone, Debug)]
pub struct S3Options {
    /// `s3://BUCKET` or `s3://BUCKET/PREFIX`.
    pub url: String,
    /// Endpoint of a store other than AWS (`http://127.0.0.1:9000`).
    pub endpoint: Option<String>,
    /// The bucket's region.
    pub region: String,
}

/// Textures in an S3-compatible bucket.
pub struct ObjectStorage {
    store: Arc<dyn ObjectStore>,
    /// Key prefix without a trailing slash (may be empty).
    prefix: String,
    url: String,
    runtime: tokio::runtime::Handle,
    lock: Mutex<()>,
}

/// Times `meta.json` is read again when another replica replaced it
/// between the read and the conditional write.
const META_RETRIES: usize = 5;

fn other(e: object_store::Error) -> io::Error {
    match e {
        object_store::Error::NotFound { .. } => io::Error::new(io::ErrorKind::NotFound, e),
        e => io::Error::other(e),
    }
}

impl ObjectStorage {
    /// The bucket of `opts`, its credentials from the usual `AWS_*`
    /// variables (`AWS_ACCESS_KEY_ID`, `AWS_SECRET_ACCESS_KEY`,
    /// `AWS_SESSION_TOKEN`, or the instance's role). Its requests run on
    /// `runtime`. Checks that the bucket can be listed.
    pub fn open(opts: &S3Options, runtime: tokio::runtime::Handle) -> io::Result<ObjectStorage> {
        let rest = opts.url.strip_prefix("s3://").ok_or_else(|| {
            io::Error::new(
                io::ErrorKind::InvalidInput,
                format!("`{}` is not an s3://BUCKET[/PREFIX] URL", opts.url),
            )
        })?;
        let (bucket, prefix) = rest.split_once('/').unwrap_or((rest, ""));
        let prefix = prefix.trim_matches('/').to_string();
        if bucket.is_empty() {
            return Err(io::Error::new(
                io::ErrorKind::InvalidInput,
                format!("`{}` names no bucket", opts.url),
            ));
        }
        let mut builder = AmazonS3Builder::from_env()
            .with_bucket_name(bucket)
            .with_region(&opts.region)
            // A request that fails is tried again a few times over ten
            // seconds at most, so a store that is down fails requests
            // quickly instead of holding them.
            .with_retry(RetryConfig {
                max_retries: 3,
                retry_timeout: Duration::from_secs(10),
                ..RetryConfig::default()
            });
        if let Some(endpoint) = &opts.endpoint {
            builder = builder
                .with_endpoint(endpoint)
                .with_allow_http(endpoint.starts_with("http://"));
        }
        let store = builder.build().map_err(io::Error::other)?;
        let s = ObjectStorage {
            store: Arc::new(store),
            prefix,
            url: opts.url.clone(),
            runtime,
            lock: Mutex::new(()),
        };
        s.ids()?;
        Ok(s)
    }

    fn key(&self, id: &str, name: &str) -> Key {
        Key::from(self.textures_prefix() + id + "/" + name)
    }

    fn textures_prefix(&self) -> String {
        if self.prefix.is_empty() {
            "textures/".to_string()
        } else {
            format!("{}/textures/", self.prefix)
        }
    }

    /// Runs `f` on the runtime and waits for it (from a blocking thread).
    fn block<T: Send + 'static>(
        &self,
        f: impl Future<Output = io::Result<T>> + Send + 'static,
    ) -> io::Result<T> {
        let (tx, rx) = std::sync::mpsc::sync_channel(1);
        self.runtime.spawn(async move {
            let _ = tx.send(f.await);
        });
        rx.recv()
            .map_err(|_| io::Error::other("the object store's request was abandoned"))?
    }

    /// The object at `key`, or `None` when there is none.
    fn get(&self, key: Key) -> io::Result<Option<Vec<u8>>> {
        let store = self.store.clone();
        self.block(async move {
            match store.get(&key).await {
                Ok(r) => Ok(Some(r.bytes().await.map_err(other)?.to_vec())),
                Err(object_store::Error::NotFound { .. }) => Ok(None),
                Err(e) => Err(other(e)),
            }
        })
    }

    /// Writes `bytes` at `key` unless an object is there already: true
    /// when this call created it.
    fn put_new(&self, key: &Key, bytes: Vec<u8>) -> io::Result<bool> {
        let store = self.store.clone();
        let key = key.clone();
        self.block(async move {
            let opts = PutOptions {
                mode: PutMode::Create,
                ..PutOptions::default()
            };
            match store.put_opts(&key, PutPayload::from(bytes), opts).await {
                Ok(_) => Ok(true),
                Err(
                    object_store::Error::AlreadyExists { .. }
                    | object_store::Error::Precondition { .. },
                ) => Ok(false),
                Err(e) => Err(other(e)),
            }
        })
    }

    fn put(&self, key: &Key, bytes: Vec<u8>) -> io::Result<()> {
        let store = self.store.clone();
        let key = key.clone();
        self.block(async move {
            store
                .put(&key, PutPayload::from(bytes))
                .await
                .map(|_| ())
                .map_err(other)
        })
    }

    /// Writes `bytes` at `key`, leaving an equal object in place (another
    /// replica wrote the same upload) and replacing a different one.
    fn put_same(&self, key: &Key, bytes: Vec<u8>) -> io::Result<()> {
        if self.put_new(key, bytes.clone())? {
            return Ok(());
        }
        if self.get(key.clone())?.as_deref() == Some(&bytes[..]) {
            tracing::debug!(key = %key, "object already stored by another writer");
            return Ok(());
        }
        self.put(key, bytes)
    }

    /// Every object key and size under `textures/`.
    fn list(&self) -> io::Result<Vec<(String, u64)>> {
        self.list_under(self.textures_prefix())
    }

    /// The key of region texture `id`'s definition.
    fn region_key(&self, id: &str) -> Key {
        Key::from(format!("{}{id}.json", self.regions_prefix()))
    }

    fn regions_prefix(&self) -> String {
        if self.prefix.is_empty() {
            "regions/".to_string()
        } else {
            format!("{}/regions/", self.prefix)
        }
    }

    /// Every object key (less `root`) and size under `root`.
    fn list_under(&self, root: String) -> io::Result<Vec<(String, u64)>> {
        let store = self.store.clone();
        let prefix = Key::from(root.clone());
        self.block(async move {
            let objects: Vec<_> = store
                .list(Some(&prefix))
                .try_collect()
                .await
                .map_err(other)?;
            Ok(objects
                .into_iter()
                .filter_map(|o| {
                    let rest = o.location.as_ref().strip_prefix(&root)?.to_string();
                    Some((rest, o.size))
                })
                .collect())
        })
    }

    fn delete(&self, key: Key) -> io::Result<()> {
        let store = self.store.clone();
        self.block(async move {
            match store.delete(&key).await {
                Ok(()) | Err(object_store::Error::NotFound { .. }) => Ok(()),
                Err(e) => Err(other(e)),
            }
        })
    }

    fn read_meta(&self, id: &str) -> io::Result<Option<Found>> {
        let key = self.key(id, "meta.json");
        let Some(bytes) = self.get(key.clone())? else {
            return Ok(None);
        };
        match parse_meta(id, &bytes) {
            Ok(meta) => Ok(Some(Found {
                meta,
                location: format!("s3://{}", key),
            })),
            Err(e) => {
                tracing::warn!(key = %key, error = %e, "skipping unreadable texture metadata");
                Ok(None)
            }
        }
    }

    /// Removes every object of texture `id` but its metadata.
    fn remove_files(&self, id: &str) -> io::Result<()> {
        for name in WRITTEN.iter().filter(|n| **n != "meta.json") {
            self.delete(self.key(id, name))?;
        }
        Ok(())
    }
}

impl Storage for ObjectStorage {
    fn location(&self) -> String {
        self.url.clone()
    }

    fn shared(&self) -> bool {
        true
    }

    fn lock(&self) -> MutexGuard<'_, ()> {
        self.lock.lock()
    }

    fn bytes(&self) -> io::Result<u64> {
        Ok(self.list()?.iter().map(|(_, size)| size).sum())
    }

    /// Another replica may be storing the same upload at the same time:
    /// the exemplars are written conditionally, and metadata already there
    /// for the same content is kept (the first writer's).
    fn create(&self, meta: &StoredMeta, planes: &Planes) -> io::Result<()> {
        for (name, png) in plane_files(planes)? {
            self.put_same(&self.key(&meta.id, &name), png)?;
        }
        let key = self.key(&meta.id, "meta.json");
        let json = serde_json::to_vec_pretty(meta).map_err(io::Error::other)?;
        if self.put_new(&key, json.clone())? {
            return Ok(());
        }
        match self.read_meta(&meta.id)? {
            Some(found) if found.meta.content_hash == meta.content_hash => {
                tracing::info!(id = %meta.id, "texture stored already by another replica");
                Ok(())
            }
            // A fixed id (the bundled texture) of other content: replaced.
            _ => self.put(&key, json),
        }
    }

    fn write_meta(&self, meta: &StoredMeta) -> io::Result<()> {
        let key = self.key(&meta.id, "meta.json");
        let json = serde_json::to_vec_pretty(meta).map_err(io::Error::other)?;
        for _ in 0..META_RETRIES {
            let store = self.store.clone();
            let k = key.clone();
            let body = json.clone();
            let written = self.block(async move {
                let current = match store.head(&k).await {
                    Ok(m) => m,
                    Err(object_store::Error::NotFound { .. }) => return Ok(None),
                    Err(e) => return Err(other(e)),
                };
                let opts = PutOptions {
                    mode: PutMode::Update(UpdateVersion {
                        e_tag: current.e_tag,
                        version: current.version,
                    }),
                    ..PutOptions::default()
                };
                match store.put_opts(&k, PutPayload::from(body), opts).await {
                    Ok(_) => Ok(Some(true)),
                    Err(object_store::Error::Precondition { .. }) => Ok(Some(false)),
                    Err(object_store::Error::NotFound { .. }) => Ok(None),
                    Err(e) => Err(other(e)),
                }
            })?;
            match written {
                Some(true) => return Ok(()),
                Some(false) => continue,
                None => {
                    // Deleted by another replica: what this one wrote
                    // since goes too.
                    self.remove_files(&meta.id)?;
                    return Err(io::Error::new(
                        io::ErrorKind::NotFound,
                        format!("texture `{}` was deleted", meta.id),
                    ));
                }
            }
        }
        Err(io::Error::other(format!(
            "{key} kept changing under {META_RETRIES} conditional writes"
        )))
    }

    /// Candidates already there (another replica's precompute) are kept
    /// when they load and pass their checksum.
    fn write_candidates(&self, id: &str, c: &Candidates) -> io::Result<()> {
        let key = self.key(id, "candidates.stx");
        let bytes = candidates_bytes(c)?;
        if self.put_new(&key, bytes.clone())? {
            return Ok(());
        }
        let kept = self
            .get(key.clone())?
            .is_some_and(|b| Candidates::load(&b).is_ok());
        if kept {
            tracing::info!(id, "candidates stored already by another replica");
            Ok(())
        } else {
            self.put(&key, bytes)
        }
    }

    fn read_candidates(&self, id: &str) -> io::Result<Vec<u8>> {
        self.get(self.key(id, "candidates.stx"))?.ok_or_else(|| {
            io::Error::new(
                io::ErrorKind::NotFound,
                format!("texture `{id}` has no stored candidates"),
            )
        })
    }

    fn read_planes(&self, meta: &StoredMeta) -> solidtex_core::Result<Planes> {
        planes_from(meta, |name| self.get(self.key(&meta.id, name)))
    }

    /// The metadata goes first: from then on no replica finds the texture.
    fn remove(&self, id: &str) -> io::Result<()> {
        self.delete(self.key(id, "meta.json"))?;
        if let Err(e) = self.remove_files(id) {
            tracing::warn!(id, error = %e, "could not remove every object of a deleted texture");
        }
        Ok(())
    }

    fn scan(&self) -> io::Result<Vec<Found>> {
        let mut out = Vec::new();
        for id in self.ids()? {
            out.extend(self.read_meta(&id)?);
        }
        oldest_first(&mut out);
        Ok(out)
    }

    fn find(&self, id: &str) -> io::Result<Option<Found>> {
        if !valid_id(id) {
            return Ok(None);
        }
        self.read_meta(id)
    }

    fn ids(&self) -> io::Result<Vec<String>> {
        let mut ids: Vec<String> = self
            .list()?
            .into_iter()
            .filter_map(|(rest, _)| {
                let id = rest.strip_suffix("/meta.json")?;
                valid_id(id).then(|| id.to_string())
            })
            .collect();
        ids.sort();
        Ok(ids)
    }

    fn write_region(&self, id: &str, json: &[u8]) -> io::Result<()> {
        self.put_same(&self.region_key(id), json.to_vec())
    }

    fn read_region(&self, id: &str) -> io::Result<Option<Vec<u8>>> {
        if !valid_id(id) {
            return Ok(None);
        }
        self.get(self.region_key(id))
    }

    fn remove_region(&self, id: &str) -> io::Result<()> {
        self.delete(self.region_key(id))
    }

    fn region_ids(&self) -> io::Result<Vec<String>> {
        let mut ids: Vec<String> = self
            .list_under(self.regions_prefix())?
            .into_iter()
            .filter_map(|(rest, _)| {
                let id = rest.strip_suffix(".json")?;
                valid_id(id).then(|| id.to_string())
            })
            .collect();
        ids.sort();
        Ok(ids)
    }
}
