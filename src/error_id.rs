//! Finding the stable identifier ([`ErrorId`]) of any error the library
//! returns.
//!
//! The identifiers, their meanings and remedies are listed once in the
//! physics crate (`mpm_physics::error_id`, re-exported here); each error
//! type implements [`Identified`] where it is defined. [`identify`] looks an
//! error up through those implementations.

use mpm_solvers::SolverError;

pub use mpm_physics::error_id::{markdown_table, ErrorId, Identified};

use crate::campaign::CampaignError;
use crate::error::{RunError, StepError};
use crate::output_dir::OutputDirError;
use crate::point_driver::PointDriverError;
use crate::scene::SceneError;
use crate::study::StudyError;

/// The identifier of an error returned by the library (looked up through
/// the error types that carry one); `None` for an error of another kind.
pub fn identify(error: &(dyn std::error::Error + 'static)) -> Option<ErrorId> {
    if let Some(e) = error.downcast_ref::<SceneError>() {
        return Some(e.error_id());
    }
    if let Some(e) = error.downcast_ref::<OutputDirError>() {
        return Some(e.error_id());
    }
    if let Some(e) = error.downcast_ref::<RunError>() {
        return Some(e.error_id());
    }
    if let Some(e) = error.downcast_ref::<StepError>() {
        return Some(e.error_id());
    }
    if let Some(e) = error.downcast_ref::<SolverError>() {
        return Some(e.error_id());
    }
    if let Some(e) = error.downcast_ref::<CampaignError>() {
        return Some(e.error_id());
    }
    if let Some(e) = error.downcast_ref::<StudyError>() {
        return Some(e.error_id());
    }
    if let Some(e) = error.downcast_ref::<crate::checkpoint::CheckpointError>() {
        return Some(e.error_id());
    }
    if let Some(e) = error.downcast_ref::<PointDriverError>() {
        return Some(e.error_id());
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn boxed_library_errors_are_identified() {
        let step: Box<dyn std::error::Error> = Box::new(RunError::Step {
            step: 3,
            time: 0.1,
            cause: StepError::ParticleLeftGrid {
                particle: 7,
                position: [1.0, 2.0],
            },
        });
        assert_eq!(identify(step.as_ref()), Some(ErrorId::RunPointLeftGrid));
        let campaign: Box<dyn std::error::Error> =
            Box::new(CampaignError::Unfinished("a, b".into()));
        assert_eq!(
            identify(campaign.as_ref()),
            Some(ErrorId::CampaignUnfinished)
        );
        let other: Box<dyn std::error::Error> = "plain".into();
        assert_eq!(identify(other.as_ref()), None);
    }
}
