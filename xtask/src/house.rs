//! `cargo xtask house`: code a reader can hold. Fails, naming `file:line`, on a Rust source
//! file over [`MAX_FILE_LINES`] lines, a function over [`MAX_FN_LINES`] lines (from its `fn`
//! line to its closing brace), or an import circle between sibling modules of a crate's
//! `src/` tree (`a` uses `crate::b`, `b` uses `crate::a`). A child using its parent's items
//! (`super::Item`) is no circle, nor is anything's use of the crate root, the crate's table of
//! contents.
//!
//! The scan is lexical: comments, strings and character literals are blanked, then `fn` items
//! are matched brace to brace and `crate::`/`super::`/`self::` paths (also inside `use`
//! trees) are resolved against the module tree that the files form.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use anyhow::{bail, Result};

/// The longest a source file may be.
pub const MAX_FILE_LINES: usize = 1500;
/// The longest a function may be.
pub const MAX_FN_LINES: usize = 150;

/// Files the check leaves out, each with why.
const EXEMPT: &[(&str, &str)] = &[];

/// The folders scanned, relative to the workspace root.
const ROOTS: &[&str] = &["crates", "xtask", "tests"];

/// Runs the check on the workspace and prints the offenders.
pub fn run() -> Result<()> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .ok_or_else(|| anyhow::anyhow!("the workspace root"))?
        .to_path_buf();
    let offences = check(&root)?;
    let files = rust_files(&root)?.len();
    for o in &offences {
        println!("{o}");
    }
    if !offences.is_empty() {
        bail!(
            "{} offence(s) against the house rules (files <= {MAX_FILE_LINES} lines, functions \
             <= {MAX_FN_LINES} lines, no import circles)",
            offences.len()
        );
    }
    println!(
        "house: {files} Rust files, none over {MAX_FILE_LINES} lines, no function over \
         {MAX_FN_LINES} lines, no import circle ({} exempt: {})",
        EXEMPT.len(),
        EXEMPT
            .iter()
            .map(|(f, why)| format!("{f}, {why}"))
            .collect::<Vec<_>>()
            .join("; ")
    );
    Ok(())
}

/// Every offence in the workspace at `root`, as `file:line: what` lines.
pub fn check(root: &Path) -> Result<Vec<String>> {
    let mut offences = Vec::new();
    let files = rust_files(root)?;
    for file in &files {
        let rel = relative(root, file);
        if EXEMPT.iter().any(|(f, _)| *f == rel) {
            continue;
        }
        let src = std::fs::read_to_string(file)?;
        let lines = src.lines().count();
        if lines > MAX_FILE_LINES {
            offences.push(format!("{rel}:1: {lines} lines (at most {MAX_FILE_LINES})"));
        }
        for f in functions(&blank(&src)) {
            if f.lines > MAX_FN_LINES {
                offences.push(format!(
                    "{rel}:{}: fn {} is {} lines (at most {MAX_FN_LINES})",
                    f.line, f.name, f.lines
                ));
            }
        }
    }
    let mut trees: BTreeSet<PathBuf> = BTreeSet::new();
    for file in &files {
        if let Some(src) = file.ancestors().find(|a| a.ends_with("src")) {
            trees.insert(src.to_path_buf());
        }
    }
    for src in trees {
        offences.extend(circles(root, &src, &files)?);
    }
    Ok(offences)
}

/// The `.rs` files under [`ROOTS`], sorted; `target` and `fixtures` folders left out.
fn rust_files(root: &Path) -> Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    let mut stack: Vec<PathBuf> = ROOTS.iter().map(|r| root.join(r)).collect();
    while let Some(dir) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&dir) else {
            continue;
        };
        for e in entries {
            let path = e?.path();
            let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
            if path.is_dir() {
                if name != "target" && name != "fixtures" && !name.starts_with('.') {
                    stack.push(path);
                }
            } else if name.ends_with(".rs") {
                out.push(path);
            }
        }
    }
    out.sort();
    Ok(out)
}

fn relative(root: &Path, file: &Path) -> String {
    file.strip_prefix(root)
        .unwrap_or(file)
        .to_string_lossy()
        .replace('\\', "/")
}

/// The source with comments, string literals and character literals replaced by spaces
/// (newlines kept, so that line numbers hold).
pub fn blank(src: &str) -> String {
    let b = src.as_bytes();
    let mut out = b.to_vec();
    let mut i = 0;
    let wipe = |out: &mut Vec<u8>, from: usize, to: usize| {
        for c in &mut out[from..to.min(b.len())] {
            if *c != b'\n' {
                *c = b' ';
            }
        }
    };
    while i < b.len() {
        let ident_before = i > 0 && (b[i - 1].is_ascii_alphanumeric() || b[i - 1] == b'_');
        if b[i..].starts_with(b"//") {
            let end = b[i..]
                .iter()
                .position(|&c| c == b'\n')
                .map_or(b.len(), |p| i + p);
            wipe(&mut out, i, end);
            i = end;
        } else if b[i..].starts_with(b"/*") {
            let (mut depth, mut j) = (1, i + 2);
            while j < b.len() && depth > 0 {
                if b[j..].starts_with(b"/*") {
                    depth += 1;
                    j += 2;
                } else if b[j..].starts_with(b"*/") {
                    depth -= 1;
                    j += 2;
                } else {
                    j += 1;
                }
            }
            wipe(&mut out, i, j);
            i = j;
        } else if !ident_before && raw_string_start(&b[i..]).is_some() {
            let (open, hashes) = raw_string_start(&b[i..]).unwrap_or((0, 0));
            let mut j = i + open;
            loop {
                if j >= b.len() {
                    break;
                }
                if b[j] == b'"'
                    && b[j + 1..]
                        .iter()
                        .take(hashes)
                        .filter(|&&c| c == b'#')
                        .count()
                        == hashes
                {
                    j += 1 + hashes;
                    break;
                }
                j += 1;
            }
            wipe(&mut out, i, j);
            i = j;
        } else if b[i] == b'"' {
            let mut j = i + 1;
            while j < b.len() && b[j] != b'"' {
                j += if b[j] == b'\\' { 2 } else { 1 };
            }
            wipe(&mut out, i, j + 1);
            i = j + 1;
        } else if b[i] == b'\'' {
            // a character literal ('x', '\n', '\u{..}'), not a lifetime ('a)
            let len = char_literal_len(&b[i..]);
            wipe(&mut out, i, i + len);
            i += len.max(1);
        } else {
            i += 1;
        }
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// `r"`, `r#"`, `br##"`...: the length of the opening and the number of `#`.
fn raw_string_start(b: &[u8]) -> Option<(usize, usize)> {
    let mut j = usize::from(b.first() == Some(&b'b'));
    if b.get(j) != Some(&b'r') {
        return None;
    }
    j += 1;
    let hashes = b[j..].iter().take_while(|&&c| c == b'#').count();
    (b.get(j + hashes) == Some(&b'"')).then_some((j + hashes + 1, hashes))
}

/// The length of the character literal at the start of `b`, 0 when it is a lifetime.
fn char_literal_len(b: &[u8]) -> usize {
    if b.get(1) == Some(&b'\\') {
        let close = b[2..].iter().take(10).position(|&c| c == b'\'');
        return close.map_or(0, |p| p + 3);
    }
    // one UTF-8 character then the closing quote
    let width = match b.get(1) {
        Some(c) if *c >= 0xF0 => 4,
        Some(c) if *c >= 0xE0 => 3,
        Some(c) if *c >= 0xC0 => 2,
        Some(_) => 1,
        None => return 0,
    };
    if b.get(1 + width) == Some(&b'\'') {
        2 + width
    } else {
        0
    }
}

/// A function item found by [`functions`].
pub struct Function {
    /// Its name.
    pub name: String,
    /// The line of its `fn` keyword, 1-based.
    pub line: usize,
    /// Lines from the `fn` line to the closing brace, both included.
    pub lines: usize,
}

/// The functions with a body in blanked source (see [`blank`]).
pub fn functions(src: &str) -> Vec<Function> {
    let lines: Vec<&str> = src.lines().collect();
    let starts: Vec<usize> = std::iter::once(0)
        .chain(src.match_indices('\n').map(|(i, _)| i + 1))
        .collect();
    let b = src.as_bytes();
    let mut out = Vec::new();
    for (n, line) in lines.iter().enumerate() {
        let Some(name) = fn_name(line) else {
            continue;
        };
        // the body: the first `{` outside parentheses and brackets, unless a `;` comes first
        let (mut i, mut nest) = (starts[n], 0i32);
        let mut body = None;
        while i < b.len() {
            match b[i] {
                b'(' | b'[' => nest += 1,
                b')' | b']' => nest -= 1,
                b';' if nest == 0 => break,
                b'{' if nest == 0 => {
                    body = Some(i);
                    break;
                }
                _ => {}
            }
            i += 1;
        }
        let Some(open) = body else {
            continue;
        };
        let mut depth = 0usize;
        let mut close = None;
        for (j, &c) in b.iter().enumerate().skip(open) {
            if c == b'{' {
                depth += 1;
            } else if c == b'}' {
                depth -= 1;
                if depth == 0 {
                    close = Some(j);
                    break;
                }
            }
        }
        let Some(close) = close else {
            continue;
        };
        let end_line = starts.partition_point(|&s| s <= close);
        out.push(Function {
            name,
            line: n + 1,
            lines: end_line - n,
        });
    }
    out
}

/// The name of the function whose `fn` keyword starts this line after its qualifiers.
fn fn_name(line: &str) -> Option<String> {
    let mut rest = line.trim_start();
    loop {
        if let Some(r) = rest.strip_prefix("pub(") {
            rest = r.split_once(')')?.1.trim_start();
            continue;
        }
        let word_end = rest
            .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
            .unwrap_or(rest.len());
        match &rest[..word_end] {
            "pub" | "const" | "async" | "unsafe" | "extern" | "default" => {
                rest = rest[word_end..].trim_start();
            }
            "fn" => {
                let name: String = rest[word_end..]
                    .trim_start()
                    .chars()
                    .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                    .collect();
                return (!name.is_empty()).then_some(name);
            }
            _ => return None,
        }
    }
}

/// The module path of a file of the `src` tree (`a/b.rs` and `a/b/mod.rs` are `[a, b]`; the
/// crate root, lib.rs or main.rs, is `[]`); None for other roots (`src/bin/`).
fn module_path(src: &Path, file: &Path) -> Option<Vec<String>> {
    let rel = file.strip_prefix(src).ok()?;
    let mut parts: Vec<String> = rel
        .iter()
        .map(|p| p.to_string_lossy().into_owned())
        .collect();
    let last = parts.pop()?;
    if parts.first().is_some_and(|p| p == "bin") {
        return None;
    }
    match last.as_str() {
        "lib.rs" | "main.rs" if parts.is_empty() => {}
        "mod.rs" => {}
        other => parts.push(other.strip_suffix(".rs")?.to_string()),
    }
    Some(parts)
}

/// The import circles between sibling modules of one `src` tree.
fn circles(root: &Path, src: &Path, files: &[PathBuf]) -> Result<Vec<String>> {
    let mut modules: BTreeMap<Vec<String>, PathBuf> = BTreeMap::new();
    for f in files.iter().filter(|f| f.starts_with(src)) {
        if let Some(m) = module_path(src, f) {
            modules.insert(m, f.clone());
        }
    }
    // edges between siblings: (parent, from, to) -> first file:line
    let mut edges: BTreeMap<(Vec<String>, String, String), String> = BTreeMap::new();
    for (module, file) in &modules {
        if EXEMPT.iter().any(|(f, _)| relative(root, file) == *f) {
            continue;
        }
        let text = blank(&std::fs::read_to_string(file)?);
        for (line, path) in paths(&text) {
            let Some(target) = resolve(module, &path, &modules) else {
                continue;
            };
            let common = module
                .iter()
                .zip(&target)
                .take_while(|(a, b)| a == b)
                .count();
            if common < module.len() && common < target.len() {
                let key = (
                    module[..common].to_vec(),
                    module[common].clone(),
                    target[common].clone(),
                );
                edges
                    .entry(key)
                    .or_insert_with(|| format!("{}:{line}", relative(root, file)));
            }
        }
    }
    let mut out = Vec::new();
    for ((parent, from, to), at) in &edges {
        if from < to && reaches(&edges, parent, to, from) {
            let back = edges
                .iter()
                .find(|((p, f, _), _)| p == parent && f == to)
                .map_or(String::new(), |(_, a)| a.clone());
            let scope = if parent.is_empty() {
                "crate".to_string()
            } else {
                format!("crate::{}", parent.join("::"))
            };
            out.push(format!(
                "{at}: import circle in {scope}: {from} uses {to}, and {to} reaches {from} \
                 (e.g. {back})"
            ));
        }
    }
    Ok(out)
}

/// Whether `from` reaches `to` through the sibling edges under `parent`.
fn reaches(
    edges: &BTreeMap<(Vec<String>, String, String), String>,
    parent: &[String],
    from: &str,
    to: &str,
) -> bool {
    let mut seen = BTreeSet::new();
    let mut stack = vec![from.to_string()];
    while let Some(m) = stack.pop() {
        if m == to {
            return true;
        }
        if seen.insert(m.clone()) {
            stack.extend(
                edges
                    .keys()
                    .filter(|(p, f, _)| p == parent && *f == m)
                    .map(|(_, _, t)| t.clone()),
            );
        }
    }
    false
}

/// The module a path names, as far as it names modules of the tree: `crate::a::b::Item` is
/// `[a, b]` when `a::b` is a module; paths from `super` and `self` start at `module`.
fn resolve(
    module: &[String],
    path: &[String],
    modules: &BTreeMap<Vec<String>, PathBuf>,
) -> Option<Vec<String>> {
    let mut at: Vec<String> = match path.first()?.as_str() {
        "crate" => Vec::new(),
        "self" | "super" => module.to_vec(),
        _ => return None,
    };
    let mut rest = &path[usize::from(path[0] == "crate" || path[0] == "self")..];
    while rest.first().is_some_and(|p| p == "super") {
        at.pop()?;
        rest = &rest[1..];
    }
    for part in rest {
        let mut next = at.clone();
        next.push(part.clone());
        if !modules.contains_key(&next) {
            break;
        }
        at = next;
    }
    Some(at)
}

/// The `crate::`, `super::` and `self::` paths in blanked source, with their lines; `use`
/// trees (`use crate::{a::X, b::{Y, Z}}`) are expanded.
fn paths(src: &str) -> Vec<(usize, Vec<String>)> {
    let b = src.as_bytes();
    let mut out = Vec::new();
    let line_of = |i: usize| src[..i].matches('\n').count() + 1;
    let mut i = 0;
    while i < b.len() {
        let starts_word = i == 0
            || !(b[i - 1].is_ascii_alphanumeric()
                || b[i - 1] == b'_'
                || b[i - 1] == b'$'
                || b[i - 1] == b':');
        if !starts_word {
            i += 1;
            continue;
        }
        let head = ["crate", "super", "self"]
            .into_iter()
            .find(|h| src[i..].starts_with(h) && src[i + h.len()..].trim_start().starts_with("::"));
        let Some(_) = head else {
            i += 1;
            continue;
        };
        let (tree, len) = use_tree(&src[i..]);
        for p in tree {
            out.push((line_of(i), p));
        }
        i += len.max(1);
    }
    out
}

/// The paths of a `use` tree or plain path at the start of `s`, and the bytes it spans.
fn use_tree(s: &str) -> (Vec<Vec<String>>, usize) {
    let mut prefix: Vec<String> = Vec::new();
    let mut i = 0;
    let b = s.as_bytes();
    loop {
        while i < b.len() && b[i].is_ascii_whitespace() {
            i += 1;
        }
        if i < b.len() && b[i] == b'{' {
            // a group: split at top-level commas, each a subtree
            let mut out = Vec::new();
            i += 1;
            loop {
                while i < b.len() && (b[i].is_ascii_whitespace() || b[i] == b',') {
                    i += 1;
                }
                if i >= b.len() || b[i] == b'}' {
                    return (out, i + 1);
                }
                let (sub, len) = use_tree(&s[i..]);
                if len == 0 {
                    return (out, i + 1);
                }
                for p in sub {
                    let mut full = prefix.clone();
                    full.extend(p);
                    out.push(full);
                }
                i += len;
            }
        }
        let start = i;
        while i < b.len() && (b[i].is_ascii_alphanumeric() || b[i] == b'_' || b[i] == b'*') {
            i += 1;
        }
        if i == start {
            return (vec![prefix], i);
        }
        prefix.push(s[start..i].to_string());
        let after = s[i..].trim_start();
        if after.starts_with("::") {
            i = s.len() - after.len() + 2;
        } else {
            return (vec![prefix], i);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_function_lengths_past_strings_and_comments() {
        let src = "pub(crate) fn a(x: [u8; 2]) -> u8 {\n    let s = \"}\"; // }\n    '}';\n    x[0]\n}\ntrait T { fn b(&self); }\nfn c<'a>(s: &'a str) { /* { */ }\n";
        let f = functions(&blank(src));
        let got: Vec<(&str, usize, usize)> = f
            .iter()
            .map(|f| (f.name.as_str(), f.line, f.lines))
            .collect();
        assert_eq!(got, vec![("a", 1, 5), ("c", 7, 1)]);
    }

    #[test]
    fn expands_use_trees() {
        let (p, _) = use_tree("crate::{a::X, b::{self, Y}, Z};");
        let p: Vec<String> = p.iter().map(|p| p.join("::")).collect();
        assert_eq!(
            p,
            ["crate::a::X", "crate::b::self", "crate::b::Y", "crate::Z"]
        );
    }

    #[test]
    fn resolves_to_modules() {
        let mut m = BTreeMap::new();
        for p in [
            vec![],
            vec!["a".to_string()],
            vec!["a".into(), "b".into()],
            vec!["c".into()],
        ] {
            m.insert(p, PathBuf::new());
        }
        let s = |v: &[&str]| v.iter().map(|x| x.to_string()).collect::<Vec<_>>();
        assert_eq!(
            resolve(&s(&["a", "b"]), &s(&["super", "super", "c", "F"]), &m),
            Some(s(&["c"]))
        );
        assert_eq!(
            resolve(&s(&["c"]), &s(&["crate", "a", "b", "G"]), &m),
            Some(s(&["a", "b"]))
        );
        assert_eq!(resolve(&s(&["c"]), &s(&["self", "x"]), &m), Some(s(&["c"])));
    }
}
