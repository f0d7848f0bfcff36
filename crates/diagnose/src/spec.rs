//! What to diagnose: the model (a list of effect ids) and the options.

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::effect::{Effect, catalog, lookup};
use crate::error::DiagnoseError;

/// A model: the baseline plus a list of effects by id. Stored as a RON list,
/// e.g. `["tip_cutting_force", "material_stiffening"]`.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(transparent)]
pub struct ModelSpec {
    /// Effect ids, in the order their parameters are appended.
    pub effects: Vec<String>,
}

impl ModelSpec {
    /// The paper's baseline: no effect.
    pub fn baseline() -> Self {
        Self::default()
    }

    /// A model from effect ids (checked against the catalog).
    pub fn from_ids<S: AsRef<str>>(ids: &[S]) -> Result<Self, DiagnoseError> {
        let spec = Self {
            effects: ids.iter().map(|s| s.as_ref().to_string()).collect(),
        };
        spec.effects()?;
        Ok(spec)
    }

    /// Reads a model file (a RON list of ids).
    pub fn read(path: &Path) -> Result<Self, DiagnoseError> {
        let text = std::fs::read_to_string(path).map_err(|source| DiagnoseError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let spec: Self = ron::from_str(&text).map_err(|e| DiagnoseError::ModelFile {
            path: path.to_path_buf(),
            message: e.to_string(),
        })?;
        spec.effects()?;
        Ok(spec)
    }

    /// The same model with one more effect.
    pub fn with(&self, id: &str) -> Self {
        let mut effects = self.effects.clone();
        effects.push(id.to_string());
        Self { effects }
    }

    /// The effect objects, or an error naming an unknown or repeated id.
    pub fn effects(&self) -> Result<Vec<Box<dyn Effect>>, DiagnoseError> {
        let mut out: Vec<Box<dyn Effect>> = Vec::new();
        for id in &self.effects {
            if out.iter().any(|e| e.id() == id) {
                return Err(DiagnoseError::DuplicateEffect(id.clone()));
            }
            let effect = lookup(id).ok_or_else(|| DiagnoseError::UnknownEffect {
                id: id.clone(),
                known: catalog()
                    .iter()
                    .map(|e| e.id())
                    .collect::<Vec<_>>()
                    .join(", "),
            })?;
            out.push(effect);
        }
        Ok(out)
    }
}

/// Options of [`crate::diagnose`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DiagnoseOptions {
    /// Family-wise false-alarm rate of the verdict: an effect is named only
    /// if its likelihood-ratio p-value is below `significance / candidates`
    /// (Bonferroni).
    pub significance: f64,
    /// The leading candidate is named only if its likelihood ratio is at
    /// least this fraction of the current fit's unexplained misfit (per
    /// channel the excess $\chi^2 - \nu$, at least the noise's spread
    /// `chi2_spread` $\sqrt{2\nu}$): an effect that only soaks up a
    /// little of a large structured residual is not what is missing (the
    /// residual is then `Unexplained`).
    pub min_explained: f64,
    /// A channel's chi-square per dof is consistent with 1 when within this
    /// many sampling standard deviations `sqrt(2/dof)`.
    pub chi2_spread: f64,
    /// The model mesh has elements of at most (marker spacing) / `refinement`.
    pub refinement: usize,
    /// The `out_of_plane` slab has elements of at most (marker spacing) /
    /// `slab_refinement` in the plane (and two layers through the thickness).
    pub slab_refinement: usize,
    /// Radius of the needle (m), 0 for a line. The `out_of_plane` slab
    /// places the needle's load by the drag of the needle's surface, not
    /// of its axis (`Body::needle_drag`); below a quarter of the
    /// phantom's thickness. A bundle does not state it: it is the
    /// instrument's, like its gauge.
    pub needle_radius: f64,
    /// Grade the `out_of_plane` slab's plan towards every needle along x
    /// or y: node lines on its line, half the plan's spacing either side,
    /// and at a half, a quarter and an eighth of it from its entry. It
    /// resolves the needle's near field and its entry better, at about
    /// twice the slab's cost (default campaign: 114 to 253 s for the final
    /// model's fit and ranking).
    pub slab_needle_grading: bool,
    /// Number of force samples nearest in time averaged into a probe
    /// trial's force at a camera frame.
    pub probe_force_samples: usize,
    /// At most this many camera frames of each trial enter the fit, evenly
    /// spaced and ending with the last (0: all). Fewer frames cost less and
    /// keep the statistics valid; they only lose power.
    pub frames_per_trial: usize,
    /// Add the recommended effect and refit until the verdict is not
    /// `MissingEffect`, building the error ladder.
    pub add_recommended: bool,
    /// At most this many effects are added by `add_recommended`.
    pub max_added: usize,
    /// Starting Young's modulus (Pa).
    pub initial_youngs_modulus: f64,
    /// Starting Poisson ratio.
    pub initial_poisson_ratio: f64,
    /// Starting width of the probe's contact patch (m), fitted when the
    /// bundle has probing trials.
    pub initial_probe_width: f64,
    /// A probe frame's markers closer to the contact point than this many
    /// phantom thicknesses are left out of the fit. The model spreads the
    /// measured force over the patch as a rigid punch would in the plane
    /// and evenly through the thickness; a real punch's pressure differs
    /// near its edges and corners, and by Saint-Venant's principle the
    /// difference fades within about the largest size of the loaded patch,
    /// here the thickness. Nearer markers would fit the model's idealised
    /// contact, not the tissue (on the quick campaign the six markers
    /// within one thickness of each probe raised the probes' chi-square
    /// per value from 1.0 to 1.2). 0 keeps every marker.
    pub probe_near_field: f64,
}

impl Default for DiagnoseOptions {
    fn default() -> Self {
        Self {
            significance: 0.01,
            chi2_spread: 3.0,
            min_explained: 0.2,
            refinement: 3,
            slab_refinement: 1,
            needle_radius: 0.0,
            slab_needle_grading: false,
            probe_force_samples: 9,
            frames_per_trial: 12,
            add_recommended: false,
            max_added: 4,
            initial_youngs_modulus: 25.0e3,
            initial_poisson_ratio: 0.45,
            initial_probe_width: 0.002,
            probe_near_field: 1.0,
        }
    }
}

impl DiagnoseOptions {
    /// Checks every option, naming the first out of range; [`crate::diagnose`]
    /// does this first, callers that do slow work before it can too.
    pub fn validate(&self) -> Result<(), DiagnoseError> {
        let bad = |field: &'static str, reason: String| {
            Err(DiagnoseError::InvalidOption { field, reason })
        };
        if !(self.significance > 0.0 && self.significance < 1.0) {
            return bad(
                "significance",
                format!("{} must be in (0, 1)", self.significance),
            );
        }
        if !(0.0..1.0).contains(&self.min_explained) {
            return bad(
                "min_explained",
                format!("{} must be in [0, 1)", self.min_explained),
            );
        }
        if !(self.chi2_spread.is_finite() && self.chi2_spread > 0.0) {
            return bad(
                "chi2_spread",
                format!("{} must be positive", self.chi2_spread),
            );
        }
        if self.refinement == 0 || self.refinement > 16 {
            return bad(
                "refinement",
                format!("{} must be in 1..=16", self.refinement),
            );
        }
        if self.slab_refinement == 0 || self.slab_refinement > 8 {
            return bad(
                "slab_refinement",
                format!("{} must be in 1..=8", self.slab_refinement),
            );
        }
        if !(self.needle_radius.is_finite() && self.needle_radius >= 0.0) {
            return bad(
                "needle_radius",
                format!("{} must be finite and at least 0", self.needle_radius),
            );
        }
        if self.probe_force_samples == 0 {
            return bad("probe_force_samples", "must be at least 1".into());
        }
        if !(self.probe_near_field.is_finite() && self.probe_near_field >= 0.0) {
            return bad(
                "probe_near_field",
                format!("{} must be finite and at least 0", self.probe_near_field),
            );
        }
        if !(self.initial_youngs_modulus.is_finite() && self.initial_youngs_modulus > 0.0) {
            return bad(
                "initial_youngs_modulus",
                format!("{} must be positive", self.initial_youngs_modulus),
            );
        }
        if !(self.initial_poisson_ratio > 0.0 && self.initial_poisson_ratio < 0.5) {
            return bad(
                "initial_poisson_ratio",
                format!("{} must be in (0, 0.5)", self.initial_poisson_ratio),
            );
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::DiagnoseOptions;
    use crate::error::DiagnoseError;

    #[test]
    fn lengths_must_be_finite_and_not_negative() {
        type Set = fn(&mut DiagnoseOptions, f64);
        let fields: [(&str, Set); 2] = [
            ("probe_near_field", |o, v| o.probe_near_field = v),
            ("needle_radius", |o, v| o.needle_radius = v),
        ];
        for (name, set) in fields {
            for bad in [-1.0, f64::NAN, f64::INFINITY] {
                let mut options = DiagnoseOptions::default();
                set(&mut options, bad);
                assert!(
                    matches!(
                        options.validate(),
                        Err(DiagnoseError::InvalidOption { field, .. }) if field == name
                    ),
                    "{name} = {bad}"
                );
            }
            let mut zero = DiagnoseOptions::default();
            set(&mut zero, 0.0);
            assert!(zero.validate().is_ok(), "{name} = 0");
        }
    }
}
