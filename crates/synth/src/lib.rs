//! needle-synth: the truth world. It generates realistic measured data, a
//! measurement bundle, from physics at higher fidelity than any model the
//! pipeline fits, with physical effects hidden in it, and writes the
//! ground truth (effects present, every true value) beside the bundle.
//!
//! # Where it sits
//!
//! `fem` (meshes, element stiffness, assembly) and `data` (the bundle
//! writer) -> **synth** -> `xtask` (`cargo xtask synth --scenario FILE
//! --out DIR`). The truth calls the FEM crate for meshing and the linear
//! stiffness matrix only; it implements every effect itself (one file per
//! effect in [`effect`], each documenting its physics), and its own point
//! location, loads, constraints, solver set-up, hyperelastic Newton solver,
//! needle-tip consistency and sensor models. It does not fit anything and
//! shares no code with the model crates.
//!
//! # The truth
//!
//! - A scenario ([`Scenario`], RON) gives the phantom, the material, the
//!   resolution, the sensors, the experiments (compression test, boundary
//!   probing, needle insertions at several velocities on several days,
//!   each along a new line) and the effects present.
//! - Without `out_of_plane` the phantom is a plane-strain mesh of 6-node
//!   triangles; with it, a slab of 10-node tetrahedra with several layers
//!   through the thickness, markers read on the top face, the needle load
//!   on the mid-plane. The slab's mesh is mirrored in its mid-plane, and
//!   unless the platform's foundation acts under its bottom face it is
//!   solved as its upper half, which gives the whole's displacement
//!   exactly (`slab_mesh`). The slab is a tensor grid cut into six
//!   tetrahedra per cell, or, with `SlabGrading::local`, an octree on the
//!   grid's cells refined towards the needles, probe edges and back face
//!   (`local_mesh`).
//! - A linear truth factorises $K$ once for every day whose moduli are a
//!   uniform multiple of the day-0 moduli (stiffening over days scales the
//!   solution by $1/c$), and every state is a back-substitution; probes
//!   hold their face by Lagrange multipliers on that same factorisation;
//!   a needle insertion keeps the columns of $K^{-1}$ for the dofs its
//!   line loads, so that its consistency iterations need no
//!   back-substitution ([`needle`]), and the insertions run in parallel.
//!   With `resolution.marker_grading` the consistency iteration of every
//!   state goes on from the loads it found, on a finer slab, until the
//!   needle's placement there is consistent too, and the needle trials'
//!   markers and base force are read there (`marker_mesh`). A finer slab
//!   refined locally is refined along where the placement put each
//!   needle's loads in the material, one slab per insertion (the fine
//!   paper default).
//!   With `resolution.probe_grading` each probe is pressed on a slab of
//!   its own, graded towards its edges and factorised with its face held
//!   (`probe_mesh`).
//!   Every factor is ordered by METIS's nested dissection on the graph
//!   of the mesh's nodes (`ordering`, the one foreign library the truth
//!   links), which fills less than faer's default minimum degree.
//! - Needle shaft loads act at the material points whose deformed images
//!   lie on the needle ([`needle`]); the tool force is their integral.
//! - Measurements: force sensor noise and quantisation, Gaussian marker
//!   noise, at the sensor and camera rates ([`sensor`]); when the scenario
//!   asks for them, camera frames of some trials rendered through the true
//!   camera, and calibration images of a dot-grid target ([`camera`],
//!   [`frames`]).
//!
//! # Entry points
//!
//! [`load_scenario`], [`Scenario::paper_default`],
//! [`Scenario::paper_default_fine`], [`Scenario::quick`], [`generate()`].

pub mod camera;
pub mod effect;
pub mod error;
pub mod frames;
pub mod generate;
pub mod interpolate;
pub mod needle;
pub mod scenario;
pub mod sensor;
pub mod truth;

mod body;
mod contact;
mod grid;
mod line_response;
mod local_mesh;
mod low_rank;
mod marker_mesh;
mod ordering;
mod presets;
mod probe;
mod probe_mesh;
mod record;
mod shaft;
mod slab_mesh;
mod strain;
mod system;
mod world;

#[cfg(test)]
mod tests;

pub use camera::{CameraFrames, FrameSelection, TrueCamera};
pub use effect::{EffectId, Effects};
pub use error::SynthError;
pub use generate::{Stage, Summary, TrialResponse, generate, respond};
pub use scenario::{LocalRefinement, Resolution, Scenario, SlabGrading, load_scenario};
pub use truth::GroundTruth;
