//! # needle-fem
//!
//! Meshes, finite elements, materials, sparse assembly and solvers for
//! linear elastostatics, with closed-form reference solutions to test them.
//! It implements Section III-A of DiMaio & Salcudean (the element matrices
//! $A^e$ of equation (3) and the global system $K u = f$ of equation (4)) in
//! 2-D (plane strain / plane stress, 3- and 6-node triangles) and 3-D (4-
//! and 10-node tetrahedra).
//!
//! ## Place in the chain
//!
//! `data <- fem <- identify <- force <- diagnose`, `fem <- synth`,
//! `fem <- condense`. Identification needs $K(E,\nu)$, $\partial K/\partial E$,
//! $\partial K/\partial\nu$ and the marker interpolation operator; the
//! truth world (`synth`) builds 3-D quadratic-tetrahedron slabs and applies
//! needle line loads; the condensed haptic solver takes the assembled $K$
//! and its Cholesky factor.
//!
//! ## Conventions
//!
//! - Frame of the measurement bundle: x across the phantom, y the insertion
//!   direction (front face $y=0$, back face $y=$ depth), z through the
//!   thickness with mid-plane $z=0$ and markers on the top face $z=t/2$.
//!   SI units, `f64`.
//! - Degrees of freedom are **interleaved per node**: node `n` owns dofs
//!   `D*n + i`, `i` = 0 ($u_x$), 1 ($u_y$)[, 2 ($u_z$)]. Every load,
//!   displacement and reaction vector is a full vector in this order.
//! - In 2-D, stiffness and tractions are multiplied by the formulation's
//!   thickness, so forces are totals in N.
//!
//! ## Modules
//!
//! - [`mesh`]: [`Mesh`] (nodes, connectivity, regions), [`RectangleMesh`],
//!   [`SlabMesh`], node and facet look-ups ([`Face`]).
//! - [`element`]: reference shape functions, quadrature, local stiffness.
//! - [`material`]: [`Material`], [`Materials`], [`Formulation`], $D$ and
//!   $\partial D/\partial\nu$.
//! - [`assemble`]: [`Assembler`], [`StiffnessPattern`]: parallel assembly of
//!   $K$ and $\partial K/\partial p$ into faer `SparseColMat<usize, f64>`.
//! - [`dirichlet`], [`support`], [`load`]: boundary conditions and loads
//!   (point, line along the needle, traction; springs and foundations).
//! - [`solve`]: [`LinearProblem`]: sparse Cholesky with kept symbolic and
//!   numeric factors, many right-hand sides, reactions.
//! - [`locate`]: [`Locator`]: point location, interpolation, and the sparse
//!   marker operator $H$ with $u_\text{markers} = H u$.
//! - [`stress`]: strains and stresses.
//! - [`analytic`]: closed-form solutions (Lamé cylinder, Flamant, Timoshenko
//!   cantilever, manufactured fields) used by the tests.
//!
//! ## Example
//!
//! A 2-D plane-strain block fixed on its back face, pulled on its front
//! face; the mean displacement of the front face matches $F L/(E' A)$ with
//! $E' = E/(1-\nu^2)$ only approximately (the fixed face adds lateral
//! restraint), so we check equilibrium and the sign instead.
//!
//! ```
//! use needle_fem::{
//!     Assembler, Dirichlet, ElementKind, Face, Formulation, LinearProblem, Material, Materials,
//!     RectangleMesh,
//! };
//!
//! # fn main() -> Result<(), needle_fem::FemError> {
//! let mesh = RectangleMesh::uniform(0.075, 0.075, 8, 8)?.build(ElementKind::Tri6)?;
//! let formulation = Formulation::PlaneStrain { thickness: 0.0075 };
//! let fixed = Dirichlet::fixed_face(&mesh, Face::Back);
//! let front = mesh.facets_on_face(Face::Front);
//! let mut loads = vec![0.0; mesh.dof_count()];
//! // 1 kPa pulling the front face towards -y.
//! needle_fem::load::add_traction(&mesh, formulation, &mut loads, &front, |_| [0.0, -1.0e3])?;
//!
//! let mut problem = LinearProblem::new(Assembler::new(mesh, formulation)?, vec![], fixed)?;
//! problem.factorize(&Materials::homogeneous(Material::new(25.3e3, 0.48)?))?;
//! let solution = problem.solve(&loads)?;
//!
//! // Reactions balance the applied load: 1 kPa * 0.075 m * 0.0075 m.
//! let reaction_y: f64 = solution.reactions.iter().skip(1).step_by(2).sum();
//! assert!((reaction_y - 1.0e3 * 0.075 * 0.0075).abs() < 1e-9);
//! let front_node = problem.mesh().nearest_node([0.0375, 0.0]).unwrap();
//! assert!(solution.displacement[2 * front_node + 1] < 0.0);
//! # Ok(())
//! # }
//! ```
//!
//! ## Limitations
//!
//! - Small-strain linear elasticity only; no contact, no geometric or
//!   material nonlinearity (the truth world implements those effects itself).
//! - Simplices only; point location assumes straight-sided elements (all
//!   meshes built here are).
//! - Linear elements (T3, Tet4) lock as $\nu \to 0.5$; use T6/Tet10 for the
//!   phantom's $\nu = 0.48$ (see `docs/locking.md`).
//! - Direct sparse Cholesky only; no iterative solver.

pub mod analytic;
pub mod assemble;
pub mod dirichlet;
pub mod element;
pub mod error;
pub mod load;
pub mod locate;
pub mod material;
pub mod mesh;
pub mod norm;
pub mod solve;
pub mod stress;
pub mod support;

pub use assemble::{Assembler, StiffnessPattern};
pub use dirichlet::Dirichlet;
pub use element::ElementKind;
pub use error::FemError;
pub use load::LineDensity;
pub use locate::{Location, Locator};
pub use material::{Constitutive, Formulation, Material, Materials, Parameter};
pub use mesh::{
    BoundaryFacet, Face, MarkerGrid, Mesh, Mesh2, Mesh3, QualityReport, RectangleMesh, SlabMesh,
};
pub use solve::{LinearProblem, Solution};
pub use support::Support;
