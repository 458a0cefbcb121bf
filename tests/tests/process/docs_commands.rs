//! The documentation shows only what the binaries take: every `navsync` and `navsync-bench`
//! command in `README.md` and `docs/**/*.md` names subcommands that exist and flags that those
//! subcommands accept, read from the binaries' own `--help`.
//!
//! * A command line of a shell code block (a fence labelled `sh`, `bash`, `shell`, `console` or
//!   not labelled; `sudo`, `env`, `VAR=value`, `ExecStart=` and `cargo run … --` in front of
//!   it understood) is checked flag by flag, and also run with its own arguments and `--help`
//!   appended: clap rejects an unknown flag or a value it cannot parse (a baud rate, an enum)
//!   before it reaches `--help`, and prints the help without starting anything otherwise.
//! * `navsync …` in inline code (the tables' synopses, `[--baud N|auto]`) is checked flag by
//!   flag; alternatives (`ipc|e2e`) must each be a subcommand that takes the flags shown.
//! * Every `toml` code block is a configuration file: `navsync --config FILE check-config`
//!   must accept it.
//! * Every repository path in inline code (`tests/tests/live/demo.rs`) and every relative link
//!   (`[x](../guide/install.md#staging)`, its anchor among the target's headings) exists.
//!
//! It runs the binaries only with `--help` and `check-config` (no services, no devices), in a
//! process of its own like every test of this binary.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;

use navsync_tests::TestEnv;

/// The repository's root (the parent of the `tests` crate).
fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("repository root")
        .to_path_buf()
}

/// `README.md` and every `*.md` under `docs/`, as paths relative to the repository.
fn markdown_files() -> Vec<PathBuf> {
    let root = repo();
    let mut out = vec![PathBuf::from("README.md")];
    let mut dirs = vec![PathBuf::from("docs")];
    while let Some(d) = dirs.pop() {
        let rd = std::fs::read_dir(root.join(&d)).unwrap_or_else(|e| panic!("{}: {e}", d.display()));
        for e in rd.flatten() {
            let rel = d.join(e.file_name());
            if e.path().is_dir() {
                dirs.push(rel);
            } else if rel.extension().is_some_and(|x| x == "md") {
                out.push(rel);
            }
        }
    }
    out.sort();
    out
}

/// A fenced code block: its language tag and its lines with their line numbers (1-based).
struct Fence {
    lang: String,
    lines: Vec<(usize, String)>,
}

/// A markdown file split into its fenced blocks and its prose (fenced lines blanked, so that
/// offsets still give line numbers).
struct Doc {
    path: PathBuf,
    fences: Vec<Fence>,
    prose: String,
}

fn parse_doc(path: &Path, text: &str) -> Doc {
    let mut fences = Vec::new();
    let mut prose = String::new();
    let mut open: Option<Fence> = None;
    for (i, line) in text.lines().enumerate() {
        let trimmed = line.trim_start();
        if let Some(tag) = trimmed.strip_prefix("```") {
            match open.take() {
                Some(f) => fences.push(f),
                None => {
                    open = Some(Fence {
                        lang: tag.trim().to_string(),
                        lines: Vec::new(),
                    })
                }
            }
            prose.push('\n');
            continue;
        }
        match &mut open {
            Some(f) => {
                f.lines.push((i + 1, line.to_string()));
                prose.push('\n');
            }
            None => {
                prose.push_str(line);
                prose.push('\n');
            }
        }
    }
    assert!(open.is_none(), "{}: a code block is not closed", path.display());
    Doc {
        path: path.to_path_buf(),
        fences,
        prose,
    }
}

fn line_of(text: &str, offset: usize) -> usize {
    text[..offset].matches('\n').count() + 1
}

/// Which binary a command runs.
#[derive(Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Debug)]
enum Prog {
    Navsync,
    Bench,
}

impl Prog {
    fn name(self) -> &'static str {
        match self {
            Prog::Navsync => "navsync",
            Prog::Bench => "navsync-bench",
        }
    }

    fn bin(self) -> PathBuf {
        match self {
            Prog::Navsync => navsync_tests::navsync_bin(),
            Prog::Bench => navsync_tests::bench_bin(),
        }
    }

    /// `navsync`, `target/release/navsync`, `/usr/local/bin/navsync`, … (likewise the bench).
    fn of_word(word: &str) -> Option<Prog> {
        match word.rsplit('/').next() {
            Some("navsync") => Some(Prog::Navsync),
            Some("navsync-bench") => Some(Prog::Bench),
            _ => None,
        }
    }
}

/// What one (sub)command's `--help` says.
#[derive(Default)]
struct Help {
    /// Long and short flags, with their visible aliases.
    flags: BTreeSet<String>,
    /// The flags that take a value (`--port <PORT>`, `--watch [<S>]`).
    valued: BTreeSet<String>,
    /// Subcommands and their visible aliases.
    subcommands: BTreeSet<String>,
}

/// The aliases of a help line: `[alias: gps]`, `[aliases: a, b]`.
fn aliases(line: &str) -> Vec<String> {
    let mut out = Vec::new();
    for key in ["[alias: ", "[aliases: "] {
        let mut rest = line;
        while let Some(i) = rest.find(key) {
            rest = &rest[i + key.len()..];
            let end = rest.find(']').unwrap_or(rest.len());
            out.extend(rest[..end].split(',').map(|a| a.trim().to_string()));
            rest = &rest[end..];
        }
    }
    out
}

fn parse_help(text: &str) -> Help {
    let mut h = Help::default();
    let mut section = "";
    for line in text.lines() {
        let indent = line.len() - line.trim_start().len();
        let trimmed = line.trim();
        if indent == 0 {
            if trimmed.ends_with(':') {
                section = trimmed;
            }
            continue;
        }
        if section == "Commands:" && indent == 2 {
            if let Some(name) = trimmed.split_whitespace().next() {
                h.subcommands.insert(name.to_string());
            }
            h.subcommands.extend(aliases(line));
            continue;
        }
        // A flag line: `  -v, --verbose …`, `      --port <PORT> …`; descriptions are indented
        // further (long help) or follow on the same line.
        if indent > 6 || !trimmed.starts_with('-') {
            continue;
        }
        let words: Vec<&str> = trimmed.split_whitespace().collect();
        let mut names = Vec::new();
        let mut i = 0;
        while let Some(w) = words.get(i) {
            let w = w.trim_end_matches(',');
            if !w.starts_with('-') {
                break;
            }
            names.push(w.to_string());
            i += 1;
        }
        let takes_value = words.get(i).is_some_and(|w| w.starts_with('<') || w.starts_with("[<"));
        for n in &names {
            if takes_value {
                h.valued.insert(n.clone());
            }
            h.flags.insert(n.clone());
        }
        for a in aliases(line).into_iter().filter(|a| a.starts_with('-')) {
            if takes_value {
                h.valued.insert(a.clone());
            }
            h.flags.insert(a);
        }
    }
    h
}

/// The binaries' help texts, read once per (sub)command.
#[derive(Default)]
struct Helps {
    cache: HashMap<(Prog, Vec<String>), Option<Help>>,
}

impl Helps {
    /// `PROG PATH… --help`, or `None` when that is not a command.
    fn get(&mut self, prog: Prog, path: &[String]) -> Option<&Help> {
        self.cache
            .entry((prog, path.to_vec()))
            .or_insert_with(|| {
                let out = Command::new(prog.bin())
                    .args(path)
                    .arg("--help")
                    .env("RUST_LOG", "warn")
                    .output()
                    .unwrap_or_else(|e| panic!("{}: {e}", prog.bin().display()));
                out.status
                    .success()
                    .then(|| parse_help(&String::from_utf8_lossy(&out.stdout)))
            })
            .as_ref()
    }
}

/// Where a command was found, for the failure message.
struct Origin<'a> {
    file: &'a Path,
    line: usize,
    text: &'a str,
}

impl Origin<'_> {
    fn say(&self, what: &str) -> String {
        format!(
            "{}:{}: {what}\n    in: {}",
            self.file.display(),
            self.line,
            self.text.trim()
        )
    }
}

/// Walks `args` of `prog`: each word that is not a flag or a flag's value descends into a
/// subcommand while the command has subcommands (`a|b` descends into each); every flag must be
/// one the command it follows accepts. `inline`: the words are a synopsis (`[--baud N|auto]`,
/// `--estimate|--record FILE`, `…`), so flags are picked out of each word.
fn check_words(
    helps: &mut Helps,
    prog: Prog,
    args: &[String],
    inline: bool,
    origin: &Origin,
    errors: &mut Vec<String>,
) {
    let mut paths: Vec<Vec<String>> = vec![Vec::new()];
    let mut i = 0;
    while i < args.len() {
        let word = args[i].as_str();
        i += 1;
        let flags: Vec<String> = if inline {
            flags_in(word)
        } else if word.starts_with('-')
            && word.len() > 1
            && word != "--"
            && !word[1..].starts_with(|c: char| c.is_ascii_digit())
        {
            vec![word.split('=').next().unwrap_or(word).to_string()]
        } else {
            Vec::new()
        };
        if !flags.is_empty() {
            let mut takes_value = false;
            for path in &paths {
                let Some(help) = helps.get(prog, path) else { continue };
                for f in &flags {
                    if help.flags.contains(f) {
                        takes_value |= help.valued.contains(f);
                    } else {
                        errors.push(origin.say(&format!("`{}` has no flag {f}", shown(prog, path))));
                    }
                }
            }
            // `--flag VALUE` (not `--flag=VALUE`, and not a synopsis' `--a|--b`).
            let last = word.rsplit('|').next().unwrap_or(word);
            if takes_value && !last.contains('=') && i < args.len() && !args[i].starts_with('-') {
                i += 1;
            }
            continue;
        }
        let bare = word.trim_matches(|c: char| "[]()…,;.".contains(c));
        if bare.is_empty() {
            continue;
        }
        let has_subcommands = paths
            .iter()
            .all(|p| helps.get(prog, p).is_some_and(|h| !h.subcommands.is_empty()));
        if !has_subcommands {
            continue; // a positional argument
        }
        if bare.chars().all(|c| c.is_ascii_uppercase() || c == '_') {
            return; // `navsync SUBCOMMAND --help`: any subcommand, its flags unknown
        }
        let mut next = Vec::new();
        for path in &paths {
            for alt in bare.split('|') {
                let known = helps.get(prog, path).is_some_and(|h| h.subcommands.contains(alt));
                if !known {
                    errors.push(origin.say(&format!("`{}` has no subcommand `{alt}`", shown(prog, path))));
                    return;
                }
                let mut p = path.clone();
                p.push(alt.to_string());
                next.push(p);
            }
        }
        paths = next;
    }
}

/// `navsync bridge zenoh`: the program and the subcommands of a path.
fn shown(prog: Prog, path: &[String]) -> String {
    std::iter::once(prog.name())
        .chain(path.iter().map(String::as_str))
        .collect::<Vec<_>>()
        .join(" ")
}

/// The flags named in a synopsis word: `[--baud`, `--estimate|--record`, `…|--no-export]`.
fn flags_in(word: &str) -> Vec<String> {
    let mut out = Vec::new();
    let bytes = word.as_bytes();
    let mut i = 0;
    while i < bytes.len() {
        let boundary = i == 0 || !(bytes[i - 1].is_ascii_alphanumeric() || bytes[i - 1] == b'-');
        if bytes[i] == b'-' && boundary {
            let start = i;
            while i < bytes.len() && bytes[i] == b'-' {
                i += 1;
            }
            let dashes = i - start;
            let name_start = i;
            while i < bytes.len() && (bytes[i].is_ascii_alphanumeric() || bytes[i] == b'-') {
                i += 1;
            }
            let name = &word[name_start..i];
            let named = name.as_bytes().first().is_some_and(u8::is_ascii_alphabetic);
            if named && (dashes == 2 || (dashes == 1 && name.len() == 1)) {
                out.push(word[start..i].to_string());
            }
        } else {
            i += 1;
        }
    }
    out
}

/// Shell words of one simple command (quotes removed; no expansion).
fn shell_words(s: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut cur = String::new();
    let mut quote: Option<char> = None;
    let mut any = false;
    for c in s.chars() {
        match quote {
            Some(q) if c == q => quote = None,
            Some(_) => cur.push(c),
            None if c == '\'' || c == '"' => {
                quote = Some(c);
                any = true;
            }
            None if c.is_whitespace() => {
                if any || !cur.is_empty() {
                    out.push(std::mem::take(&mut cur));
                }
                any = false;
            }
            None => cur.push(c),
        }
    }
    if any || !cur.is_empty() {
        out.push(cur);
    }
    out
}

/// The simple commands of a shell line: split at `|`, `||`, `&&` and `;` outside quotes, a
/// comment (`#` after a blank) cut off.
fn simple_commands(line: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut cur = String::new();
    let mut quote: Option<char> = None;
    let mut prev_blank = true;
    for c in line.chars() {
        match quote {
            Some(q) => {
                if c == q {
                    quote = None;
                }
                cur.push(c);
            }
            None if c == '\'' || c == '"' => {
                quote = Some(c);
                cur.push(c);
            }
            None if c == '#' && prev_blank => break,
            None if c == '|' || c == ';' || c == '&' => {
                if !cur.trim().is_empty() {
                    out.push(std::mem::take(&mut cur));
                }
                cur.clear();
            }
            None => cur.push(c),
        }
        prev_blank = c.is_whitespace();
    }
    if !cur.trim().is_empty() {
        out.push(cur);
    }
    out
}

/// The binary and the arguments of a shell command, if it runs one of navsync's: through
/// `sudo [-u USER]`, `env`, `VAR=value`, `ExecStart=`, or `cargo run [-p PKG] [--release] --`.
fn navsync_command(words: &[String]) -> Option<(Prog, Vec<String>)> {
    let mut w: Vec<String> = words.to_vec();
    // Redirections and what follows them are not arguments.
    if let Some(i) = w
        .iter()
        .position(|x| x.starts_with('>') || x.starts_with("2>") || x == "<")
    {
        w.truncate(i);
    }
    let mut i = 0;
    loop {
        let x = w.get(i)?.clone();
        if let Some(rest) = x.strip_prefix("ExecStart=") {
            w[i] = rest.to_string();
            continue;
        }
        if x == "sudo" {
            i += 1;
            while w.get(i).is_some_and(|o| o.starts_with('-')) {
                let o = w[i].clone();
                i += if o == "-u" || o == "-g" { 2 } else { 1 };
            }
        } else if x == "env" || x == "time" || is_assignment(&x) {
            i += 1;
        } else {
            break;
        }
    }
    let head = &w[i];
    if let Some(prog) = Prog::of_word(head) {
        return Some((prog, w[i + 1..].to_vec()));
    }
    if head == "cargo" && w.get(i + 1).is_some_and(|x| x == "run") {
        let sep = w.iter().position(|x| x == "--")?;
        let cargo = &w[i + 2..sep];
        if cargo.iter().any(|x| x == "--example") {
            return None;
        }
        let package = cargo
            .iter()
            .position(|x| x == "-p" || x == "--package" || x == "--bin")
            .and_then(|p| cargo.get(p + 1))
            .map(String::as_str);
        let prog = match package {
            None | Some("navsync") => Prog::Navsync,
            Some("navsync-bench") => Prog::Bench,
            Some(_) => return None,
        };
        return Some((prog, w[sep + 1..].to_vec()));
    }
    None
}

/// `NAVSYNC_IPC_ROOT=/run/…`: an environment variable set for the command.
fn is_assignment(word: &str) -> bool {
    word.split_once('=').is_some_and(|(k, _)| {
        !k.is_empty()
            && k.chars()
                .all(|c| c.is_ascii_uppercase() || c.is_ascii_digit() || c == '_')
    })
}

/// Shell code blocks: a fence labelled as a shell, or not labelled.
fn is_shell(lang: &str) -> bool {
    matches!(lang, "" | "sh" | "bash" | "shell" | "console")
}

/// Each command line of the shell blocks, continuation lines joined, with its line number.
fn shell_lines(f: &Fence) -> Vec<(usize, String)> {
    let mut out: Vec<(usize, String)> = Vec::new();
    let mut pending: Option<(usize, String)> = None;
    for (n, line) in &f.lines {
        let text = line.trim();
        let text = text.strip_prefix("$ ").unwrap_or(text);
        let (start, mut acc) = pending.take().unwrap_or((*n, String::new()));
        match text.strip_suffix('\\') {
            Some(head) => {
                acc.push_str(head);
                acc.push(' ');
                pending = Some((start, acc));
            }
            None => {
                acc.push_str(text);
                out.push((start, acc));
            }
        }
    }
    out.extend(pending);
    out
}

/// The commands of inline code spans: `navsync …`, `navsync-bench …`, `cargo run … -- …`.
fn inline_commands(doc: &Doc) -> Vec<(usize, String)> {
    let mut out = Vec::new();
    let text = &doc.prose;
    let mut rest = 0;
    while let Some(open) = text[rest..].find('`') {
        let start = rest + open + 1;
        let Some(len) = text[start..].find('`') else { break };
        let span = &text[start..start + len];
        rest = start + len + 1;
        let span = span.replace("\\|", "|");
        let first = span.split_whitespace().next().unwrap_or("");
        if span.contains(char::is_whitespace) && (Prog::of_word(first).is_some() || span.starts_with("cargo run")) {
            out.push((
                line_of(text, start),
                span.split_whitespace().collect::<Vec<_>>().join(" "),
            ));
        }
    }
    out
}

/// Every command of the documentation; returns the failures (and the count checked).
fn check_commands(docs: &[Doc], helps: &mut Helps) -> (Vec<String>, usize, usize) {
    let mut errors = Vec::new();
    let (mut fenced, mut inline) = (0, 0);
    for doc in docs {
        for fence in doc.fences.iter().filter(|f| is_shell(&f.lang)) {
            for (n, line) in shell_lines(fence) {
                for cmd in simple_commands(&line) {
                    let Some((prog, args)) = navsync_command(&shell_words(&cmd)) else {
                        continue;
                    };
                    fenced += 1;
                    let origin = Origin {
                        file: &doc.path,
                        line: n,
                        text: &cmd,
                    };
                    check_words(helps, prog, &args, false, &origin, &mut errors);
                    // clap parses every flag and value before it reaches `--help`.
                    let out = Command::new(prog.bin())
                        .args(&args)
                        .arg("--help")
                        .env("RUST_LOG", "warn")
                        .output()
                        .expect("running the binary");
                    if !out.status.success() {
                        let why = String::from_utf8_lossy(&out.stderr);
                        let why = why.lines().next().unwrap_or("").to_string();
                        errors.push(origin.say(&format!("does not parse: {why}")));
                    }
                }
            }
        }
        for (n, span) in inline_commands(doc) {
            let words = shell_words(&span);
            let (prog, args) = match navsync_command(&words) {
                Some(c) => c,
                None if span.starts_with("cargo run") => continue,
                None => {
                    let prog = Prog::of_word(&words[0]).expect("a navsync command");
                    (prog, words[1..].to_vec())
                }
            };
            inline += 1;
            let origin = Origin {
                file: &doc.path,
                line: n,
                text: &span,
            };
            check_words(helps, prog, &args, true, &origin, &mut errors);
        }
    }
    (errors, fenced, inline)
}

/// GitHub's anchor of a heading: lower case, punctuation dropped, blanks as hyphens.
fn slug(heading: &str) -> String {
    heading
        .trim()
        .to_lowercase()
        .chars()
        .filter(|c| c.is_alphanumeric() || *c == ' ' || *c == '-' || *c == '_')
        .map(|c| if c == ' ' { '-' } else { c })
        .collect()
}

fn anchors(text: &str) -> BTreeSet<String> {
    let mut in_fence = false;
    let mut out = BTreeSet::new();
    for line in text.lines() {
        if line.trim_start().starts_with("```") {
            in_fence = !in_fence;
        } else if !in_fence && line.starts_with('#') {
            out.insert(slug(line.trim_start_matches('#')));
        }
    }
    out
}

/// A name of the repository's top level that a path in the documentation starts with.
const TOP_LEVEL: &[&str] = &[
    "wire/",
    "shared/",
    "recording/",
    "drivers/",
    "sim/",
    "estimator/",
    "daemon/",
    "bridge/",
    "bench/",
    "tests/",
    "systemd/",
    "fuzz/",
    "docs/",
    ".ci/",
    ".cargo/",
];

/// Whether `pattern` (`*` matches within a name) names an existing path under `root`.
fn exists(root: &Path, pattern: &str) -> bool {
    let Some((dir, name)) = pattern.trim_end_matches('/').rsplit_once('/') else {
        return root.join(pattern).exists();
    };
    if !name.contains('*') {
        return root.join(pattern).exists();
    }
    let (pre, post) = name.split_once('*').expect("a wildcard");
    std::fs::read_dir(root.join(dir)).is_ok_and(|rd| {
        rd.flatten().any(|e| {
            let n = e.file_name().to_string_lossy().into_owned();
            n.starts_with(pre) && n.ends_with(post.trim_start_matches('*'))
        })
    })
}

/// Repository paths in inline code, and relative links with their anchors.
fn check_paths(docs: &[Doc]) -> Vec<String> {
    let root = repo();
    let mut errors = Vec::new();
    let mut headings: BTreeMap<PathBuf, BTreeSet<String>> = BTreeMap::new();
    for doc in docs {
        let text = &doc.prose;
        // Inline code.
        let mut rest = 0;
        while let Some(open) = text[rest..].find('`') {
            let start = rest + open + 1;
            let Some(len) = text[start..].find('`') else { break };
            rest = start + len + 1;
            for word in text[start..start + len].split(|c: char| c.is_whitespace() || ",;()".contains(c)) {
                let word = word.trim_end_matches([':', '.']);
                let pathlike = word.ends_with('/') || word.rsplit('/').next().is_some_and(|n| n.contains('.'));
                if TOP_LEVEL.iter().any(|t| word.starts_with(t))
                    && pathlike
                    && !word.contains(['<', '{', '$'])
                    && !exists(&root, word)
                {
                    errors.push(format!(
                        "{}:{}: `{word}` does not exist",
                        doc.path.display(),
                        line_of(text, start)
                    ));
                }
            }
        }
        // Links: `](target)`.
        let mut rest = 0;
        while let Some(i) = text[rest..].find("](") {
            let start = rest + i + 2;
            let Some(len) = text[start..].find(')') else { break };
            rest = start + len;
            let target = &text[start..start + len];
            if target.contains("://") || target.starts_with("mailto:") {
                continue;
            }
            let (file, anchor) = target.split_once('#').unwrap_or((target, ""));
            let dir = doc.path.parent().unwrap_or(Path::new(""));
            let resolved = if file.is_empty() {
                doc.path.clone()
            } else {
                dir.join(file)
            };
            let full = root.join(&resolved);
            let line = line_of(text, start);
            if !full.exists() {
                errors.push(format!("{}:{line}: link to {target}: no such file", doc.path.display()));
                continue;
            }
            if anchor.is_empty() {
                continue;
            }
            let known = headings
                .entry(resolved.clone())
                .or_insert_with(|| anchors(&std::fs::read_to_string(&full).unwrap_or_default()));
            if !known.contains(anchor) {
                errors.push(format!(
                    "{}:{line}: link to {target}: {} has no heading #{anchor}",
                    doc.path.display(),
                    resolved.display()
                ));
            }
        }
    }
    errors
}

/// Every `toml` block through `check-config`.
fn check_configs(docs: &[Doc], env: &TestEnv) -> (Vec<String>, usize) {
    let mut errors = Vec::new();
    let mut n = 0;
    for doc in docs {
        for fence in doc.fences.iter().filter(|f| f.lang == "toml") {
            n += 1;
            let file = env.dir.join(format!("config-{n}.toml"));
            let body: String = fence.lines.iter().map(|(_, l)| format!("{l}\n")).collect();
            std::fs::write(&file, body).expect("writing the configuration");
            let out = env
                .command(&["--config", file.to_str().expect("utf-8 path"), "check-config"])
                .output()
                .expect("navsync check-config");
            if !out.status.success() {
                let line = fence.lines.first().map_or(0, |(l, _)| *l);
                errors.push(format!(
                    "{}:{line}: the configuration does not pass check-config: {}",
                    doc.path.display(),
                    String::from_utf8_lossy(&out.stderr).trim()
                ));
            }
        }
    }
    (errors, n)
}

fn load_docs() -> Vec<Doc> {
    let root = repo();
    markdown_files()
        .iter()
        .map(|p| {
            let text = std::fs::read_to_string(root.join(p)).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
            parse_doc(p, &text)
        })
        .collect()
}

fn report(what: &str, errors: &[String]) -> String {
    let mut s = format!("{} {what}:\n", errors.len());
    for e in errors {
        let _ = writeln!(s, "  {e}");
    }
    s
}

#[test]
fn every_command_in_the_docs_parses() {
    if !navsync_tests::in_own_process!() {
        return;
    }
    let docs = load_docs();
    let mut helps = Helps::default();
    let (errors, fenced, inline) = check_commands(&docs, &mut helps);
    println!(
        "{} files: {fenced} command lines in code blocks, {inline} commands in inline code",
        docs.len()
    );
    assert!(
        errors.is_empty(),
        "{}",
        report("commands the binaries do not take", &errors)
    );
    assert!(
        fenced >= 5 && inline >= 50,
        "too few commands found: the extraction is broken"
    );
}

#[test]
fn every_configuration_in_the_docs_passes_check_config() {
    if !navsync_tests::in_own_process!() {
        return;
    }
    let env = TestEnv::new("docsconfig");
    let docs = load_docs();
    let (errors, n) = check_configs(&docs, &env);
    println!("{n} configuration files");
    assert!(n >= 1, "no toml block found: the README's setup has one");
    assert!(errors.is_empty(), "{}", report("configurations refused", &errors));
    env.finish();
}

#[test]
fn every_path_and_link_in_the_docs_exists() {
    if !navsync_tests::in_own_process!() {
        return;
    }
    let errors = check_paths(&load_docs());
    assert!(
        errors.is_empty(),
        "{}",
        report("paths and links that do not exist", &errors)
    );
}

/// The checks themselves: a wrong flag, a wrong subcommand, a value clap refuses and a
/// synopsis with a flag of another subcommand are each found.
#[test]
fn the_checks_find_a_wrong_flag() {
    if !navsync_tests::in_own_process!() {
        return;
    }
    let text = "```sh\nnavsync gnss --port /dev/ttyACM0 --protocl ubx\nnavsync gnsss --id 0\n\
                sudo target/release/navsync gnss --baud 12345\nnavsync gnss --port /dev/x | tee log\n```\n\
                The table: `navsync-bench ipc|timing [--quick]`, `navsync pps --source S [--id ID]`.\n";
    let docs = vec![parse_doc(Path::new("example.md"), text)];
    let mut helps = Helps::default();
    let (errors, fenced, inline) = check_commands(&docs, &mut helps);
    assert_eq!((fenced, inline), (4, 2), "{errors:#?}");
    let has = |needle: &str| errors.iter().any(|e| e.contains(needle));
    assert!(has("`navsync gnss` has no flag --protocl"), "{errors:#?}");
    assert!(has("has no subcommand `gnsss`"), "{errors:#?}");
    assert!(has("is not a standard baud rate"), "{errors:#?}");
    assert!(has("`navsync-bench timing` has no flag --quick"), "{errors:#?}");
    assert!(!errors.iter().any(|e| e.contains("/dev/x")), "{errors:#?}");
    assert!(!errors.iter().any(|e| e.contains("pps")), "{errors:#?}");
}

/// `docs/guide/configuration.md` is what `navsync config-reference` prints: the reference of
/// every declared estimator setting, generated from the declarations, never edited by hand.
#[test]
fn the_configuration_reference_is_generated_from_the_declarations() {
    let o = std::process::Command::new(navsync_tests::navsync_bin())
        .arg("config-reference")
        .output()
        .expect("navsync config-reference");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let generated = String::from_utf8(o.stdout).unwrap();
    assert!(
        generated.contains("| `gate_scale` | `--gate-scale` |"),
        "a declared setting is missing:\n{generated}"
    );
    let path = repo().join("docs/guide/configuration.md");
    let kept = std::fs::read_to_string(&path).unwrap_or_default();
    assert!(
        kept == generated,
        "{} differs from `navsync config-reference`: regenerate it with\n  target/debug/navsync config-reference > docs/guide/configuration.md",
        path.display()
    );
}
