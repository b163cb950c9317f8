//! Where a new version of an output file goes: the one rule every writer of the workspace follows
//! (the scene file here, the tools' images and reports, the ray report).
//!
//! A regular file is replaced whole: the writer fills a temporary file beside it and renames it
//! over the file only when complete, so an interrupted or failed write leaves the old file. That
//! rename must not reach what is not a regular file: renamed over `/dev/null` (`--out /dev/null`,
//! run as root) it replaced the device for the whole machine with an empty file, and over a
//! symbolic link it replaced the link instead of the file it names. So a link is followed to its
//! file, and a device, a pipe or a socket is written in place.

use std::io;
use std::path::{Path, PathBuf};

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
    fn a_folder_is_refused() {
        let dir = scratch("folder");
        assert_eq!(destination(&dir).unwrap_err().kind(), io::ErrorKind::IsADirectory);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
