//! Work that blocks (file writes and fsyncs, the CPU-bound turn, the simulator's grinding)
//! kept off the async workers: on a multi-threaded runtime the calling worker hands its
//! other tasks to another thread for the duration (`block_in_place`), so timers, sources and
//! the database's answers go on while a machine syncs or computes. On a single-threaded
//! runtime (tests) the work simply runs.

use std::future::Future;
use tokio::runtime::{Handle, RuntimeFlavor};

fn multi_threaded() -> Option<Handle> {
    Handle::try_current()
        .ok()
        .filter(|h| h.runtime_flavor() == RuntimeFlavor::MultiThread)
}

/// Runs `f`, which may block, off the async workers.
pub(crate) fn blocking<T>(f: impl FnOnce() -> T) -> T {
    match multi_threaded() {
        Some(_) => tokio::task::block_in_place(f),
        None => f(),
    }
}

/// Drives `work` (a machine's event, command or retry: it awaits the database but also
/// writes files and computes) to its end off the async workers.
pub(crate) async fn drive<F: Future>(work: F) -> F::Output {
    match multi_threaded() {
        Some(handle) => tokio::task::block_in_place(|| handle.block_on(work)),
        None => work.await,
    }
}

/// Waits for `work` from blocking code that [`blocking`] runs (the simulated control waiting
/// on the service's answer). None on a single-threaded runtime, where the wait could never
/// end: the work it waits for would need the very thread that waits.
pub(crate) fn wait<F: Future>(work: F) -> Option<F::Output> {
    multi_threaded().map(|handle| handle.block_on(work))
}
