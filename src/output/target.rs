//! The one rule of every command that writes: its target is new or empty, or holds what this
//! command wrote, which only `--force` replaces; anything else is refused, naming the path and
//! the file in the way.
//!
//! The rule lives in [`phi_io::output_dir`], where the library functions behind the commands
//! (dataset generation, say) apply it too: a command declares what it writes once ([`Outputs`]
//! for a folder, [`OutputFile`] for a single file) and claims its target with
//! [`OutputDir::claim`] (or [`OutputDir::inspect`], when it resumes its own unfinished output),
//! which also clears the previous output, removes stale temporary files and writes JSON
//! atomically.
//!
//! The free functions below are the same rule with `anyhow` errors, for the call sites that
//! still use them (`phi model init`, `phi rollout`, `phi eval`); [`Previous`] is an
//! [`OutputDir`] whose methods return `anyhow` errors.

use std::path::Path;

use anyhow::Result;
pub use phi_io::output_dir::{
    Marker, OutputDir, OutputDirError, OutputFile, OutputSubdir, Outputs,
};

/// The previous output found in a target folder, to be removed before writing anew: an
/// [`OutputDir`] with `anyhow` errors.
#[derive(Debug)]
#[must_use = "a previous output is replaced only once removed"]
pub(crate) struct Previous(OutputDir);

impl Previous {
    /// The previous output, refused unless `force` or there is none
    /// ([`OutputDir::require_force`]).
    ///
    /// # Errors
    /// A previous output and no `force`: the message names the folder, what it holds and
    /// `--force`.
    pub(crate) fn require_force(self, force: bool) -> Result<Self> {
        Ok(Self(self.0.require_force(force)?))
    }

    /// The previous output without the entry `name`, which the command keeps.
    pub fn keep(self, name: &str) -> Self {
        Self(self.0.keep(name))
    }

    /// Removes the previous output ([`OutputDir::clear_previous`]).
    ///
    /// # Errors
    /// A file or folder that cannot be removed, named.
    pub fn remove(mut self) -> Result<()> {
        self.0.clear_previous()?;
        Ok(())
    }
}

/// Refuses a `path` that exists and is not a directory, naming `flag`.
///
/// # Errors
/// As above.
pub(crate) fn check_not_a_file(path: &Path, flag: &'static str) -> Result<()> {
    Ok(OutputDir::check_not_a_file(path, flag)?)
}

/// [`OutputDir::claim`]: the rule applied to the folder `out`.
///
/// # Errors
/// `out` is a file; holds a file or folder the command does not write (named with its path
/// inside `out`); holds a previous output and `force` is off.
pub(crate) fn check_dir(out: &Path, outputs: &Outputs, force: bool) -> Result<Previous> {
    Ok(Previous(OutputDir::claim(out, outputs, force)?))
}

/// [`OutputDir::inspect`]: what of the command's previous output `out` holds, refusing a
/// folder that holds anything else.
///
/// # Errors
/// `out` is a file; holds a file or folder the command does not write, or the command's file
/// names without its marker.
pub(crate) fn previous_output(out: &Path, outputs: &Outputs, force: bool) -> Result<Previous> {
    Ok(Previous(OutputDir::inspect(out, outputs, force)?))
}

/// [`OutputFile::check`]: the rule applied to the single file `out`.
///
/// # Errors
/// As there, naming the path.
pub(crate) fn check_file(out: &Path, output: &OutputFile, force: bool) -> Result<()> {
    Ok(output.check(out, force)?)
}
