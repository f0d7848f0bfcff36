//! How far the model's own mesh moves its predictions: the mesh
//! convergence check of every diagnosis.
//!
//! The first fit's model is evaluated once more, at the fitted parameters,
//! with the plane body's elements [`CHECK_FACTOR`] times smaller. With
//! $\Delta = W(\hat y_\text{fine} - \hat y)$ the whitened change of the
//! predictions, $\Delta^2 = |\Delta|^2$ is the scale of what an effect
//! could gain in $\chi^2$ by absorbing the coarse mesh's error. It is a
//! yardstick, not a bound: at an order of convergence $p$ the coarse
//! mesh's own error is about $\Delta / (1 - 2^{-p})$, 1.5 times it at the
//! $p = 1.66$ the unit test measures, while the fitted parameters take up
//! part of that error and an effect only the part its shape matches. An
//! effect named with a likelihood ratio no larger may stand for the mesh
//! rather than for physics, and the diagnosis says so; a larger ratio
//! still leaves rerunning at a finer mesh the test that settles it.
//! The `out_of_plane` slab is not refined: eight times the unknowns.

use serde::{Deserialize, Serialize};

use crate::error::DiagnoseError;
use crate::forward::Forward;
use crate::model::Model;
use crate::observe::Observations;
use crate::whiten::Whitening;

/// The finer mesh's elements are this many times smaller.
pub const CHECK_FACTOR: usize = 2;

/// The change of the first fit's predictions on a finer plane mesh.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DiscretisationCheck {
    /// The model's refinement, and the finer one it was compared with.
    pub refinements: [usize; 2],
    /// RMS change of the predicted marker displacements (m).
    pub rms_marker: f64,
    /// Largest change of a predicted marker displacement (m).
    pub max_marker: f64,
    /// RMS change of the predicted base forces (N); `NaN` without any.
    pub rms_force: f64,
    /// The whitened change's squared norm, $\Delta^2$, in units of
    /// $\chi^2$.
    pub chi2: f64,
}

impl DiscretisationCheck {
    /// The warning for `effect`, named with `likelihood_ratio`, when the
    /// mesh alone could account for that much: a ratio no larger than
    /// the check's $\Delta^2$.
    pub fn doubt(&self, effect: &str, likelihood_ratio: f64) -> Option<String> {
        let [coarse, fine] = self.refinements;
        (likelihood_ratio <= self.chi2).then(|| {
            format!(
                "`{effect}` is named with a likelihood ratio of {likelihood_ratio:.1}, no more \
                 than the {:.1} by which the plane model's own mesh moves the misfit \
                 (refinement {coarse} against {fine}; markers {:.2} um rms): it may stand for \
                 the mesh's error rather than physics; rerun with --refinement {fine} to tell",
                self.chi2,
                self.rms_marker * 1e6
            )
        })
    }
}

/// Evaluates `model` at `params` with `finer` (the same bodies at a finer
/// plane refinement) and compares with `predicted`, its predictions on its
/// own mesh, under `whitening`.
pub(crate) fn check_discretisation(
    obs: &Observations,
    whitening: &Whitening,
    predicted: &[f64],
    finer: &Forward,
    model: &Model,
    params: &[f64],
    refinements: [usize; 2],
) -> Result<DiscretisationCheck, DiagnoseError> {
    let fine = finer.predict(model, params, obs)?.values;
    let change: Vec<f64> = fine.iter().zip(predicted).map(|(f, c)| f - c).collect();
    let (marker_part, force_part) = change.split_at(obs.marker_count());
    let lengths: Vec<f64> = marker_part
        .chunks_exact(2)
        .map(|c| c[0].hypot(c[1]))
        .collect();
    let rms = |v: &[f64], per: f64| {
        if v.is_empty() {
            f64::NAN
        } else {
            (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64 * per).sqrt()
        }
    };
    Ok(DiscretisationCheck {
        refinements,
        rms_marker: rms(&lengths, 1.0),
        max_marker: lengths.iter().copied().fold(0.0, f64::max),
        rms_force: rms(force_part, 2.0),
        chi2: whitening.apply(&change).iter().map(|x| x * x).sum(),
    })
}

#[cfg(test)]
mod tests {
    use needle_data::TrialKind;

    use super::*;
    use crate::forward::tests::{observations_of, paper_phantom};
    use crate::model::Baseline;
    use crate::spec::ModelSpec;

    #[test]
    fn the_mesh_s_change_shrinks_at_the_rate_of_the_elements() {
        let obs = observations_of(&[
            ("probe", TrialKind::Probe, 2.0, 0.0),
            ("needle", TrialKind::Needle, 3.0, 0.04),
        ]);
        let forward = |r: usize| Forward::new(&paper_phantom(), &obs.rest, r, 1, &[], 0.0).unwrap();
        let start = Baseline {
            youngs_modulus: 25.0e3,
            poisson_ratio: 0.45,
            shaft_density: 10.0,
            probe_width: 0.002,
        };
        let meshes = [forward(1), forward(2), forward(4)];
        let model = Model::new(&ModelSpec::baseline(), &meshes[0].geometry, start).unwrap();
        let p: Vec<f64> = model.parameters.iter().map(|q| q.initial).collect();
        let whitening = Whitening::independent(obs.marker_count(), 8e-6, &obs.row_sigmas(), 5e-3);
        let check = |coarse: usize, r: usize| {
            let predicted = meshes[coarse].predict(&model, &p, &obs).unwrap().values;
            check_discretisation(
                &obs,
                &whitening,
                &predicted,
                &meshes[coarse + 1],
                &model,
                &p,
                [r, 2 * r],
            )
            .unwrap()
        };
        let (first, second) = (check(0, 1), check(1, 2));
        // Quadratic elements, singular loads: an observed order of at least
        // 1.5 between the two halvings.
        let order = (first.rms_marker / second.rms_marker).log2();
        assert!(order > 1.5, "order {order}");
        assert!(second.rms_marker > 0.0 && second.max_marker >= second.rms_marker);
    }

    #[test]
    fn an_effect_is_doubted_only_within_the_mesh_s_change() {
        let check = DiscretisationCheck {
            refinements: [3, 6],
            rms_marker: 0.54e-6,
            max_marker: 5.6e-6,
            rms_force: 2.9e-5,
            chi2: 1426.1,
        };
        let doubt = check.doubt("layered_stiffness", 838.3).unwrap();
        assert!(doubt.contains("--refinement 6"), "{doubt}");
        assert!(
            doubt.contains("1426.1") && doubt.contains("838.3"),
            "{doubt}"
        );
        assert!(check.doubt("layered_stiffness", 1500.0).is_none());
    }
}
