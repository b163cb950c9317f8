//! Where a new version of an output file goes: the one rule every writer of the workspace follows
//! (the scene file here, the tools' images and reports, the ray report).
//!
//! A regular file is replaced whole: the writer fills a temporary file beside it and renames it
//! over the file only when complete, so an interrupted or failed write leaves the old file. That
//! rename must not reach what is not a regular file: renamed over `/dev/null` (`--out /dev/null`,
//! run as root) it replaced the device for the whole machine with an empty file, and over a
//! symbolic link it replaced the link instead of the file it names. So a link is followed to its
//! file, and a device, a pipe or a socket is written in place. [`write_replacing`] is that rule as
//! the one writer every output goes through; [`remove_temporaries`] is for an interrupt handler.

use std::fs::File;
use std::io::{self, BufWriter};
use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard};

/// How to write a new version of a path ([`destination`]).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Destination {
    /// A regular file, or none yet: write a temporary file in this file's folder and rename it
    /// to this path when complete. A symbolic link is resolved to the file it names.
    Replace(PathBuf),
    /// A device, a pipe or a socket (`/dev/null`, a FIFO, a terminal): written in place, as a
    /// stream; nothing to replace.
    InPlace(PathBuf),
}

/// Where writing `path` should go; an error for a folder, or where the path cannot be examined.
pub fn destination(path: &Path) -> io::Result<Destination> {
    let meta = match std::fs::metadata(path) {
        Ok(meta) => meta,
        // New (or a link to nothing): the new file goes at the path itself.
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(Destination::Replace(path.to_owned())),
        Err(e) => return Err(e),
    };
    if meta.is_dir() {
        return Err(io::Error::new(io::ErrorKind::IsADirectory, "it is a folder"));
    }
    // Through every link, so that the temporary file sits beside the file that is replaced.
    let resolved = if std::fs::symlink_metadata(path)?.file_type().is_symlink() {
        std::fs::canonicalize(path)?
    } else {
        path.to_owned()
    };
    Ok(if meta.is_file() { Destination::Replace(resolved) } else { Destination::InPlace(resolved) })
}

/// Temporary files this process is writing, for [`remove_temporaries`].
static PENDING: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

fn pending() -> MutexGuard<'static, Vec<PathBuf>> {
    PENDING.lock().unwrap_or_else(|e| e.into_inner())
}

/// The temporary name of `file` while its new version is written: hidden, in the same folder (so
/// that the rename cannot cross file systems), and distinct per process.
pub fn temporary_name(file: &Path) -> PathBuf {
    let name = file.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let folder = file.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    folder.join(format!(".{name}.{}.partial", std::process::id()))
}

/// Writes a new version of `path` through `write`, by [`destination`]'s rule: a file is written
/// under [`temporary_name`], flushed to disk and renamed over the old one only when complete; on
/// any failure the temporary file is removed and the old file is left as it was. A device or a
/// pipe is written in place.
pub fn write_replacing(path: &Path, write: impl FnOnce(&mut BufWriter<File>) -> io::Result<()>) -> io::Result<()> {
    let file = match destination(path)? {
        Destination::Replace(file) => file,
        Destination::InPlace(stream) => {
            let mut w = BufWriter::new(File::create(stream)?);
            write(&mut w)?;
            return w.into_inner().map(drop).map_err(|e| e.into_error());
        }
    };
    let tmp = temporary_name(&file);
    pending().push(tmp.clone());
    let written = (|| {
        let file = File::create(&tmp)?;
        let flusher = Flusher::start(&file);
        let mut w = BufWriter::new(file);
        let wrote = write(&mut w);
        let synced = flusher.stop();
        wrote?;
        synced?;
        w.into_inner().map_err(|e| e.into_error())?.sync_all()
    })();
    // The rename happens under the lock, so an interrupt either removes the temporary file before
    // it or finds it already renamed.
    let mut list = pending();
    let result = written.and_then(|()| std::fs::rename(&tmp, &file));
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    list.retain(|p| *p != tmp);
    result
}

/// Sends what a long write has put into the page cache so far to the disk while the write goes
/// on, so that the `sync_all` at its end, which must finish before the rename, waits only for the
/// rest: a second handle of the file synced every [`Flusher::PERIOD`] on a thread of its own. For
/// a file written in less than one period it never syncs. Its errors are the write's: the handle
/// shares the file's open description, and Linux reports a failed write-back to one sync of it
/// only, so the final `sync_all` would not see what this thread was told.
struct Flusher {
    stop: std::sync::mpsc::Sender<()>,
    thread: Option<std::thread::JoinHandle<io::Result<usize>>>,
}

impl Flusher {
    const PERIOD: std::time::Duration = std::time::Duration::from_millis(8);

    fn start(file: &File) -> Self {
        let (stop, stopped) = std::sync::mpsc::channel::<()>();
        // Without a second handle (or a thread) the write still ends in its full sync.
        let thread = file.try_clone().ok().and_then(|f| {
            std::thread::Builder::new()
                .name("flush".into())
                .spawn(move || {
                    let mut syncs = 0;
                    while let Err(std::sync::mpsc::RecvTimeoutError::Timeout) = stopped.recv_timeout(Self::PERIOD) {
                        f.sync_data()?;
                        syncs += 1;
                    }
                    Ok(syncs)
                })
                .ok()
        });
        Flusher { stop, thread }
    }

    /// Ends the thread (after the sync it may be in): how many syncs it made, or the error of the
    /// one that failed.
    fn stop(self) -> io::Result<usize> {
        let _ = self.stop.send(());
        match self.thread.map(std::thread::JoinHandle::join) {
            Some(Ok(synced)) => synced,
            Some(Err(_)) => Err(io::Error::other("the thread that syncs the file to disk stopped")),
            None => Ok(0),
        }
    }
}

/// Removes every temporary file [`write_replacing`] is writing, and keeps others from being
/// renamed into place until the process ends: for a handler of Ctrl-C and the like, which then
/// exits. No old file is touched.
pub fn remove_temporaries() {
    let list = pending();
    for p in list.iter() {
        let _ = std::fs::remove_file(p);
    }
    // Held to the exit, so that no write in flight renames a file after this.
    std::mem::forget(list);
}

#[cfg(all(test, unix))]
mod tests {
    use super::*;

    fn scratch(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("bvh-format-destination-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    #[test]
    fn regular_files_and_new_paths_are_replaced_where_they_are() {
        let dir = scratch("regular");
        let (old, new) = (dir.join("old.bin"), dir.join("new.bin"));
        std::fs::write(&old, b"x").unwrap();
        assert_eq!(destination(&old).unwrap(), Destination::Replace(old.clone()));
        assert_eq!(destination(&new).unwrap(), Destination::Replace(new.clone()));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_link_is_followed_to_its_file_and_a_device_is_written_in_place() {
        let dir = scratch("links");
        let target = dir.join("target.bin");
        std::fs::write(&target, b"x").unwrap();
        let link = dir.join("link.bin");
        std::os::unix::fs::symlink(&target, &link).unwrap();
        let real = std::fs::canonicalize(&target).unwrap();
        assert_eq!(destination(&link).unwrap(), Destination::Replace(real));
        assert_eq!(destination(Path::new("/dev/null")).unwrap(), Destination::InPlace("/dev/null".into()));
        let null_link = dir.join("null");
        std::os::unix::fs::symlink("/dev/null", &null_link).unwrap();
        assert_eq!(destination(&null_link).unwrap(), Destination::InPlace("/dev/null".into()));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_failed_write_leaves_the_old_file_and_no_temporary_one() {
        use std::io::Write;
        let dir = scratch("replace");
        let file = dir.join("out.txt");
        std::fs::write(&file, b"old").unwrap();
        let failed = write_replacing(&file, |w| {
            w.write_all(b"half")?;
            Err(io::Error::other("the encoder failed"))
        });
        assert_eq!(failed.unwrap_err().to_string(), "the encoder failed");
        assert_eq!(std::fs::read(&file).unwrap(), b"old");
        assert!(!temporary_name(&file).exists());
        write_replacing(&file, |w| w.write_all(b"new")).unwrap();
        assert_eq!(std::fs::read(&file).unwrap(), b"new");
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1, "only the file itself is left");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_long_write_is_synced_while_it_goes_on_and_still_replaces_the_file_whole() {
        use std::io::Write;
        let dir = scratch("flush");
        let file = dir.join("out.bin");
        let piece = vec![7u8; 1 << 20];
        // The flusher on its own: a write of several periods is synced on the way.
        let f = File::create(dir.join("direct.bin")).unwrap();
        let flusher = Flusher::start(&f);
        // Long pauses, so that even a loaded machine runs the thread's first sync among them.
        for _ in 0..4 {
            (&f).write_all(&piece).unwrap();
            std::thread::sleep(Flusher::PERIOD * 8);
        }
        assert!(flusher.stop().unwrap() >= 1, "no sync while the write went on");
        // Through write_replacing: the whole file arrives, and a failure late in a long write
        // leaves the old file and no temporary one.
        std::fs::write(&file, b"old").unwrap();
        let slow = |fail: bool| {
            write_replacing(&file, |w| {
                for _ in 0..4 {
                    w.write_all(&piece)?;
                    w.flush()?;
                    std::thread::sleep(Flusher::PERIOD * 2);
                }
                if fail { Err(io::Error::other("the encoder failed")) } else { Ok(()) }
            })
        };
        assert!(slow(true).is_err());
        assert_eq!(std::fs::read(&file).unwrap(), b"old");
        assert!(!temporary_name(&file).exists());
        slow(false).unwrap();
        let got = std::fs::read(&file).unwrap();
        assert_eq!(got.len(), 4 << 20);
        assert!(got.iter().all(|&b| b == 7));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_folder_is_refused() {
        let dir = scratch("folder");
        assert_eq!(destination(&dir).unwrap_err().kind(), io::ErrorKind::IsADirectory);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
