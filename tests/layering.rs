//! Two crates and no circle (issue 42, item 1).
//!
//! The physics crate (`physics/src`) never depends on the application
//! (`src`): Cargo enforces that. Inside each crate, this test enforces that
//! the top-level modules (`src/X.rs` or `src/X/`) form layers: it reads the
//! `crate::…` paths of every module file (`use crate::a::…`,
//! `use crate::{a, b::{…}}`, `crate::a::f(…)` in code), builds the graph
//! "module X names module Y", and fails, naming the circle and the files
//! that close it, if some module reaches itself.
//!
//! What is not counted: comments (a doc link is no import), and unit tests
//! (`tests.rs` files and the `#[cfg(test)] mod tests` at the end of a
//! file), which may use any module of their crate to build their cases.

use std::collections::{BTreeMap, BTreeSet};
use std::fs;
use std::path::{Path, PathBuf};

/// Module → (module it names → files that name it).
type Graph = BTreeMap<String, BTreeMap<String, BTreeSet<String>>>;

/// The `.rs` files under `dir`, recursively, sorted.
fn rust_files(dir: &Path) -> Vec<PathBuf> {
    let mut files = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in fs::read_dir(&d).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
            } else if path.extension().is_some_and(|e| e == "rs") {
                files.push(path);
            }
        }
    }
    files.sort();
    files
}

/// The file's code without comments and without its unit tests.
fn code(text: &str) -> String {
    let text = match text.find("#[cfg(test)]\nmod tests") {
        Some(at) => &text[..at],
        None => text,
    };
    let mut out = String::new();
    for line in text.lines() {
        // no string of the sources holds `//` before a `crate::` path
        let line = line.split("//").next().unwrap_or("");
        out.push_str(line);
        out.push('\n');
    }
    out
}

fn is_ident(c: char) -> bool {
    c.is_ascii_alphanumeric() || c == '_'
}

/// The first path segments after every `crate::` of `code`, including each
/// item of a `crate::{a, b::{c, d}}` group.
fn crate_references(code: &str) -> BTreeSet<String> {
    let mut names = BTreeSet::new();
    let bytes = code.as_bytes();
    let mut from = 0;
    while let Some(at) = code[from..].find("crate::") {
        let start = from + at;
        from = start + "crate::".len();
        // `mpm_crate::` or `$crate::` are not this crate's paths
        if start > 0 && (is_ident(bytes[start - 1] as char) || bytes[start - 1] == b'$') {
            continue;
        }
        let rest = &code[from..];
        if let Some(group) = rest.strip_prefix('{') {
            // the items at depth 1 of the group
            let mut depth = 1;
            let mut item_start = true;
            let mut name = String::new();
            for c in group.chars() {
                if depth == 1 && item_start && is_ident(c) {
                    name.push(c);
                    continue;
                }
                if !name.is_empty() {
                    names.insert(std::mem::take(&mut name));
                    item_start = false;
                }
                match c {
                    '{' => depth += 1,
                    '}' => {
                        depth -= 1;
                        if depth == 0 {
                            break;
                        }
                    }
                    ',' if depth == 1 => item_start = true,
                    _ => {}
                }
            }
            if !name.is_empty() {
                names.insert(name);
            }
        } else {
            let name: String = rest.chars().take_while(|&c| is_ident(c)).collect();
            if !name.is_empty() {
                names.insert(name);
            }
        }
    }
    names
}

/// The top-level module graph of the crate whose sources are `src`.
fn module_graph(src: &Path) -> Graph {
    let mut modules = BTreeSet::new();
    for entry in fs::read_dir(src).unwrap() {
        let path = entry.unwrap().path();
        let name = path.file_stem().unwrap().to_string_lossy().to_string();
        if path.is_dir()
            || (path.extension().is_some_and(|e| e == "rs") && name != "lib" && name != "main")
        {
            modules.insert(name);
        }
    }
    let mut graph: Graph = modules
        .iter()
        .map(|m| (m.clone(), BTreeMap::new()))
        .collect();
    for file in rust_files(src) {
        let relative = file.strip_prefix(src).unwrap();
        let first = relative
            .components()
            .next()
            .unwrap()
            .as_os_str()
            .to_string_lossy()
            .to_string();
        let module = first.trim_end_matches(".rs").to_string();
        if !modules.contains(&module) || file.file_name().is_some_and(|n| n == "tests.rs") {
            continue;
        }
        let text = fs::read_to_string(&file).unwrap();
        for name in crate_references(&code(&text)) {
            if name != module && modules.contains(&name) {
                graph
                    .get_mut(&module)
                    .unwrap()
                    .entry(name)
                    .or_default()
                    .insert(relative.display().to_string());
            }
        }
    }
    graph
}

/// A circle of `graph` (its modules in order, the first repeated at the
/// end), if there is one.
fn find_circle(graph: &Graph) -> Option<Vec<String>> {
    // 0: not seen, 1: on the current path, 2: done
    fn visit(
        graph: &Graph,
        module: &str,
        state: &mut BTreeMap<String, u8>,
        path: &mut Vec<String>,
    ) -> Option<Vec<String>> {
        state.insert(module.to_string(), 1);
        path.push(module.to_string());
        for next in graph[module].keys() {
            match state.get(next).copied().unwrap_or(0) {
                1 => {
                    let at = path.iter().position(|m| m == next).unwrap();
                    let mut circle = path[at..].to_vec();
                    circle.push(next.clone());
                    return Some(circle);
                }
                0 => {
                    if let Some(circle) = visit(graph, next, state, path) {
                        return Some(circle);
                    }
                }
                _ => {}
            }
        }
        path.pop();
        state.insert(module.to_string(), 2);
        None
    }
    let mut state = BTreeMap::new();
    for module in graph.keys() {
        if state.get(module).copied().unwrap_or(0) == 0 {
            if let Some(circle) = visit(graph, module, &mut state, &mut Vec::new()) {
                return Some(circle);
            }
        }
    }
    None
}

/// The circle, each step with the files that take it.
fn describe(graph: &Graph, circle: &[String]) -> String {
    let mut text = circle.join(" -> ");
    for pair in circle.windows(2) {
        let files: Vec<&str> = graph[&pair[0]][&pair[1]]
            .iter()
            .map(String::as_str)
            .collect();
        text.push_str(&format!(
            "\n  {} -> {}: {}",
            pair[0],
            pair[1],
            files.join(", ")
        ));
    }
    text
}

fn check(crate_dir: &str) {
    // another checkout's tree can be checked with LAYERING_ROOT=DIR
    let root = std::env::var_os("LAYERING_ROOT")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")));
    let src = root.join(crate_dir);
    let graph = module_graph(&src);
    assert!(graph.len() > 5, "{crate_dir}: too few modules found");
    if let Some(circle) = find_circle(&graph) {
        panic!(
            "the top-level modules of {crate_dir} import each other in a circle: {}",
            describe(&graph, &circle)
        );
    }
}

#[test]
fn application_modules_form_layers() {
    check("src");
}

#[test]
fn physics_modules_form_layers() {
    check("physics/src");
}

#[test]
fn references_are_read_from_paths_and_groups() {
    let code = code(
        "use crate::grid::Grid;\nuse crate::{a, b::{c, d}, e::f as g};\n\
         let x = crate::h::k(); // crate::comment\n$crate::macro_path\nmpm_crate::other\n\
         #[cfg(test)]\nmod tests {\n    use crate::tested;\n}\n",
    );
    let names: Vec<String> = crate_references(&code).into_iter().collect();
    assert_eq!(names, ["a", "b", "e", "grid", "h"]);
    let mut graph = Graph::new();
    for (from, to) in [("a", "b"), ("b", "c"), ("c", "a")] {
        graph
            .entry(from.into())
            .or_default()
            .entry(to.into())
            .or_default()
            .insert(format!("{from}.rs"));
    }
    assert_eq!(find_circle(&graph).unwrap(), ["a", "b", "c", "a"]);
    graph.get_mut("c").unwrap().clear();
    assert_eq!(find_circle(&graph), None);
}
