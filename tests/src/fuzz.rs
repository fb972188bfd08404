//! Damage for fuzzing the files the project reads (bundle manifests, world files, training configs): a
//! document's value tree with one node replaced or removed, or its text cut short or one bit flipped.
//! `FASTRACK_FUZZ_CASES` sets the cases of every fuzz test (a long run raises it).

use proptest::prelude::*;
use serde_json::Value;

/// Cases per fuzz test: `FASTRACK_FUZZ_CASES`, else `default`.
pub fn cases(default: u32) -> u32 {
    std::env::var("FASTRACK_FUZZ_CASES").ok().and_then(|v| v.parse().ok()).unwrap_or(default)
}

/// One change to a document.
#[derive(Debug, Clone)]
pub enum Damage {
    /// The `pick`-th node (modulo the number of nodes, in document order; the root is never picked)
    /// replaced by `value`.
    Replace {
        /// Which node.
        pick: usize,
        /// What it becomes.
        value: Value,
    },
    /// The `pick`-th node removed from its object or array.
    Remove {
        /// Which node.
        pick: usize,
    },
    /// The text cut to this share of its bytes.
    Truncate {
        /// Share kept, in [0, 1).
        share: f64,
    },
    /// One bit of the text flipped.
    FlipBit {
        /// Where, as a share of the text's bytes.
        share: f64,
        /// Which bit of that byte.
        bit: u8,
    },
}

/// Numbers a file might hold by mistake or malice: ordinary, negative, zero, huge, tiny, integral extremes.
fn odd_number() -> impl Strategy<Value = Value> {
    prop_oneof![
        (-10.0..10.0f64).prop_map(Value::from),
        Just(Value::from(0)),
        Just(Value::from(-1)),
        Just(Value::from(f64::MAX)),
        Just(Value::from(-f64::MAX)),
        Just(Value::from(f64::MIN_POSITIVE / 8.0)),
        Just(Value::from(1e300)),
        Just(Value::from(i64::MAX)),
        Just(Value::from(u64::MAX)),
        Just(Value::from(i64::MIN)),
        (0u64..100_000).prop_map(Value::from),
    ]
}

/// A value of any kind: numbers, strings (empty, long, unicode), booleans, null, arrays and objects.
pub fn odd_value() -> impl Strategy<Value = Value> {
    let leaf = prop_oneof![
        4 => odd_number(),
        1 => Just(Value::Null),
        1 => any::<bool>().prop_map(Value::from),
        1 => "[a-z_]{0,8}".prop_map(Value::from),
        1 => Just(Value::from("é∞\u{0}\u{202e}")),
        1 => Just(Value::from("x".repeat(10_000))),
    ];
    leaf.prop_recursive(2, 16, 4, |inner| {
        prop_oneof![
            prop::collection::vec(inner.clone(), 0..4).prop_map(Value::from),
            prop::collection::btree_map("[a-z_]{1,8}", inner, 0..3)
                .prop_map(|m| Value::Object(m.into_iter().collect())),
        ]
    })
}

/// Any one [`Damage`], tree changes three times as often as text changes.
pub fn damage() -> impl Strategy<Value = Damage> {
    prop_oneof![
        4 => (any::<usize>(), odd_value()).prop_map(|(pick, value)| Damage::Replace { pick, value }),
        2 => any::<usize>().prop_map(|pick| Damage::Remove { pick }),
        1 => (0.0..1.0f64).prop_map(|share| Damage::Truncate { share }),
        1 => (0.0..1.0f64, 0u8..8).prop_map(|(share, bit)| Damage::FlipBit { share, bit }),
    ]
}

/// Every node below the root, in document order, as paths of keys and indices.
fn node_paths(value: &Value, prefix: &mut Vec<Step>, out: &mut Vec<Vec<Step>>) {
    let children: Vec<(Step, &Value)> = match value {
        Value::Object(map) => map.iter().map(|(k, v)| (Step::Key(k.clone()), v)).collect(),
        Value::Array(items) => items.iter().enumerate().map(|(i, v)| (Step::Index(i), v)).collect(),
        _ => Vec::new(),
    };
    for (step, child) in children {
        prefix.push(step);
        out.push(prefix.clone());
        node_paths(child, prefix, out);
        prefix.pop();
    }
}

#[derive(Debug, Clone)]
enum Step {
    Key(String),
    Index(usize),
}

/// The parent of the node at `path` and the node's last step.
fn parent_mut<'a>(root: &'a mut Value, path: &[Step]) -> (&'a mut Value, Step) {
    let (last, above) = path.split_last().expect("a node below the root");
    let parent = above.iter().fold(root, |node, step| match step {
        Step::Key(k) => &mut node[k.as_str()],
        Step::Index(i) => &mut node[*i],
    });
    (parent, last.clone())
}

impl Damage {
    /// The damaged bytes of the document `tree`, written by `write` (which may fail, e.g. TOML has no null:
    /// then the damaged tree is written as JSON, itself a damage for a TOML reader).
    pub fn apply(&self, tree: &Value, write: impl Fn(&Value) -> Option<String>) -> Vec<u8> {
        let text = |tree: &Value| write(tree).unwrap_or_else(|| tree.to_string());
        match self {
            Damage::Replace { pick, .. } | Damage::Remove { pick } => {
                let mut paths = Vec::new();
                node_paths(tree, &mut Vec::new(), &mut paths);
                let mut damaged = tree.clone();
                if let Some(path) = paths.get(pick % paths.len().max(1)) {
                    let (parent, last) = parent_mut(&mut damaged, path);
                    match (self, last) {
                        (Damage::Replace { value, .. }, Step::Key(k)) => parent[k.as_str()] = value.clone(),
                        (Damage::Replace { value, .. }, Step::Index(i)) => parent[i] = value.clone(),
                        (_, Step::Key(k)) => {
                            parent.as_object_mut().map(|map| map.remove(&k));
                        }
                        (_, Step::Index(i)) => {
                            parent.as_array_mut().map(|items| items.remove(i));
                        }
                    }
                }
                text(&damaged).into_bytes()
            }
            Damage::Truncate { share } => {
                let bytes = text(tree).into_bytes();
                bytes[..(share * bytes.len() as f64) as usize].to_vec()
            }
            Damage::FlipBit { share, bit } => {
                let mut bytes = text(tree).into_bytes();
                let at = ((share * bytes.len() as f64) as usize).min(bytes.len().saturating_sub(1));
                if let Some(byte) = bytes.get_mut(at) {
                    *byte ^= 1 << bit;
                }
                bytes
            }
        }
    }

    /// A short label of the kind of damage, for counting outcomes per kind.
    pub fn kind(&self) -> &'static str {
        match self {
            Damage::Replace { .. } => "replace",
            Damage::Remove { .. } => "remove",
            Damage::Truncate { .. } => "truncate",
            Damage::FlipBit { .. } => "flip",
        }
    }
}

/// TOML text of a value tree, if TOML can hold it.
pub fn toml_text(tree: &Value) -> Option<String> {
    toml::to_string(tree).ok()
}

/// Pretty JSON text of a value tree.
pub fn json_text(tree: &Value) -> Option<String> {
    serde_json::to_string_pretty(tree).ok()
}

/// Outcomes of a fuzz target's cases, by kind of input: accepted (answered, loaded, read) or refused.
pub struct Tally {
    target: &'static str,
    cases: u32,
    started: std::time::Instant,
    outcomes: std::collections::BTreeMap<String, (u32, u32)>,
}

impl Tally {
    /// An empty tally of `target`'s run of `cases` cases per property.
    pub fn new(target: &'static str, cases: u32) -> Self {
        Self { target, cases, started: std::time::Instant::now(), outcomes: Default::default() }
    }

    /// Counts one case of `kind`.
    pub fn count(&mut self, kind: impl Into<String>, accepted: bool) {
        let entry = self.outcomes.entry(kind.into()).or_default();
        if accepted {
            entry.0 += 1;
        } else {
            entry.1 += 1;
        }
    }

    /// Accepted and refused cases over every kind starting with `prefix`.
    pub fn outcomes(&self, prefix: &str) -> (u32, u32) {
        self.outcomes.iter().filter(|(k, _)| k.starts_with(prefix)).fold((0, 0), |(a, r), (_, (x, y))| (a + x, r + y))
    }

    /// Asserts that the kinds starting with `prefix` were both accepted and refused: a property that only
    /// ever sees one outcome checks little.
    pub fn assert_both(&self, prefix: &str) {
        let (accepted, refused) = self.outcomes(prefix);
        assert!(
            accepted > 0 && refused > 0,
            "{}: `{prefix}` {accepted} accepted, {refused} refused; the draws check little",
            self.target
        );
    }

    /// Prints the tally; with `FASTRACK_FUZZ_RECORD=<name>` also writes this target's section of the record
    /// `bench/results/<name>.{json,md}` (written only after every case passed: a long run's evidence of no
    /// panic and no wrong answer), keeping the other targets' sections. Test binaries that share a record
    /// run one after another (each binary's own tests may run at once).
    pub fn report(&self) {
        eprintln!("{}: accepted / refused per kind: {:?}", self.target, self.outcomes);
        let Ok(name) = std::env::var("FASTRACK_FUZZ_RECORD") else { return };
        static ONE_WRITER: std::sync::Mutex<()> = std::sync::Mutex::new(());
        let _writing = ONE_WRITER.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../bench/results");
        let earlier: Value = std::fs::read_to_string(dir.join(format!("{name}.json")))
            .ok()
            .and_then(|text| serde_json::from_str(&text).ok())
            .unwrap_or_default();
        let section = |key: &str| earlier.get(key).and_then(Value::as_object).cloned().unwrap_or_default();
        let (mut config, mut figures) = (section("config"), section("figures"));
        let (accepted, refused) = self.outcomes("");
        config.insert(self.target.into(), serde_json::json!({ "cases_per_property": self.cases }));
        figures.insert(
            self.target.into(),
            serde_json::json!({
                "cases": accepted + refused, "accepted": accepted, "refused": refused, "failures": 0,
                "wall_s": self.started.elapsed().as_secs_f64(),
                "outcomes": self.outcomes.iter().map(|(k, (a, r))| (k.clone(), serde_json::json!([a, r]))).collect::<serde_json::Map<_, _>>(),
                "source_revision": fastrack_lab::provenance::source_revision(),
            }),
        );
        let tables: Vec<(String, fastrack_lab::record::MarkdownTable)> = figures
            .iter()
            .map(|(target, figures)| (format!("{target}: cases per kind"), outcome_table(&figures["outcomes"])))
            .collect();
        let command = format!(
            "FASTRACK_FUZZ_CASES=<cases> FASTRACK_FUZZ_RECORD={name} cargo test -p fastrack-e2e --test fuzzed_*"
        );
        let tables: Vec<(&str, &fastrack_lab::record::MarkdownTable)> =
            tables.iter().map(|(title, table)| (title.as_str(), table)).collect();
        fastrack_lab::record::write_record(&dir, &name, &command, config.into(), figures.into(), &tables)
            .expect("write the fuzz record");
    }
}

/// Accepted and refused cases per kind (`{"kind": [accepted, refused]}`), with a total row.
fn outcome_table(outcomes: &Value) -> fastrack_lab::record::MarkdownTable {
    let mut table = fastrack_lab::record::MarkdownTable::new(&["kind", "accepted", "refused"]);
    let (mut all_accepted, mut all_refused) = (0, 0);
    for (kind, counts) in outcomes.as_object().into_iter().flatten() {
        let count = |i: usize| counts.get(i).and_then(Value::as_u64).unwrap_or(0);
        (all_accepted, all_refused) = (all_accepted + count(0), all_refused + count(1));
        table.row(vec![kind.clone(), count(0).to_string(), count(1).to_string()]);
    }
    table.row(vec!["all".into(), all_accepted.to_string(), all_refused.to_string()]);
    table
}
