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

/// Top-level module -> the top-level modules its non-test code names by
/// `crate::` paths (comments and `#[cfg(test)]` modules left out; `error`,
/// which every stage uses, too).
fn import_graph(src: &Path) -> BTreeMap<String, BTreeSet<String>> {
    let mut files = Vec::new();
    rust_files(src, &mut files);
    let mut graph: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for f in files {
        let rel = f.strip_prefix(src).unwrap();
        let top = rel.components().next().unwrap().as_os_str().to_string_lossy().trim_end_matches(".rs").to_string();
        if top == "lib" || top == "error" {
            continue;
        }
        let text = std::fs::read_to_string(&f).unwrap();
        let code = text.split("#[cfg(test)]").next().unwrap();
        let deps = graph.entry(top.clone()).or_default();
        for line in code.lines().filter(|l| !l.trim_start().starts_with("//")) {
            for (i, _) in line.match_indices("crate::") {
                let name: String = line[i + 7..].chars().take_while(|c| c.is_ascii_lowercase() || *c == '_').collect();
                if !name.is_empty() && name != top && name != "error" {
                    deps.insert(name);
                }
            }
        }
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
