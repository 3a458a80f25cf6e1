//! The scene reference (`docs/scene.md`) is checked against the scene types
//! (issue 14 check 6), so it cannot drift from them:
//! - every key that the scene types write (every field of every table,
//!   collected from all validation scenes serialised back from their types,
//!   defaults included, and the optional `[limits]` set on one) is named in its table's section of the reference;
//! - every key a section's table lists (`| \`key\` | …`) for a table with fixed
//!   keys is a field of that table in the types.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use mpm_physics::scene::Scene;

/// Every `.toml` under `dir` that is a scene (has `[scene]` and `[grid]`).
fn scene_files(dir: &Path, found: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            scene_files(&path, found);
        } else if path.extension().is_some_and(|e| e == "toml") {
            let text = std::fs::read_to_string(&path).unwrap();
            if text.contains("[scene]") && text.contains("[grid]") {
                found.push(path);
            }
        }
    }
}

/// Field names below `value`, with the tables' own names (map keys of
/// `[materials.NAME]`) skipped.
fn field_names(value: &serde_json::Value, skip_map_level: bool, names: &mut BTreeSet<String>) {
    match value {
        serde_json::Value::Object(map) => {
            for (key, child) in map {
                if skip_map_level {
                    field_names(child, false, names);
                } else {
                    names.insert(key.clone());
                    field_names(child, false, names);
                }
            }
        }
        serde_json::Value::Array(items) => {
            for item in items {
                field_names(item, false, names);
            }
        }
        _ => {}
    }
}

/// The reference's sections by table name (`scene`, `grid`, `materials`, `body`, …).
fn sections() -> BTreeMap<String, String> {
    let text = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/scene.md"))
        .unwrap();
    let mut sections = BTreeMap::new();
    for part in text.split("\n## ").skip(1) {
        let header = part.lines().next().unwrap_or("");
        if let Some(start) = header.find("`[") {
            let name: String = header[start..]
                .trim_start_matches("`[[")
                .trim_start_matches("`[")
                .chars()
                .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                .collect();
            sections.insert(name, part.to_string());
        }
    }
    sections
}

fn mentions(text: &str, word: &str) -> bool {
    text.match_indices(word).any(|(i, _)| {
        let before = text[..i].chars().next_back();
        let after = text[i + word.len()..].chars().next();
        let boundary = |c: Option<char>| !c.is_some_and(|c| c.is_ascii_alphanumeric() || c == '_');
        boundary(before) && boundary(after)
    })
}

#[test]
fn the_scene_reference_matches_the_scene_types() {
    let mut files = Vec::new();
    scene_files(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("validation"),
        &mut files,
    );
    assert!(files.len() >= 30, "{} scenes", files.len());
    // table → fields written by the types (all levels) and its direct fields
    let mut all_fields: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    let mut direct_fields: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    // optional keys that are not written when absent, set on one scene
    let optional = [
        "limits.max_memory_gb=8".to_string(),
        "limits.max_steps=1000".to_string(),
    ];
    let loads = files
        .iter()
        .map(|f| (f, &[][..]))
        .chain(std::iter::once((&files[0], &optional[..])));
    for (file, overrides) in loads {
        let scene =
            Scene::load(file, overrides).unwrap_or_else(|e| panic!("{}: {e}", file.display()));
        let value = serde_json::to_value(&scene).unwrap();
        for (table, content) in value.as_object().unwrap() {
            let names = all_fields.entry(table.clone()).or_default();
            field_names(content, table == "materials", names);
            if let Some(map) = content.as_object() {
                direct_fields
                    .entry(table.clone())
                    .or_default()
                    .extend(map.keys().cloned());
            }
        }
    }
    let sections = sections();
    let mut undocumented = Vec::new();
    for (table, names) in &all_fields {
        let Some(section) = sections.get(table) else {
            undocumented.push(format!("[{table}] (no section)"));
            continue;
        };
        for name in names {
            if !mentions(section, name) {
                undocumented.push(format!("{table}.{name}"));
            }
        }
    }
    assert!(
        undocumented.is_empty(),
        "keys of the scene types missing from docs/scene.md: {undocumented:?}"
    );
    let mut unknown = Vec::new();
    for table in [
        "scene",
        "grid",
        "solver",
        "nonlocal",
        "smoothing",
        "loads",
        "output",
        "limits",
    ] {
        let section = &sections[table];
        let fields = &direct_fields[table];
        for line in section.lines().filter(|l| l.starts_with("| `")) {
            let key = line[3..].split('`').next().unwrap_or("");
            if !fields.contains(key) {
                unknown.push(format!("{table}.{key}"));
            }
        }
    }
    assert!(
        unknown.is_empty(),
        "docs/scene.md lists keys the scene types do not have: {unknown:?}"
    );
}
