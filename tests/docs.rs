//! The documentation's own checks: the README's size and first example, the test command CI
//! runs, no dated notebook entries in the README and `docs/`, links that resolve, and
//! `docs/scenes.md` generated from the scene settings' own definitions.
//!
//! `docs/scenes.md` is made from the doc comments of the scene structs (`src/scene/mod.rs`,
//! `src/scene/thickness.rs`: every field's doc ends with a `- unit:` and a `- default:` line)
//! and the presets of `src/scene/materials.rs`. The field names the parser finds are checked
//! against the names serde deserializes, so a field the parser misses fails too. To
//! regenerate the page after changing a setting:
//!
//! ```text
//! UPDATE_DOCS=1 cargo test --release --test docs
//! ```

use furrow::coupling::wavelength::Bilayer;
use furrow::scene::materials::{INTERIOR_PRESETS, SKIN_PRESETS};
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::PathBuf;

/// The project's root (where `Cargo.toml` is).
fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn read(rel: &str) -> String {
    std::fs::read_to_string(root().join(rel)).unwrap_or_else(|e| panic!("{rel}: {e}"))
}

/// The README, then every `docs/*.md`, as (path, text).
fn pages() -> Vec<(String, String)> {
    let mut out = vec![("README.md".to_string(), read("README.md"))];
    let mut docs: Vec<PathBuf> = std::fs::read_dir(root().join("docs"))
        .expect("docs/")
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "md"))
        .collect();
    docs.sort();
    for p in docs {
        let rel = format!("docs/{}", p.file_name().unwrap().to_string_lossy());
        out.push((rel.clone(), read(&rel)));
    }
    out
}

// ----- the README -------------------------------------------------------------------------

/// At most this many lines: a newcomer reads it at once; the rest is in `docs/`.
const README_MAX_LINES: usize = 250;

/// `furrow animate` (the main job) appears within this many lines.
const FIRST_EXAMPLE_WITHIN: usize = 40;

#[test]
fn readme_is_short_and_shows_the_main_job_first() {
    let readme = read("README.md");
    let lines: Vec<&str> = readme.lines().collect();
    assert!(
        lines.len() <= README_MAX_LINES,
        "README.md has {} lines, at most {README_MAX_LINES}: move detail to docs/",
        lines.len()
    );
    let first = lines
        .iter()
        .take(FIRST_EXAMPLE_WITHIN)
        .position(|l| l.contains("furrow animate"));
    assert!(
        first.is_some(),
        "README.md: no `furrow animate` example within its first {FIRST_EXAMPLE_WITHIN} lines"
    );
}

/// The test commands `.ci/run` runs: its lines that start with `cargo test`.
fn ci_test_commands() -> Vec<String> {
    read(".ci/run")
        .lines()
        .map(str::trim)
        .filter(|l| l.starts_with("cargo test"))
        .map(str::to_string)
        .collect()
}

#[test]
fn readme_holds_the_test_command_ci_runs() {
    let commands = ci_test_commands();
    assert!(!commands.is_empty(), ".ci/run runs no `cargo test` command");
    let readme = read("README.md");
    for c in commands {
        assert!(
            readme.lines().any(|l| l.trim() == c),
            "README.md does not show `{c}` (the test command .ci/run runs) on a line of its own"
        );
    }
}

// ----- no notebook entries ----------------------------------------------------------------

/// Where `text` holds an ISO date (dddd-dd-dd), `issue N` or `stop N` (any case): the
/// matches, for the message.
fn notebook_marks(text: &str) -> Vec<String> {
    let lower = text.to_lowercase();
    let b = lower.as_bytes();
    let digit = |i: usize| i < b.len() && b[i].is_ascii_digit();
    let mut found = Vec::new();
    for i in 0..b.len() {
        let date = (0..4).all(|k| digit(i + k))
            && b.get(i + 4) == Some(&b'-')
            && digit(i + 5)
            && digit(i + 6)
            && b.get(i + 7) == Some(&b'-')
            && digit(i + 8)
            && digit(i + 9);
        if date {
            found.push(lower[i..i + 10].to_string());
        }
        for word in ["issue", "stop"] {
            let starts_word = i == 0 || !b[i - 1].is_ascii_alphanumeric();
            if starts_word && b[i..].starts_with(word.as_bytes()) {
                let mut j = i + word.len();
                let spaced = j < b.len() && b[j].is_ascii_whitespace();
                while j < b.len() && b[j].is_ascii_whitespace() {
                    j += 1;
                }
                if spaced && digit(j) {
                    found.push(lower[i..(j + 1).min(lower.len())].to_string());
                }
            }
        }
    }
    found
}

#[test]
fn readme_and_docs_carry_no_dates_issues_or_stops() {
    for (path, text) in pages() {
        for (n, line) in text.lines().enumerate() {
            let marks = notebook_marks(line);
            assert!(
                marks.is_empty(),
                "{path}:{}: {marks:?}: dates and issue/stop numbers belong in CHANGELOG.md or git",
                n + 1
            );
        }
    }
}

#[test]
fn the_notebook_check_sees_what_it_looks_for() {
    assert_eq!(notebook_marks("run on 2026-11-27 at noon"), ["2026-11-27"]);
    assert_eq!(notebook_marks("see Issue 18."), ["issue 1"]);
    assert_eq!(notebook_marks("stop  43's code"), ["stop  4"]);
    assert!(notebook_marks("nonstop 4 issues 3 stop-gap 1e-3 2026").is_empty());
}

// ----- links ------------------------------------------------------------------------------

/// The relative link targets of a markdown text (`](target)`), without their `#anchor`.
fn relative_links(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut rest = text;
    while let Some(i) = rest.find("](") {
        rest = &rest[i + 2..];
        let end = rest.find(')').unwrap_or(rest.len());
        let target = rest[..end].split('#').next().unwrap_or("").trim();
        let external = target.contains("://") || target.starts_with("mailto:");
        if !target.is_empty() && !external {
            out.push(target.to_string());
        }
    }
    out
}

#[test]
fn every_relative_link_resolves() {
    let readme_docs: Vec<String> = relative_links(&read("README.md"))
        .into_iter()
        .filter(|l| l.starts_with("docs/") && l.ends_with(".md"))
        .collect();
    assert!(!readme_docs.is_empty(), "README.md links no docs/*.md page");
    for (path, text) in pages() {
        let dir = root().join(&path);
        let dir = dir.parent().unwrap();
        for link in relative_links(&text) {
            assert!(
                dir.join(&link).exists(),
                "{path}: the link `{link}` leads nowhere"
            );
        }
    }
}

// ----- quoted report files ----------------------------------------------------------------

/// Marks a page's verbatim copy of a file a furrow command writes:
/// `<!-- quote: PATH -->`, the file's text, `<!-- end quote -->`.
const QUOTE_START: &str = "<!-- quote: ";
const QUOTE_END: &str = "<!-- end quote -->";

/// The quoted blocks of a page: (path, byte range of the quoted text).
fn quotes(text: &str) -> Vec<(String, std::ops::Range<usize>)> {
    let mut out = Vec::new();
    let mut from = 0;
    while let Some(i) = text[from..].find(QUOTE_START) {
        let head = from + i + QUOTE_START.len();
        let close = text[head..].find("-->").expect("an unclosed quote mark") + head;
        let path = text[head..close].trim().to_string();
        let body = text[close..]
            .find('\n')
            .map_or(text.len(), |n| close + n + 1);
        let end = text[body..]
            .find(QUOTE_END)
            .unwrap_or_else(|| panic!("quote of {path}: no `{QUOTE_END}`"))
            + body;
        out.push((path, body..end));
        from = end + QUOTE_END.len();
    }
    out
}

/// Pages that quote a report file (`docs/performance.md`, `docs/validation.md`) hold it as
/// the file now reads; `UPDATE_DOCS=1` copies the files in.
#[test]
fn quoted_report_files_are_current() {
    for (path, text) in pages() {
        let mut updated = text.clone();
        for (file, range) in quotes(&text).into_iter().rev() {
            let now = read(&file);
            let (fence, quoted) = unfenced(&text[range.clone()]);
            if quoted.trim_end() == now.trim_end() {
                continue;
            }
            assert!(
                std::env::var_os("UPDATE_DOCS").is_some(),
                "{path} quotes {file} as it no longer reads; copy it in with\n  UPDATE_DOCS=1 cargo test --release --test docs"
            );
            let body = match fence {
                Some(open) => format!("{open}\n{}\n```\n", now.trim_end()),
                None => format!("{}\n", now.trim_end()),
            };
            updated.replace_range(range, &body);
        }
        if updated != text {
            std::fs::write(root().join(&path), updated).unwrap();
            println!("rewrote the quotes of {path}");
        }
    }
}

/// A quoted block's text without its code fence (a CSV is quoted inside ```` ```csv ````),
/// and the fence's opening line when it has one.
fn unfenced(block: &str) -> (Option<&str>, &str) {
    let Some(rest) = block.strip_prefix("```") else {
        return (None, block);
    };
    let open_end = rest.find('\n').map_or(block.len(), |n| n + 4);
    let inner = &block[open_end.min(block.len())..];
    let inner = inner.trim_end();
    let inner = inner.strip_suffix("```").unwrap_or(inner);
    (Some(&block[..open_end - 1]), inner)
}

#[test]
fn table_cells_show_intra_doc_links_as_code() {
    assert_eq!(
        cell("see [`SKIN_HOLDS`]: a | b"),
        "see `SKIN_HOLDS`: a \\| b"
    );
    assert_eq!(cell("[`x`](y) and [`z`]"), "[`x`](y) and `z`");
}

#[test]
fn the_quote_marks_are_found() {
    assert_eq!(
        unfenced("```csv\na,b\n1,2\n```\n"),
        (Some("```csv"), "a,b\n1,2\n")
    );
    assert_eq!(unfenced("| t |\n"), (None, "| t |\n"));
    let page = "a\n<!-- quote: x.md -->\n| t |\n<!-- end quote -->\nb <!-- quote: y.csv -->\n1,2\n<!-- end quote -->";
    let q = quotes(page);
    assert_eq!(q.len(), 2);
    assert_eq!(
        (q[0].0.as_str(), &page[q[0].1.clone()]),
        ("x.md", "| t |\n")
    );
    assert_eq!((q[1].0.as_str(), &page[q[1].1.clone()]), ("y.csv", "1,2\n"));
}

// ----- docs/scenes.md ---------------------------------------------------------------------

/// One field of a scene struct as its source declares it.
#[derive(Debug, Clone, PartialEq)]
struct FieldDoc {
    name: String,
    ty: String,
    doc: Vec<String>,
}

/// One struct: its doc comment and fields.
#[derive(Debug, Clone, PartialEq)]
struct StructDoc {
    doc: Vec<String>,
    fields: Vec<FieldDoc>,
}

/// Net bracket depth change of a line of code: `(`, `[`, `{`, `<` open, their pairs close
/// (`->` and `=>` are not brackets).
fn depth_change(code: &str) -> i32 {
    let code = code.replace("->", "").replace("=>", "");
    code.chars()
        .map(|c| match c {
            '(' | '[' | '{' | '<' => 1,
            ')' | ']' | '}' | '>' => -1,
            _ => 0,
        })
        .sum()
}

/// The text of a `///` doc line, or `None` for another line.
fn doc_text(line: &str) -> Option<String> {
    let t = line.trim_start();
    let body = t.strip_prefix("///")?;
    if body.starts_with('/') {
        return None;
    }
    Some(
        body.strip_prefix(' ')
            .unwrap_or(body)
            .trim_end()
            .to_string(),
    )
}

/// A field declaration `pub name: Type...` (any visibility): its name and the type text on
/// this line.
fn field_start(line: &str) -> Option<(String, String)> {
    let t = line.trim();
    let t = t.strip_prefix("pub")?;
    let t = if t.starts_with('(') {
        &t[t.find(')')? + 1..]
    } else {
        t
    };
    if !t.starts_with(char::is_whitespace) {
        return None;
    }
    let (name, ty) = t.trim_start().split_once(':')?;
    let name = name.trim().trim_start_matches("r#");
    if name.is_empty() || !name.chars().all(|c| c.is_alphanumeric() || c == '_') {
        return None;
    }
    Some((name.to_string(), ty.trim().to_string()))
}

/// Every braced `pub struct` of a Rust source, by name, with its doc comment and each
/// field's name, type and doc comment. Attributes (one or several lines), blank lines and
/// `//` comments between a doc comment and its item are skipped; a type may span lines.
fn parse_structs(src: &str) -> BTreeMap<String, StructDoc> {
    let mut out = BTreeMap::new();
    let mut doc: Vec<String> = Vec::new();
    let mut lines = src.lines().peekable();
    let mut current: Option<(String, StructDoc)> = None;
    while let Some(line) = lines.next() {
        let t = line.trim();
        if let Some(d) = doc_text(line) {
            doc.push(d);
        } else if t.starts_with("#[") {
            let mut depth = depth_change(t);
            while depth > 0 {
                depth += depth_change(lines.next().unwrap_or("]"));
            }
        } else if t.is_empty() || t.starts_with("//") {
        } else if let Some(rest) = t.strip_prefix("pub struct ").filter(|r| r.ends_with('{')) {
            let name: String = rest
                .chars()
                .take_while(|c| c.is_alphanumeric() || *c == '_')
                .collect();
            let s = StructDoc {
                doc: std::mem::take(&mut doc),
                fields: Vec::new(),
            };
            current = Some((name, s));
        } else if let (Some((_, s)), Some((name, mut ty))) = (current.as_mut(), field_start(t)) {
            let mut depth = depth_change(&ty);
            while depth > 0 || !(ty.ends_with(',') || lines.peek().is_some_and(|l| l.trim() == "}"))
            {
                let Some(next) = lines.next() else { break };
                ty.push(' ');
                ty.push_str(next.trim());
                depth += depth_change(next);
            }
            s.fields.push(FieldDoc {
                name,
                ty: ty.trim_end_matches(',').trim().to_string(),
                doc: std::mem::take(&mut doc),
            });
        } else {
            if t == "}" {
                if let Some((name, s)) = current.take() {
                    out.insert(name, s);
                }
            }
            doc.clear();
        }
    }
    out
}

/// The struct a field's type names, through `Option<…>`, `Vec<…>` and paths, and whether it
/// is a list of them.
fn inner_type(ty: &str) -> (String, bool) {
    let mut t = ty.replace(' ', "").replace(",>", ">");
    let mut list = false;
    loop {
        if let Some(x) = t.strip_prefix("Option<").and_then(|x| x.strip_suffix('>')) {
            t = x.to_string();
        } else if let Some(x) = t.strip_prefix("Vec<").and_then(|x| x.strip_suffix('>')) {
            t = x.to_string();
            list = true;
        } else {
            break;
        }
    }
    let last = t.rsplit("::").next().unwrap_or(&t).to_string();
    (last, list)
}

/// A field's meaning, unit and default from its doc comment: the `- unit:` and `- default:`
/// items (continued on indented lines) and the text before them as one paragraph.
fn split_doc(doc: &[String]) -> Result<(String, String, String), String> {
    let mut meaning = Vec::new();
    let mut items: Vec<(String, String)> = Vec::new();
    for line in doc {
        let lower = line.trim_start().to_lowercase();
        if let Some(key) = ["unit", "default"]
            .into_iter()
            .find(|k| lower.starts_with(&format!("- {k}:")))
        {
            let value = line.trim_start()[key.len() + 3..].trim().to_string();
            items.push((key.to_string(), value));
        } else if let (Some(last), true) = (items.last_mut(), line.starts_with(' ')) {
            last.1.push(' ');
            last.1.push_str(line.trim());
        } else if items.is_empty() {
            meaning.push(line.trim());
        } else {
            return Err(format!("text after the unit and default lines: {line:?}"));
        }
    }
    let get = |k: &str| {
        items
            .iter()
            .find(|(key, _)| key == k)
            .map(|(_, v)| v.clone())
            .ok_or_else(|| format!("no `- {k}:` line"))
    };
    let meaning = meaning
        .into_iter()
        .filter(|l| !l.is_empty())
        .collect::<Vec<_>>()
        .join(" ");
    Ok((meaning, get("unit")?, get("default")?))
}

/// A markdown table cell: rustdoc's intra-doc links (`` [`name`] ``) as plain code, pipes
/// escaped.
fn cell(s: &str) -> String {
    let mut out = String::new();
    let mut rest = s;
    while let Some(i) = rest.find("[`") {
        let Some(len) = rest[i + 2..].find("`]") else {
            break;
        };
        let after = &rest[i + 2 + len + 2..];
        out.push_str(&rest[..i]);
        if after.starts_with('(') || after.starts_with('[') {
            out.push_str(&rest[i..i + 2 + len + 2]);
        } else {
            out.push('`');
            out.push_str(&rest[i + 2..i + 2 + len]);
            out.push('`');
        }
        rest = after;
    }
    out.push_str(rest);
    out.replace('|', "\\|")
}

/// The text under a struct's heading: its doc comment's first paragraph, without a leading
/// `` `[name]`: `` that repeats the heading, capitalised.
fn struct_intro(s: &StructDoc) -> String {
    let text = s
        .doc
        .iter()
        .map(|l| l.trim())
        .take_while(|l| !l.is_empty())
        .collect::<Vec<_>>()
        .join(" ");
    let text = match text.strip_prefix('`').and_then(|t| t.split_once("`: ")) {
        Some((_, rest)) => rest.to_string(),
        None => text,
    };
    let mut chars = text.chars();
    chars.next().map_or(String::new(), |c| {
        c.to_uppercase().chain(chars).collect::<String>()
    })
}

/// One table of `fields` (of the struct at `path`, e.g. `skin`), and the sub-tables of the
/// struct-typed fields whose struct is not yet documented; `done` holds the documented ones.
fn write_table(
    md: &mut String,
    structs: &BTreeMap<String, StructDoc>,
    path: &str,
    fields: &[FieldDoc],
    done: &mut Vec<String>,
    errors: &mut Vec<String>,
) {
    md.push_str("| key | unit | default | meaning |\n| --- | --- | --- | --- |\n");
    let mut nested = Vec::new();
    for f in fields {
        let key = if path.is_empty() {
            f.name.clone()
        } else {
            format!("{path}.{}", f.name)
        };
        match split_doc(&f.doc) {
            Ok((meaning, unit, default)) => {
                let _ = writeln!(
                    md,
                    "| `{key}` | {} | {} | {} |",
                    cell(&unit),
                    cell(&default),
                    cell(&meaning)
                );
            }
            Err(e) => errors.push(format!("`{key}`: {e}")),
        }
        let (inner, list) = inner_type(&f.ty);
        if structs.contains_key(&inner) && !done.contains(&inner) {
            done.push(inner.clone());
            nested.push((key, inner, list));
        }
    }
    for (key, inner, list) in nested {
        let s = &structs[&inner];
        let (heading, path) = if list {
            (format!("`{key}[]`, each entry"), format!("{key}[]"))
        } else {
            (format!("`{key}`"), key.clone())
        };
        let _ = writeln!(md, "\n### {heading}\n\n{}\n", struct_intro(s));
        write_table(md, structs, &path, &s.fields, done, errors);
    }
}

/// Numbers for the presets table: up to four significant digits, no trailing zeros.
fn num(x: f64) -> String {
    let s = format!("{x:.4}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    s.to_string()
}

/// The presets table and λ of every skin preset on every interior preset, from
/// `furrow::scene::materials`.
fn presets_markdown() -> String {
    let mut md = String::from("## Material presets\n\nFrom `src/scene/materials.rs`; any value can be overridden in the scene.\n\n");
    md.push_str("| preset | section | E (Pa) | ν | h (mm) or ρ (kg/m³) | from |\n| --- | --- | --- | --- | --- | --- |\n");
    for p in &SKIN_PRESETS {
        let m = p.material;
        let _ = writeln!(
            md,
            "| `{}` | `[skin]` | {:e} | {} | h {} | {} |",
            p.name,
            m.young,
            num(m.poisson),
            num(m.thickness * 1e3),
            cell(p.note)
        );
    }
    for p in &INTERIOR_PRESETS {
        let m = p.material;
        let _ = writeln!(
            md,
            "| `{}` | `[interior]` | {:e} | {} | ρ {} | {} |",
            p.name,
            m.young,
            num(m.poisson),
            num(m.density),
            cell(p.note)
        );
    }
    md.push_str("\nThe critical wavelength λ (mm) of each pair (`furrow wavelength` computes any other):\n\n| skin \\ interior |");
    for q in &INTERIOR_PRESETS {
        let _ = write!(md, " `{}` |", q.name);
    }
    md.push_str("\n| --- |");
    md.push_str(&" ---: |".repeat(INTERIOR_PRESETS.len()));
    md.push('\n');
    for p in &SKIN_PRESETS {
        let _ = write!(md, "| `{}` |", p.name);
        for q in &INTERIOR_PRESETS {
            let b = Bilayer {
                thickness: p.material.thickness,
                skin_modulus: p.material.young,
                skin_poisson: p.material.poisson,
                interior_modulus: q.material.young,
                interior_poisson: q.material.poisson,
            };
            let _ = write!(md, " {:.1} |", b.critical_wavelength() * 1e3);
        }
        md.push('\n');
    }
    md
}

/// The scene source files the page is generated from, as (path, text).
fn scene_sources() -> Vec<(String, String)> {
    ["src/scene/mod.rs", "src/scene/thickness.rs"]
        .iter()
        .map(|p| (p.to_string(), read(p)))
        .collect()
}

/// `docs/scenes.md` from the scene sources: the top-level keys, one section per struct-typed
/// field of `Scene`, the presets. An error lists every field without a unit or default.
fn scenes_markdown(sources: &[(String, String)]) -> Result<String, String> {
    let mut structs = BTreeMap::new();
    for (_, text) in sources {
        structs.extend(parse_structs(text));
    }
    let scene = structs.get("Scene").ok_or("no `pub struct Scene`")?;
    let mut md = String::from(
        "# Scene files\n\n\
         <!-- Generated from the doc comments of src/scene/mod.rs and src/scene/thickness.rs and the\n\
         presets of src/scene/materials.rs: do not edit. After changing a setting, run\n\
         `UPDATE_DOCS=1 cargo test --release --test docs` (tests/docs.rs checks the page is current). -->\n\n\
         A scene file (TOML) says what a run needs: `furrow animate RIG -o OUT.glb --scene S.toml`\n\
         for a rig, `furrow scene S.toml` for a synthetic block (with `[geometry]` and `[load]`).\n\
         Every key is optional; a run without a scene uses the defaults below. Unknown keys are\n\
         errors, and every value is checked with a message naming the key. Units are SI (lengths\n\
         in metres of the simulated model). Examples: `examples/robot.toml` (a rig),\n\
         `examples/slab.toml`, `examples/cushions.toml`, `examples/cubes.toml` (synthetic).\n\n",
    );
    let mut errors = Vec::new();
    let mut done = vec!["Scene".to_string()];
    let (sections, top): (Vec<&FieldDoc>, Vec<&FieldDoc>) = scene
        .fields
        .iter()
        .partition(|f| structs.contains_key(&inner_type(&f.ty).0));
    md.push_str("## Top level\n\n");
    let top: Vec<FieldDoc> = top.into_iter().cloned().collect();
    write_table(&mut md, &structs, "", &top, &mut done, &mut errors);
    for f in sections {
        let inner = inner_type(&f.ty).0;
        let s = &structs[&inner];
        done.push(inner.clone());
        let _ = writeln!(md, "\n## `[{}]`\n\n{}\n", f.name, struct_intro(s));
        write_table(
            &mut md,
            &structs,
            &f.name,
            &s.fields,
            &mut done,
            &mut errors,
        );
    }
    md.push('\n');
    md.push_str(&presets_markdown());
    if errors.is_empty() {
        Ok(md)
    } else {
        Err(format!(
            "scene fields without a `- unit:` / `- default:` doc line:\n  {}",
            errors.join("\n  ")
        ))
    }
}

/// The field names serde reads for a struct `T` (its `deserialize_struct` field list).
fn serde_fields<T: serde::de::DeserializeOwned>() -> Vec<&'static str> {
    use serde::de::{Error as _, Visitor};
    struct Recorder(Option<&'static [&'static str]>);
    impl<'de> serde::Deserializer<'de> for &mut Recorder {
        type Error = serde::de::value::Error;
        fn deserialize_any<V: Visitor<'de>>(self, _: V) -> Result<V::Value, Self::Error> {
            Err(Self::Error::custom("not a struct"))
        }
        fn deserialize_struct<V: Visitor<'de>>(
            self,
            _: &'static str,
            fields: &'static [&'static str],
            _: V,
        ) -> Result<V::Value, Self::Error> {
            self.0 = Some(fields);
            Err(Self::Error::custom("recorded"))
        }
        serde::forward_to_deserialize_any! {
            bool i8 i16 i32 i64 i128 u8 u16 u32 u64 u128 f32 f64 char str string bytes
            byte_buf option unit unit_struct newtype_struct seq tuple tuple_struct map enum
            identifier ignored_any
        }
    }
    let mut r = Recorder(None);
    let _ = T::deserialize(&mut r);
    r.0.expect("a struct").to_vec()
}

/// The serde field names of every scene struct the page documents, by struct name.
fn scene_serde_fields() -> BTreeMap<&'static str, Vec<&'static str>> {
    use furrow::scene::*;
    BTreeMap::from([
        ("Scene", serde_fields::<Scene>()),
        ("RigSection", serde_fields::<RigSection>()),
        ("SkinSection", serde_fields::<SkinSection>()),
        ("Aabb", serde_fields::<Aabb>()),
        ("InteriorSection", serde_fields::<InteriorSection>()),
        ("DynamicsSection", serde_fields::<DynamicsSection>()),
        ("MuscleSection", serde_fields::<MuscleSection>()),
        ("SolverSection", serde_fields::<SolverSection>()),
        ("ExportSection", serde_fields::<ExportSection>()),
        ("Geometry", serde_fields::<Geometry>()),
        ("Load", serde_fields::<Load>()),
        ("ThicknessRegion", serde_fields::<ThicknessRegion>()),
        ("ThicknessTexture", serde_fields::<ThicknessTexture>()),
    ])
}

/// The structs reachable from `Scene` through struct-typed fields.
fn reachable(structs: &BTreeMap<String, StructDoc>) -> Vec<String> {
    let mut seen = vec!["Scene".to_string()];
    let mut i = 0;
    while i < seen.len() {
        for f in &structs[&seen[i]].fields {
            let inner = inner_type(&f.ty).0;
            if structs.contains_key(&inner) && !seen.contains(&inner) {
                seen.push(inner);
            }
        }
        i += 1;
    }
    seen
}

#[test]
fn the_parser_finds_every_field_serde_reads() {
    let mut structs = BTreeMap::new();
    for (_, text) in scene_sources() {
        structs.extend(parse_structs(&text));
    }
    let serde = scene_serde_fields();
    for name in reachable(&structs) {
        let wanted = serde.get(name.as_str()).unwrap_or_else(|| {
            panic!("scene struct `{name}` is new: add it to scene_serde_fields in tests/docs.rs")
        });
        let parsed: Vec<&str> = structs[&name]
            .fields
            .iter()
            .map(|f| f.name.as_str())
            .collect();
        assert_eq!(
            &parsed, wanted,
            "`{name}`: the fields parsed from the source differ from serde's"
        );
    }
}

#[test]
fn scenes_md_is_generated_from_the_scene_settings() {
    let md = scenes_markdown(&scene_sources()).unwrap_or_else(|e| panic!("{e}"));
    let path = root().join("docs/scenes.md");
    let on_disk = std::fs::read_to_string(&path).unwrap_or_default();
    if on_disk == md {
        return;
    }
    if std::env::var_os("UPDATE_DOCS").is_some() {
        std::fs::write(&path, &md).unwrap();
        println!("rewrote {}", path.display());
        return;
    }
    let line = md
        .lines()
        .zip(on_disk.lines())
        .position(|(a, b)| a != b)
        .unwrap_or(md.lines().count().min(on_disk.lines().count()));
    panic!(
        "docs/scenes.md is out of date with the scene settings (first difference at line {}:\n  generated: {:?}\n  on disk:   {:?}).\nRegenerate it with\n  UPDATE_DOCS=1 cargo test --release --test docs",
        line + 1,
        md.lines().nth(line).unwrap_or(""),
        on_disk.lines().nth(line).unwrap_or("")
    );
}

/// The check above can fail: a field added, removed or redocumented in the source changes
/// the generated page, and a field without its unit or default is an error.
#[test]
fn scenes_md_changes_with_any_field_or_doc() {
    let sources = scene_sources();
    let page = scenes_markdown(&sources).unwrap();
    let edit = |from: &str, to: &str| -> Result<String, String> {
        let mut s = sources.clone();
        assert!(s[0].1.contains(from), "{from:?} not in src/scene/mod.rs");
        s[0].1 = s[0].1.replacen(from, to, 1);
        scenes_markdown(&s)
    };
    let dt = "    pub dt: Option<f64>,\n";
    let added = edit(
        dt,
        &format!("{dt}    /// A new key.\n    /// - unit: s\n    /// - default: 1\n    pub new_key: Option<f64>,\n"),
    )
    .unwrap();
    assert!(added.contains("`dynamics.new_key`") && added != page);
    // The field with its doc comment: the `///` lines just above it.
    let mod_rs = &sources[0].1;
    let at = mod_rs.find(dt).expect("the dt field");
    let doc_start = mod_rs[..at]
        .lines()
        .rev()
        .take_while(|l| l.trim_start().starts_with("///"))
        .map(|l| l.len() + 1)
        .sum::<usize>();
    let dt_with_doc = &mod_rs[at - doc_start..at + dt.len()];
    let removed = edit(dt_with_doc, "").unwrap();
    assert!(!removed.contains("`dynamics.dt`") && removed != page);
    let redoc = edit("/// - default: 0.02", "/// - default: 0.01").unwrap();
    assert!(redoc != page);
    let undocumented = edit(dt, &format!("{dt}    pub bare: Option<f64>,\n"));
    assert!(undocumented.unwrap_err().contains("dynamics.bare"));
}

#[test]
fn the_struct_parser_reads_attributes_and_wrapped_types() {
    let src = "/// A.\n#[derive(\n    Debug,\n)]\npub struct A {\n    /// x.\n    /// - unit: m\n    #[serde(\n        default\n    )]\n    pub x: Option<\n        Vec<f64>,\n    >,\n    // a comment\n    pub(crate) y: [f64; 3],\n}\n";
    let s = parse_structs(src);
    let a = &s["A"];
    assert_eq!(a.doc, ["A."]);
    assert_eq!(a.fields.len(), 2, "{a:?}");
    assert_eq!(a.fields[0].name, "x");
    assert_eq!(inner_type(&a.fields[0].ty), ("f64".to_string(), true));
    assert_eq!(a.fields[1].name, "y");
    assert!(a.fields[1].doc.is_empty());
}
