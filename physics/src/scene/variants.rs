//! Variants of a scene that campaigns run beside the scene as written: the
//! same problem with the explicit integrator, and with the paper's literal
//! formulation.

use super::{
    AnalysisKind, DoubleMapping, PointLayout, Scene, SceneError, ShapeFunctionChoice,
    VolumetricTreatment,
};

/// Which discretisation and regularisation a campaign runs its scenes with.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Formulation {
    /// The scenes as written: uGIMP, 2 × 2 points on sub-cell centres,
    /// over-nonlocal m as written (1.1 in the benchmarks), no double mapping
    /// (theory §11 rows 23–29); B-bar where a scene asks for it.
    #[default]
    AsWritten,
    /// The paper's literal method: bilinear cells, 2 × 2 Gauss points, m = 1
    /// (theory D35), double mapping of the stress increment (theory §7) and
    /// the standard volumetric strain (no B-bar: the paper accepts locking,
    /// theory §2).
    Paper,
}

impl Scene {
    /// The same problem integrated by explicit MUSL (theory §4) to the same end
    /// time: an implicit dynamic scene of `steps` × `dt` becomes an explicit
    /// scene ending at `steps · dt` with the stable step of `[solver] cfl`.
    /// Monitors, loads, snapshots at times and everything else are kept;
    /// snapshots by step number are dropped (the explicit steps differ).
    pub fn explicit_twin(&self) -> Result<Scene, SceneError> {
        let refuse = |message: &str| SceneError::Invalid {
            path: self.scene.name.clone(),
            errors: vec![super::FieldError {
                field: "scene.analysis".into(),
                message: message.into(),
            }],
        };
        let mut twin = self.clone();
        let analysis = &mut twin.scene;
        match analysis.analysis {
            AnalysisKind::Explicit => return Ok(twin),
            AnalysisKind::QuasiStatic => {
                return Err(refuse(
                    "a quasi-static scene has no explicit twin (it has no time scale)",
                ))
            }
            AnalysisKind::ImplicitDynamic => {}
        }
        if analysis.dt.is_none() || (analysis.steps.is_none() && analysis.end_time.is_none()) {
            return Err(refuse("an implicit dynamic scene needs steps and dt"));
        }
        analysis.analysis = AnalysisKind::Explicit;
        // adaptive steps end at `end_time` when given, fixed ones after `steps`
        if !twin.solver.adaptive() {
            analysis.end_time = None;
        }
        analysis.end_time = Some(analysis.end_time_or_steps());
        twin.solver.time_step = super::TimeStepControl::Fixed;
        analysis.steps = None;
        analysis.dt = None;
        twin.output.snapshots.clear();
        twin.output.snapshot_every = 0;
        twin.checked()
    }

    /// The scene with `formulation`'s discretisation and regularisation.
    pub fn with_formulation(&self, formulation: Formulation) -> Result<Scene, SceneError> {
        let mut scene = self.clone();
        if formulation == Formulation::Paper {
            scene.grid.shape_functions = ShapeFunctionChoice::Bilinear;
            scene.grid.point_layout = PointLayout::Gauss;
            if let Some(nonlocal) = &mut scene.nonlocal {
                nonlocal.over_nonlocal = 1.0;
            }
            scene.smoothing.double_mapping = DoubleMapping::Increment;
            // the paper accepts volumetric locking (theory §2): standard B
            scene.grid.volumetric = VolumetricTreatment::Standard;
        }
        scene.checked()
    }

    /// The scene if it validates (a variant may break a rule the original met).
    fn checked(self) -> Result<Scene, SceneError> {
        let errors = self.validate();
        if errors.is_empty() {
            Ok(self)
        } else {
            Err(SceneError::Invalid {
                path: self.scene.name.clone(),
                errors,
            })
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const CUT: &str = include_str!("../../../validation/vertical_cut/nonlocal_h100.toml");

    #[test]
    fn explicit_twin_ends_at_the_implicit_end_time() {
        let scene = Scene::from_str_with_overrides(CUT, "cut", &[]).unwrap();
        let twin = scene.explicit_twin().unwrap();
        assert_eq!(twin.scene.analysis, AnalysisKind::Explicit);
        let end = twin.scene.end_time.unwrap();
        assert!((end - 1.0).abs() < 1e-12, "end time {end}");
        assert_eq!(twin.scene.dt, None);
        assert_eq!(twin.monitor, scene.monitor);
        assert_eq!(twin.output.snapshot_times, scene.output.snapshot_times);
    }

    #[test]
    fn quasi_static_scene_has_no_explicit_twin() {
        let text = include_str!("../../../validation/footing_nosoft/footing_nosoft_h250.toml");
        let scene = Scene::from_str_with_overrides(text, "footing", &[]).unwrap();
        let message = scene.explicit_twin().unwrap_err().to_string();
        assert!(message.contains("scene.analysis"), "{message}");
    }

    #[test]
    fn paper_formulation_is_bilinear_gauss_plain_nonlocal_with_double_mapping() {
        let scene = Scene::from_str_with_overrides(CUT, "cut", &[]).unwrap();
        assert_eq!(scene.nonlocal.as_ref().unwrap().over_nonlocal, 1.1);
        let paper = scene.with_formulation(Formulation::Paper).unwrap();
        assert_eq!(paper.grid.shape_functions, ShapeFunctionChoice::Bilinear);
        assert_eq!(paper.grid.point_layout, PointLayout::Gauss);
        assert_eq!(paper.nonlocal.as_ref().unwrap().over_nonlocal, 1.0);
        assert_eq!(paper.smoothing.double_mapping, DoubleMapping::Increment);
        assert_eq!(
            scene.with_formulation(Formulation::AsWritten).unwrap(),
            scene
        );
    }

    #[test]
    fn paper_formulation_drops_b_bar() {
        let text = include_str!("../../../validation/footing/nonlocal_h250.toml");
        let b_bar = ["grid.volumetric=\"b_bar\"".to_string()];
        let scene = Scene::from_str_with_overrides(text, "footing", &b_bar).unwrap();
        assert_eq!(scene.grid.volumetric, VolumetricTreatment::BBar);
        let paper = scene.with_formulation(Formulation::Paper).unwrap();
        assert_eq!(paper.grid.volumetric, VolumetricTreatment::Standard);
        assert_eq!(paper.smoothing.double_mapping, DoubleMapping::Increment);
    }
}
