//! needle-identify: material identification from boundary probing, the
//! paper's section III-B and equation (5).
//!
//! A blunt probe presses on a free face of the phantom with a measured force
//! while a camera tracks the markers on the top face. The phantom is a
//! linear elastic body, so the marker displacements are the stiffness
//! system's response to the probe force; this crate finds the Young's
//! modulus $E$ and Poisson's ratio $\nu$ (or one modulus per layer) that make
//! the model reproduce the tracked displacements,
//!
//! $$\min_{E,\nu}\; \big(u - P K(E,\nu)^{-1} f\big)^T W \big(u - P K(E,\nu)^{-1} f\big) \qquad (5)$$
//!
//! where $u$ stacks the measured marker displacements of every frame in
//! contact, $f$ the probe force of that frame, spread over the contact
//! patch of a rigid flat punch of fitted width $a$ centred on the probe
//! tip's point of the boundary (pressure $\propto 1/\sqrt{1 - (2s/a)^2}$
//! along the face, [`ProbeLoad::FlatPunch`], the default) or applied at
//! that point ([`ProbeLoad::Point`], the paper's), $K$ the plane-strain (or plane-stress) stiffness
//! of equation (4) with the fixed faces imposed, or that of the 3-D slab of
//! tetrahedra ([`PlaneModel::Slab`]: markers on the top face, the probe
//! force spread over the thickness), $P$ the interpolation of
//! nodal displacements at the markers, and $W = \mathrm{diag}(1/\sigma_i^2)$
//! the whitening by the marker noise (the paper's unweighted form is
//! $W = I$; with one stated noise the minimiser is the same).
//!
//! # Variable projection
//!
//! For a homogeneous body $K(E,\nu) = E\,K(1,\nu)$, so for fixed $\nu$ the
//! prediction is $s\,g(\nu)$ with $s = E_\text{ref}/E$ and
//! $g = P K(E_\text{ref},\nu)^{-1} f$: linear in the single scalar $s$, whose
//! optimum is closed-form, $s^* = \langle g,u\rangle_W/\langle g,g\rangle_W$.
//! What is left is a one-dimensional profile in $\nu$, which is scanned over
//! the whole interval $[0, 0.499]$ (points crowded towards $1/2$, where the
//! response changes fastest). The best scan point starts a
//! Levenberg-Marquardt polish of $(E,\nu)$ and the punch width by the
//! project's engine
//! ([`lsq`], re-exported here) with the analytic Jacobian
//! $\partial u/\partial p = -K^{-1}(\partial K/\partial p)\,u$ (for the
//! width, $K^{-1}\partial b/\partial a$ by a difference of the load), which also
//! yields the covariance, the standard errors and 95% intervals. The
//! starting values therefore do not decide which minimum is found: any start
//! with $E$ in 1 kPa..1 MPa and $\nu$ in 0..0.499 gives the same fit (tested).
//!
//! Per-region moduli are not separable this way (only their common scale
//! is), so they are fitted directly with the engine from the homogeneous
//! optimum. Per-trial moduli hold $\nu$ and the displacement pattern of the
//! global fit and fit one scale per trial; a line through them against the
//! day exposes drift (the paper's phantom stiffened over the days between
//! tests as plasticiser leaked out).
//!
//! The stiffness sparsity pattern and its symbolic Cholesky factorisation
//! are built once; every evaluation only reassembles values and refactors.
//!
//! # Where it sits
//!
//! `needle-data` (bundles), `needle-fem` (meshes, assembly, locating
//! markers) and `needle-lsq` (the fitting engine) come in; `needle-force`
//! takes the identified material to invert needle forces, and
//! `needle-diagnose` compares models. Chain:
//! fem, lsq, data -> identify -> force -> diagnose.
//!
//! Entry points: [`identify_material`] for a bundle, [`identify_from_data`]
//! for plain arrays ([`ProbeData`]), [`extract_probe_data`] for the step
//! between them.
//!
//! # What it does not do
//!
//! It does not track markers (needle-vision), model friction under the
//! probe, a pressure that varies through the thickness, viscoelasticity or
//! large strains (the needle-diagnose effects), or treat the force as
//! uncertain: the probe force is taken as exact and only marker noise
//! whitens the residuals (a straight line fitted to the force record around
//! each frame, `force_window`, averages the sensor's noise and quantisation
//! out; what is left still dominates chi2/dof on the default sensor,
//! `docs/identification.md`). With the point-force model, markers closer
//! than one marker spacing to the load point are left out by default,
//! because a point load's displacement is singular there; the flat punch
//! models the contact patch and keeps them.
//!
//! # Bad input
//!
//! Too few markers, no Probe trial, a zero force everywhere, no frame in
//! contact, a probe tip away from every free face, no fixed face (a
//! singular stiffness), or displacements that do not respond to the force
//! are typed errors ([`IdentifyError`]). A trial that cannot contribute is
//! skipped with a [`FitFlag`]; a fit that stops on a limit, sits on a bound,
//! leaves parameters undetermined, misses the stated noise by far
//! (chi2/dof > 2) or shows drift is flagged, never reported silently.

mod error;
mod extract;
mod fe;
mod identify;
mod model;
mod observe;
mod options;
mod probe;
mod problem;
mod punch;
mod result;

pub use needle_lsq as lsq;

pub use error::IdentifyError;
pub use extract::{extract_probe_data, fitted_sample_at, sample_at};
pub use fe::Response;
pub use identify::{identify_from_data, identify_material};
pub use model::{ModelSpec, ProbeModel, project_to_boundary};
pub use options::{IdentifyOptions, PlaneModel, ProbeLoad, Regions};
pub use probe::{MIN_MARKERS, MarkerDisplacement, ProbeData, ProbeFrame, ProbeSetup, ProbeTrial};
pub use result::{
    CONFIDENCE_LEVEL, DriftFit, Estimate, FitFlag, MaterialFit, ModelSummary, NoiseSource,
    RegionFit, TrialFit,
};
