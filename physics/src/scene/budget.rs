//! Resources a scene will need, estimated from its keys before anything big
//! is allocated: material points, grid nodes, the nonlocal neighbour load,
//! the implicit tangent and its factor, and the explicit step count. A scene
//! over the limits ([`ResourceLimits`]) is refused naming the keys that drive
//! the estimate ([`Scene::check_resources`]).
//!
//! The per-unit costs were measured (peak resident memory of `mpm-geo run`,
//! 2 steps) on the footing and bar scenes of `validation/` over h = 1/4 to
//! 1/32 m:
//! - explicit runs: 1.1–1.2 kB per material point (positions, stresses,
//!   states, shape functions and the step's per-point arrays), 140–160 B per
//!   grid node (nodal arrays of a step);
//! - implicit runs: the sparse LU factor of the tangent (COLAMD ordering)
//!   dominates, ≈ 2 kB · n^1.25 for n unknowns (within 10 % of 65 MB,
//!   366 MB, 546 MB and 1.95 GB measured for n = 3.8k, 15k, 23k, 58k).

use std::fmt;

use super::schema::*;
use super::SceneError;
use crate::constitutive::ConstitutiveModel;

/// Bytes per material point (measured 1.1–1.2 kB, see the module notes).
const BYTES_PER_POINT: f64 = 1200.0;
/// Bytes per grid node (measured 140–160 B).
const BYTES_PER_NODE: f64 = 200.0;
/// Bytes per stored nonlocal weight (dense tile-pair blocks, `nonlocal::WeightCache`).
const BYTES_PER_PAIR: f64 = 8.0;
/// Stored weights per ordered neighbour pair: each unordered pair once, plus the blocks'
/// entries beyond the cutoff (measured 0.59 on the biaxial lattice: 16.6M weights for
/// 6,000 points × 4,704 neighbours).
const STORED_PER_PAIR: f64 = 0.6;
/// Bytes per node of the nonlocal averaging grid (theory §6.1): the spread fields, their
/// transposed transform and the kernel's spectrum, 16 bytes each.
const BYTES_PER_AVERAGING_NODE: f64 = 48.0;
/// Bytes per stored nonzero of the tangent (value, index; assembly and CSR copies).
const BYTES_PER_NONZERO: f64 = 32.0;
/// Factor entries ≈ `FILL_COEFFICIENT` · n^`FILL_EXPONENT` (LU with COLAMD on
/// the 2-D grid graphs of the scenes, measured).
const FILL_COEFFICIENT: f64 = 225.0;
/// Exponent of the factor fill estimate.
const FILL_EXPONENT: f64 = 1.25;
/// Bytes per factor entry.
const BYTES_PER_FACTOR_ENTRY: f64 = 8.0;
/// Fixed cost of a run (executable, thread pools, buffers), bytes.
const BASE_BYTES: f64 = 16e6;
/// Share of the available memory a scene may use when no limit is given.
pub const DEFAULT_MEMORY_SHARE: f64 = 0.5;
/// Memory limit when `/proc/meminfo` cannot be read, bytes.
pub const FALLBACK_MEMORY_LIMIT: f64 = 8e9;
/// Default step-count limit (implicit `steps`, explicit `end_time` / Δt).
pub const DEFAULT_MAX_STEPS: u64 = 10_000_000;

/// One part of the memory estimate.
#[derive(Clone, Debug, PartialEq)]
pub struct MemoryPart {
    /// What is counted (`material points`, `grid nodes`, …) with its count.
    pub what: String,
    /// Estimated bytes.
    pub bytes: f64,
    /// Scene keys that drive it.
    pub fields: Vec<String>,
}

/// What a scene will need, estimated from its keys.
#[derive(Clone, Debug, PartialEq)]
pub struct ResourceEstimate {
    /// Material points seeded.
    pub points: f64,
    /// Grid cells.
    pub cells: f64,
    /// Grid nodes.
    pub nodes: f64,
    /// Nonlocal weight pairs within the cutoff (points × neighbours), if nonlocal.
    pub neighbour_pairs: Option<f64>,
    /// Unknowns of the implicit tangent (2 per node of the cells holding
    /// points), if implicit.
    pub unknowns: Option<f64>,
    /// Nonzeros of the implicit tangent, if implicit.
    pub matrix_nonzeros: Option<f64>,
    /// Entries of its sparse factor, if implicit.
    pub factor_entries: Option<f64>,
    /// The parts of the memory estimate, largest first.
    pub parts: Vec<MemoryPart>,
    /// Total estimated memory, bytes.
    pub bytes: f64,
    /// Steps the run will take (explicit: an upper estimate from the stable step).
    pub steps: f64,
    /// How the step count was found, and the keys that drive it.
    pub steps_reason: String,
    /// Scene keys that drive the step count.
    pub step_fields: Vec<String>,
}

/// The limits a scene is checked against.
#[derive(Clone, Debug, PartialEq)]
pub struct ResourceLimits {
    /// Largest estimated memory allowed, bytes.
    pub max_memory: f64,
    /// Where `max_memory` comes from (for messages).
    pub memory_source: String,
    /// Largest step count allowed.
    pub max_steps: u64,
}

impl ResourceLimits {
    /// The scene's `[limits]`, else [`DEFAULT_MEMORY_SHARE`] of the memory
    /// available now (`MemAvailable` of `/proc/meminfo`) and [`DEFAULT_MAX_STEPS`].
    pub fn for_scene(scene: &Scene) -> Self {
        let (max_memory, memory_source) = match scene.limits.max_memory_gb {
            Some(gb) => (gb * 1e9, "limits.max_memory_gb (--max-memory)".to_string()),
            None => match available_memory() {
                Some(bytes) => (
                    DEFAULT_MEMORY_SHARE * bytes,
                    format!(
                        "{DEFAULT_MEMORY_SHARE} of the available memory {} (raise with --max-memory or limits.max_memory_gb)",
                        human_bytes(bytes)
                    ),
                ),
                None => (
                    FALLBACK_MEMORY_LIMIT,
                    "the default when /proc/meminfo is unreadable (raise with --max-memory or limits.max_memory_gb)".to_string(),
                ),
            },
        };
        Self {
            max_memory,
            memory_source,
            max_steps: scene.limits.max_steps.unwrap_or(DEFAULT_MAX_STEPS),
        }
    }
}

/// `MemAvailable` of `/proc/meminfo`, bytes.
pub fn available_memory() -> Option<f64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024.0)
}

/// `1.23 GB`-style text of a byte count.
pub fn human_bytes(bytes: f64) -> String {
    if !bytes.is_finite() {
        return format!("{bytes} B");
    }
    let units = [(1e12, "TB"), (1e9, "GB"), (1e6, "MB"), (1e3, "kB")];
    for (scale, unit) in units {
        if bytes >= scale {
            return format!("{:.3} {unit}", bytes / scale);
        }
    }
    format!("{bytes:.0} B")
}

/// Parse `--max-memory`: a number of bytes with an optional suffix `k`, `M`,
/// `G` or `T` (decimal, an optional trailing `B`), e.g. `8G`, `512MB`, `2e9`.
pub fn parse_memory(text: &str) -> Result<f64, String> {
    let t = text.trim();
    let t = t.strip_suffix(['B', 'b']).unwrap_or(t);
    let (number, scale) = match t.chars().last() {
        Some('k' | 'K') => (&t[..t.len() - 1], 1e3),
        Some('m' | 'M') => (&t[..t.len() - 1], 1e6),
        Some('g' | 'G') => (&t[..t.len() - 1], 1e9),
        Some('t' | 'T') => (&t[..t.len() - 1], 1e12),
        _ => (t, 1.0),
    };
    let value: f64 = number
        .trim()
        .parse()
        .map_err(|_| format!("`{text}` is not a memory size such as 8G, 512M or 2e9"))?;
    let bytes = value * scale;
    if bytes.is_finite() && bytes > 0.0 {
        Ok(bytes)
    } else {
        Err(format!("`{text}`: the memory limit must be > 0 and finite"))
    }
}

/// Area of a polygon (shoelace), m².
fn polygon_area(v: &[[f64; 2]]) -> f64 {
    let twice: f64 = (0..v.len())
        .map(|i| {
            let (a, c) = (v[i], v[(i + 1) % v.len()]);
            a[0] * c[1] - c[0] * a[1]
        })
        .sum();
    0.5 * twice.abs()
}

impl Scene {
    /// Estimate what the run will need from the scene's keys (a validated
    /// scene; nothing is allocated).
    pub fn estimate_resources(&self) -> ResourceEstimate {
        let g = &self.grid;
        let h = g.cell_size;
        let cells_xy = [g.size[0] / h, g.size[1] / h];
        let cells = cells_xy[0] * cells_xy[1];
        let nodes = (cells_xy[0] + 1.0) * (cells_xy[1] + 1.0);
        let ppc = g.points_per_cell as f64;
        let body_area: f64 = self.body.iter().map(|b| polygon_area(&b.outline())).sum();
        let area = body_area.min(g.size[0] * g.size[1]);
        let density = (ppc / h).powi(2); // points per m²
        let points = area * density;
        let body_keys: Vec<String> = self
            .body
            .iter()
            .enumerate()
            .map(|(i, b)| {
                let key = if b.rectangle.is_some() {
                    "box"
                } else {
                    "polygon"
                };
                format!("body[{i}].{key}")
            })
            .collect();
        let mut point_fields = vec!["grid.cell_size".to_string(), "grid.points_per_cell".into()];
        point_fields.extend(body_keys.iter().cloned());
        let mut parts = vec![
            MemoryPart {
                what: format!("{points:.3e} material points"),
                bytes: points * BYTES_PER_POINT,
                fields: point_fields,
            },
            MemoryPart {
                what: format!("{cells:.3e} grid cells ({nodes:.3e} nodes)"),
                bytes: nodes * BYTES_PER_NODE,
                fields: vec!["grid.size".into(), "grid.cell_size".into()],
            },
        ];
        let grid_averaging = self
            .nonlocal
            .as_ref()
            .filter(|nl| nl.averaging == crate::nonlocal::NonlocalAveraging::Grid);
        if let Some(nl) = grid_averaging {
            // theory §6.1: the whole grid padded by R_c, three arrays of complex numbers
            let spacing = nl.grid_spacing();
            let side = |a: usize| (g.size[a] + nl.cutoff_radius()) / spacing + 2.0;
            let grid_nodes = side(0) * side(1);
            parts.push(MemoryPart {
                what: format!("{grid_nodes:.3e} nodes of the nonlocal averaging grid"),
                bytes: grid_nodes * BYTES_PER_AVERAGING_NODE,
                fields: vec![
                    "nonlocal.grid_spacing_factor".into(),
                    "nonlocal.length_scale".into(),
                    "grid.size".into(),
                ],
            });
        }
        let neighbour_pairs = self
            .nonlocal
            .as_ref()
            .filter(|_| grid_averaging.is_none())
            .map(|nl| {
                let radius = nl.cutoff_factor * nl.length_scale;
                let neighbours = (std::f64::consts::PI * radius * radius * density).min(points);
                (points * neighbours, nl.weight_budget() as f64)
            });
        if let Some((pairs, budget)) = neighbour_pairs {
            let cached = (STORED_PER_PAIR * pairs).min(budget);
            parts.push(MemoryPart {
                what: format!("{pairs:.3e} nonlocal neighbour pairs ({cached:.3e} cached)"),
                bytes: cached * BYTES_PER_PAIR,
                fields: vec![
                    "nonlocal.length_scale".into(),
                    "nonlocal.cutoff_factor".into(),
                    "grid.cell_size".into(),
                    "grid.points_per_cell".into(),
                    "nonlocal.weight_cache_mb".into(),
                ],
            });
        }
        let (mut unknowns_estimate, mut matrix_nonzeros, mut factor_entries) = (None, None, None);
        if self.scene.analysis != AnalysisKind::Explicit {
            // cells holding points and their nodes; 2 unknowns per node
            let active_cells = (points / (ppc * ppc)).min(cells);
            let active_nodes = active_cells + 2.0 * active_cells.sqrt() + 1.0;
            let unknowns = 2.0 * active_nodes.min(nodes);
            // a node couples with the nodes of every cell its points share:
            // 3 × 3 nodes (bilinear) or 5 × 5 (GIMP domains reach a neighbour cell)
            let stencil = match g.shape_functions {
                ShapeFunctionChoice::Bilinear => 9.0,
                ShapeFunctionChoice::Gimp => 25.0,
            };
            let nonzeros = unknowns * 2.0 * stencil;
            let fill = FILL_COEFFICIENT * unknowns.powf(FILL_EXPONENT);
            let mut fields = vec!["grid.cell_size".to_string(), "grid.shape_functions".into()];
            fields.extend(body_keys.iter().cloned());
            parts.push(MemoryPart {
                what: format!("tangent matrix ({unknowns:.3e} unknowns, {nonzeros:.3e} nonzeros)"),
                bytes: nonzeros * BYTES_PER_NONZERO,
                fields: fields.clone(),
            });
            parts.push(MemoryPart {
                what: format!("sparse factor (fill ≈ {fill:.3e} entries)"),
                bytes: fill * BYTES_PER_FACTOR_ENTRY,
                fields,
            });
            unknowns_estimate = Some(unknowns);
            matrix_nonzeros = Some(nonzeros);
            factor_entries = Some(fill);
        }
        parts.sort_by(|a, b| b.bytes.total_cmp(&a.bytes));
        let bytes = BASE_BYTES + parts.iter().map(|p| p.bytes).sum::<f64>();
        let (steps, steps_reason, step_fields) = self.estimate_steps();
        ResourceEstimate {
            points,
            cells,
            nodes,
            neighbour_pairs: neighbour_pairs.map(|(pairs, _)| pairs),
            unknowns: unknowns_estimate,
            matrix_nonzeros,
            factor_entries,
            parts,
            bytes,
            steps,
            steps_reason,
            step_fields,
        }
    }

    /// The step count: `scene.steps` (implicit; a path-following run's step
    /// budget, its most steps), or `end_time` over the
    /// explicit step (the scene's `dt`, else α_CFL times the smallest stable
    /// step h / c_p of the materials in use, combined with the penalty
    /// springs of rigid bodies as in [`crate::integrators::time_step`]).
    fn estimate_steps(&self) -> (f64, String, Vec<String>) {
        let a = &self.scene;
        if a.analysis == AnalysisKind::ImplicitDynamic && self.solver.adaptive() {
            let (end, dt) = (a.end_time_or_steps(), a.dt.unwrap_or(1.0));
            return (
                end / dt,
                format!("adaptive steps: scene end {end:.4e} s / first step {dt:.4e} s"),
                vec!["scene.end_time".into(), "scene.dt".into()],
            );
        }
        if self.solver.follows_path() {
            let budget = self.solver.path_step_budget(a.steps);
            return (
                budget as f64,
                format!(
                    "path following: at most solver.path_max_steps = {budget} steps to the end travel ({} nominal steps)",
                    a.steps.unwrap_or(0)
                ),
                vec!["solver.path_max_steps".into(), "scene.steps".into()],
            );
        }
        if a.analysis != AnalysisKind::Explicit {
            let steps = a.steps.unwrap_or(0) as f64;
            return (steps, "scene.steps".into(), vec!["scene.steps".into()]);
        }
        let end = a.end_time.unwrap_or(0.0);
        if let Some(dt) = a.dt {
            return (
                end / dt,
                format!("scene.end_time {end:.4e} s / scene.dt {dt:.4e} s"),
                vec!["scene.end_time".into(), "scene.dt".into()],
            );
        }
        let h = self.grid.cell_size;
        let damping = self.solver.damping;
        let penalty_factor = self.solver.penalty_factor.unwrap_or(10.0);
        let rigid = !self.bc.rigid.is_empty();
        let ppc = self.grid.points_per_cell as f64;
        let mut limit = f64::INFINITY;
        let mut limiting = String::new();
        let used: Vec<&String> = self.body.iter().map(|b| &b.material).collect();
        for (name, m) in &self.materials {
            if !used.contains(&name) {
                continue;
            }
            let (e, nu, rho) = (m.youngs_modulus(), m.poisson_ratio(), m.density());
            let modulus = crate::constitutive::LinearElastic::new(e, nu).p_wave_modulus();
            let wave = h / (modulus / rho).sqrt();
            let mut dt = wave;
            if rigid {
                // a surface node: mass ≥ ρ h²/4, springs ≤ ppc · β_pen E
                let penalty =
                    2.0 * (rho * h * h / 4.0 / ((1.0 + damping) * ppc * penalty_factor * e)).sqrt();
                dt = 1.0 / (1.0 / (wave * wave) + 1.0 / (penalty * penalty)).sqrt();
            }
            let dt = if dt.is_nan() { 0.0 } else { dt };
            if dt < limit || limiting.is_empty() {
                limit = dt.min(limit);
                limiting = name.clone();
            }
        }
        let dt = self.solver.cfl * limit;
        let steps = if dt > 0.0 { end / dt } else { f64::INFINITY };
        let mut fields = vec![
            "scene.end_time".to_string(),
            "solver.cfl".into(),
            "grid.cell_size".into(),
        ];
        if !limiting.is_empty() {
            for key in ["E", "nu", "density"] {
                fields.push(format!("materials.{limiting}.{key}"));
            }
        }
        if rigid {
            fields.push("solver.penalty_factor".into());
        }
        let springs = if rigid {
            " and the penalty springs of [[bc.rigid]]"
        } else {
            ""
        };
        (
            steps,
            format!(
                "scene.end_time {end:.4e} s / (solver.cfl {:.4e} × stable step {limit:.4e} s from the wave speed of material `{limiting}`{springs})",
                self.solver.cfl
            ),
            fields,
        )
    }

    /// Refuse the scene if its estimated memory or step count exceeds
    /// `limits`, naming the keys that drive the estimate; the estimate otherwise.
    pub fn check_resources(&self, limits: &ResourceLimits) -> Result<ResourceEstimate, SceneError> {
        let estimate = self.estimate_resources();
        if estimate.bytes.is_nan() || estimate.bytes > limits.max_memory {
            return Err(SceneError::MemoryLimit {
                path: self.scene.name.clone(),
                estimate: Box::new(estimate),
                limit: limits.max_memory,
                source_of_limit: limits.memory_source.clone(),
            });
        }
        if estimate.steps.is_nan() || estimate.steps > limits.max_steps as f64 {
            return Err(SceneError::StepLimit {
                path: self.scene.name.clone(),
                steps: estimate.steps,
                limit: limits.max_steps,
                reason: estimate.steps_reason.clone(),
                fields: estimate.step_fields.clone(),
            });
        }
        Ok(estimate)
    }
}

impl fmt::Display for ResourceEstimate {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "estimated memory {}", human_bytes(self.bytes))?;
        for p in &self.parts {
            write!(
                f,
                "\n    {}: {} (driven by {})",
                p.what,
                human_bytes(p.bytes),
                p.fields.join(", ")
            )?;
        }
        write!(f, "\n    steps: {:.3e} ({})", self.steps, self.steps_reason)
    }
}
