//! Measurement records (bench/results/README.md): `bench/results/<name>.json` (what ran, the exact command, config,
//! machine, date, revision, figures) and a markdown table beside it.

use crate::provenance::{machine_description, source_revision, utc_now_rfc3339};
use serde_json::{json, Value};
use std::path::{Path, PathBuf};

/// A markdown table.
#[derive(Debug, Clone, PartialEq)]
pub struct MarkdownTable {
    /// Column headers.
    pub header: Vec<String>,
    /// Rows of cells.
    pub rows: Vec<Vec<String>>,
}

impl MarkdownTable {
    /// A table with these headers.
    pub fn new(header: &[&str]) -> Self {
        Self { header: header.iter().map(|s| s.to_string()).collect(), rows: Vec::new() }
    }

    /// Appends a row; it must have one cell per column.
    pub fn row(&mut self, cells: Vec<String>) {
        assert_eq!(
            cells.len(),
            self.header.len(),
            "a row of {} cells in a table of {} columns",
            cells.len(),
            self.header.len()
        );
        self.rows.push(cells);
    }

    /// GitHub-flavoured markdown.
    pub fn to_markdown(&self) -> String {
        let line = |cells: &[String]| format!("| {} |", cells.join(" | "));
        let mut out =
            vec![line(&self.header), line(&self.header.iter().map(|_| "---".to_string()).collect::<Vec<_>>())];
        out.extend(self.rows.iter().map(|r| line(r)));
        out.join("\n") + "\n"
    }
}

/// Writes `<dir>/<name>.json` and `<dir>/<name>.md`; returns the JSON path.
pub fn write_record(
    dir: &Path,
    name: &str,
    command: &str,
    config: Value,
    figures: Value,
    tables: &[(&str, &MarkdownTable)],
) -> std::io::Result<PathBuf> {
    std::fs::create_dir_all(dir)?;
    let (machine, date, revision) = (machine_description(), utc_now_rfc3339(), source_revision());
    let record = json!({
        "name": name, "command": command, "config": config, "machine": machine, "date": date,
        "source_revision": revision, "figures": figures,
    });
    let json_path = dir.join(format!("{name}.json"));
    std::fs::write(&json_path, serde_json::to_string_pretty(&record)? + "\n")?;
    let mut md = format!("# {name}\n\n`{command}`\n\n{machine}, {date}, revision {revision}\n");
    for (title, table) in tables {
        md += &format!("\n## {title}\n\n{}", table.to_markdown());
    }
    std::fs::write(dir.join(format!("{name}.md")), md)?;
    Ok(json_path)
}
