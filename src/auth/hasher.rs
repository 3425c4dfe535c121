//! Where password hashes run: on a fixed set of threads, one per core, with a short queue
//! in front; beyond the queue a check is refused at once.
//!
//! Each argon2id hash takes 19 MiB for its run. Unbounded, 60 sign-ins at once took
//! 60 × 19 MiB, and the allocator kept it. Bounded to the cores, a burst costs what the
//! cores can hash at once, and takes no longer than the same work queued by the operating
//! system. The threads are the hasher's own, not tokio's blocking pool: glibc gives each
//! thread that allocates an arena of its own and keeps freed 19 MiB blocks in it, so hashes
//! spread over the pool's changing threads left up to one block per arena (measured: 60
//! sign-ins kept 330 MiB); on a fixed thread per core the same block is reused. Each
//! thread now keeps its argon2 memory itself (`verify_password_in`), allocated at its first
//! check and reused for every later one, so a burst never allocates more than one block per
//! thread and the allocator has nothing to keep.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};
use std::sync::{Arc, Mutex};

/// Password checks queued per core before more are refused.
const QUEUED_PER_CORE: usize = 8;

/// The hash queue was full: refused without hashing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("{queued} password checks are waiting already: try again in a moment")]
pub struct Busy {
    pub queued: usize,
}

type Job = Box<dyn FnOnce() + Send>;

thread_local! {
    /// A hashing thread's argon2 memory, kept between checks (19 MiB once used).
    static THREAD_BLOCKS: std::cell::RefCell<Vec<argon2::Block>> =
        const { std::cell::RefCell::new(Vec::new()) };
}

/// Runs argon2 hashes on `parallel` threads of its own, `queue` more waiting. The threads
/// end when the hasher is dropped.
#[derive(Debug)]
pub struct Hasher {
    jobs: SyncSender<Job>,
    queue: usize,
    /// Jobs handed over and not yet started.
    queued: Arc<AtomicUsize>,
    /// Jobs running now.
    running: Arc<AtomicUsize>,
    /// The most jobs that ran at once since start (`/metrics`).
    most_running: Arc<AtomicUsize>,
    /// Checks refused because the queue was full.
    refused: AtomicUsize,
    /// The threads made: the most that can run at once.
    parallel: usize,
}

impl Default for Hasher {
    /// One thread per core, [`QUEUED_PER_CORE`] waiting per core.
    fn default() -> Self {
        let cores = std::thread::available_parallelism().map_or(1, usize::from);
        Self::new(cores, cores * QUEUED_PER_CORE)
    }
}

fn worker(jobs: Arc<Mutex<Receiver<Job>>>) {
    loop {
        let job = jobs.lock().unwrap_or_else(|p| p.into_inner()).recv();
        match job {
            Ok(job) => job(),
            Err(_) => return, // the hasher is gone
        }
    }
}

impl Hasher {
    /// `parallel` (at least 1) threads, `queue` more checks waiting.
    pub fn new(parallel: usize, queue: usize) -> Self {
        let (jobs, rx) = sync_channel::<Job>(queue);
        let rx = Arc::new(Mutex::new(rx));
        let parallel = parallel.max(1);
        for i in 0..parallel {
            let rx = Arc::clone(&rx);
            // A thread that cannot be made leaves the others; with none, every check waits
            // in the queue and is refused once it is full, which the caller reports.
            let _ = std::thread::Builder::new()
                .name(format!("camloop-hash-{i}"))
                .spawn(move || worker(rx));
        }
        Self {
            jobs,
            queue,
            queued: Arc::new(AtomicUsize::new(0)),
            running: Arc::new(AtomicUsize::new(0)),
            most_running: Arc::new(AtomicUsize::new(0)),
            refused: AtomicUsize::new(0),
            parallel,
        }
    }

    /// Runs `work` on a hashing thread once one is free; refused when `queue` checks are
    /// waiting already. `None`: the work panicked.
    pub async fn run<T: Send + 'static>(
        &self,
        work: impl FnOnce() -> T + Send + 'static,
    ) -> Result<Option<T>, Busy> {
        let (done, result) = tokio::sync::oneshot::channel();
        let (queued, running) = (Arc::clone(&self.queued), Arc::clone(&self.running));
        let most = Arc::clone(&self.most_running);
        let job: Job = Box::new(move || {
            queued.fetch_sub(1, Ordering::SeqCst);
            let now = running.fetch_add(1, Ordering::SeqCst) + 1;
            most.fetch_max(now, Ordering::SeqCst);
            let out = std::panic::catch_unwind(std::panic::AssertUnwindSafe(work)).ok();
            running.fetch_sub(1, Ordering::SeqCst);
            // The caller may have gone (the client hung up): the hash ran all the same.
            let _ = done.send(out);
        });
        self.queued.fetch_add(1, Ordering::SeqCst);
        if let Err(e) = self.jobs.try_send(job) {
            self.queued.fetch_sub(1, Ordering::SeqCst);
            self.refused.fetch_add(1, Ordering::SeqCst);
            return match e {
                TrySendError::Full(_) | TrySendError::Disconnected(_) => {
                    Err(Busy { queued: self.queue })
                }
            };
        }
        Ok(result.await.ok().flatten())
    }

    /// Whether `password` matches the stored `hash` (see [`super::verify_password`]), in
    /// the hashing thread's own argon2 memory.
    pub async fn verify(&self, password: String, hash: String) -> Result<bool, Busy> {
        let matched = self
            .run(move || {
                THREAD_BLOCKS.with(|blocks| {
                    let mut blocks = blocks.borrow_mut();
                    super::verify_password_in(&password, &hash, &mut blocks)
                })
            })
            .await?;
        Ok(matched.unwrap_or(false))
    }

    /// Hashes running now.
    pub fn running(&self) -> usize {
        self.running.load(Ordering::SeqCst)
    }

    /// Checks waiting for a thread now.
    pub fn queued(&self) -> usize {
        self.queued.load(Ordering::SeqCst)
    }

    /// The hasher's series for `/metrics`: running now, the most at once since start, the
    /// bound (its threads), waiting now, and refused since start.
    pub fn render_metrics(&self) -> String {
        let families: [(&str, &str, &str, usize); 5] = [
            (
                "camloop_password_hashes_running",
                "gauge",
                "Password hashes (argon2id, 19 MiB each) running now.",
                self.running(),
            ),
            (
                "camloop_password_hashes_running_max",
                "gauge",
                "The most password hashes that ran at once since start.",
                self.most_running.load(Ordering::SeqCst),
            ),
            (
                "camloop_password_hashes_parallel",
                "gauge",
                "The most password hashes that may run at once (one per core).",
                self.parallel,
            ),
            (
                "camloop_password_hashes_queued",
                "gauge",
                "Password checks waiting for a hashing thread now.",
                self.queued(),
            ),
            (
                "camloop_password_hashes_refused_total",
                "counter",
                "Password checks refused (503) because the hash queue was full.",
                self.refused.load(Ordering::SeqCst),
            ),
        ];
        families
            .iter()
            .map(|(name, kind, help, v)| {
                format!("# HELP {name} {help}\n# TYPE {name} {kind}\n{name} {v}\n")
            })
            .collect()
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
        let gate = Arc::new(std::sync::atomic::AtomicBool::new(false));
        let mut tasks = Vec::new();
        // Two to run first, then three to wait: a job is in the queue until a thread takes
        // it, so all five at once could find the queue full.
        for (count, wait_for) in [(2, (2, 0)), (3, (2, 3))] {
            for _ in 0..count {
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
                        while !g.load(Ordering::SeqCst) {
                            std::thread::yield_now();
                        }
                        r.fetch_sub(1, Ordering::SeqCst);
                    })
                    .await
                }));
            }
            while (hasher.running(), hasher.queued()) != wait_for {
                tokio::task::yield_now().await;
            }
        }
        // Two run, three wait: the sixth is refused.
        assert_eq!(hasher.run(|| ()).await, Err(Busy { queued: 3 }));
        gate.store(true, Ordering::SeqCst);
        for t in tasks {
            assert_eq!(t.await.unwrap(), Ok(Some(())));
        }
        assert_eq!(
            most.load(Ordering::SeqCst),
            2,
            "never more than two at once"
        );
        assert_eq!(hasher.queued(), 0);
    }
}
