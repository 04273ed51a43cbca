//! Durable output. Every file is written to a temporary name, flushed to disk and renamed into
//! place, so a reader never sees a half-written file. A run's output folder is staged whole
//! (every file written and flushed in a staging folder inside it) before anything is moved into
//! place, so a failed write (a full disk) leaves the earlier run's complete output untouched.
//! The folder carries a manifest of what the run wrote; files of an earlier run that the new
//! one does not write are removed when the old manifest lists them, and a folder holding files
//! that no manifest lists is refused before any work is done.
use serde::{Deserialize, Serialize};
use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};

/// Name of the manifest of an output folder.
pub const MANIFEST: &str = "hushfuse-manifest.json";
/// Folder (inside the output folder) where a run's files are staged before they move in.
const STAGING: &str = ".hushfuse-staging";
/// Marker that hushfuse writes first into a staging folder it creates: a staging folder
/// without it is not hushfuse's, and nothing in it is ever deleted.
const STAGING_OWNER: &str = ".hushfuse-owner";
/// Lock file of an output folder: held (advisory `flock`) by the one run writing the folder.
pub const LOCK: &str = ".hushfuse-lock";
/// Environment variable used only by tests: a write to a file of this name (its last path
/// component) fails half-way with "no space left on device", as on a full disk.
pub const FAIL_WRITE_ENV: &str = "HUSHFUSE_TEST_FAIL_WRITE";

/// Hex of a SHA-256 digest.
pub fn sha256_hex(bytes: &[u8]) -> String {
    use sha2::Digest;
    sha2::Sha256::digest(bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

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
const WRITE_BUFFER: usize = 64 * 1024;

/// Creates `path`, streams `produce` into it and flushes it to disk. `name` is the name the
/// test hook matches.
fn write_synced<F>(path: &Path, name: &str, mut produce: F) -> Result<(), String>
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
fn write_half_then_fail<F>(file: File, produce: &mut F) -> std::io::Result<()>
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
fn disk_full() -> std::io::Error {
    std::io::Error::new(
        std::io::ErrorKind::StorageFull,
        format!("no space left on device (injected by {FAIL_WRITE_ENV})"),
    )
}

/// Counts the bytes written to it (the size of a streamed file, for the test hook).
struct CountingSink(usize);

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
struct FullDisk {
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
fn sync_dir(dir: &Path) {
    if let Ok(d) = File::open(dir) {
        let _ = d.sync_all();
    }
}

/// What an output folder holds and which run wrote it.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct Manifest {
    pub hushfuse_version: String,
    /// `run`, `merge`, `arena` or `table`.
    pub kind: String,
    pub scenario: String,
    /// SHA-256 of the scenario as run (text, source, trials and seed).
    pub scenario_sha256: String,
    pub seed: Option<u64>,
    pub trials: Option<usize>,
    /// Every file the run wrote, relative to the folder, in the order written.
    pub files: Vec<String>,
}

impl Manifest {
    /// A manifest of this version of hushfuse, with no files yet.
    pub fn new(kind: &str, scenario: &str, scenario_sha256: &str) -> Self {
        Self {
            hushfuse_version: env!("CARGO_PKG_VERSION").to_string(),
            kind: kind.to_string(),
            scenario: scenario.to_string(),
            scenario_sha256: scenario_sha256.to_string(),
            seed: None,
            trials: None,
            files: Vec::new(),
        }
    }
}

/// Whether a file name is one hushfuse keeps in an output folder besides what a manifest
/// lists: the manifest, checkpoints, shard files, and temporaries of an interrupted write.
fn is_own_file(rel: &str) -> bool {
    let name = rel.rsplit('/').next().unwrap_or(rel);
    rel == MANIFEST
        || rel == LOCK
        || (name.starts_with(".hushfuse-lock-shard-") && !rel.contains('/'))
        || rel.starts_with(&format!("{STAGING}/"))
        || (name.starts_with("hushfuse-checkpoint") && name.ends_with(".bin"))
        || name.ends_with(".hfshard")
        || (name.starts_with('.') && name.contains(".tmp-"))
}

/// Every file under `dir`, relative to it with `/` separators, sorted.
fn list_files(dir: &Path) -> Result<Vec<String>, String> {
    fn walk(root: &Path, dir: &Path, out: &mut Vec<String>) -> Result<(), String> {
        let entries =
            std::fs::read_dir(dir).map_err(|e| format!("cannot read {}: {e}", dir.display()))?;
        for entry in entries {
            let entry = entry.map_err(|e| format!("cannot read {}: {e}", dir.display()))?;
            let path = entry.path();
            let ft = entry
                .file_type()
                .map_err(|e| format!("cannot read {}: {e}", path.display()))?;
            if ft.is_dir() {
                walk(root, &path, out)?;
            } else {
                let rel = path.strip_prefix(root).unwrap_or(&path);
                out.push(
                    rel.components()
                        .map(|c| c.as_os_str().to_string_lossy().into_owned())
                        .collect::<Vec<_>>()
                        .join("/"),
                );
            }
        }
        Ok(())
    }
    let mut out = Vec::new();
    if dir.is_dir() {
        walk(dir, dir, &mut out)?;
    }
    out.sort();
    Ok(out)
}

/// Reads the manifest of `dir`, if it has one. Every file it lists must be a normalized
/// relative path inside the folder (no `..`, no absolute path, nothing of hushfuse's own):
/// the list decides what a later run removes, so a manifest that reaches outside is refused.
pub fn read_manifest(dir: &Path) -> Result<Option<Manifest>, String> {
    let path = dir.join(MANIFEST);
    let manifest: Manifest = match std::fs::read_to_string(&path) {
        Ok(text) => serde_json::from_str(&text).map_err(|e| {
            format!(
                "{}: not a hushfuse manifest ({e}); remove it or choose another output folder",
                path.display()
            )
        })?,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(format!("cannot read {}: {e}", path.display())),
    };
    for f in &manifest.files {
        check_entry(f).map_err(|why| {
            format!(
                "{}: lists {f:?}, which {why}; a manifest may only name files inside its folder (remove it or choose another output folder)",
                path.display()
            )
        })?;
    }
    Ok(Some(manifest))
}

/// Whether `rel` is a name a manifest may list: relative, `/`-separated, normalized, and not
/// one of hushfuse's own files.
fn check_entry(rel: &str) -> Result<(), String> {
    if rel.is_empty() {
        return Err("is empty".into());
    }
    if rel.starts_with('/') || rel.contains('\\') || rel.contains('\0') || rel.contains(':') {
        return Err("is not a relative path".into());
    }
    for part in rel.split('/') {
        if part.is_empty() || part == "." || part == ".." {
            return Err("is not a normalized path inside the folder".into());
        }
    }
    if is_own_file(rel) {
        return Err("is one of hushfuse's own files".into());
    }
    Ok(())
}

/// Refuses a path `rel` inside `dir` that passes through a symbolic link (a folder of the
/// output that leads elsewhere): writing or removing through it would touch files outside.
fn check_no_link(dir: &Path, rel: &str) -> Result<(), String> {
    let parts: Vec<&str> = rel.split('/').collect();
    let mut p = dir.to_path_buf();
    for part in &parts[..parts.len().saturating_sub(1)] {
        p.push(part);
        match std::fs::symlink_metadata(&p) {
            Ok(m) if m.file_type().is_symlink() => {
                return Err(format!(
                    "{} is a symbolic link: hushfuse writes and removes files only inside the output folder; remove the link or choose another --out",
                    p.display()
                ))
            }
            _ => {}
        }
    }
    Ok(())
}

/// An advisory lock (`flock`) on a lock file of an output folder, held until dropped. The
/// operating system releases it when its process dies, so a lock of a dead run never stands.
#[derive(Debug)]
pub struct FolderLock {
    file: File,
}

impl Drop for FolderLock {
    /// Empties the lock file before the lock goes, so that a finished folder holds no process
    /// number (two finished runs of one experiment leave the same bytes everywhere).
    fn drop(&mut self) {
        let _ = self.file.set_len(0);
    }
}

/// Takes the lock `name` (e.g. [`LOCK`]) of folder `dir`, creating it; refuses, naming the
/// other process, while another run holds it. Also checks that the folder can take new files,
/// so that a read-only `--out` is found before any trial runs.
pub fn lock_folder(dir: &Path, name: &str) -> Result<FolderLock, String> {
    std::fs::create_dir_all(dir).map_err(|e| format!("cannot create {}: {e}", dir.display()))?;
    let path = dir.join(name);
    let mut file = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .create(true)
        .truncate(false)
        .open(&path)
        .map_err(|e| {
            format!(
                "cannot write to output folder {}: {e}; choose a writable --out",
                dir.display()
            )
        })?;
    match file.try_lock() {
        Ok(()) => {}
        Err(std::fs::TryLockError::WouldBlock) => {
            let mut text = String::new();
            let _ = std::io::Read::read_to_string(&mut file, &mut text);
            let who = match text.trim().parse::<u32>() {
                Ok(pid) => format!("another hushfuse run (process {pid})"),
                Err(_) => "another hushfuse run".to_string(),
            };
            return Err(format!(
                "output folder {} is being written by {who}; wait for it to finish or choose another --out",
                dir.display()
            ));
        }
        Err(std::fs::TryLockError::Error(e)) => {
            return Err(format!("cannot lock {}: {e}", path.display()));
        }
    }
    // Who holds it, for the message of a run refused meanwhile.
    let _ = file.set_len(0);
    let _ = write!(file, "{}", std::process::id());
    let _ = file.sync_all();
    probe_writable(dir)?;
    Ok(FolderLock { file })
}

/// Refuses a folder whose file system has less room than `needed` bytes (a run's estimated
/// output), before any trial runs. A file system that cannot say is not refused.
pub fn check_free_space(dir: &Path, needed: f64) -> Result<(), String> {
    let Ok(free) = fs4::available_space(dir) else {
        return Ok(());
    };
    if needed.is_nan() || needed > free as f64 {
        let mib = |b: f64| b / (1024.0 * 1024.0);
        return Err(format!(
            "output folder {} has {:.1} MiB free, and this run will write up to about {:.1} MiB; free some space, choose another --out, or lower `steps` or the number of variants",
            dir.display(),
            mib(free as f64),
            mib(needed)
        ));
    }
    Ok(())
}

/// Creates, flushes and removes a small file in `dir`: a folder that cannot take new files is
/// refused before any work (the name is a temporary's, removed if this process dies).
fn probe_writable(dir: &Path) -> Result<(), String> {
    let probe = dir.join(format!(".write-probe.tmp-{}", std::process::id()));
    let result =
        File::create(&probe).and_then(|mut f| f.write_all(b"hushfuse").and_then(|()| f.sync_all()));
    let _ = std::fs::remove_file(&probe);
    result.map_err(|e| {
        format!(
            "cannot write to output folder {}: {e}; choose a writable --out",
            dir.display()
        )
    })
}

/// Moves staged file `name` from `staging` into place in `dir`.
fn move_in(dir: &Path, staging: &Path, name: &str) -> Result<(), String> {
    check_no_link(dir, name)?;
    let from = staging.join(name);
    let to = dir.join(name);
    if let Some(parent) = to.parent() {
        std::fs::create_dir_all(parent)
            .map_err(|e| format!("cannot create {}: {e}", parent.display()))?;
    }
    std::fs::rename(&from, &to)
        .map_err(|e| format!("cannot move {} into place: {e}", to.display()))?;
    if let Some(parent) = to.parent() {
        sync_dir(parent);
    }
    Ok(())
}

/// Removes the files of an earlier run (manifest entries, so inside `dir`) and the folders
/// (budget-*/) that their removal emptied.
fn remove_stale(dir: &Path, stale: &[String]) -> Result<(), String> {
    for stale in stale {
        check_no_link(dir, stale)?;
        let path = dir.join(stale);
        match std::fs::remove_file(&path) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => return Err(format!("cannot remove stale {}: {e}", path.display())),
        }
        let mut parent = path.parent();
        while let Some(p) = parent.filter(|p| *p != dir) {
            if std::fs::remove_dir(p).is_err() {
                break;
            }
            parent = p.parent();
        }
    }
    Ok(())
}

/// Deals with a staging folder left in `dir` by an earlier process. One that hushfuse made
/// (it holds [`STAGING_OWNER`]) and that holds a staged manifest was killed while moving its
/// files into place: the move is finished (every file it computed is kept, the earlier run's
/// stale files go, the manifest last), and `old` becomes the new manifest. One without a
/// staged manifest died while staging: its files are its own, and are removed. A staging
/// folder that hushfuse did not make is refused, and nothing in it is touched.
fn recover_staging(dir: &Path, old: &mut Option<Manifest>) -> Result<(), String> {
    let staging = dir.join(STAGING);
    let meta = match std::fs::symlink_metadata(&staging) {
        Ok(m) => m,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
        Err(e) => return Err(format!("cannot read {}: {e}", staging.display())),
    };
    let foreign = |what: String| {
        format!(
            "{} {what}, which hushfuse did not stage; move them elsewhere or choose another --out",
            staging.display()
        )
    };
    if !meta.is_dir() {
        return Err(foreign("is not a folder".into()));
    }
    if !staging.join(STAGING_OWNER).is_file() {
        let files = list_files(&staging)?;
        if !files.is_empty() {
            return Err(foreign(format!("holds {}", files.join(", "))));
        }
        let _ = std::fs::remove_dir_all(&staging);
        return Ok(());
    }
    if let Some(new) = read_manifest(&staging)? {
        for name in &new.files {
            if staging.join(name).exists() {
                move_in(dir, &staging, name)?;
            }
        }
        let stale: Vec<String> = old
            .as_ref()
            .map(|m| {
                m.files
                    .iter()
                    .filter(|f| !new.files.contains(f))
                    .cloned()
                    .collect()
            })
            .unwrap_or_default();
        remove_stale(dir, &stale)?;
        std::fs::rename(staging.join(MANIFEST), dir.join(MANIFEST))
            .map_err(|e| format!("cannot move {MANIFEST} into place: {e}"))?;
        eprintln!(
            "note: {}: finished moving the outputs of an interrupted run into place ({} files)",
            dir.display(),
            new.files.len()
        );
        *old = Some(new);
    }
    std::fs::remove_dir_all(&staging)
        .map_err(|e| format!("cannot remove {}: {e}", staging.display()))?;
    sync_dir(dir);
    Ok(())
}

/// An output folder being written: files are staged, then moved in together by
/// [`OutputDir::commit`]. Dropped without a commit, it removes what it staged and leaves the
/// folder as it was.
pub struct OutputDir {
    dir: PathBuf,
    staging: PathBuf,
    old: Option<Manifest>,
    staged: Vec<String>,
    committed: bool,
    /// Held for the whole life of the output: one run per folder.
    _lock: FolderLock,
}

impl OutputDir {
    /// Opens `dir` for a new run's output, creating it. Refuses (before any work is done) when
    /// it holds files that neither its manifest nor hushfuse's own naming accounts for: they
    /// would otherwise sit beside the new results with nothing to tell them apart.
    pub fn open(dir: &Path) -> Result<Self, String> {
        let lock = lock_folder(dir, LOCK)?;
        remove_stale_temporaries(dir);
        let mut old = read_manifest(dir)?;
        recover_staging(dir, &mut old)?;
        let listed: Vec<&str> = old
            .as_ref()
            .map(|m| m.files.iter().map(String::as_str).collect())
            .unwrap_or_default();
        let unknown: Vec<String> = list_files(dir)?
            .into_iter()
            .filter(|f| !is_own_file(f) && !listed.contains(&f.as_str()))
            .collect();
        if !unknown.is_empty() {
            let why = if old.is_some() {
                format!("its {MANIFEST} does not list")
            } else {
                format!("it has no {MANIFEST}, so they are not known to be an earlier run's")
            };
            let shown: Vec<&str> = unknown.iter().take(8).map(String::as_str).collect();
            return Err(format!(
                "output folder {} holds files that {why}: {}{}; remove them or choose another --out",
                dir.display(),
                shown.join(", "),
                if unknown.len() > shown.len() {
                    format!(" and {} more", unknown.len() - shown.len())
                } else {
                    String::new()
                }
            ));
        }
        Ok(Self::at(dir, old, lock))
    }

    /// Opens an existing run's folder to add files to it (`hushfuse report`): the files its
    /// manifest lists stay, and the new ones join the list.
    pub fn open_existing(dir: &Path) -> Result<Self, String> {
        let lock = lock_folder(dir, LOCK)?;
        let mut old = read_manifest(dir)?;
        recover_staging(dir, &mut old)?;
        Ok(Self::at(dir, old, lock))
    }

    fn at(dir: &Path, old: Option<Manifest>, lock: FolderLock) -> Self {
        Self {
            dir: dir.to_path_buf(),
            staging: dir.join(STAGING),
            old,
            staged: Vec::new(),
            committed: false,
            _lock: lock,
        }
    }

    /// The output folder.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The folder where writers that take a folder (plots) put their files; name them with
    /// [`OutputDir::record`].
    pub fn staging(&mut self) -> Result<&Path, String> {
        let owner = self.staging.join(STAGING_OWNER);
        if !owner.is_file() {
            std::fs::create_dir_all(&self.staging)
                .map_err(|e| format!("cannot create {}: {e}", self.staging.display()))?;
            // First into the folder: what follows is hushfuse's (see `recover_staging`).
            write_file(&owner, std::process::id().to_string().as_bytes())?;
        }
        Ok(&self.staging)
    }

    /// Stages file `name` (relative, `/`-separated; subfolders allowed).
    pub fn stage(&mut self, name: &str, bytes: &[u8]) -> Result<(), String> {
        self.stage_with(name, |w| w.write_all(bytes))
    }

    /// Stages file `name` streamed by `produce` (see [`write_file_with`]): for outputs too
    /// large to hold whole in memory beside the results they are made from.
    pub fn stage_with<F>(&mut self, name: &str, produce: F) -> Result<(), String>
    where
        F: FnMut(&mut dyn Write) -> std::io::Result<()>,
    {
        let path = self.staging()?.join(name);
        write_file_with(&path, produce).map_err(|e| {
            e.replace(
                &self.staging.display().to_string(),
                &self.dir.display().to_string(),
            )
        })?;
        self.record([name.to_string()]);
        Ok(())
    }

    /// Names files that were written into [`OutputDir::staging`] by someone else.
    pub fn record(&mut self, names: impl IntoIterator<Item = String>) {
        for n in names {
            if !self.staged.contains(&n) {
                self.staged.push(n);
            }
        }
    }

    /// Moves every staged file into place, removes the files of the earlier run (as listed
    /// by its manifest) that this run did not write, and writes the manifest. With `keep_old`,
    /// the earlier run's files stay and are listed too. Returns the files written.
    pub fn commit(mut self, mut manifest: Manifest, keep_old: bool) -> Result<Vec<String>, String> {
        let old_files = self.old.take().map(|m| m.files).unwrap_or_default();
        let stale: Vec<String> = old_files
            .iter()
            .filter(|f| !self.staged.contains(f))
            .cloned()
            .collect();
        let mut files = if keep_old { stale.clone() } else { Vec::new() };
        files.extend(self.staged.iter().cloned());
        manifest.files = files;
        // The manifest is staged too: from here on nothing is written, only renamed, so a full
        // disk cannot strike between the files moving in and the manifest that lists them.
        let json = serde_json::to_string_pretty(&manifest).map_err(|e| e.to_string())?;
        write_file(&self.staging()?.join(MANIFEST), json.as_bytes())?;
        for name in &self.staged {
            move_in(&self.dir, &self.staging, name)?;
        }
        if !keep_old {
            remove_stale(&self.dir, &stale)?;
        }
        std::fs::rename(self.staging.join(MANIFEST), self.dir.join(MANIFEST))
            .map_err(|e| format!("cannot move {} into place: {e}", MANIFEST))?;
        let _ = std::fs::remove_dir_all(&self.staging);
        sync_dir(&self.dir);
        self.committed = true;
        Ok(std::mem::take(&mut self.staged))
    }
}

#[cfg(test)]
impl OutputDir {
    /// As a process killed now: the staging folder stays, the lock goes with the process.
    fn abandon(mut self) {
        self.committed = true;
    }
}

impl Drop for OutputDir {
    fn drop(&mut self) {
        // Only a staging folder of this output's own making (see `recover_staging`).
        if !self.committed && self.staging.join(STAGING_OWNER).is_file() {
            let _ = std::fs::remove_dir_all(&self.staging);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_rerun_removes_the_stale_files_its_manifest_lists_and_refuses_unknown_ones() {
        let dir = tempfile::tempdir().unwrap();
        let m = Manifest::new("run", "s", "h");
        let mut out = OutputDir::open(dir.path()).unwrap();
        out.stage("a.txt", b"1").unwrap();
        out.stage("sub/b.txt", b"2").unwrap();
        out.commit(m.clone(), false).unwrap();
        assert_eq!(std::fs::read(dir.path().join("sub/b.txt")).unwrap(), b"2");
        let mut out = OutputDir::open(dir.path()).unwrap();
        out.stage("a.txt", b"3").unwrap();
        let files = out.commit(m.clone(), false).unwrap();
        assert_eq!(files, vec!["a.txt".to_string()]);
        assert!(
            !dir.path().join("sub").exists(),
            "stale file and its folder removed"
        );
        assert_eq!(read_manifest(dir.path()).unwrap().unwrap().files, files);
        std::fs::write(dir.path().join("notes.txt"), "mine").unwrap();
        let e = OutputDir::open(dir.path()).err().unwrap();
        assert!(
            e.contains("notes.txt") && e.contains("does not list"),
            "{e}"
        );
        std::fs::remove_file(dir.path().join(MANIFEST)).unwrap();
        let e = OutputDir::open(dir.path()).err().unwrap();
        assert!(
            e.contains("a.txt") && e.contains("no hushfuse-manifest.json"),
            "{e}"
        );
    }

    #[test]
    fn temporaries_of_dead_writers_are_removed_and_live_ones_kept() {
        let dir = tempfile::tempdir().unwrap();
        let dead = dir.path().join(".summary.json.tmp-999999999");
        let live = dir
            .path()
            .join(format!(".summary.json.tmp-{}", std::process::id()));
        std::fs::write(&dead, "half").unwrap();
        std::fs::write(&live, "writing").unwrap();
        remove_stale_temporaries(dir.path());
        assert!(!dead.exists() || !Path::new("/proc/self").exists());
        assert!(live.exists());
    }

    /// A producer writing `0..n` as text in many small pieces, as serde_json does.
    fn numbers(n: usize) -> impl FnMut(&mut dyn Write) -> std::io::Result<()> {
        move |w| (0..n).try_for_each(|i| write!(w, "{i},"))
    }

    #[test]
    fn a_streamed_file_is_written_whole_and_a_failed_one_leaves_the_old_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("sub/a.csv");
        write_file_with(&path, numbers(100_000)).unwrap();
        let mut expected = Vec::new();
        numbers(100_000)(&mut expected).unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), expected);
        let failing = |w: &mut dyn Write| {
            w.write_all(&[b'x'; 200_000])?;
            Err(std::io::Error::other("the producer failed"))
        };
        let e = write_file_with(&path, failing).unwrap_err();
        assert!(e.contains("the producer failed"), "{e}");
        assert_eq!(std::fs::read(&path).unwrap(), expected, "old file kept");
        let left: Vec<_> = std::fs::read_dir(dir.path().join("sub")).unwrap().collect();
        assert_eq!(left.len(), 1, "no temporary left");
    }

    #[test]
    fn the_test_hook_lets_half_a_streamed_file_reach_the_disk_then_fails_as_a_full_disk() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("half.csv");
        let mut whole = Vec::new();
        numbers(50_000)(&mut whole).unwrap();
        let e =
            write_half_then_fail(File::create(&path).unwrap(), &mut numbers(50_000)).unwrap_err();
        assert_eq!(e.kind(), std::io::ErrorKind::StorageFull);
        assert!(e.to_string().contains("no space left on device"), "{e}");
        assert_eq!(std::fs::read(&path).unwrap(), whole[..whole.len() / 2]);
        // An empty file fails too: the hook always fails.
        let e = write_half_then_fail(
            File::create(&path).unwrap(),
            &mut |_: &mut dyn Write| Ok(()),
        )
        .unwrap_err();
        assert_eq!(e.kind(), std::io::ErrorKind::StorageFull);
    }

    #[test]
    fn an_uncommitted_output_leaves_the_folder_as_it_was() {
        let dir = tempfile::tempdir().unwrap();
        let mut out = OutputDir::open(dir.path()).unwrap();
        out.stage("a.txt", b"1").unwrap();
        drop(out);
        // Only the (released) lock file stays.
        assert_eq!(list_files(dir.path()).unwrap(), vec![LOCK.to_string()]);
    }

    #[test]
    fn a_manifest_naming_files_outside_its_folder_is_refused_and_nothing_is_removed() {
        let root = tempfile::tempdir().unwrap();
        let dir = root.path().join("o");
        std::fs::write(root.path().join("victim.txt"), "keep").unwrap();
        let victim = root.path().join("victim.txt").display().to_string();
        for bad in [
            "../victim.txt",
            victim.as_str(),
            "a/../../victim.txt",
            "./a",
            "",
            "a//b",
            ".hushfuse-staging/x",
            "hushfuse-manifest.json",
        ] {
            std::fs::create_dir_all(&dir).unwrap();
            let mut m = Manifest::new("run", "s", "h");
            m.files = vec![bad.to_string()];
            std::fs::write(dir.join(MANIFEST), serde_json::to_string(&m).unwrap()).unwrap();
            let e = OutputDir::open(&dir).err().expect(bad);
            assert!(
                e.contains("hushfuse-manifest.json") && e.contains("lists"),
                "{bad}: {e}"
            );
            assert_eq!(
                std::fs::read_to_string(root.path().join("victim.txt")).unwrap(),
                "keep"
            );
        }
    }

    #[test]
    fn a_folder_reached_through_a_symbolic_link_is_neither_written_nor_cleaned() {
        let root = tempfile::tempdir().unwrap();
        let dir = root.path().join("o");
        let outside = root.path().join("outside");
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::create_dir_all(&outside).unwrap();
        std::fs::write(outside.join("x.txt"), "keep").unwrap();
        std::os::unix::fs::symlink(&outside, dir.join("sub")).unwrap();
        let mut m = Manifest::new("run", "s", "h");
        m.files = vec!["sub/x.txt".into(), "sub".into()];
        std::fs::write(dir.join(MANIFEST), serde_json::to_string(&m).unwrap()).unwrap();
        let out = OutputDir::open(&dir).unwrap();
        let e = out
            .commit(Manifest::new("run", "s", "h"), false)
            .unwrap_err();
        assert!(e.contains("symbolic link"), "{e}");
        assert_eq!(
            std::fs::read_to_string(outside.join("x.txt")).unwrap(),
            "keep"
        );
    }

    #[test]
    fn a_staging_folder_hushfuse_did_not_make_is_refused_and_kept() {
        let dir = tempfile::tempdir().unwrap();
        let staging = dir.path().join(STAGING);
        std::fs::create_dir_all(&staging).unwrap();
        std::fs::write(staging.join("user.txt"), "mine").unwrap();
        let e = OutputDir::open(dir.path()).err().unwrap();
        assert!(e.contains("user.txt") && e.contains("did not stage"), "{e}");
        assert_eq!(
            std::fs::read_to_string(staging.join("user.txt")).unwrap(),
            "mine"
        );
        // An empty one is removed, as is hushfuse's own from a run that died while staging.
        std::fs::remove_file(staging.join("user.txt")).unwrap();
        drop(OutputDir::open(dir.path()).unwrap());
        assert!(!staging.exists());
        let mut out = OutputDir::open(dir.path()).unwrap();
        out.stage("half.txt", b"1").unwrap();
        out.abandon(); // killed: no clean-up, no commit
        drop(OutputDir::open(dir.path()).unwrap());
        assert!(!staging.exists());
    }

    #[test]
    fn a_commit_killed_between_the_moves_and_the_manifest_is_finished_by_the_next_open() {
        let dir = tempfile::tempdir().unwrap();
        // An earlier run wrote old.txt and a.txt.
        let mut out = OutputDir::open(dir.path()).unwrap();
        out.stage("old.txt", b"old").unwrap();
        out.stage("a.txt", b"old a").unwrap();
        out.commit(Manifest::new("run", "s", "h1"), false).unwrap();
        // The next one staged a.txt and b/c.txt and its manifest, moved a.txt, then died.
        let mut out = OutputDir::open(dir.path()).unwrap();
        out.stage("a.txt", b"new a").unwrap();
        out.stage("b/c.txt", b"new c").unwrap();
        let mut m = Manifest::new("run", "s", "h2");
        m.files = vec!["a.txt".into(), "b/c.txt".into()];
        let staging = dir.path().join(STAGING);
        write_file(
            &staging.join(MANIFEST),
            serde_json::to_string(&m).unwrap().as_bytes(),
        )
        .unwrap();
        std::fs::rename(staging.join("a.txt"), dir.path().join("a.txt")).unwrap();
        out.abandon();
        let out = OutputDir::open(dir.path()).unwrap();
        assert_eq!(std::fs::read(dir.path().join("a.txt")).unwrap(), b"new a");
        assert_eq!(std::fs::read(dir.path().join("b/c.txt")).unwrap(), b"new c");
        assert!(
            !dir.path().join("old.txt").exists(),
            "the earlier run's stale file"
        );
        assert_eq!(read_manifest(dir.path()).unwrap().unwrap(), m);
        assert!(!staging.exists());
        drop(out);
    }

    #[test]
    fn one_output_per_folder_at_a_time() {
        let dir = tempfile::tempdir().unwrap();
        let first = OutputDir::open(dir.path()).unwrap();
        let e = OutputDir::open(dir.path()).err().unwrap();
        assert!(
            e.contains("being written by another hushfuse run")
                && e.contains(&std::process::id().to_string()),
            "{e}"
        );
        assert!(OutputDir::open_existing(dir.path()).is_err());
        drop(first);
        drop(OutputDir::open(dir.path()).unwrap());
        // A released lock names no process: finished folders of one experiment are identical.
        assert_eq!(std::fs::read(dir.path().join(LOCK)).unwrap(), b"");
    }

    #[test]
    fn a_folder_without_room_for_the_output_is_refused_naming_both_sizes() {
        let dir = tempfile::tempdir().unwrap();
        assert!(check_free_space(dir.path(), 1.0).is_ok());
        let e = check_free_space(dir.path(), 1e30).unwrap_err();
        assert!(
            e.contains(&dir.path().display().to_string()) && e.contains("MiB free"),
            "{e}"
        );
        assert!(check_free_space(dir.path(), f64::NAN).is_err());
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig {
            cases: 128,
            // A fixed seed: the same cases on every run and machine (CI included).
            rng_seed: proptest::test_runner::RngSeed::Fixed(0x5eed0002),
            ..proptest::prelude::ProptestConfig::default()
        })]
        /// Whatever a manifest lists, a run into its folder touches nothing outside it: entries
        /// that are not normalized names inside the folder are refused before anything moves.
        #[test]
        fn no_manifest_makes_a_run_touch_files_outside_its_folder(
            entries in proptest::collection::vec(
                proptest::collection::vec(
                    proptest::sample::select(vec![
                        "..", ".", "", "a", "b", "victim.txt", "o", ".hushfuse-staging",
                        "hushfuse-manifest.json", ".hushfuse-lock", "c:", "d\\e",
                        "../victim.txt", "../o/../victim.txt", "b/a",
                    ]),
                    1..4,
                ),
                0..4,
            ),
            absolute in proptest::bool::ANY,
        ) {
            let root = tempfile::tempdir().unwrap();
            let dir = root.path().join("o");
            std::fs::create_dir_all(dir.join("b")).unwrap();
            std::fs::write(root.path().join("victim.txt"), "keep").unwrap();
            std::fs::write(dir.join("b/a"), "old").unwrap();
            // The folder's one file is listed, so a folder is refused only for its entries.
            let mut files: Vec<String> = entries.iter().map(|parts| parts.join("/")).collect();
            files.push("b/a".to_string());
            if absolute {
                files.push(root.path().join("victim.txt").display().to_string());
            }
            let mut m = Manifest::new("run", "s", "h");
            m.files = files.clone();
            std::fs::write(dir.join(MANIFEST), serde_json::to_string(&m).unwrap()).unwrap();
            let valid = files.iter().all(|f| check_entry(f).is_ok());
            match OutputDir::open(&dir) {
                Ok(mut out) => {
                    proptest::prop_assert!(valid, "{files:?} was accepted");
                    out.stage("a", b"new").unwrap();
                    // A listed name that is a folder, or an unlisted file, may refuse the
                    // commit; neither may touch anything outside.
                    let _ = out.commit(Manifest::new("run", "s", "h2"), false);
                }
                // A bad entry is refused by name; a valid manifest may still be refused for
                // another reason (a listed name that is a folder), never for its entries.
                Err(e) => proptest::prop_assert_eq!(!valid, e.contains(" lists "), "{}", e),
            }
            proptest::prop_assert_eq!(
                std::fs::read_to_string(root.path().join("victim.txt")).unwrap(),
                "keep"
            );
            let outside: Vec<_> = std::fs::read_dir(root.path())
                .unwrap()
                .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                .collect();
            proptest::prop_assert_eq!(outside.len(), 2, "{:?}", outside);
        }
    }
}
