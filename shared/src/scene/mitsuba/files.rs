//! Where a Mitsuba scene's files come from: the disk, or the contents a job sent, keyed by their path relative
//! to the scene file's folder (so that a worker without the coordinator's folders reads the same scene).

use std::borrow::Cow;
use std::collections::BTreeMap;
use std::path::{Component, Path, PathBuf};

/// The source of the files a scene reads: included XML, spectra, meshes and textures.
#[derive(Clone, Copy, Debug)]
pub enum FileSource<'a> {
    /// Paths as resolved against the scene's folder on this machine.
    Disk,
    /// Contents by their path relative to the scene file's folder, `/`-separated and without `.` or `x/..`
    /// steps (`relative_key`); the scene file itself is then named by its bare file name.
    Memory(&'a BTreeMap<String, Vec<u8>>),
}

impl<'a> FileSource<'a> {
    /// The bytes of the file at `path`.
    pub fn read(&self, path: &Path) -> Result<Cow<'a, [u8]>, String> {
        match self {
            FileSource::Disk => {
                std::fs::read(path).map(Cow::Owned).map_err(|e| format!("cannot read {}: {e}", path.display()))
            }
            FileSource::Memory(files) => {
                let files: &'a BTreeMap<String, Vec<u8>> = files;
                files
                    .get(&memory_key(path))
                    .map(|b| Cow::Borrowed(b.as_slice()))
                    .ok_or_else(|| format!("{} was not sent with the job", path.display()))
            }
        }
    }

    /// True when a file exists at `path`.
    pub fn exists(&self, path: &Path) -> bool {
        match self {
            FileSource::Disk => path.exists(),
            FileSource::Memory(files) => files.contains_key(&memory_key(path)),
        }
    }

    /// True when `path` is a folder: on disk, one that exists; in memory, one that holds a file.
    pub fn is_dir(&self, path: &Path) -> bool {
        match self {
            FileSource::Disk => path.is_dir(),
            FileSource::Memory(files) => {
                let key = memory_key(path);
                let prefix = if key.is_empty() { String::new() } else { format!("{key}/") };
                files.keys().any(|k| k.starts_with(&prefix))
            }
        }
    }

    /// A name that is the same for every path to the same file (the include cycle check): on disk the
    /// canonical path, in memory the key.
    pub fn identity(&self, path: &Path) -> Result<PathBuf, String> {
        match self {
            FileSource::Disk => path.canonicalize().map_err(|e| format!("cannot read {}: {e}", path.display())),
            FileSource::Memory(_) => {
                if self.exists(path) {
                    Ok(PathBuf::from(memory_key(path)))
                } else {
                    Err(format!("{} was not sent with the job", path.display()))
                }
            }
        }
    }
}

/// `path` with `.` steps dropped and `name/..` pairs folded, written with `/`.
fn memory_key(path: &Path) -> String {
    let mut parts: Vec<String> = Vec::new();
    for component in path.components() {
        match component {
            Component::CurDir => {}
            Component::ParentDir => {
                if parts.last().is_some_and(|p| p != "..") {
                    parts.pop();
                } else {
                    parts.push("..".into());
                }
            }
            Component::Normal(name) => parts.push(name.to_string_lossy().into_owned()),
            Component::RootDir | Component::Prefix(_) => parts.push(component.as_os_str().to_string_lossy().into()),
        }
    }
    parts.join("/")
}

/// The key a file read from disk travels under: its path relative to the scene file's folder `folder` (with
/// `..` steps where it lies outside), as `FileSource::Memory` looks it up. Both paths must exist.
pub fn relative_key(folder: &Path, path: &Path) -> Result<String, String> {
    let canonical = |p: &Path| p.canonicalize().map_err(|e| format!("cannot read {}: {e}", p.display()));
    let base = canonical(if folder.as_os_str().is_empty() { Path::new(".") } else { folder })?;
    let file = canonical(path)?;
    let base: Vec<Component> = base.components().collect();
    let file: Vec<Component> = file.components().collect();
    let common = base.iter().zip(&file).take_while(|(a, b)| a == b).count();
    let mut key = PathBuf::new();
    for _ in common..base.len() {
        key.push("..");
    }
    for c in &file[common..] {
        key.push(c);
    }
    Ok(memory_key(&key))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_fold_dots_and_keep_leading_parents() {
        assert_eq!(memory_key(Path::new("./a/b/../c.obj")), "a/c.obj");
        assert_eq!(memory_key(Path::new("include/../../common/x.jpg")), "../common/x.jpg");
        assert_eq!(memory_key(Path::new("")), "");
    }

    #[test]
    fn a_file_outside_the_scene_folder_is_reached_through_parents() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::create_dir_all(dir.path().join("docs/scenes")).unwrap();
        std::fs::create_dir_all(dir.path().join("common")).unwrap();
        std::fs::write(dir.path().join("common/m.ply"), b"x").unwrap();
        let key = relative_key(&dir.path().join("docs/scenes"), &dir.path().join("common/m.ply")).unwrap();
        assert_eq!(key, "../../common/m.ply");
        let files = BTreeMap::from([(key, b"x".to_vec())]);
        let memory = FileSource::Memory(&files);
        assert!(memory.is_dir(Path::new("../../common")));
        assert!(memory.exists(Path::new("include/../../../common/m.ply")));
        assert!(!memory.exists(Path::new("common/m.ply")));
    }
}
