//! Docs that cannot rot: every shell block in the README, `CONTRIBUTING.md`, `docs/` and the crate READMEs
//! is run, or has its commands' arguments parsed by the real binaries, or is checked to be what CI runs;
//! and every relative link resolves inside the repository.
//!
//! A fenced block's info string says which:
//! - `sh`: run (bash, repository root, one bash per file with its blocks in order, the workspace's binaries
//!   and `.cache/tools/bin` first on `PATH`); background jobs are killed at the end of the file.
//! - `sh long`: too long for CI (training, full-size solves, benchmarks): each command's arguments are parsed
//!   by the binary it names (`<command> ... --help` must succeed), `cargo` commands must name workspace
//!   packages and test targets that exist, `bash <script>` scripts that exist.
//! - `sh ci`: the commands CI runs itself; each must appear in `.ci/run` or a script under `scripts/`.
//! - `sh hardware`: needs hardware CI lacks (a GPU, a Docker engine, a cluster); not run.
//! - any other language (`toml`, `json`, `text`, `proto`, `rust`, `python`) is not a shell command.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// How long the quick blocks of one file may take together.
const FILE_LIMIT: Duration = Duration::from_secs(300);

/// Binaries a `sh long` command may name, by the package that builds them.
const BINARIES: [(&str, &str); 4] = [
    ("fastrack-grid", "fastrack-grid"),
    ("fastrack-trainer", "fastrack-trainer"),
    ("fastrack-server", "fastrack-server"),
    ("fastrack-cli", "fastrack"),
];

/// Info strings that are not shell.
const OTHER_LANGUAGES: [&str; 8] = ["toml", "json", "text", "proto", "rust", "python", "yaml", "dockerfile"];

fn repository() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).parent().expect("the workspace root").to_path_buf()
}

/// One fenced block.
struct Block {
    file: PathBuf,
    line: usize,
    info: String,
    body: String,
}

/// The documentation files: README.md, CONTRIBUTING.md, docs/**/*.md and every README one folder down.
fn documents() -> Vec<PathBuf> {
    let root = repository();
    let mut files = vec![root.join("README.md"), root.join("CONTRIBUTING.md")];
    let mut stack = vec![root.join("docs")];
    while let Some(dir) = stack.pop() {
        for entry in std::fs::read_dir(&dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display())) {
            let path = entry.expect("directory entry").path();
            if path.is_dir() {
                stack.push(path);
            } else if path.extension().is_some_and(|x| x == "md") {
                files.push(path);
            }
        }
    }
    for entry in std::fs::read_dir(&root).expect("the repository") {
        let readme = entry.expect("directory entry").path().join("README.md");
        if readme.is_file() && !readme.starts_with(root.join("docs")) {
            files.push(readme);
        }
    }
    files.push(root.join("bench/results/README.md"));
    files.sort();
    files.dedup();
    files
}

/// The fenced blocks of a markdown file (fences may be indented, as in list items).
fn blocks(file: &Path) -> Vec<Block> {
    let text = std::fs::read_to_string(file).unwrap_or_else(|e| panic!("{}: {e}", file.display()));
    let mut out = Vec::new();
    let mut open: Option<Block> = None;
    for (i, line) in text.lines().enumerate() {
        match (&mut open, line.trim_start().strip_prefix("```")) {
            (None, Some(info)) => {
                open = Some(Block { file: file.into(), line: i + 1, info: info.trim().into(), body: String::new() })
            }
            (Some(_), Some(rest)) if rest.trim().is_empty() => out.extend(open.take()),
            (Some(block), _) => {
                block.body.push_str(line);
                block.body.push('\n');
            }
            (None, None) => {}
        }
    }
    assert!(open.is_none(), "{}: a code fence is never closed", file.display());
    out
}

fn all_blocks() -> Vec<Block> {
    documents().iter().flat_map(|f| blocks(f)).collect()
}

fn place(block: &Block) -> String {
    format!("{}:{}", block.file.strip_prefix(repository()).unwrap_or(&block.file).display(), block.line)
}

/// The commands of a block: continuation lines joined, comments and blank lines dropped.
fn commands(body: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut current = String::new();
    for line in body.lines() {
        let line = line.trim();
        if current.is_empty() && (line.is_empty() || line.starts_with('#')) {
            continue;
        }
        match line.strip_suffix('\\') {
            Some(head) => {
                current.push_str(head);
                current.push(' ');
            }
            None => {
                current.push_str(line);
                out.push(std::mem::take(&mut current));
            }
        }
    }
    out
}

/// Splits a simple command into words (single and double quotes; no expansions).
fn words(command: &str) -> Result<Vec<String>, String> {
    let mut out = Vec::new();
    let mut word = String::new();
    let mut in_word = false;
    let mut chars = command.chars().peekable();
    while let Some(c) = chars.next() {
        match c {
            '\'' | '"' => {
                in_word = true;
                loop {
                    match chars.next() {
                        Some(q) if q == c => break,
                        Some(x) => word.push(x),
                        None => return Err("an unclosed quote".into()),
                    }
                }
            }
            ' ' | '\t' => {
                if in_word {
                    out.push(std::mem::take(&mut word));
                    in_word = false;
                }
            }
            '|' | ';' | '&' | '>' | '<' | '`' | '(' | ')' => {
                return Err(format!("`{c}`: a long block holds simple commands only (no pipes, lists, redirections)"))
            }
            '$' if chars.peek() == Some(&'(') => return Err("no command substitution in a long block".into()),
            _ => {
                in_word = true;
                word.push(c);
            }
        }
    }
    if in_word {
        out.push(word);
    }
    Ok(out)
}

/// The test targets (`tests/*.rs`) of the workspace package `package`, or of every member for `None`;
/// `None` if no member is called `package`.
fn workspace_tests(package: Option<&str>) -> Option<Vec<String>> {
    let root = repository();
    let manifest = std::fs::read_to_string(root.join("Cargo.toml")).expect("Cargo.toml");
    let members = manifest.lines().find(|l| l.starts_with("members")).expect("a members line");
    let mut found = None;
    for folder in members.split('"').skip(1).step_by(2) {
        let text = std::fs::read_to_string(root.join(folder).join("Cargo.toml")).unwrap_or_default();
        if package.is_some_and(|p| !text.contains(&format!("name = \"{p}\""))) {
            continue;
        }
        let tests = found.get_or_insert_with(Vec::new);
        if let Ok(dir) = std::fs::read_dir(root.join(folder).join("tests")) {
            tests.extend(dir.filter_map(|e| e.ok()?.path().file_stem().map(|s| s.to_string_lossy().into_owned())));
        }
    }
    found
}

/// Checks one `sh long` command; `Err` says what is wrong.
fn check_long_command(command: &str) -> Result<(), String> {
    let mut words = words(command)?;
    while words.first().is_some_and(|w| w.contains('=') && !w.starts_with('-')) {
        words.remove(0);
    }
    let Some(program) = words.first().cloned() else { return Err("an empty command".into()) };
    let (binary, args): (&str, Vec<String>) = match program.as_str() {
        "cargo" => {
            let package = words.iter().position(|w| w == "-p").and_then(|i| words.get(i + 1)).cloned();
            let tests = workspace_tests(package.as_deref())
                .ok_or_else(|| format!("`-p {}` is not a workspace package", package.as_deref().unwrap_or_default()))?;
            if let Some(test) = words.iter().position(|w| w == "--test").and_then(|i| words.get(i + 1)) {
                if !tests.contains(test) {
                    return Err(format!(
                        "no test target `{test}` in {}",
                        package.as_deref().unwrap_or("the workspace")
                    ));
                }
            }
            if words.get(1).map(String::as_str) != Some("run") {
                return Ok(());
            }
            let package = package.ok_or("`cargo run` needs `-p <package>`")?;
            let binary = BINARIES
                .iter()
                .find(|(p, _)| *p == package)
                .map(|(_, b)| *b)
                .ok_or_else(|| format!("`cargo run -p {package}`: not a package with a binary"))?;
            let args = match words.iter().position(|w| w == "--") {
                Some(i) => words[i + 1..].to_vec(),
                None => Vec::new(),
            };
            (binary, args)
        }
        "bash" => {
            let script = words.get(1).ok_or("`bash` without a script")?;
            return if repository().join(script).is_file() { Ok(()) } else { Err(format!("no script {script}")) };
        }
        name => match BINARIES.iter().find(|(_, b)| *b == name) {
            Some((_, b)) => (*b, words[1..].to_vec()),
            None => return Err(format!("`{name}` is not a workspace binary, cargo or a script")),
        },
    };
    let output = Command::new(fastrack_e2e::binary(binary))
        .args(&args)
        .arg("--help")
        .current_dir(repository())
        .output()
        .map_err(|e| format!("running {binary}: {e}"))?;
    if output.status.success() {
        Ok(())
    } else {
        Err(format!("{binary} does not accept these arguments:\n{}", String::from_utf8_lossy(&output.stderr)))
    }
}

#[test]
fn every_block_says_what_it_is() {
    let mut bad = Vec::new();
    for block in all_blocks() {
        let known = match block.info.split_whitespace().collect::<Vec<_>>()[..] {
            ["sh"] | ["sh", "long" | "ci" | "hardware"] => true,
            [language] => OTHER_LANGUAGES.contains(&language),
            _ => false,
        };
        if !known {
            bad.push(format!("{}: info string {:?}", place(&block), block.info));
        }
    }
    assert!(
        bad.is_empty(),
        "fenced blocks must say `sh`, `sh long`, `sh ci`, `sh hardware` or one of {OTHER_LANGUAGES:?}:\n{}",
        bad.join("\n")
    );
}

#[test]
fn long_commands_parse() {
    let mut bad = Vec::new();
    let mut checked = 0;
    for block in all_blocks().iter().filter(|b| b.info == "sh long") {
        for command in commands(&block.body) {
            checked += 1;
            if let Err(problem) = check_long_command(&command) {
                bad.push(format!("{}: `{command}`: {problem}", place(block)));
            }
        }
    }
    assert!(checked > 0, "no long commands found: the block parser is broken");
    assert!(bad.is_empty(), "long commands that would fail:\n{}", bad.join("\n\n"));
}

#[test]
fn ci_commands_are_what_ci_runs() {
    let root = repository();
    let mut ci = std::fs::read_to_string(root.join(".ci/run")).expect(".ci/run");
    for entry in std::fs::read_dir(root.join("scripts")).expect("scripts/") {
        ci += &std::fs::read_to_string(entry.expect("entry").path()).unwrap_or_default();
    }
    let mut bad = Vec::new();
    for block in all_blocks().iter().filter(|b| b.info == "sh ci") {
        for command in commands(&block.body) {
            if !ci.lines().any(|line| line.trim() == command) {
                bad.push(format!("{}: `{command}`", place(block)));
            }
        }
    }
    assert!(bad.is_empty(), "marked `sh ci` but not run by .ci/run or scripts/:\n{}", bad.join("\n"));
}

#[test]
fn quick_commands_run() {
    let root = repository();
    let binaries = fastrack_e2e::server_binary().parent().expect("target/<profile>").to_path_buf();
    let path = format!(
        "{}:{}:{}",
        binaries.display(),
        root.join(".cache/tools/bin").display(),
        std::env::var("PATH").unwrap_or_default()
    );
    let mut ran = 0;
    for file in documents() {
        let quick: Vec<Block> = blocks(&file).into_iter().filter(|b| b.info == "sh").collect();
        if quick.is_empty() {
            continue;
        }
        let mut script = String::from("set -euo pipefail\ntrap 'kill $(jobs -p) 2>/dev/null || true' EXIT\n");
        for block in &quick {
            script += &format!("echo '>>> {}'\n{}", place(block), block.body);
            ran += 1;
        }
        // Output goes to a file, not a pipe: a chatty background server must never block on a full pipe.
        let log = tempfile::NamedTempFile::new().expect("a log file");
        let out = log.reopen().expect("the log file");
        let start = Instant::now();
        let mut child = Command::new("bash")
            .arg("-c")
            .arg(&script)
            .current_dir(&root)
            .env("PATH", &path)
            .stdin(Stdio::null())
            .stdout(out.try_clone().expect("the log for stdout"))
            .stderr(out)
            .spawn()
            .expect("bash runs");
        let status = loop {
            if let Some(status) = child.try_wait().expect("wait") {
                break status;
            }
            if start.elapsed() > FILE_LIMIT {
                let _ = child.kill();
                let output = std::fs::read_to_string(log.path()).unwrap_or_default();
                panic!("{}: the quick blocks ran past {FILE_LIMIT:?}; output:\n{output}", file.display());
            }
            std::thread::sleep(Duration::from_millis(50));
        };
        let output = std::fs::read_to_string(log.path()).unwrap_or_default();
        assert!(status.success(), "{}: a quick block failed ({status}); output:\n{output}", file.display());
    }
    assert!(ran > 0, "no quick blocks found: the block parser is broken");
}

#[test]
fn relative_links_resolve_inside_the_repository() {
    let root = repository();
    let mut bad = Vec::new();
    for file in documents() {
        let text = std::fs::read_to_string(&file).expect("readable");
        let mut in_code = false;
        for (i, line) in text.lines().enumerate() {
            if line.trim_start().starts_with("```") {
                in_code = !in_code;
            }
            if in_code {
                continue;
            }
            for target in line.split("](").skip(1).filter_map(|rest| rest.split(')').next()) {
                let target = target.split_whitespace().next().unwrap_or_default();
                if target.starts_with("http://") || target.starts_with("https://") || target.starts_with('#') {
                    continue;
                }
                let path = target.split('#').next().unwrap_or_default();
                let resolved = file.parent().expect("a folder").join(path);
                let inside = resolved.canonicalize().map(|p| p.starts_with(&root));
                if !matches!(inside, Ok(true)) {
                    bad.push(format!("{}:{}: {target}", file.strip_prefix(&root).unwrap_or(&file).display(), i + 1));
                }
            }
        }
    }
    assert!(bad.is_empty(), "links that do not resolve to a file of the repository:\n{}", bad.join("\n"));
}

#[test]
fn the_block_parser_finds_commands_and_refuses_compound_ones() {
    assert_eq!(
        commands("# a comment\ncargo run -p x -- a \\\n  --b 1\n\nfastrack models\n"),
        ["cargo run -p x -- a  --b 1", "fastrack models"]
    );
    assert_eq!(
        words("fastrack-grid solve --beta '0.5' \"a b\"").unwrap(),
        ["fastrack-grid", "solve", "--beta", "0.5", "a b"]
    );
    assert!(words("for b in 1 2; do x; done").is_err());
    assert!(words("a | b").is_err());
    assert!(check_long_command("fastrack-grid solve --no-such-flag 1").is_err());
    assert!(check_long_command("cargo test -p no-such-package").is_err());
    assert!(check_long_command("cargo test --workspace --test no_such_test").is_err());
    assert!(check_long_command("cargo test --workspace --test docs_commands").is_ok());
}
