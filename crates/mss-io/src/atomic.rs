//! Atomic file writes and the error type of the output writers.
//!
//! Every output file is written under a temporary name in the destination
//! folder and renamed over the final name only once it is complete, so a reader
//! (or a user after a crash) never sees a half-written file: the final name
//! holds either the previous complete version or the new one.

use std::fs::{self, File, OpenOptions};
use std::io::{self, BufWriter, Seek, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// Errors of the output writers. Every variant names the file concerned.
#[derive(Debug, thiserror::Error)]
pub enum IoError {
    /// The operating system refused an operation (create, write, rename, ...).
    #[error("cannot write {}: {source}", path.display())]
    Io {
        /// File (or folder) being written.
        path: PathBuf,
        /// Underlying error.
        #[source]
        source: io::Error,
    },
    /// The data handed to a writer is inconsistent (an index out of range, a
    /// field of the wrong length, a name the format cannot store, ...).
    #[error("invalid data for {}: {reason}", path.display())]
    InvalidData {
        /// File that was to be written.
        path: PathBuf,
        /// What is wrong and, where possible, how to fix it.
        reason: String,
    },
    /// No exporter of that name exists.
    #[error("unknown {kind} exporter `{name}` (known: {known})")]
    UnknownExporter {
        /// "frame" or "skin".
        kind: &'static str,
        /// The name asked for.
        name: String,
        /// Comma-separated list of the known names.
        known: String,
    },
}

impl IoError {
    /// Shorthand for [`IoError::InvalidData`].
    pub fn invalid(path: &Path, reason: impl Into<String>) -> Self {
        IoError::InvalidData {
            path: path.to_path_buf(),
            reason: reason.into(),
        }
    }

    /// Shorthand for [`IoError::Io`].
    pub fn io(path: &Path, source: io::Error) -> Self {
        IoError::Io {
            path: path.to_path_buf(),
            source,
        }
    }
}

/// Distinguishes temporary files of concurrent writes within one process.
static TEMP_COUNTER: AtomicU64 = AtomicU64::new(0);

/// Buffer size of the writer handed to the closure: large writes of binary
/// frames go straight through, small formatted writes are batched.
const BUFFER_BYTES: usize = 1 << 20;

/// Writes a file atomically: `write` fills a temporary file
/// `.NAME.tmp-PID-N` in the same folder as `path`, which is flushed and then
/// renamed to `path` (replacing an existing file).
///
/// If `write` or any file operation fails, the temporary file is removed and
/// `path` is left untouched. The data is flushed to the operating system but
/// not fsync'ed: an atomic rename protects against interrupted runs, not
/// against power loss.
///
/// ```
/// use std::io::Write;
/// let dir = tempfile::tempdir().unwrap();
/// let path = dir.path().join("hello.txt");
/// mss_io::atomic::write_atomic(&path, |w| w.write_all(b"hello")).unwrap();
/// assert_eq!(std::fs::read_to_string(&path).unwrap(), "hello");
/// ```
pub fn write_atomic(
    path: &Path,
    write: impl FnOnce(&mut dyn Write) -> io::Result<()>,
) -> Result<(), IoError> {
    write_atomic_seekable(path, |w| write(w))
}

/// A writer that can go back, as the `.vtu` writer does to fill in an
/// array's header once its compressed blocks are written.
pub(crate) trait WriteSeek: Write + Seek {}

impl<T: Write + Seek + ?Sized> WriteSeek for T {}

/// [`write_atomic`] with a writer that can seek within the file written.
pub(crate) fn write_atomic_seekable(
    path: &Path,
    write: impl FnOnce(&mut dyn WriteSeek) -> io::Result<()>,
) -> Result<(), IoError> {
    let file_name = path.file_name().ok_or_else(|| {
        IoError::invalid(
            path,
            "the output path has no file name (it ends in `..` or `/`)",
        )
    })?;
    let (temp, file) = create_temporary(path, file_name)?;
    match fill_and_close(file, write) {
        Ok(()) => fs::rename(&temp, path).map_err(|e| {
            let _ = fs::remove_file(&temp);
            IoError::io(path, e)
        }),
        Err(e) => {
            // The write error is what the caller needs; a failed cleanup of a
            // file we just created is only worth a log line.
            if let Err(rm) = fs::remove_file(&temp) {
                log::warn!("cannot remove temporary file {}: {rm}", temp.display());
            }
            Err(IoError::io(path, e))
        }
    }
}

/// Creates a fresh temporary file `.NAME.tmp-PID-N` beside `path` (whose
/// file name is `file_name`), unique within this process; errors name `path`.
pub(crate) fn create_temporary(
    path: &Path,
    file_name: &std::ffi::OsStr,
) -> Result<(PathBuf, File), IoError> {
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let n = TEMP_COUNTER.fetch_add(1, Ordering::Relaxed);
    let mut temp_name = std::ffi::OsString::from(".");
    temp_name.push(file_name);
    temp_name.push(format!(".tmp-{}-{n}", std::process::id()));
    let temp = dir.join(temp_name);
    let file = OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&temp)
        .map_err(|e| IoError::io(path, e))?;
    Ok((temp, file))
}

fn fill_and_close(
    file: File,
    write: impl FnOnce(&mut dyn WriteSeek) -> io::Result<()>,
) -> io::Result<()> {
    let mut w = BufWriter::with_capacity(BUFFER_BYTES, file);
    write(&mut w)?;
    w.flush()?;
    // Surface errors of the buffered data here rather than in a silent drop.
    w.into_inner().map_err(|e| e.into_error())?;
    Ok(())
}

/// Checks that `prefix` is a plain file-name stem (series files are named
/// `PREFIX_NNNN.ext` inside one folder).
pub(crate) fn check_prefix(dir: &Path, prefix: &str) -> Result<(), IoError> {
    if prefix.is_empty() || prefix == "." || prefix == ".." || prefix.contains(['/', '\\', '\0']) {
        return Err(IoError::invalid(
            &dir.join(prefix),
            format!("file prefix {prefix:?} must be a plain, non-empty file name stem"),
        ));
    }
    Ok(())
}

/// Creates `dir` and its parents if missing.
pub fn ensure_dir(dir: &Path) -> Result<(), IoError> {
    fs::create_dir_all(dir).map_err(|e| IoError::io(dir, e))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names_in(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> = fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    #[test]
    fn failing_writer_leaves_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.vtu");
        let err = write_atomic(&path, |w| {
            w.write_all(&[7u8; 3 * BUFFER_BYTES])?;
            Err(io::Error::other("disk on fire"))
        })
        .unwrap_err();
        let msg = err.to_string();
        assert!(
            msg.contains("out.vtu") && msg.contains("disk on fire"),
            "{msg}"
        );
        assert!(
            names_in(dir.path()).is_empty(),
            "{:?}",
            names_in(dir.path())
        );
    }

    #[test]
    fn failing_writer_keeps_previous_version() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.txt");
        write_atomic(&path, |w| w.write_all(b"first")).unwrap();
        assert!(
            write_atomic(&path, |w| {
                w.write_all(b"sec")?;
                Err(io::Error::other("interrupted"))
            })
            .is_err()
        );
        assert_eq!(fs::read_to_string(&path).unwrap(), "first");
        assert_eq!(names_in(dir.path()), vec!["a.txt".to_string()]);
        write_atomic(&path, |w| w.write_all(b"second")).unwrap();
        assert_eq!(fs::read_to_string(&path).unwrap(), "second");
        assert_eq!(names_in(dir.path()), vec!["a.txt".to_string()]);
    }

    #[test]
    fn missing_folder_is_an_error_naming_the_path() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("no/such/dir/x.vtk");
        let err = write_atomic(&path, |w| w.write_all(b"x")).unwrap_err();
        assert!(matches!(err, IoError::Io { .. }));
        assert!(err.to_string().contains("x.vtk"));
    }
}
