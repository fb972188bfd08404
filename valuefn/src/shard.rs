//! Shards of batch work: `--shard INDEX/COUNT` splits a list of items (worlds of a benchmark, rows of a
//! table) among `COUNT` independent processes, for example the pods of a Kubernetes Indexed Job; a merge
//! combines their parts into what a single run gives. `--shard COUNT` alone takes the index from
//! `JOB_COMPLETION_INDEX`, which Kubernetes sets in each pod of an Indexed Job.

use serde::{Deserialize, Serialize};
use std::fmt;
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
}
