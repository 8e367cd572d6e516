//! The server's own bound on its resident memory, from its configured
//! limits and what it holds now, exposed at `/metrics` as
//! `solidtex_memory_bound_bytes` (one gauge per part; their sum is the
//! bound) so that a soak can check the process against it and an operator
//! can size a machine from the flags.
//!
//! The parts: the tile cache at its bound; the candidates resident now
//! (at most `--max-resident-bytes`); the estimated peaks of the
//! precomputes running now (at most `--max-precompute-bytes`); every job
//! slot at its most (`--max-jobs` times a job's working set and answer);
//! the decodes of uploaded images at their bound (`--max-decode-bytes`:
//! they are brief, and what they free stays resident for about a second);
//! the process's own footprint; and the allocator's slack over the heap.
//! Not counted: answers already computed and still being written to slow
//! clients.

/// Resident memory of the process besides the parts below: the binary's
/// mapped pages, thread stacks, the runtime's and allocator's own
/// structures (measured on an idle server: docs/server.md).
pub const BASE_BYTES: u64 = 64 << 20;

/// Working memory of one synthesis job besides its answer: the dependency
/// masks and triple grids of its tile groups, one group per level at most
/// at a time. Above the largest heap peak measured over requests near the
/// work budget (docs/server.md).
pub const JOB_WORKING_BYTES: u64 = 160 << 20;

/// Bytes per voxel of a job's answer: the final triples of the requested
/// box (12), its RGB (3) and the encoded answer (at most as large).
pub const JOB_BYTES_PER_VOXEL: u64 = 18;

/// One part of the bound.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Part {
    /// Its label in `/metrics`.
    pub name: &'static str,
    /// Its bytes.
    pub bytes: u64,
}

/// What the bound is made of now.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Inputs {
    /// `--cache-bytes`.
    pub cache_max_bytes: u64,
    /// Bytes of candidates resident now.
    pub candidates_bytes: u64,
    /// Estimated peaks of the precomputes running now.
    pub precompute_bytes: u64,
    /// `--max-jobs`.
    pub max_jobs: u64,
    /// `--max-decode-bytes`.
    pub decode_bytes: u64,
    /// Voxels one answer may hold: the smaller of `--max-request-voxels`
    /// and `--max-request-work` (a request's own voxels are part of what
    /// it synthesizes).
    pub answer_voxels: u64,
}

/// The parts of the bound; their sum is the bound.
pub fn bound(i: &Inputs) -> [Part; 7] {
    let job = JOB_WORKING_BYTES.saturating_add(i.answer_voxels.saturating_mul(JOB_BYTES_PER_VOXEL));
    let jobs = i.max_jobs.saturating_mul(job);
    let heap = i
        .cache_max_bytes
        .saturating_add(i.candidates_bytes)
        .saturating_add(i.precompute_bytes)
        .saturating_add(jobs)
        .saturating_add(i.decode_bytes);
    [
        Part {
            name: "base",
            bytes: BASE_BYTES,
        },
        Part {
            name: "cache",
            bytes: i.cache_max_bytes,
        },
        Part {
            name: "candidates",
            bytes: i.candidates_bytes,
        },
        Part {
            name: "precomputes",
            bytes: i.precompute_bytes,
        },
        Part {
            name: "jobs",
            bytes: jobs,
        },
        Part {
            name: "decodes",
            bytes: i.decode_bytes,
        },
        // Size classes and freed pages the allocator has not returned yet
        // (it returns them after about a second, see `main.rs`).
        Part {
            name: "allocator",
            bytes: heap / 8,
        },
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_parts_add_up_from_the_limits() {
        let parts = bound(&Inputs {
            cache_max_bytes: 256 << 20,
            candidates_bytes: 64 << 20,
            precompute_bytes: 0,
            max_jobs: 2,
            decode_bytes: 32 << 20,
            answer_voxels: 1 << 20,
        });
        let get = |n: &str| parts.iter().find(|p| p.name == n).unwrap().bytes;
        assert_eq!(get("jobs"), 2 * (JOB_WORKING_BYTES + 18 * (1 << 20)));
        assert_eq!(get("decodes"), 32 << 20);
        let heap = (256u64 << 20) + (64 << 20) + get("jobs") + (32 << 20);
        assert_eq!(get("allocator"), heap / 8);
        let total: u64 = parts.iter().map(|p| p.bytes).sum();
        assert_eq!(total, BASE_BYTES + heap + heap / 8);
    }
}
