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
//! - [`hyperelastic`], [`assemble_nonlinear`], [`solve_nonlinear`],
//!   [`nonlinear_error`]: the compressible neo-Hookean model for strains
//!   beyond the linear range (see below).
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
//! ## Large strain: compressible neo-Hookean
//!
//! For strains above about 15 % the crate offers the hyperelastic energy
//! $W = \frac{\mu}{2}(I_1 - 3) - \mu\ln J + \frac{\lambda}{2}(\ln J)^2$
//! ($I_1 = \operatorname{tr} F^TF$, $J = \det F$) with the $\mu$, $\lambda$ of
//! the linear [`Material`], so both models agree at small strain; the first
//! Piola–Kirchhoff stress is $P = \mu(F - F^{-T}) + \lambda\ln J\,F^{-T}$ and
//! the tangent $\mathbb{A} = \partial P/\partial F$ is written out in
//! [`hyperelastic`]. Plane strain sets $F_{33} = 1$ (forces are totals over
//! the thickness, as in the linear 2-D model); 3-D is the full model.
//! [`HyperelasticAssembler`] assembles $f_\text{int}(u) = \int P\,\nabla_X N$
//! and $K_T(u)$ in parallel, in the linear pattern; [`HyperelasticProblem`]
//! wraps a [`LinearProblem`] (same constraints, supports and symbolic
//! factorisation) and solves $f_\text{int}(u) = f_\text{ext}$ by Newton with
//! line search and load steps, or by modified Newton with the linear
//! problem's factor (cheap, many load cases, linear rate; it stops
//! contracting at large strain of nearly incompressible bodies). Failure is
//! a typed [`NonlinearError`].
//!
//! *Homogeneous stretch (the closed form the tests check).* A block
//! stretched by $s$ along $x$ with traction-free sides has
//! $F = \operatorname{diag}(s, l, 1)$ in plane strain; $P_{22} = 0$ gives
//! $\mu(l^2 - 1) + \lambda\ln(s\,l) = 0$ for the lateral stretch $l$, and the
//! nominal stress (force per reference area) is
//! $P_{11} = \mu(s - 1/s) + \lambda\ln(s\,l)/s$. In 3-D uniaxial tension,
//! $F = \operatorname{diag}(s, l, l)$, $\mu(l^2-1) + \lambda\ln(s\,l^2) = 0$ and
//! $P_{11} = \mu(s - 1/s) + \lambda\ln(s\,l^2)/s$. Linearised in $s - 1$ both
//! reduce to the linear model's $P_{11} = (\lambda + 2\mu)\varepsilon_{11} + \lambda\varepsilon_{22}(+\lambda\varepsilon_{33})$.
//!
//! ```
//! use needle_fem::{
//!     Assembler, Dirichlet, ElementKind, Face, Formulation, HyperelasticProblem, LinearProblem,
//!     Material, Materials, NonlinearOptions, RectangleMesh,
//! };
//!
//! # fn main() -> Result<(), needle_fem::NonlinearError> {
//! let mesh = RectangleMesh::uniform(0.075, 0.075, 4, 4)?.build(ElementKind::Tri6)?;
//! let formulation = Formulation::PlaneStrain { thickness: 0.0075 };
//! let fixed = Dirichlet::fixed_face(&mesh, Face::Back);
//! let mut loads = vec![0.0; mesh.dof_count()];
//! let front = mesh.facets_on_face(Face::Front);
//! needle_fem::load::add_traction(&mesh, formulation, &mut loads, &front, |_| [0.0, -3.0e3])?;
//! let linear = LinearProblem::new(Assembler::new(mesh, formulation)?, vec![], fixed)?;
//! let mut problem = HyperelasticProblem::new(linear)?;
//! let materials = Materials::homogeneous(Material::new(25.3e3, 0.48)?);
//!
//! let newton = problem.solve_newton(&materials, &loads, None, &NonlinearOptions::default())?;
//! // The cheap variant needs the linear factor.
//! problem.linear_mut().factorize(&materials)?;
//! let options = NonlinearOptions { max_iterations: 200, ..NonlinearOptions::default() };
//! let modified = problem.solve_modified_newton(&materials, &[&loads], None, &options)?;
//! let gap = newton.displacement.iter().zip(&modified[0].displacement)
//!     .map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
//! assert!(gap < 1e-8 * newton.displacement.iter().fold(0.0_f64, |m, v| m.max(v.abs())));
//! assert!(modified[0].iterations > newton.iterations);
//! # Ok(())
//! # }
//! ```
//!
//! ## Limitations
//!
//! - Linear elasticity, plus the neo-Hookean model above (plane strain and
//!   3-D; no plane stress); no contact and no needle–tissue friction (the
//!   truth world implements those effects itself).
//! - Simplices only; point location assumes straight-sided elements (all
//!   meshes built here are).
//! - Linear elements (T3, Tet4) lock as $\nu \to 0.5$; use T6/Tet10 for the
//!   phantom's $\nu = 0.48$ (see `docs/locking.md`).
//! - Direct sparse Cholesky only; no iterative solver.

pub mod analytic;
pub mod assemble;
pub mod assemble_nonlinear;
pub mod dirichlet;
mod dissect;
pub mod element;
pub mod error;
pub mod hyperelastic;
pub mod load;
pub mod locate;
pub mod material;
pub mod mesh;
pub mod nonlinear_error;
pub mod norm;
mod reach;
pub mod solve;
pub mod solve_nonlinear;
pub mod stress;
pub mod support;

pub use assemble::{Assembler, StiffnessPattern};
pub use assemble_nonlinear::HyperelasticAssembler;
pub use dirichlet::Dirichlet;
pub use element::ElementKind;
pub use error::FemError;
pub use hyperelastic::NeoHookean;
pub use load::LineDensity;
pub use locate::{Location, Locator};
pub use material::{Constitutive, Formulation, Material, Materials, Parameter};
pub use mesh::{
    BoundaryFacet, Face, MarkerGrid, Mesh, Mesh2, Mesh3, QualityReport, RectangleMesh, SlabMesh,
};
pub use nonlinear_error::NonlinearError;
pub use solve::{CholeskyFactor, LinearProblem, Solution};
pub use solve_nonlinear::{HyperelasticProblem, NonlinearOptions, NonlinearSolution};
pub use support::Support;
