//! Result files that survive: every file the host writes as a result (calibration, loop, report,
//! figures, exports, session manifest) is written whole to a temporary name in its own directory,
//! flushed to disk, and renamed into place, so a reader, a concurrent writer or a kill at any
//! instant sees either the old file or the new one, never a fragment or 0 bytes. The output
//! directory's lock keeps two calibrations from interleaving their sets of files.

use anyhow::{Context, Result};
use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// Writes `bytes` to `path` atomically: a temporary file in the same directory (a rename is
/// atomic only within one file system), `fsync`, rename over `path`, then `fsync` of the
/// directory so the rename itself survives a power cut (ext4 and XFS need it; POSIX says so).
pub fn write_atomic(path: &Path, bytes: impl AsRef<[u8]>) -> Result<()> {
    let what = || format!("cannot write {}", path.display());
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    // Hidden, named after its target, unique per process and call. Made here rather than with
    // `tempfile`, whose errors name the random temporary path instead of the user's file.
    static SERIAL: AtomicU64 = AtomicU64::new(0);
    let name = path.file_name().map(|f| f.to_string_lossy()).unwrap_or_default();
    let tmp = dir.join(format!(".{name}.{}.{}.tmp", std::process::id(), SERIAL.fetch_add(1, Ordering::Relaxed)));
    let mut options = std::fs::OpenOptions::new();
    options.write(true).create_new(true);
    // 0666 less the umask, as `File::create` does.
    #[cfg(unix)]
    std::os::unix::fs::OpenOptionsExt::mode(&mut options, 0o666);
    let written = options.open(&tmp).and_then(|mut f| {
        f.write_all(bytes.as_ref())?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)
    });
    if let Err(e) = written {
        let _ = std::fs::remove_file(&tmp);
        return Err(e).with_context(what);
    }
    // Best effort: some file systems (and non-Unix systems) cannot open or sync a directory.
    if let Ok(d) = File::open(dir) {
        let _ = d.sync_all();
    }
    Ok(())
}

/// An exclusive lock on an output directory (`DIR/.gyrocal.lock`, advisory `flock`), held until
/// dropped: a second `calibrate` into the same directory is refused at once rather than mixing
/// its files with the first's. The kernel releases the lock when the process ends, however it
/// ends, so a killed run never leaves the directory locked.
#[derive(Debug)]
pub struct DirLock {
    _file: File,
    path: PathBuf,
}

/// The lock file's name in the directory it guards.
pub const LOCK_FILE: &str = ".gyrocal.lock";

impl DirLock {
    /// Creates `dir` if needed and locks it, or says that another `host` holds it.
    pub fn acquire(dir: &Path) -> Result<Self> {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
        let path = dir.join(LOCK_FILE);
        let file = std::fs::OpenOptions::new()
            .create(true)
            .truncate(false)
            .write(true)
            .open(&path)
            .with_context(|| format!("cannot create {}", path.display()))?;
        match rustix::fs::flock(&file, rustix::fs::FlockOperation::NonBlockingLockExclusive) {
            Ok(()) => Ok(Self { _file: file, path }),
            Err(rustix::io::Errno::WOULDBLOCK) => anyhow::bail!(
                "{} is in use by another calibration (it holds {}): wait for it to finish or choose another --out-dir",
                dir.display(),
                LOCK_FILE
            ),
            Err(e) => Err(std::io::Error::from(e)).with_context(|| format!("cannot lock {}", path.display())),
        }
    }

    /// The lock file.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

/// Writes `text` to standard output and flushes it: a closed pipe (`| head`, `| true`) or a
/// full device is an error naming standard output, never a panic (`print!` panics on both).
pub fn stdout(text: &str) -> Result<()> {
    let mut out = std::io::stdout().lock();
    out.write_all(text.as_bytes()).and_then(|()| out.flush()).context("cannot write to standard output")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_atomic_write_replaces_the_file_whole_and_leaves_no_temporary() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("calibration.json");
        write_atomic(&p, "old").unwrap();
        write_atomic(&p, "new, longer").unwrap();
        assert_eq!(std::fs::read_to_string(&p).unwrap(), "new, longer");
        let names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(names, vec![std::ffi::OsString::from("calibration.json")]);
    }

    #[test]
    fn an_atomic_write_into_a_missing_directory_names_the_file() {
        let e = write_atomic(Path::new("/nonexistent-gyrocal/x.json"), "x").unwrap_err();
        assert_eq!(
            format!("{e:#}"),
            "cannot write /nonexistent-gyrocal/x.json: No such file or directory (os error 2)"
        );
    }

    #[cfg(unix)]
    #[test]
    fn a_result_file_gets_the_usual_permissions_not_the_temporary_files() {
        use std::os::unix::fs::PermissionsExt as _;
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("r.json");
        write_atomic(&p, "x").unwrap();
        let plain = dir.path().join("plain");
        std::fs::write(&plain, "x").unwrap();
        let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode(&p), mode(&plain));
    }

    #[test]
    fn a_locked_directory_is_refused_and_freed_on_drop() {
        let dir = tempfile::tempdir().unwrap();
        let first = DirLock::acquire(dir.path()).unwrap();
        let e = DirLock::acquire(dir.path()).unwrap_err();
        assert_eq!(
            e.to_string(),
            format!(
                "{} is in use by another calibration (it holds .gyrocal.lock): wait for it to finish or choose another --out-dir",
                dir.path().display()
            )
        );
        drop(first);
        DirLock::acquire(dir.path()).unwrap();
    }
}
