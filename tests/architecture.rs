//! docs/architecture.md matches the code: its import graph is the one the
//! library's `crate::` paths give, it names every source file of both
//! crates, and every document it cites exists. A stage that starts using
//! another, or a new file, fails here until the doc says so.

mod common;

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// The library's source files: path under src/, its text with comments
/// and string contents blanked and its `#[cfg(test)]` items removed (code),
/// and its raw text.
struct Source {
    rel: String,
    code: String,
    raw: String,
}

fn sources(src: &Path) -> Vec<Source> {
    let mut files = Vec::new();
    rust_files(src, &mut files);
    files.sort();
    files
        .into_iter()
        .map(|f| {
            let raw = std::fs::read_to_string(&f).unwrap();
            let rel = f.strip_prefix(src).unwrap().to_string_lossy().replace('\\', "/");
            Source { rel, code: strip_test_items(&blank_comments_and_strings(&raw)), raw }
        })
        .collect()
}

/// `text` with every comment and the inside of every string and char
/// literal replaced by spaces (newlines kept), so braces and paths found in
/// the result are code. Lifetimes (`'a`) stay.
fn blank_comments_and_strings(text: &str) -> String {
    let b: Vec<char> = text.chars().collect();
    let mut out = String::with_capacity(text.len());
    let blank = |c: char| if c == '\n' { '\n' } else { ' ' };
    let mut i = 0;
    while i < b.len() {
        let c = b[i];
        let next = b.get(i + 1).copied();
        if c == '/' && next == Some('/') {
            while i < b.len() && b[i] != '\n' {
                out.push(' ');
                i += 1;
            }
        } else if c == '/' && next == Some('*') {
            let mut depth = 0;
            while i < b.len() {
                if b[i] == '/' && b.get(i + 1) == Some(&'*') {
                    depth += 1;
                    out.push_str("  ");
                    i += 2;
                } else if b[i] == '*' && b.get(i + 1) == Some(&'/') {
                    depth -= 1;
                    out.push_str("  ");
                    i += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    out.push(blank(b[i]));
                    i += 1;
                }
            }
        } else if c == 'r' && (next == Some('"') || next == Some('#')) && (i == 0 || !is_ident(b[i - 1])) {
            // Raw string: r"...", r#"..."#.
            let mut j = i + 1;
            while b.get(j) == Some(&'#') {
                j += 1;
            }
            if b.get(j) != Some(&'"') {
                out.push(c);
                i += 1;
                continue;
            }
            let hashes = j - i - 1;
            out.extend(std::iter::repeat_n(' ', j - i + 1));
            i = j + 1;
            while i < b.len() {
                if b[i] == '"' && (0..hashes).all(|k| b.get(i + 1 + k) == Some(&'#')) {
                    out.extend(std::iter::repeat_n(' ', hashes + 1));
                    i += hashes + 1;
                    break;
                }
                out.push(blank(b[i]));
                i += 1;
            }
        } else if c == '"' {
            out.push(' ');
            i += 1;
            while i < b.len() && b[i] != '"' {
                if b[i] == '\\' {
                    out.push(' ');
                    i += 1;
                }
                if i < b.len() {
                    out.push(blank(b[i]));
                    i += 1;
                }
            }
            out.push(' ');
            i += 1;
        } else if c == '\'' {
            // A char literal ('x', '\n', '\u{..}') or a lifetime ('a).
            let end = if next == Some('\\') {
                (i + 2..b.len().min(i + 12)).find(|&j| b[j] == '\'')
            } else if b.get(i + 2) == Some(&'\'') {
                Some(i + 2)
            } else {
                None
            };
            match end {
                Some(e) => {
                    out.extend(std::iter::repeat_n(' ', e - i + 1));
                    i = e + 1;
                }
                None => {
                    out.push(c);
                    i += 1;
                }
            }
        } else {
            out.push(c);
            i += 1;
        }
    }
    out
}

fn is_ident(c: char) -> bool {
    c.is_alphanumeric() || c == '_'
}

/// The byte index just past the item that starts at `from` (in code with
/// comments and strings blanked): through its `{ ... }` body, or through
/// its `;` if that comes first.
fn item_end(code: &str, from: usize) -> usize {
    let (mut depth, mut brackets) = (0usize, 0i32);
    for (i, c) in code[from..].char_indices() {
        match c {
            '(' | '[' => brackets += 1,
            ')' | ']' => brackets -= 1,
            ';' if depth == 0 && brackets == 0 => return from + i + 1,
            '{' => depth += 1,
            '}' => {
                depth -= 1;
                if depth == 0 {
                    return from + i + 1;
                }
            }
            _ => {}
        }
    }
    code.len()
}

/// `code` with each `#[cfg(test)]` item (a test module, a test-only
/// function or import) blanked, newlines kept: the rest of the file,
/// before and after it, is still checked.
fn strip_test_items(code: &str) -> String {
    let mut out = code.to_string();
    let mut from = 0;
    while let Some(at) = out[from..].find("#[cfg(test)]").map(|i| from + i) {
        let end = item_end(&out, at);
        let blanked: String = out[at..end].chars().map(|c| if c == '\n' { c } else { ' ' }).collect();
        out.replace_range(at..end, &blanked);
        from = end;
    }
    out
}

/// A file's module path (`render/exr/mod.rs` -> render, exr).
fn module_of(rel: &str) -> Vec<String> {
    let mut parts: Vec<String> = rel.trim_end_matches(".rs").split('/').map(String::from).collect();
    if parts.last().is_some_and(|p| p == "mod") {
        parts.pop();
    }
    if parts == ["lib"] {
        parts.clear();
    }
    parts
}

/// Every path a file's code names through `crate::` or `super::`, as
/// module paths from the crate root (a `use` group's lower-case members
/// extend the path, since they may be modules).
fn named_paths(source: &Source) -> Vec<Vec<String>> {
    let me = module_of(&source.rel);
    let code = &source.code;
    let mut paths = Vec::new();
    for keyword in ["crate::", "super::"] {
        for (i, _) in code.match_indices(keyword) {
            if i > 0 && is_ident(code[..i].chars().next_back().unwrap()) || code[..i].ends_with("::") {
                continue;
            }
            let mut base: Vec<String> =
                if keyword == "crate::" { Vec::new() } else { me[..me.len().saturating_sub(1)].to_vec() };
            let mut rest = &code[i + keyword.len()..];
            // Chained `super::super::`.
            while let Some(r) = rest.strip_prefix("super::") {
                base.pop();
                rest = r;
            }
            let mut path = base;
            loop {
                let name: String = rest.chars().take_while(|&c| is_ident(c)).collect();
                if name.is_empty() || !name.starts_with(|c: char| c.is_ascii_lowercase() || c == '_') {
                    break;
                }
                rest = &rest[name.len()..];
                path.push(name);
                match rest.strip_prefix("::") {
                    Some(r) => rest = r,
                    None => break,
                }
            }
            if let Some(group) = rest.strip_prefix('{') {
                let group = &group[..group.find('}').unwrap_or(group.len())];
                for member in group.split(',') {
                    let first = member.trim().split("::").next().unwrap_or("").split_whitespace().next().unwrap_or("");
                    if first.starts_with(|c: char| c.is_ascii_lowercase()) && first != "self" {
                        let mut p = path.clone();
                        p.push(first.to_string());
                        paths.push(p);
                    }
                }
            }
            paths.push(path);
        }
    }
    paths
}

/// Top-level module -> the top-level modules its non-test code names by
/// `crate::` paths (comments and `#[cfg(test)]` items left out; `error`,
/// which every stage uses, too).
fn import_graph(src: &Path) -> BTreeMap<String, BTreeSet<String>> {
    let mut graph: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for source in sources(src) {
        let top = source.rel.split('/').next().unwrap().trim_end_matches(".rs").to_string();
        if top == "lib" || top == "error" {
            continue;
        }
        let deps = graph.entry(top.clone()).or_default();
        for (i, _) in source.code.match_indices("crate::") {
            let name: String =
                source.code[i + 7..].chars().take_while(|c| c.is_ascii_lowercase() || *c == '_').collect();
            if !name.is_empty() && name != top && name != "error" {
                deps.insert(name);
            }
        }
    }
    graph
}

/// File -> the files its non-test code names through `crate::` and
/// `super::` paths (the longest prefix of each path that is a file).
fn file_graph(src: &Path) -> BTreeMap<String, BTreeSet<String>> {
    let sources = sources(src);
    let files: BTreeMap<Vec<String>, String> = sources.iter().map(|s| (module_of(&s.rel), s.rel.clone())).collect();
    let mut graph = BTreeMap::new();
    for source in &sources {
        let mut deps = BTreeSet::new();
        for path in named_paths(source) {
            let file = (1..=path.len()).rev().find_map(|k| files.get(&path[..k]));
            if let Some(file) = file.filter(|f| **f != source.rel) {
                deps.insert(file.clone());
            }
        }
        graph.insert(source.rel.clone(), deps);
    }
    graph
}

/// The fenced block after the heading "## Which module uses which":
/// `module -> a, b (why), c` lines.
fn documented_graph(doc: &str) -> BTreeMap<String, BTreeSet<String>> {
    let section =
        doc.split("## Which module uses which").nth(1).expect("the doc has a 'Which module uses which' section");
    let block = section.split("```").nth(1).expect("a fenced graph in that section");
    let mut graph = BTreeMap::new();
    for line in block.lines().filter(|l| l.contains("->")) {
        let (from, to) = line.split_once("->").unwrap();
        // Drop parenthesised notes, which may hold commas.
        let mut bare = String::new();
        let mut depth = 0;
        for c in to.chars() {
            match c {
                '(' => depth += 1,
                ')' => depth -= 1,
                c if depth == 0 => bare.push(c),
                _ => {}
            }
        }
        let deps = bare.split(',').map(str::trim).filter(|d| !d.is_empty() && *d != "-").map(String::from).collect();
        graph.insert(from.trim().to_string(), deps);
    }
    graph
}

fn doc() -> String {
    std::fs::read_to_string(common::repo_path("docs/architecture.md")).unwrap()
}

#[test]
fn the_documented_import_graph_is_the_code_s() {
    let code = import_graph(&common::repo_path("src"));
    let documented = documented_graph(&doc());
    assert_eq!(
        documented, code,
        "docs/architecture.md's graph (left) differs from the `crate::` imports in src/ (right)"
    );
}

#[test]
fn every_source_file_is_named_in_the_doc() {
    let doc = doc();
    for src in ["src", "cli/src"] {
        let mut files = Vec::new();
        rust_files(&common::repo_path(src), &mut files);
        for f in files {
            let rel = f.strip_prefix(common::repo_path(src)).unwrap().to_string_lossy().replace('\\', "/");
            // A file is named by its path under its crate's src/ in
            // backticks (`render/exr/mattes.rs`); a folder's `mod.rs` may be
            // named by the folder (`render/exr/`).
            let named = doc.contains(&format!("`{rel}`"))
                || rel.ends_with("/mod.rs") && doc.contains(&format!("`{}`", rel.trim_end_matches("mod.rs")));
            assert!(named, "docs/architecture.md does not name {src}/{rel}");
        }
    }
}

#[test]
fn every_document_the_doc_cites_exists() {
    let doc = doc();
    for word in doc.split(|c: char| c.is_whitespace() || "`()[],;:".contains(c)) {
        let word = word.trim_end_matches('.');
        if word.ends_with(".md") {
            let path = if word.contains('/') { common::repo_path(word) } else { common::repo_path("docs").join(word) };
            assert!(path.is_file(), "docs/architecture.md cites {word}, which is not in the repository");
        }
    }
    assert!(!doc.contains("SPEC"), "docs/architecture.md cites a SPEC that is not in the repository");
}

#[test]
fn no_circle_of_imports_between_files() {
    let graph = file_graph(&common::repo_path("src"));
    // Depth-first search; a back edge closes a circle, reported as its path.
    fn visit(
        f: &str,
        graph: &BTreeMap<String, BTreeSet<String>>,
        state: &mut BTreeMap<String, u8>,
        stack: &mut Vec<String>,
        circles: &mut Vec<String>,
    ) {
        state.insert(f.to_string(), 1);
        stack.push(f.to_string());
        for d in graph.get(f).into_iter().flatten() {
            match state.get(d.as_str()).copied().unwrap_or(0) {
                0 => visit(d, graph, state, stack, circles),
                1 => {
                    let from = stack.iter().position(|s| s == d).unwrap();
                    circles.push(format!("{} -> {d}", stack[from..].join(" -> ")));
                }
                _ => {}
            }
        }
        stack.pop();
        state.insert(f.to_string(), 2);
    }
    let mut state = BTreeMap::new();
    let mut circles = Vec::new();
    for f in graph.keys() {
        if !state.contains_key(f.as_str()) {
            visit(f, &graph, &mut state, &mut Vec::new(), &mut circles);
        }
    }
    assert!(circles.is_empty(), "files in src/ import each other in a circle:\n{}", circles.join("\n"));
}

/// Every function's length in lines, from its `fn` line to its closing
/// brace: (file, line, name, lines).
fn function_lengths(source: &Source) -> Vec<(usize, String, usize)> {
    let code = &source.code;
    let line_of = |at: usize| code[..at].matches('\n').count() + 1;
    let mut out = Vec::new();
    for (at, _) in code.match_indices("fn ") {
        if at > 0 && is_ident(code[..at].chars().next_back().unwrap()) {
            continue;
        }
        let name: String = code[at + 3..].trim_start().chars().take_while(|&c| is_ident(c)).collect();
        if name.is_empty() {
            continue;
        }
        let end = item_end(code, at);
        if !code[at..end].ends_with('}') {
            continue; // a declaration without a body
        }
        out.push((line_of(at), name, line_of(end) - line_of(at) + 1));
    }
    out
}

#[test]
fn no_function_is_too_long() {
    let mut long = Vec::new();
    for source in sources(&common::repo_path("src")) {
        // The path tracer and casting read as small named steps.
        let limit = if source.rel.starts_with("render/") || source.rel.starts_with("casting/") { 120 } else { 200 };
        for (line, name, lines) in function_lengths(&source) {
            if lines > limit {
                long.push(format!("src/{}:{line}: fn {name} is {lines} lines (at most {limit})", source.rel));
            }
        }
    }
    assert!(long.is_empty(), "split these into named steps:\n{}", long.join("\n"));
}

#[test]
fn every_allow_gives_its_reason() {
    let mut bare = Vec::new();
    for src in ["src", "cli/src"] {
        for source in sources(&common::repo_path(src)) {
            let code = &source.code;
            for (at, _) in code.match_indices("allow(") {
                if !code[..at].ends_with("#[") && !code[..at].ends_with("#![") {
                    continue;
                }
                let close = code[at..].find(")]").map_or(code.len(), |i| at + i);
                if !code[at..close].contains("reason") {
                    let line = code[..at].matches('\n').count() + 1;
                    bare.push(format!("{src}/{}:{line}", source.rel));
                }
            }
        }
    }
    assert!(bare.is_empty(), "#[allow] without `reason = \"...\"`:\n{}", bare.join("\n"));
}

#[test]
fn the_library_has_no_mutable_static() {
    let mut found = Vec::new();
    for source in sources(&common::repo_path("src")) {
        for (n, line) in source.code.lines().enumerate() {
            let t = line.trim_start();
            let t = t.strip_prefix("pub(crate) ").or_else(|| t.strip_prefix("pub ")).unwrap_or(t);
            let Some(decl) = t.strip_prefix("static ") else { continue };
            let ty = decl.split_once(':').map_or("", |(_, ty)| ty);
            let interior = ["Atomic", "Mutex", "RwLock", "Cell", "OnceLock", "LazyLock"];
            if decl.starts_with("mut ") || interior.iter().any(|k| ty.contains(k)) {
                found.push(format!("src/{}:{}: {}", source.rel, n + 1, line.trim()));
            }
        }
    }
    assert!(
        found.is_empty(),
        "a process-wide switch in the library (make it a field of the settings that need it):\n{}",
        found.join("\n")
    );
}

#[test]
fn comments_carry_no_dated_figure() {
    // A measurement ages in a comment: dates, CPU models and measured ratios
    // belong in docs/benchmarks.md, the comment keeps the why.
    let marks =
        ["Xeon", "EPYC", "Ryzen", "Zen 4", "Zen 5", "Emerald Rapids", "Sapphire Rapids", "Skylake", "this session"];
    let mut found = Vec::new();
    for src in ["src", "cli/src"] {
        for source in sources(&common::repo_path(src)) {
            for (n, line) in source.raw.lines().enumerate() {
                let Some(at) = line.find("//") else { continue };
                let comment = &line[at..];
                let dated = comment.as_bytes().windows(8).any(|w| {
                    w[..2] == *b"20"
                        && w[2..4].iter().all(u8::is_ascii_digit)
                        && w[4] == b'-'
                        && w[5..7].iter().all(u8::is_ascii_digit)
                });
                let ratio = comment
                    .split(|c: char| c.is_whitespace() || "(),;".contains(c))
                    .any(|w| w.strip_suffix('x').is_some_and(|n| n.contains('.') && n.parse::<f64>().is_ok()));
                if dated || ratio || marks.iter().any(|m| comment.contains(m)) {
                    found.push(format!("{src}/{}:{}: {}", source.rel, n + 1, line.trim()));
                }
            }
        }
    }
    assert!(found.is_empty(), "measured figures in comments (move them to docs/benchmarks.md):\n{}", found.join("\n"));
}

#[test]
fn the_checks_read_what_they_should() {
    // The scanner itself: code after a test-only item is still read, the
    // test item is not, and strings and comments hide nothing from the brace count.
    let raw = "fn a() { let s = \"}\"; }\n#[cfg(test)]\nfn only_in_tests() { crate::x::y(); }\n// crate::commented\nfn b() {\n    crate::render::job::run();\n}\n";
    let source = Source {
        rel: "farm/plan.rs".into(),
        code: strip_test_items(&blank_comments_and_strings(raw)),
        raw: raw.into(),
    };
    let paths = named_paths(&source);
    assert_eq!(paths, vec![vec!["render".to_string(), "job".into(), "run".into()]]);
    assert_eq!(function_lengths(&source), vec![(1, "a".to_string(), 1), (5, "b".to_string(), 3)]);
    let sup = Source {
        rel: "render/exr/mattes.rs".into(),
        code: "use super::{header, Film};\nuse super::super::film::X;".into(),
        raw: String::new(),
    };
    let paths = named_paths(&sup);
    assert!(paths.contains(&vec!["render".to_string(), "exr".into(), "header".into()]), "{paths:?}");
    assert!(paths.contains(&vec!["render".to_string(), "film".into()]), "{paths:?}");
}
