//! The PKI folder's `rejected/` kept bounded: the stack writes every refused client
//! certificate there, so a scanner or a misconfigured client would otherwise fill the disk
//! one file per attempt. The newest [`MAX_REJECTED`] stay (an operator trusts a client by
//! moving its file to `trusted/`); older ones are removed.

use std::path::Path;
use std::time::{Duration, SystemTime};

/// Files kept in `rejected/`.
pub(crate) const MAX_REJECTED: usize = 100;

/// How often `rejected/` is trimmed while the server runs.
pub(crate) const TRIM_EVERY: Duration = Duration::from_secs(10);

/// Removes the oldest files of `dir` beyond the newest `keep` (by modification time, then
/// name); returns how many were removed. A missing folder is empty.
pub(crate) fn trim(dir: &Path, keep: usize) -> std::io::Result<usize> {
    let entries = match std::fs::read_dir(dir) {
        Ok(entries) => entries,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(0),
        Err(e) => return Err(e),
    };
    let mut files: Vec<(SystemTime, std::path::PathBuf)> = Vec::new();
    for entry in entries {
        let entry = entry?;
        let meta = entry.metadata()?;
        if meta.is_file() {
            let at = meta.modified().unwrap_or(SystemTime::UNIX_EPOCH);
            files.push((at, entry.path()));
        }
    }
    if files.len() <= keep {
        return Ok(0);
    }
    files.sort();
    let excess = files.len() - keep;
    let mut removed = 0;
    for (_, path) in files.into_iter().take(excess) {
        match std::fs::remove_file(&path) {
            Ok(()) => removed += 1,
            // Moved to trusted/ by an operator meanwhile: nothing to remove.
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => return Err(e),
        }
    }
    Ok(removed)
}

/// Trims `<pki>/rejected` every [`TRIM_EVERY`] until `shutdown`.
pub(crate) async fn keep_rejected_bounded(
    pki: std::path::PathBuf,
    mut shutdown: tokio::sync::watch::Receiver<bool>,
) {
    let dir = pki.join("rejected");
    let mut tick = tokio::time::interval(TRIM_EVERY);
    loop {
        tokio::select! {
            _ = tick.tick() => {}
            _ = shutdown.changed() => return,
        }
        let folder = dir.clone();
        match tokio::task::spawn_blocking(move || trim(&folder, MAX_REJECTED)).await {
            Ok(Ok(0)) => {}
            Ok(Ok(n)) => {
                tracing::warn!(removed = n, kept = MAX_REJECTED, folder = %dir.display(), "OPC UA: refused client certificates beyond the newest kept were removed");
            }
            Ok(Err(e)) => {
                tracing::warn!(error = %e, folder = %dir.display(), "OPC UA: the rejected certificates cannot be trimmed");
            }
            Err(_) => return,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_the_newest_rejected_certificates_are_kept() {
        let dir = tempfile::tempdir().unwrap();
        let base = SystemTime::UNIX_EPOCH + Duration::from_secs(1_795_773_600);
        for i in 0..7u64 {
            let path = dir.path().join(format!("CN=client {i} [{i:040}].der"));
            std::fs::write(&path, [i as u8]).unwrap();
            let file = std::fs::File::options().write(true).open(&path).unwrap();
            file.set_modified(base + Duration::from_secs(i)).unwrap();
        }
        std::fs::create_dir(dir.path().join("a folder")).unwrap();
        assert_eq!(trim(dir.path(), 3).unwrap(), 4);
        let mut left: Vec<String> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.ends_with(".der"))
            .collect();
        left.sort();
        let newest: Vec<String> = (4..7u64)
            .map(|i| format!("CN=client {i} [{i:040}].der"))
            .collect();
        assert_eq!(left, newest);
        assert!(
            dir.path().join("a folder").is_dir(),
            "folders are not touched"
        );
        assert_eq!(trim(dir.path(), 3).unwrap(), 0);
        assert_eq!(trim(&dir.path().join("missing"), 3).unwrap(), 0);
    }
}
