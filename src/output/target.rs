//! The one rule of every command that writes: its target is new or empty, or holds what this
//! command wrote, which only `--force` replaces; anything else is refused, naming the path and
//! the file in the way.
//!
//! A command describes what it writes once ([`Outputs`] for a folder, [`OutputFile`] for a
//! single file), and [`check_dir`] / [`check_file`] apply the rule. A folder is the command's
//! own when every entry in it is a name of [`Outputs`] and, where the command writes a
//! [`Marker`], the marker is there (and holds the command's key). A folder's previous output
//! is removed by [`Previous::remove`] only once the command has checked everything else, so a
//! refused run leaves the target as it was. A command that resumes its own unfinished output
//! (`phi eval`) asks [`previous_output`] what is there and decides itself when `--force` is
//! needed ([`Previous::require_force`]).

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};

/// A folder a command writes inside its target folder, and the files it puts there: names
/// starting with `prefix` and ending with `suffix`.
#[derive(Debug, Clone, Copy)]
pub struct OutputSubdir {
    /// The folder's name; `*` stands for any name (a dataset's split folders).
    pub name: &'static str,
    /// How the name of each file in it starts.
    pub prefix: &'static str,
    /// How the name of each file in it ends.
    pub suffix: &'static str,
}

/// The file by which a folder is recognised as a command's output: the command writes it
/// first, and every one it writes holds `key` (a dotted JSON path) with `value`.
#[derive(Debug, Clone, Copy)]
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

    /// Why the marker in `out` is not this command's, `None` when it is.
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

/// What a command writes into its target folder.
#[derive(Debug, Clone, Copy)]
pub struct Outputs {
    /// The command as users type it (`phi optimize`).
    pub command: &'static str,
    /// The option naming the target (`--out`).
    pub flag: &'static str,
    /// The files it writes in the target; a `*` in a name stands for any text (`*.npz`).
    pub files: &'static [&'static str],
    /// The folders it writes in the target.
    pub subdirs: &'static [OutputSubdir],
    /// The file it writes first, where one exists: a target holding the command's other files
    /// without it was not written by the command (another tool's files of the same names).
    pub marker: Option<Marker>,
}

/// The previous output found in a target folder, to be removed before writing anew.
#[derive(Debug)]
#[must_use = "a previous output is replaced only once removed"]
pub struct Previous {
    out: PathBuf,
    outputs: Outputs,
    /// Every entry of the folder, sorted, for messages.
    names: Vec<String>,
    files: Vec<PathBuf>,
    subdirs: Vec<PathBuf>,
}

impl Previous {
    fn none(out: &Path, outputs: &Outputs) -> Self {
        Self {
            out: out.to_path_buf(),
            outputs: *outputs,
            names: Vec::new(),
            files: Vec::new(),
            subdirs: Vec::new(),
        }
    }

    /// Whether the target held nothing of a previous output.
    pub fn is_empty(&self) -> bool {
        self.files.is_empty() && self.subdirs.is_empty()
    }

    /// The previous output, refused unless `force` or there is none.
    ///
    /// # Errors
    /// A previous output and no `force`: the message names the folder, what it holds and
    /// `--force`.
    pub fn require_force(self, force: bool) -> Result<Self> {
        if force || self.is_empty() {
            return Ok(self);
        }
        let Outputs { command, flag, .. } = self.outputs;
        let names = &self.names;
        let shown = names.iter().take(3).cloned().collect::<Vec<_>>().join(", ");
        bail!(
            "{flag} {}: is not empty ({} entries: {shown}{}); it holds a previous `{command}` \
             output: pass --force to replace it, or choose a new or empty {flag}",
            self.out.display(),
            names.len(),
            if names.len() > 3 { ", ..." } else { "" }
        );
    }

    /// The previous output without the entry `name`, which the command keeps (`phi eval`'s
    /// cache, reused where it fits).
    pub fn keep(mut self, name: &str) -> Self {
        let kept = self.out.join(name);
        self.files.retain(|f| *f != kept && !is_temporary(f, name));
        self.subdirs.retain(|d| *d != kept);
        self
    }

    /// Removes the previous output, so that the files of two runs never mix. The marker goes
    /// last, so that a run killed meanwhile leaves a folder still recognised as the command's.
    ///
    /// # Errors
    /// A file or folder that cannot be removed, named.
    pub fn remove(self) -> Result<()> {
        for dir in &self.subdirs {
            std::fs::remove_dir_all(dir)
                .with_context(|| format!("removing the previous output {}", dir.display()))?;
        }
        let marker = self.outputs.marker.map(|m| self.out.join(m.file));
        let (last, first): (Vec<_>, Vec<_>) =
            self.files.iter().partition(|f| Some(*f) == marker.as_ref());
        for file in first.into_iter().chain(last) {
            std::fs::remove_file(file)
                .with_context(|| format!("removing the previous output {}", file.display()))?;
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
    name.strip_prefix('.')
        .and_then(|rest| rest.rsplit_once(".tmp-"))
        .filter(|(_, pid)| !pid.is_empty() && pid.bytes().all(|b| b.is_ascii_digit()))
        .map_or(name, |(file, _)| file)
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
fn list(dir: &Path) -> Result<Vec<String>> {
    let mut names = Vec::new();
    for entry in std::fs::read_dir(dir).with_context(|| format!("reading {}", dir.display()))? {
        let entry = entry.with_context(|| format!("reading {}", dir.display()))?;
        names.push(entry.file_name().to_string_lossy().into_owned());
    }
    names.sort();
    Ok(names)
}

/// Refuses a `path` that exists and is not a directory, naming `flag`.
///
/// # Errors
/// As above.
pub fn check_not_a_file(path: &Path, flag: &str) -> Result<()> {
    if path.exists() && !path.is_dir() {
        bail!("{flag} {}: exists and is not a directory", path.display());
    }
    Ok(())
}

/// Applies the rule to the target folder `out` of `outputs.command`: a missing or empty folder
/// is fine; one holding only the command's outputs is its previous output, refused without
/// `force` and returned with it (remove it with [`Previous::remove`] before writing); anything
/// else is refused, `force` or not.
///
/// # Errors
/// `out` is a file; holds a file or folder the command does not write (named with its path
/// inside `out`); holds a previous output and `force` is off.
pub fn check_dir(out: &Path, outputs: &Outputs, force: bool) -> Result<Previous> {
    previous_output(out, outputs, force)?.require_force(force)
}

/// What of `outputs.command`'s previous output `out` holds, refusing a folder that holds
/// anything else; unlike [`check_dir`], a previous output is returned whether or not `force`
/// (which only words the refusals).
///
/// # Errors
/// `out` is a file; holds a file or folder the command does not write, or the command's file
/// names without its marker.
pub fn previous_output(out: &Path, outputs: &Outputs, force: bool) -> Result<Previous> {
    let Outputs {
        command,
        flag,
        files,
        subdirs,
        marker,
    } = *outputs;
    let mut previous = Previous::none(out, outputs);
    if !out.exists() {
        return Ok(previous);
    }
    if !out.is_dir() {
        bail!(
            "{flag} {}: exists and is not a directory; `{command}` writes a directory",
            out.display()
        );
    }
    let names = list(out)?;
    let mut foreign = None;
    for name in &names {
        if files.iter().any(|f| matches(f, written_name(name))) {
            previous.files.push(out.join(name));
            continue;
        }
        let Some(subdir) = subdirs.iter().find(|d| matches(d.name, name)) else {
            foreign.get_or_insert_with(|| name.clone());
            continue;
        };
        let dir = out.join(name);
        if !dir.is_dir() {
            foreign.get_or_insert_with(|| name.clone());
            continue;
        }
        let inside = list(&dir)?;
        let ours = |n: &String| {
            let file = written_name(n);
            file.starts_with(subdir.prefix) && file.ends_with(subdir.suffix)
        };
        match inside.iter().find(|n| !ours(n)) {
            Some(other) => {
                foreign.get_or_insert_with(|| format!("{name}/{other}"));
            }
            None => previous.subdirs.push(dir),
        }
    }
    let even = if force { " even with --force" } else { "" };
    if let Some(name) = foreign {
        let what = if name == "metadata.json" {
            " (a dataset)"
        } else {
            ""
        };
        bail!(
            "{flag} {}: holds '{name}'{what}, which `{command}` does not write; refusing to \
             write into it{even}: choose a new or empty {flag}",
            out.display(),
        );
    }
    if previous.is_empty() {
        return Ok(previous);
    }
    if let Some(marker) = marker
        && let Some(mismatch) = marker.mismatch(out)
    {
        bail!(
            "{flag} {}: holds '{}' but {mismatch} (`{command}` writes {} first): not its \
             output; refusing to write into it{even}: choose a new or empty {flag}",
            out.display(),
            names[0],
            marker.file
        );
    }
    previous.names = names;
    Ok(previous)
}

/// A single file a command writes, and how to recognise one.
#[derive(Debug, Clone, Copy)]
pub struct OutputFile {
    /// The command as users type it (`phi render`).
    pub command: &'static str,
    /// The option naming the file (`--out`).
    pub flag: &'static str,
    /// What the command writes, for messages (`a GIF`).
    pub kind: &'static str,
    /// The first bytes of every file the command writes (alternatives).
    pub magic: &'static [&'static [u8]],
}

/// Applies the rule to the file `out` of `output.command`: a missing file is fine; a file of
/// the command's kind (by its first bytes) is replaced only with `force`; a directory or any
/// other file is refused, `force` or not.
///
/// # Errors
/// As above, naming the path.
pub fn check_file(out: &Path, output: &OutputFile, force: bool) -> Result<()> {
    let OutputFile {
        command,
        flag,
        kind,
        magic,
    } = *output;
    if out.is_dir() {
        bail!(
            "{flag} {}: is a directory; name the file to write ({kind})",
            out.display()
        );
    }
    if !out.exists() {
        return Ok(());
    }
    let longest = magic.iter().map(|m| m.len()).max().unwrap_or(0);
    let mut head = Vec::with_capacity(longest);
    std::io::Read::read_to_end(
        &mut std::io::Read::take(
            std::fs::File::open(out).with_context(|| format!("reading {}", out.display()))?,
            longest as u64,
        ),
        &mut head,
    )
    .with_context(|| format!("reading {}", out.display()))?;
    if !magic.iter().any(|m| head.starts_with(m)) {
        bail!(
            "{flag} {}: exists and is not {kind}, which `{command}` writes; refusing to overwrite \
             it{}: choose another {flag}",
            out.display(),
            if force { " even with --force" } else { "" }
        );
    }
    if !force {
        bail!(
            "{flag} {}: exists ({kind}); pass --force to replace it, or choose another {flag}",
            out.display()
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::output::test_util::temp_dir;

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
        assert!(
            check_dir(&dir.join("new"), &OUTPUTS, false)
                .unwrap()
                .is_empty()
        );
        assert!(check_dir(&dir, &OUTPUTS, false).unwrap().is_empty());
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
        let error = check_dir(&dir, &OUTPUTS, false).unwrap_err().to_string();
        assert!(
            error.contains("previous `phi test` output") && error.contains("--force"),
            "{error}"
        );
        check_dir(&dir, &OUTPUTS, true).unwrap().remove().unwrap();
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
                let error = check_dir(&dir, &OUTPUTS, force).unwrap_err().to_string();
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
        let error = check_dir(&dir, &OUTPUTS, true).unwrap_err().to_string();
        assert!(error.contains("no record.json"), "{error}");
        for (record, expected) in [
            (r#"{"made": {"by": "phi other"}}"#, "made.by is 'phi other'"),
            (r#"{"made": 1}"#, "without made.by"),
            ("not json", "not JSON"),
        ] {
            std::fs::write(dir.join("record.json"), record).unwrap();
            let error = check_dir(&dir, &OUTPUTS, true).unwrap_err().to_string();
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
        let previous = previous_output(&dir, &PATTERNS, false).unwrap();
        let error = previous.require_force(false).unwrap_err().to_string();
        assert!(error.contains("--force"), "{error}");
        let previous = previous_output(&dir, &PATTERNS, false).unwrap();
        previous.keep("cache").keep("record.json").remove().unwrap();
        assert_eq!(list(&dir).unwrap(), ["cache", "record.json"]);
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
        check_file(&path, &output, false).unwrap();
        std::fs::write(&path, b"GIF89a...").unwrap();
        let error = check_file(&path, &output, false).unwrap_err().to_string();
        assert!(error.contains("--force"), "{error}");
        check_file(&path, &output, true).unwrap();
        std::fs::write(&path, b"GIF").unwrap();
        let error = check_file(&path, &output, true).unwrap_err().to_string();
        assert!(error.contains("is not a GIF"), "{error}");
        let error = check_file(&dir, &output, true).unwrap_err().to_string();
        assert!(error.contains("is a directory"), "{error}");
        let _ = std::fs::remove_dir_all(dir);
    }
}
