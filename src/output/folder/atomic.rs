//! Atomic, durable file writing: every file to a temporary name beside it, flushed (fsync)
//! and renamed into place, so a reader never sees a half-written file; the test hook that
//! makes a write fail half-way as on a full disk; clean-up of temporaries of killed writers.
use std::fs::File;
use std::io::Write;
use std::path::Path;

/// Environment variable used only by tests: a write to a file of this name (its last path
/// component) fails half-way with "no space left on device", as on a full disk.
pub const FAIL_WRITE_ENV: &str = "HUSHFUSE_TEST_FAIL_WRITE";

/// Writes `bytes` to `path` durably: to a temporary name beside it, flushed (fsync), then
/// renamed into place and the folder flushed. Creates missing parent folders. On error the
/// file at `path` is as before and no temporary file is left.
pub fn write_file(path: &Path, bytes: &[u8]) -> Result<(), String> {
    write_file_with(path, |w| w.write_all(bytes))
}

/// [`write_file`] for a file that is produced as it is written: `produce` streams its bytes
/// into the (buffered) temporary file, so a large output never exists whole in memory.
/// `produce` may be called more than once (the test hook measures the file before failing half
/// way through it) and must write the same bytes each time.
pub fn write_file_with<F>(path: &Path, produce: F) -> Result<(), String>
where
    F: FnMut(&mut dyn Write) -> std::io::Result<()>,
{
    let name = path
        .file_name()
        .ok_or_else(|| format!("cannot write {}: not a file name", path.display()))?
        .to_string_lossy()
        .into_owned();
    let parent = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    std::fs::create_dir_all(parent)
        .map_err(|e| format!("cannot create {}: {e}", parent.display()))?;
    let tmp = parent.join(format!(".{name}.tmp-{}", std::process::id()));
    let result = write_synced(&tmp, &name, produce).and_then(|()| {
        std::fs::rename(&tmp, path)
            .map_err(|e| format!("cannot rename {} to {}: {e}", tmp.display(), path.display()))
    });
    if let Err(e) = result {
        let _ = std::fs::remove_file(&tmp);
        return Err(e);
    }
    sync_dir(parent);
    Ok(())
}

/// Buffer of a streamed file: large enough that a writer of many small pieces (serde_json,
/// CSV rows) costs few system calls, small beside the outputs it spares from memory.
pub(super) const WRITE_BUFFER: usize = 64 * 1024;

/// Creates `path`, streams `produce` into it and flushes it to disk. `name` is the name the
/// test hook matches.
pub(super) fn write_synced<F>(path: &Path, name: &str, mut produce: F) -> Result<(), String>
where
    F: FnMut(&mut dyn Write) -> std::io::Result<()>,
{
    let err = |e: std::io::Error| format!("cannot write {}: {e}", path.display());
    let file = File::create(path).map_err(err)?;
    if std::env::var_os(FAIL_WRITE_ENV).is_some_and(|v| v == name) {
        return write_half_then_fail(file, &mut produce).map_err(err);
    }
    let mut w = std::io::BufWriter::with_capacity(WRITE_BUFFER, file);
    produce(&mut w).map_err(err)?;
    let file = w.into_inner().map_err(|e| err(e.into_error()))?;
    file.sync_all().map_err(err)
}

/// The test hook: half the bytes `produce` writes reach the disk, then the disk is full. The
/// same streaming path as a real write, so a failure in the middle of a streamed file is what
/// the durability tests exercise.
pub(super) fn write_half_then_fail<F>(file: File, produce: &mut F) -> std::io::Result<()>
where
    F: FnMut(&mut dyn Write) -> std::io::Result<()>,
{
    let mut size = CountingSink(0);
    produce(&mut size)?;
    let mut disk = FullDisk {
        file,
        room: size.0 / 2,
    };
    let streamed = {
        let mut w = std::io::BufWriter::with_capacity(WRITE_BUFFER, &mut disk);
        produce(&mut w).and_then(|()| w.flush())
    };
    let _ = disk.file.sync_all();
    match streamed {
        // Only an empty file fits on the "full" disk.
        Ok(()) => Err(disk_full()),
        Err(e) => Err(e),
    }
}

/// The error of a full disk, as injected by [`FAIL_WRITE_ENV`].
pub(super) fn disk_full() -> std::io::Error {
    std::io::Error::new(
        std::io::ErrorKind::StorageFull,
        format!("no space left on device (injected by {FAIL_WRITE_ENV})"),
    )
}

/// Counts the bytes written to it (the size of a streamed file, for the test hook).
pub(super) struct CountingSink(usize);

impl Write for CountingSink {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0 += buf.len();
        Ok(buf.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

/// A file on a disk with `room` bytes left: writes beyond it fail with [`disk_full`].
pub(super) struct FullDisk {
    file: File,
    room: usize,
}

impl Write for FullDisk {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        if self.room == 0 && !buf.is_empty() {
            return Err(disk_full());
        }
        let n = self.file.write(&buf[..buf.len().min(self.room)])?;
        self.room -= n;
        Ok(n)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.file.flush()
    }
}

/// Removes the temporaries (`.NAME.tmp-PID`) that a process killed while writing left in
/// `dir`, when that process is gone (so that a live writer's temporary in a shared shard folder
/// stays). Best effort: where liveness cannot be told (no /proc), nothing is removed.
pub fn remove_stale_temporaries(dir: &Path) {
    let proc = Path::new("/proc");
    if !proc.join("self").exists() {
        return;
    }
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let name = entry.file_name().to_string_lossy().into_owned();
        let Some(pid) = name
            .strip_prefix('.')
            .and_then(|n| n.rsplit_once(".tmp-"))
            .map(|(_, pid)| pid.to_string())
        else {
            continue;
        };
        if pid.parse::<u32>().is_ok()
            && pid != std::process::id().to_string()
            && !proc.join(&pid).exists()
        {
            let _ = std::fs::remove_file(entry.path());
        }
    }
}

/// Flushes a folder's entries (renames) to disk; best effort (not every file system can).
pub(super) fn sync_dir(dir: &Path) {
    if let Ok(d) = File::open(dir) {
        let _ = d.sync_all();
    }
}
