//! # needle-condense
//!
//! The condensed reduced-system solver of section VI of DiMaio & Salcudean
//! (equations (7)-(10) and the appendix), for haptic-rate needle simulation.
//!
//! Only a few *working nodes* matter at haptic rate (those touching the needle
//! and those shown), so the linear elastostatic model `K u = f` is condensed to
//! `u_W = K_W^{-1} f_W` with every other node force-free. This crate:
//!
//! - factorises the full model once ([`FullModel::factor`], sparse Cholesky,
//!   faer) and builds `K_W^{-1}` column by column with parallel solves
//!   ([`CondensedSystem::new`]), for 2-D and 3-D node layouts;
//! - adds and removes working nodes at run time by a bordered update from
//!   (prefetched) columns of the factorised model
//!   ([`CondensedSystem::add_node`], [`CondensedSystem::prefetch`],
//!   [`CondensedSystem::remove_node`]);
//! - holds mixed boundary conditions per coordinate, equation (7): `x = S y`
//!   with `S = (K_W^{-1})'`, exchanging a displacement and a force variable by
//!   the rank-one update of equation (8) ([`CondensedSystem::exchange`]);
//! - rotates node frames to follow the needle: equation (9) as O(N) row and
//!   column operations, equation (10) with the appendix's closed-form inverse
//!   for a slipping node ([`CondensedSystem::rotate_node`],
//!   [`appendix_slip_inverse_columns`]);
//! - applies updates at once, keeps them as a low-rank (Woodbury) buffer
//!   folded in later, or never forms `S` and keeps `G` with the Cholesky
//!   factor of its small displacement-given block (the capacitance form)
//!   ([`UpdatePolicy`]);
//! - answers the per-tick query of the needle unknowns in O(m N)
//!   ([`CondensedSystem::unknowns_into`]), apart from the graphics-rate query
//!   of all unknowns ([`CondensedSystem::unknowns_all_into`]);
//! - measures accumulated round-off against the factorised full model and
//!   rebuilds exactly when it exceeds a bound ([`CondensedSystem::drift`],
//!   [`CondensedSystem::refresh`]).
//!
//! Every operation is exact: after any sequence of them, `x` equals the direct
//! sparse solution of the same mixed boundary-value problem on the full mesh
//! (tested to 1e-9 relative by proptest on synthetic 2-D and 3-D lattices, and
//! on needle-fem T3/T6 plane-strain meshes against needle-fem's own solve).
//! The derivations, the two misprints found in the paper (equation (8) and the
//! appendix's Σ) and the benchmark figures are in `docs/condense.md`.
//!
//! ## Where it sits
//!
//! `fem <- condense <- haptic`: the input is any assembled stiffness matrix (a
//! faer `SparseColMat`, symmetric positive definite once the fixed dofs are
//! removed) with interleaved dofs per node, such as needle-fem assembles; the
//! haptic loop (contact states, stick/slip decisions, devices) sits on top.
//!
//! ## What it does not do
//!
//! No meshing or assembly (needle-fem), no contact logic (which node sticks or
//! slips, and when: needle-haptic), no nonlinear material, no dynamics: the
//! model is linear elastostatic, as in the paper. [`lattice`] only provides
//! synthetic SPD models for tests and benchmarks.

mod border;
mod capacitance;
mod dense;
mod drift;
mod error;
mod exchange;
mod factor;
pub mod lattice;
mod query;
mod rotate;
mod system;

pub use error::CondenseError;
pub use factor::FullModel;
pub use query::NodeState;
pub use rotate::appendix_slip_inverse_columns;
pub use system::{CondensedSystem, Condition, Frame, UpdatePolicy};
