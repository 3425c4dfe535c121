//! The on-disk queue of messages for the broker: a JSON-lines file appended as events come
//! and mirrored in memory, so events survive a broker outage and a restart. It holds at
//! most `max` messages: when full, the oldest is dropped and counted, and the count is
//! published once the broker is back. The file is emptied when everything is sent, and
//! rewritten with what is pending when one more line would make it longer than `max`
//! lines, so the file never holds more than `max` lines either. (While the broker is away
//! and the queue is full, that is one rewrite of the file per event.)
//!
//! Delivery is at least once (MQTT QoS 1): a message sent but not yet acknowledged when the
//! process stops is sent again after the restart.

use std::collections::VecDeque;
use std::fs::{File, OpenOptions};
use std::io::Write;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

/// Queue file name in the queue folder.
pub(crate) const QUEUE_FILE: &str = "queue.jsonl";
/// The count of drops not yet reported, kept across restarts (the dropped lines are gone
/// from the queue file, which never exceeds the bound).
pub(crate) const DROPPED_FILE: &str = "queue.dropped";

/// One event to publish: its payload on its topic, then each state it changed, retained.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub(crate) struct Message {
    pub topic: String,
    pub payload: String,
    /// Queues written before the per-feature states: the payload again, retained, here.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub state_topic: Option<String>,
    /// (topic, payload) of each state the event changed, published retained.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub states: Vec<(String, String)>,
}

/// The queue (see the module doc).
#[derive(Debug)]
pub(crate) struct DiskQueue {
    path: PathBuf,
    file: File,
    pending: VecDeque<Message>,
    max: usize,
    /// Lines in the file (pending ones and those already sent).
    lines: usize,
    /// Messages dropped because the queue was full, not yet reported to the broker.
    dropped_unreported: u64,
    dropped_total: u64,
}

impl DiskQueue {
    /// Opens the queue in `dir`, loading what a previous run left (the newest `max`; older
    /// ones count as dropped, unreadable lines are skipped and counted the same way).
    pub fn open(dir: &Path, max: usize) -> std::io::Result<Self> {
        std::fs::create_dir_all(dir)?;
        let path = dir.join(QUEUE_FILE);
        let text = match std::fs::read_to_string(&path) {
            Ok(t) => t,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => String::new(),
            Err(e) => return Err(e),
        };
        let mut pending = VecDeque::new();
        let mut dropped = 0_u64;
        // A torn last line (a kill mid-append) does not parse and is dropped like a bad one.
        for line in text.lines() {
            match serde_json::from_str::<Message>(line) {
                Ok(m) => pending.push_back(m),
                Err(_) => dropped += 1,
            }
        }
        let max = max.max(1);
        dropped += std::fs::read_to_string(dir.join(DROPPED_FILE))
            .ok()
            .and_then(|t| t.trim().parse::<u64>().ok())
            .unwrap_or(0);
        while pending.len() > max {
            pending.pop_front();
            dropped += 1;
        }
        let file = OpenOptions::new().create(true).append(true).open(&path)?;
        let mut queue = Self {
            path,
            file,
            lines: pending.len(),
            pending,
            max,
            dropped_unreported: dropped,
            dropped_total: dropped,
        };
        queue.rewrite()?;
        Ok(queue)
    }

    /// Appends a message; when the queue is full, the oldest pending one is dropped (and
    /// `Ok(true)` says so).
    pub fn push(&mut self, message: Message) -> std::io::Result<bool> {
        let full = self.pending.len() >= self.max;
        if full {
            self.pending.pop_front();
            self.count_dropped(1);
        }
        let mut line = serde_json::to_string(&message).map_err(std::io::Error::other)?;
        line.push('\n');
        self.pending.push_back(message);
        if self.lines >= self.max {
            // The file holds sent or dropped lines: write the pending ones alone.
            self.rewrite()?;
        } else {
            self.file.write_all(line.as_bytes())?;
            self.lines += 1;
        }
        Ok(full)
    }

    /// The oldest pending message.
    pub fn front(&self) -> Option<&Message> {
        self.pending.front()
    }

    /// The oldest pending message was acknowledged by the broker.
    pub(crate) fn pop_front(&mut self) -> std::io::Result<()> {
        self.pending.pop_front();
        if self.pending.is_empty() {
            self.file.set_len(0)?;
            self.lines = 0;
        }
        Ok(())
    }

    pub fn len(&self) -> usize {
        self.pending.len()
    }

    #[cfg(test)]
    pub fn is_empty(&self) -> bool {
        self.pending.is_empty()
    }

    /// Counts messages lost before they reached the queue (its intake was full).
    pub(crate) fn count_dropped(&mut self, n: u64) {
        if n == 0 {
            return;
        }
        self.dropped_unreported += n;
        self.save_dropped();
        self.dropped_total += n;
    }

    /// `n` drops were reported to the broker.
    pub(crate) fn dropped_reported(&mut self, n: u64) {
        self.dropped_unreported = self.dropped_unreported.saturating_sub(n);
        self.save_dropped();
    }

    /// Drops not yet reported (still to be told to the broker).
    pub(crate) fn dropped_unreported(&self) -> u64 {
        self.dropped_unreported
    }

    /// Every drop since the queue was opened (with those found at open).
    pub(crate) fn dropped_total(&self) -> u64 {
        self.dropped_total
    }

    /// Keeps the unreported count for a restart; a failure only risks under-reporting.
    fn save_dropped(&self) {
        let path = self.path.with_file_name(DROPPED_FILE);
        let _ = match self.dropped_unreported {
            0 => std::fs::remove_file(&path).or(Ok(())),
            n => std::fs::write(&path, n.to_string()),
        };
    }

    /// Rewrites the file with the pending messages only (temporary, then rename).
    fn rewrite(&mut self) -> std::io::Result<()> {
        let tmp = self.path.with_extension("jsonl.tmp");
        let mut text = String::new();
        for m in &self.pending {
            text.push_str(&serde_json::to_string(m).map_err(std::io::Error::other)?);
            text.push('\n');
        }
        std::fs::write(&tmp, text)?;
        std::fs::rename(&tmp, &self.path)?;
        self.file = OpenOptions::new().append(true).open(&self.path)?;
        self.lines = self.pending.len();
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn msg(n: usize) -> Message {
        Message {
            topic: format!("t/{n}"),
            payload: n.to_string(),
            state_topic: None,
            states: Vec::new(),
        }
    }

    #[test]
    fn the_oldest_are_dropped_at_the_bound_and_a_reopen_resumes_the_rest() {
        let dir = tempfile::tempdir().unwrap();
        let mut q = DiskQueue::open(dir.path(), 3).unwrap();
        for n in 0..5 {
            q.push(msg(n)).unwrap();
        }
        assert_eq!(q.len(), 3);
        assert_eq!(q.front(), Some(&msg(2)));
        assert_eq!(q.dropped_unreported(), 2);
        q.pop_front().unwrap();
        drop(q);
        // The file holds the newest 3 lines (message 2 was sent but the file had it: at
        // least once), and the count of the 2 dropped, not yet reported, comes back too.
        let mut q = DiskQueue::open(dir.path(), 3).unwrap();
        assert_eq!(q.len(), 3);
        assert_eq!(q.front(), Some(&msg(2)));
        assert_eq!(q.dropped_unreported(), 2);
        q.dropped_reported(2);
        assert_eq!(q.dropped_unreported(), 0);
        for _ in 0..3 {
            q.pop_front().unwrap();
        }
        assert!(q.is_empty());
        assert_eq!(
            std::fs::metadata(dir.path().join(QUEUE_FILE))
                .unwrap()
                .len(),
            0
        );
    }

    #[test]
    fn the_file_stays_bounded_and_a_torn_line_is_skipped() {
        let dir = tempfile::tempdir().unwrap();
        let mut q = DiskQueue::open(dir.path(), 4).unwrap();
        let lines = || {
            std::fs::read_to_string(dir.path().join(QUEUE_FILE))
                .unwrap()
                .lines()
                .count()
        };
        for n in 0..100 {
            // Full from the fifth on, but for the one after a message was sent.
            assert_eq!(q.push(msg(n)).unwrap(), n >= 4 && n != 51, "message {n}");
            // Never more lines than the bound, whether sent lines or dropped ones fill it.
            assert_eq!(lines(), (n + 1).min(4), "after message {n}");
            if n == 50 {
                q.pop_front().unwrap();
            }
        }
        drop(q);
        let mut f = OpenOptions::new()
            .append(true)
            .open(dir.path().join(QUEUE_FILE))
            .unwrap();
        f.write_all(b"{\"topic\":\"t/").unwrap();
        let q = DiskQueue::open(dir.path(), 4).unwrap();
        assert_eq!(q.front(), Some(&msg(96)));
        assert_eq!(q.len(), 4);
    }
}
