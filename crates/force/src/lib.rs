//! needle-force: the needle shaft force distribution from tracked marker
//! displacements, the paper's section IV (equations (4) and (6), Figs. 9 to
//! 15).
//!
//! # What it does
//!
//! - **The paper's method as it is** ([`paper_nodal_forces`],
//!   [`MarkerMeshModel`]): the mesh nodes are the markers (linear triangles on
//!   the marker grid), the measured displacement $u$ of every node gives the
//!   external nodal forces of equation (4),
//!   $$f = K u,$$
//!   with the plane model (plane strain as in the paper, or plane stress).
//!   Nodes within half a grid spacing of the needle path are shaft nodes, the
//!   nodes on the fixed face carry the reactions, and $\sum f = 0$. The
//!   shaft-node sum against the measured base force over an insertion is
//!   [`integrated_vs_base`] with [`Method::PaperNodal`] (Fig. 11);
//!   [`average_nodal_forces`] averages repeated insertions.
//! - **The regularised estimator** ([`ShaftEstimator`],
//!   [`shaft_force_distribution`]): the force support is restricted to the
//!   needle line, the unknowns are the station values $q_j$ of a
//!   piecewise-linear axial force density $q(s)$ from the entry to the
//!   material tip, mapped to the marker displacements by the finite-element
//!   model, $u = Gq$ ([`ShaftResponse`]), and
//!   $$\hat q = \arg\min_q |W(Gq - u)|^2 + \lambda |Lq|^2$$
//!   with $W$ the inverse marker noise, $L$ a first- or second-difference
//!   operator along the shaft ([`Smoothness`]) and $\lambda$ from the
//!   discrepancy principle when the noise is known or generalised
//!   cross-validation otherwise ([`Regularisation`]; the solve is
//!   `needle-lsq`'s Tikhonov solver). With a known noise,
//!   [`Regularisation::MarginalLikelihood`] takes $\lambda$ and a penalty
//!   relaxed near the tip ([`TipPrior`]) from the marginal likelihood of
//!   the data, so that the tip peak is not smoothed away. With [`Model::Slab`] ($G$ from a 3-D
//!   Tet10 slab, the load on the mid-plane, the markers on the top face)
//!   this is the paper's equation (6),
//!   $$\min_{F_s} (u - G(E,\nu)F_s)^T(u - G(E,\nu)F_s),$$
//!   solved as the linear least-squares problem it is rather than by
//!   gradient descent (Figs. 10b, 13). With [`Model::Plane`] it is the same
//!   estimator on the plane model.
//! - **The tip-following estimator** ([`fit_tip_following`],
//!   [`tip_following_distributions`]): at a constant insertion velocity the
//!   density is a steady profile $f(d)$ of the distance behind the tip,
//!   $q_k(s) = f(L_k - s)$ at every frame; the tip moves past fixed markers,
//!   so one profile fitted to the frames of one marker spacing of depth
//!   (and of repeated insertions) resolves a tip peak below the marker
//!   spacing. Its prior is chosen by the same marginal likelihood; frames
//!   the steady profile does not explain are flagged ([`FrameCheck`]).
//! - **Derived results**: the density behind the tip against velocity
//!   ([`density_vs_velocity`], Fig. 14), layered phantoms through
//!   [`MaterialField::LayersInY`] (Fig. 15), error metrics against a known
//!   density ([`distribution_error`]).
//! - **Figures** as SVG strings: [`plot_nodal_forces`] (Fig. 9),
//!   [`plot_shaft_distributions`] (Fig. 10), [`plot_integrated_vs_base`]
//!   (Figs. 11 and 13), [`plot_density_vs_velocity`] (Fig. 14),
//!   [`plot_layered_distribution`] (Fig. 15).
//!
//! $G$ is built once per insertion: the model is factorised once and solved
//! for a unit force on every dof the needle line can load; a frame's $G$ is
//! then that response times the consistent nodal loads of its hat functions
//! (`needle-fem`'s line load), so a frame costs a few small dense solves.
//! The load acts on the material points whose deformed images lie on the
//! needle, from the deformed front face to the tip, with the density per
//! length of needle: placed first in the measured displacement, then in
//! the model's own mid-plane field of the previous fit, a fixed number of
//! rounds (`place`).
//!
//! Bad input gives a [`ForceError`] naming what was wrong (too few markers,
//! markers not on a grid, a trial that is not a needle insertion or has no
//! frame in contact, a missing marker for $f = Ku$, a singular fit), and a
//! fit that cannot reach the stated noise is *flagged*
//! ([`ShaftDistribution::is_flagged`], [`LambdaChoice`]) rather than
//! reported with confidence.
//!
//! # Where it sits
//!
//! `needle-data` (bundles), `needle-fem` (meshes, assembly, solves, line
//! loads, marker interpolation) and `needle-lsq` (Tikhonov) -> **force** ->
//! `needle-diagnose` and the pipeline's report.
//!
//! # What it does not do
//!
//! It does not identify $E$ and $\nu$ (that is `needle-identify`; pass the
//! material in), track markers, or model effects beyond linear elasticity
//! (the diagnosis crate does). Only the axial component of the shaft force
//! is estimated; the models need the markers on a rectangular grid and a
//! straight needle path per insertion.

mod error;
mod estimate;
mod evidence;
mod follow;
mod nodal;
mod observe;
mod place;
mod plot;
mod pool;
mod regularise;
mod respond;
mod series;
mod shaft;
mod tip;
mod velocity;

pub use error::ForceError;
pub use estimate::{
    EstimatorOptions, ShaftDistribution, ShaftEstimator, shaft_force_distribution,
    shaft_force_distributions,
};
pub use follow::{FollowOptions, FollowedFrame, FrameCheck, TipFollowing, fit_tip_following};
pub use nodal::{MarkerMeshModel, PaperNodalForces, average_nodal_forces, paper_nodal_forces};
pub use observe::{Frame, GridIndex, Insertion, MarkerLayout, observe_insertion};
pub use plot::{
    ShaftCurve, plot_density_vs_velocity, plot_integrated_vs_base, plot_layered_distribution,
    plot_nodal_forces, plot_shaft_distributions,
};
pub use pool::{fit_explained_pool, tip_following_distributions};
pub use regularise::{
    DISCREPANCY_SAFETY, LambdaChoice, Regularisation, RegularisedFit, solve_regularised,
};
pub use respond::{MaterialField, Model, ModelOptions, PlaneKind, ShaftResponse};
pub use series::{
    DistributionError, IntegratedPoint, IntegratedSeries, Method, average_distributions,
    average_series, distribution_error, integrated_vs_base, point_of,
};
pub use shaft::{ShaftBasis, ShaftPath, Smoothness};
pub use tip::{TIP_RELAXATIONS, TIP_ZONES, TipPrior, TipZone, fit_with_tip_prior};
pub use velocity::{ShaftWindow, VelocityPoint, density_vs_velocity, window_density};
