//! All-or-nothing output: every file of a command is staged under a temporary name in its
//! destination folder and renamed into place only once all of them are written.

use anyhow::Context;
use std::io::Write;
use std::path::{Path, PathBuf};

/// Files a command will write, staged in memory until [`Outputs::commit`].
#[derive(Debug, Default)]
pub(crate) struct Outputs {
    files: Vec<(PathBuf, String)>,
}

impl Outputs {
    pub fn add(&mut self, path: &Path, contents: String) {
        self.files.push((path.to_path_buf(), contents));
    }

    /// Writes every file to a temporary sibling (creating missing folders), syncs it, then
    /// renames them all into place. On any failure the temporaries are removed and no destination is touched.
    pub fn commit(self) -> anyhow::Result<Vec<PathBuf>> {
        let mut staged = Vec::with_capacity(self.files.len());
        for (path, contents) in &self.files {
            let dir = match path.parent() {
                Some(p) if !p.as_os_str().is_empty() => p,
                _ => Path::new("."),
            };
            std::fs::create_dir_all(dir)
                .with_context(|| format!("cannot create folder {}", dir.display()))?;
            let mut tmp = tempfile::Builder::new()
                .prefix(".camloop-")
                .tempfile_in(dir)
                .with_context(|| format!("cannot create a file in {}", dir.display()))?;
            tmp.write_all(contents.as_bytes())
                .and_then(|()| tmp.as_file().sync_all())
                .with_context(|| format!("cannot write {}", path.display()))?;
            staged.push((tmp, path.clone()));
        }
        let mut written = Vec::with_capacity(staged.len());
        for (tmp, path) in staged {
            tmp.persist(&path)
                .with_context(|| format!("cannot write {}", path.display()))?;
            written.push(path);
        }
        Ok(written)
    }
}
