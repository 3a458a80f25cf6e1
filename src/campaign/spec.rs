//! `campaign.toml`: what a campaign directory holds (which benchmark, so which
//! curves, metrics and figures) and which integrators run each scene.
//!
//! ```toml
//! benchmark = "vertical_cut"            # biaxial | footing | vertical_cut | load_curve
//! integrators = ["as_written", "explicit"]
//! ```
//!
//! A directory without the file is a `load_curve` campaign run as written.

use std::path::Path;

use serde::Deserialize;

use super::CampaignError;
use crate::plot::Bounds;
use crate::scene::Scene;

/// Name of the campaign description in a campaign directory.
pub const SPEC_FILE: &str = "campaign.toml";

/// The benchmark a campaign reproduces: it fixes the curves read, the
/// metrics and the figures.
#[derive(Clone, Copy, Debug, Default, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum Benchmark {
    /// Any load–displacement campaign (δ in m, initial slope over 5–20 % of
    /// the last δ, fields over the whole grid).
    #[default]
    LoadCurve,
    /// Biaxial compression (paper Figs. 3–5, theory §8.1): δ in mm.
    Biaxial,
    /// Rigid strip footing (paper Figs. 7–8, theory §8.2): load curves plus
    /// the soil inside the footing's outline and the corner-band reach.
    Footing,
    /// Vertical cut (paper Figs. 10–12, theory §8.3): time histories of u_A,
    /// q_B and the run-out instead of a load curve.
    VerticalCut,
}

/// The integrator a campaign runs a scene with.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum IntegratorChoice {
    /// The scene's own `scene.analysis`.
    AsWritten,
    /// Explicit MUSL to the same end time ([`Scene::explicit_twin`]).
    Explicit,
}

impl IntegratorChoice {
    /// Suffix of the run name (`""` for the scene as written).
    pub fn suffix(self) -> &'static str {
        match self {
            Self::AsWritten => "",
            Self::Explicit => "_explicit",
        }
    }

    /// The scene for this integrator.
    pub fn apply(self, scene: &Scene) -> Result<Scene, CampaignError> {
        match self {
            Self::AsWritten => Ok(scene.clone()),
            Self::Explicit => scene
                .explicit_twin()
                .map_err(|e| CampaignError::Scene(e.to_string())),
        }
    }
}

fn as_written() -> Vec<IntegratorChoice> {
    vec![IntegratorChoice::AsWritten]
}

/// The contents of `campaign.toml`.
#[derive(Clone, Debug, Deserialize, PartialEq, Eq)]
#[serde(deny_unknown_fields)]
pub struct CampaignSpec {
    /// Which benchmark (default `load_curve`).
    #[serde(default)]
    pub benchmark: Benchmark,
    /// The integrators every scene is run with (default: as written).
    #[serde(default = "as_written")]
    pub integrators: Vec<IntegratorChoice>,
}

impl Default for CampaignSpec {
    fn default() -> Self {
        Self {
            benchmark: Benchmark::default(),
            integrators: as_written(),
        }
    }
}

impl CampaignSpec {
    /// Read `dir/campaign.toml` (the default spec if there is none).
    pub fn load(dir: &Path) -> Result<Self, CampaignError> {
        let path = dir.join(SPEC_FILE);
        if !path.exists() {
            return Ok(Self::default());
        }
        let refuse =
            |e: &dyn std::fmt::Display| CampaignError::Scene(format!("{}: {e}", path.display()));
        let text = std::fs::read_to_string(&path).map_err(|e| refuse(&e))?;
        let spec: Self = toml::from_str(&text).map_err(|e| refuse(&e))?;
        if spec.integrators.is_empty() {
            return Err(refuse(&"`integrators` must name at least one integrator"));
        }
        Ok(spec)
    }
}

impl Benchmark {
    /// Whether the last step holds one band whose width M4 measures (theory
    /// §9). Not the footing: at δ = 0.3 m its mechanism has collapsed (the
    /// load is 0.5–2 % of the peak) and the strain fills the whole Prandtl
    /// zone and the soil heaved around the footing, with no single band to
    /// cross; Fig. 7's claims are read from the field plots and the
    /// corner-band reach instead.
    pub fn has_one_band(self) -> bool {
        self != Self::Footing
    }

    /// Unit of δ in tables and plots: (name, metres → unit factor).
    pub fn length_unit(self) -> (&'static str, f64) {
        match self {
            Self::Biaxial => ("mm", 1e3),
            _ => ("m", 1.0),
        }
    }

    /// δ range of the initial-slope fit, m: the elastic part of the curve
    /// after the start-up transient of slow dynamic runs.
    pub fn slope_window(self, delta_end: f64) -> (f64, f64) {
        match self {
            Self::Biaxial => (1e-4, 5e-4),
            // elastic to delta ~ 0.016 m (theory §8.2 reference curves)
            Self::Footing => (2.5e-3, 1.0e-2),
            _ => (0.05 * delta_end, 0.2 * delta_end),
        }
    }

    /// Region of the field plots.
    pub fn field_window(self, scene: &Scene) -> Bounds {
        let g = &scene.grid;
        let whole = Bounds::new(
            g.origin[0],
            g.origin[0] + g.size[0],
            g.origin[1],
            g.origin[1] + g.size[1],
        );
        match self {
            // the specimen with its room for bulging
            Self::Biaxial => Bounds::new(0.0, 0.04, 0.0, 0.05),
            // the Prandtl mechanism (it reaches ~3.5 m beside the footing edges)
            Self::Footing => Bounds::new(2.0, 12.0, 3.0, 8.5),
            // the run-out (h = 0.1 m, t = 1 s: front at 21.8 m explicit, 23.9 m
            // implicit), 1.5 m above the crest: not the air the scenes keep
            // for the explicit twin's throws
            Self::VerticalCut => Bounds::new(
                whole.x.0,
                whole.x.1.min(whole.x.0 + 30.0),
                whole.y.0,
                whole.y.1.min(whole.y.0 + 4.5),
            ),
            _ => whole,
        }
    }
}
