//! # needle-diagnose: compare the model with the measurements, see where it
//! fails, learn which physical effect is missing, add it, watch the error fall
//!
//! Given a measurement bundle and a model (the paper's baseline plus a list
//! of effects), [`diagnose`] fits the model to all trials jointly, reports
//! the misfit per channel, ranks every catalog effect not in the model by
//! how much of the residual it explains, gives a [`Verdict`], and on request
//! adds the recommended effect and refits, building the error [`Ladder`].
//! [`write_outputs`] writes `diagnosis.ron`, `ladder.csv`, the fitted
//! `model.ron` and the residual tables.
//!
//! ## Where it sits
//!
//! `needle-data` (bundles), `needle-fem` (meshes, assembly, Cholesky,
//! loads, supports) and `needle-lsq` (the Levenberg-Marquardt engine)
//! -> **needle-diagnose** -> `xtask diagnose`.
//!
//! ## The forward model
//!
//! The baseline is the paper's: a homogeneous linear elastic plane-strain
//! T6 model of the top face with a node on every marker, the manifest's
//! fixed faces held rigidly. A probe trial loads it with the measured tool
//! force and moment spread over a contact patch of width $a$ on the
//! boundary as under a rigid flat punch,
//! centred on the point of the outline nearest the tip (a blunt probe is not
//! a point: at the marker noise its contact shape is seen tens of
//! millimetres away, and a point force is singular under it). Markers
//! within one phantom thickness of the contact are left out of a probe
//! frame ([`DiagnoseOptions::probe_near_field`]): there the idealised
//! punch (even through the thickness) and a real one differ by more than
//! the noise, and by Saint-Venant's principle the difference fades within
//! about that distance. A needle trial loads it with a uniform shaft
//! density $q$ along the inserted needle, whose integral is the predicted
//! base force. The needle's load acts on the
//! tissue it holds: the material points whose deformed positions lie on the
//! needle, from the front face as dragged in by the shaft (millimetres in a
//! soft phantom), found by a few fixed-point rounds per frame. Parameters: $E$, $\nu$, $q$, $a$
//! ($a$ is held when no trial probes). Every [`effect::Effect`] adds parameters
//! and changes one part: the modulus field, the supports, the shaft
//! density, the kinematics (`out_of_plane` blends in a Tet10 slab through
//! the thickness), the constitutive law (`material_nonlinearity` adds the
//! neo-Hookean terms of second and third order in the load, see `series`),
//! or the measurement map (see [`effect`] and
//! `docs/adding-an-effect.md`). Details in the `forward` and `body`
//! modules.
//!
//! ## The statistics
//!
//! Residuals are whitened by the stated noise: marker $\sigma_m$ (or, for
//! a row of `markers.csv` that gives them, its own `sx,sy`) and force
//! $\sigma_F$, and for each probe frame the force noise of the measured
//! probe force (averaged over the nearest samples), which moves all markers
//! of the frame together: that frame is whitened with its full covariance
//! $\sigma_m^2 I + s^2 (g_x g_x^T + g_y g_y^T)$ (see `whiten`). If the
//! bundle states no noise, each channel's $\sigma$ is estimated from the
//! data's repeated samples: successive camera frames and sensor samples,
//! by differences of second and third order in time, which cancel a
//! signal that is smooth between samples and must agree (see `noise`).
//! Where they do not (frames far apart), or give more than the fit
//! leaves, the channel's $\sigma$ is the one under which the fit's
//! chi-square per dof is 1, taken again at every step of the ladder; the
//! result says which ([`NoiseSource::Estimated`], [`NoiseBasis`]). On the
//! quick campaign with its noise removed from the manifest the estimates
//! are 7.99 um and 5.97 mN (8 um and 6.17 mN generated), and the ladder
//! adds the same effects as with the noise stated, to the same verdict
//! (chi-square per dof 5.5 to 6.6% higher for the force, 0.3 to 0.6% for
//! the markers).
//!
//! Each diagnosis also checks its own mesh (see `discretisation`): the first
//! fit evaluated with plane elements half the size moves the whitened
//! predictions by $\Delta^2$ in $\chi^2$, and an effect named with a
//! likelihood ratio no larger is flagged ([`Diagnosis::doubt`]): it may
//! stand for the mesh's error rather than physics.
//!
//! - **Chi-square per dof** of a channel $c$ with $n_c$ residuals:
//!   $\chi^2_c / \nu_c$, $\nu_c = n_c - p\, n_c / n$ (the $p$ fitted
//!   parameters charged in proportion). Under a correct model it is 1 with
//!   sampling standard deviation $\sqrt{2/\nu_c}$.
//! - **Score test** of a candidate effect at the current fit: the gradient
//!   of the cost with respect to the effect's parameters at their null
//!   values, $U = J_\psi^T r$, against the efficient Fisher information
//!   $I = J_\psi^T (1 - P_\theta) J_\psi$; $S = U^T I^{-1} U \sim \chi^2_k$
//!   (see `rank`).
//! - **Refit**: the model with the effect added; likelihood ratio
//!   $\Lambda = \chi^2_\text{now} - \chi^2_\text{with} \sim \chi^2_{k'}$,
//!   AIC and BIC. The best candidate by score is refitted, and any other
//!   whose score p-value is below 0.05 and whose score reaches a tenth of
//!   the larger of the leader's likelihood ratio and the least one the
//!   verdict names an effect with (`Candidate::refitted`): a refit is the
//!   costliest work of a step, and the score is the local form of the
//!   likelihood ratio, so a candidate far behind by score is hardly the
//!   one that explains most by refit, nor one that could be named. Refits
//!   stop once a step lowers $\chi^2$ by less than $10^{-4}\chi^2$ (their
//!   likelihood ratio is then a lower bound), and their Jacobians place
//!   the needle loads from the base point's placements in one round
//!   (within 2.5% of the model's own derivative, for fewer
//!   back-substitutions; see `fit::Precision`);
//!   the model that continues the ladder is refitted to $10^{-8}$ with
//!   columns placed in two rounds (within 1%).
//!
//! ## The verdict
//!
//! With $N$ candidates and family-wise level $\alpha$ (default 0.01), a
//! candidate is significant when its likelihood-ratio p-value is below
//! $\alpha/N$ (Bonferroni), so the chance of naming any effect on data the
//! model explains is at most $\alpha$.
//!
//! - `MissingEffect(id)`: the significant candidate with the largest
//!   $\Lambda$ (the one that explains most of the residual), provided it
//!   explains at least a fraction `min_explained` (default 0.2) of the
//!   misfit, $\Lambda \ge f \sum_c \max(\chi^2_c - \nu_c,\, z\sqrt{2\nu_c})$
//!   over the channels $c$ ($z$ = `chi2_spread`): a candidate that soaks
//!   up only a sliver of a large structured residual (a stiff inclusion
//!   partly mimicked by a per-trial effect) is not named, nor is one that
//!   explains a sliver of what the noise's own spread could hide (the
//!   model's small inexactness: its mesh, its idealised probe contact). A
//!   channel below its noise (a generous stated sigma) does not offset
//!   another's excess.
//! - `ConsistentWithNoise`: no candidate significant, and every channel has
//!   $\chi^2/\nu \le 1 + z\sqrt{2/\nu}$ ($z$ = `chi2_spread`, default 3).
//! - `Unexplained`: no candidate named but some channel misfits beyond
//!   that: structured residual that no catalog effect explains (see the
//!   residual tables).
//!
//! ## What it does not do
//!
//! `material_nonlinearity` is a third-order series about the linear
//! solution, not a Newton solve, and always from the plane mesh;
//! compression trials are ignored; the needle's bending moment and
//! lateral forces are not modelled; the probe force and moment are taken
//! as measured (the force's noise enters the covariance, not the
//! parameters; the moment's noise, which the bundle does not state, is
//! neglected, and the moment does not enter the neo-Hookean terms).

mod body;
mod chi2;
mod concentrate;
mod diagnose;
mod discretisation;
pub mod effect;
mod error;
mod fit;
mod forward;
mod model;
mod noise;
mod observe;
mod place;
mod rank;
mod series;
mod spec;
mod whiten;
mod write;

pub use chi2::{chi2_upper_quantile, chi2_upper_tail};
pub use concentrate::{energy_share_of_worst, residual_concentration};
pub use diagnose::{
    Diagnosis, DiagnosisRun, FittedModel, FittedParameter, ForceResidual, Ladder, LadderRow,
    MarkerResidual, TrialMisfit, Verdict, diagnose, diagnose_campaign,
};
pub use discretisation::DiscretisationCheck;
pub use error::DiagnoseError;
pub use fit::Fit;
pub use noise::{ChannelNoise, NoiseBasis, NoiseSource, SampleNoise};
pub use rank::Candidate;
pub use spec::{DiagnoseOptions, ModelSpec};
pub use write::write_outputs;
