//! Shards of batch work: `--shard INDEX/COUNT` splits a list of items (worlds of a benchmark, rows of a
//! table) among `COUNT` independent processes, for example the pods of a Kubernetes Indexed Job; a merge
//! combines their parts into what a single run gives. `--shard COUNT` alone takes the index from
//! `JOB_COMPLETION_INDEX`, which Kubernetes sets in each pod of an Indexed Job.

use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use serde_json::Value;
use std::fmt;
use std::path::{Path, PathBuf};
use std::str::FromStr;

/// The environment variable Kubernetes sets to a pod's index in an Indexed Job.
pub const JOB_INDEX_ENV: &str = "JOB_COMPLETION_INDEX";

/// Shard `index` of `count`: it takes the items whose position `i` (from 0) has `i % count == index`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Shard {
    /// This shard, from 0.
    pub index: usize,
    /// How many shards share the work.
    pub count: usize,
}

/// A shard that cannot be read.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("--shard {given}: {why}")]
pub struct ShardError {
    given: String,
    why: String,
}

impl Shard {
    /// The whole work: one shard.
    pub const WHOLE: Shard = Shard { index: 0, count: 1 };

    /// `INDEX/COUNT`, or `COUNT` with the index from `job_index` (the value of [`JOB_INDEX_ENV`]).
    pub fn parse(text: &str, job_index: Option<&str>) -> Result<Shard, ShardError> {
        let error = |why: String| ShardError { given: text.to_string(), why };
        let number = |s: &str, what: &str| {
            s.trim().parse::<usize>().map_err(|_| error(format!("{what} `{s}` is not a whole number")))
        };
        let (index, count) = match text.split_once('/') {
            Some((index, count)) => (number(index, "the index")?, number(count, "the count")?),
            None => {
                let count = number(text, "the count")?;
                let Some(index) = job_index else {
                    return Err(error(format!("gives no index and {JOB_INDEX_ENV} is not set; use INDEX/COUNT")));
                };
                (number(index, JOB_INDEX_ENV)?, count)
            }
        };
        if count == 0 || index >= count {
            return Err(error(format!("index {index} of {count} shards; the index must be in 0..{count}")));
        }
        Ok(Shard { index, count })
    }

    /// True if the item at `position` (from 0) belongs to this shard.
    pub fn takes(&self, position: usize) -> bool {
        position % self.count == self.index
    }

    /// True for the whole work.
    pub fn is_whole(&self) -> bool {
        self.count == 1
    }

    /// The file name of this shard's part: `<stem>-part-<index>-of-<count>.json`.
    pub fn part_file_name(&self, stem: &str) -> String {
        format!("{stem}-part-{}-of-{}.json", self.index, self.count)
    }

    /// Checks that `shards` are every shard of one split, each once; returns their count.
    pub fn check_complete(shards: &[Shard]) -> Result<usize, String> {
        let Some(count) = shards.first().map(|s| s.count) else {
            return Err("no parts".into());
        };
        if let Some(other) = shards.iter().find(|s| s.count != count) {
            return Err(format!("parts of {count} and of {} shards are mixed", other.count));
        }
        let mut seen = vec![false; count];
        for s in shards {
            if std::mem::replace(&mut seen[s.index], true) {
                return Err(format!("shard {s} appears twice"));
            }
        }
        let missing: Vec<String> = (0..count).filter(|&i| !seen[i]).map(|i| i.to_string()).collect();
        if !missing.is_empty() {
            return Err(format!("shards {} of {count} are missing", missing.join(", ")));
        }
        Ok(count)
    }
}

/// What one shard produced: the configuration that decides the work (the same for every shard of one
/// split), which shard, its wall time, and its items.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Part<T> {
    /// Everything that decides the items.
    pub config: Value,
    /// Which shard.
    pub shard: Shard,
    /// Wall time of the shard (s).
    pub wall_s: f64,
    /// Its items.
    pub items: Vec<T>,
}

/// The parts of one split, merged.
#[derive(Debug, Clone, PartialEq)]
pub struct Merged<T> {
    /// The configuration every part shares.
    pub config: Value,
    /// Every part's items, in shard order.
    pub items: Vec<T>,
    /// The longest shard's wall time (s): the split's wall time when the shards ran at once.
    pub wall_s: f64,
}

/// Parts that cannot be merged.
#[derive(Debug, thiserror::Error)]
pub enum PartError {
    /// A part could not be read.
    #[error("{path}: {why}")]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        why: String,
    },
    /// The parts do not form one split of one piece of work.
    #[error("the parts in {dir} do not make one run: {why}")]
    Mismatch {
        /// The folder.
        dir: PathBuf,
        /// Why.
        why: String,
    },
}

impl<T: Serialize + DeserializeOwned> Part<T> {
    /// Writes the part into `dir` as `<stem>-part-<index>-of-<count>.json`.
    pub fn write(&self, dir: &Path, stem: &str) -> std::io::Result<PathBuf> {
        std::fs::create_dir_all(dir)?;
        let path = dir.join(self.shard.part_file_name(stem));
        std::fs::write(&path, serde_json::to_vec(self)?)?;
        Ok(path)
    }

    /// Reads every `<stem>-part-*.json` in `dir` and merges them: one configuration, every shard once.
    pub fn merge(dir: &Path, stem: &str) -> Result<Merged<T>, PartError> {
        let mismatch = |why: String| PartError::Mismatch { dir: dir.to_path_buf(), why };
        let read_error = |path: &Path, why: String| PartError::Read { path: path.to_path_buf(), why };
        let prefix = format!("{stem}-part-");
        let entries = std::fs::read_dir(dir).map_err(|e| read_error(dir, e.to_string()))?;
        let mut paths: Vec<PathBuf> = entries
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| {
                p.file_name().and_then(|n| n.to_str()).is_some_and(|n| n.starts_with(&prefix) && n.ends_with(".json"))
            })
            .collect();
        paths.sort();
        let mut parts: Vec<Part<T>> = Vec::with_capacity(paths.len());
        for path in &paths {
            let bytes = std::fs::read(path).map_err(|e| read_error(path, e.to_string()))?;
            parts.push(serde_json::from_slice(&bytes).map_err(|e| read_error(path, e.to_string()))?);
        }
        let shards: Vec<Shard> = parts.iter().map(|p| p.shard).collect();
        Shard::check_complete(&shards).map_err(&mismatch)?;
        parts.sort_by_key(|p| p.shard.index);
        let config = parts[0].config.clone();
        if let Some(other) = parts.iter().find(|p| p.config != config) {
            return Err(mismatch(format!("shard {} ran {} where shard 0 ran {config}", other.shard, other.config)));
        }
        let wall_s = parts.iter().map(|p| p.wall_s).fold(0.0, f64::max);
        Ok(Merged { config, items: parts.into_iter().flat_map(|p| p.items).collect(), wall_s })
    }
}

impl fmt::Display for Shard {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

impl FromStr for Shard {
    type Err = ShardError;

    /// `INDEX/COUNT`, or `COUNT` with the index from `JOB_COMPLETION_INDEX`.
    fn from_str(text: &str) -> Result<Self, Self::Err> {
        Shard::parse(text, std::env::var(JOB_INDEX_ENV).ok().as_deref())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn index_and_count_or_the_job_index() {
        assert_eq!(Shard::parse("2/8", None), Ok(Shard { index: 2, count: 8 }));
        assert_eq!(Shard::parse("8", Some("5")), Ok(Shard { index: 5, count: 8 }));
        assert_eq!(Shard::parse("3/8", Some("5")), Ok(Shard { index: 3, count: 8 }), "an explicit index wins");
        for (bad, job, says) in [
            ("8", None, "JOB_COMPLETION_INDEX is not set"),
            ("8/8", None, "must be in 0..8"),
            ("0/0", None, "must be in 0..0"),
            ("a/3", None, "the index `a`"),
            ("8", Some("x"), "JOB_COMPLETION_INDEX `x`"),
            ("-1/3", None, "the index `-1`"),
        ] {
            let e = Shard::parse(bad, job).unwrap_err().to_string();
            assert!(e.contains(says) && e.starts_with(&format!("--shard {bad}")), "{bad}: {e}");
        }
    }

    #[test]
    fn the_shards_of_a_split_take_every_item_once() {
        let shards: Vec<Shard> = (0..3).map(|index| Shard { index, count: 3 }).collect();
        for position in 0..20 {
            assert_eq!(shards.iter().filter(|s| s.takes(position)).count(), 1, "item {position}");
        }
        assert!(Shard::WHOLE.takes(7) && Shard::WHOLE.is_whole());
        assert_eq!(Shard::check_complete(&shards), Ok(3));
        assert!(Shard::check_complete(&shards[..2]).unwrap_err().contains("shards 2 of 3 are missing"));
        let twice = [shards[0], shards[0], shards[1], shards[2]];
        assert!(Shard::check_complete(&twice).unwrap_err().contains("0/3 appears twice"));
        let mixed = [Shard { index: 0, count: 2 }, shards[1]];
        assert!(Shard::check_complete(&mixed).unwrap_err().contains("mixed"));
        assert_eq!(shards[1].part_file_name("sim-bench"), "sim-bench-part-1-of-3.json");
    }

    #[test]
    fn parts_merge_in_shard_order_and_only_when_they_make_one_split() {
        let dir = tempfile::tempdir().unwrap();
        let config = serde_json::json!({"worlds": 5});
        for index in [1, 0] {
            let items: Vec<usize> = (0..5).filter(|&i| Shard { index, count: 2 }.takes(i)).collect();
            let part =
                Part { config: config.clone(), shard: Shard { index, count: 2 }, wall_s: 1.0 + index as f64, items };
            part.write(dir.path(), "work").unwrap();
        }
        let merged = Part::<usize>::merge(dir.path(), "work").unwrap();
        assert_eq!((merged.config, merged.items, merged.wall_s), (config, vec![0, 2, 4, 1, 3], 2.0));
        let other = Part {
            config: serde_json::json!({"worlds": 6}),
            shard: Shard { index: 1, count: 2 },
            wall_s: 0.0,
            items: vec![1usize],
        };
        other.write(dir.path(), "work").unwrap();
        let e = Part::<usize>::merge(dir.path(), "work").unwrap_err().to_string();
        assert!(e.contains("shard 1/2 ran {\"worlds\":6} where shard 0 ran {\"worlds\":5}"), "{e}");
        std::fs::write(dir.path().join("work-part-1-of-2.json"), "{").unwrap();
        assert!(matches!(Part::<usize>::merge(dir.path(), "work"), Err(PartError::Read { .. })));
        assert!(Part::<usize>::merge(dir.path(), "other").unwrap_err().to_string().contains("no parts"));
    }
}
