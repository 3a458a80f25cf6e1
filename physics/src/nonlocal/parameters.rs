//! The parameters of the averaging and its errors.

use serde::{Deserialize, Serialize};

use super::DEFAULT_CUTOFF_FACTOR;

/// When the nonlocal variable is updated (theory §6).
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum NonlocalUpdate {
    /// Every Newton iteration, lagged by one (theory D36).
    #[default]
    Iteration,
    /// Once per step after convergence (strength frozen at κ̄(n)); explicit runs always.
    Step,
}

/// How the average \[D34\] is evaluated (theory §6, §6.1).
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum NonlocalAveraging {
    /// Over every pair of points within `R_c` (\[D34\] as written).
    #[default]
    Points,
    /// On an auxiliary grid of spacing `grid_spacing_factor · l_s`, by FFT (NG1–NG3): an
    /// approximation whose error falls as the spacing squared.
    Grid,
}

/// `[nonlocal]`: averaging of the equivalent plastic strain (paper eq. 6,
/// theory §6): the scene's table and the parameters of the averaging
/// (theory \[D33\]–\[D36\]).
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct NonlocalSpec {
    /// Length scale l_s, m (> cell size; ≥ 5 cells recommended, the paper's 0.2 l_s rule).
    pub length_scale: f64,
    /// Cutoff radius in units of l_s (theory §6: 3).
    #[serde(default = "default_cutoff")]
    pub cutoff_factor: f64,
    /// `iteration` (default) or `step`.
    #[serde(default)]
    pub update: NonlocalUpdate,
    /// ε_κ of theory D18 (third criterion).
    #[serde(default = "default_kappa_tolerance")]
    pub tolerance: f64,
    /// Over-nonlocal factor m in [1, 3] (Vermeer & Brinkgreve 1994): κ̄ = κ̄(n) +
    /// m Σ_q W_pq Δκ_q + (1 − m) Δκ_p. The default 1 is theory D35.
    #[serde(default = "default_over_nonlocal")]
    pub over_nonlocal: f64,
    /// Memory for the weights cached within a step (D36), MiB (default 512;
    /// 0 caches none). Pairs beyond it are evaluated on the fly, with the
    /// same result to round-off; the run's memory estimate counts it.
    #[serde(default = "default_weight_cache_mb")]
    pub weight_cache_mb: f64,
    /// `points` (default, \[D34\]) or `grid` (NG1–NG3).
    #[serde(default)]
    pub averaging: NonlocalAveraging,
    /// Spacing of the grid of `averaging = "grid"`, in units of l_s (default 0.1).
    #[serde(default = "default_grid_spacing_factor")]
    pub grid_spacing_factor: f64,
}

fn default_grid_spacing_factor() -> f64 {
    0.1
}

fn default_over_nonlocal() -> f64 {
    1.0
}

fn default_weight_cache_mb() -> f64 {
    (super::DEFAULT_PAIR_BUDGET * std::mem::size_of::<f64>()) as f64 / MIB
}

/// Bytes per MiB.
const MIB: f64 = (1u64 << 20) as f64;

impl NonlocalSpec {
    /// `weight_cache_mb` as a number of stored weights (8 bytes each).
    pub fn weight_budget(&self) -> usize {
        (self.weight_cache_mb * MIB / std::mem::size_of::<f64>() as f64) as usize
    }
}

fn default_cutoff() -> f64 {
    DEFAULT_CUTOFF_FACTOR
}

fn default_kappa_tolerance() -> f64 {
    1e-3
}

impl NonlocalSpec {
    /// The averaging with length scale `l_s` and every other setting at its
    /// default (cutoff `R_c = 3 l_s`, [`DEFAULT_CUTOFF_FACTOR`], theory §6).
    pub fn new(length_scale: f64) -> Self {
        Self {
            length_scale,
            cutoff_factor: default_cutoff(),
            update: NonlocalUpdate::default(),
            tolerance: default_kappa_tolerance(),
            over_nonlocal: default_over_nonlocal(),
            weight_cache_mb: default_weight_cache_mb(),
            averaging: NonlocalAveraging::default(),
            grid_spacing_factor: default_grid_spacing_factor(),
        }
    }

    /// Spacing Δ of the grid of `averaging = "grid"` (m), theory §6.1.
    pub fn grid_spacing(&self) -> f64 {
        self.grid_spacing_factor * self.length_scale
    }

    /// Cutoff radius `R_c = cutoff_factor · l_s` (m), theory §6.
    pub fn cutoff_radius(&self) -> f64 {
        self.cutoff_factor * self.length_scale
    }

    /// Checks `l_s` and the cutoff factor (finite and strictly positive).
    pub fn validate(&self) -> Result<(), NonlocalError> {
        if !(self.length_scale.is_finite() && self.length_scale > 0.0) {
            return Err(NonlocalError::InvalidLengthScale(self.length_scale));
        }
        if !(self.cutoff_factor.is_finite() && self.cutoff_factor > 0.0) {
            return Err(NonlocalError::InvalidCutoffFactor(self.cutoff_factor));
        }
        if !(self.cutoff_radius().is_finite() && self.cutoff_radius() > 0.0) {
            return Err(NonlocalError::InvalidCutoffFactor(self.cutoff_factor));
        }
        if !(self.grid_spacing_factor > 0.0 && self.grid_spacing_factor <= 1.0) {
            return Err(NonlocalError::InvalidGridSpacing(self.grid_spacing_factor));
        }
        Ok(())
    }
}

/// Errors of the nonlocal averaging (invalid parameters or inconsistent inputs).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum NonlocalError {
    /// `l_s` is not finite or not strictly positive (\[D33\]).
    #[error("nonlocal length scale must be finite and > 0, got {0}")]
    InvalidLengthScale(f64),
    /// The cutoff factor is not finite or not strictly positive (theory §6).
    #[error("nonlocal cutoff factor must be finite and > 0, got {0}")]
    InvalidCutoffFactor(f64),
    /// The grid spacing factor is not in (0, 1] (theory §6.1).
    #[error("nonlocal grid spacing factor must lie in (0, 1], got {0}")]
    InvalidGridSpacing(f64),
    /// The points of one group spread over more grid nodes than the grid averaging allows.
    #[error("the nonlocal grid averaging would need {nodes} nodes of {spacing} m (at most 2^26): the points spread too far for it; use averaging = \"points\" or a larger grid_spacing_factor")]
    GridTooLarge {
        /// Nodes the grid would need.
        nodes: usize,
        /// Its spacing, m.
        spacing: f64,
    },
    /// Positions, volumes and groups of the MPs have different lengths.
    #[error(
        "nonlocal input lengths differ: {positions} positions, {volumes} volumes, {groups} groups"
    )]
    InputLengthMismatch {
        /// Number of positions.
        positions: usize,
        /// Number of volumes.
        volumes: usize,
        /// Number of group ids.
        groups: usize,
    },
    /// A field or output slice does not have one entry per MP.
    #[error(
        "nonlocal field length mismatch: {expected} material points, field {field}, output {out}"
    )]
    FieldLengthMismatch {
        /// Number of MPs of the averager.
        expected: usize,
        /// Length of the field slice.
        field: usize,
        /// Length of the output slice.
        out: usize,
    },
    /// A position coordinate is NaN or infinite.
    #[error("material point {index}: non-finite position {position:?}")]
    NonFinitePosition {
        /// Index of the offending MP.
        index: usize,
        /// Its position.
        position: [f64; 2],
    },
    /// A volume is negative, NaN or infinite.
    #[error("material point {index}: volume must be finite and >= 0, got {volume}")]
    InvalidVolume {
        /// Index of the offending MP.
        index: usize,
        /// Its volume.
        volume: f64,
    },
}
