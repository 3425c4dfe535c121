//! Where password hashes run: at most one per core at a time, on tokio's blocking threads,
//! with a short queue in front; beyond the queue a check is refused at once.
//!
//! Each argon2id hash takes 19 MiB for its run. Unbounded, 60 sign-ins at once took
//! 60 × 19 MiB, and the allocator kept it. Bounded to the cores, a burst costs what the
//! cores can hash at once and no more, and takes no longer than the same work queued by
//! the operating system. The permit travels with the hash onto its thread, so a client that
//! hangs up while its hash runs does not free a slot for another hash beside it.

use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use tokio::sync::Semaphore;

/// Password checks queued per core before more are refused.
const QUEUED_PER_CORE: usize = 8;

/// The hash queue was full: refused without hashing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("{queued} password checks are waiting already: try again in a moment")]
pub struct Busy {
    pub queued: usize,
}

/// Runs argon2 hashes, at most `parallel` at once and `queue` waiting.
#[derive(Debug)]
pub struct Hasher {
    parallel: usize,
    permits: Arc<Semaphore>,
    waiting: AtomicUsize,
    queue: usize,
}

impl Default for Hasher {
    /// One hash per core, [`QUEUED_PER_CORE`] waiting per core.
    fn default() -> Self {
        let cores = std::thread::available_parallelism().map_or(1, usize::from);
        Self::new(cores, cores * QUEUED_PER_CORE)
    }
}

/// Counts a waiting check, and stops counting it however the wait ends.
struct Waiting<'a>(&'a AtomicUsize);

impl Drop for Waiting<'_> {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::SeqCst);
    }
}

impl Hasher {
    /// At most `parallel` (at least 1) hashes at once, `queue` more waiting.
    pub fn new(parallel: usize, queue: usize) -> Self {
        let parallel = parallel.max(1);
        Self {
            parallel,
            permits: Arc::new(Semaphore::new(parallel)),
            waiting: AtomicUsize::new(0),
            queue,
        }
    }

    /// Runs `work` on a blocking thread once a slot is free; refused when `queue` checks
    /// are waiting already. `None`: the work panicked.
    pub async fn run<T: Send + 'static>(
        &self,
        work: impl FnOnce() -> T + Send + 'static,
    ) -> Result<Option<T>, Busy> {
        let queued = self.waiting.fetch_add(1, Ordering::SeqCst);
        let waiting = Waiting(&self.waiting);
        if queued >= self.queue && self.permits.available_permits() == 0 {
            return Err(Busy { queued });
        }
        let permit = Arc::clone(&self.permits)
            .acquire_owned()
            .await
            .expect("the hasher's semaphore is never closed");
        drop(waiting);
        let done = tokio::task::spawn_blocking(move || {
            let out = work();
            drop(permit);
            out
        });
        // A hash that panicked is a failed check, not a crashed service.
        Ok(done.await.ok())
    }

    /// Whether `password` matches the stored `hash` (see [`super::verify_password`]).
    pub async fn verify(&self, password: String, hash: String) -> Result<bool, Busy> {
        let matched = self
            .run(move || super::verify_password(&password, &hash))
            .await?;
        Ok(matched.unwrap_or(false))
    }

    /// Hashes running now.
    pub fn running(&self) -> usize {
        self.parallel - self.permits.available_permits()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn at_most_parallel_run_at_once_and_a_full_queue_is_refused() {
        let hasher = Arc::new(Hasher::new(2, 3));
        let (running, most) = (Arc::new(AtomicUsize::new(0)), Arc::new(AtomicUsize::new(0)));
        // Held until released, so the queue fills while two run.
        let gate = Arc::new(tokio::sync::Semaphore::new(0));
        let mut tasks = Vec::new();
        for _ in 0..5 {
            let (h, r, m, g) = (
                Arc::clone(&hasher),
                Arc::clone(&running),
                Arc::clone(&most),
                Arc::clone(&gate),
            );
            tasks.push(tokio::spawn(async move {
                h.run(move || {
                    let now = r.fetch_add(1, Ordering::SeqCst) + 1;
                    m.fetch_max(now, Ordering::SeqCst);
                    let rt = tokio::runtime::Handle::current();
                    drop(rt.block_on(g.acquire()).map(|p| p.forget()));
                    r.fetch_sub(1, Ordering::SeqCst);
                })
                .await
            }));
        }
        // Two run, three wait: the sixth is refused.
        while hasher.running() < 2 || hasher.waiting.load(Ordering::SeqCst) < 3 {
            tokio::task::yield_now().await;
        }
        assert_eq!(hasher.run(|| ()).await, Err(Busy { queued: 3 }));
        gate.add_permits(5);
        for t in tasks {
            assert_eq!(t.await.unwrap(), Ok(Some(())));
        }
        assert_eq!(
            most.load(Ordering::SeqCst),
            2,
            "never more than two at once"
        );
        assert_eq!(hasher.waiting.load(Ordering::SeqCst), 0);
    }
}
