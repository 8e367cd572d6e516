//! The textures the server knows: their status, precompute progress and,
//! once ready, the [`Texture`] that answers requests.
//!
//! A texture is created `pending` by an upload (or found so at start),
//! precomputed in the background — at most `max_precomputes` at once, on
//! a blocking thread driving a rayon pool of its own, so uploads never
//! starve voxel requests of synthesis threads — and becomes `ready` once
//! its candidates are durable in the `Storage`, or `failed` with a reason.
//! Uploading content that is already known returns the existing texture;
//! uploading a failed one tries again.

use super::metrics::{Metrics, OutcomeLabels};
use super::panics::panic_message;
use super::spec::{ExemplarInfo, Planes, TextureParams, TextureSpec};
use super::store::{Found, META_VERSION, Storage, StoredMeta, StoredStatus};
use crate::peak_alloc::{self, Meter};
use parking_lot::{Mutex, RwLock};
use solidtex_core::Layout;
use solidtex_core::{CancelFlag, Cancelled, run_cancellable};
use solidtex_core::{Candidates, Stage, Texture, TileCache};
use std::collections::HashMap;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, AtomicUsize, Ordering};
use std::time::{Instant, SystemTime, UNIX_EPOCH};
use tokio::sync::Semaphore;

/// Why the registry refuses a request.
#[derive(Debug, thiserror::Error)]
pub(crate) enum RegistryError {
    /// No texture has this id.
    #[error("no texture with id `{0}`")]
    UnknownTexture(String),
    /// The texture is evicted from memory and being loaded back.
    #[error("texture `{0}` is being loaded back into memory")]
    Loading(String),
    /// The texture is still being precomputed.
    #[error("texture `{id}` is still being precomputed ({:.0}%)", .progress * 100.0)]
    Pending {
        /// Its id.
        id: String,
        /// Its precompute progress, 0..=1.
        progress: f32,
    },
    /// The texture's precompute failed.
    #[error("texture `{id}` failed to precompute: {reason}")]
    Failed {
        /// Its id.
        id: String,
        /// Why.
        reason: String,
    },
    /// Too many precomputes wait already.
    #[error("precompute queue is full")]
    QueueFull,
    /// The upload's precompute is estimated to need more memory than
    /// precomputes may take.
    #[error("precomputing this texture is estimated to take {estimated} bytes, over {bound}")]
    PrecomputeTooLarge {
        /// Estimated peak bytes.
        estimated: u64,
        /// The bound, bytes.
        bound: u64,
    },
    /// No more textures are kept until some are deleted.
    #[error("{0}")]
    StorageFull(String),
    /// The stored textures are still being brought back after a start.
    #[error("the server is starting: its stored textures are still being loaded")]
    Starting,
    /// Something failed inside the server (the data directory, a task).
    #[error("{0}")]
    Internal(String),
}

/// Where a texture stands.
#[derive(Clone)]
pub(crate) enum Status {
    /// Precompute queued or running.
    Pending,
    /// Ready to synthesize.
    Ready(Texture),
    /// Ready, but evicted from memory to keep within the server's bound;
    /// loaded again from disk when asked for.
    Stored,
    /// Precompute failed.
    Failed(String),
}

/// One texture.
pub(crate) struct Entry {
    /// Id in URLs.
    pub id: String,
    /// The uploaded file's name, for people; not part of the id.
    pub name: Option<String>,
    /// Content hash of exemplars and parameters.
    pub content_hash: String,
    /// Creation time, seconds since the Unix epoch.
    pub created: u64,
    /// Exemplar size and plane count.
    pub exemplar: ExemplarInfo,
    /// Parameters.
    pub params: TextureParams,
    /// How the exemplars are laid on the planes (`None` where the
    /// parameters cannot apply to the exemplars, which an upload refuses).
    pub layout: Option<Layout>,
    analysis_hash: String,
    candidates: Mutex<Option<Arc<Candidates>>>,
    planes: Planes,
    status: RwLock<Status>,
    progress: AtomicU32,
    stage: Mutex<&'static str>,
    precompute_seconds: Mutex<Option<f64>>,
    /// Heap bytes its precompute is expected to peak at.
    pub precompute_estimate: u64,
    /// Heap bytes its precompute peaked at, when measured.
    precompute_peak: Mutex<Option<u64>>,
    deleted: AtomicBool,
    /// Set when it is deleted or replaced: stops its precompute.
    cancel: CancelFlag,
    /// Woken whenever the status changes.
    settled: tokio::sync::Notify,
    /// When it was last asked for (the registry's use counter).
    last_used: AtomicU64,
    /// Its candidates are on disk, so it may be evicted from memory.
    on_disk: AtomicBool,
    /// Highest level of detail, known once ready.
    max_lod: AtomicU32,
    /// Serialises loading it back from disk.
    loading: Mutex<()>,
    /// Since when its metadata is known to be in the storage (a texture
    /// missing from a listing that started later was deleted).
    stored_since: Mutex<Option<Instant>>,
}

impl Entry {
    fn new(id: String, content_hash: String, created: u64, spec: TextureSpec) -> Entry {
        let (width, height) = spec.planes.size();
        let planes_n = match spec.planes {
            Planes::Single(_) => 1,
            Planes::Triple(_) => 3,
        };
        let analysis_hash = spec.analysis_hash();
        let layout = spec.layout().ok();
        // Turned planes differ from each other, so the search runs per
        // plane, as for three exemplars.
        let turned = layout
            .as_ref()
            .is_some_and(|l| l.arrangement.rotate != [0; 3]);
        let precompute_estimate = solidtex_core::Candidates::estimated_peak_bytes(
            width,
            height,
            planes_n == 3 || turned,
            &spec.params.analysis,
        );
        Entry {
            id,
            name: None,
            content_hash,
            analysis_hash,
            candidates: Mutex::new(None),
            created,
            exemplar: ExemplarInfo {
                width,
                height,
                planes: planes_n,
                feature_masks: spec.planes.feature_masks(),
            },
            params: spec.params,
            layout,
            planes: spec.planes,
            status: RwLock::new(Status::Pending),
            progress: AtomicU32::new(0f32.to_bits()),
            stage: Mutex::new("queued"),
            precompute_seconds: Mutex::new(None),
            precompute_estimate,
            precompute_peak: Mutex::new(None),
            deleted: AtomicBool::new(false),
            cancel: CancelFlag::new(),
            settled: tokio::sync::Notify::new(),
            last_used: AtomicU64::new(0),
            on_disk: AtomicBool::new(false),
            max_lod: AtomicU32::new(0),
            loading: Mutex::new(()),
            stored_since: Mutex::new(None),
        }
    }

    /// The entry with a display name.
    fn named(mut self, name: Option<String>) -> Entry {
        self.name = name;
        self
    }

    /// Marks it deleted (or replaced) and stops its precompute, if one
    /// runs, at its next check: its memory and slot are freed within a
    /// fraction of a second.
    fn discard(&self) {
        self.deleted.store(true, Ordering::SeqCst);
        self.cancel.cancel();
    }

    /// The xy exemplar (the only one of a single-exemplar texture).
    pub fn exemplar_xy(&self) -> &solidtex_core::Exemplar {
        self.planes.named()[0].1
    }

    /// What the texture is made of: its exemplars and parameters.
    pub fn spec(&self) -> TextureSpec {
        TextureSpec {
            planes: self.planes.clone(),
            params: self.params.clone(),
        }
    }

    /// An entry for a texture made of this one (a region texture, `id`
    /// of content `content_hash`): this one's exemplars and parameters,
    /// ready, never registered.
    pub(crate) fn standing_for(&self, id: String, content_hash: String, t: Texture) -> Entry {
        Entry {
            id,
            name: None,
            content_hash,
            created: self.created,
            exemplar: self.exemplar,
            params: self.params.clone(),
            layout: self.layout,
            analysis_hash: self.analysis_hash.clone(),
            candidates: Mutex::new(None),
            planes: self.planes.clone(),
            progress: AtomicU32::new(1f32.to_bits()),
            stage: Mutex::new("ready"),
            precompute_seconds: Mutex::new(None),
            precompute_estimate: 0,
            precompute_peak: Mutex::new(None),
            deleted: AtomicBool::new(false),
            cancel: CancelFlag::new(),
            settled: tokio::sync::Notify::new(),
            last_used: AtomicU64::new(0),
            on_disk: AtomicBool::new(true),
            max_lod: AtomicU32::new(t.max_lod()),
            loading: Mutex::new(()),
            stored_since: Mutex::new(None),
            status: RwLock::new(Status::Ready(t)),
        }
    }

    /// Current status.
    pub fn status(&self) -> Status {
        self.status.read().clone()
    }

    fn candidates(&self) -> Option<Arc<Candidates>> {
        self.candidates.lock().clone()
    }

    fn set_ready(&self, c: Arc<Candidates>, t: Texture) {
        self.max_lod.store(t.max_lod(), Ordering::Relaxed);
        *self.candidates.lock() = Some(c);
        self.set_status(Status::Ready(t));
    }

    /// Highest level of detail served (meaningful once ready).
    pub fn max_lod(&self) -> u32 {
        self.max_lod.load(Ordering::Relaxed)
    }

    /// Drops its candidates from memory; requests in flight keep theirs.
    fn evict(&self) {
        *self.candidates.lock() = None;
        self.set_status(Status::Stored);
    }

    fn set_status(&self, s: Status) {
        *self.status.write() = s;
        self.settled.notify_waiters();
    }

    /// Waits until the texture is no longer pending, or until `deadline`.
    pub async fn settle(&self, deadline: tokio::time::Instant) {
        loop {
            // Registered before the status is read, so a change between
            // the two still wakes this waiter.
            let changed = self.settled.notified();
            tokio::pin!(changed);
            changed.as_mut().enable();
            if !matches!(self.status(), Status::Pending) {
                return;
            }
            if tokio::time::timeout_at(deadline, changed).await.is_err() {
                return;
            }
        }
    }

    /// Precompute progress 0..=1 (1 once ready).
    pub fn progress(&self) -> f32 {
        f32::from_bits(self.progress.load(Ordering::Relaxed))
    }

    /// Current precompute stage name.
    pub fn stage(&self) -> &'static str {
        *self.stage.lock()
    }

    /// Seconds the precompute took, when it ran in this process or was
    /// recorded by an earlier one.
    pub fn precompute_seconds(&self) -> Option<f64> {
        *self.precompute_seconds.lock()
    }

    /// Heap bytes the precompute peaked at, when it ran in this process
    /// under the counting allocator or was recorded by an earlier one.
    pub fn precompute_peak(&self) -> Option<u64> {
        *self.precompute_peak.lock()
    }

    fn set_progress(&self, stage: &'static str, fraction: f32) {
        *self.stage.lock() = stage;
        // Never goes back (stages report their own fractions).
        let new = fraction.clamp(0.0, 1.0);
        let _ = self
            .progress
            .fetch_update(Ordering::Relaxed, Ordering::Relaxed, |old| {
                (new > f32::from_bits(old)).then_some(new.to_bits())
            });
    }

    fn meta(&self) -> StoredMeta {
        let (status, reason) = match self.status() {
            Status::Pending => (StoredStatus::Pending, None),
            Status::Ready(_) | Status::Stored => (StoredStatus::Ready, None),
            Status::Failed(r) => (StoredStatus::Failed, Some(r)),
        };
        StoredMeta {
            version: META_VERSION,
            id: self.id.clone(),
            name: self.name.clone(),
            content_hash: self.content_hash.clone(),
            created: self.created,
            exemplar: self.exemplar,
            params: self.params.to_flat(),
            status,
            reason,
            precompute_seconds: self.precompute_seconds(),
            precompute_peak_bytes: self.precompute_peak(),
        }
    }
}

/// Overall progress from a stage and its fraction (stages weighted by their
/// usual share of the time).
fn overall_progress(stage: Stage, f: f32) -> (&'static str, f32) {
    let (name, start, span) = match stage {
        Stage::Analysis => ("analysis", 0.0, 0.05),
        Stage::Search => ("search", 0.05, 0.4),
        Stage::Coherence => ("coherence", 0.45, 0.05),
        Stage::Finish => ("finish", 0.5, 0.1),
        Stage::Reference => ("reference", 0.6, 0.4),
    };
    (name, (start + span * f.clamp(0.0, 1.0)).min(0.999))
}

/// What an upload found.
pub(crate) enum Submitted {
    /// The texture exists and is ready.
    Known(Arc<Entry>),
    /// The texture is (now) being precomputed.
    Pending(Arc<Entry>),
}

/// All textures of a server.
pub struct Registry {
    map: RwLock<HashMap<String, Arc<Entry>>>,
    store: Arc<dyn Storage>,
    cache: Arc<TileCache>,
    metrics: Arc<Metrics>,
    slots: Arc<Semaphore>,
    pool: rayon::ThreadPool,
    pending: AtomicUsize,
    max_pending: usize,
    /// Uploaded textures kept at most (the bundled one not counted).
    max_textures: usize,
    /// Bytes of candidates kept in memory; beyond it the least recently
    /// used textures are evicted.
    max_resident_bytes: u64,
    /// Counts uses, to find the least recently used texture.
    uses: AtomicU64,
    /// Bytes the textures may take on disk.
    max_stored_bytes: u64,
    /// Estimated peak bytes of the precomputes running at once, at most.
    max_precompute_bytes: u64,
    /// Units of [`MEMORY_UNIT`] bytes of that bound not taken by a running
    /// precompute.
    precompute_memory: Arc<Semaphore>,
    /// Bytes taken from it now, and the most ever.
    precompute_reserved: AtomicU64,
    precompute_reserved_peak: AtomicU64,
    /// Counts the allocations of the precompute pool's threads.
    meter: Option<&'static Meter>,
    /// Serialises taking up textures found in a shared storage.
    adopting: Mutex<()>,
    /// True once every stored texture found at start is brought back.
    recovered: tokio::sync::watch::Sender<bool>,
    /// How long a request for a texture not brought back yet, or an
    /// upload, waits for the start to finish before it is answered 503.
    startup_wait: std::time::Duration,
}

/// A stored texture read and checked, its candidates not loaded yet.
struct Restoring {
    entry: Arc<Entry>,
    status: StoredStatus,
    reason: Option<String>,
}

/// Granularity of the precompute memory bound.
const MEMORY_UNIT: u64 = 1 << 20;

/// Units of [`MEMORY_UNIT`] in a bound of `bytes`, as many as a semaphore
/// and one acquisition can hold.
fn memory_units(bytes: u64) -> u64 {
    (bytes / MEMORY_UNIT).clamp(1, u64::from(u32::MAX))
}

/// Disk bytes a texture takes per exemplar pixel and plane once its
/// candidates are written (a 128² exemplar: about 6 MB), for admitting an
/// upload before its candidates exist.
const STORED_BYTES_PER_PIXEL: u64 = 400;

/// Precompute memory counted as reserved while it lives.
struct Reserved<'a> {
    registry: &'a Registry,
    bytes: u64,
}

impl Drop for Reserved<'_> {
    fn drop(&mut self) {
        let r = self.registry;
        let now = r
            .precompute_reserved
            .fetch_sub(self.bytes, Ordering::SeqCst)
            - self.bytes;
        r.metrics.precompute_reserved_bytes.set(now as i64);
    }
}

/// Seconds since the Unix epoch.
pub(crate) fn now() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_secs())
        .unwrap_or(0)
}

impl Registry {
    /// An empty registry over `store`; precomputes run on `pool`.
    pub(crate) fn new(
        store: Arc<dyn Storage>,
        cache: Arc<TileCache>,
        metrics: Arc<Metrics>,
        max_precomputes: u32,
        precompute_queue: u32,
        pool: rayon::ThreadPool,
    ) -> Registry {
        Registry {
            pool,
            map: RwLock::new(HashMap::new()),
            store,
            cache,
            metrics,
            slots: Arc::new(Semaphore::new(max_precomputes.max(1) as usize)),
            pending: AtomicUsize::new(0),
            max_pending: (max_precomputes + precompute_queue) as usize,
            max_textures: usize::MAX,
            max_stored_bytes: u64::MAX,
            max_resident_bytes: u64::MAX,
            uses: AtomicU64::new(0),
            max_precompute_bytes: u64::MAX,
            precompute_memory: Arc::new(Semaphore::new(memory_units(u64::MAX) as usize)),
            precompute_reserved: AtomicU64::new(0),
            precompute_reserved_peak: AtomicU64::new(0),
            meter: None,
            adopting: Mutex::new(()),
            recovered: tokio::sync::watch::Sender::new(false),
            startup_wait: std::time::Duration::ZERO,
        }
    }

    /// The same registry, letting requests wait up to `wait` for the
    /// stored textures to be brought back after a start.
    pub(crate) fn with_startup_wait(mut self, wait: std::time::Duration) -> Registry {
        self.startup_wait = wait;
        self
    }

    /// Whether every texture stored at start has been brought back.
    pub(crate) fn recovered(&self) -> bool {
        *self.recovered.borrow()
    }

    /// Waits until every texture stored at start has been brought back.
    pub async fn wait_recovered(&self) {
        let mut rx = self.recovered.subscribe();
        // The sender lives as long as `self`: this cannot fail.
        let _ = rx.wait_for(|done| *done).await;
    }

    /// Waits up to the start-up wait for the stored textures to be brought
    /// back; [`RegistryError::Starting`] when they are not by then.
    pub(crate) async fn await_recovered(&self) -> Result<(), RegistryError> {
        if self.recovered() {
            return Ok(());
        }
        let _ = tokio::time::timeout(self.startup_wait, self.wait_recovered()).await;
        if self.recovered() {
            Ok(())
        } else {
            Err(RegistryError::Starting)
        }
    }

    /// Marks the stored textures as brought back, waking those waiting.
    pub(crate) fn set_recovered(&self) {
        self.recovered.send_replace(true);
    }

    /// The same registry, running precomputes only while their estimated
    /// peaks (see [`solidtex_core::Candidates::estimated_peak_bytes`]) add up to at
    /// most `bytes`, refusing uploads whose own estimate is over it, and
    /// measuring each precompute's peak with `meter` (the precompute
    /// pool's threads must be attached to it).
    pub(crate) fn with_precompute_memory(mut self, bytes: u64, meter: &'static Meter) -> Registry {
        self.max_precompute_bytes = bytes;
        self.precompute_memory = Arc::new(Semaphore::new(memory_units(bytes) as usize));
        self.meter = Some(meter);
        self
    }

    /// Estimated peak bytes of the precomputes running now, and the most
    /// at any time.
    pub fn precompute_reserved(&self) -> (u64, u64) {
        (
            self.precompute_reserved.load(Ordering::SeqCst),
            self.precompute_reserved_peak.load(Ordering::SeqCst),
        )
    }

    /// The same registry, keeping at most `bytes` of candidates in memory:
    /// beyond it, the least recently used textures are evicted and loaded
    /// again from disk when next asked for.
    pub(crate) fn with_memory_limit(mut self, bytes: u64) -> Registry {
        self.max_resident_bytes = bytes;
        self
    }

    /// The texture `id` ready to synthesize, loaded back from disk first
    /// when it was evicted from memory.
    pub(crate) async fn loaded(
        self: &Arc<Self>,
        id: &str,
    ) -> Result<(Arc<Entry>, Texture), RegistryError> {
        // A texture evicted again between its load and its use (memory
        // contended by many) is loaded again, a few times at most.
        for _ in 0..3 {
            let Some(e) = self.get(id) else { break };
            if !matches!(e.status(), Status::Stored) {
                break;
            }
            let this = self.clone();
            tokio::task::spawn_blocking(move || this.reload(&e))
                .await
                .map_err(|e| RegistryError::Internal(e.to_string()))??;
        }
        self.ready(id)
    }

    /// Loads an evicted texture's candidates back from disk (blocking).
    fn reload(&self, entry: &Arc<Entry>) -> Result<(), RegistryError> {
        let _one = entry.loading.lock();
        if !matches!(entry.status(), Status::Stored) {
            return Ok(());
        }
        let (c, t) = self
            .load_ready(entry)
            .map_err(|e| RegistryError::Internal(format!("loading texture `{}`: {e}", entry.id)))?;
        entry.set_ready(c, t);
        let now = self.uses.fetch_add(1, Ordering::Relaxed) + 1;
        entry.last_used.store(now, Ordering::Relaxed);
        self.metrics.textures_loaded.inc();
        tracing::info!(id = %entry.id, "texture loaded back into memory");
        self.keep_within_memory(&entry.id);
        Ok(())
    }

    /// Evicts the least recently used ready textures (never `keep`, never
    /// one whose candidates are not on disk) until the candidates in memory
    /// fit the bound.
    fn keep_within_memory(&self, keep: &str) {
        if self.max_resident_bytes == u64::MAX {
            return;
        }
        let mut resident: Vec<(u64, u64, Arc<Entry>)> = self
            .map
            .read()
            .values()
            .filter(|e| matches!(e.status(), Status::Ready(_)))
            .filter_map(|e| {
                let bytes = e.candidates()?.memory_bytes().1 as u64;
                Some((e.last_used.load(Ordering::Relaxed), bytes, e.clone()))
            })
            .collect();
        let mut total: u64 = resident.iter().map(|r| r.1).sum();
        resident.sort_by_key(|r| r.0);
        for (_, bytes, e) in resident {
            if total <= self.max_resident_bytes {
                break;
            }
            if e.id == keep || !e.on_disk.load(Ordering::Relaxed) {
                continue;
            }
            e.evict();
            total = total.saturating_sub(bytes);
            tracing::info!(id = %e.id, bytes, "texture evicted from memory");
        }
    }

    /// Bytes of candidates in memory now (candidates shared by textures
    /// that differ in synthesis parameters only are counted once).
    pub(crate) fn resident_candidate_bytes(&self) -> u64 {
        let map = self.map.read();
        let mut seen = Vec::new();
        let mut total = 0;
        for c in map.values().filter_map(|e| e.candidates()) {
            if !seen.iter().any(|s| Arc::ptr_eq(s, &c)) {
                total += c.memory_bytes().1 as u64;
                seen.push(c);
            }
        }
        total
    }

    /// The same registry, refusing uploads ([`RegistryError::StorageFull`]) beyond
    /// `max_textures` textures or `max_stored_bytes` bytes on disk.
    pub(crate) fn with_storage_limits(
        mut self,
        max_textures: usize,
        max_stored_bytes: u64,
    ) -> Registry {
        self.max_textures = max_textures;
        self.max_stored_bytes = max_stored_bytes;
        self
    }

    /// Where the textures are kept.
    pub(crate) fn store(&self) -> Arc<dyn Storage> {
        self.store.clone()
    }

    /// Where the textures are kept, for people.
    pub(crate) fn location(&self) -> String {
        self.store.location()
    }

    /// The shared tile cache.
    pub(crate) fn cache(&self) -> &Arc<TileCache> {
        &self.cache
    }

    /// The texture `id`, if known.
    pub(crate) fn get(&self, id: &str) -> Option<Arc<Entry>> {
        self.map.read().get(id).cloned()
    }

    /// Every texture, oldest first.
    pub(crate) fn list(&self) -> Vec<Arc<Entry>> {
        let mut v: Vec<Arc<Entry>> = self.map.read().values().cloned().collect();
        v.sort_by(|a, b| (a.created, &a.id).cmp(&(b.created, &b.id)));
        v
    }

    /// The texture `id` ready to synthesize, or why it is not.
    pub(crate) fn ready(&self, id: &str) -> Result<(Arc<Entry>, Texture), RegistryError> {
        let e = self
            .get(id)
            .ok_or_else(|| RegistryError::UnknownTexture(id.to_string()))?;
        match e.status() {
            Status::Ready(t) => {
                let now = self.uses.fetch_add(1, Ordering::Relaxed) + 1;
                e.last_used.store(now, Ordering::Relaxed);
                Ok((e, t))
            }
            Status::Stored => Err(RegistryError::Loading(id.to_string())),
            Status::Pending => Err(RegistryError::Pending {
                id: id.to_string(),
                progress: e.progress(),
            }),
            Status::Failed(reason) => Err(RegistryError::Failed {
                id: id.to_string(),
                reason,
            }),
        }
    }

    fn update_gauges(&self) {
        let (mut p, mut r, mut f) = (0, 0, 0);
        for e in self.map.read().values() {
            match e.status() {
                Status::Pending => p += 1,
                Status::Ready(_) | Status::Stored => r += 1,
                Status::Failed(_) => f += 1,
            }
        }
        self.metrics.set_textures(p, r, f);
    }

    /// Registers an upload under its content hash (or under `id` when
    /// given, as for `default`) and starts its precompute unless it is
    /// known already. Fails when too many precomputes wait, or when it
    /// would not fit the memory or storage bounds.
    pub(crate) async fn submit(
        self: &Arc<Self>,
        id: Option<&str>,
        spec: TextureSpec,
        name: Option<String>,
    ) -> Result<Submitted, RegistryError> {
        let fixed_id = id.is_some();
        // An upload may be a texture not brought back yet: known, not new.
        if !fixed_id {
            self.await_recovered().await?;
        }
        let hash = spec.content_hash();
        let id = id.map(str::to_string).unwrap_or_else(|| hash.clone());
        let (w, h) = spec.planes.size();
        let planes = spec.planes.named().len() as u64;
        let estimate = (u64::from(w) * u64::from(h))
            .saturating_mul(planes)
            .saturating_mul(STORED_BYTES_PER_PIXEL);
        let stored = if fixed_id || self.max_stored_bytes == u64::MAX {
            0
        } else {
            let store = self.store.clone();
            tokio::task::spawn_blocking(move || store.bytes())
                .await
                .map_err(|e| RegistryError::Internal(e.to_string()))?
                .map_err(|e| RegistryError::Internal(format!("reading the data directory: {e}")))?
        };
        let entry = {
            let mut map = self.map.write();
            // The same content under another id (the bundled texture, whose
            // id is not its hash) is that texture, not a copy of it.
            let same = map.get(&id).filter(|e| e.content_hash == hash).or_else(|| {
                map.values().find(|e| {
                    !fixed_id && e.content_hash == hash && !matches!(e.status(), Status::Failed(_))
                })
            });
            if let Some(e) = same {
                match e.status() {
                    Status::Ready(_) | Status::Stored => {
                        return Ok(Submitted::Known(e.clone()));
                    }
                    Status::Pending => return Ok(Submitted::Pending(e.clone())),
                    Status::Failed(_) => {}
                }
            }
            // Server-chosen ids (the bundled default) are never refused.
            // The check and the reservation happen under the map's lock, so
            // concurrent uploads cannot all pass the check before any of
            // them is counted.
            if !fixed_id && self.pending.load(Ordering::SeqCst) >= self.max_pending {
                self.metrics.jobs_rejected.inc();
                return Err(RegistryError::QueueFull);
            }
            if !fixed_id {
                let need = solidtex_core::Candidates::estimated_peak_bytes(
                    w,
                    h,
                    planes == 3,
                    &spec.params.analysis,
                );
                if need > self.max_precompute_bytes {
                    return Err(RegistryError::PrecomputeTooLarge {
                        estimated: need,
                        bound: self.max_precompute_bytes,
                    });
                }
                let uploaded = map.values().filter(|e| e.id == e.content_hash).count();
                if uploaded >= self.max_textures {
                    return Err(RegistryError::StorageFull(format!(
                        "this server keeps at most {} textures (--max-textures); delete one first",
                        self.max_textures
                    )));
                }
                // Precomputes in flight have not written their candidates
                // yet: count them at the estimate too.
                let pending = self.pending.load(Ordering::SeqCst) as u64;
                let needed = stored.saturating_add(estimate.saturating_mul(pending + 1));
                if needed > self.max_stored_bytes {
                    return Err(RegistryError::StorageFull(format!(
                        "the textures take {stored} bytes on disk and this one would need about \
                         {estimate} more; the limit is {} (--max-stored-bytes); delete some first",
                        self.max_stored_bytes
                    )));
                }
            }
            self.reserve_precompute();
            if let Some(old) = map.get(&id) {
                old.discard();
            }
            let e = Arc::new(Entry::new(id.clone(), hash, now(), spec).named(name));
            map.insert(id.clone(), e.clone());
            e
        };
        self.update_gauges();
        let store = self.store.clone();
        let meta = entry.meta();
        let planes = entry.planes.clone();
        let written = tokio::task::spawn_blocking(move || {
            let _g = store.lock();
            store.create(&meta, &planes)
        })
        .await;
        let failure = match written {
            Ok(Ok(())) => {
                *entry.stored_since.lock() = Some(Instant::now());
                None
            }
            Ok(Err(e)) => Some(e.to_string()),
            Err(e) => Some(e.to_string()),
        };
        if let Some(why) = failure {
            let mut map = self.map.write();
            if map.get(&id).is_some_and(|e| Arc::ptr_eq(e, &entry)) {
                map.remove(&id);
            }
            drop(map);
            self.release_precompute();
            self.update_gauges();
            return Err(RegistryError::Internal(format!(
                "could not store the texture: {why}"
            )));
        }
        self.start_precompute(entry.clone());
        Ok(Submitted::Pending(entry))
    }

    /// Removes texture `id` and its files. The files go first: when they
    /// cannot be removed the texture stays as it was.
    pub(crate) async fn delete(self: &Arc<Self>, id: &str) -> Result<(), RegistryError> {
        let entry = self
            .find(id)
            .await?
            .ok_or_else(|| RegistryError::UnknownTexture(id.to_string()))?;
        let this = self.clone();
        let id_for_error = id.to_string();
        let id = id.to_string();
        let found = tokio::task::spawn_blocking(move || {
            // Under the store's lock, as a precompute's final writes are,
            // so that none lands after the removal.
            let _g = this.store.lock();
            // A concurrent delete or re-upload may have replaced it by now;
            // the new one owns the directory.
            let (present, current) = {
                let map = this.map.read();
                let e = map.get(&id);
                (e.is_some(), e.is_some_and(|e| Arc::ptr_eq(e, &entry)))
            };
            if !current {
                return Ok(present);
            }
            this.store.remove(&id)?;
            let mut map = this.map.write();
            if map.get(&id).is_some_and(|e| Arc::ptr_eq(e, &entry)) {
                map.remove(&id);
            }
            entry.discard();
            Ok::<_, std::io::Error>(true)
        })
        .await
        .map_err(|e| RegistryError::Internal(e.to_string()))?
        .map_err(|e| {
            RegistryError::Internal(format!("could not remove the texture's files: {e}"))
        })?;
        self.update_gauges();
        if found {
            Ok(())
        } else {
            Err(RegistryError::UnknownTexture(id_for_error))
        }
    }

    /// Counts one more precompute as pending.
    fn reserve_precompute(&self) {
        self.pending.fetch_add(1, Ordering::SeqCst);
        self.metrics.precomputes_pending.inc();
    }

    /// Counts one pending precompute less.
    fn release_precompute(&self) {
        self.pending.fetch_sub(1, Ordering::SeqCst);
        self.metrics.precomputes_pending.dec();
    }

    /// Runs the precompute of `entry`, whose place in the queue is
    /// reserved already ([`Registry::reserve_precompute`]).
    fn start_precompute(self: &Arc<Self>, entry: Arc<Entry>) {
        let this = self.clone();
        tokio::spawn(async move {
            let permit = this.slots.clone().acquire_owned().await;
            // Deleted while it waited: it leaves the queue without waiting
            // for memory too.
            if entry.deleted.load(Ordering::SeqCst) {
                this.release_precompute();
                this.update_gauges();
                return;
            }
            // Whatever its estimate, a precompute takes at most the whole
            // bound (a texture found at start may predate a lower one).
            let units = entry
                .precompute_estimate
                .div_ceil(MEMORY_UNIT)
                .clamp(1, memory_units(this.max_precompute_bytes));
            let units = u32::try_from(units).unwrap_or(u32::MAX);
            let memory = this
                .precompute_memory
                .clone()
                .acquire_many_owned(units)
                .await;
            let worker = this.clone();
            let e = entry.clone();
            let done = tokio::task::spawn_blocking(move || {
                let _permits = (permit, memory);
                let _reserved = worker.reserve_memory(e.precompute_estimate);
                worker.precompute(&e);
            })
            .await;
            if let Err(err) = done {
                entry.set_status(Status::Failed(format!("precompute aborted: {err}")));
            }
            this.release_precompute();
            this.update_gauges();
        });
    }

    /// Counts `bytes` as reserved by a running precompute until the guard
    /// is dropped.
    fn reserve_memory(&self, bytes: u64) -> Reserved<'_> {
        let now = self.precompute_reserved.fetch_add(bytes, Ordering::SeqCst) + bytes;
        self.precompute_reserved_peak
            .fetch_max(now, Ordering::SeqCst);
        self.metrics.precompute_reserved_bytes.set(now as i64);
        Reserved {
            registry: self,
            bytes,
        }
    }

    /// Candidates already in memory for the same pixels and analysis
    /// parameters (a texture that differs in synthesis parameters only).
    fn shared_candidates(&self, entry: &Entry) -> Option<Arc<Candidates>> {
        self.map
            .read()
            .values()
            .filter(|e| e.analysis_hash == entry.analysis_hash)
            .find_map(|e| e.candidates())
    }

    /// Candidates of another texture of the same pixels and analysis
    /// parameters read back from disk, when none is in memory (they were
    /// evicted): a variant of a texture then costs a read, not a search.
    fn stored_shared_candidates(&self, entry: &Entry) -> Option<Arc<Candidates>> {
        let siblings: Vec<Arc<Entry>> = self
            .map
            .read()
            .values()
            .filter(|e| {
                e.analysis_hash == entry.analysis_hash
                    && e.id != entry.id
                    && e.on_disk.load(Ordering::Relaxed)
            })
            .cloned()
            .collect();
        let set = entry.planes.to_set().ok()?;
        siblings.iter().find_map(|e| {
            let bytes = self.store.read_candidates(&e.id).ok()?;
            let c = Candidates::load(&bytes).ok()?;
            (c.params() == &entry.params.analysis && c.exemplars() == &set).then(|| Arc::new(c))
        })
    }

    /// Runs one precompute to its end (blocking).
    fn precompute(&self, entry: &Arc<Entry>) {
        if entry.deleted.load(Ordering::SeqCst) {
            return;
        }
        let span = tracing::info_span!("precompute", texture = %entry.id);
        let _s = span.enter();
        tracing::info!(
            width = entry.exemplar.width,
            height = entry.exemplar.height,
            planes = entry.exemplar.planes,
            "precompute started"
        );
        let t0 = Instant::now();
        let shared = self
            .shared_candidates(entry)
            .or_else(|| self.stored_own_candidates(entry))
            .or_else(|| self.stored_shared_candidates(entry));
        let reused = shared.is_some();
        let mut computed = false;
        let baseline = self.meter.map(Meter::reset);
        let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            if let Some(c) = shared {
                let t = Texture::new(c.clone(), entry.params.synth.clone(), self.cache.clone())
                    .map_err(|e| e.to_string())?;
                return Ok(Some((c, t)));
            }
            let set = entry.planes.to_set().map_err(|e| e.to_string())?;
            let progress = |stage: Stage, f: f32| {
                let (name, p) = overall_progress(stage, f);
                entry.set_progress(name, p);
            };
            let c = match solidtex_core::bundled::candidates_for(&set, &entry.params.analysis) {
                Some(c) => c,
                None => {
                    computed = true;
                    let run = || {
                        run_cancellable(&entry.cancel, || {
                            Candidates::compute(&set, &entry.params.analysis, &progress)
                        })
                    };
                    match self.pool.install(run) {
                        Ok(c) => c.map_err(|e| e.to_string())?,
                        Err(Cancelled) => return Ok(None),
                    }
                }
            };
            let c = Arc::new(c);
            let t = Texture::new(c.clone(), entry.params.synth.clone(), self.cache.clone())
                .map_err(|e| e.to_string())?;
            Ok::<_, String>(Some((c, t)))
        }))
        .unwrap_or_else(|p| {
            Err(format!(
                "precompute panicked: {}",
                panic_message(p.as_ref())
            ))
        });
        let result = match result {
            Ok(Some(done)) => Ok(done),
            Ok(None) => {
                self.count_precompute("cancelled");
                tracing::info!(
                    seconds = t0.elapsed().as_secs_f64(),
                    "precompute stopped: its texture was deleted"
                );
                return;
            }
            Err(why) => Err(why),
        };
        let seconds = t0.elapsed().as_secs_f64();
        *entry.precompute_seconds.lock() = Some(seconds);
        if !reused {
            self.metrics.precompute_seconds.observe(seconds);
        }
        // Only counts of the counting allocator, and only of a real
        // computation (not the bundled or shared candidates), are kept.
        let peak = match (self.meter, baseline) {
            (Some(m), Some(b)) if computed && peak_alloc::installed() => Some(m.peak_above(b)),
            _ => None,
        };
        if let Some(bytes) = peak {
            *entry.precompute_peak.lock() = Some(bytes);
            self.metrics.precompute_peak_bytes.observe(bytes as f64);
        }
        let _g = self.store.lock();
        if entry.deleted.load(Ordering::SeqCst) {
            tracing::info!("texture deleted during its precompute; result dropped");
            return;
        }
        match result {
            Ok((c, t)) => {
                // Progress and counters are final before the status turns
                // ready, so no reader sees a ready texture in progress.
                entry.set_progress("done", 1.0);
                if reused {
                    self.count_precompute("reused");
                    tracing::info!("candidates shared with a texture of the same exemplars");
                } else {
                    self.count_precompute("ok");
                    tracing::info!(
                        seconds,
                        peak_bytes = peak,
                        estimated_bytes = entry.precompute_estimate,
                        "precompute finished"
                    );
                }
                if let Err(e) = self.store.write_candidates(&entry.id, &c) {
                    // Still served from memory; the next start recomputes.
                    tracing::error!(error = %e, "could not store candidates");
                    entry.set_ready(c, t);
                } else {
                    entry.on_disk.store(true, Ordering::Relaxed);
                    // Durable as ready before anyone sees it ready: a
                    // restart right after must not compute it again.
                    let meta = StoredMeta {
                        status: StoredStatus::Ready,
                        reason: None,
                        ..entry.meta()
                    };
                    match self.store.write_meta(&meta) {
                        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                            tracing::info!(
                                "texture deleted by another server during its precompute; result dropped"
                            );
                            self.forget(entry);
                            return;
                        }
                        Err(e) => tracing::error!(error = %e, "could not store texture metadata"),
                        Ok(()) => {}
                    }
                    entry.set_ready(c, t);
                }
                self.keep_within_memory(&entry.id);
            }
            Err(why) => {
                tracing::error!(reason = %why, "precompute failed");
                entry.set_status(Status::Failed(why));
                entry.set_progress("failed", entry.progress());
                if let Err(e) = self.store.write_meta(&entry.meta()) {
                    tracing::error!(error = %e, "could not store texture metadata");
                }
                self.count_precompute("failed");
            }
        }
    }

    fn count_precompute(&self, outcome: &str) {
        self.metrics
            .precomputes
            .get_or_create(&OutcomeLabels {
                outcome: outcome.into(),
            })
            .inc();
    }

    /// The textures of the storage (blocking), to bring back with
    /// [`Registry::recover`].
    pub(crate) fn scan(&self) -> std::io::Result<Vec<Found>> {
        self.store.scan()
    }

    /// Brings back the textures `found` (blocking): ready ones are loaded
    /// from their `.stx` without recomputation, interrupted or unreadable
    /// ones are queued for a new precompute (or marked failed when their
    /// exemplars are gone), failed ones stay failed. Each is served as soon
    /// as it is loaded. Of the textures that share candidates, the first
    /// reads them and the others (variants, whose sketches are solved as
    /// they load) follow in parallel. Returns the entries to precompute;
    /// start them with [`Registry::resume`].
    pub(crate) fn recover(&self, found: Vec<Found>) -> Vec<Arc<Entry>> {
        use rayon::prelude::*;
        let mut groups: Vec<Vec<Restoring>> = Vec::new();
        for r in found.into_iter().filter_map(|f| self.prepare(f)) {
            let analysis = &r.entry.analysis_hash;
            match groups
                .iter_mut()
                .find(|g| &g[0].entry.analysis_hash == analysis)
            {
                Some(g) => g.push(r),
                None => groups.push(vec![r]),
            }
        }
        let todo = Mutex::new(Vec::new());
        let bring_back = |r: Restoring| {
            let (entry, precompute) = self.finish(r);
            if precompute {
                todo.lock().push(entry.clone());
            }
            self.insert(entry);
            // A data directory larger than the memory bound loads one
            // texture at a time past it.
            self.keep_within_memory("");
            self.update_gauges();
        };
        groups.into_par_iter().for_each(|mut first| {
            let others = first.split_off(1);
            first.into_iter().for_each(bring_back);
            others.into_par_iter().for_each(bring_back);
        });
        todo.into_inner()
    }

    /// The entry of one stored texture, and whether it needs a precompute;
    /// `None` when it cannot be served.
    fn restore(&self, found: Found) -> Option<(Arc<Entry>, bool)> {
        self.prepare(found).map(|r| self.finish(r))
    }

    /// A stored texture's metadata and exemplars read and checked against
    /// its id; `None` when it cannot be served.
    fn prepare(&self, Found { meta, location }: Found) -> Option<Restoring> {
        let params = match TextureParams::from_stored(&meta.params) {
            Ok(p) => p,
            Err(e) => {
                tracing::warn!(location = %location, error = %e, "skipping texture with unreadable parameters");
                return None;
            }
        };
        let planes = match self.store.read_planes(&meta) {
            Ok(p) => p,
            Err(e) => {
                tracing::warn!(id = %meta.id, error = %e, "texture exemplars unreadable; marking failed");
                // Keep something to report: a 16×16 black placeholder.
                let blank = solidtex_core::Exemplar::from_rgb(16, 16, &[0; 16 * 16 * 3])
                    .expect("valid placeholder");
                let entry = Arc::new(
                    Entry::new(
                        meta.id.clone(),
                        meta.content_hash.clone(),
                        meta.created,
                        TextureSpec {
                            planes: Planes::Single(blank),
                            params,
                        },
                    )
                    .named(meta.name.clone()),
                );
                let why = format!("stored exemplars unreadable: {e}");
                entry.set_status(Status::Failed(why.clone()));
                let _ = self.store.write_meta(&StoredMeta {
                    exemplar: meta.exemplar,
                    ..entry.meta()
                });
                return Some(Restoring {
                    entry,
                    status: StoredStatus::Failed,
                    reason: Some(why),
                });
            }
        };
        let spec = TextureSpec { planes, params };
        // What is served must be what the id names: recompute it from
        // the pixels and parameters as loaded (a tampered exemplar or
        // metadata is refused, and never shares its candidates).
        let hash = spec.content_hash_as_stored(&meta.params);
        if hash != meta.content_hash
            || (meta.id != meta.content_hash && meta.id != super::DEFAULT_ID)
        {
            tracing::error!(
                id = %meta.id,
                content_hash = %meta.content_hash,
                computed = %hash,
                "stored texture does not match its id; not served"
            );
            self.metrics.textures_refused.inc();
            return None;
        }
        let entry = Arc::new(
            Entry::new(
                meta.id.clone(),
                meta.content_hash.clone(),
                meta.created,
                spec,
            )
            .named(meta.name.clone()),
        );
        *entry.precompute_seconds.lock() = meta.precompute_seconds;
        *entry.precompute_peak.lock() = meta.precompute_peak_bytes;
        *entry.stored_since.lock() = Some(Instant::now());
        Some(Restoring {
            entry,
            status: meta.status,
            reason: meta.reason,
        })
    }

    /// Loads a checked stored texture's candidates, or says it needs a
    /// precompute.
    fn finish(&self, r: Restoring) -> (Arc<Entry>, bool) {
        let Restoring {
            entry,
            status,
            reason,
        } = r;
        let mut precompute = false;
        match status {
            StoredStatus::Ready => match self.load_ready(&entry) {
                Ok((c, t)) => {
                    entry.set_progress("done", 1.0);
                    entry.on_disk.store(true, Ordering::Relaxed);
                    entry.set_ready(c, t);
                    self.metrics.textures_loaded.inc();
                    tracing::info!(id = %entry.id, "texture loaded");
                }
                Err(e) => {
                    tracing::warn!(id = %entry.id, error = %e, "stored candidates unusable; recomputing");
                    precompute = true;
                }
            },
            StoredStatus::Pending => {
                tracing::info!(id = %entry.id, "precompute was interrupted; recomputing");
                precompute = true;
            }
            StoredStatus::Failed => {
                entry.set_status(Status::Failed(
                    reason.unwrap_or_else(|| "precompute failed".into()),
                ));
            }
        }
        (entry, precompute)
    }

    fn load_ready(&self, entry: &Entry) -> Result<(Arc<Candidates>, Texture), String> {
        let c = match self.shared_candidates(entry) {
            Some(c) => c,
            None => Arc::new(self.read_verified(entry)?),
        };
        let t = Texture::new(c.clone(), entry.params.synth.clone(), self.cache.clone())
            .map_err(|e| e.to_string())?;
        Ok((c, t))
    }

    /// The texture's own stored candidates, checked against it.
    fn read_verified(&self, entry: &Entry) -> Result<Candidates, String> {
        let bytes = self
            .store
            .read_candidates(&entry.id)
            .map_err(|e| e.to_string())?;
        let c = Candidates::load(&bytes).map_err(|e| e.to_string())?;
        if c.params() != &entry.params.analysis {
            return Err("stored candidates were made with other parameters".into());
        }
        let set = entry.planes.to_set().map_err(|e| e.to_string())?;
        if c.exemplars() != &set {
            return Err("stored candidates were made from other exemplars".into());
        }
        if Some(c.layout().arrangement) != entry.layout.map(|l| l.arrangement) {
            return Err(
                "stored candidates were made with another arrangement of the planes".into(),
            );
        }
        Ok(c)
    }

    /// With a shared storage, the candidates another server stored for
    /// this texture (it finished the precompute first).
    fn stored_own_candidates(&self, entry: &Entry) -> Option<Arc<Candidates>> {
        if !self.store.shared() {
            return None;
        }
        self.read_verified(entry).ok().map(Arc::new)
    }

    /// The texture `id`: known here or, with a shared storage, stored by
    /// another server and taken up now (its candidates loaded, or
    /// recomputed when they are not stored yet).
    pub(crate) async fn find(
        self: &Arc<Self>,
        id: &str,
    ) -> Result<Option<Arc<Entry>>, RegistryError> {
        if let Some(e) = self.get(id) {
            return Ok(Some(e));
        }
        if !self.recovered() {
            self.await_recovered().await?;
            if let Some(e) = self.get(id) {
                return Ok(Some(e));
            }
        }
        if !self.store.shared() || !super::spec::valid_id(id) {
            return Ok(None);
        }
        let this = self.clone();
        let id = id.to_string();
        tokio::task::spawn_blocking(move || this.adopt(&id))
            .await
            .map_err(|e| RegistryError::Internal(e.to_string()))?
    }

    /// Takes up texture `id` from the shared storage (blocking).
    fn adopt(self: &Arc<Self>, id: &str) -> Result<Option<Arc<Entry>>, RegistryError> {
        let _one = self.adopting.lock();
        if let Some(e) = self.get(id) {
            return Ok(Some(e));
        }
        let found = self.store.find(id).map_err(|e| {
            RegistryError::Internal(format!("reading {}: {e}", self.store.location()))
        })?;
        let Some((entry, precompute)) = found.and_then(|f| self.restore(f)) else {
            return Ok(None);
        };
        *entry.stored_since.lock() = Some(Instant::now());
        self.insert(entry.clone());
        if precompute {
            self.reserve_precompute();
            self.start_precompute(entry.clone());
        }
        self.keep_within_memory(id);
        self.update_gauges();
        Ok(Some(entry))
    }

    /// With a shared storage, checks every `every` which textures are
    /// still stored, and forgets those another server deleted: a delete
    /// reaches this server within `every` and one listing of the store.
    pub(crate) fn follow_deletes(self: &Arc<Self>, every: std::time::Duration) {
        if !self.store.shared() {
            return;
        }
        let weak = Arc::downgrade(self);
        tokio::spawn(async move {
            let mut tick = tokio::time::interval(every);
            tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
            loop {
                tick.tick().await;
                let Some(this) = weak.upgrade() else { return };
                let checked = tokio::task::spawn_blocking(move || {
                    let listed_at = Instant::now();
                    let ids = this.store.ids()?;
                    this.forget_deleted(&ids, listed_at);
                    Ok::<_, std::io::Error>(())
                })
                .await;
                match checked {
                    Ok(Ok(())) => {}
                    Ok(Err(e)) => tracing::warn!(error = %e, "could not list the shared store"),
                    Err(e) => tracing::warn!(error = %e, "listing the shared store failed"),
                }
            }
        });
    }

    /// Forgets the textures stored before `listed_at` that the listing
    /// `stored` (sorted) no longer holds.
    fn forget_deleted(&self, stored: &[String], listed_at: Instant) {
        let gone: Vec<Arc<Entry>> = self
            .map
            .read()
            .values()
            .filter(|e| {
                e.stored_since.lock().is_some_and(|t| t < listed_at)
                    && stored.binary_search(&e.id).is_err()
            })
            .cloned()
            .collect();
        for e in gone {
            let _g = self.store.lock();
            tracing::info!(id = %e.id, "texture deleted by another server");
            self.forget(&e);
        }
        self.update_gauges();
    }

    /// Drops `entry` from the registry (requests in flight keep theirs).
    fn forget(&self, entry: &Arc<Entry>) {
        let mut map = self.map.write();
        if map.get(&entry.id).is_some_and(|e| Arc::ptr_eq(e, entry)) {
            map.remove(&entry.id);
        }
        drop(map);
        entry.deleted.store(true, Ordering::SeqCst);
        *entry.candidates.lock() = None;
    }

    fn insert(&self, entry: Arc<Entry>) {
        self.map.write().insert(entry.id.clone(), entry);
    }

    /// Starts the precomputes [`Registry::recover`] found necessary.
    pub(crate) fn resume(self: &Arc<Self>, todo: Vec<Arc<Entry>>) {
        for e in todo {
            self.reserve_precompute();
            self.start_precompute(e);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn progress_is_monotone_over_stages() {
        let mut last = -1.0;
        for s in [
            Stage::Analysis,
            Stage::Search,
            Stage::Coherence,
            Stage::Finish,
            Stage::Reference,
        ] {
            for f in [0.0, 0.5, 1.0] {
                let (_, p) = overall_progress(s, f);
                assert!(p >= last - 1e-6);
                assert!(p < 1.0);
                last = p;
            }
        }
    }
}
