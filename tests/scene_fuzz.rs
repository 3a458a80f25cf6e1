//! Fuzzed scene loader: every scene of `validation/` mutated many times
//! (numbers scaled, negated, zeroed or replaced by nan/inf, lines dropped or
//! repeated, values replaced by strings) must be either accepted or refused
//! with an error, never panic, in the loader (`Scene::load`), in the set-up
//! of the run (`Simulation::new`) and in its first steps (on grids small
//! enough to build). A fixed seed keeps the mutations the same on every run.

mod common;

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};

use mpm_geo::scene::Scene;
use mpm_geo::simulation::Simulation;

/// Mutations per scene file.
const MUTATIONS: usize = 200;
/// Steps run on every scene that sets up.
const STEPS: usize = 2;
/// Largest grid the test builds a simulation for (cells).
const MAX_CELLS_BUILT: usize = 20_000;
/// Largest number of material points the test builds a simulation for (the
/// paper-resolution footings, 28,672 and 44,800 points, would take seconds per
/// mutant).
const MAX_POINTS_BUILT: f64 = 10_000.0;

/// Material points a scene seeds: body areas (shoelace) over the sub-cell area.
fn seeded_points(scene: &Scene) -> f64 {
    let area: f64 = scene
        .body
        .iter()
        .map(|b| {
            let v = b.outline();
            let twice: f64 = (0..v.len())
                .map(|i| {
                    let (a, c) = (v[i], v[(i + 1) % v.len()]);
                    a[0] * c[1] - c[0] * a[1]
                })
                .sum();
            0.5 * twice.abs()
        })
        .sum();
    let sub_cell = scene.grid.cell_size / scene.grid.points_per_cell as f64;
    area / (sub_cell * sub_cell)
}

/// A small linear congruential generator (Knuth's MMIX constants).
struct Lcg(u64);

impl Lcg {
    fn next(&mut self) -> u64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        self.0 >> 33
    }

    fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
}

fn scene_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let mut entries: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    entries.sort();
    for path in entries {
        if path.is_dir() {
            // study specs are not scenes (tests/study_bar.rs runs them)
            if path.file_name().is_some_and(|n| n != "studies") {
                scene_files(&path, out);
            }
        } else if path.extension().is_some_and(|e| e == "toml")
            && path.file_name().is_some_and(|n| n != "campaign.toml")
        {
            out.push(path);
        }
    }
}

/// Byte ranges of the numbers in `line` after its `=` (not in comments).
fn numbers(line: &str) -> Vec<(usize, usize)> {
    let Some(eq) = line.find('=') else {
        return Vec::new();
    };
    let end = line.find('#').unwrap_or(line.len());
    let bytes = line.as_bytes();
    let mut found = Vec::new();
    let mut i = eq + 1;
    while i < end {
        let starts = bytes[i].is_ascii_digit()
            || (bytes[i] == b'-' && i + 1 < end && bytes[i + 1].is_ascii_digit());
        let inside_word = i > 0 && (bytes[i - 1].is_ascii_alphabetic() || bytes[i - 1] == b'_');
        if starts && !inside_word {
            let mut j = i + 1;
            while j < end && (bytes[j].is_ascii_digit() || b".eE-+_".contains(&bytes[j])) {
                j += 1;
            }
            found.push((i, j));
            i = j;
        } else {
            i += 1;
        }
    }
    found
}

fn mutate(text: &str, rng: &mut Lcg) -> String {
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    for _ in 0..1 + rng.below(3) {
        let k = rng.below(lines.len());
        match rng.below(4) {
            0 => {
                lines.remove(k);
            }
            1 => {
                let copy = lines[k].clone();
                lines.insert(k, copy);
            }
            2 if lines[k].contains('=') && !lines[k].trim_start().starts_with('#') => {
                let eq = lines[k].find('=').unwrap();
                lines[k] = format!("{}= \"fuzz\"", &lines[k][..eq]);
            }
            _ => {
                let spans = numbers(&lines[k]);
                if spans.is_empty() {
                    continue;
                }
                let (a, b) = spans[rng.below(spans.len())];
                let value: f64 = lines[k][a..b].replace('_', "").parse().unwrap_or(1.0);
                let replacement = match rng.below(8) {
                    0 => "nan".to_string(),
                    1 => "inf".to_string(),
                    2 => "0".to_string(),
                    3 => format!("{:e}", -value),
                    4 => format!("{:e}", value * 1e-3),
                    5 => format!("{:e}", value * 1e3),
                    6 => format!("{:e}", value * 1.5),
                    _ => "-1".to_string(),
                };
                lines[k].replace_range(a..b, &replacement);
            }
        }
        if lines.is_empty() {
            break;
        }
    }
    lines.join("\n")
}

#[test]
fn mutated_scenes_are_accepted_or_refused_without_panicking() {
    let mut files = Vec::new();
    scene_files(&common::validation(""), &mut files);
    assert!(files.len() >= 15, "{files:?}");
    let dir = tempfile::tempdir().unwrap();
    let mut rng = Lcg(0x5eed);
    let (mut refused, mut built) = (0usize, 0usize);
    for file in &files {
        let text = std::fs::read_to_string(file).unwrap();
        for m in 0..MUTATIONS {
            let mutated = mutate(&text, &mut rng);
            let path = dir.path().join("fuzz.toml");
            std::fs::write(&path, &mutated).unwrap();
            let loaded = catch_unwind(AssertUnwindSafe(|| Scene::load(&path, &[])));
            let scene = match loaded {
                Err(_) => panic!(
                    "Scene::load panicked on mutation {m} of {}:\n{mutated}",
                    file.display()
                ),
                Ok(Err(_)) => {
                    refused += 1;
                    continue;
                }
                Ok(Ok(scene)) => scene,
            };
            let cells = scene.grid.size[0] / scene.grid.cell_size * scene.grid.size[1]
                / scene.grid.cell_size;
            if cells > MAX_CELLS_BUILT as f64 || seeded_points(&scene) > MAX_POINTS_BUILT {
                continue;
            }
            let run = catch_unwind(AssertUnwindSafe(|| {
                if let Ok(mut sim) = Simulation::new(scene) {
                    for _ in 0..STEPS {
                        if sim.finished() || sim.step_once().is_err() {
                            break;
                        }
                    }
                }
            }));
            if run.is_err() {
                panic!(
                    "set-up or first steps panicked on mutation {m} of {}:\n{mutated}",
                    file.display()
                );
            }
            built += 1;
        }
    }
    println!(
        "{} scene files × {MUTATIONS} mutations: {refused} refused, {built} set up and stepped",
        files.len()
    );
    assert!(refused > 0 && built > 0);
}
