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
