//! The documentation's links, checked without a network: every relative link
//! and image in `README.md` and in the user guide (`docs/guide/src/`) names
//! a file that exists, and a `#anchor` names a heading of its page. The
//! guide must also stay a book that mdBook can render whole: its links stay
//! inside `docs/guide/src/` (mdBook copies nothing else), a page it links to
//! is a chapter of `SUMMARY.md` (mdBook renders no other), and the files it
//! `{{#include}}`s exist. `README.md` stays at most 250 lines: the details
//! live in the guide.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Component, Path, PathBuf};

const README_MAX_LINES: usize = 250;
const GUIDE_SRC: &str = "docs/guide/src";

/// `text` with fenced code blocks blanked (line count kept) and inline code
/// spans removed, so that neither yields links or headings.
fn prose(text: &str) -> String {
    let mut out = String::new();
    let mut fence: Option<String> = None;
    for line in text.lines() {
        let t = line.trim_start();
        let marker: String = t.chars().take_while(|&c| c == '`' || c == '~').collect();
        if let Some(open) = &fence {
            if marker.len() >= open.len() && marker.starts_with(&open[..1]) {
                fence = None;
            }
            out.push('\n');
            continue;
        }
        if marker.len() >= 3 && line.len() - t.len() < 4 {
            fence = Some(marker);
            out.push('\n');
            continue;
        }
        out.push_str(line);
        out.push('\n');
    }
    strip_code_spans(&out)
}

/// Removes `code spans` (any run of backticks up to the next run of the same
/// length, across line ends as CommonMark allows).
fn strip_code_spans(text: &str) -> String {
    let b = text.as_bytes();
    let mut out = String::with_capacity(text.len());
    let mut i = 0;
    let mut copied = 0;
    while i < b.len() {
        if b[i] != b'`' {
            i += 1;
            continue;
        }
        let start = i;
        while i < b.len() && b[i] == b'`' {
            i += 1;
        }
        let run = i - start;
        // The closing run: exactly `run` backticks.
        let mut j = i;
        let mut close = None;
        while j < b.len() {
            if b[j] == b'`' {
                let s = j;
                while j < b.len() && b[j] == b'`' {
                    j += 1;
                }
                if j - s == run {
                    close = Some(j);
                    break;
                }
            } else {
                j += 1;
            }
        }
        if let Some(end) = close {
            out.push_str(&text[copied..start]);
            // Keep line ends so line numbers stay right.
            out.extend(text[start..end].chars().filter(|&c| c == '\n'));
            copied = end;
            i = end;
        }
    }
    out.push_str(&text[copied..]);
    out
}

/// (line, target) of every inline link or image `[..](target)` and every
/// reference definition `[..]: target`.
fn links(text: &str) -> Vec<(usize, String)> {
    let mut found = Vec::new();
    for (n, line) in prose(text).lines().enumerate() {
        let mut rest = line;
        while let Some(at) = rest.find("](") {
            let after = &rest[at + 2..];
            let Some(end) = after.find(')') else { break };
            let inside = after[..end].trim();
            let target = inside
                .split_whitespace()
                .next()
                .unwrap_or("")
                .trim_start_matches('<')
                .trim_end_matches('>');
            found.push((n + 1, target.to_owned()));
            rest = &after[end..];
        }
        let t = line.trim_start();
        if t.starts_with('[')
            && let Some(close) = t.find("]:")
            && !t[..close].contains('(')
        {
            let target = t[close + 2..].split_whitespace().next().unwrap_or("");
            if !target.is_empty() {
                found.push((n + 1, target.to_owned()));
            }
        }
    }
    found
}

/// The anchor mdBook (and GitHub, for these headings) gives a heading:
/// its text without markup, lower case, spaces as `-`, only letters, digits,
/// `_` and `-` kept.
fn anchor_of(heading: &str) -> String {
    // [text](url) → text; emphasis and code markers go.
    let mut plain = String::new();
    let mut rest = heading;
    while let Some(open) = rest.find('[') {
        plain.push_str(&rest[..open]);
        let after = &rest[open + 1..];
        match (after.find("]("), after.find(')')) {
            (Some(mid), Some(end)) if mid < end => {
                plain.push_str(&after[..mid]);
                rest = &after[end + 1..];
            }
            _ => {
                plain.push('[');
                rest = after;
            }
        }
    }
    plain.push_str(rest);
    plain
        .trim()
        .chars()
        .filter_map(|c| {
            if c.is_alphanumeric() || c == '_' || c == '-' {
                Some(c.to_ascii_lowercase())
            } else if c.is_whitespace() {
                Some('-')
            } else {
                None
            }
        })
        .collect()
}

/// The anchors of a page's headings (a repeated heading gets `-1`, `-2` …).
fn anchors(text: &str) -> BTreeSet<String> {
    let mut seen: BTreeMap<String, usize> = BTreeMap::new();
    let mut out = BTreeSet::new();
    let mut fence: Option<String> = None;
    for line in text.lines() {
        let t = line.trim_start();
        let marker: String = t.chars().take_while(|&c| c == '`' || c == '~').collect();
        if let Some(open) = &fence {
            if marker.len() >= open.len() && marker.starts_with(&open[..1]) {
                fence = None;
            }
            continue;
        }
        if marker.len() >= 3 && line.len() - t.len() < 4 {
            fence = Some(marker);
            continue;
        }
        let hashes = t.chars().take_while(|&c| c == '#').count();
        if (1..=6).contains(&hashes) && line.len() - t.len() < 4 && t[hashes..].starts_with(' ') {
            let title = t[hashes..].trim().trim_end_matches('#').trim();
            let base = anchor_of(&title.replace(['`', '*'], ""));
            let n = seen.entry(base.clone()).or_insert(0);
            out.insert(if *n == 0 {
                base.clone()
            } else {
                format!("{base}-{n}")
            });
            *n += 1;
        }
    }
    out
}

/// `a/b/../c` → `a/c`, without touching the file system.
fn normalise(path: &Path) -> PathBuf {
    let mut out = PathBuf::new();
    for c in path.components() {
        match c {
            Component::ParentDir => {
                if !out.pop() {
                    out.push("..");
                }
            }
            Component::CurDir => {}
            other => out.push(other.as_os_str()),
        }
    }
    out
}

/// Expands mdBook's `{{#include FILE}}`, `{{#include FILE:A:B}}` (lines A
/// to B, either may be left out) and `{{#include FILE:N}}`, as mdBook does;
/// problems (a missing file, an unsupported form) go to `problems`.
fn expand_includes(page: &Path, text: &str, problems: &mut Vec<String>) -> String {
    let mut out = String::new();
    for (n, line) in text.lines().enumerate() {
        let t = line.trim();
        let Some(spec) = t
            .strip_prefix("{{#include ")
            .and_then(|s| s.strip_suffix("}}"))
        else {
            out.push_str(line);
            out.push('\n');
            continue;
        };
        let mut parts = spec.trim().split(':');
        let file = parts.next().unwrap_or("");
        let range: Vec<&str> = parts.collect();
        let path = normalise(&page.parent().unwrap().join(file));
        let Ok(body) = std::fs::read_to_string(&path) else {
            problems.push(format!(
                "{}:{}: includes {file}, which does not exist",
                page.display(),
                n + 1
            ));
            continue;
        };
        let lines: Vec<&str> = body.lines().collect();
        let number = |s: &str, default: usize| -> Option<usize> {
            if s.is_empty() {
                Some(default)
            } else {
                s.parse().ok()
            }
        };
        let (from, to) = match range.as_slice() {
            [] => (Some(1), Some(lines.len())),
            [one] => (number(one, 1), number(one, 1)),
            [a, b] => (number(a, 1), number(b, lines.len())),
            _ => (None, None),
        };
        match (from, to) {
            (Some(a), Some(b)) if a >= 1 && a <= b.min(lines.len()) => {
                for l in &lines[a - 1..b.min(lines.len())] {
                    out.push_str(l);
                    out.push('\n');
                }
            }
            _ => problems.push(format!(
                "{}:{}: `{t}`: only whole files and line ranges are checked here",
                page.display(),
                n + 1
            )),
        }
    }
    out
}

/// The chapters `SUMMARY.md` lists, as paths under the guide's source.
fn chapters(root: &Path) -> BTreeSet<PathBuf> {
    let src = root.join(GUIDE_SRC);
    let summary = std::fs::read_to_string(src.join("SUMMARY.md")).unwrap_or_default();
    links(&summary)
        .into_iter()
        .filter(|(_, t)| !t.is_empty())
        .map(|(_, t)| normalise(&src.join(t.split('#').next().unwrap())))
        .collect()
}

fn markdown_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in entries {
        let path = entry.unwrap().path();
        if path.is_dir() {
            markdown_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "md") {
            out.push(path);
        }
    }
}

/// Every problem with the documentation under `root`, one line each
/// (`file:line: what`); empty when all is well.
fn check(root: &Path) -> Vec<String> {
    let root = normalise(root);
    let src = root.join(GUIDE_SRC);
    let mut problems = Vec::new();
    let mut pages = vec![root.join("README.md")];
    markdown_files(&src, &mut pages);
    pages.sort();
    let summary = chapters(&root);
    // A page as it renders: the guide's with its includes expanded.
    let rendered = |page: &Path, problems: &mut Vec<String>| -> Option<String> {
        let text = std::fs::read_to_string(page).ok()?;
        Some(if page.starts_with(&src) {
            expand_includes(page, &text, problems)
        } else {
            text
        })
    };
    for page in &pages {
        let Some(text) = rendered(page, &mut problems) else {
            problems.push(format!("{}: cannot be read", page.display()));
            continue;
        };
        let in_guide = page.starts_with(&src);
        let shown = page
            .strip_prefix(&root)
            .unwrap_or(page)
            .display()
            .to_string();
        for (line, target) in links(&text) {
            let at = format!("{shown}:{line}: link `{target}`");
            if target.is_empty() {
                problems.push(format!("{at}: empty target"));
                continue;
            }
            if target.contains("://") || target.starts_with("mailto:") {
                continue; // not checked: no network here
            }
            let (file, fragment) = match target.split_once('#') {
                Some((f, a)) => (f, Some(a)),
                None => (target.as_str(), None),
            };
            let dest = if file.is_empty() {
                page.clone()
            } else if file.starts_with('/') {
                problems.push(format!("{at}: absolute path (make it relative)"));
                continue;
            } else {
                normalise(&page.parent().unwrap().join(file))
            };
            if !dest.exists() {
                let shown = dest.strip_prefix(&root).unwrap_or(&dest).display();
                problems.push(format!("{at}: {shown} does not exist"));
                continue;
            }
            if in_guide && !dest.starts_with(&src) {
                problems.push(format!(
                    "{at}: leaves the guide's {GUIDE_SRC}/ — mdBook copies nothing from outside it (name the file as `code` instead)"
                ));
                continue;
            }
            let is_page = dest.extension().is_some_and(|e| e == "md");
            if in_guide && is_page && !summary.contains(&dest) {
                problems.push(format!(
                    "{at}: not a chapter of SUMMARY.md, so the book has no page for it"
                ));
            }
            if let Some(fragment) = fragment {
                if !is_page {
                    continue;
                }
                let mut ignored = Vec::new();
                let Some(dest_text) = rendered(&dest, &mut ignored) else {
                    continue;
                };
                if !anchors(&dest_text).contains(fragment) {
                    problems.push(format!(
                        "{at}: no heading of {} has the anchor #{fragment}",
                        dest.strip_prefix(&root).unwrap_or(&dest).display()
                    ));
                }
            }
        }
    }
    match std::fs::read_to_string(root.join("README.md")) {
        Ok(readme) => {
            let n = readme.lines().count();
            if n > README_MAX_LINES {
                problems.push(format!(
                    "README.md: {n} lines, more than {README_MAX_LINES}: move the detail into the guide ({GUIDE_SRC}/)"
                ));
            }
        }
        Err(e) => problems.push(format!("README.md: {e}")),
    }
    problems
}

#[test]
fn readme_and_guide_links_resolve_and_readme_is_short() {
    let problems = check(Path::new(env!("CARGO_MANIFEST_DIR")));
    assert!(
        problems.is_empty(),
        "{} documentation problem(s):\n{}",
        problems.len(),
        problems.join("\n")
    );
}

#[test]
fn the_guide_has_its_chapters() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let chapters = chapters(root);
    for name in [
        "quick-start.md",
        "install.md",
        "qgroundcontrol.md",
        "cockpit.md",
        "hmi.md",
        "safety.md",
        "security.md",
        "parameters.md",
        "troubleshooting.md",
        "architecture.md",
        "tests.md",
    ] {
        assert!(
            chapters.contains(&normalise(&root.join(GUIDE_SRC).join(name))),
            "SUMMARY.md lists no {name}"
        );
    }
}

/// The checker itself: a small tree with one of each mistake, and the same
/// tree repaired.
#[test]
fn the_checker_finds_each_kind_of_broken_link() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    let src = root.join(GUIDE_SRC);
    std::fs::create_dir_all(src.join("img")).unwrap();
    std::fs::create_dir_all(root.join("docs/other")).unwrap();
    std::fs::write(src.join("img/a.png"), b"png").unwrap();
    std::fs::write(
        root.join("docs/other/notes.md"),
        "# Notes\n\n## Kept part\n",
    )
    .unwrap();
    std::fs::write(
        src.join("SUMMARY.md"),
        "# Summary\n\n- [One](one.md)\n- [Two](two.md)\n- [Notes](notes.md)\n",
    )
    .unwrap();
    std::fs::write(
        src.join("notes.md"),
        "{{#include ../../other/notes.md:2:}}\n",
    )
    .unwrap();
    let one = "# One\n\n## A `code` heading (with: punctuation)\n\n\
               See [two](two.md#second-part), [kept](notes.md#kept-part), \
               [here](#a-code-heading-with-punctuation) and ![a](img/a.png).\n\n\
               ```sh\n[not a link](nowhere.md)\n```\n\n`[nor this](nowhere.md)`\n";
    std::fs::write(src.join("one.md"), one).unwrap();
    std::fs::write(src.join("two.md"), "# Two\n\n## Second part\n").unwrap();
    let readme = "# R\n\n[guide](docs/guide/src/one.md#one) [web](https://example.org/x)\n";
    std::fs::write(root.join("README.md"), readme).unwrap();
    assert_eq!(check(root), Vec::<String>::new());

    let broken = format!(
        "{one}\n[gone](gone.md) [bad anchor](two.md#third-part) [out](../../other/notes.md) \
         [unlisted](extra.md) ![gone](img/b.png) [self](#nothing)\n{{{{#include ../missing.md}}}}\n"
    );
    std::fs::write(src.join("extra.md"), "# Extra\n").unwrap();
    std::fs::write(src.join("one.md"), broken).unwrap();
    std::fs::write(
        root.join("README.md"),
        "line\n".repeat(README_MAX_LINES + 1),
    )
    .unwrap();
    let problems = check(root).join("\n");
    for expected in [
        "`gone.md`: ",
        "#third-part",
        "`../../other/notes.md`: leaves the guide",
        "`extra.md`: not a chapter",
        "`img/b.png`: ",
        "#nothing",
        "includes ../missing.md",
        "README.md: 251 lines",
    ] {
        assert!(
            problems.contains(expected),
            "{expected} not reported in:\n{problems}"
        );
    }
    assert!(!problems.contains("nowhere.md"), "{problems}");
}
