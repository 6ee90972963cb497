//! The layering of `src/`, checked rather than hoped for (see
//! docs/ARCHITECTURE.md): the numerical core does no I/O and knows nothing
//! of the store, HTTP, SQL or the CLI, and no two top-level modules depend
//! on each other in a cycle.
//!
//! The check reads the source text: every `crate::name` path outside
//! comments is a dependency of the file's top-level module on `name`, and
//! each forbidden token (`tokio`, `std::fs`, `sqlx`...) in a core file's
//! code is a violation.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The numerical core: plain synchronous Rust, no I/O.
const CORE: &[&str] = &[
    "error",
    "rng",
    "stats",
    "model",
    "report",
    "kinematics",
    "measure",
    "identify",
    "physics",
    "pipeline",
    "plan",
    "compensate",
    "report_html",
    "export",
];

/// What a core file must not use: file, network, process or async I/O,
/// the service's crates, and the layers above the core.
const FORBIDDEN_IN_CORE: &[&str] = &[
    "std::fs",
    "File::",
    "std::net",
    "std::process",
    "std::env",
    "tokio",
    "async ",
    ".await",
    "sqlx",
    "axum",
    "hyper",
    "tower",
    "reqwest",
    "tracing",
    "println!",
    "eprintln!",
    "crate::store",
    "crate::http",
    "crate::jobs",
    "crate::cli",
];

/// The code of a Rust source: comments removed (line, doc and block
/// comments) and string literals emptied (`""`, raw strings too), so that
/// a doc link or a message naming `tokio` is not a use of it.
fn code_of(text: &str) -> String {
    let b = text.as_bytes();
    let mut out = String::with_capacity(text.len());
    let (mut i, mut block) = (0, 0usize);
    while i < b.len() {
        let rest = &b[i..];
        if block > 0 {
            if rest.starts_with(b"*/") {
                block -= 1;
                i += 2;
            } else if rest.starts_with(b"/*") {
                block += 1;
                i += 2;
            } else {
                i += 1;
            }
            continue;
        }
        let prev_ident = i > 0 && (b[i - 1].is_ascii_alphanumeric() || b[i - 1] == b'_');
        if rest.starts_with(b"//") {
            while i < b.len() && b[i] != b'\n' {
                i += 1;
            }
        } else if rest.starts_with(b"/*") {
            block += 1;
            i += 2;
        } else if rest[0] == b'r' && !prev_ident && matches!(rest.get(1), Some(b'"' | b'#')) {
            // A raw string r"..." or r#"..."#: skip to its closing quote
            // followed by as many hashes.
            let hashes = rest[1..].iter().take_while(|&&c| c == b'#').count();
            if rest.get(1 + hashes) != Some(&b'"') {
                out.push('r');
                i += 1;
                continue;
            }
            let close: Vec<u8> = std::iter::once(b'"')
                .chain(std::iter::repeat_n(b'#', hashes))
                .collect();
            let body = 2 + hashes;
            let end = rest[body..]
                .windows(close.len())
                .position(|w| w == close.as_slice())
                .map_or(rest.len(), |p| body + p + close.len());
            out.push_str("\"\"");
            i += end;
        } else if rest[0] == b'"' {
            let mut j = 1;
            while j < rest.len() && rest[j] != b'"' {
                j += if rest[j] == b'\\' { 2 } else { 1 };
            }
            out.push_str("\"\"");
            i += (j + 1).min(rest.len());
        } else if rest[0] == b'\'' && rest.len() > 2 && (rest[2] == b'\'' || rest[1] == b'\\') {
            // A char literal ('"', '\n'): not the start of a string.
            let len = rest[1..]
                .iter()
                .skip(1)
                .position(|&c| c == b'\'')
                .map_or(1, |p| p + 3);
            out.push_str("' '");
            i += len;
        } else {
            let ch = text[i..].chars().next().unwrap();
            out.push(ch);
            i += ch.len_utf8();
        }
    }
    out
}

/// The top-level module a file under `src/` belongs to (`None` for the
/// crate root and the binary).
fn module_of(rel: &Path) -> Option<String> {
    let first = rel.components().next()?.as_os_str().to_str()?;
    match first {
        "lib.rs" | "main.rs" => None,
        f => Some(f.trim_end_matches(".rs").to_string()),
    }
}

/// Every `crate::name` the code uses.
fn crate_paths(code: &str) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    let mut rest = code;
    while let Some(at) = rest.find("crate::") {
        let before = rest[..at].chars().last();
        rest = &rest[at + "crate::".len()..];
        // `drawcal_crate::` or `foo_crate::` are other names.
        if before.is_some_and(|c| c.is_alphanumeric() || c == '_') {
            continue;
        }
        let name: String = rest
            .chars()
            .take_while(|c| c.is_alphanumeric() || *c == '_')
            .collect();
        if !name.is_empty() {
            out.insert(name);
        }
    }
    out
}

/// The layering problems of a set of files (path relative to `src/`, text).
fn violations(files: &[(PathBuf, String)]) -> Vec<String> {
    let mut problems = Vec::new();
    let mut graph: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for (rel, text) in files {
        let Some(module) = module_of(rel) else {
            continue;
        };
        // A file's unit tests (its `#[cfg(test)]` module, at the end by
        // convention) may print and read files.
        let text = text.split("\n#[cfg(test)]").next().unwrap_or(text);
        let code = code_of(text);
        let deps = graph.entry(module.clone()).or_default();
        for dep in crate_paths(&code) {
            if dep != module {
                deps.insert(dep);
            }
        }
        if CORE.contains(&module.as_str()) {
            for token in FORBIDDEN_IN_CORE {
                if let Some(line) = code.lines().position(|l| l.contains(token)) {
                    problems.push(format!(
                        "src/{}:{}: the core module `{module}` uses `{token}`",
                        rel.display(),
                        line + 1
                    ));
                }
            }
        }
    }
    // Core modules depend on core modules only.
    for (module, deps) in &graph {
        if !CORE.contains(&module.as_str()) {
            continue;
        }
        for dep in deps {
            if graph.contains_key(dep) && !CORE.contains(&dep.as_str()) {
                problems.push(format!(
                    "the core module `{module}` depends on `{dep}`, a layer above the core"
                ));
            }
        }
    }
    if let Some(cycle) = find_cycle(&graph) {
        problems.push(format!("a dependency cycle: {}", cycle.join(" -> ")));
    }
    problems
}

/// A cycle among the modules of `graph`, as the modules along it.
fn find_cycle(graph: &BTreeMap<String, BTreeSet<String>>) -> Option<Vec<String>> {
    fn visit<'a>(
        m: &'a str,
        graph: &'a BTreeMap<String, BTreeSet<String>>,
        done: &mut BTreeSet<&'a str>,
        path: &mut Vec<&'a str>,
    ) -> Option<Vec<String>> {
        if let Some(at) = path.iter().position(|p| *p == m) {
            let mut c: Vec<String> = path[at..].iter().map(|s| s.to_string()).collect();
            c.push(m.to_string());
            return Some(c);
        }
        if !done.insert(m) {
            return None;
        }
        path.push(m);
        for dep in graph.get(m).into_iter().flatten() {
            if graph.contains_key(dep) {
                if let Some(c) = visit(dep, graph, done, path) {
                    return Some(c);
                }
            }
        }
        path.pop();
        None
    }
    let mut done = BTreeSet::new();
    graph
        .keys()
        .find_map(|m| visit(m, graph, &mut done, &mut Vec::new()))
}

fn source_files(dir: &Path, root: &Path, out: &mut Vec<(PathBuf, String)>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            source_files(&path, root, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            let text = std::fs::read_to_string(&path).unwrap();
            out.push((path.strip_prefix(root).unwrap().to_path_buf(), text));
        }
    }
}

fn src_files() -> Vec<(PathBuf, String)> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    source_files(&root, &root, &mut files);
    files.sort();
    files
}

#[test]
fn the_layers_hold() {
    let files = src_files();
    // Every top-level module is classified: a new one must be placed.
    let layers = ["store", "jobs", "http", "cli"];
    for (rel, _) in &files {
        if let Some(m) = module_of(rel) {
            assert!(
                CORE.contains(&m.as_str()) || layers.contains(&m.as_str()),
                "src/{}: module `{m}` is neither core nor a known layer; add it to this test",
                rel.display()
            );
        }
    }
    let problems = violations(&files);
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}

#[test]
fn the_check_catches_io_in_the_core_and_cycles() {
    let file = |p: &str, t: &str| (PathBuf::from(p), t.to_string());
    // tokio in the identification: caught, with file and line.
    let v = violations(&[file(
        "identify/mod.rs",
        "use crate::model::Robot;\nuse tokio::fs;\n",
    )]);
    assert_eq!(v.len(), 1, "{v:?}");
    assert!(v[0].contains("src/identify/mod.rs:2") && v[0].contains("tokio"));
    // File I/O in physics, the store from compensate.
    let v = violations(&[
        file(
            "physics/simulate.rs",
            "fn f() { std::fs::write(\"a\", \"b\"); }",
        ),
        file("compensate/mod.rs", "use crate::store::Store;"),
        file("store/mod.rs", "pub struct Store;"),
    ]);
    assert!(v.iter().any(|p| p.contains("`std::fs`")), "{v:?}");
    assert!(v.iter().any(|p| p.contains("`crate::store`")), "{v:?}");
    assert!(v.iter().any(|p| p.contains("depends on `store`")), "{v:?}");
    // A cycle between identify and physics.
    let v = violations(&[
        file("identify/mod.rs", "fn f() { crate::physics::analyse(); }"),
        file("physics/mod.rs", "use crate::identify::Observations;"),
    ]);
    assert!(
        v.iter()
            .any(|p| p.contains("cycle") && p.contains("identify")),
        "{v:?}"
    );
    // Comments and strings do not count: a doc link, a message.
    let v = violations(&[
        file(
            "identify/mod.rs",
            "//! See [`crate::pipeline`].\n/* crate::physics */ fn f() -> &'static str { \"tokio // std::fs\" }",
        ),
        file("pipeline/mod.rs", "use crate::identify::geometric;"),
    ]);
    assert!(v.is_empty(), "{v:?}");
}
