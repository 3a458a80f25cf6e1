//! `[solver]` keys of the linear solver (issue 16): their mapping onto
//! [`mpm_solvers::LinearOptions`] and their checks, and the `[output] systems`
//! export's.

use mpm_solvers::{
    Factorization, LinearOptions, Method, Ordering, PcgOptions, Preconditioner, SolverOptions,
};

use super::{
    AnalysisKind, FactorizationChoice, FieldError, LinearSolverChoice, OrderingChoice, OutputSpec,
    PreconditionerChoice, SolverSpec,
};

impl SolverSpec {
    /// The linear solver's options these keys ask for.
    pub fn linear_options(&self) -> LinearOptions {
        LinearOptions {
            method: match self.linear_solver {
                LinearSolverChoice::Auto => Method::Auto,
                LinearSolverChoice::Cholesky => Method::Cholesky,
                LinearSolverChoice::Lu => Method::Lu,
                LinearSolverChoice::Pcg => Method::Pcg,
                LinearSolverChoice::Ldl => Method::Ldl,
                LinearSolverChoice::LuReuse => Method::LuReuse,
                LinearSolverChoice::Multifrontal => Method::Multifrontal,
            },
            direct: SolverOptions {
                factorization: match self.factorization {
                    FactorizationChoice::Auto => Factorization::Auto,
                    FactorizationChoice::Supernodal => Factorization::Supernodal,
                    FactorizationChoice::Simplicial => Factorization::Simplicial,
                },
                ordering: match self.ordering {
                    OrderingChoice::Default => Ordering::Default,
                    OrderingChoice::Amd => Ordering::Amd,
                    OrderingChoice::Colamd => Ordering::Colamd,
                    OrderingChoice::Identity => Ordering::Identity,
                },
                ..Default::default()
            },
            pcg: PcgOptions {
                preconditioner: match self.pcg_preconditioner {
                    PreconditionerChoice::Jacobi => Preconditioner::Jacobi,
                    PreconditionerChoice::IncompleteCholesky => Preconditioner::IncompleteCholesky,
                },
                tolerance: self.pcg_tolerance,
                max_iterations: self.pcg_max_iterations,
            },
        }
    }

    /// Checks of the linear-solver keys and of `[output] systems` (the
    /// materials' symmetry is checked when the integrator is built, see
    /// `integrators::tangent::Tangent::new`).
    pub(crate) fn validate_linear(
        &self,
        output: &OutputSpec,
        analysis: AnalysisKind,
        e: &mut Vec<FieldError>,
    ) {
        let mut refuse = |field: &str, message: String| {
            e.push(FieldError {
                field: field.into(),
                message,
            })
        };
        let options = self.linear_options();
        if !options.method.available() {
            refuse(
                "solver.linear_solver",
                "`ldl` needs mpm-geo built with `--features ldl` (sprs_ldl, LGPL)".into(),
            );
        }
        if options.method == Method::Lu {
            if let Err(m) = options.direct.check_lu() {
                refuse("solver.ordering", m);
            }
        }
        if options.method == Method::Multifrontal {
            // the multifrontal factorisation has its own ordering (AMD of K + Kᵀ) and is
            // supernodal: faer's choices would be ignored
            if self.ordering != OrderingChoice::Default {
                refuse(
                    "solver.ordering",
                    "does not apply to `multifrontal` (it orders by AMD of K + Kᵀ)".into(),
                );
            }
            if self.factorization != FactorizationChoice::Auto {
                refuse(
                    "solver.factorization",
                    "does not apply to `multifrontal` (its fronts are dense blocks)".into(),
                );
            }
        }
        if !(self.pcg_tolerance > 0.0 && self.pcg_tolerance < 1.0) {
            refuse(
                "solver.pcg_tolerance",
                format!("must be in (0, 1) (got {})", self.pcg_tolerance),
            );
        }
        if self.pcg_max_iterations == 0 {
            refuse("solver.pcg_max_iterations", "must be >= 1".into());
        }
        if output.systems_max_mb.is_nan() || output.systems_max_mb <= 0.0 {
            refuse(
                "output.systems_max_mb",
                format!("must be > 0 (got {})", output.systems_max_mb),
            );
        }
        if let Some(bound) = output.energy_remainder_warning {
            if !(bound.is_finite() && bound > 0.0) {
                refuse(
                    "output.energy_remainder_warning",
                    format!("must be a share > 0 (got {bound})"),
                );
            }
        }
        if !output.systems.is_empty() && analysis == AnalysisKind::Explicit {
            refuse(
                "output.systems",
                "an explicit run solves no linear systems".into(),
            );
        }
    }
}
