//! The solution file format (`.ftgrid`), little-endian:
//!
//! | bytes | content |
//! |---|---|
//! | 8 | magic `FTGRID01` |
//! | 8 | `u64` length `H` of the header |
//! | `H` | UTF-8 JSON header: `{"axes": [{name, min, max, n, periodic}, ...], "info": SolveInfo}` |
//! | `8 N` | `N = prod(n)` `f64` values, row-major (the last axis varies fastest) |
//!
//! Node `i` of a non-periodic axis sits at `min + i (max - min) / (n - 1)`; of a periodic axis at
//! `min + i (max - min) / n`.

use crate::grid::{Axis, Grid, GridError};
use crate::solution::{Solution, SolveInfo};
use serde::{Deserialize, Serialize};
use std::io::{Read, Write};
use std::path::{Path, PathBuf};

/// The file's first eight bytes.
pub const MAGIC: &[u8; 8] = b"FTGRID01";

/// A solution file that cannot be written or read.
#[derive(Debug, thiserror::Error)]
pub enum FormatError {
    /// I/O failure.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The error.
        source: std::io::Error,
    },
    /// The file is not a solution file or is damaged.
    #[error("{path}: {problem}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        problem: String,
    },
}

#[derive(Serialize, Deserialize)]
struct Header {
    axes: Vec<Axis>,
    info: SolveInfo,
}

/// Writes `solution` to `path`.
pub fn save(solution: &Solution, path: &Path) -> Result<(), FormatError> {
    let io = |source| FormatError::Io { path: path.into(), source };
    let header = Header { axes: solution.grid.axes().to_vec(), info: solution.info.clone() };
    let json = serde_json::to_vec(&header).map_err(|e| io(e.into()))?;
    let file = std::fs::File::create(path).map_err(io)?;
    let mut out = std::io::BufWriter::new(file);
    out.write_all(MAGIC).map_err(io)?;
    out.write_all(&(json.len() as u64).to_le_bytes()).map_err(io)?;
    out.write_all(&json).map_err(io)?;
    for v in &solution.values {
        out.write_all(&v.to_le_bytes()).map_err(io)?;
    }
    out.flush().map_err(io)
}

/// Reads a solution written by [`save`].
pub fn load(path: &Path) -> Result<Solution, FormatError> {
    let invalid = |problem: String| FormatError::Invalid { path: path.into(), problem };
    let mut bytes = Vec::new();
    std::fs::File::open(path)
        .and_then(|mut f| f.read_to_end(&mut bytes))
        .map_err(|source| FormatError::Io { path: path.into(), source })?;
    if bytes.len() < 16 || &bytes[..8] != MAGIC {
        return Err(invalid("not a fastrack grid solution (magic FTGRID01 missing)".into()));
    }
    let header_len = u64::from_le_bytes(bytes[8..16].try_into().unwrap_or_default()) as usize;
    let body = 16usize.checked_add(header_len).filter(|&e| e <= bytes.len()).ok_or_else(|| {
        invalid(format!("header length {header_len} runs past the end of the {}-byte file", bytes.len()))
    })?;
    let header: Header =
        serde_json::from_slice(&bytes[16..body]).map_err(|e| invalid(format!("header is not valid: {e}")))?;
    let grid = Grid::new(header.axes).map_err(|e: GridError| invalid(format!("header grid: {e}")))?;
    let data = &bytes[body..];
    if data.len() != grid.num_points() * 8 {
        return Err(invalid(format!(
            "{} bytes of values for a grid of {} points (expected {})",
            data.len(),
            grid.num_points(),
            grid.num_points() * 8
        )));
    }
    let values =
        data.chunks_exact(8).map(|c| f64::from_le_bytes(c.try_into().unwrap_or_default())).collect::<Vec<f64>>();
    Ok(Solution { grid, values, info: header.info })
}
