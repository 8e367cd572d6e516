//! Backpressure for synthesis: at most `max_jobs` jobs run at once and at
//! most `queue` more wait for a slot; a request beyond that is refused at
//! once as overloaded (503 with `Retry-After` to clients) instead of piling
//! up memory or timing out.
//!
//! Waiting is bounded in time too: a job that has not started within
//! `max_wait` is refused too, and one whose predicted wait (the jobs ahead
//! of it times the recent mean job time, over the running slots) already
//! exceeds `max_wait` is refused on arrival. Latency under overload thus
//! stays near `max_wait` plus one job, and `Retry-After` carries the
//! prediction.
//!
//! A job runs on a dedicated blocking thread, never on the async workers
//! that answer HTTP; the engine parallelises inside it on the rayon pool.
//! Calling the engine from outside the rayon pool matters: a tile that a
//! concurrent request is already computing is then waited for instead of
//! recomputed (inside the pool the engine must compute it again to avoid
//! blocking a rayon worker). The slots are owned by the job itself, so a
//! client that disconnects does not free a slot before its work has
//! actually stopped; its synthesis is cancelled (see
//! [`solidtex_core::synth::cancel`]) and stops within a correction subpass.

use super::metrics::Metrics;
use super::panics::panic_message;
use solidtex_core::{CancelFlag, Cancelled, run_cancellable};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};
use tokio::sync::Semaphore;

/// Why a job did not run to its end.
#[derive(Debug, thiserror::Error)]
pub enum JobError {
    /// Refused for now: the queue is full or too slow; a retry after
    /// `retry_after` seconds may succeed.
    #[error("{reason}; retry later")]
    Overloaded {
        /// What is overloaded.
        reason: &'static str,
        /// Seconds after which a retry may succeed.
        retry_after: u32,
    },
    /// Stopped: it would synthesize more than `budget` voxels.
    #[error("over the work budget of {budget} voxels")]
    OverBudget {
        /// The budget of one job, voxels.
        budget: u64,
    },
    /// It panicked or was cancelled.
    #[error("{0}")]
    Failed(String),
}

/// The synthesis job queue.
#[derive(Clone)]
pub struct Jobs {
    admit: Arc<Semaphore>,
    run: Arc<Semaphore>,
    max_jobs: usize,
    max_wait: Duration,
    /// Exponential moving average of job run time, seconds (`f64` bits).
    mean_run: Arc<AtomicU64>,
    metrics: Arc<Metrics>,
    /// Voxels one job may synthesize (`None`: unbounded).
    work_budget: Option<u64>,
}

/// Weight of the newest job in the moving average of run times.
const MEAN_WEIGHT: f64 = 0.2;

impl Jobs {
    /// `max_jobs` running at once, `queue` more waiting, none waiting
    /// longer than `max_wait`.
    pub fn new(max_jobs: u32, queue: u32, max_wait: Duration, metrics: Arc<Metrics>) -> Jobs {
        let max_jobs = max_jobs.max(1) as usize;
        Jobs {
            admit: Arc::new(Semaphore::new(max_jobs + queue as usize)),
            run: Arc::new(Semaphore::new(max_jobs)),
            max_jobs,
            max_wait,
            mean_run: Arc::new(AtomicU64::new(0f64.to_bits())),
            metrics,
            work_budget: None,
        }
    }

    /// The same queue, stopping any job that would synthesize more than
    /// `voxels` voxels (all levels; cached ones are free) with
    /// [`JobError::OverBudget`], so that no admitted request runs for long.
    pub fn with_work_budget(mut self, voxels: u64) -> Jobs {
        self.work_budget = Some(voxels);
        self
    }

    /// Recent mean run time of a job, seconds (0 before the first).
    pub fn mean_run_seconds(&self) -> f64 {
        f64::from_bits(self.mean_run.load(Ordering::Relaxed))
    }

    fn record_run(&self, seconds: f64) {
        let _ = self
            .mean_run
            .fetch_update(Ordering::Relaxed, Ordering::Relaxed, |old| {
                let old = f64::from_bits(old);
                let new = if old == 0.0 {
                    seconds
                } else {
                    old + MEAN_WEIGHT * (seconds - old)
                };
                Some(new.to_bits())
            });
    }

    /// Predicted wait of a job arriving now: the jobs already waiting take
    /// their turn on `max_jobs` slots at the mean run time. The running
    /// jobs' remainders are not counted, so the first in line is always
    /// admitted and the slots never idle while refused clients back off.
    fn predicted_wait(&self) -> f64 {
        let busy = self.metrics.jobs_running.get().max(0) as usize;
        if busy < self.max_jobs {
            return 0.0;
        }
        let ahead = self.metrics.jobs_queued.get().max(0) as f64;
        ahead / self.max_jobs as f64 * self.mean_run_seconds()
    }

    fn refuse(&self, reason: &'static str, retry_seconds: f64) -> JobError {
        self.metrics.jobs_rejected.inc();
        JobError::Overloaded {
            reason,
            retry_after: retry_seconds.ceil().clamp(1.0, 3600.0) as u32,
        }
    }

    /// Runs `f` on a blocking thread once a slot is free. Fails overloaded
    /// if the queue is full or the wait for a slot would exceed the limit,
    /// and failed if `f` panics.
    pub async fn run<T, F>(&self, f: F) -> Result<T, JobError>
    where
        T: Send + 'static,
        F: FnOnce() -> T + Send + 'static,
    {
        self.run_within(self.work_budget, f).await
    }

    /// [`Jobs::run`] under a work budget of its own (`None`: unbounded),
    /// for requests larger than interactive ones (a mesh bake).
    pub async fn run_within<T, F>(&self, work_budget: Option<u64>, f: F) -> Result<T, JobError>
    where
        T: Send + 'static,
        F: FnOnce() -> T + Send + 'static,
    {
        let predicted = self.predicted_wait();
        if predicted > self.max_wait.as_secs_f64() {
            return Err(self.refuse("synthesis queue is too slow", predicted));
        }
        let Ok(admitted) = self.admit.clone().try_acquire_owned() else {
            return Err(self.refuse("synthesis queue is full", predicted));
        };
        let queued = GaugeGuard::new(&self.metrics.jobs_queued);
        let admitted_at = Instant::now();
        let running_slot =
            match tokio::time::timeout(self.max_wait, self.run.clone().acquire_owned()).await {
                Ok(slot) => slot.map_err(|_| JobError::Failed("job queue closed".into()))?,
                Err(_) => {
                    self.metrics.jobs_timed_out.inc();
                    return Err(self.refuse(
                        "synthesis queue wait limit reached",
                        self.predicted_wait().max(1.0),
                    ));
                }
            };
        drop(queued);
        self.metrics
            .job_wait
            .observe(admitted_at.elapsed().as_secs_f64());
        let metrics = self.metrics.clone();
        let this = self.clone();
        // Dropping this future (the client hung up) stops the synthesis.
        let flag = work_budget.map_or_else(CancelFlag::new, CancelFlag::with_budget);
        let budget_flag = flag.clone();
        let _cancel_on_drop = CancelOnDrop(flag.clone());
        let handle = tokio::task::spawn_blocking(move || {
            let _slots = (admitted, running_slot);
            let _running = GaugeGuard::new(&metrics.jobs_running);
            let started = Instant::now();
            let out = run_cancellable(&flag, f);
            match out {
                Ok(_) => this.record_run(started.elapsed().as_secs_f64()),
                Err(Cancelled) => {
                    metrics.jobs_cancelled.inc();
                }
            }
            out
        });
        match handle.await {
            Ok(Ok(v)) => Ok(v),
            Ok(Err(Cancelled)) if budget_flag.is_over_budget() => {
                self.metrics.over_budget("running");
                Err(JobError::OverBudget {
                    budget: work_budget.unwrap_or_default(),
                })
            }
            Ok(Err(Cancelled)) => Err(JobError::Failed("job cancelled".into())),
            Err(e) if e.is_panic() => {
                let p = e.into_panic();
                Err(JobError::Failed(format!(
                    "internal error: {}",
                    panic_message(p.as_ref())
                )))
            }
            Err(_) => Err(JobError::Failed("job cancelled".into())),
        }
    }

    /// Jobs running at once at most.
    pub fn max_jobs(&self) -> usize {
        self.max_jobs
    }

    /// True when a new job would be refused.
    pub fn is_full(&self) -> bool {
        self.admit.available_permits() == 0
    }

    /// Jobs waiting plus running.
    #[cfg(test)]
    fn in_flight(&self) -> usize {
        (self.metrics.jobs_queued.get() + self.metrics.jobs_running.get()) as usize
    }
}

/// Sets a cancellation flag when dropped.
struct CancelOnDrop(CancelFlag);

impl Drop for CancelOnDrop {
    fn drop(&mut self) {
        self.0.cancel();
    }
}

/// Increments a gauge for as long as it lives.
struct GaugeGuard(prometheus_client::metrics::gauge::Gauge);

impl GaugeGuard {
    fn new(g: &prometheus_client::metrics::gauge::Gauge) -> GaugeGuard {
        g.inc();
        GaugeGuard(g.clone())
    }
}

impl Drop for GaugeGuard {
    fn drop(&mut self) {
        self.0.dec();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use solidtex_core::TileCache;
    use std::sync::mpsc;

    fn jobs(max: u32, queue: u32) -> Jobs {
        jobs_waiting(max, queue, Duration::from_secs(600))
    }

    fn jobs_waiting(max: u32, queue: u32, wait: Duration) -> Jobs {
        Jobs::new(
            max,
            queue,
            wait,
            Arc::new(Metrics::new(Arc::new(TileCache::new(1 << 20)))),
        )
    }

    /// Occupies every running slot of `j` until the returned sender is
    /// dropped or sent to.
    async fn hold_slots(
        j: &Jobs,
        n: usize,
    ) -> (mpsc::Sender<()>, Vec<tokio::task::JoinHandle<()>>) {
        let (tx, rx) = mpsc::channel::<()>();
        let rx = Arc::new(std::sync::Mutex::new(rx));
        let mut held = Vec::new();
        for _ in 0..n {
            let j = j.clone();
            let rx = rx.clone();
            held.push(tokio::spawn(async move {
                let _ = j
                    .run(move || {
                        let _ = rx.lock().unwrap().recv();
                    })
                    .await;
            }));
        }
        for _ in 0..200 {
            if j.metrics.jobs_running.get() as usize == n {
                break;
            }
            tokio::time::sleep(Duration::from_millis(5)).await;
        }
        assert_eq!(j.metrics.jobs_running.get() as usize, n);
        (tx, held)
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_job_waiting_past_the_limit_is_refused() {
        let j = jobs_waiting(1, 4, Duration::from_millis(150));
        let (tx, held) = hold_slots(&j, 1).await;
        let t = Instant::now();
        let e = j.run(|| ()).await.unwrap_err();
        assert!(
            matches!(e, JobError::Overloaded { retry_after, .. } if retry_after >= 1),
            "{e:?}"
        );
        assert!(t.elapsed() >= Duration::from_millis(150));
        assert_eq!(j.metrics.jobs_timed_out.get(), 1);
        drop(tx);
        for h in held {
            h.await.unwrap();
        }
        // With the slot free again, a job runs.
        assert_eq!(j.run(|| 5).await.unwrap(), 5);
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_job_predicted_to_wait_too_long_is_refused_at_once() {
        let j = jobs_waiting(1, 4, Duration::from_secs(2));
        j.record_run(10.0);
        let (tx, held) = hold_slots(&j, 1).await;
        // The first in line is admitted: it may get the slot in time.
        let first = {
            let j = j.clone();
            tokio::spawn(async move { j.run(|| ()).await })
        };
        for _ in 0..200 {
            if j.metrics.jobs_queued.get() == 1 {
                break;
            }
            tokio::time::sleep(Duration::from_millis(5)).await;
        }
        assert_eq!(j.metrics.jobs_queued.get(), 1);
        // The next would wait a whole mean job (10 s) behind it.
        let t = Instant::now();
        let e = j.run(|| ()).await.unwrap_err();
        assert!(t.elapsed() < Duration::from_secs(1), "not refused at once");
        assert!(
            matches!(
                e,
                JobError::Overloaded {
                    retry_after: 10,
                    ..
                }
            ),
            "{e:?}"
        );
        assert_eq!(j.metrics.jobs_timed_out.get(), 0);
        drop(tx);
        for h in held {
            h.await.unwrap();
        }
        first.await.unwrap().unwrap();
        // The mean moves towards recent jobs.
        j.run(|| ()).await.unwrap();
        assert!(j.mean_run_seconds() < 10.0);
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn runs_and_returns() {
        let j = jobs(2, 2);
        assert_eq!(j.run(|| 6 * 7).await.unwrap(), 42);
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_full_queue_refuses() {
        let j = jobs(1, 1);
        let (tx, rx) = mpsc::channel::<()>();
        let rx = Arc::new(std::sync::Mutex::new(rx));
        let mut held = Vec::new();
        for _ in 0..2 {
            let j = j.clone();
            let rx = rx.clone();
            held.push(tokio::spawn(async move {
                j.run(move || {
                    let _ = rx.lock().unwrap().recv();
                })
                .await
            }));
        }
        // Let both be admitted (one running, one queued).
        for _ in 0..100 {
            if j.in_flight() == 2 {
                break;
            }
            tokio::time::sleep(std::time::Duration::from_millis(5)).await;
        }
        let e = j.run(|| ()).await.unwrap_err();
        assert!(
            matches!(e, JobError::Overloaded { retry_after: 1, .. }),
            "{e:?}"
        );
        tx.send(()).unwrap();
        tx.send(()).unwrap();
        for h in held {
            h.await.unwrap().unwrap();
        }
        assert_eq!(j.in_flight(), 0);
        j.run(|| ()).await.unwrap();
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn jobs_call_the_engine_from_outside_the_rayon_pool() {
        // Outside the pool the engine waits for a tile a concurrent request
        // is computing instead of computing it again.
        let j = jobs(2, 2);
        let in_pool = j.run(|| rayon::current_thread_index().is_some()).await;
        assert!(!in_pool.unwrap());
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_panic_fails_the_job_and_frees_the_slot() {
        let j = jobs(1, 0);
        let e = j.run(|| panic!("kaboom")).await.unwrap_err();
        assert!(
            matches!(&e, JobError::Failed(m) if m.contains("kaboom")),
            "{e:?}"
        );
        assert_eq!(j.run(|| 1).await.unwrap(), 1);
    }
}
