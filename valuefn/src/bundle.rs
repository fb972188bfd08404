//! Model bundles on disk: `models/<name>/<version>/{model.onnx, manifest.json}`, checksummed.

use crate::manifest::{Manifest, ManifestError};
use sha2::{Digest, Sha256};
use std::path::{Path, PathBuf};

/// File name of the graph inside a version folder.
pub const MODEL_FILE: &str = "model.onnx";
/// File name of the manifest inside a version folder.
pub const MANIFEST_FILE: &str = "manifest.json";

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

fn read(path: &Path) -> Result<Vec<u8>, BundleError> {
    std::fs::read(path).map_err(|source| BundleError::Io { path: path.into(), source })
}

impl Bundle {
    /// Reads and checks the bundle in a version folder `<root>/<name>/<version>`.
    pub fn load(dir: &Path) -> Result<Self, BundleError> {
        let manifest_path = dir.join(MANIFEST_FILE);
        let text = String::from_utf8_lossy(&read(&manifest_path)?).into_owned();
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
        let onnx = read(&onnx_path)?;
        let actual = sha256_hex(&onnx);
        if actual != manifest.onnx_sha256 {
            return Err(BundleError::Checksum { path: onnx_path, expected: manifest.onnx_sha256, actual });
        }
        Ok(Self { dir: dir.into(), manifest, onnx })
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

/// Lists `<root>/<name>/<version>/` folders (versions are positive integers; other entries are
/// reported in the second list with the reason they were skipped).
pub fn scan_repository(root: &Path) -> std::io::Result<(Vec<VersionDir>, Vec<Skipped>)> {
    let mut found = Vec::new();
    let mut skipped = Vec::new();
    for model in std::fs::read_dir(root)? {
        let model = model?;
        if !model.file_type()?.is_dir() {
            continue;
        }
        let name = model.file_name().to_string_lossy().into_owned();
        for version in std::fs::read_dir(model.path())? {
            let version = version?;
            let label = version.file_name().to_string_lossy().into_owned();
            match label.parse::<u32>() {
                Ok(v) if v > 0 && version.file_type()?.is_dir() => {
                    found.push(VersionDir { name: name.clone(), version: v, path: version.path() })
                }
                _ => skipped.push((version.path(), "not a positive-integer version folder".to_string())),
            }
        }
    }
    found.sort();
    Ok((found, skipped))
}
