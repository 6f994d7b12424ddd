//! The code's shape, as `docs/ARCHITECTURE.md` promises it: every file in
//! `src/` small enough to read in one sitting, and no import circle between
//! files (a child may use its parent's items and a folder's `mod.rs` may
//! re-export its children; siblings depend one way only).
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// About 600 lines, with a little slack so a comment does not break the build.
const MAX_LINES: usize = 650;

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// `src/a/b/mod.rs` and `src/a/b.rs` → ["a", "b"]; lib.rs and main.rs → [].
fn module_of(src: &Path, file: &Path) -> Vec<String> {
    let rel = file.strip_prefix(src).unwrap().with_extension("");
    let mut parts: Vec<String> = rel
        .components()
        .map(|c| c.as_os_str().to_string_lossy().into_owned())
        .collect();
    if parts
        .last()
        .is_some_and(|p| p == "mod" || p == "lib" || p == "main")
    {
        parts.pop();
    }
    parts
}

/// The code of a file without its comments and its test module.
fn code(text: &str) -> String {
    let text = text.split("#[cfg(test)]\nmod tests").next().unwrap_or("");
    text.lines()
        .filter(|l| !l.trim_start().starts_with("//"))
        .collect::<Vec<_>>()
        .join("\n")
}

/// The modules a file names through `crate::…` and `super::…` paths, and
/// the children a `mod.rs` re-exports (`pub use child::…`).
fn dependencies(module: &[String], is_folder: bool, text: &str) -> Vec<Vec<String>> {
    let mut deps = Vec::new();
    let bytes = text.as_bytes();
    for start in ["crate::", "super::"] {
        let mut from = 0;
        while let Some(i) = text[from..].find(start) {
            let at = from + i;
            from = at + start.len();
            if at > 0 && (bytes[at - 1].is_ascii_alphanumeric() || bytes[at - 1] == b'_') {
                continue;
            }
            let path: Vec<String> = text[at..]
                .split(|c: char| !(c.is_alphanumeric() || c == '_' || c == ':'))
                .next()
                .unwrap_or("")
                .split("::")
                .filter(|s| !s.is_empty())
                .map(str::to_owned)
                .collect();
            let mut base: Vec<String> = if path[0] == "crate" {
                Vec::new()
            } else {
                // `super` of module a::b (a/b.rs or a/b/mod.rs) is a.
                module[..module.len().saturating_sub(1)].to_vec()
            };
            let mut rest = &path[1..];
            while rest.first().is_some_and(|s| s == "super") {
                base.pop();
                rest = &rest[1..];
            }
            base.extend(rest.iter().cloned());
            deps.push(base);
        }
    }
    if is_folder {
        for line in text.lines() {
            let l = line.trim_start().trim_start_matches("pub ");
            if let Some(rest) = l.strip_prefix("use ")
                && let Some(child) = rest.split("::").next()
                && child.chars().all(|c| c.is_alphanumeric() || c == '_')
            {
                let mut m = module.to_vec();
                m.push(child.to_owned());
                deps.push(m);
            }
        }
    }
    deps
}

#[test]
fn every_source_file_reads_in_one_sitting() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    let long: Vec<String> = files
        .iter()
        .filter_map(|f| {
            let n = std::fs::read_to_string(f).unwrap().lines().count();
            (n > MAX_LINES).then(|| format!("{} ({n} lines)", f.display()))
        })
        .collect();
    assert!(
        long.is_empty(),
        "split these by concern (docs/ARCHITECTURE.md): {long:?}"
    );
}

#[test]
fn no_import_circles_between_files() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    let modules: BTreeMap<Vec<String>, PathBuf> = files
        .iter()
        .map(|f| (module_of(&src, f), f.clone()))
        .collect();
    // The longest module prefix of a path that is a file.
    let resolve = |path: &[String]| -> Option<Vec<String>> {
        (1..=path.len())
            .rev()
            .map(|i| path[..i].to_vec())
            .find(|p| modules.contains_key(p))
    };
    let related = |a: &[String], b: &[String]| b.starts_with(a) || a.starts_with(b);
    let mut graph: BTreeMap<Vec<String>, BTreeSet<Vec<String>>> = BTreeMap::new();
    for (module, file) in &modules {
        let is_folder = file.file_name().is_some_and(|n| n == "mod.rs");
        let text = code(&std::fs::read_to_string(file).unwrap());
        let deps = graph.entry(module.clone()).or_default();
        for d in dependencies(module, is_folder, &text) {
            if let Some(t) = resolve(&d)
                && !related(module, &t)
            {
                deps.insert(t);
            }
        }
    }
    // Every file that reaches itself through others is in a circle.
    let mut circles = Vec::new();
    for start in graph.keys() {
        let mut seen = BTreeSet::new();
        let mut stack: Vec<Vec<String>> = graph[start].iter().cloned().collect();
        while let Some(m) = stack.pop() {
            if &m == start {
                circles.push(start.join("/"));
                break;
            }
            if seen.insert(m.clone()) {
                stack.extend(graph.get(&m).into_iter().flatten().cloned());
            }
        }
    }
    assert!(circles.is_empty(), "files in an import circle: {circles:?}");
}
