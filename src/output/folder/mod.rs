//! Durable output. Every file is written to a temporary name, flushed to disk and renamed into
//! place, so a reader never sees a half-written file. A run's output folder is staged whole
//! (every file written and flushed in a staging folder inside it) before anything is moved into
//! place, so a failed write (a full disk) leaves the earlier run's complete output untouched.
//! The folder carries a manifest of what the run wrote; files of an earlier run that the new
//! one does not write are removed when the old manifest lists them, and a folder holding files
//! that no manifest lists is refused before any work is done.
//!
//! Writing one file atomically is in `atomic.rs`; this file holds the folder: its manifest,
//! lock, staging and commit.
mod atomic;
#[cfg(test)]
mod tests;

pub use atomic::*;
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
/// The key `hushfuse live` makes for its own run in its folder; its frame counters and
/// accepted counters sit beside it as `live.key.*` (`hushfuse::live::secure::LiveKeys`).
pub const LIVE_KEY: &str = "live.key";

/// Hex of a SHA-256 digest.
pub fn sha256_hex(bytes: &[u8]) -> String {
    use sha2::Digest;
    sha2::Sha256::digest(bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
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
        || (rel == LIVE_KEY || rel.starts_with(&format!("{LIVE_KEY}.")))
        || (name.starts_with("hushfuse-checkpoint") && name.ends_with(".bin"))
        || name.ends_with(".hfshard")
        || (name.starts_with('.') && name.contains(".tmp-"))
}

/// Every file under `dir`, relative to it with `/` separators, sorted.
fn list_files(dir: &Path) -> Result<Vec<String>, String> {
    fn walk(root: &Path, dir: &Path, out: &mut Vec<String>) -> Result<(), String> {
        // A folder that cannot be read holds files no manifest lists (`--out /`: /proc).
        let unreadable = |e: std::io::Error| {
            format!(
                "output folder {} holds other files ({} cannot be read: {e}); choose another --out",
                root.display(),
                dir.display()
            )
        };
        let entries = std::fs::read_dir(dir).map_err(unreadable)?;
        for entry in entries {
            let entry = entry.map_err(unreadable)?;
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
        // A listed name that is a folder (hand-made, or left by something else) would make the
        // run fail at its very end, after its files moved in beside the old manifest: refused
        // here, before anything runs or moves.
        let is_folder = std::fs::symlink_metadata(dir.join(f)).is_ok_and(|m| m.is_dir());
        let checked = check_entry(f).and_then(|()| match is_folder {
            true => Err("is a folder".to_string()),
            false => Ok(()),
        });
        checked.map_err(|why| {
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
