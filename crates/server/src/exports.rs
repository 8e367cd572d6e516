//! Exports being made and made (see [`solidtex_core::export`]): each is a
//! background job, one running at a time and a few waiting, with a work
//! budget of its own (an export is far larger than an interactive request
//! and must not hold the interactive job slots), known by an id derived
//! from the texture and the export, so that asking twice joins the first.
//! A client that stops waiting does not stop it. Progress is counted in
//! voxels synthesized. Finished files stay in memory up to a byte bound,
//! oldest dropped first; a dropped one is made again when asked for
//! (mostly from the tile cache).

use crate::error::ApiError;
use crate::registry::Entry;
use crate::spec::hex;
use axum::body::Bytes;
use parking_lot::Mutex;
use serde_json::{Value, json};
use sha2::{Digest, Sha256};
use solidtex_core::export::Export;
use solidtex_core::{CancelFlag, Cancelled, Texture, run_cancellable};
use std::collections::{HashMap, VecDeque};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use tokio::sync::{Semaphore, watch};

/// Where an export stands.
#[derive(Clone, Debug)]
pub(crate) enum Phase {
    /// Being synthesized.
    Running,
    /// Done: the file's bytes.
    Done(Bytes),
    /// Failed, with the error a client gets.
    Failed(ApiError),
}

/// One export, running or done.
pub(crate) struct ExportJob {
    /// Its id (hex).
    pub id: String,
    /// The texture's id.
    pub texture: String,
    /// What is exported.
    pub export: Export,
    /// The file's name.
    pub file_name: String,
    /// Voxels to synthesize.
    pub total: u64,
    done: AtomicU64,
    phase: watch::Sender<Phase>,
}

impl ExportJob {
    /// Voxels synthesized so far.
    pub fn done_voxels(&self) -> u64 {
        self.done.load(Ordering::Relaxed)
    }

    /// Where it stands now.
    pub fn phase(&self) -> Phase {
        self.phase.borrow().clone()
    }

    /// Waits until it is done or failed.
    pub async fn finished(&self) -> Phase {
        let mut rx = self.phase.subscribe();
        let seen = rx
            .wait_for(|p| !matches!(p, Phase::Running))
            .await
            .map(|p| p.clone());
        seen.unwrap_or_else(|_| Phase::Failed(ApiError::internal("the export was dropped")))
    }

    /// Its status as JSON (what `GET /v1/exports/{id}` answers).
    pub fn status(&self) -> Value {
        let done = self.done_voxels();
        let (status, bytes, error) = match self.phase() {
            Phase::Running => ("running", None, None),
            Phase::Done(b) => ("done", Some(b.len()), None),
            Phase::Failed(e) => (
                "failed",
                None,
                Some(json!({"code": e.code, "message": e.message, "status": e.status.as_u16()})),
            ),
        };
        let progress = if status == "done" {
            1.0
        } else {
            done as f64 / self.total.max(1) as f64
        };
        let mut v = json!({
            "id": self.id,
            "texture": self.texture,
            "format": self.export.format.name(),
            "file": self.file_name,
            "media_type": self.export.format.media_type(),
            "status": status,
            "progress": progress,
            "voxels": {"done": done, "total": self.total},
            "url": format!("/v1/exports/{}", self.id),
            "file_url": format!("/v1/exports/{}/file", self.id),
        });
        let o = v.as_object_mut().expect("an object");
        if let Some(b) = bytes {
            o.insert("bytes".into(), json!(b));
        }
        if let Some(e) = error {
            o.insert("error".into(), e);
        }
        v
    }
}

/// The exports of a server.
pub(crate) struct Exports {
    /// Exports running or waiting, at most one more than may wait.
    admit: Arc<Semaphore>,
    /// The one export that runs.
    run: Arc<Semaphore>,
    max_work: u64,
    max_bytes: u64,
    inner: Mutex<Inner>,
}

#[derive(Default)]
struct Inner {
    by_id: HashMap<String, Arc<ExportJob>>,
    /// Finished exports, oldest first, and the bytes they hold.
    finished: VecDeque<String>,
    bytes: u64,
}

/// The normalised form of an export, for ids and ETags.
pub fn export_key(e: &Export) -> String {
    let r = &e.region;
    format!(
        "export/{}/{}/{}/{}/{}/{}/{}/{}/{}/{:?}/{}",
        e.format.name(),
        e.lod,
        r.origin[0],
        r.origin[1],
        r.origin[2],
        r.size[0],
        r.size[1],
        r.size[2],
        u8::from(e.srgb),
        e.mips,
        env!("CARGO_PKG_VERSION"),
    )
}

impl Exports {
    /// One export running and `queue` waiting, none synthesizing more than
    /// `max_work` voxels, keeping at most `max_bytes` of finished files.
    pub(crate) fn new(queue: u32, max_work: u64, max_bytes: u64) -> Exports {
        Exports {
            admit: Arc::new(Semaphore::new(1 + queue as usize)),
            run: Arc::new(Semaphore::new(1)),
            max_work,
            max_bytes,
            inner: Mutex::default(),
        }
    }

    /// The export `id`, if it is known.
    pub(crate) fn get(&self, id: &str) -> Option<Arc<ExportJob>> {
        self.inner.lock().by_id.get(id).cloned()
    }

    /// The export of `tex` (the texture `entry`) described by `export`:
    /// the one already made or being made, or a new one started now.
    pub(crate) fn start(
        self: &Arc<Self>,
        entry: &Entry,
        tex: Texture,
        export: Export,
    ) -> Result<Arc<ExportJob>, ApiError> {
        let mut h = Sha256::new();
        h.update(b"solidtex export v1\0");
        h.update(entry.content_hash.as_bytes());
        h.update(b"\0");
        h.update(export_key(&export).as_bytes());
        let id = hex(&h.finalize()[..16]);
        let mut inner = self.inner.lock();
        if let Some(job) = inner.by_id.get(&id)
            && !matches!(job.phase(), Phase::Failed(_))
        {
            return Ok(job.clone());
        }
        let Ok(admitted) = self.admit.clone().try_acquire_owned() else {
            return Err(ApiError::overloaded("the export queue is full").retry_after(10));
        };
        let job = Arc::new(ExportJob {
            id: id.clone(),
            texture: entry.id.clone(),
            file_name: export.file_name(&entry.id),
            total: export.voxels(&tex),
            export,
            done: AtomicU64::new(0),
            phase: watch::Sender::new(Phase::Running),
        });
        inner.by_id.insert(id, job.clone());
        drop(inner);
        let (this, running) = (self.clone(), job.clone());
        tokio::spawn(async move {
            let phase = this.run(admitted, &running, tex, export).await;
            if let Phase::Done(bytes) = &phase {
                this.keep(&running.id, bytes.len() as u64);
            }
            running.phase.send_replace(phase);
        });
        Ok(job)
    }

    /// Runs one export once the slot is free, on a blocking thread.
    async fn run(
        &self,
        admitted: tokio::sync::OwnedSemaphorePermit,
        job: &Arc<ExportJob>,
        tex: Texture,
        export: Export,
    ) -> Phase {
        let Ok(slot) = self.run.clone().acquire_owned().await else {
            return Phase::Failed(ApiError::internal("the export queue closed"));
        };
        let flag = CancelFlag::with_budget(self.max_work);
        let budget = flag.clone();
        let progress = job.clone();
        let handle = tokio::task::spawn_blocking(move || {
            let _slots = (admitted, slot);
            run_cancellable(&flag, || {
                export.run(&tex, &|done, _| {
                    progress.done.store(done, Ordering::Relaxed);
                })
            })
        });
        match handle.await {
            Ok(Ok(Ok((bytes, _)))) => Phase::Done(Bytes::from(bytes)),
            Ok(Ok(Err(e))) => Phase::Failed(e.into()),
            Ok(Err(Cancelled)) if budget.is_over_budget() => Phase::Failed(ApiError::new(
                axum::http::StatusCode::BAD_REQUEST,
                "over_budget",
                format!(
                    "this export needed more than {} voxels synthesized, the server's budget \
                     per export (--max-export-work)",
                    self.max_work
                ),
            )),
            Ok(Err(Cancelled)) => Phase::Failed(ApiError::internal("the export was cancelled")),
            Err(e) => Phase::Failed(ApiError::internal(format!("the export failed: {e}"))),
        }
    }

    /// Counts a finished file and drops the oldest beyond the bound.
    fn keep(&self, id: &str, bytes: u64) {
        let mut inner = self.inner.lock();
        inner.finished.push_back(id.to_string());
        inner.bytes += bytes;
        while inner.bytes > self.max_bytes {
            let Some(old) = inner.finished.pop_front() else {
                break;
            };
            let size = match inner.by_id.remove(&old).map(|j| j.phase()) {
                Some(Phase::Done(b)) => b.len() as u64,
                // The one finishing now, whose phase is set after this.
                _ if old == id => bytes,
                _ => 0,
            };
            inner.bytes = inner.bytes.saturating_sub(size);
        }
    }
}
