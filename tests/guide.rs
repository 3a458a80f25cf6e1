//! The user guide (`docs/guide.md`, issue 14 check 6) cannot drift from the
//! program:
//! - every `mpm-geo` command of its `sh` blocks runs, in order, in a scratch
//!   directory, to exit code 0, in a short form: `--set scene.steps=2`
//!   appended to `run`, `campaign` and `study` (the scenes it runs are
//!   implicit; a campaign's explicit twins run to the same 2-step end time);
//! - every scene it names exists and passes `check`;
//! - its error list is exactly `mpm-geo errors`, the program's own list of
//!   identifiers.
//!
//! The scene reference (`docs/scene.md`) is checked against the scene types
//! by `tests/scene_reference.rs`.

use std::path::PathBuf;
use std::process::Command;

fn repository() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn guide() -> String {
    std::fs::read_to_string(repository().join("docs/guide.md")).unwrap()
}

/// The command lines of the guide's `sh` blocks, comments removed.
fn shell_lines(text: &str) -> Vec<String> {
    let mut lines = Vec::new();
    let mut inside = false;
    for line in text.lines() {
        if line.starts_with("```") {
            inside = !inside && line.trim() == "```sh";
            continue;
        }
        if inside {
            let command = match line.find(" #") {
                Some(i) => &line[..i],
                None => line,
            };
            if !command.trim().is_empty() {
                lines.push(command.trim().to_string());
            }
        }
    }
    lines
}

/// Split a command line into words (double quotes group words).
fn words(line: &str) -> Vec<String> {
    let mut words = Vec::new();
    let mut current = String::new();
    let mut quoted = false;
    for c in line.chars() {
        match c {
            '"' => quoted = !quoted,
            ' ' if !quoted => {
                if !current.is_empty() {
                    words.push(std::mem::take(&mut current));
                }
            }
            c => current.push(c),
        }
    }
    if !current.is_empty() {
        words.push(current);
    }
    words
}

#[test]
fn every_guide_command_runs() {
    let scratch = tempfile::tempdir().unwrap();
    std::os::unix::fs::symlink(
        repository().join("validation"),
        scratch.path().join("validation"),
    )
    .unwrap();
    let lines = shell_lines(&guide());
    let mut ran = 0;
    for line in &lines {
        let words = words(line);
        if words[0] == "cargo" {
            // building and testing is what CI does; `cargo install` is cargo's own
            continue;
        }
        assert_eq!(words[0], "mpm-geo", "{line}");
        let mut args: Vec<String> = words[1..].to_vec();
        if ["run", "campaign", "study", "paper"].contains(&args[0].as_str()) {
            if args[0] == "run" {
                let scene = std::fs::read_to_string(scratch.path().join(&args[1])).unwrap();
                assert!(
                    !scene.contains("\"explicit\""),
                    "{line}: the short form is for implicit scenes"
                );
            }
            // a collect is given the same overrides as its shards
            args.extend(["--set".into(), "scene.steps=2".into()]);
        }
        let output = Command::new(env!("CARGO_BIN_EXE_mpm-geo"))
            .args(&args)
            .current_dir(scratch.path())
            .output()
            .unwrap();
        assert!(
            output.status.success(),
            "`{line}` failed: {}",
            String::from_utf8_lossy(&output.stderr)
        );
        ran += 1;
    }
    println!("{ran} guide commands ran");
    assert!(ran >= 15, "only {ran} commands found");
}

/// `a{b,c}d{e,f}` → abde, abdf, acde, acdf.
fn expand_braces(pattern: &str) -> Vec<String> {
    match (pattern.find('{'), pattern.find('}')) {
        (Some(open), Some(close)) if open < close => pattern[open + 1..close]
            .split(',')
            .flat_map(|choice| {
                expand_braces(&format!(
                    "{}{choice}{}",
                    &pattern[..open],
                    &pattern[close + 1..]
                ))
            })
            .collect(),
        _ => vec![pattern.to_string()],
    }
}

#[test]
fn every_scene_the_guide_names_is_valid() {
    let text = guide();
    let mut scenes = Vec::new();
    for (start, _) in text.match_indices("validation/") {
        let rest = &text[start..];
        let end = rest
            .find(|c: char| c.is_whitespace() || c == '`' || c == ')')
            .unwrap_or(rest.len());
        let path = &rest[..end];
        if path.ends_with(".toml") {
            scenes.extend(expand_braces(path));
        }
    }
    assert!(scenes.len() >= 20, "{scenes:?}");
    for scene in &scenes {
        let path = repository().join(scene);
        assert!(path.is_file(), "{scene} does not exist");
        let is_study = scene.contains("/studies/") || scene.ends_with("campaign.toml");
        if is_study {
            continue;
        }
        let output = Command::new(env!("CARGO_BIN_EXE_mpm-geo"))
            .arg("check")
            .arg(&path)
            .output()
            .unwrap();
        assert!(output.status.success(), "{scene} is not a valid scene");
    }
}

#[test]
fn the_guide_lists_exactly_the_programs_error_identifiers() {
    let output = Command::new(env!("CARGO_BIN_EXE_mpm-geo"))
        .arg("errors")
        .output()
        .unwrap();
    assert!(output.status.success());
    let table = String::from_utf8(output.stdout).unwrap();
    let text = guide();
    let marker = "<!-- error list";
    let section = &text[text.find(marker).expect("the guide's error list marker")..];
    let section = &section[section.find("-->").unwrap() + 3..];
    assert_eq!(
        section.trim(),
        table.trim(),
        "docs/guide.md's error table differs from `mpm-geo errors`: paste its output there"
    );
    assert!(table.lines().count() > 40);
}
