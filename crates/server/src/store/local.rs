//! The data directory: the default [`Storage`], on this machine.
//!
//! ```text
//! <data-dir>/textures/<id>/...   as laid out in the parent module
//!           /solidtex.lock       held locked while a server uses it
//! ```
//!
//! Every file is written to a temporary name, fsynced, renamed over its
//! final name and the directory fsynced, so a crash leaves either the old
//! or the new file, never a torn one. `meta.json` is written last on
//! creation (a directory without it is debris) and flips to `ready` only
//! after `candidates.stx` is durable, so a texture whose precompute was
//! interrupted is found `pending` at start and computed again.
//!
//! `<data-dir>/solidtex.lock` is held locked while a server uses the
//! directory, so that two servers never write it at once. Only files the
//! server writes are ever removed: anything else found there is reported
//! and left alone.

use super::{
    Found, Storage, StoredMeta, WRITTEN, oldest_first, parse_meta, plane_files, planes_from,
    save_candidates,
};
use crate::spec::{Planes, valid_id};
use parking_lot::{Mutex, MutexGuard};
use solidtex_core::Candidates;
use std::fs::{self, File};
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};

const TMP_SUFFIX: &str = ".tmp";
/// Suffix of a texture directory being deleted.
const DELETING_SUFFIX: &str = ".deleting.tmp";
/// The file locked while a server uses the data directory.
pub const LOCK_FILE: &str = "solidtex.lock";
/// The data directory.
pub struct DataDir {
    root: PathBuf,
    lock: Mutex<()>,
    /// Holds the exclusive lock on [`LOCK_FILE`] while the store lives.
    _owner: File,
}

impl DataDir {
    /// Opens (creating) `root`, locks it against other servers, and clears
    /// debris of interrupted writes: temporary files, texture directories
    /// without metadata and deletions cut short. Only files the server
    /// writes are removed; anything else is reported and left alone.
    pub fn open(root: &Path) -> io::Result<DataDir> {
        fs::create_dir_all(root)?;
        let owner = lock_exclusive(root)?;
        let textures = root.join("textures");
        fs::create_dir_all(&textures)?;
        let store = DataDir {
            root: root.to_path_buf(),
            lock: Mutex::new(()),
            _owner: owner,
        };
        for entry in fs::read_dir(&textures)? {
            let entry = entry?;
            let path = entry.path();
            let name = entry.file_name().to_string_lossy().to_string();
            let is_dir = entry.file_type()?.is_dir();
            let deleting = name.strip_suffix(DELETING_SUFFIX).is_some_and(valid_id);
            if !is_dir || !(valid_id(&name) || deleting) {
                tracing::warn!(path = %path.display(), "ignoring an entry the server did not write");
                continue;
            }
            for f in fs::read_dir(&path)? {
                let f = f?;
                let n = f.file_name().to_string_lossy().to_string();
                if f.file_type()?.is_file() && is_temporary(&n) {
                    fs::remove_file(f.path())?;
                }
            }
            if deleting || !path.join("meta.json").exists() {
                tracing::warn!(path = %path.display(), "removing debris of an interrupted write or deletion");
                remove_written(&path)?;
            }
        }
        Ok(store)
    }

    /// The directory of texture `id`.
    pub fn dir(&self, id: &str) -> PathBuf {
        self.root.join("textures").join(id)
    }

    /// The texture in directory `dir`, when its metadata is readable.
    fn read_found(&self, dir: &Path) -> Option<Found> {
        let id = dir.file_name()?.to_string_lossy().to_string();
        let meta_path = dir.join("meta.json");
        let meta = fs::read(&meta_path)
            .map_err(|e| e.to_string())
            .and_then(|b| parse_meta(&id, &b));
        match meta {
            Ok(meta) => Some(Found {
                meta,
                location: dir.display().to_string(),
            }),
            Err(e) => {
                tracing::warn!(path = %meta_path.display(), error = %e, "skipping unreadable texture metadata");
                None
            }
        }
    }
}

impl Storage for DataDir {
    fn location(&self) -> String {
        self.root.display().to_string()
    }

    fn shared(&self) -> bool {
        false
    }

    fn lock(&self) -> MutexGuard<'_, ()> {
        self.lock.lock()
    }

    fn bytes(&self) -> io::Result<u64> {
        let mut total = 0u64;
        for entry in fs::read_dir(self.root.join("textures"))? {
            let entry = entry?;
            if !entry.file_type()?.is_dir() {
                continue;
            }
            for f in fs::read_dir(entry.path())? {
                let m = f?.metadata()?;
                if m.is_file() {
                    total = total.saturating_add(m.len());
                }
            }
        }
        Ok(total)
    }

    /// Replaces any leftover directory of the same id first.
    fn create(&self, meta: &StoredMeta, planes: &Planes) -> io::Result<()> {
        let dir = self.dir(&meta.id);
        if dir.exists() && !remove_written(&dir)? {
            return Err(io::Error::other(format!(
                "{} holds files the server did not write",
                dir.display()
            )));
        }
        fs::create_dir_all(&dir)?;
        for (name, png) in plane_files(planes)? {
            write_atomic(&dir.join(name), &png)?;
        }
        self.write_meta(meta)?;
        sync_dir(&self.root.join("textures"))
    }

    fn write_meta(&self, meta: &StoredMeta) -> io::Result<()> {
        let json = serde_json::to_vec_pretty(meta).map_err(io::Error::other)?;
        write_atomic(&self.dir(&meta.id).join("meta.json"), &json)
    }

    fn write_candidates(&self, id: &str, c: &Candidates) -> io::Result<()> {
        write_atomic_with(&self.dir(id).join("candidates.stx"), |w| {
            save_candidates(c, w)
        })
    }

    fn read_candidates(&self, id: &str) -> io::Result<Vec<u8>> {
        fs::read(self.dir(id).join("candidates.stx"))
    }

    fn read_planes(&self, meta: &StoredMeta) -> solidtex_core::Result<Planes> {
        let dir = self.dir(&meta.id);
        planes_from(meta, |name| match fs::read(dir.join(name)) {
            Ok(b) => Ok(Some(b)),
            Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(None),
            Err(e) => Err(e),
        })
    }

    fn remove(&self, id: &str) -> io::Result<()> {
        let dir = self.dir(id);
        if !dir.exists() {
            return Ok(());
        }
        // Rename first so that a crash mid-way leaves no half directory
        // under a valid id (the trash is cleared at the next start).
        let trash = self
            .root
            .join("textures")
            .join(format!("{id}{DELETING_SUFFIX}"));
        fs::rename(&dir, &trash)?;
        sync_dir(&self.root.join("textures"))?;
        match remove_written(&trash) {
            Ok(true) => {}
            Ok(false) => {
                tracing::warn!(path = %trash.display(), "left files the server did not write")
            }
            Err(e) => {
                tracing::warn!(path = %trash.display(), error = %e, "could not clear a deleted texture; retried at the next start")
            }
        }
        Ok(())
    }

    fn scan(&self) -> io::Result<Vec<Found>> {
        let mut out = Vec::new();
        for entry in fs::read_dir(self.root.join("textures"))? {
            let entry = entry?;
            if !entry.file_type()?.is_dir() || !valid_id(&entry.file_name().to_string_lossy()) {
                continue;
            }
            out.extend(self.read_found(&entry.path()));
        }
        oldest_first(&mut out);
        Ok(out)
    }

    fn find(&self, id: &str) -> io::Result<Option<Found>> {
        let dir = self.dir(id);
        if !valid_id(id) || !dir.join("meta.json").exists() {
            return Ok(None);
        }
        Ok(self.read_found(&dir))
    }

    fn ids(&self) -> io::Result<Vec<String>> {
        Ok(self.scan()?.into_iter().map(|f| f.meta.id).collect())
    }

    fn write_region(&self, id: &str, json: &[u8]) -> io::Result<()> {
        let dir = self.root.join("regions");
        fs::create_dir_all(&dir)?;
        write_atomic(&dir.join(format!("{id}.json")), json)
    }

    fn read_region(&self, id: &str) -> io::Result<Option<Vec<u8>>> {
        if !valid_id(id) {
            return Ok(None);
        }
        match fs::read(self.root.join("regions").join(format!("{id}.json"))) {
            Ok(b) => Ok(Some(b)),
            Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(None),
            Err(e) => Err(e),
        }
    }

    fn remove_region(&self, id: &str) -> io::Result<()> {
        let dir = self.root.join("regions");
        match fs::remove_file(dir.join(format!("{id}.json"))) {
            Ok(()) => sync_dir(&dir),
            Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(()),
            Err(e) => Err(e),
        }
    }

    fn region_ids(&self) -> io::Result<Vec<String>> {
        let dir = self.root.join("regions");
        let entries = match fs::read_dir(&dir) {
            Ok(e) => e,
            Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(Vec::new()),
            Err(e) => return Err(e),
        };
        let mut ids = Vec::new();
        for entry in entries {
            let name = entry?.file_name().to_string_lossy().to_string();
            if let Some(id) = name.strip_suffix(".json").filter(|id| valid_id(id)) {
                ids.push(id.to_string());
            }
        }
        ids.sort();
        Ok(ids)
    }
}

/// Takes the exclusive lock of the data directory `root`. A server still
/// exiting gets two seconds to let go; then another one is assumed to use
/// it and opening fails.
fn lock_exclusive(root: &Path) -> io::Result<File> {
    let path = root.join(LOCK_FILE);
    let f = File::options()
        .read(true)
        .write(true)
        .create(true)
        .truncate(false)
        .open(&path)?;
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(2);
    loop {
        match f.try_lock() {
            Ok(()) => return Ok(f),
            Err(fs::TryLockError::WouldBlock) if std::time::Instant::now() < deadline => {
                std::thread::sleep(std::time::Duration::from_millis(50));
            }
            Err(fs::TryLockError::WouldBlock) => {
                return Err(io::Error::new(
                    io::ErrorKind::WouldBlock,
                    format!(
                        "{} is in use by another solidtex server (it holds {})",
                        root.display(),
                        path.display()
                    ),
                ));
            }
            Err(fs::TryLockError::Error(e)) => return Err(e),
        }
    }
}

/// A temporary of [`write_atomic_with`] for one of the [`WRITTEN`] files:
/// `.NAME.PID.tmp`.
fn is_temporary(name: &str) -> bool {
    let Some(inner) = name
        .strip_prefix('.')
        .and_then(|n| n.strip_suffix(TMP_SUFFIX))
    else {
        return false;
    };
    inner.rsplit_once('.').is_some_and(|(file, pid)| {
        WRITTEN.contains(&file) && !pid.is_empty() && pid.bytes().all(|b| b.is_ascii_digit())
    })
}

/// Removes a texture directory if it holds only files the server writes
/// (true); leaves it untouched otherwise (false).
fn remove_written(dir: &Path) -> io::Result<bool> {
    let mut files = Vec::new();
    for f in fs::read_dir(dir)? {
        let f = f?;
        let name = f.file_name().to_string_lossy().to_string();
        if !f.file_type()?.is_file() || !(WRITTEN.contains(&name.as_str()) || is_temporary(&name)) {
            tracing::warn!(path = %f.path().display(), "not written by the server; left in place");
            return Ok(false);
        }
        files.push(f.path());
    }
    for f in files {
        fs::remove_file(f)?;
    }
    fs::remove_dir(dir)?;
    Ok(true)
}

/// Writes `bytes` to `path` atomically and durably: readers see the old
/// file or the new one, never half of it. The one such helper, for the
/// data directory and the command line's outputs alike.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> io::Result<()> {
    write_atomic_with(path, |w| w.write_all(bytes))
}

/// Writes `path` atomically and durably through `fill`: a temporary file in
/// the same directory is written, fsynced and renamed over `path`, then the
/// directory is fsynced.
pub fn write_atomic_with(
    path: &Path,
    fill: impl FnOnce(&mut dyn Write) -> io::Result<()>,
) -> io::Result<()> {
    // A bare file name lives in the current directory.
    let dir = match path.parent() {
        Some(d) if d.as_os_str().is_empty() => Path::new("."),
        Some(d) => d,
        None => return Err(io::Error::other("path has no parent")),
    };
    let name = path
        .file_name()
        .ok_or_else(|| io::Error::other("path has no file name"))?
        .to_string_lossy();
    let tmp = dir.join(format!(".{name}.{}{TMP_SUFFIX}", std::process::id()));
    let result = (|| {
        let mut w = BufWriter::new(File::create(&tmp)?);
        fill(&mut w)?;
        let f = w.into_inner().map_err(|e| e.into_error())?;
        f.sync_all()?;
        drop(f);
        fs::rename(&tmp, path)?;
        sync_dir(dir)
    })();
    if result.is_err() {
        let _ = fs::remove_file(&tmp);
    }
    result
}

/// Fsyncs a directory so a rename in it is durable.
pub fn sync_dir(dir: &Path) -> io::Result<()> {
    #[cfg(unix)]
    {
        File::open(dir)?.sync_all()
    }
    #[cfg(not(unix))]
    {
        let _ = dir;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::super::StoredStatus;
    use super::super::tests::{meta, planes};
    use super::*;

    #[test]
    fn atomic_write_replaces() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("f");
        write_atomic(&p, b"one").unwrap();
        write_atomic(&p, b"two").unwrap();
        assert_eq!(fs::read(&p).unwrap(), b"two");
        assert_eq!(
            fs::read_dir(d.path()).unwrap().count(),
            1,
            "no temporary left"
        );
        let err = write_atomic_with(&p, |w| {
            w.write_all(b"partial")?;
            Err(io::Error::other("fail"))
        });
        assert!(err.is_err());
        assert_eq!(
            fs::read(&p).unwrap(),
            b"two",
            "failed write leaves the old file"
        );
        assert_eq!(fs::read_dir(d.path()).unwrap().count(), 1);
    }

    #[test]
    fn create_scan_remove() {
        let d = tempfile::tempdir().unwrap();
        let s = DataDir::open(d.path()).unwrap();
        let m = meta("abc", StoredStatus::Pending);
        s.create(&m, &planes()).unwrap();
        let found = s.scan().unwrap();
        assert_eq!(found.len(), 1);
        assert_eq!(found[0].meta, m);
        let back = s.read_planes(&m).unwrap();
        assert_eq!(back.named()[0].1, planes().named()[0].1);
        s.remove("abc").unwrap();
        assert!(s.scan().unwrap().is_empty());
    }

    #[test]
    fn open_clears_debris() {
        let d = tempfile::tempdir().unwrap();
        let s = DataDir::open(d.path()).unwrap();
        s.create(&meta("keep", StoredStatus::Ready), &planes())
            .unwrap();
        fs::write(s.dir("keep").join(".candidates.stx.1.tmp"), b"half").unwrap();
        fs::create_dir_all(s.dir("nometa")).unwrap();
        fs::write(s.dir("nometa").join("exemplar.png"), b"x").unwrap();
        fs::create_dir_all(d.path().join("textures").join("x.deleting.tmp")).unwrap();
        drop(s);
        let s = DataDir::open(d.path()).unwrap();
        let ids: Vec<String> = s.scan().unwrap().into_iter().map(|f| f.meta.id).collect();
        assert_eq!(ids, vec!["keep".to_string()]);
        assert!(!s.dir("keep").join(".candidates.stx.1.tmp").exists());
        assert!(!s.dir("nometa").exists());
    }

    #[test]
    fn unreadable_meta_is_skipped() {
        let d = tempfile::tempdir().unwrap();
        let s = DataDir::open(d.path()).unwrap();
        fs::create_dir_all(s.dir("bad")).unwrap();
        fs::write(s.dir("bad").join("meta.json"), b"{not json").unwrap();
        assert!(s.scan().unwrap().is_empty());
    }
}
