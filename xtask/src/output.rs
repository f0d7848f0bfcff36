//! Fresh output folders that never hold a half-written result under their
//! final name: everything is written into `<out>.partial` and renamed at the end.

use std::fs;
use std::path::{Path, PathBuf};
use std::time::{SystemTime, UNIX_EPOCH};

/// An output folder being written.
pub struct OutputFolder {
    partial: PathBuf,
    target: PathBuf,
}

impl OutputFolder {
    /// Claims `requested` (which must not exist yet), or a new folder under
    /// `out/` named after `stem` and the current time.
    pub fn create(requested: Option<&Path>, stem: &str) -> Result<Self, String> {
        let target = match requested {
            Some(path) => path.to_path_buf(),
            None => {
                let seconds = SystemTime::now()
                    .duration_since(UNIX_EPOCH)
                    .map(|elapsed| elapsed.as_secs())
                    .unwrap_or_default();
                PathBuf::from("out").join(format!("{stem}-{seconds}"))
            }
        };
        if target.exists() {
            return Err(format!(
                "output folder {} exists already; choose a new one with --out",
                target.display()
            ));
        }
        let mut partial_name = target.as_os_str().to_owned();
        partial_name.push(".partial");
        let partial = PathBuf::from(partial_name);
        if partial.exists() {
            fs::remove_dir_all(&partial)
                .map_err(|e| format!("cannot clear {}: {e}", partial.display()))?;
        }
        fs::create_dir_all(&partial)
            .map_err(|e| format!("cannot create {}: {e}", partial.display()))?;
        Ok(Self { partial, target })
    }

    /// Path of a file inside the folder being written.
    pub fn file(&self, name: &str) -> PathBuf {
        self.partial.join(name)
    }

    /// Writes a text file into the folder.
    pub fn write(&self, name: &str, contents: &str) -> Result<(), String> {
        let path = self.file(name);
        fs::write(&path, contents).map_err(|e| format!("cannot write {}: {e}", path.display()))
    }

    /// Moves the finished folder to its final name and returns that name.
    pub fn finish(self) -> Result<PathBuf, String> {
        fs::rename(&self.partial, &self.target).map_err(|e| {
            format!(
                "cannot rename {} to {}: {e}",
                self.partial.display(),
                self.target.display()
            )
        })?;
        Ok(self.target)
    }
}
