//! Background jobs: exports (see [`solidtex_core::export`]) and mesh bakes
//! asked for with `Prefer: respond-async`. Each is far larger than an
//! interactive request and must not hold the interactive job slots, so
//! they run here, one at a time with a few waiting, each under a work
//! budget of its own (`--max-export-work`). A job is known by an id derived
//! from its texture and what it makes, so that asking twice joins the
//! first. A client that stops waiting does not stop it; `DELETE` does
//! (through the same [`CancelFlag`] that stops a synchronous request whose
//! client hung up) and frees its file.
//!
//! What is held is bounded: jobs running or waiting (503 with
//! `Retry-After` beyond), finished jobs by count, the bytes of finished
//! files (least recently read dropped first), and the time a finished job
//! is kept unread (`--export-ttl`). A dropped file is made again when
//! asked for (mostly from the tile cache).

use crate::error::ApiError;
use crate::spec::hex;
use axum::body::Bytes;
use parking_lot::Mutex;
use schemars::JsonSchema;
use serde::Serialize;
use sha2::{Digest, Sha256};
use solidtex_core::{CancelFlag, Cancelled, run_cancellable};
use std::collections::{HashMap, VecDeque};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};
use tokio::sync::{Notify, OwnedSemaphorePermit, Semaphore, watch};

/// Finished jobs kept at most (their status, and their file if it fits
/// the byte bound).
const MAX_FINISHED: usize = 256;

/// What a job makes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Kind {
    /// A file of `/v1/textures/{id}/export`.
    Export,
    /// A textured mesh of `POST /v1/textures/{id}/bake`.
    Bake,
}

impl Kind {
    /// Its name in statuses and error codes.
    pub(crate) fn name(self) -> &'static str {
        match self {
            Kind::Export => "export",
            Kind::Bake => "bake",
        }
    }

    /// The id of the job of this kind that makes `key` (what it makes,
    /// normalised) from the texture whose content hash is `content_hash`.
    pub(crate) fn job_id(self, content_hash: &str, key: &str) -> String {
        let mut h = Sha256::new();
        h.update(b"solidtex ");
        h.update(self.name().as_bytes());
        h.update(b" v1\0");
        h.update(content_hash.as_bytes());
        h.update(b"\0");
        h.update(key.as_bytes());
        hex(&h.finalize()[..16])
    }

    /// Where its jobs are: `/v1/{collection}/{id}`.
    pub(crate) fn collection(self) -> &'static str {
        match self {
            Kind::Export => "exports",
            Kind::Bake => "bakes",
        }
    }
}

/// Where a job stands.
#[derive(Clone, Debug)]
pub(crate) enum Phase {
    /// Waiting for the running slot.
    Queued,
    /// Running.
    Running,
    /// Done: the file's bytes.
    Done(Bytes),
    /// Failed, with the error a client gets.
    Failed(ApiError),
    /// Cancelled by `DELETE` (its file, if any, freed).
    Cancelled,
}

/// The names of the phases, as [`Phase::name`] gives them.
const STATES: [&str; 5] = ["queued", "running", "done", "failed", "cancelled"];

impl Phase {
    /// Its name in a status.
    pub(crate) fn name(&self) -> &'static str {
        match self {
            Phase::Queued => "queued",
            Phase::Running => "running",
            Phase::Done(_) => "done",
            Phase::Failed(_) => "failed",
            Phase::Cancelled => "cancelled",
        }
    }

    /// Whether the job will not change any more.
    pub(crate) fn finished(&self) -> bool {
        !matches!(self, Phase::Queued | Phase::Running)
    }
}

/// What a job is, fixed when it starts.
pub(crate) struct Spec {
    /// Its id (hex), derived from what it makes.
    pub id: String,
    /// Export or bake.
    pub kind: Kind,
    /// The texture's id.
    pub texture: String,
    /// The file's name.
    pub file_name: String,
    /// The file's media type.
    pub media_type: &'static str,
    /// What the file's ETag is made from (with the texture).
    pub etag_key: String,
    /// What progress counts: `voxels`, `texels` or `vertices`.
    pub unit: &'static str,
    /// How many of them there are.
    pub total: u64,
    /// Voxels predicted to be synthesized from a cold cache, until the
    /// work sets a closer guess (see [`Progress::set_predicted`]).
    pub predicted: u64,
    /// What its status tells of its kind's own.
    pub detail: Detail,
}

/// What a job's status tells of what only its kind has.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Detail {
    /// An export's format (`ktx2`, `atlas`, `nrrd`, `raw`).
    Export { format: &'static str },
    /// A bake's mesh and texture.
    Bake(BakeDetail),
}

/// What a bake's status tells of its mesh and texture.
#[derive(Clone, Copy, Debug)]
pub(crate) struct BakeDetail {
    pub triangles: u64,
    pub resolution: u32,
    /// `None` for vertex colours.
    pub texture_size: Option<u32>,
    pub lod: u32,
}

// openapi.yaml's `JobStatus` schema is generated from this type. Its
// fields stand in alphabetical order: the status was a JSON map before it
// was a type, and its bytes stay the same.
/// A background job: an export, or a bake asked for with `Prefer:
/// respond-async` (what `GET /v1/{exports,bakes}/{id}` answers).
#[derive(Serialize, JsonSchema)]
#[schemars(example = JobStatus::example())]
pub(crate) struct JobStatus {
    /// The file's size (when done).
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schemars(with = "u64")]
    pub bytes: Option<u64>,
    /// When it started, seconds since the Unix epoch.
    pub created: u64,
    /// Units finished (all once done).
    pub done: u64,
    /// Why it failed (when failed).
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schemars(with = "JobError")]
    pub error: Option<JobError>,
    /// The file's name.
    pub file: String,
    /// Where the file is served once done.
    pub file_url: String,
    /// An export's format.
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schemars(with = "String")]
    #[schemars(extend("enum" = ["ktx2", "atlas", "nrrd", "raw"]))]
    pub format: Option<&'static str>,
    /// Derived from the texture and what the job makes: the same request
    /// gets the same id.
    pub id: String,
    /// Export or bake.
    #[schemars(extend("enum" = ["export", "bake"]))]
    pub kind: &'static str,
    /// A bake's level of detail.
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schemars(with = "u32")]
    pub lod: Option<u32>,
    /// The file's media type.
    pub media_type: &'static str,
    /// Voxels a cold cache would synthesize: the upper bound checked
    /// against `--max-export-work` before it started; for a bake, once
    /// `planning` is over, a closer guess (one union of the shell's chains
    /// per level), which the synthesis may pass.
    pub predicted_voxels: u64,
    /// Share done, never decreasing, 1 once done: the larger of `done`
    /// over `total` and of `synthesized_voxels` over `predicted_voxels`
    /// (at most 0.99: the prediction is a guess that the synthesis may
    /// pass).
    #[schemars(range(min = 0, max = 1))]
    pub progress: f64,
    /// A bake's resolution.
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schemars(with = "u32")]
    pub resolution: Option<u32>,
    /// What it is doing: `queued`, `planning` (a bake's prediction),
    /// `synthesis`, `writing` (a bake's glTF), then the state once
    /// finished.
    pub stage: &'static str,
    /// Where it stands.
    #[schemars(extend("enum" = STATES))]
    pub state: &'static str,
    /// Voxels synthesized so far, all levels (cached ones are free).
    pub synthesized_voxels: u64,
    /// The texture's id.
    pub texture: String,
    /// A bake's texture side (null for vertex colours).
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schemars(with = "Option<u32>")]
    pub texture_size: Option<Option<u32>>,
    /// How many units there are.
    pub total: u64,
    /// A bake's triangles.
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schemars(with = "u64")]
    pub triangles: Option<u64>,
    /// What `done` and `total` count: an export's voxels, a bake's texels
    /// or vertices.
    #[schemars(extend("enum" = ["voxels", "texels", "vertices"]))]
    pub unit: &'static str,
    /// Where this status is.
    pub url: String,
}

impl JobStatus {
    /// A bake under way, as the document shows it.
    fn example() -> JobStatus {
        let id = "5f0c2a9e41d7b3c8a6e2f19d0b4c7a83";
        JobStatus {
            bytes: None,
            created: 1_796_425_200,
            done: 1_048_576,
            error: None,
            file: "default-5f0c2a9e.glb".into(),
            file_url: format!("/v1/bakes/{id}/file"),
            format: None,
            id: id.into(),
            kind: "bake",
            lod: Some(0),
            media_type: "model/gltf-binary",
            predicted_voxels: 41_203_712,
            progress: 0.42,
            resolution: Some(1024),
            stage: "synthesis",
            state: "running",
            synthesized_voxels: 17_305_600,
            texture: "default".into(),
            texture_size: Some(Some(2048)),
            total: 4_194_304,
            triangles: Some(4608),
            unit: "texels",
            url: format!("/v1/bakes/{id}"),
        }
    }
}

/// Why a job failed: the error a client asking for its file gets.
#[derive(Serialize, JsonSchema)]
#[schemars(inline)]
pub(crate) struct JobError {
    /// Stable identifier of the error class.
    pub code: &'static str,
    /// Human-readable explanation.
    pub message: String,
    /// The HTTP status of that answer.
    pub status: u16,
}

/// What a running job tells its status as it goes.
pub(crate) struct Progress {
    done: AtomicU64,
    stage: Mutex<&'static str>,
    /// Voxels the synthesis is measured against.
    predicted: AtomicU64,
}

impl Progress {
    /// `done` of the job's units are finished.
    pub(crate) fn set_done(&self, done: u64) {
        self.done.fetch_max(done, Ordering::Relaxed);
    }

    /// The synthesis is guessed to compute `voxels` from a cold cache:
    /// what its progress is measured against from now on, if lower (a
    /// prediction is never raised, so the share done never falls).
    pub(crate) fn set_predicted(&self, voxels: u64) {
        self.predicted.fetch_min(voxels, Ordering::Relaxed);
    }

    /// The job entered `stage`.
    pub(crate) fn set_stage(&self, stage: &'static str) {
        *self.stage.lock() = stage;
    }
}

/// The work of a job, run on a blocking thread under its cancel flag.
pub(crate) type Work = Box<dyn FnOnce(&Progress) -> Result<Bytes, ApiError> + Send>;

/// One job, waiting, running or finished.
pub(crate) struct Job {
    /// What it is.
    pub spec: Spec,
    /// When it was started, seconds since the Unix epoch.
    created: u64,
    progress: Progress,
    flag: CancelFlag,
    /// Wakes a waiting job that was cancelled.
    cancelled: Notify,
    phase: watch::Sender<Phase>,
}

impl Job {
    /// Where it stands now.
    pub(crate) fn phase(&self) -> Phase {
        self.phase.borrow().clone()
    }

    /// Units done so far (all of them once done).
    pub(crate) fn done(&self) -> u64 {
        match self.phase() {
            Phase::Done(_) => self.spec.total,
            _ => self.progress.done.load(Ordering::Relaxed),
        }
    }

    /// Waits until it is finished.
    pub(crate) async fn finished(&self) -> Phase {
        let mut rx = self.phase.subscribe();
        let seen = rx.wait_for(Phase::finished).await.map(|p| p.clone());
        seen.unwrap_or_else(|_| Phase::Failed(ApiError::internal("the job was dropped")))
    }

    /// Share done, 0 to 1, never decreasing, 1 once done: the larger of
    /// the units done and of the voxels synthesized against the
    /// prediction (a share that stops short of 1, and moves while a step
    /// of units is being synthesized).
    fn fraction(&self, phase: &Phase) -> f64 {
        if matches!(phase, Phase::Done(_)) {
            return 1.0;
        }
        let units = self.done() as f64 / self.spec.total.max(1) as f64;
        units.max(self.flag.share_of(self.predicted())).min(1.0)
    }

    /// Voxels the synthesis is measured against.
    fn predicted(&self) -> u64 {
        self.progress.predicted.load(Ordering::Relaxed)
    }

    /// Its status (what `GET /v1/{exports,bakes}/{id}` answers).
    pub(crate) fn status(&self) -> JobStatus {
        let phase = self.phase();
        let spec = &self.spec;
        let stage = match &phase {
            Phase::Queued | Phase::Running => *self.progress.stage.lock(),
            finished => finished.name(),
        };
        let url = format!("/v1/{}/{}", spec.kind.collection(), spec.id);
        let (format, bake) = match spec.detail {
            Detail::Export { format } => (Some(format), None),
            Detail::Bake(bake) => (None, Some(bake)),
        };
        JobStatus {
            bytes: match &phase {
                Phase::Done(b) => Some(b.len() as u64),
                _ => None,
            },
            created: self.created,
            done: self.done(),
            error: match &phase {
                Phase::Failed(e) => Some(JobError {
                    code: e.code,
                    message: e.message.clone(),
                    status: e.status.as_u16(),
                }),
                _ => None,
            },
            file: spec.file_name.clone(),
            file_url: format!("{url}/file"),
            format,
            id: spec.id.clone(),
            kind: spec.kind.name(),
            lod: bake.map(|b| b.lod),
            media_type: spec.media_type,
            predicted_voxels: self.predicted(),
            progress: self.fraction(&phase),
            resolution: bake.map(|b| b.resolution),
            stage,
            state: phase.name(),
            synthesized_voxels: self.flag.synthesized(),
            texture: spec.texture.clone(),
            texture_size: bake.map(|b| b.texture_size),
            total: spec.total,
            triangles: bake.map(|b| b.triangles),
            unit: spec.unit,
            url,
        }
    }
}

/// The background jobs of a server.
pub(crate) struct Background {
    /// Jobs running or waiting, at most one more than may wait.
    admit: Arc<Semaphore>,
    /// The one job that runs.
    run: Arc<Semaphore>,
    /// Jobs that may be running or waiting at once.
    held: usize,
    max_work: u64,
    max_bytes: u64,
    ttl: Duration,
    inner: Mutex<Inner>,
}

#[derive(Default)]
struct Inner {
    by_id: HashMap<String, Arc<Job>>,
    /// Finished jobs, least recently used first.
    finished: VecDeque<Held>,
    /// Bytes of the files held.
    bytes: u64,
}

/// A finished job in the eviction order.
struct Held {
    id: String,
    bytes: u64,
    used: Instant,
}

impl Inner {
    /// Takes the finished job `id` out of the eviction order (its bytes
    /// with it), if it is there.
    fn unhold(&mut self, id: &str) -> Option<Held> {
        let at = self.finished.iter().position(|h| h.id == id)?;
        let held = self.finished.remove(at)?;
        self.bytes = self.bytes.saturating_sub(held.bytes);
        Some(held)
    }
}

impl Background {
    /// One job running and `queue` waiting, none synthesizing more than
    /// `max_work` voxels, keeping at most `max_bytes` of finished files,
    /// each at most `ttl` after it was last asked for.
    pub(crate) fn new(queue: u32, max_work: u64, max_bytes: u64, ttl: Duration) -> Background {
        Background {
            admit: Arc::new(Semaphore::new(1 + queue as usize)),
            run: Arc::new(Semaphore::new(1)),
            held: 1 + queue as usize,
            max_work,
            max_bytes,
            ttl,
            inner: Mutex::default(),
        }
    }

    /// The jobs held, as (kind, state name, count) for every kind and
    /// state (zero counts included), and the bytes of the files held.
    pub(crate) fn census(&self) -> (Vec<(Kind, &'static str, u64)>, u64) {
        let mut inner = self.inner.lock();
        self.evict(&mut inner);
        let mut out: Vec<(Kind, &'static str, u64)> = [Kind::Export, Kind::Bake]
            .into_iter()
            .flat_map(|k| STATES.map(|s| (k, s, 0)))
            .collect();
        for job in inner.by_id.values() {
            let (kind, state) = (job.spec.kind, job.phase().name());
            if let Some(n) = out.iter_mut().find(|(k, s, _)| *k == kind && *s == state) {
                n.2 += 1;
            }
        }
        (out, inner.bytes)
    }

    /// The job `id` of `kind`, if it is held; reading it counts as a use.
    pub(crate) fn get(&self, kind: Kind, id: &str) -> Option<Arc<Job>> {
        let mut inner = self.inner.lock();
        self.evict(&mut inner);
        let job = inner.by_id.get(id).filter(|j| j.spec.kind == kind)?.clone();
        if let Some(h) = inner.finished.iter().position(|h| h.id == id)
            && let Some(mut held) = inner.finished.remove(h)
        {
            held.used = Instant::now();
            inner.finished.push_back(held);
        }
        Some(job)
    }

    /// The job `id`, waiting, running or done, to join; `None` when there
    /// is none or it failed or was cancelled (asking again starts anew).
    pub(crate) fn joinable(&self, kind: Kind, id: &str) -> Option<Arc<Job>> {
        self.get(kind, id)
            .filter(|j| !matches!(j.phase(), Phase::Failed(_) | Phase::Cancelled))
    }

    /// The job `spec` describes: the one already held under its id, or a
    /// new one that runs `work` once the running slot is free. 503 when
    /// as many jobs as may wait are waiting.
    pub(crate) fn start(self: &Arc<Self>, spec: Spec, work: Work) -> Result<Arc<Job>, ApiError> {
        let mut inner = self.inner.lock();
        self.evict(&mut inner);
        if let Some(job) = inner.by_id.get(&spec.id)
            && job.spec.kind == spec.kind
            && !matches!(job.phase(), Phase::Failed(_) | Phase::Cancelled)
        {
            return Ok(job.clone());
        }
        let Ok(admitted) = self.admit.clone().try_acquire_owned() else {
            return Err(ApiError::overloaded(&format!(
                "the queue of exports and bakes is full ({} running or waiting)",
                self.held
            ))
            .retry_after(10));
        };
        inner.unhold(&spec.id);
        let job = Arc::new(Job {
            created: SystemTime::now()
                .duration_since(UNIX_EPOCH)
                .map_or(0, |d| d.as_secs()),
            progress: Progress {
                done: AtomicU64::new(0),
                stage: Mutex::new("queued"),
                predicted: AtomicU64::new(spec.predicted),
            },
            flag: CancelFlag::with_budget(self.max_work),
            cancelled: Notify::new(),
            phase: watch::Sender::new(Phase::Queued),
            spec,
        });
        inner.by_id.insert(job.spec.id.clone(), job.clone());
        drop(inner);
        let (this, running) = (self.clone(), job.clone());
        tokio::spawn(async move {
            let phase = this.run(admitted, &running, work).await;
            this.finish(&running, phase);
        });
        Ok(job)
    }

    /// Cancels the job `id` of `kind`: a waiting or running one stops (its
    /// synthesis within a correction subpass), a done one drops its file.
    /// Returns it, cancelled, or `None` when it is not held.
    pub(crate) fn cancel(&self, kind: Kind, id: &str) -> Option<Arc<Job>> {
        let job = self.get(kind, id)?;
        job.flag.cancel();
        job.cancelled.notify_one();
        // A failure stays what it was; a done job's file is dropped here.
        job.phase.send_if_modified(|p| {
            let change = !matches!(p, Phase::Failed(_) | Phase::Cancelled);
            if change {
                *p = Phase::Cancelled;
            }
            change
        });
        let mut inner = self.inner.lock();
        if let Some(held) = inner.unhold(id) {
            inner.finished.push_back(Held { bytes: 0, ..held });
        }
        Some(job)
    }

    /// Runs one job once the slot is free, on a blocking thread.
    async fn run(&self, admitted: OwnedSemaphorePermit, job: &Arc<Job>, work: Work) -> Phase {
        let slot = tokio::select! {
            slot = self.run.clone().acquire_owned() => slot,
            () = job.cancelled.notified() => return Phase::Cancelled,
        };
        let Ok(slot) = slot else {
            return Phase::Failed(ApiError::internal("the job queue closed"));
        };
        if job.flag.is_cancelled() {
            return Phase::Cancelled;
        }
        job.phase.send_if_modified(|p| {
            let queued = matches!(p, Phase::Queued);
            if queued {
                *p = Phase::Running;
            }
            queued
        });
        let running = job.clone();
        let handle = tokio::task::spawn_blocking(move || {
            // The slots are held until the work has really stopped.
            let _slots = (admitted, slot);
            run_cancellable(&running.flag, || work(&running.progress))
        });
        let kind = job.spec.kind.name();
        match handle.await {
            Ok(Ok(Ok(bytes))) => Phase::Done(bytes),
            Ok(Ok(Err(e))) => Phase::Failed(e),
            Ok(Err(Cancelled)) if job.flag.is_over_budget() => Phase::Failed(ApiError::new(
                axum::http::StatusCode::BAD_REQUEST,
                "over_budget",
                format!(
                    "this {kind} needed more than {} voxels synthesized, the server's budget \
                     per export or bake (--max-export-work)",
                    self.max_work
                ),
            )),
            Ok(Err(Cancelled)) => Phase::Cancelled,
            Err(e) => Phase::Failed(ApiError::internal(format!("the {kind} failed: {e}"))),
        }
    }

    /// Records how `job` ended (a cancelled one stays cancelled) and
    /// drops what no longer fits.
    fn finish(&self, job: &Arc<Job>, phase: Phase) {
        let mut inner = self.inner.lock();
        let phase = if job.flag.is_cancelled() && !job.flag.is_over_budget() {
            Phase::Cancelled
        } else {
            phase
        };
        let bytes = match &phase {
            Phase::Done(b) => b.len() as u64,
            _ => 0,
        };
        // Only the job still held under its id is counted (a cancelled
        // one may have been replaced by a new start meanwhile).
        if inner
            .by_id
            .get(&job.spec.id)
            .is_some_and(|j| Arc::ptr_eq(j, job))
        {
            inner.unhold(&job.spec.id);
            inner.finished.push_back(Held {
                id: job.spec.id.clone(),
                bytes,
                used: Instant::now(),
            });
            inner.bytes = inner.bytes.saturating_add(bytes);
        }
        job.phase.send_replace(phase);
        self.evict(&mut inner);
    }

    /// Drops finished jobs past their time, past the count, and, least
    /// recently used first, past the byte bound.
    fn evict(&self, inner: &mut Inner) {
        let now = Instant::now();
        while let Some(front) = inner.finished.front() {
            let expired = now.duration_since(front.used) > self.ttl;
            if !(expired || inner.bytes > self.max_bytes || inner.finished.len() > MAX_FINISHED) {
                break;
            }
            let Some(old) = inner.finished.pop_front() else {
                break;
            };
            inner.bytes = inner.bytes.saturating_sub(old.bytes);
            inner.by_id.remove(&old.id);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec(id: &str) -> Spec {
        Spec {
            id: id.into(),
            kind: Kind::Bake,
            texture: "t".into(),
            file_name: format!("{id}.glb"),
            media_type: "model/gltf-binary",
            etag_key: id.into(),
            unit: "texels",
            total: 10,
            predicted: 100,
            detail: Detail::Bake(BakeDetail {
                triangles: 12,
                resolution: 64,
                texture_size: None,
                lod: 0,
            }),
        }
    }

    fn bytes(n: usize) -> Work {
        Box::new(move |p: &Progress| {
            p.set_done(10);
            Ok(Bytes::from(vec![7u8; n]))
        })
    }

    #[test]
    fn the_census_names_every_phase() {
        let phases = [
            Phase::Queued,
            Phase::Running,
            Phase::Done(Bytes::new()),
            Phase::Failed(ApiError::internal("x")),
            Phase::Cancelled,
        ];
        assert_eq!(phases.map(|p| p.name()), STATES);
    }

    #[tokio::test]
    async fn the_same_id_joins_and_files_past_the_bound_are_dropped() {
        let b = Arc::new(Background::new(4, 1000, 100, Duration::from_secs(60)));
        let first = b.start(spec("a"), bytes(60)).unwrap();
        let again = b.start(spec("a"), bytes(60)).unwrap();
        assert!(Arc::ptr_eq(&first, &again));
        assert!(matches!(first.finished().await, Phase::Done(f) if f.len() == 60));
        assert_eq!(first.status().progress, 1.0);
        assert_eq!(first.status().done, 10);
        // Another kind does not see it.
        assert!(b.get(Kind::Export, "a").is_none());
        let second = b.start(spec("b"), bytes(60)).unwrap();
        second.finished().await;
        // 120 bytes over a bound of 100: the least recently used goes.
        assert!(b.get(Kind::Bake, "a").is_none());
        assert!(b.get(Kind::Bake, "b").is_some());
    }

    #[tokio::test]
    async fn finished_jobs_are_held_up_to_the_count_and_no_more() {
        let b = Arc::new(Background::new(4, 1000, 1 << 20, Duration::from_secs(60)));
        for i in 0..MAX_FINISHED {
            b.start(spec(&format!("j{i}")), bytes(1))
                .unwrap()
                .finished()
                .await;
        }
        // At the count every one is held; reading j0 makes j1 the least
        // recently used.
        assert!(b.get(Kind::Bake, "j0").is_some());
        // One past it: the least recently used goes, the rest stay.
        b.start(spec("past"), bytes(1)).unwrap().finished().await;
        assert!(b.get(Kind::Bake, "j1").is_none());
        assert!(b.get(Kind::Bake, "j0").is_some());
        assert!(b.get(Kind::Bake, "j2").is_some());
        assert!(b.get(Kind::Bake, "past").is_some());
    }

    #[tokio::test]
    async fn a_status_is_written_as_the_map_it_was() {
        let b = Arc::new(Background::new(4, 1000, 1000, Duration::from_secs(60)));
        let done = b.start(spec("a"), bytes(3)).unwrap();
        done.finished().await;
        let status = done.status();
        assert!(crate::openapi::keys_in_map_order(&status));
        let v = serde_json::to_value(&status).unwrap();
        // A vertex-coloured bake has a texture side of null; a bake has
        // no format, and only a failed job an error.
        assert_eq!(v["texture_size"], serde_json::Value::Null);
        assert!(v.as_object().unwrap().contains_key("texture_size"));
        assert_eq!(v["bytes"], 3);
        assert!(v.get("format").is_none() && v.get("error").is_none());
        assert_eq!(v["url"], "/v1/bakes/a");
        assert_eq!(v["file_url"], "/v1/bakes/a/file");
        let failing = Spec {
            kind: Kind::Export,
            detail: Detail::Export { format: "nrrd" },
            ..spec("f")
        };
        let failed = b
            .start(
                failing,
                Box::new(|_: &Progress| Err(ApiError::internal("no room"))),
            )
            .unwrap();
        failed.finished().await;
        let status = failed.status();
        assert!(crate::openapi::keys_in_map_order(&status));
        let v = serde_json::to_value(&status).unwrap();
        assert_eq!(v["error"]["status"], 500);
        assert_eq!(v["error"]["message"], "no room");
        assert_eq!(v["format"], "nrrd");
        assert_eq!(v["state"], "failed");
        for bake_only in ["lod", "resolution", "texture_size", "triangles", "bytes"] {
            assert!(v.get(bake_only).is_none(), "{bake_only}");
        }
    }

    #[tokio::test]
    async fn finished_jobs_expire() {
        let b = Arc::new(Background::new(4, 1000, 1000, Duration::from_millis(50)));
        b.start(spec("a"), bytes(1)).unwrap().finished().await;
        assert!(b.get(Kind::Bake, "a").is_some());
        tokio::time::sleep(Duration::from_millis(120)).await;
        assert!(b.get(Kind::Bake, "a").is_none());
    }

    #[tokio::test]
    async fn a_full_queue_is_refused_and_a_waiting_job_cancels() {
        let b = Arc::new(Background::new(1, 1000, 1000, Duration::from_secs(60)));
        let (tx, rx) = std::sync::mpsc::channel::<()>();
        let blocker: Work = Box::new(move |_| {
            let _ = rx.recv();
            Ok(Bytes::new())
        });
        let running = b.start(spec("run"), blocker).unwrap();
        let waiting = b.start(spec("wait"), bytes(1)).unwrap();
        let refused = b.start(spec("more"), bytes(1)).map(|_| ()).unwrap_err();
        assert_eq!(refused.status, axum::http::StatusCode::SERVICE_UNAVAILABLE);
        b.cancel(Kind::Bake, "wait").unwrap();
        assert!(matches!(waiting.finished().await, Phase::Cancelled));
        assert_eq!(waiting.status().state, "cancelled");
        // Its place in the queue is free again (once its task has ended).
        tokio::time::sleep(Duration::from_millis(50)).await;
        let next = b.start(spec("next"), bytes(1)).unwrap();
        tx.send(()).unwrap();
        assert!(matches!(running.finished().await, Phase::Done(_)));
        assert!(matches!(next.finished().await, Phase::Done(_)));
        // A cancelled job is started anew when asked again.
        let again = b.start(spec("wait"), bytes(1)).unwrap();
        assert!(!Arc::ptr_eq(&again, &waiting));
        assert!(matches!(again.finished().await, Phase::Done(_)));
    }
}
