//! The one rule of everything that writes a folder or a file for phi (each command of the
//! `phi` tool, and the library functions behind them): its target is new or empty, or holds what
//! the same writer wrote before, which only `force` replaces; anything else is refused, naming
//! the path and the file in the way.
//!
//! A writer describes what it writes once: [`Outputs`] for a folder (its file names, folders and
//! the [`Marker`] by which its output is recognised), [`OutputFile`] for a single file
//! (recognised by its first bytes). [`OutputDir::claim`] applies the rule to a folder and
//! returns the [`OutputDir`], which knows the previous output it found: it removes only the
//! files its writer writes ([`OutputDir::clear_previous`], marker last, so a run killed
//! meanwhile still leaves a folder recognised as the writer's), removes the temporary files a
//! killed run left ([`OutputDir::remove_stale_temp_files`]) and writes JSON atomically
//! ([`OutputDir::write_json`]). A writer that resumes its own unfinished output (`phi eval`)
//! opens the folder with [`OutputDir::inspect`] and decides itself when `force` is needed
//! ([`OutputDir::require_force`]).
//!
//! ```
//! use phi_io::output_dir::{Marker, OutputDir, OutputSubdir, Outputs};
//!
//! const OUTPUTS: Outputs = Outputs {
//!     command: "phi example",
//!     flag: "--out",
//!     files: &["run.json", "data.csv"],
//!     subdirs: &[OutputSubdir { name: "frames", prefix: "frame_", suffix: ".png" }],
//!     marker: Some(Marker::json("run.json", "made_by", "phi example")),
//! };
//!
//! let out = std::env::temp_dir().join(format!("phi-io-doc-output-dir-{}", std::process::id()));
//! # let _ = std::fs::remove_dir_all(&out);
//! // A new folder: claimed, created, the marker written first.
//! let dir = OutputDir::claim(&out, &OUTPUTS, false)?;
//! dir.create()?;
//! dir.write_json("run.json", &serde_json::json!({ "made_by": "phi example" }))?;
//! std::fs::write(out.join("notes.txt"), "mine")?;
//! // A file the writer does not write: refused, even with force.
//! let refused = OutputDir::claim(&out, &OUTPUTS, true).unwrap_err();
//! assert!(refused.to_string().contains("'notes.txt'"));
//! std::fs::remove_file(out.join("notes.txt"))?;
//! // Its own previous output: refused without force, replaced with it.
//! assert!(OutputDir::claim(&out, &OUTPUTS, false).is_err());
//! let mut dir = OutputDir::claim(&out, &OUTPUTS, true)?;
//! dir.clear_previous()?;
//! assert_eq!(std::fs::read_dir(&out)?.count(), 0);
//! # std::fs::remove_dir_all(&out)?;
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use std::path::{Path, PathBuf};

use crate::IoError;
use crate::atomic::{remove_stale_temp_files, temp_file_pid, write_atomic, write_json};

/// A folder a writer puts inside its target folder, and the files it puts there: names starting
/// with `prefix` and ending with `suffix`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OutputSubdir {
    /// The folder's name; `*` stands for any name (a dataset's split folders).
    pub name: &'static str,
    /// How the name of each file in it starts.
    pub prefix: &'static str,
    /// How the name of each file in it ends.
    pub suffix: &'static str,
}

/// The file by which a folder is recognised as a writer's output: the writer writes it first,
/// and every one it writes holds `key` (a dotted JSON path) with `value`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Marker {
    /// The file's name.
    pub file: &'static str,
    /// The JSON key and the string it holds; `None`: the file's presence is enough.
    pub key: Option<(&'static str, &'static str)>,
}

impl Marker {
    /// A marker recognised by its presence.
    pub const fn file(file: &'static str) -> Self {
        Self { file, key: None }
    }

    /// A JSON marker whose dotted `key` holds the string `value`.
    pub const fn json(file: &'static str, key: &'static str, value: &'static str) -> Self {
        Self {
            file,
            key: Some((key, value)),
        }
    }

    /// Why the marker in `out` is not the writer's, `None` when it is.
    fn mismatch(&self, out: &Path) -> Option<String> {
        let path = out.join(self.file);
        if !path.is_file() {
            return Some(format!("no {}", self.file));
        }
        let (key, value) = self.key?;
        let json: Option<serde_json::Value> = std::fs::read(&path)
            .ok()
            .and_then(|bytes| serde_json::from_slice(&bytes).ok());
        let Some(json) = json else {
            return Some(format!("a {} that is not JSON", self.file));
        };
        let found = key
            .split('.')
            .try_fold(&json, |v, k| v.get(k))
            .and_then(|v| v.as_str());
        match found {
            Some(found) if found == value => None,
            Some(found) => Some(format!("a {} whose {key} is '{found}'", self.file)),
            None => Some(format!("a {} without {key}", self.file)),
        }
    }
}

/// What a writer puts into its target folder.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Outputs {
    /// The writer as users call it (`phi optimize`), for messages.
    pub command: &'static str,
    /// How users name the target (`--out`), for messages.
    pub flag: &'static str,
    /// The files it writes in the target; a `*` in a name stands for any text (`*.npz`).
    pub files: &'static [&'static str],
    /// The folders it writes in the target.
    pub subdirs: &'static [OutputSubdir],
    /// The file it writes first, where one exists: a target holding the writer's other files
    /// without it was not written by the writer (another tool's files of the same names).
    pub marker: Option<Marker>,
}

impl Outputs {
    /// Whether `name` (a file directly in the target) is one the writer writes.
    pub(crate) fn writes_file(&self, name: &str) -> bool {
        self.files.iter().any(|f| matches(f, name))
    }
}

/// Why a target is refused, or what failed while clearing or writing it.
#[derive(Debug, thiserror::Error)]
pub enum OutputDirError {
    /// The target exists and is not a folder.
    #[error(
        "{flag} {path}: exists and is not a directory{writes}",
        path = path.display(),
        writes = command.map_or(String::new(), |c| format!("; `{c}` writes a directory"))
    )]
    NotADirectory {
        /// How users name the target.
        flag: &'static str,
        /// The target.
        path: PathBuf,
        /// The writer, where known.
        command: Option<&'static str>,
    },
    /// The target holds a file or folder the writer does not write (`name`, its path inside
    /// the target); refused whether or not `force`.
    #[error(
        "{flag} {path}: holds '{name}'{what}, which `{command}` does not write; refusing to \
         write into it{even}: choose a new or empty {flag}",
        path = path.display(),
        what = if name == "metadata.json" { " (a dataset)" } else { "" },
        even = if *force { " even with --force" } else { "" }
    )]
    Foreign {
        /// How users name the target.
        flag: &'static str,
        /// The target.
        path: PathBuf,
        /// The entry in the way.
        name: String,
        /// The writer.
        command: &'static str,
        /// Whether `force` was asked for.
        force: bool,
    },
    /// The target holds the writer's file names but not its marker: another tool's files.
    #[error(
        "{flag} {path}: holds '{first}' but {mismatch} (`{command}` writes {marker} first): not \
         its output; refusing to write into it{even}: choose a new or empty {flag}",
        path = path.display(),
        even = if *force { " even with --force" } else { "" }
    )]
    NotItsOutput {
        /// How users name the target.
        flag: &'static str,
        /// The target.
        path: PathBuf,
        /// The target's first entry.
        first: String,
        /// What is wrong with the marker.
        mismatch: String,
        /// The writer.
        command: &'static str,
        /// The marker's file name.
        marker: &'static str,
        /// Whether `force` was asked for.
        force: bool,
    },
    /// The target holds the writer's previous output and `force` is off.
    #[error(
        "{flag} {path}: is not empty ({count} entries: {shown}{more}); it holds a previous \
         `{command}` output: pass --force to replace it, or choose a new or empty {flag}",
        path = path.display(),
        count = names.len(),
        shown = names.iter().take(3).cloned().collect::<Vec<_>>().join(", "),
        more = if names.len() > 3 { ", ..." } else { "" }
    )]
    NeedsForce {
        /// How users name the target.
        flag: &'static str,
        /// The target.
        path: PathBuf,
        /// Every entry of the target, sorted.
        names: Vec<String>,
        /// The writer.
        command: &'static str,
    },
    /// A single-file target is a folder.
    #[error("{flag} {path}: is a directory; name the file to write ({kind})", path = path.display())]
    FileIsADirectory {
        /// How users name the target.
        flag: &'static str,
        /// The target.
        path: PathBuf,
        /// What the writer writes (`a GIF`).
        kind: &'static str,
    },
    /// A single-file target holds a file of another kind; refused whether or not `force`.
    #[error(
        "{flag} {path}: exists and is not {kind}, which `{command}` writes; refusing to \
         overwrite it{even}: choose another {flag}",
        path = path.display(),
        even = if *force { " even with --force" } else { "" }
    )]
    OtherKind {
        /// How users name the target.
        flag: &'static str,
        /// The target.
        path: PathBuf,
        /// What the writer writes.
        kind: &'static str,
        /// The writer.
        command: &'static str,
        /// Whether `force` was asked for.
        force: bool,
    },
    /// A single-file target holds the writer's earlier file and `force` is off.
    #[error(
        "{flag} {path}: exists ({kind}); pass --force to replace it, or choose another {flag}",
        path = path.display()
    )]
    FileExists {
        /// How users name the target.
        flag: &'static str,
        /// The target.
        path: PathBuf,
        /// What the writer writes.
        kind: &'static str,
    },
    /// A file the writer does not declare in its [`Outputs`] was to be written into the target.
    #[error("'{path}': `{command}` does not declare this file among its outputs", path = path.display())]
    Undeclared {
        /// The file.
        path: PathBuf,
        /// The writer.
        command: &'static str,
    },
    /// Reading, removing or writing a file failed (the error names it).
    #[error(transparent)]
    File(#[from] IoError),
}

/// A target folder claimed by a writer: the rule applied, with the previous output it holds
/// (nothing, for a new or empty folder) until [`OutputDir::clear_previous`] removes it.
#[derive(Debug)]
#[must_use = "a previous output is replaced only once cleared"]
pub struct OutputDir {
    path: PathBuf,
    outputs: Outputs,
    /// Every entry of the folder, sorted, for messages.
    names: Vec<String>,
    files: Vec<PathBuf>,
    subdirs: Vec<PathBuf>,
}

impl OutputDir {
    /// Applies the rule to the target folder `path` of `outputs.command`: a missing or empty
    /// folder is fine; one holding only the writer's outputs is its previous output, refused
    /// without `force` and returned with it (remove it with [`OutputDir::clear_previous`]
    /// before writing); anything else is refused, `force` or not.
    ///
    /// # Errors
    /// `path` is a file; holds a file or folder the writer does not write (named with its path
    /// inside `path`); holds a previous output and `force` is off; cannot be listed.
    pub fn claim(path: &Path, outputs: &Outputs, force: bool) -> Result<Self, OutputDirError> {
        Self::inspect(path, outputs, force)?.require_force(force)
    }

    /// What of `outputs.command`'s previous output `path` holds, refusing a folder that holds
    /// anything else; unlike [`OutputDir::claim`], a previous output is returned whether or not
    /// `force` (which only words the refusals).
    ///
    /// # Errors
    /// `path` is a file; holds a file or folder the writer does not write, or the writer's
    /// file names without its marker; cannot be listed.
    pub fn inspect(path: &Path, outputs: &Outputs, force: bool) -> Result<Self, OutputDirError> {
        let Outputs {
            command,
            flag,
            subdirs,
            marker,
            ..
        } = *outputs;
        let mut dir = OutputDir {
            path: path.to_path_buf(),
            outputs: *outputs,
            names: Vec::new(),
            files: Vec::new(),
            subdirs: Vec::new(),
        };
        if !path.exists() {
            return Ok(dir);
        }
        if !path.is_dir() {
            return Err(OutputDirError::NotADirectory {
                flag,
                path: path.to_path_buf(),
                command: Some(command),
            });
        }
        let names = list(path)?;
        let mut foreign = None;
        for name in &names {
            if outputs.writes_file(written_name(name)) {
                dir.files.push(path.join(name));
                continue;
            }
            let Some(subdir) = subdirs.iter().find(|d| matches(d.name, name)) else {
                foreign.get_or_insert_with(|| name.clone());
                continue;
            };
            let folder = path.join(name);
            if !folder.is_dir() {
                foreign.get_or_insert_with(|| name.clone());
                continue;
            }
            let ours = |n: &String| {
                let file = written_name(n);
                file.starts_with(subdir.prefix) && file.ends_with(subdir.suffix)
            };
            match list(&folder)?.iter().find(|n| !ours(n)) {
                Some(other) => {
                    foreign.get_or_insert_with(|| format!("{name}/{other}"));
                }
                None => dir.subdirs.push(folder),
            }
        }
        if let Some(name) = foreign {
            return Err(OutputDirError::Foreign {
                flag,
                path: path.to_path_buf(),
                name,
                command,
                force,
            });
        }
        if dir.holds_nothing() {
            return Ok(dir);
        }
        if let Some(marker) = marker
            && let Some(mismatch) = marker.mismatch(path)
        {
            return Err(OutputDirError::NotItsOutput {
                flag,
                path: path.to_path_buf(),
                first: names[0].clone(),
                mismatch,
                command,
                marker: marker.file,
                force,
            });
        }
        dir.names = names;
        Ok(dir)
    }

    /// The folder `path` taken as `outputs.command`'s own without applying the rule: for a
    /// writer that continues its own output by checks of its own (a dataset resumed against its
    /// manifest), to clean up and write through the same type. Holds no previous output.
    pub fn adopt(path: &Path, outputs: &Outputs) -> Self {
        OutputDir {
            path: path.to_path_buf(),
            outputs: *outputs,
            names: Vec::new(),
            files: Vec::new(),
            subdirs: Vec::new(),
        }
    }

    /// Refuses a `path` that exists and is not a folder, naming `flag`: the check of a target
    /// that a writer fills with folders of its own, each claimed separately (`phi rollout`).
    ///
    /// # Errors
    /// As above.
    pub fn check_not_a_file(path: &Path, flag: &'static str) -> Result<(), OutputDirError> {
        if path.exists() && !path.is_dir() {
            return Err(OutputDirError::NotADirectory {
                flag,
                path: path.to_path_buf(),
                command: None,
            });
        }
        Ok(())
    }

    /// The target folder.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// What the writer writes here.
    pub fn outputs(&self) -> &Outputs {
        &self.outputs
    }

    /// Whether the target held nothing of a previous output (or it has been cleared).
    pub fn holds_nothing(&self) -> bool {
        self.files.is_empty() && self.subdirs.is_empty()
    }

    /// The folder, refused unless `force` or it holds no previous output.
    ///
    /// # Errors
    /// [`OutputDirError::NeedsForce`] naming the folder, what it holds and `--force`.
    pub fn require_force(self, force: bool) -> Result<Self, OutputDirError> {
        if force || self.holds_nothing() {
            return Ok(self);
        }
        Err(OutputDirError::NeedsForce {
            flag: self.outputs.flag,
            path: self.path,
            names: self.names,
            command: self.outputs.command,
        })
    }

    /// The folder without the entry `name` in its previous output, which the writer keeps
    /// (`phi eval`'s cache, reused where it fits).
    pub fn keep(mut self, name: &str) -> Self {
        let kept = self.path.join(name);
        self.files.retain(|f| *f != kept && !is_temporary(f, name));
        self.subdirs.retain(|d| *d != kept);
        self
    }

    /// Removes the previous output, so that the files of two runs never mix: only the files
    /// and folders the writer writes were found, so only those go. The marker goes last, so
    /// that a run killed meanwhile leaves a folder still recognised as the writer's.
    ///
    /// # Errors
    /// A file or folder that cannot be removed, named.
    pub fn clear_previous(&mut self) -> Result<(), OutputDirError> {
        for dir in std::mem::take(&mut self.subdirs) {
            std::fs::remove_dir_all(&dir)
                .map_err(|e| IoError::io(&dir, "cannot remove the previous output", e))?;
        }
        let marker = self.outputs.marker.map(|m| self.path.join(m.file));
        let (last, first): (Vec<_>, Vec<_>) = std::mem::take(&mut self.files)
            .into_iter()
            .partition(|f| Some(f) == marker.as_ref());
        for file in first.into_iter().chain(last) {
            std::fs::remove_file(&file)
                .map_err(|e| IoError::io(&file, "cannot remove the previous output", e))?;
        }
        self.names.clear();
        Ok(())
    }

    /// Creates the folder (and its parents) where it is missing.
    ///
    /// # Errors
    /// [`IoError::Io`] naming the folder.
    pub fn create(&self) -> Result<(), OutputDirError> {
        std::fs::create_dir_all(&self.path)
            .map_err(|e| IoError::io(&self.path, "cannot create", e))?;
        Ok(())
    }

    /// Removes the temporary files of atomic writes ([`write_atomic`]) that killed runs left in
    /// the folder and in the writer's folders inside it (`*` folders: every folder present);
    /// returns them, sorted.
    ///
    /// # Errors
    /// [`IoError::Io`] when a folder cannot be listed or a file removed.
    pub fn remove_stale_temp_files(&self) -> Result<Vec<PathBuf>, OutputDirError> {
        let mut removed = remove_stale_temp_files(&self.path)?;
        let mut inner: Vec<PathBuf> = Vec::new();
        for subdir in self.outputs.subdirs {
            if subdir.name.contains('*') {
                if self.path.is_dir() {
                    for name in list(&self.path)? {
                        let path = self.path.join(&name);
                        if matches(subdir.name, &name) && path.is_dir() && !inner.contains(&path) {
                            inner.push(path);
                        }
                    }
                }
            } else {
                let path = self.path.join(subdir.name);
                if !inner.contains(&path) {
                    inner.push(path);
                }
            }
        }
        for dir in inner {
            removed.extend(remove_stale_temp_files(&dir)?);
        }
        Ok(removed)
    }

    /// Writes `value` as pretty-printed JSON with a final newline to the file `name` of the
    /// folder, atomically.
    ///
    /// # Errors
    /// [`OutputDirError::Undeclared`] for a name the writer's [`Outputs`] does not list; the
    /// errors of [`write_json`].
    pub fn write_json(
        &self,
        name: &str,
        value: &impl serde::Serialize,
    ) -> Result<(), OutputDirError> {
        let path = self.declared(name)?;
        write_json(&path, value)?;
        Ok(())
    }

    /// Writes `bytes` to the file `name` of the folder, atomically.
    ///
    /// # Errors
    /// [`OutputDirError::Undeclared`] for a name the writer's [`Outputs`] does not list;
    /// [`IoError::Io`] naming the file.
    pub fn write_bytes(&self, name: &str, bytes: &[u8]) -> Result<(), OutputDirError> {
        let path = self.declared(name)?;
        write_atomic::<IoError>(&path, |w| crate::write_all(w, bytes, &path))?;
        Ok(())
    }

    /// The path of the declared file `name`.
    fn declared(&self, name: &str) -> Result<PathBuf, OutputDirError> {
        let path = self.path.join(name);
        if !self.outputs.writes_file(name) {
            return Err(OutputDirError::Undeclared {
                path,
                command: self.outputs.command,
            });
        }
        Ok(path)
    }
}

/// A single file a writer writes, and how to recognise one.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OutputFile {
    /// The writer as users call it (`phi render`).
    pub command: &'static str,
    /// How users name the file (`--out`).
    pub flag: &'static str,
    /// What the writer writes, for messages (`a GIF`).
    pub kind: &'static str,
    /// The first bytes of every file the writer writes (alternatives).
    pub magic: &'static [&'static [u8]],
}

impl OutputFile {
    /// Applies the rule to the file `path`: a missing file is fine; a file of the writer's kind
    /// (by its first bytes) is replaced only with `force`; a folder or any other file is
    /// refused, `force` or not.
    ///
    /// # Errors
    /// As above, naming the path.
    pub fn check(&self, path: &Path, force: bool) -> Result<(), OutputDirError> {
        let OutputFile {
            command,
            flag,
            kind,
            magic,
        } = *self;
        if path.is_dir() {
            return Err(OutputDirError::FileIsADirectory {
                flag,
                path: path.to_path_buf(),
                kind,
            });
        }
        if !path.exists() {
            return Ok(());
        }
        let longest = magic.iter().map(|m| m.len()).max().unwrap_or(0);
        let mut head = Vec::with_capacity(longest);
        let file = std::fs::File::open(path).map_err(|e| IoError::io(path, "cannot read", e))?;
        std::io::Read::read_to_end(&mut std::io::Read::take(file, longest as u64), &mut head)
            .map_err(|e| IoError::io(path, "cannot read", e))?;
        if !magic.iter().any(|m| head.starts_with(m)) {
            return Err(OutputDirError::OtherKind {
                flag,
                path: path.to_path_buf(),
                kind,
                command,
                force,
            });
        }
        if !force {
            return Err(OutputDirError::FileExists {
                flag,
                path: path.to_path_buf(),
                kind,
            });
        }
        Ok(())
    }
}

/// Whether `path` is the temporary file of an atomic write of `name` in the same folder.
fn is_temporary(path: &Path, name: &str) -> bool {
    path.file_name()
        .and_then(|n| n.to_str())
        .is_some_and(|n| n != name && written_name(n) == name)
}

/// The name of the file that `name` is being written to: `file` for the temporary file of an
/// atomic write (`.{file}.tmp-{pid}`, which a killed run leaves behind), else `name`.
fn written_name(name: &str) -> &str {
    match temp_file_pid(name) {
        Some(_) => name
            .strip_prefix('.')
            .and_then(|rest| rest.rsplit_once(".tmp-"))
            .map_or(name, |(file, _)| file),
        None => name,
    }
}

/// Whether `name` matches `pattern`, in which one `*` stands for any non-empty text.
fn matches(pattern: &str, name: &str) -> bool {
    match pattern.split_once('*') {
        None => pattern == name,
        Some((head, tail)) => {
            name.len() > head.len() + tail.len() && name.starts_with(head) && name.ends_with(tail)
        }
    }
}

/// The sorted names in `dir`.
fn list(dir: &Path) -> Result<Vec<String>, IoError> {
    let mut names = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(|e| IoError::io(dir, "cannot list", e))? {
        let entry = entry.map_err(|e| IoError::io(dir, "cannot list", e))?;
        names.push(entry.file_name().to_string_lossy().into_owned());
    }
    names.sort();
    Ok(names)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_util::temp_dir;

    const OUTPUTS: Outputs = Outputs {
        command: "phi test",
        flag: "--out",
        files: &["record.json", "data.csv"],
        subdirs: &[OutputSubdir {
            name: "frames",
            prefix: "frame_",
            suffix: ".png",
        }],
        marker: Some(Marker::json("record.json", "made.by", "phi test")),
    };

    const RECORD: &str = r#"{"made": {"by": "phi test"}}"#;

    #[test]
    fn a_missing_or_empty_folder_is_fine() {
        let dir = temp_dir("target-empty");
        let new = OutputDir::claim(&dir.join("new"), &OUTPUTS, false).unwrap();
        assert!(new.holds_nothing());
        assert!(
            OutputDir::claim(&dir, &OUTPUTS, false)
                .unwrap()
                .holds_nothing()
        );
        let _ = std::fs::remove_dir_all(dir);
    }

    #[test]
    fn a_previous_output_is_replaced_only_with_force() {
        let dir = temp_dir("target-previous");
        std::fs::write(dir.join("record.json"), RECORD).unwrap();
        std::fs::write(dir.join(".data.csv.tmp-12"), "").unwrap();
        std::fs::create_dir(dir.join("frames")).unwrap();
        std::fs::write(dir.join("frames/frame_00001.png"), "").unwrap();
        std::fs::write(dir.join("frames/.frame_00002.png.tmp-7"), "").unwrap();
        let error = OutputDir::claim(&dir, &OUTPUTS, false)
            .unwrap_err()
            .to_string();
        assert!(
            error.contains("previous `phi test` output") && error.contains("--force"),
            "{error}"
        );
        let mut claimed = OutputDir::claim(&dir, &OUTPUTS, true).unwrap();
        claimed.clear_previous().unwrap();
        assert!(claimed.holds_nothing());
        assert!(list(&dir).unwrap().is_empty());
        let _ = std::fs::remove_dir_all(dir);
    }

    #[test]
    fn foreign_files_are_refused_even_with_force() {
        for (place, expected) in [
            ("notes.txt", "'notes.txt'"),
            ("frames/notes.txt", "'frames/notes.txt'"),
            ("metadata.json", "(a dataset)"),
        ] {
            let dir = temp_dir("target-foreign");
            std::fs::write(dir.join("record.json"), RECORD).unwrap();
            std::fs::create_dir(dir.join("frames")).unwrap();
            std::fs::write(dir.join(place), "mine").unwrap();
            for force in [false, true] {
                let error = OutputDir::claim(&dir, &OUTPUTS, force)
                    .unwrap_err()
                    .to_string();
                assert!(
                    error.contains(expected) && error.contains("does not write"),
                    "{error}"
                );
            }
            assert_eq!(std::fs::read(dir.join(place)).unwrap(), b"mine");
            let _ = std::fs::remove_dir_all(dir);
        }
    }

    #[test]
    fn our_file_names_without_our_marker_are_not_ours() {
        let dir = temp_dir("target-marker");
        std::fs::write(dir.join("data.csv"), "1,2").unwrap();
        let error = OutputDir::claim(&dir, &OUTPUTS, true)
            .unwrap_err()
            .to_string();
        assert!(error.contains("no record.json"), "{error}");
        for (record, expected) in [
            (r#"{"made": {"by": "phi other"}}"#, "made.by is 'phi other'"),
            (r#"{"made": 1}"#, "without made.by"),
            ("not json", "not JSON"),
        ] {
            std::fs::write(dir.join("record.json"), record).unwrap();
            let error = OutputDir::claim(&dir, &OUTPUTS, true)
                .unwrap_err()
                .to_string();
            assert!(
                error.contains(expected) && error.contains("even with --force"),
                "{error}"
            );
        }
        assert_eq!(std::fs::read(dir.join("data.csv")).unwrap(), b"1,2");
        let _ = std::fs::remove_dir_all(dir);
    }

    #[test]
    fn patterns_match_names_and_kept_entries_stay() {
        const PATTERNS: Outputs = Outputs {
            command: "phi test",
            flag: "--out",
            files: &["record.json", "*.npz"],
            subdirs: &[OutputSubdir {
                name: "*",
                prefix: "",
                suffix: ".json",
            }],
            marker: Some(Marker::file("record.json")),
        };
        assert!(matches("*.npz", "train.npz") && !matches("*.npz", ".npz"));
        assert!(!matches("*.npz", "train.npz.bak") && matches("a", "a") && !matches("a", "ab"));
        let dir = temp_dir("target-patterns");
        std::fs::write(dir.join("record.json"), "{}").unwrap();
        std::fs::write(dir.join("train.npz"), "").unwrap();
        std::fs::write(dir.join(".valid.npz.tmp-3"), "").unwrap();
        std::fs::create_dir_all(dir.join("cache")).unwrap();
        std::fs::write(dir.join("cache/b.json"), "").unwrap();
        let previous = OutputDir::inspect(&dir, &PATTERNS, false).unwrap();
        let error = previous.require_force(false).unwrap_err().to_string();
        assert!(error.contains("--force"), "{error}");
        let previous = OutputDir::inspect(&dir, &PATTERNS, false).unwrap();
        let mut kept = previous.keep("cache").keep("record.json");
        kept.clear_previous().unwrap();
        assert_eq!(list(&dir).unwrap(), ["cache", "record.json"]);
        let _ = std::fs::remove_dir_all(dir);
    }

    #[test]
    fn stale_temporary_files_go_and_json_is_written_only_under_declared_names() {
        let dir = temp_dir("target-stale");
        // A process id no live process has (above the kernel's pid_max).
        let stale = ".data.csv.tmp-4194305";
        std::fs::create_dir_all(dir.join("frames")).unwrap();
        std::fs::write(dir.join("record.json"), RECORD).unwrap();
        std::fs::write(dir.join(stale), "").unwrap();
        std::fs::write(dir.join("frames").join(".frame_1.png.tmp-4194305"), "").unwrap();
        let out = OutputDir::inspect(&dir, &OUTPUTS, false).unwrap();
        let removed = out.remove_stale_temp_files().unwrap();
        if Path::new("/proc/self").exists() {
            assert_eq!(removed.len(), 2, "{removed:?}");
            assert!(!dir.join(stale).exists());
        }
        out.write_json(
            "record.json",
            &serde_json::json!({"made": {"by": "phi test"}}),
        )
        .unwrap();
        let text = std::fs::read_to_string(dir.join("record.json")).unwrap();
        assert!(text.ends_with("}\n"), "{text}");
        let error = out.write_json("other.json", &1).unwrap_err().to_string();
        assert!(error.contains("other.json") && error.contains("does not declare"));
        assert!(!dir.join("other.json").exists());
        let _ = std::fs::remove_dir_all(dir);
    }

    #[test]
    fn a_file_of_another_kind_is_refused_and_ours_needs_force() {
        let output = OutputFile {
            command: "phi test",
            flag: "--out",
            kind: "a GIF",
            magic: &[b"GIF89a", b"GIF87a"],
        };
        let dir = temp_dir("target-file");
        let path = dir.join("a.gif");
        output.check(&path, false).unwrap();
        std::fs::write(&path, b"GIF89a...").unwrap();
        let error = output.check(&path, false).unwrap_err().to_string();
        assert!(error.contains("--force"), "{error}");
        output.check(&path, true).unwrap();
        std::fs::write(&path, b"GIF").unwrap();
        let error = output.check(&path, true).unwrap_err().to_string();
        assert!(error.contains("is not a GIF"), "{error}");
        let error = output.check(&dir, true).unwrap_err().to_string();
        assert!(error.contains("is a directory"), "{error}");
        let _ = std::fs::remove_dir_all(dir);
    }
}
