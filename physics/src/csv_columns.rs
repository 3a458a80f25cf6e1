//! Columns and fields of the CSV files the program writes (`curve.csv`,
//! the campaign and study tables, `point.csv`; docs/guide.md §9 lists every
//! column).
//!
//! Every column is either
//! - a *number column* named `quantity_unit`, where the unit is the last
//!   part of the name, spelt as in [`Unit::suffix`] (`time_s`,
//!   `load_kN_per_m`, `kappa_max_1`: `1` marks a dimensionless number, a
//!   ratio, a relative error or a count); each field is a number that Rust,
//!   pandas and R read as one (`1.5e-3`), or empty where there is no value
//!   (never `NaN`, `inf`, `–` or text); or
//! - an *identifier column* holding text that names a row: `run`, `scene`,
//!   `family`, `integrator`, `status`, `case`, `method`, `series`, `refine`,
//!   `reference` (and `system`, `solver` in `mpm-solvers`' `bench.csv`) and,
//!   in `study.csv`, the axis columns `axis_<name>`.

use crate::scene::{MonitorKind, MonitorSpec, StressQuantity};

/// A unit of a number column (the program's units: kN, m, s, kPa, t).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Unit {
    /// A dimensionless number: a strain, a ratio, a relative error, a count.
    One,
    /// Seconds.
    Second,
    /// Metres.
    Metre,
    /// Metres per second.
    MetrePerSecond,
    /// Metres per second squared.
    MetrePerSecondSquared,
    /// Kilopascals (stresses, pressures, moduli).
    Kilopascal,
    /// Kilonewtons per metre of thickness (plane-strain forces).
    KilonewtonPerMetre,
    /// Kilonewtons per square metre: a force per metre over a displacement
    /// (the slope of a load curve).
    KilonewtonPerSquareMetre,
    /// Kilonewtons per cubic metre (unit weights).
    KilonewtonPerCubicMetre,
    /// Kilojoules per metre of thickness (plane-strain energies).
    KilojoulePerMetre,
    /// Square metres per metre of thickness (plane-strain areas).
    SquareMetrePerMetre,
    /// Tonnes per cubic metre (densities).
    TonnePerCubicMetre,
    /// Degrees (angles).
    Degree,
    /// Megabytes.
    Megabyte,
    /// Gigabytes.
    Gigabyte,
}

impl Unit {
    /// The unit as the last part of a column name.
    pub fn suffix(self) -> &'static str {
        match self {
            Unit::One => "1",
            Unit::Second => "s",
            Unit::Metre => "m",
            Unit::MetrePerSecond => "m_per_s",
            Unit::MetrePerSecondSquared => "m_per_s2",
            Unit::Kilopascal => "kPa",
            Unit::KilonewtonPerMetre => "kN_per_m",
            Unit::KilonewtonPerSquareMetre => "kN_per_m2",
            Unit::KilonewtonPerCubicMetre => "kN_per_m3",
            Unit::KilojoulePerMetre => "kJ_per_m",
            Unit::SquareMetrePerMetre => "m2_per_m",
            Unit::TonnePerCubicMetre => "t_per_m3",
            Unit::Degree => "deg",
            Unit::Megabyte => "MB",
            Unit::Gigabyte => "GB",
        }
    }
}

/// The name of the number column of `quantity` in `unit`: `quantity_unit`.
pub fn column(quantity: &str, unit: Unit) -> String {
    format!("{quantity}_{}", unit.suffix())
}

/// A number field: `v` with full round-trip precision (`1.5e-3`), empty
/// when it is not finite.
pub fn number(v: f64) -> String {
    if v.is_finite() {
        format!("{v:e}")
    } else {
        String::new()
    }
}

/// A number field of an optional value: empty when there is none (or it is
/// not finite).
pub fn optional(v: Option<f64>) -> String {
    v.map(number).unwrap_or_default()
}

impl MonitorSpec {
    /// The unit of the monitor's values, from its kind (and quantity). The
    /// monitor's `scale` and `offset` are taken in this unit: a scale that
    /// changed the unit (1000 for millimetres) is not reflected.
    pub fn unit(&self) -> Unit {
        match self.kind {
            MonitorKind::PointDisplacement
            | MonitorKind::RigidDisplacement
            | MonitorKind::RunOut => Unit::Metre,
            MonitorKind::PointVelocity => Unit::MetrePerSecond,
            MonitorKind::PointStress | MonitorKind::NeighbourhoodStress => {
                match self.quantity.unwrap_or(StressQuantity::Q) {
                    StressQuantity::Kappa | StressQuantity::KappaBar => Unit::One,
                    StressQuantity::X | StressQuantity::Y => Unit::Metre,
                    _ => Unit::Kilopascal,
                }
            }
            MonitorKind::Reaction | MonitorKind::RigidForce => Unit::KilonewtonPerMetre,
            MonitorKind::KineticEnergy
            | MonitorKind::StrainEnergy
            | MonitorKind::ExternalWork
            | MonitorKind::InternalWork
            | MonitorKind::DissipatedEnergy
            | MonitorKind::BoundaryWork
            | MonitorKind::EnergyRemainder => Unit::KilojoulePerMetre,
            MonitorKind::MaxPlasticStrain => Unit::One,
            MonitorKind::Gravity => Unit::MetrePerSecondSquared,
        }
    }

    /// The monitor's column in `curve.csv`: its name and its unit (`load_kN_per_m`).
    pub fn column(&self) -> String {
        column(&self.name, self.unit())
    }
}

/// The unit of the scene key `key` (a path such as `solver.cfl` or
/// `materials.soil.E`, or `dt` for the scene's time step), from its last
/// part; `None` for a key of no known unit.
pub fn scene_key_unit(key: &str) -> Option<Unit> {
    let last = key.rsplit('.').next().unwrap_or(key);
    let unit = match last {
        "dt" | "dt_min" | "dt_max" | "end_time" | "ramp_time" | "interval" => Unit::Second,
        "cell_size" | "length_scale" | "radius" | "surface_y" | "size" | "origin" | "footprint"
        | "point" | "value" => Unit::Metre,
        "E" | "youngs_modulus" | "c" | "c_ini" | "c_post" | "pt_ini" | "pt_post" | "p"
        | "stress0" => Unit::Kilopascal,
        "density" => Unit::TonnePerCubicMetre,
        "unit_weight" => Unit::KilonewtonPerCubicMetre,
        "gravity" | "increment" => Unit::MetrePerSecondSquared,
        "velocity" | "velocity0" | "rate" => Unit::MetrePerSecond,
        "phi_ini" | "phi_peak" | "phi_res" | "psi" => Unit::Degree,
        "weight_cache_mb" | "systems_max_mb" => Unit::Megabyte,
        "max_memory_gb" => Unit::Gigabyte,
        "cfl"
        | "nu"
        | "damping"
        | "newmark_gamma"
        | "newmark_beta"
        | "rho_infinity"
        | "cutoff_factor"
        | "over_nonlocal"
        | "tolerance"
        | "tolerance_force"
        | "tolerance_energy"
        | "error_tolerance"
        | "pcg_tolerance"
        | "penalty_factor"
        | "k0"
        | "mu"
        | "omega"
        | "b_post"
        | "b_res"
        | "steps"
        | "points_per_cell"
        | "max_iterations"
        | "max_halvings"
        | "pcg_max_iterations"
        | "path_max_steps"
        | "curve_every"
        | "snapshot_every"
        | "max_steps"
        | "background_stiffness"
        | "energy_remainder_warning" => Unit::One,
        _ => return None,
    };
    Some(unit)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Number fields: full precision, empty for NaN, ±inf and no value.
    #[test]
    fn number_fields_are_numbers_or_empty() {
        assert_eq!(number(1.5e-3), "1.5e-3");
        assert_eq!(number(0.1 + 0.2).parse::<f64>().unwrap(), 0.1 + 0.2);
        for v in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            assert_eq!(number(v), "");
        }
        assert_eq!(optional(None), "");
        assert_eq!(optional(Some(-2.0)), "-2e0");
    }

    /// Scene keys: by their last part; the study's `dt`; unknown keys have none.
    #[test]
    fn scene_keys_have_their_units() {
        assert_eq!(scene_key_unit("dt"), Some(Unit::Second));
        assert_eq!(scene_key_unit("scene.dt"), Some(Unit::Second));
        assert_eq!(scene_key_unit("solver.cfl"), Some(Unit::One));
        assert_eq!(scene_key_unit("grid.cell_size"), Some(Unit::Metre));
        assert_eq!(scene_key_unit("materials.soil.E"), Some(Unit::Kilopascal));
        assert_eq!(scene_key_unit("grid.shape_functions"), None);
        assert_eq!(column("load", Unit::KilonewtonPerMetre), "load_kN_per_m");
    }
}
