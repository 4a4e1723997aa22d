//! One writer per dataset: the lock every writing command takes, and the clean-up of what dead
//! writers left behind.
//!
//! The lock is an OS file lock on `<dataset>/.gedisim.lock` (released by the OS when the process
//! ends, even by `kill -9`). A second writer fails at once with one line naming the holder's pid.
//! Readers (`sql`, `export`, the simulator reading `als/`) take no lock: every table file appears
//! by an atomic rename, and ALS points appear with their `tiles/` row (see
//! [`super::Dataset::visible_files`]).
//!
//! Holding the lock, the writer removes what only a dead writer can have left: temporary files
//! (`*.tmp`) in the table folders, and `als/` files whose `tiles/` row was never written.

use std::fs::{File, OpenOptions};
use std::io::{Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use super::{tables, Dataset};
use crate::error::{Error, Result};

/// Name of the lock file in the dataset directory.
pub const LOCK_FILE: &str = ".gedisim.lock";

/// The dataset's writer lock, held until dropped.
#[derive(Debug)]
pub struct WriteLock {
    _file: File,
}

/// What a writer removed when it took the lock.
#[derive(Debug, Default, Clone, PartialEq, Eq)]
pub struct Cleanup {
    /// Temporary files of dead writers.
    pub temporaries: Vec<PathBuf>,
    /// `als/` files without their `tiles/` row.
    pub orphan_points: Vec<PathBuf>,
}

impl WriteLock {
    /// Take the writer lock of `ds`, or fail with one line if another process holds it; then
    /// remove what dead writers left (see the module documentation).
    pub fn acquire(ds: &Dataset) -> Result<(WriteLock, Cleanup)> {
        let path = ds.root().join(LOCK_FILE);
        let mut file = OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(&path)
            .map_err(|e| Error::file(&path, format!("cannot open the dataset's lock: {e}")))?;
        match file.try_lock() {
            Ok(()) => {}
            Err(std::fs::TryLockError::WouldBlock) => {
                let mut holder = String::new();
                let _ = file.read_to_string(&mut holder);
                let holder = holder.trim();
                let who = if holder.is_empty() { String::new() } else { format!(" (pid {holder})") };
                return Err(Error::file(
                    ds.root(),
                    format!("another gedisim process{who} is writing this dataset; run again when it has finished"),
                ));
            }
            Err(std::fs::TryLockError::Error(e)) => {
                return Err(Error::file(&path, format!("cannot lock the dataset: {e}")));
            }
        }
        // Record the holder for the message above (best effort: the lock is what counts).
        let _ = file.set_len(0).and_then(|_| file.seek(SeekFrom::Start(0))).and_then(|_| {
            write!(file, "{}", std::process::id())?;
            file.flush()
        });
        let cleanup = clean(ds)?;
        Ok((WriteLock { _file: file }, cleanup))
    }
}

/// Remove the temporaries and orphan `als/` files of dead writers (called holding the lock).
fn clean(ds: &Dataset) -> Result<Cleanup> {
    let mut cleanup = Cleanup::default();
    let entries = std::fs::read_dir(ds.root()).map_err(|e| Error::file(ds.root(), e))?;
    for entry in entries.flatten() {
        let dir = entry.path();
        if !dir.is_dir() {
            continue;
        }
        for file in std::fs::read_dir(&dir).map_err(|e| Error::file(&dir, e))?.flatten() {
            let path = file.path();
            if path.extension().and_then(|e| e.to_str()) == Some("tmp") && is_stale(&path) {
                remove(&path)?;
                cleanup.temporaries.push(path);
            }
        }
    }
    let als = ds.root().join(tables::ALS);
    if als.is_dir() {
        let visible = ds.visible_files(tables::ALS).map_err(|e| Error::file(&als, e))?;
        for path in super::table_files(&als).map_err(|e| Error::file(&als, e))? {
            if !visible.contains(&path) {
                remove(&path)?;
                cleanup.orphan_points.push(path);
            }
        }
    }
    Ok(cleanup)
}

/// A temporary file is stale unless this process made it (`<name>.<pid>[-<n>].tmp`): holding the
/// lock, no other live process writes the dataset.
fn is_stale(path: &Path) -> bool {
    let stem = path.file_stem().and_then(|s| s.to_str()).unwrap_or("");
    let tag = stem.rsplit('.').next().unwrap_or("");
    let pid = tag.split('-').next().and_then(|p| p.parse::<u32>().ok());
    pid != Some(std::process::id())
}

fn remove(path: &Path) -> Result<()> {
    std::fs::remove_file(path).map_err(|e| Error::file(path, format!("cannot remove a dead writer's file: {e}")))
}
