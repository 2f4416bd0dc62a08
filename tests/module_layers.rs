//! Every `crate::` path in `src/` points down the layer list of `lib.rs` ([`furrow::LAYERS`]):
//! a module uses only modules of lower layers.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let p = entry.unwrap().path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|e| e == "rs") {
            out.push(p);
        }
    }
}

fn layer_of() -> BTreeMap<&'static str, usize> {
    let mut m = BTreeMap::new();
    for (i, layer) in furrow::LAYERS.iter().enumerate() {
        for &module in *layer {
            assert!(m.insert(module, i).is_none(), "{module} is listed twice");
        }
    }
    m
}

/// Top-level modules named by `crate::` paths in the code of `text` (comments left out),
/// including those in grouped imports `crate::{a::x, b}`; in a file `depth` modules below the
/// crate root, `super::` repeated `depth` times is the crate root too (up to the file's test
/// module, whose `super::` is one level deeper).
fn crate_paths(text: &str, depth: usize) -> Vec<(usize, String)> {
    let root = "super::".repeat(depth);
    let mut out = Vec::new();
    let mut in_tests = false;
    for (n, line) in text.lines().enumerate() {
        in_tests |= line.trim() == "#[cfg(test)]";
        let code = line.split("//").next().unwrap_or("");
        let code = if in_tests {
            code.to_string()
        } else {
            code.replace(&root, "crate::")
        };
        let code = code.as_str();
        let mut rest = code;
        while let Some(i) = rest.find("crate::") {
            let after = &rest[i + "crate::".len()..];
            if let Some(group) = after.strip_prefix('{') {
                let end = group.find('}').unwrap_or(group.len());
                for item in group[..end].split(',') {
                    let name: String = item
                        .trim()
                        .chars()
                        .take_while(|c| c.is_alphanumeric() || *c == '_')
                        .collect();
                    if !name.is_empty() {
                        out.push((n + 1, name));
                    }
                }
            } else {
                let name: String = after
                    .chars()
                    .take_while(|c| c.is_alphanumeric() || *c == '_')
                    .collect();
                out.push((n + 1, name));
            }
            rest = after;
        }
    }
    out
}

#[test]
fn every_crate_path_points_down_the_layer_list() {
    let layers = layer_of();
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    let mut wrong = Vec::new();
    let mut checked = 0;
    for f in &files {
        let rel = f.strip_prefix(&src).unwrap();
        let first = rel
            .components()
            .next()
            .unwrap()
            .as_os_str()
            .to_string_lossy();
        let own = first.trim_end_matches(".rs").to_string();
        if own == "lib" || own == "main" {
            continue;
        }
        let own_layer = *layers
            .get(own.as_str())
            .unwrap_or_else(|| panic!("src/{own} is not in furrow::LAYERS"));
        let text = std::fs::read_to_string(f).unwrap();
        // Module depth: src/a.rs and src/a/mod.rs are 1, src/a/b.rs is 2, ...
        let parts = rel.components().count();
        let depth = if rel.ends_with("mod.rs") {
            parts - 1
        } else {
            parts
        };
        for (line, dep) in crate_paths(&text, depth) {
            checked += 1;
            if dep == own || dep == "LAYERS" {
                continue;
            }
            match layers.get(dep.as_str()) {
                Some(&l) if l < own_layer => {}
                Some(&l) => wrong.push(format!(
                    "{}:{line}: {own} (layer {own_layer}) uses crate::{dep} (layer {l})",
                    rel.display()
                )),
                None => wrong.push(format!(
                    "{}:{line}: crate::{dep} is not a module",
                    rel.display()
                )),
            }
        }
    }
    assert!(
        checked > 250,
        "only {checked} crate:: paths found: is the scan broken?"
    );
    assert!(
        wrong.is_empty(),
        "{} paths point up or across:\n{}",
        wrong.len(),
        wrong.join("\n")
    );
}

#[test]
fn the_scan_reads_grouped_imports_and_skips_comments() {
    let text = "use crate::{mesh::TriMesh, math};\n// crate::cli in a comment\nlet x = crate::io::load(); // crate::studies\n";
    let found: Vec<String> = crate_paths(text, 2).into_iter().map(|(_, m)| m).collect();
    assert_eq!(found, vec!["mesh", "math", "io"]);
    let up = crate_paths("use super::super::pipeline::run;\nuse super::plot;\n", 2);
    assert_eq!(up, vec![(1, "pipeline".to_string())]);
}

/// The module path of `rel` (a file under `src/`): `pipeline/step/mod.rs` is
/// `pipeline::step`, `pipeline/step/skin.rs` is `pipeline::step::skin`.
fn module_of(rel: &Path) -> Vec<String> {
    let mut parts: Vec<String> = rel
        .components()
        .map(|c| {
            c.as_os_str()
                .to_string_lossy()
                .trim_end_matches(".rs")
                .to_string()
        })
        .collect();
    if parts.last().is_some_and(|p| p == "mod" || p == "lib") {
        parts.pop();
    }
    parts
}

/// `text` without comments and without its test module (tests may use anything).
fn code_of(text: &str) -> String {
    let mut out = String::new();
    for line in text.lines() {
        if line.trim() == "#[cfg(test)]" {
            break;
        }
        out.push_str(line.split("//").next().unwrap_or(""));
        out.push('\n');
    }
    out
}

/// The paths a `use` tree names, grouped imports expanded: `a::{b, c::{d, e}}` is `a::b`,
/// `a::c::d` and `a::c::e`.
fn expand_use(tree: &str) -> Vec<String> {
    let tree: String = tree.chars().filter(|c| !c.is_whitespace()).collect();
    let Some(open) = tree.find('{') else {
        return vec![tree];
    };
    let (prefix, group) = (&tree[..open], &tree[open + 1..tree.len() - 1]);
    let mut items = Vec::new();
    let (mut depth, mut start) = (0, 0);
    for (i, c) in group.char_indices() {
        match c {
            '{' => depth += 1,
            '}' => depth -= 1,
            ',' if depth == 0 => {
                items.push(&group[start..i]);
                start = i + 1;
            }
            _ => {}
        }
    }
    items.push(&group[start..]);
    items
        .into_iter()
        .filter(|i| !i.is_empty())
        .flat_map(|i| expand_use(&format!("{prefix}{i}")))
        .collect()
}

/// Every module path the code of a file names: `use` trees and paths written inline,
/// beginning with `crate`, `super` or `self`, or with a module `use`d by its last name.
fn named_paths(code: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut rest = code;
    while let Some(i) = rest.find("use ") {
        let before = rest[..i].chars().last();
        rest = &rest[i + 4..];
        if before.is_some_and(|c| c.is_alphanumeric() || c == '_') {
            continue;
        }
        let end = rest.find(';').unwrap_or(rest.len());
        out.extend(expand_use(&rest[..end]));
        rest = &rest[end..];
    }
    let bytes = code.as_bytes();
    for start in ["crate::", "super::", "self::"] {
        let mut from = 0;
        while let Some(i) = code[from..].find(start) {
            let i = from + i;
            from = i + start.len();
            if i > 0
                && (bytes[i - 1].is_ascii_alphanumeric()
                    || bytes[i - 1] == b'_'
                    || bytes[i - 1] == b':')
            {
                continue;
            }
            let path: String = code[i..]
                .chars()
                .take_while(|c| c.is_alphanumeric() || *c == '_' || *c == ':')
                .collect();
            out.push(path);
        }
    }
    out
}

/// The module file a path written in module `at` leads to: the longest prefix of the
/// resolved path that is a module of `modules`.
fn file_of(
    path: &str,
    at: &[String],
    modules: &BTreeMap<Vec<String>, PathBuf>,
) -> Option<Vec<String>> {
    let mut segs = path.split("::").filter(|s| !s.is_empty()).peekable();
    let mut m: Vec<String> = match segs.peek().copied() {
        Some("crate") => {
            segs.next();
            Vec::new()
        }
        Some("super") | Some("self") => at.to_vec(),
        // A path through a child module or a module `use`d by name is resolved where
        // the `use` is; others (std, external crates, items) lead nowhere.
        Some(first) if modules.contains_key(&[at, &[first.to_string()]].concat()) => at.to_vec(),
        _ => return None,
    };
    for s in segs {
        match s {
            "super" => {
                m.pop();
            }
            "self" => {}
            _ => {
                let mut next = m.clone();
                next.push(s.to_string());
                if modules.contains_key(&next) {
                    m = next;
                } else {
                    break;
                }
            }
        }
    }
    Some(m)
}

/// The strongly connected components of more than one file in `edges` (Tarjan).
fn cycles(edges: &BTreeMap<Vec<String>, Vec<Vec<String>>>) -> Vec<Vec<Vec<String>>> {
    struct Walk<'a> {
        edges: &'a BTreeMap<Vec<String>, Vec<Vec<String>>>,
        index: BTreeMap<Vec<String>, (usize, usize)>,
        stack: Vec<Vec<String>>,
        on: std::collections::BTreeSet<Vec<String>>,
        out: Vec<Vec<Vec<String>>>,
    }
    fn visit(w: &mut Walk, v: &Vec<String>) {
        let n = w.index.len();
        w.index.insert(v.clone(), (n, n));
        w.stack.push(v.clone());
        w.on.insert(v.clone());
        for u in w.edges.get(v).into_iter().flatten() {
            if !w.index.contains_key(u) {
                visit(w, u);
                let low = w.index[u].1.min(w.index[v].1);
                w.index.get_mut(v).unwrap().1 = low;
            } else if w.on.contains(u) {
                let low = w.index[u].0.min(w.index[v].1);
                w.index.get_mut(v).unwrap().1 = low;
            }
        }
        if w.index[v].0 == w.index[v].1 {
            let mut comp = Vec::new();
            while let Some(u) = w.stack.pop() {
                w.on.remove(&u);
                let done = &u == v;
                comp.push(u);
                if done {
                    break;
                }
            }
            if comp.len() > 1 {
                w.out.push(comp);
            }
        }
    }
    let mut w = Walk {
        edges,
        index: BTreeMap::new(),
        stack: Vec::new(),
        on: Default::default(),
        out: Vec::new(),
    };
    for v in edges.keys() {
        if !w.index.contains_key(v) {
            visit(&mut w, v);
        }
    }
    w.out
}

/// Which file uses which, over `src/`, leaving out a module's use of its own descendants
/// (a `mod.rs` is the face of the files below it).
fn file_edges() -> BTreeMap<Vec<String>, Vec<Vec<String>>> {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    let modules: BTreeMap<Vec<String>, PathBuf> = files
        .iter()
        .map(|f| (module_of(f.strip_prefix(&src).unwrap()), f.clone()))
        .collect();
    let mut edges = BTreeMap::new();
    for (at, f) in &modules {
        let code = code_of(&std::fs::read_to_string(f).unwrap());
        let mut to: Vec<Vec<String>> = named_paths(&code)
            .iter()
            .filter_map(|p| file_of(p, at, &modules))
            .filter(|m| !m.starts_with(at) && !m.is_empty())
            .collect();
        to.sort();
        to.dedup();
        edges.insert(at.clone(), to);
    }
    edges
}

/// No two files use each other, directly or around a loop: each file can be read after the
/// files it uses.
#[test]
fn no_files_import_each_other_in_a_cycle() {
    let edges = file_edges();
    let used: usize = edges.values().map(Vec::len).sum();
    assert!(
        used > 500,
        "only {used} file uses found: is the scan broken?"
    );
    // Each cycle with the uses inside it, so the message says which `use` to move.
    let found: Vec<String> = cycles(&edges)
        .iter()
        .map(|c| {
            let inside: Vec<String> = c
                .iter()
                .flat_map(|a| {
                    edges[a]
                        .iter()
                        .filter(|b| c.contains(b))
                        .map(move |b| format!("{} → {}", a.join("::"), b.join("::")))
                })
                .collect();
            inside.join(", ")
        })
        .collect();
    assert!(
        found.is_empty(),
        "{} import cycles between files:\n{}",
        found.len(),
        found.join("\n")
    );
}

#[test]
fn the_cycle_scan_resolves_paths_and_finds_a_loop() {
    assert_eq!(
        expand_use("super::{record::{A, B}, setup}"),
        vec!["super::record::A", "super::record::B", "super::setup"]
    );
    let m = |s: &str| s.split("::").map(String::from).collect::<Vec<_>>();
    let modules: BTreeMap<Vec<String>, PathBuf> =
        ["pipeline", "pipeline::record", "pipeline::setup"]
            .iter()
            .map(|s| (m(s), PathBuf::new()))
            .collect();
    let at = m("pipeline::record");
    assert_eq!(
        file_of("super::setup::Model", &at, &modules),
        Some(m("pipeline::setup"))
    );
    assert_eq!(
        file_of("crate::pipeline::record::X", &at, &modules),
        Some(m("pipeline::record"))
    );
    assert_eq!(file_of("std::fmt", &at, &modules), None);
    let edges = BTreeMap::from([
        (m("a"), vec![m("b")]),
        (m("b"), vec![m("c")]),
        (m("c"), vec![m("a")]),
        (m("d"), vec![m("a")]),
    ]);
    assert_eq!(cycles(&edges).len(), 1);
    assert_eq!(cycles(&edges)[0].len(), 3);
}
