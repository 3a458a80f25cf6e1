//! Every citation of the physics reference resolves (issue 42, check 4).
//!
//! `docs/theory.md` defines the labels the repository cites:
//! - sections: a heading numbered `N` or `N.M` (`### 8.1 Biaxial …`), cited
//!   as `theory §8.1` (or `docs/theory.md §8.1`, or a bare `§8.1`);
//! - equations and items: `(D20)` or `(D23; paper eq. 3)` at the end of a
//!   line, or a line opening in bold with the label (`**M1 – …`,
//!   `- **FR1, implicit …`), cited as `theory D20`, `theory eq. FR2`,
//!   `theory M4`, and, for the D labels, bare (`D20`, `[D20]`, `D10–D14`);
//! - decisions: the numbered rows of the decision log (§11), cited as
//!   `theory decision 27` (`decisions 24–27`).
//!
//! The test scans the text files of `src`, `physics`, `solvers`, `tests`,
//! `validation`, `docs`, `scripts`, `benches` and `README.md` for those
//! forms and fails, naming file, line and label, on any citation whose
//! label the reference does not define, and on any file that still names
//! `DESIGN` (the specification the code started from, which is not in the
//! repository). `§` citations preceded by `paper` or `guide` refer to those
//! documents and are skipped.

use std::collections::BTreeSet;
use std::fs;
use std::path::{Path, PathBuf};

const REFERENCE: &str = "docs/theory.md";
const SCANNED: [&str; 9] = [
    "src",
    "physics",
    "solvers",
    "tests",
    "validation",
    "docs",
    "scripts",
    "benches",
    "README.md",
];

/// The labels `docs/theory.md` defines.
#[derive(Debug, Default)]
struct Reference {
    sections: BTreeSet<String>,
    labels: BTreeSet<String>,
    decisions: BTreeSet<u32>,
}

/// A label such as `D20`, `GA1`, `FR7`, `M4`: one or two capitals, digits.
fn is_label(s: &str) -> bool {
    let letters = s.chars().take_while(|c| c.is_ascii_uppercase()).count();
    (1..=2).contains(&letters)
        && s.len() > letters
        && s[letters..].chars().all(|c| c.is_ascii_digit())
}

/// The leading `N`, `N.M`, … of `s` (a trailing dot dropped), if any.
fn section_number(s: &str) -> Option<String> {
    let n: String = s
        .chars()
        .take_while(|c| c.is_ascii_digit() || *c == '.')
        .collect();
    let n = n.trim_end_matches('.');
    (!n.is_empty() && n.starts_with(|c: char| c.is_ascii_digit())).then(|| n.to_string())
}

/// The leading label-like token of `s` (`FR1` of `FR1, implicit`).
fn leading_token(s: &str) -> &str {
    let end = s
        .find(|c: char| !c.is_ascii_alphanumeric())
        .unwrap_or(s.len());
    &s[..end]
}

impl Reference {
    fn parse(text: &str) -> Self {
        let mut reference = Reference::default();
        let mut chapter = String::new();
        for line in text.lines() {
            let trimmed = line.trim();
            if trimmed.starts_with('#') {
                let heading = trimmed.trim_start_matches('#').trim();
                if let Some(n) = section_number(heading) {
                    chapter = n.split('.').next().unwrap_or_default().to_string();
                    reference.sections.insert(n);
                }
                continue;
            }
            // `… (D23; paper eq. 3)` at the end of an equation line
            if let Some(open) = trimmed.strip_suffix(')').and_then(|s| s.rfind('(')) {
                let inner = &trimmed[open + 1..trimmed.len() - 1];
                let label = inner.split(';').next().unwrap_or_default().trim();
                if is_label(label) {
                    reference.labels.insert(label.to_string());
                }
            }
            // `**M1 – …` or `- **FR1, implicit …`
            let bold = trimmed.trim_start_matches("- ");
            if let Some(rest) = bold.strip_prefix("**") {
                let token = leading_token(rest);
                if is_label(token) {
                    reference.labels.insert(token.to_string());
                }
            }
            // `| 27 | …` rows of the decision log
            if chapter == "11" {
                if let Some(rest) = trimmed.strip_prefix('|') {
                    if let Ok(n) = rest.split('|').next().unwrap_or_default().trim().parse() {
                        reference.decisions.insert(n);
                    }
                }
            }
        }
        reference
    }
}

/// One citation found in the tree.
#[derive(Debug, PartialEq)]
enum Cited {
    Section(String),
    Label(String),
    Decision(u32),
}

impl Cited {
    fn resolves(&self, reference: &Reference) -> bool {
        match self {
            Cited::Section(s) => reference.sections.contains(s),
            Cited::Label(l) => reference.labels.contains(l),
            Cited::Decision(n) => reference.decisions.contains(n),
        }
    }
}

/// The numbers of `42`, `24–27`, `24-27`, `18, 19 and 20` at the start of `s`.
fn numbers(s: &str) -> Vec<u32> {
    let mut out = Vec::new();
    let mut rest = s;
    loop {
        let digits: String = rest.chars().take_while(|c| c.is_ascii_digit()).collect();
        let Ok(n) = digits.parse() else { break };
        out.push(n);
        rest = &rest[digits.len()..];
        let next = ["–", "-", ", ", " and "]
            .iter()
            .find_map(|sep| rest.strip_prefix(sep))
            .filter(|r| r.starts_with(|c: char| c.is_ascii_digit()));
        match next {
            Some(r) => rest = r,
            None => break,
        }
    }
    out
}

/// Every label-like token `D…` standing alone (not inside a word).
fn bare_d_labels(line: &str) -> Vec<String> {
    let bytes = line.as_bytes();
    let mut out = Vec::new();
    for (i, _) in line.match_indices('D') {
        let before_ok = i == 0 || !(bytes[i - 1].is_ascii_alphanumeric() || bytes[i - 1] == b'_');
        let token = leading_token(&line[i..]);
        if before_ok && is_label(token) && token.len() > 1 {
            out.push(token.to_string());
        }
    }
    out
}

/// The citations of one line.
fn citations(line: &str) -> Vec<Cited> {
    let mut out: Vec<Cited> = bare_d_labels(line).into_iter().map(Cited::Label).collect();
    // `§N.M`, `§3–4`, unless it cites the paper or the guide
    for (i, _) in line.match_indices('§') {
        let before = &line[..i];
        let context: String = before.chars().rev().take(12).collect::<String>();
        let context: String = context.chars().rev().collect();
        if context.contains("paper") || context.contains("guide") {
            continue;
        }
        let after = line[i + '§'.len_utf8()..].trim_start();
        if let Some(first) = section_number(after) {
            let mut rest = &after[first.len()..];
            out.push(Cited::Section(first));
            while let Some(r) = rest.strip_prefix('–').or_else(|| rest.strip_prefix("–§")) {
                let Some(n) = section_number(r) else { break };
                rest = &r[n.len()..];
                out.push(Cited::Section(n));
            }
        }
    }
    // `theory …` / `theory.md …` / `DESIGN …`: labels and decisions
    for key in ["theory", "DESIGN"] {
        for (i, _) in line.match_indices(key) {
            let mut rest = &line[i + key.len()..];
            for prefix in [".md", "`", ")", "'s", " eq.", " "] {
                rest = rest.strip_prefix(prefix).unwrap_or(rest);
            }
            let rest = rest.trim_start();
            if let Some(d) = rest
                .strip_prefix("decisions ")
                .or_else(|| rest.strip_prefix("decision "))
            {
                out.extend(numbers(d).into_iter().map(Cited::Decision));
                continue;
            }
            let token = leading_token(rest);
            if is_label(token) {
                out.push(Cited::Label(token.to_string()));
                let after = &rest[token.len()..];
                if let Some(second) = after.strip_prefix('–').map(leading_token) {
                    if is_label(second) {
                        out.push(Cited::Label(second.to_string()));
                    }
                }
            }
        }
    }
    // a D label is found both bare and after `theory`: report it once
    let mut unique = Vec::new();
    for cited in out {
        if !unique.contains(&cited) {
            unique.push(cited);
        }
    }
    unique
}

fn text_files(path: &Path, out: &mut Vec<PathBuf>) {
    if path.is_dir() {
        let mut entries: Vec<_> = fs::read_dir(path)
            .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
            .map(|e| e.expect("directory entry").path())
            .collect();
        entries.sort();
        for entry in entries {
            text_files(&entry, out);
        }
    } else if path.is_file() {
        out.push(path.to_path_buf());
    }
}

fn reference() -> Reference {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let text = fs::read_to_string(root.join(REFERENCE)).expect("docs/theory.md");
    Reference::parse(&text)
}

#[test]
fn the_reference_defines_every_label_it_promises() {
    let reference = reference();
    for n in 1..=43 {
        assert!(
            reference.labels.contains(&format!("D{n}")),
            "docs/theory.md does not define D{n}"
        );
    }
    for n in 1..=36 {
        assert!(
            reference.decisions.contains(&n),
            "docs/theory.md has no decision {n}"
        );
    }
    for s in [
        "1", "2", "3", "4", "5", "5.6", "6", "7", "8.0", "8.4", "9", "11",
    ] {
        assert!(reference.sections.contains(s), "no section {s}");
    }
    for l in ["M1", "M6", "GA3", "AS4", "SR1", "E3", "B1", "FR7", "N2"] {
        assert!(reference.labels.contains(l), "no label {l}");
    }
}

#[test]
fn every_citation_in_the_repository_resolves() {
    let reference = reference();
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut files = Vec::new();
    for entry in SCANNED {
        text_files(&root.join(entry), &mut files);
    }
    let mut checked = 0;
    let mut unresolved = Vec::new();
    for file in &files {
        // figures are not read: binary ones, and SVG, whose colours
        // (#D62728) look like labels
        if file.extension().is_some_and(|e| e == "svg") {
            continue;
        }
        let Ok(text) = fs::read_to_string(file) else {
            continue;
        };
        let name = file
            .strip_prefix(root)
            .unwrap_or(file)
            .display()
            .to_string();
        // this file's own examples include labels that must not resolve
        if name == "tests/citations.rs" {
            continue;
        }
        if text.contains("DESIGN") {
            unresolved.push(format!(
                "{name}: names DESIGN, a file outside the repository (cite docs/theory.md)"
            ));
        }
        for (k, line) in text.lines().enumerate() {
            for cited in citations(line) {
                checked += 1;
                if !cited.resolves(&reference) {
                    unresolved.push(format!("{name}:{}: {cited:?}", k + 1));
                }
            }
        }
    }
    assert!(
        checked > 500,
        "only {checked} citations found: is the scan broken?"
    );
    assert!(
        unresolved.is_empty(),
        "{} citation(s) name no label of {REFERENCE}:\n{}",
        unresolved.len(),
        unresolved.join("\n")
    );
}

#[test]
fn a_label_that_does_not_exist_is_caught() {
    let reference = Reference::parse(
        "## 8. Benchmarks\n### 8.1 Biaxial\n    p = −tr σ/3    (D1)\n    q = √(3 J2)    (D5; paper eq. 7)\n\
         **M1 – discrepancy.**\n- **FR1, implicit.**\n## 11. Decisions\n| 27 | double mapping |\n",
    );
    let line = "see theory D1, D5 and D99, theory §8.1 and §8.7, theory M1, theory eq. FR1, \
                theory decisions 27–28, and paper §3.9";
    let unresolved: Vec<Cited> = citations(line)
        .into_iter()
        .filter(|c| !c.resolves(&reference))
        .collect();
    assert_eq!(
        unresolved,
        vec![
            Cited::Label("D99".into()),
            Cited::Section("8.7".into()),
            Cited::Decision(28),
        ]
    );
}
