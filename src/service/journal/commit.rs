//! Group commit for every journal of the process: one writer thread takes whatever appends
//! are queued, writes each journal's lines with one write, and makes the whole batch durable
//! with one sync (`syncfs` of the file system when the batch spans several journals on
//! Linux, `fdatasync` of the one journal otherwise); only then is each caller answered.
//!
//! So a caller still proceeds only once its record is on disk (the write-ahead rule), the
//! file format is unchanged (each journal gets its own lines, in the order its caller
//! appended them), and a plant of machines pays one sync per batch rather than one per
//! record. A batch that fails is cut back out of every file it touched, as a single append
//! was before, so a partial line never glues itself to the next record.

use std::collections::HashMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, OnceLock, mpsc};

/// One append waiting for its batch.
struct Request {
    path: PathBuf,
    bytes: Vec<u8>,
    done: mpsc::SyncSender<std::io::Result<()>>,
}

/// What the writer has done (for tests and the metrics).
#[derive(Debug, Default)]
pub(crate) struct CommitStats {
    /// Appends made durable.
    pub appends: AtomicU64,
    /// Syncs issued (one per batch; one per journal where the file system cannot be synced
    /// at once).
    pub syncs: AtomicU64,
    /// Batches written.
    pub batches: AtomicU64,
}

/// A writer thread and the way to it.
pub(crate) struct GroupCommit {
    tx: mpsc::Sender<Request>,
    stats: Arc<CommitStats>,
}

/// An append handed to the writer; [`Ticket::wait`] returns once it is durable.
pub(crate) struct Ticket(mpsc::Receiver<std::io::Result<()>>);

impl Ticket {
    /// Waits until the append is durable (or failed). Off the async workers: on a
    /// multi-threaded runtime the wait hands this worker's other tasks to another thread.
    pub(crate) fn wait(self) -> std::io::Result<()> {
        let recv = || {
            self.0
                .recv()
                .unwrap_or_else(|_| Err(std::io::Error::other("the journal writer stopped")))
        };
        crate::service::offload::blocking(recv)
    }
}

impl GroupCommit {
    /// The process's writer, started on first use.
    pub(crate) fn global() -> &'static GroupCommit {
        static WRITER: OnceLock<GroupCommit> = OnceLock::new();
        WRITER.get_or_init(|| GroupCommit::start(None))
    }

    /// Starts a writer thread. With `held`, the thread waits for that channel to close or
    /// send before its first batch (a test queues a whole batch first).
    pub(crate) fn start(held: Option<mpsc::Receiver<()>>) -> GroupCommit {
        let (tx, rx) = mpsc::channel::<Request>();
        let stats = Arc::new(CommitStats::default());
        let thread_stats = stats.clone();
        let spawned = std::thread::Builder::new()
            .name("camloop-journal".into())
            .spawn(move || {
                if let Some(held) = held {
                    let _ = held.recv();
                }
                run(&rx, &thread_stats);
            });
        if let Err(e) = spawned {
            // Without the thread every append fails (its answer channel closes), so the
            // machines hold learning and say why rather than lose records silently.
            tracing::error!(error = %e, "the journal writer thread cannot start");
        }
        GroupCommit { tx, stats }
    }

    /// Queues `bytes` to be appended to `path`.
    pub(crate) fn submit(&self, path: &Path, bytes: Vec<u8>) -> Ticket {
        let (done, rx) = mpsc::sync_channel(1);
        let request = Request {
            path: path.to_path_buf(),
            bytes,
            done,
        };
        if let Err(mpsc::SendError(r)) = self.tx.send(request) {
            let _ = r
                .done
                .send(Err(std::io::Error::other("the journal writer stopped")));
        }
        Ticket(rx)
    }

    pub(crate) fn stats(&self) -> &CommitStats {
        &self.stats
    }
}

/// The writer's loop: a batch is everything queued when the previous one is done.
fn run(rx: &mpsc::Receiver<Request>, stats: &CommitStats) {
    while let Ok(first) = rx.recv() {
        let mut batch = vec![first];
        batch.extend(rx.try_iter());
        commit(batch, stats);
    }
}

/// One journal's part of a batch: the file, where it ended, the requests in order.
struct FileBatch {
    file: Option<std::fs::File>,
    before: u64,
    requests: Vec<Request>,
    result: std::io::Result<()>,
}

fn commit(batch: Vec<Request>, stats: &CommitStats) {
    let mut order: Vec<PathBuf> = Vec::new();
    let mut files: HashMap<PathBuf, FileBatch> = HashMap::new();
    for r in batch {
        let entry = files.entry(r.path.clone()).or_insert_with(|| {
            order.push(r.path.clone());
            FileBatch {
                file: None,
                before: 0,
                requests: Vec::new(),
                result: Ok(()),
            }
        });
        entry.requests.push(r);
    }
    for path in &order {
        let fb = files
            .get_mut(path)
            .expect("every path in order has its batch");
        fb.result = write_lines(path, fb);
    }
    let written: Vec<&PathBuf> = order.iter().filter(|p| files[*p].result.is_ok()).collect();
    let synced = sync(&written, &files, stats);
    // Counted before any caller hears its answer, so a reader woken by the answer sees
    // this batch in the totals.
    stats.batches.fetch_add(1, Ordering::Relaxed);
    for path in &order {
        let fb = files
            .remove(path)
            .expect("every path in order has its batch");
        let result = match (&fb.result, &synced) {
            (Err(e), _) => Err(std::io::Error::new(e.kind(), e.to_string())),
            (Ok(()), Err(e)) => {
                // Not known to be on disk: cut back, as a failed append always was.
                if let Some(f) = &fb.file {
                    let _ = f.set_len(fb.before);
                }
                Err(std::io::Error::new(e.kind(), e.to_string()))
            }
            (Ok(()), Ok(())) => Ok(()),
        };
        let ok = result.is_ok();
        for r in fb.requests {
            let answer = match &result {
                Ok(()) => Ok(()),
                Err(e) => Err(std::io::Error::new(e.kind(), e.to_string())),
            };
            if ok {
                stats.appends.fetch_add(1, Ordering::Relaxed);
            }
            let _ = r.done.send(answer);
        }
    }
}

/// Appends one journal's requests with one write; on failure the file is cut back to where
/// it was.
fn write_lines(path: &Path, fb: &mut FileBatch) -> std::io::Result<()> {
    let mut file = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(path)?;
    fb.before = file.metadata()?.len();
    let bytes: Vec<u8> = fb.requests.iter().flat_map(|r| r.bytes.clone()).collect();
    let result = file.write_all(&bytes);
    if result.is_err() {
        let _ = file.set_len(fb.before);
    }
    fb.file = Some(file);
    result
}

/// Makes every written journal durable: one `syncfs` for several on Linux, else each file.
fn sync(
    written: &[&PathBuf],
    files: &HashMap<PathBuf, FileBatch>,
    stats: &CommitStats,
) -> std::io::Result<()> {
    let open = |p: &PathBuf| files[p].file.as_ref().expect("a written journal is open");
    #[cfg(target_os = "linux")]
    if written.len() > 1 && same_file_system(written) {
        stats.syncs.fetch_add(1, Ordering::Relaxed);
        return nix::unistd::syncfs(open(written[0])).map_err(std::io::Error::from);
    }
    for p in written {
        stats.syncs.fetch_add(1, Ordering::Relaxed);
        open(p).sync_data()?;
    }
    Ok(())
}

/// Whether every journal is on one file system (one `syncfs` covers them all).
#[cfg(target_os = "linux")]
fn same_file_system(paths: &[&PathBuf]) -> bool {
    use std::os::unix::fs::MetadataExt;
    let mut devices = paths.iter().map(|p| std::fs::metadata(p).map(|m| m.dev()));
    match devices.next() {
        Some(Ok(first)) => devices.all(|d| d.is_ok_and(|d| d == first)),
        _ => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Records of several machines' features queued together go to disk in one batch: fewer
    /// syncs than records, every record in its own journal, in the order it was appended.
    #[test]
    fn a_batch_across_journals_takes_fewer_syncs_than_records() {
        let dir = tempfile::tempdir().unwrap();
        let (release, held) = mpsc::channel();
        let writer = GroupCommit::start(Some(held));
        let journals: Vec<PathBuf> = ["M1/IN1", "M1/EX1", "M2/IN1", "M3/IN1"]
            .iter()
            .map(|f| {
                let d = dir.path().join(f);
                std::fs::create_dir_all(&d).unwrap();
                d.join("journal.jsonl")
            })
            .collect();
        let mut tickets = Vec::new();
        for n in 0..5 {
            for j in &journals {
                tickets.push(writer.submit(j, format!("{{\"n\":{n}}}\n").into_bytes()));
            }
        }
        let records = tickets.len() as u64;
        release.send(()).unwrap();
        for t in tickets {
            t.wait().unwrap();
        }
        let stats = writer.stats();
        assert_eq!(stats.appends.load(Ordering::Relaxed), records);
        assert_eq!(stats.batches.load(Ordering::Relaxed), 1);
        let syncs = stats.syncs.load(Ordering::Relaxed);
        // One syncfs on Linux; one fdatasync per journal elsewhere: fewer than the records
        // either way.
        assert!(syncs <= journals.len() as u64, "{syncs} syncs");
        assert!(syncs < records, "{syncs} syncs for {records} records");
        for j in &journals {
            let text = std::fs::read_to_string(j).unwrap();
            let expected: String = (0..5).map(|n| format!("{{\"n\":{n}}}\n")).collect();
            assert_eq!(text, expected, "{}", j.display());
        }
    }

    /// An append to a journal that cannot be written fails for its callers only; the other
    /// journals of the batch are durable.
    #[test]
    fn a_failed_journal_fails_alone_in_its_batch() {
        let dir = tempfile::tempdir().unwrap();
        let (release, held) = mpsc::channel();
        let writer = GroupCommit::start(Some(held));
        let good = dir.path().join("journal.jsonl");
        // A directory where the file should be: opening it for append fails.
        let bad = dir.path().join("bad");
        std::fs::create_dir_all(&bad).unwrap();
        let a = writer.submit(&good, b"{\"a\":1}\n".to_vec());
        let b = writer.submit(&bad, b"{\"b\":1}\n".to_vec());
        drop(release);
        assert!(a.wait().is_ok());
        assert!(b.wait().is_err());
        assert_eq!(std::fs::read_to_string(&good).unwrap(), "{\"a\":1}\n");
    }
}
