//! The parameters of the averaging and its errors.

use serde::{Deserialize, Serialize};

use super::DEFAULT_CUTOFF_FACTOR;

/// Parameters of the nonlocal averaging (theory §6, \[D33\]–\[D34\]; paper eq. 6).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct NonlocalParameters {
    /// Material length scale `l_s` (m) of the weight \[D33\]; must be finite and `> 0`.
    pub length_scale: f64,
    /// Cutoff radius in units of `l_s`: `R_c = cutoff_factor · l_s` (default 3, theory §6);
    /// must be finite and `> 0`.
    pub cutoff_factor: f64,
}

impl NonlocalParameters {
    /// Parameters with the given length scale `l_s` and the default cutoff `R_c = 3 l_s`
    /// ([`DEFAULT_CUTOFF_FACTOR`], theory §6).
    pub fn new(length_scale: f64) -> Self {
        Self {
            length_scale,
            cutoff_factor: DEFAULT_CUTOFF_FACTOR,
        }
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
