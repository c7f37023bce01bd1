//! What a command may write over or remove: names that become paths must be plain file names,
//! and a folder a command replaces must not be, hold or lie inside what the user keeps (the
//! dataset it reads, the working folder).
//!
//! Every command that replaces or clears a folder asks [`check_replaceable`] first, so `--force`
//! can never mean "delete the dataset" or "delete the folder I am in".

use std::path::{Component, Path, PathBuf};

/// Longest name accepted as one path component (the common file-system limit, in bytes).
pub const MAX_NAME_BYTES: usize = 255;

/// True when `name` can be used as one file name inside a folder without leaving it: not empty,
/// not `.` or `..`, no separator, no NUL or other control character, at most
/// [`MAX_NAME_BYTES`] bytes.
pub fn is_plain_name(name: &str) -> bool {
    !name.is_empty()
        && name.len() <= MAX_NAME_BYTES
        && name != "."
        && name != ".."
        && !name
            .chars()
            .any(|c| c == '/' || c == '\\' || c.is_control())
}

/// Why a folder may not be replaced or written into.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{} {what}; {advice}", path.display())]
pub struct Refused {
    /// The folder the command was asked to write.
    pub path: PathBuf,
    /// What it is, in words ("is the dataset folder it reads").
    pub what: String,
    /// What to do instead.
    pub advice: &'static str,
}

/// A folder a command must leave alone.
#[derive(Debug, Clone)]
struct KeptFolder {
    path: PathBuf,
    /// Its name in errors.
    name: &'static str,
    /// The folders under it a command may write: any (`None`), or only these children.
    inside: Option<&'static [&'static str]>,
}

/// Folders a command must leave alone, with the words that name each one in errors.
#[derive(Debug, Clone, Default)]
pub struct Kept {
    folders: Vec<KeptFolder>,
}

impl Kept {
    /// The working and home folders (and so every folder above them), which every command keeps;
    /// outputs may go anywhere under them.
    pub fn working_folder() -> Kept {
        let mut kept = Kept::default();
        let mut push = |path: PathBuf, name| {
            kept.folders.push(KeptFolder {
                path: resolved(&path),
                name,
                inside: None,
            })
        };
        if let Ok(cwd) = std::env::current_dir() {
            push(cwd, "the working folder");
        }
        if let Some(home) = std::env::var_os("HOME").filter(|h| !h.is_empty()) {
            push(PathBuf::from(home), "the home folder");
        }
        kept
    }

    /// Adds `folder`, named `name` in errors ("the dataset folder it reads"), inside which only
    /// the children named in `inside` may be written (a command's own default folder).
    pub fn and(
        mut self,
        folder: &Path,
        name: &'static str,
        inside: &'static [&'static str],
    ) -> Kept {
        self.folders.push(KeptFolder {
            path: resolved(folder),
            name,
            inside: Some(inside),
        });
        self
    }
}

/// Checks that replacing or clearing `out` cannot touch a kept folder: `out` is refused when it is
/// the file system's root, is a kept folder, holds one, or lies inside a kept folder other than
/// the working or home folder (building under the folder one works in is the normal case).
pub fn check_replaceable(out: &Path, kept: &Kept, advice: &'static str) -> Result<(), Refused> {
    let target = resolved(out);
    let refuse = |what: String| Refused {
        path: out.to_path_buf(),
        what,
        advice,
    };
    if target.parent().is_none() {
        return Err(refuse("is the root of the file system".into()));
    }
    for KeptFolder { path, name, inside } in &kept.folders {
        if &target == path {
            return Err(refuse(format!("is {name}")));
        }
        if path.starts_with(&target) {
            return Err(refuse(format!("holds {name} ({})", path.display())));
        }
        if let (Some(allowed), Ok(under)) = (inside, target.strip_prefix(path)) {
            let child = under.components().next().map(|c| c.as_os_str());
            if !allowed
                .iter()
                .any(|a| child == Some(std::ffi::OsStr::new(a)))
            {
                return Err(refuse(format!("lies inside {name} ({})", path.display())));
            }
        }
    }
    Ok(())
}

/// Checks that `dir` can be a folder a command fills and later clears by name (a dataset folder):
/// it is not the working folder, the home folder or above them, and if it already holds anything,
/// `made_here` recognises it as motionforge's.
pub fn check_owned(
    dir: &Path,
    made_here: impl FnOnce(&Path) -> bool,
    advice: &'static str,
) -> Result<(), Refused> {
    check_replaceable(dir, &Kept::working_folder(), advice)?;
    let has_entries = std::fs::read_dir(dir).is_ok_and(|mut e| e.next().is_some());
    if has_entries && !made_here(dir) {
        return Err(Refused {
            path: dir.to_path_buf(),
            what: "holds files motionforge did not write".into(),
            advice,
        });
    }
    Ok(())
}

/// `path` made absolute with symbolic links resolved as far as it exists, and `.`/`..` folded in
/// the part that does not exist yet: two spellings of one folder compare equal.
pub fn resolved(path: &Path) -> PathBuf {
    let absolute = if path.is_absolute() {
        path.to_path_buf()
    } else {
        std::env::current_dir()
            .map(|cwd| cwd.join(path))
            .unwrap_or_else(|_| path.to_path_buf())
    };
    let absolute = super::lexical_path(&absolute);
    // The longest existing ancestor is canonicalised; the rest is appended as written.
    let mut existing = absolute.as_path();
    let mut rest: Vec<Component<'_>> = Vec::new();
    loop {
        if let Ok(real) = existing.canonicalize() {
            let mut out = real;
            for c in rest.iter().rev() {
                out.push(c.as_os_str());
            }
            return super::lexical_path(&out);
        }
        match (existing.parent(), existing.components().next_back()) {
            (Some(parent), Some(last)) => {
                rest.push(last);
                existing = parent;
            }
            _ => return absolute,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plain_names_cannot_leave_their_folder() {
        for bad in [
            "", ".", "..", "../x", "/tmp/x", "a/b", "a\\b", "a\0b", "a\nb",
        ] {
            assert!(!is_plain_name(bad), "{bad:?} accepted");
        }
        assert!(!is_plain_name(&"x".repeat(MAX_NAME_BYTES + 1)));
        for good in ["train", "val", "M000001", "a.b", "..x", "x..", "é"] {
            assert!(is_plain_name(good), "{good:?} refused");
        }
    }

    #[test]
    fn a_folder_that_is_holds_or_lies_in_a_kept_one_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let dataset = dir.path().join("out/demo");
        std::fs::create_dir_all(&dataset).unwrap();
        let kept = Kept::default().and(&dataset, "the dataset folder", &["humanml3d"]);
        let check = |p: &Path| check_replaceable(p, &kept, "choose another");
        assert!(check(&dataset).is_err());
        // Spelled another way.
        assert!(check(&dir.path().join("out/demo/../demo/.")).is_err());
        assert!(check(&dir.path().join("out")).is_err());
        assert!(check(&dataset.join("export")).is_err());
        assert!(check(&dataset.join("data")).is_err());
        // The command's own folder inside the dataset.
        assert!(check(&dataset.join("humanml3d")).is_ok());
        assert!(check(&dataset.join("not/yet/there")).is_err());
        assert!(check(Path::new("/")).is_err());
        assert!(check(&dir.path().join("out/demo-hml3d")).is_ok());
        assert!(check(&dir.path().join("elsewhere/new")).is_ok());
    }

    #[test]
    fn a_folder_of_someone_elses_files_is_not_taken_over() {
        let dir = tempfile::tempdir().unwrap();
        let marked = |d: &Path| d.join(".motionforge").is_dir();
        let mine = dir.path().join("mine");
        assert!(check_owned(&mine, marked, "").is_ok());
        std::fs::create_dir_all(mine.join(".motionforge")).unwrap();
        std::fs::write(mine.join("README.md"), "x").unwrap();
        assert!(check_owned(&mine, marked, "").is_ok());
        let theirs = dir.path().join("theirs");
        std::fs::create_dir_all(&theirs).unwrap();
        assert!(check_owned(&theirs, marked, "").is_ok());
        std::fs::write(theirs.join("README.md"), "x").unwrap();
        let err = check_owned(&theirs, marked, "").unwrap_err();
        assert!(err.to_string().contains("did not write"), "{err}");
    }

    #[test]
    fn the_working_folder_is_kept_but_may_hold_outputs() {
        let kept = Kept::working_folder();
        let cwd = std::env::current_dir().unwrap();
        assert!(check_replaceable(&cwd, &kept, "").is_err());
        assert!(check_replaceable(Path::new("."), &kept, "").is_err());
        assert!(check_replaceable(Path::new(".."), &kept, "").is_err());
        assert!(check_replaceable(Path::new("out/x"), &kept, "").is_ok());
    }
}
