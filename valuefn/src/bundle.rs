//! Model bundles on disk: `models/<name>/<version>/{model.onnx, manifest.json}`, checksummed.

use crate::manifest::{Manifest, ManifestError};
use sha2::{Digest, Sha256};
use std::path::{Path, PathBuf};

/// File name of the graph inside a version folder.
pub const MODEL_FILE: &str = "model.onnx";
/// File name of the manifest inside a version folder.
pub const MANIFEST_FILE: &str = "manifest.json";
/// Largest manifest read (bytes): a TEB table with boundary radii takes well under a megabyte.
pub const MAX_MANIFEST_BYTES: u64 = 16 << 20;
/// Largest graph read (bytes): a value network of a few hundred thousand weights takes a few megabytes.
pub const MAX_MODEL_BYTES: u64 = 1 << 30;

/// Why a bundle could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum BundleError {
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The manifest is malformed.
    #[error("{path}: {source}")]
    Manifest {
        /// The manifest file.
        path: PathBuf,
        /// What is wrong.
        source: ManifestError,
    },
    /// `model.onnx` does not hash to the manifest's checksum.
    #[error("{path}: sha256 is {actual}, manifest says {expected} (file corrupt or replaced)")]
    Checksum {
        /// The graph file.
        path: PathBuf,
        /// Checksum in the manifest.
        expected: String,
        /// Checksum of the file.
        actual: String,
    },
    /// A bundle file is a device, a pipe or a folder, not a regular file.
    #[error("{path}: not a regular file")]
    NotAFile {
        /// The file.
        path: PathBuf,
    },
    /// A bundle file is larger than a bundle file may be.
    #[error("{path}: {size} bytes, more than the {limit} a bundle's {kind} may have")]
    TooLarge {
        /// The file.
        path: PathBuf,
        /// What the file is (`manifest` or `graph`).
        kind: &'static str,
        /// Its size.
        size: u64,
        /// The largest size read.
        limit: u64,
    },
    /// A version folder or one of its files leads (through a symbolic link) outside the repository.
    #[error("{path}: leads to {target}, outside the model repository {root}")]
    OutsideRepository {
        /// The path inside the repository.
        path: PathBuf,
        /// Where it leads.
        target: PathBuf,
        /// The repository.
        root: PathBuf,
    },
    /// The folder names disagree with the manifest.
    #[error("{path}: folder says {folder}, manifest says {manifest}")]
    Location {
        /// The version folder.
        path: PathBuf,
        /// `name/version` from the folders.
        folder: String,
        /// `name/version` from the manifest.
        manifest: String,
    },
}

/// A bundle read from disk: its manifest and graph bytes, checksum verified.
#[derive(Debug, Clone)]
pub struct Bundle {
    /// The version folder.
    pub dir: PathBuf,
    /// Validated manifest.
    pub manifest: Manifest,
    /// The ONNX graph.
    pub onnx: Vec<u8>,
}

/// Lowercase hex SHA-256 of `bytes`.
pub fn sha256_hex(bytes: &[u8]) -> String {
    hex::encode(Sha256::digest(bytes))
}

/// Reads a regular file of at most `limit` bytes (checked before reading and while reading, in case it grows).
fn read(path: &Path, kind: &'static str, limit: u64) -> Result<Vec<u8>, BundleError> {
    use std::io::Read;
    let io = |source| BundleError::Io { path: path.into(), source };
    let file = std::fs::File::open(path).map_err(io)?;
    let metadata = file.metadata().map_err(io)?;
    if !metadata.is_file() {
        return Err(BundleError::NotAFile { path: path.into() });
    }
    let too_large = |size| BundleError::TooLarge { path: path.into(), kind, size, limit };
    if metadata.len() > limit {
        return Err(too_large(metadata.len()));
    }
    let mut bytes = Vec::with_capacity(metadata.len() as usize);
    file.take(limit + 1).read_to_end(&mut bytes).map_err(io)?;
    if bytes.len() as u64 > limit {
        return Err(too_large(bytes.len() as u64));
    }
    Ok(bytes)
}

fn canonical(path: &Path) -> Result<PathBuf, BundleError> {
    path.canonicalize().map_err(|source| BundleError::Io { path: path.into(), source })
}

impl Bundle {
    /// Reads and checks the bundle in a version folder `<root>/<name>/<version>`.
    pub fn load(dir: &Path) -> Result<Self, BundleError> {
        let manifest_path = dir.join(MANIFEST_FILE);
        let text = String::from_utf8_lossy(&read(&manifest_path, "manifest", MAX_MANIFEST_BYTES)?).into_owned();
        let manifest =
            Manifest::from_json(&text).map_err(|source| BundleError::Manifest { path: manifest_path, source })?;
        let folder_version = dir.file_name().and_then(|s| s.to_str()).unwrap_or_default();
        let folder_name = dir.parent().and_then(|p| p.file_name()).and_then(|s| s.to_str()).unwrap_or_default();
        if folder_name != manifest.name || folder_version != manifest.version.to_string() {
            return Err(BundleError::Location {
                path: dir.into(),
                folder: format!("{folder_name}/{folder_version}"),
                manifest: format!("{}/{}", manifest.name, manifest.version),
            });
        }
        let onnx_path = dir.join(MODEL_FILE);
        let onnx = read(&onnx_path, "graph", MAX_MODEL_BYTES)?;
        let actual = sha256_hex(&onnx);
        if actual != manifest.onnx_sha256 {
            return Err(BundleError::Checksum { path: onnx_path, expected: manifest.onnx_sha256, actual });
        }
        Ok(Self { dir: dir.into(), manifest, onnx })
    }

    /// [`Bundle::load`] for a version folder of the repository `root` that a server serves: the folder and
    /// both files must resolve (symbolic links followed) to paths inside `root`.
    pub fn load_within(root: &Path, dir: &Path) -> Result<Self, BundleError> {
        let root = canonical(root)?;
        for path in [dir.to_path_buf(), dir.join(MANIFEST_FILE), dir.join(MODEL_FILE)] {
            let target = canonical(&path)?;
            if !target.starts_with(&root) {
                return Err(BundleError::OutsideRepository { path, target, root });
            }
        }
        Self::load(dir)
    }

    /// Writes `model.onnx` and `manifest.json` (with the graph's checksum filled in) to
    /// `<root>/<name>/<version>/`, validating the manifest first.
    pub fn write(root: &Path, mut manifest: Manifest, onnx: &[u8]) -> Result<PathBuf, BundleError> {
        manifest.onnx_sha256 = sha256_hex(onnx);
        let dir = root.join(&manifest.name).join(manifest.version.to_string());
        manifest.validate().map_err(|source| BundleError::Manifest { path: dir.join(MANIFEST_FILE), source })?;
        std::fs::create_dir_all(&dir).map_err(|source| BundleError::Io { path: dir.clone(), source })?;
        let write = |name: &str, bytes: &[u8]| {
            let path = dir.join(name);
            std::fs::write(&path, bytes).map_err(|source| BundleError::Io { path, source })
        };
        write(MODEL_FILE, onnx)?;
        write(MANIFEST_FILE, format!("{}\n", manifest.to_json()).as_bytes())?;
        Ok(dir)
    }
}

/// A version folder found in a repository.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
pub struct VersionDir {
    /// Model name.
    pub name: String,
    /// Version number.
    pub version: u32,
    /// The folder.
    pub path: PathBuf,
}

/// An entry of a repository that is not a version folder, and why.
pub type Skipped = (PathBuf, String);

/// Lists `<root>/<name>/<version>/` folders (versions are positive integers; symbolic links to folders
/// count as folders, and [`Bundle::load_within`] checks where they lead). Other entries, and entries that
/// cannot be read, are reported in the second list with the reason they were skipped; only an unreadable
/// `root` is an error.
pub fn scan_repository(root: &Path) -> std::io::Result<(Vec<VersionDir>, Vec<Skipped>)> {
    let mut found = Vec::new();
    let mut skipped = Vec::new();
    for model in std::fs::read_dir(root)? {
        let Some(model) = folder_entry(model, &mut skipped) else { continue };
        let name = model.file_name().unwrap_or_default().to_string_lossy().into_owned();
        let versions = match std::fs::read_dir(&model) {
            Ok(versions) => versions,
            Err(e) => {
                skipped.push((model, format!("cannot be listed: {e}")));
                continue;
            }
        };
        for version in versions {
            let Some(path) = folder_entry(version, &mut skipped) else { continue };
            let label = path.file_name().unwrap_or_default().to_string_lossy().into_owned();
            match label.parse::<u32>() {
                Ok(v) if v > 0 => found.push(VersionDir { name: name.clone(), version: v, path }),
                _ => skipped.push((path, "not a positive-integer version folder".to_string())),
            }
        }
    }
    found.sort();
    Ok((found, skipped))
}

/// The path of a directory entry that is a folder (or a link to one); anything else is skipped with why.
fn folder_entry(entry: std::io::Result<std::fs::DirEntry>, skipped: &mut Vec<Skipped>) -> Option<PathBuf> {
    let entry = match entry {
        Ok(entry) => entry,
        Err(e) => {
            skipped.push((PathBuf::new(), format!("an entry cannot be read: {e}")));
            return None;
        }
    };
    let path = entry.path();
    match std::fs::metadata(&path) {
        Ok(metadata) if metadata.is_dir() => Some(path),
        Ok(_) => {
            skipped.push((path, "not a folder".to_string()));
            None
        }
        Err(e) => {
            skipped.push((path, format!("cannot be read (a dangling link?): {e}")));
            None
        }
    }
}
