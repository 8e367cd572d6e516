//! Uploaded images are decoded within a bound. Each upload reserves, from
//! `--max-decode-bytes`, the most its images' headers say decoding them
//! will allocate (see [`solidtex_core::Exemplar::decode_peak_bytes`])
//! before any pixel is decoded, and decodes run at most one per core. An
//! upload that does not fit now waits for room, up to the queue wait, then
//! gets 503 with `Retry-After`; one that could never fit gets 413. The
//! bound is a part of the server's memory bound ([`crate::memory`]).

use std::sync::Arc;
use std::time::Duration;
use tokio::sync::{OwnedSemaphorePermit, Semaphore};

/// Why an upload is not decoded.
#[derive(Debug, thiserror::Error)]
pub(crate) enum DecodeError {
    /// Its decode alone needs more than the whole bound.
    #[error("decoding these images takes about {needed} bytes, over {bound}")]
    TooLarge {
        /// Estimated peak bytes.
        needed: u64,
        /// The bound, bytes.
        bound: u64,
    },
    /// No room within the wait.
    #[error("image decoding is busy")]
    Busy,
}

/// Granularity of the bound.
const UNIT: u64 = 1 << 20;

/// The decode bound of one server.
pub(crate) struct Decodes {
    memory: Arc<Semaphore>,
    slots: Arc<Semaphore>,
    max_bytes: u64,
    max_wait: Duration,
}

/// Room for one upload's decodes, given back when dropped.
pub(crate) struct Admitted {
    _slot: OwnedSemaphorePermit,
    _memory: OwnedSemaphorePermit,
}

impl Decodes {
    /// Decodes taking at most `max_bytes` together, `slots` at once, an
    /// upload waiting at most `max_wait` for room.
    pub(crate) fn new(max_bytes: u64, slots: usize, max_wait: Duration) -> Decodes {
        let units = (max_bytes / UNIT).clamp(1, u64::from(u32::MAX));
        Decodes {
            memory: Arc::new(Semaphore::new(units as usize)),
            slots: Arc::new(Semaphore::new(slots.max(1))),
            max_bytes,
            max_wait,
        }
    }

    /// `--max-decode-bytes`.
    pub(crate) fn max_bytes(&self) -> u64 {
        self.max_bytes
    }

    /// Waits for room to decode images estimated to take `bytes` at their
    /// peak.
    pub(crate) async fn admit(&self, bytes: u64) -> Result<Admitted, DecodeError> {
        if bytes > self.max_bytes {
            return Err(DecodeError::TooLarge {
                needed: bytes,
                bound: self.max_bytes,
            });
        }
        let units = u32::try_from(bytes.div_ceil(UNIT).max(1)).unwrap_or(u32::MAX);
        let wait = async {
            let slot = self.slots.clone().acquire_owned().await;
            let memory = self.memory.clone().acquire_many_owned(units).await;
            match (slot, memory) {
                (Ok(slot), Ok(memory)) => Ok(Admitted {
                    _slot: slot,
                    _memory: memory,
                }),
                _ => Err(DecodeError::Busy),
            }
        };
        tokio::time::timeout(self.max_wait, wait)
            .await
            .unwrap_or(Err(DecodeError::Busy))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn decodes_share_the_bound_and_wait_for_room() {
        let d = Decodes::new(10 * UNIT, 4, Duration::from_millis(50));
        assert!(matches!(
            d.admit(11 * UNIT).await,
            Err(DecodeError::TooLarge { .. })
        ));
        let a = d.admit(6 * UNIT).await.unwrap();
        let b = d.admit(4 * UNIT).await.unwrap();
        // Full: the next one waits, then is refused.
        assert!(matches!(d.admit(1).await, Err(DecodeError::Busy)));
        drop(a);
        let c = d.admit(6 * UNIT).await.unwrap();
        drop((b, c));
        // One per slot: a second waits for the first.
        let one = Decodes::new(10 * UNIT, 1, Duration::from_millis(50));
        let first = one.admit(1).await.unwrap();
        assert!(matches!(one.admit(1).await, Err(DecodeError::Busy)));
        drop(first);
        assert!(one.admit(1).await.is_ok());
    }
}
