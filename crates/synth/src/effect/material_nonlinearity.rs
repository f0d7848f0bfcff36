//! `material_nonlinearity`: the phantom leaves the linear range at large
//! strains (the paper's Fig. 5: linear up to 15-20% strain).
//!
//! The truth material becomes compressible neo-Hookean with the same
//! small-strain moduli ($\mu = E/(2(1+\nu))$, $\lambda = E\nu/((1+\nu)(1-2\nu))$):
//! $$\psi(F) = \tfrac{\mu}{2}(I_1 - 3) - \mu \ln J + \tfrac{\lambda}{2}(\ln J)^2,$$
//! with $I_1 = \mathrm{tr}(F^TF)$ and $J = \det F$ (plane strain: $F_{zz} = 1$).
//! The first Piola-Kirchhoff stress is
//! $P = \mu(F - F^{-T}) + \lambda \ln J\,F^{-T}$ and its tangent
//! $$\partial P_{iJ}/\partial F_{kL} = \mu\,\delta_{ik}\delta_{JL} +
//! (\mu - \lambda\ln J)\,F^{-1}_{Li}F^{-1}_{Jk} + \lambda\,F^{-1}_{Ji}F^{-1}_{Lk}.$$
//!
//! Equilibrium $f_{int}(u) + K_s u = f_{ext}$ (loads are dead loads at
//! material points; $K_s$ the springs of the supports) is solved by Newton
//! iteration: the tangent is refactorised whenever the residual stops
//! falling fast, and otherwise reused (modified Newton), which keeps the
//! many nearly equal load steps of a trial cheap; where the tangent is not
//! positive definite the stiffness at rest is used instead. A residual
//! with NaN (an inverted element) is a typed non-convergence error. At small strains the
//! tangent equals the linear stiffness, so the effect only shows at large
//! strains.

use std::sync::{Arc, Mutex};

use needle_fem::element::stiffness::{ReferenceGradients, physical_gradients};
use serde::{Deserialize, Serialize};

use super::{EffectId, TruthEffect};
use crate::body::Body;
use crate::error::SynthError;
use crate::scenario::{FieldChecker, Scenario};
use crate::system::{Analysis, Factorised, Layout, Pivots, Stiffness};

/// Neo-Hookean truth material (same small-strain constants as the phantom).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MaterialNonlinearity;

impl TruthEffect for MaterialNonlinearity {
    const ID: EffectId = EffectId::MaterialNonlinearity;

    fn check(&self, _: &FieldChecker<'_>, _: &str, _: &Scenario) -> Result<(), SynthError> {
        Ok(())
    }
}

/// Lamé constants $(\lambda, \mu)$ of `(E, nu)`.
fn lame(e: f64, nu: f64) -> (f64, f64) {
    (
        e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)),
        e / (2.0 * (1.0 + nu)),
    )
}

/// Nominal (engineering) compressive stress of a uniaxial compression to
/// stretch `stretch` < 1 with free lateral faces: the lateral stretch
/// solves $P_{22} = 0$ by Newton's method; returns $-P_{11}$ (Pa).
pub fn uniaxial_nominal_stress(youngs_modulus: f64, poisson_ratio: f64, stretch: f64) -> f64 {
    let (lambda, mu) = lame(youngs_modulus, poisson_ratio);
    // P22 = mu (l2 - 1/l2) + lambda ln(J) / l2 with J = l1 l2^2.
    let lateral_stress = |l2: f64| mu * (l2 - 1.0 / l2) + lambda * (stretch * l2 * l2).ln() / l2;
    let mut l2 = 1.0 + poisson_ratio * (1.0 - stretch);
    for _ in 0..50 {
        let h = 1e-7 * l2;
        let slope = (lateral_stress(l2 + h) - lateral_stress(l2 - h)) / (2.0 * h);
        let step = lateral_stress(l2) / slope;
        l2 -= step;
        if step.abs() < 1e-15 {
            break;
        }
    }
    let j = stretch * l2 * l2;
    -(mu * (stretch - 1.0 / stretch) + lambda * j.ln() / stretch)
}

/// The neo-Hookean phantom on one day: element data and the Newton solver.
pub(crate) struct NeoHookean {
    /// $(\lambda, \mu)$ per region.
    constants: Vec<(f64, f64)>,
    springs: Vec<(usize, usize, f64)>,
    held: Vec<bool>,
    /// The tangent's pattern: the elements' entries in loop order, then
    /// the springs'.
    layout: Layout,
    /// The analysis of the tangent's free block, shared by every
    /// refactorisation.
    analysis: Arc<Analysis>,
    /// The tangent last factorised, reused while it converges fast.
    tangent: Mutex<Option<Factorised>>,
}

/// Convergence: largest residual force below this fraction of the largest
/// force in the problem.
const RELATIVE_TOLERANCE: f64 = 1e-10;

/// Maximum Newton iterations per solve.
const MAX_ITERATIONS: usize = 200;

impl NeoHookean {
    /// The material `(E, nu)` per region, springs and held components.
    pub fn new(
        body: &Body,
        moduli: &[(f64, f64)],
        springs: &[(usize, usize, f64)],
        held: Vec<bool>,
    ) -> Result<Self, SynthError> {
        if let Some(&r) = body.regions().iter().find(|&&r| r >= moduli.len()) {
            return Err(SynthError::Factorisation {
                what: "the neo-Hookean phantom".into(),
                reason: format!("region {r} has no material"),
            });
        }
        let mut positions = Vec::new();
        for e in 0..body.element_count() {
            let dofs: Vec<usize> = body
                .element(e)
                .iter()
                .flat_map(|&node| (0..body.dim).map(move |i| node * body.dim + i))
                .collect();
            for &r in &dofs {
                positions.extend(dofs.iter().map(|&s| (r, s)));
            }
        }
        positions.extend(springs.iter().map(|&(i, j, _)| (i, j)));
        let layout = Layout::new(body.dof_count(), &positions)?;
        let analysis = Arc::new(layout.analyse(&held, "the neo-Hookean tangent")?);
        Ok(Self {
            constants: moduli.iter().map(|&(e, nu)| lame(e, nu)).collect(),
            springs: springs.to_vec(),
            held,
            layout,
            analysis,
            tangent: Mutex::new(None),
        })
    }

    /// Internal forces of the elements plus the springs at `u`.
    pub fn internal_forces(&self, body: &Body, u: &[f64]) -> Vec<f64> {
        let mut f = vec![0.0; u.len()];
        self.element_loop(body, u, &mut f, None);
        for &(i, j, v) in &self.springs {
            f[i] += v * u[j];
        }
        f
    }

    /// The tangent stiffness at `u`, springs included.
    pub(crate) fn tangent_at(&self, body: &Body, u: &[f64]) -> Result<Stiffness, SynthError> {
        let mut f = vec![0.0; u.len()];
        let mut values = Vec::with_capacity(self.layout.entry_count());
        self.element_loop(body, u, &mut f, Some(&mut values));
        values.extend(self.springs.iter().map(|&(_, _, v)| v));
        self.layout.assemble(&values)
    }

    fn element_loop(&self, body: &Body, u: &[f64], f: &mut [f64], tangent: Option<&mut Vec<f64>>) {
        match body.dim {
            2 => self.element_loop_kind::<2, 6>(body, u, f, tangent),
            _ => self.element_loop_kind::<3, 10>(body, u, f, tangent),
        }
    }

    fn element_loop_kind<const D: usize, const N: usize>(
        &self,
        body: &Body,
        u: &[f64],
        f: &mut [f64],
        mut tangent: Option<&mut Vec<f64>>,
    ) {
        let reference = ReferenceGradients::<D, N>::for_degree(2);
        let scale = body.plane_factor();
        let regions = body.regions();
        for e in 0..body.element_count() {
            let nodes = body.element(e);
            let coordinates =
                nalgebra::SMatrix::<f64, D, N>::from_fn(|i, a| body.nodes[nodes[a]][i]);
            let (lambda, mu) = self.constants[regions[e]];
            let mut fe = [[0.0; 3]; N];
            let mut ke = vec![0.0; (N * D) * (N * D)];
            for (grad_ref, w) in &reference.points {
                let (grad, det) = physical_gradients(&coordinates, grad_ref);
                let dv = w * det * scale;
                // F = I + sum_a u_a (x) grad N_a, padded to 3x3.
                let mut fm = [[0.0; 3]; 3];
                for k in 0..3 {
                    fm[k][k] = 1.0;
                }
                for a in 0..N {
                    for i in 0..D {
                        let ua = u[nodes[a] * D + i];
                        for j in 0..D {
                            fm[i][j] += ua * grad[(j, a)];
                        }
                    }
                }
                let (finv, j) = inverse_and_det(&fm);
                let ln_j = j.ln();
                // P = mu (F - F^-T) + lambda ln J F^-T.
                let mut p = [[0.0; 3]; 3];
                for i in 0..3 {
                    for k in 0..3 {
                        p[i][k] = mu * (fm[i][k] - finv[k][i]) + lambda * ln_j * finv[k][i];
                    }
                }
                for a in 0..N {
                    for i in 0..D {
                        fe[a][i] += dv * (0..D).map(|jj| p[i][jj] * grad[(jj, a)]).sum::<f64>();
                    }
                }
                if tangent.is_some() {
                    let c = mu - lambda * ln_j;
                    for a in 0..N {
                        for b in 0..N {
                            for i in 0..D {
                                for k in 0..D {
                                    let mut v = 0.0;
                                    for jj in 0..D {
                                        let ga = grad[(jj, a)];
                                        for l in 0..D {
                                            let gb = grad[(l, b)];
                                            let mut aijkl = c * finv[l][i] * finv[jj][k]
                                                + lambda * finv[jj][i] * finv[l][k];
                                            if i == k && jj == l {
                                                aijkl += mu;
                                            }
                                            v += ga * aijkl * gb;
                                        }
                                    }
                                    ke[(a * D + i) * (N * D) + b * D + k] += dv * v;
                                }
                            }
                        }
                    }
                }
            }
            for a in 0..N {
                for i in 0..D {
                    f[nodes[a] * D + i] += fe[a][i];
                }
            }
            if let Some(t) = tangent.as_deref_mut() {
                // Row-major, in the order of `NeoHookean::new`'s positions.
                t.extend_from_slice(&ke);
            }
        }
    }

    /// The tangent at `u` and its factorised free block. Compressive stress
    /// can make the tangent indefinite (large compression with a coarse
    /// mesh; an antisymmetric mode of the whole mirrored slab under a
    /// probe): then it is factorised as $L D L^T$, and only if that fails
    /// too the stiffness at rest is used instead, slower to converge but
    /// always defined.
    fn factorise_at(&self, body: &Body, u: &[f64]) -> Result<(Stiffness, Factorised), SynthError> {
        let tangent = self.tangent_at(body, u)?;
        let what = "the neo-Hookean tangent";
        let analysis = &self.analysis;
        let factorised = Factorised::with_analysis(analysis, &tangent, what, Pivots::Positive)
            .or_else(|_| Factorised::with_analysis(analysis, &tangent, what, Pivots::AnySign));
        match factorised {
            Ok(f) => Ok((tangent, f)),
            Err(_) => {
                let rest = self.tangent_at(body, &vec![0.0; u.len()])?;
                let what = "the neo-Hookean stiffness at rest";
                let f = Factorised::with_analysis(analysis, &rest, what, Pivots::Positive)?;
                Ok((rest, f))
            }
        }
    }

    /// Solves $f_{int}(u) = f$ with held components at `prescribed` (zero
    /// when empty), starting from `start`.
    pub fn solve(
        &self,
        body: &Body,
        loads: &[f64],
        start: &[f64],
        prescribed: &[f64],
    ) -> Result<Vec<f64>, SynthError> {
        let mut u = start.to_vec();
        let jump: Vec<f64> = (0..u.len())
            .map(|dof| {
                if self.held[dof] {
                    prescribed.get(dof).copied().unwrap_or(0.0) - start[dof]
                } else {
                    0.0
                }
            })
            .collect();
        let mut guard = self.tangent.lock().expect("tangent lock");
        if jump.iter().any(|&j| j != 0.0) {
            // Carry the prescribed increment into the body with the tangent
            // at the start (a linear predictor): moving the held components
            // alone would shear the elements at their edge far into the
            // nonlinear range before the first iteration.
            let (tangent, factorised) = self.factorise_at(body, start)?;
            let predicted = factorised.solve_prescribed(&tangent, &jump);
            for (ui, di) in u.iter_mut().zip(&predicted) {
                *ui += di;
            }
            *guard = Some(factorised);
        }
        // The residual on the free components, and the force scale: the
        // largest external load or internal force (reactions included).
        let residual = |u: &[f64]| -> (Vec<f64>, f64, f64) {
            let internal = self.internal_forces(body, u);
            let mut scale = 0.0f64;
            let mut r: Vec<f64> = internal
                .iter()
                .zip(loads)
                .map(|(fi, fe)| {
                    scale = scale.max(fi.abs()).max(fe.abs());
                    fe - fi
                })
                .collect();
            for (dof, held) in self.held.iter().enumerate() {
                if *held {
                    r[dof] = 0.0;
                }
            }
            // NaN (an inverted element) must count as divergence, not vanish in a max.
            let norm = r.iter().fold(0.0f64, |m, v| {
                if v.is_nan() {
                    f64::INFINITY
                } else {
                    m.max(v.abs())
                }
            });
            (r, norm, scale)
        };
        let (mut r, mut norm, mut scale) = residual(&u);
        for iteration in 0..MAX_ITERATIONS {
            if norm <= RELATIVE_TOLERANCE * scale {
                return Ok(u);
            }
            if guard.is_none() {
                *guard = Some(self.factorise_at(body, &u)?.1);
            }
            let step = guard
                .as_ref()
                .expect("factorised above")
                .solve(&[&r])
                .pop()
                .expect("one solution");
            let mut length = 1.0;
            let (next, next_r, next_norm, next_scale) = loop {
                let trial: Vec<f64> = u.iter().zip(&step).map(|(a, b)| a + length * b).collect();
                let (tr, tn, ts) = residual(&trial);
                if tn.is_finite() && (tn < norm || length < 1e-3) {
                    break (trial, tr, tn, ts);
                }
                if length < 1e-3 {
                    return Err(SynthError::NoConvergence {
                        what: "the neo-Hookean phantom (inverted elements)".into(),
                        residual: norm,
                        iterations: iteration,
                    });
                }
                length *= 0.5;
            };
            // A slowly falling residual means the stored tangent is stale.
            if next_norm > 0.1 * norm || iteration % 10 == 9 {
                *guard = None;
            }
            u = next;
            r = next_r;
            norm = next_norm;
            scale = next_scale;
        }
        if norm <= RELATIVE_TOLERANCE * scale {
            return Ok(u);
        }
        Err(SynthError::NoConvergence {
            what: "the neo-Hookean phantom".into(),
            residual: norm,
            iterations: MAX_ITERATIONS,
        })
    }
}

/// Inverse (row-major `inv[i][j]`) and determinant of a 3x3 matrix.
fn inverse_and_det(m: &[[f64; 3]; 3]) -> ([[f64; 3]; 3], f64) {
    let c = |r: usize, k: usize| {
        let (r1, r2) = ((r + 1) % 3, (r + 2) % 3);
        let (k1, k2) = ((k + 1) % 3, (k + 2) % 3);
        m[r1][k1] * m[r2][k2] - m[r1][k2] * m[r2][k1]
    };
    let det = m[0][0] * c(0, 0) + m[0][1] * c(0, 1) + m[0][2] * c(0, 2);
    let mut inv = [[0.0; 3]; 3];
    for r in 0..3 {
        for k in 0..3 {
            inv[k][r] = c(r, k) / det;
        }
    }
    (inv, det)
}
