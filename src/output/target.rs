//! The one rule of every command that writes: its target is new or empty, or holds what this
//! command wrote, which only `--force` replaces; anything else is refused, naming the path and
//! the file in the way.
//!
//! A command describes what it writes once ([`Outputs`] for a folder, [`OutputFile`] for a
//! single file), and [`check_dir`] / [`check_file`] apply the rule. A folder's previous output is
//! removed by [`Previous::remove`] only once the command has checked everything else, so a
//! refused run leaves the target as it was.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};

/// A folder a command writes inside its target folder, and the files it puts there: names
/// starting with `prefix` and ending with `suffix`.
#[derive(Debug, Clone, Copy)]
pub struct OutputSubdir {
    /// The folder's name.
    pub name: &'static str,
    /// How the name of each file in it starts.
    pub prefix: &'static str,
    /// How the name of each file in it ends.
    pub suffix: &'static str,
}

/// What a command writes into its target folder.
#[derive(Debug, Clone, Copy)]
pub struct Outputs {
    /// The command as users type it (`phi optimize`).
    pub command: &'static str,
    /// The option naming the target (`--out`).
    pub flag: &'static str,
    /// The files it writes in the target.
    pub files: &'static [&'static str],
    /// The folders it writes in the target.
    pub subdirs: &'static [OutputSubdir],
    /// The file it writes first, where one exists: a target holding the command's other files
    /// without it was not written by the command (another tool's files of the same names).
    pub marker: Option<&'static str>,
}

/// The previous output found in a target folder, to be removed before writing anew.
#[derive(Debug, Default)]
#[must_use = "a previous output is replaced only once removed"]
pub struct Previous {
    files: Vec<PathBuf>,
    subdirs: Vec<PathBuf>,
}

impl Previous {
    /// Whether the target held nothing of a previous output.
    pub fn is_empty(&self) -> bool {
        self.files.is_empty() && self.subdirs.is_empty()
    }

    /// Removes the previous output, so that the files of two runs never mix.
    ///
    /// # Errors
    /// A file or folder that cannot be removed, named.
    pub fn remove(self) -> Result<()> {
        for dir in &self.subdirs {
            std::fs::remove_dir_all(dir)
                .with_context(|| format!("removing the previous output {}", dir.display()))?;
        }
        for file in &self.files {
            std::fs::remove_file(file)
                .with_context(|| format!("removing the previous output {}", file.display()))?;
        }
        Ok(())
    }
}

/// Whether `name` is `file` or the temporary file of an atomic write of it
/// (`.{file}.tmp-{pid}`), which a killed run leaves behind.
fn is_file_or_temporary(name: &str, file: &str) -> bool {
    name == file
        || name
            .strip_prefix('.')
            .and_then(|rest| rest.strip_prefix(file))
            .and_then(|rest| rest.strip_prefix(".tmp-"))
            .is_some_and(|pid| !pid.is_empty() && pid.bytes().all(|b| b.is_ascii_digit()))
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

/// Applies the rule to the target folder `out` of `outputs.command`: a missing or empty folder
/// is fine; one holding only the command's outputs is its previous output, refused without
/// `force` and returned with it (remove it with [`Previous::remove`] before writing); anything
/// else is refused, `force` or not.
///
/// # Errors
/// `out` is a file; holds a file or folder the command does not write (named with its path
/// inside `out`); holds a previous output and `force` is off.
pub fn check_dir(out: &Path, outputs: &Outputs, force: bool) -> Result<Previous> {
    let Outputs {
        command,
        flag,
        files,
        subdirs,
        marker,
    } = *outputs;
    if !out.exists() {
        return Ok(Previous::default());
    }
    if !out.is_dir() {
        bail!(
            "{flag} {}: exists and is not a directory; `{command}` writes a directory",
            out.display()
        );
    }
    let names = list(out)?;
    let mut previous = Previous::default();
    let mut foreign = None;
    for name in &names {
        if files.iter().any(|f| is_file_or_temporary(name, f)) {
            previous.files.push(out.join(name));
            continue;
        }
        let Some(subdir) = subdirs.iter().find(|d| d.name == name) else {
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
            let stem = n.strip_prefix('.').and_then(|r| r.rsplit_once(".tmp-"));
            let file = stem.map_or(n.as_str(), |(file, _)| file);
            file.starts_with(subdir.prefix) && file.ends_with(subdir.suffix)
        };
        match inside.iter().find(|n| !ours(n)) {
            Some(other) => {
                foreign.get_or_insert_with(|| format!("{name}/{other}"));
            }
            None => previous.subdirs.push(dir),
        }
    }
    if let Some(name) = foreign {
        let what = if name == "metadata.json" {
            " (a dataset)"
        } else {
            ""
        };
        bail!(
            "{flag} {}: holds '{name}'{what}, which `{command}` does not write; refusing to \
             write into it{}: choose a new or empty {flag}",
            out.display(),
            if force { " even with --force" } else { "" }
        );
    }
    if previous.is_empty() {
        return Ok(previous);
    }
    if let Some(marker) = marker
        && !out.join(marker).is_file()
    {
        bail!(
            "{flag} {}: holds '{}' but no {marker}, which `{command}` writes first: not its \
             output; refusing to write into it: choose a new or empty {flag}",
            out.display(),
            names[0]
        );
    }
    if !force {
        let shown = names.iter().take(3).cloned().collect::<Vec<_>>().join(", ");
        bail!(
            "{flag} {}: is not empty ({} entries: {shown}{}); it holds a previous `{command}` \
             output: pass --force to replace it, or choose a new or empty {flag}",
            out.display(),
            names.len(),
            if names.len() > 3 { ", ..." } else { "" }
        );
    }
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
        marker: Some("record.json"),
    };

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
        std::fs::write(dir.join("record.json"), "{}").unwrap();
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
            std::fs::write(dir.join("record.json"), "{}").unwrap();
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
    fn our_file_names_without_the_marker_are_not_ours() {
        let dir = temp_dir("target-marker");
        std::fs::write(dir.join("data.csv"), "1,2").unwrap();
        let error = check_dir(&dir, &OUTPUTS, true).unwrap_err().to_string();
        assert!(error.contains("no record.json"), "{error}");
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
