//! Backpressure for synthesis: at most `max_jobs` jobs run at once and at
//! most `queue` more wait for a slot; a request beyond that is refused at
//! once with 503 and `Retry-After` instead of piling up memory or timing
//! out.
//!
//! A job runs on a dedicated blocking thread, never on the async workers
//! that answer HTTP; the engine parallelises inside it on the rayon pool.
//! Calling the engine from outside the rayon pool matters: a tile that a
//! concurrent request is already computing is then waited for instead of
//! recomputed (inside the pool the engine must compute it again to avoid
//! blocking a rayon worker). The slots are owned by the job itself, so a
//! client that disconnects does not free a slot before its work has
//! actually stopped.

use super::error::{ApiError, panic_message};
use super::metrics::Metrics;
use std::sync::Arc;
use tokio::sync::Semaphore;

/// The synthesis job queue.
#[derive(Clone)]
pub struct Jobs {
    admit: Arc<Semaphore>,
    run: Arc<Semaphore>,
    metrics: Arc<Metrics>,
}

impl Jobs {
    /// `max_jobs` running at once, `queue` more waiting.
    pub fn new(max_jobs: u32, queue: u32, metrics: Arc<Metrics>) -> Jobs {
        let max_jobs = max_jobs.max(1) as usize;
        Jobs {
            admit: Arc::new(Semaphore::new(max_jobs + queue as usize)),
            run: Arc::new(Semaphore::new(max_jobs)),
            metrics,
        }
    }

    /// Runs `f` on a blocking thread once a slot is free. Fails with 503 if
    /// the queue is full and with 500 if `f` panics.
    pub async fn run<T, F>(&self, f: F) -> Result<T, ApiError>
    where
        T: Send + 'static,
        F: FnOnce() -> T + Send + 'static,
    {
        let Ok(admitted) = self.admit.clone().try_acquire_owned() else {
            self.metrics.jobs_rejected.inc();
            return Err(ApiError::overloaded("synthesis"));
        };
        let queued = GaugeGuard::new(&self.metrics.jobs_queued);
        let admitted_at = std::time::Instant::now();
        let running_slot = self
            .run
            .clone()
            .acquire_owned()
            .await
            .map_err(|_| ApiError::internal("job queue closed"))?;
        drop(queued);
        self.metrics
            .job_wait
            .observe(admitted_at.elapsed().as_secs_f64());
        let metrics = self.metrics.clone();
        let handle = tokio::task::spawn_blocking(move || {
            let _slots = (admitted, running_slot);
            let _running = GaugeGuard::new(&metrics.jobs_running);
            f()
        });
        match handle.await {
            Ok(v) => Ok(v),
            Err(e) if e.is_panic() => {
                let p = e.into_panic();
                Err(ApiError::internal(format!(
                    "internal error: {}",
                    panic_message(p.as_ref())
                )))
            }
            Err(_) => Err(ApiError::internal("job cancelled")),
        }
    }

    /// True when a new job would be refused.
    pub fn is_full(&self) -> bool {
        self.admit.available_permits() == 0
    }

    /// Jobs waiting plus running.
    pub fn in_flight(&self) -> usize {
        (self.metrics.jobs_queued.get() + self.metrics.jobs_running.get()) as usize
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
    use crate::TileCache;
    use std::sync::mpsc;

    fn jobs(max: u32, queue: u32) -> Jobs {
        Jobs::new(
            max,
            queue,
            Arc::new(Metrics::new(Arc::new(TileCache::new(1 << 20)))),
        )
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn runs_and_returns() {
        let j = jobs(2, 2);
        assert_eq!(j.run(|| 6 * 7).await.unwrap(), 42);
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn full_queue_is_503() {
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
        assert_eq!(e.status.as_u16(), 503);
        assert_eq!(e.retry_after, Some(1));
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
    async fn panic_is_500_and_frees_the_slot() {
        let j = jobs(1, 0);
        let e = j.run(|| panic!("kaboom")).await.unwrap_err();
        assert_eq!(e.status.as_u16(), 500);
        assert!(e.message.contains("kaboom"));
        assert_eq!(j.run(|| 1).await.unwrap(), 1);
    }
}
