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
//! positive definite it is factorised as $L D L^T$, and where that fails
//! the stiffness at rest is used instead. A solve that stalls (no step
//! lowers the residual, or too many iterations) is retried along the load
//! path from its start in increments halved until they converge
//! (`NeoHookean::solve`). One that stalls even so is a typed
//! non-convergence error naming how far along the load it got and where
//! the phantom is most compressed: in a plane phantom that is typically a
//! corner of the clamped face, whose strain is singular, compressed past
//! the range where a neo-Hookean surface stays smooth
//! (`docs/truth-world.md`). At small strains the tangent equals the linear
//! stiffness, so the effect only shows at large strains.
//!
//! A probe with rounded edges (`ProbeTrial.edge_radius`) presses this
//! material in frictionless contact instead of holding the nodes under a
//! flat face: `NeoHookean::press`, with the penalty and the Newton step
//! of `contact`.

use std::sync::{Arc, Mutex};

use needle_fem::element::stiffness::{ReferenceGradients, physical_gradients};
use serde::{Deserialize, Serialize};

use super::{EffectId, TruthEffect};
use crate::body::{Body, inverse_and_det};
use crate::contact::{Contact, Curvature, PENALTY_FACTOR, Pressed, Punch};
use crate::error::SynthError;
use crate::low_rank::{Blocks, Compliances, Updated};
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
    /// Nodes a probe may touch (`contact`), and their diagonal stiffness
    /// at rest along y, which scales their penalties.
    contact_nodes: Vec<usize>,
    contact_stiffness: Vec<f64>,
    /// The tangent's pattern: the elements' entries in loop order, then
    /// the springs', then a block per contact node.
    layout: Layout,
    /// The analysis of the tangent's free block, shared by every
    /// refactorisation.
    analysis: Arc<Analysis>,
    /// The tangent last factorised, reused while it converges fast.
    tangent: Mutex<Option<Factorised>>,
}

/// Which tangent a factorisation holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Tangent {
    /// At the state asked for, a probe's curvature term as given.
    At(Curvature),
    /// The stiffness at rest, where the tangent could not be factorised.
    AtRest,
}

/// A factorised tangent kept for later Newton iterations under a probe:
/// the nodes it pressed and the state it was evaluated at.
struct Kept {
    factorised: Factorised,
    /// The entries of its inverse met by the changes applied to it.
    compliances: Compliances,
    tangent: Tangent,
    set: Vec<bool>,
    at: Vec<f64>,
}

/// Convergence: largest residual force below this fraction of the largest
/// force in the problem.
const RELATIVE_TOLERANCE: f64 = 1e-10;

/// Convergence under a probe in contact (`contact`): no Newton step
/// larger than this (m). The penalty's stiffness amplifies rounding in
/// the residual beyond `RELATIVE_TOLERANCE` of the forces, while a
/// picometre is far below anything measured.
const CONTACT_STEP_TOLERANCE: f64 = 1e-12;

/// Convergence of an intermediate state on the way to a load that Newton's
/// method could not reach at once: only a start for the next.
const INTERMEDIATE_TOLERANCE: f64 = 1e-6;

/// Maximum Newton iterations per attempt; a solve that converges does so
/// in at most 15 (the insertions of `docs/truth-world.md`'s soft phantom),
/// one slower is stalling and is better split.
const MAX_ITERATIONS: usize = 40;

/// The smallest fraction of the load an increment may be cut to.
const SMALLEST_INCREMENT: f64 = 1.0 / 4096.0;

impl NeoHookean {
    /// The material `(E, nu)` per region, springs, held components and the
    /// nodes a probe may touch.
    pub fn new(
        body: &Body,
        moduli: &[(f64, f64)],
        springs: &[(usize, usize, f64)],
        held: Vec<bool>,
        contact_nodes: &[usize],
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
        let dim = body.dim;
        for &n in contact_nodes {
            for i in 0..dim {
                positions.extend((0..dim).map(|j| (n * dim + i, n * dim + j)));
            }
        }
        let layout = Layout::new(body.dof_count(), &positions)?;
        let analysis = Arc::new(layout.analyse(&held, "the neo-Hookean tangent")?);
        let mut solver = Self {
            constants: moduli.iter().map(|&(e, nu)| lame(e, nu)).collect(),
            springs: springs.to_vec(),
            held,
            contact_nodes: contact_nodes.to_vec(),
            contact_stiffness: Vec::new(),
            layout,
            analysis,
            tangent: Mutex::new(None),
        };
        if !contact_nodes.is_empty() {
            let rest = solver.tangent_at(body, &vec![0.0; body.dof_count()], None)?;
            solver.contact_stiffness = contact_nodes
                .iter()
                .map(|&n| rest.diagonal(n * dim + 1))
                .collect();
        }
        Ok(solver)
    }

    /// The probe `punch` touching this solver's contact nodes, no node
    /// pressed yet.
    pub(crate) fn contact(&self, punch: Punch) -> Contact {
        let penalties = self
            .contact_stiffness
            .iter()
            .map(|k| PENALTY_FACTOR * k)
            .collect();
        Contact {
            punch,
            nodes: self.contact_nodes.clone(),
            penalties,
        }
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

    /// The tangent stiffness at `u`, springs and a probe's `contact`
    /// (with or without its curvature term) included.
    pub(crate) fn tangent_at(
        &self,
        body: &Body,
        u: &[f64],
        contact: Option<(&Contact, Curvature, &[bool])>,
    ) -> Result<Stiffness, SynthError> {
        let mut f = vec![0.0; u.len()];
        let mut values = Vec::with_capacity(self.layout.entry_count());
        self.element_loop(body, u, &mut f, Some(&mut values));
        values.extend(self.springs.iter().map(|&(_, _, v)| v));
        match contact {
            Some((c, curvature, set)) => {
                c.tangent_blocks(&body.nodes, body.dim, u, curvature, set, &mut values)
            }
            None => values.resize(self.layout.entry_count(), 0.0),
        }
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
    /// probe; a probe's curvature term where a node has gone deep inside
    /// it, `contact`): then it is factorised without the probe's curvature
    /// term, then as $L D L^T$, and only if that fails too the stiffness at
    /// rest is used instead, slower to converge but always defined.
    fn factorise_at(
        &self,
        body: &Body,
        u: &[f64],
        contact: Option<(&Contact, &[bool])>,
    ) -> Result<(Stiffness, Factorised, Tangent), SynthError> {
        let what = "the neo-Hookean tangent";
        let analysis = &self.analysis;
        let with = |curvature| contact.map(|(c, set)| (c, curvature, set));
        let exact = self.tangent_at(body, u, with(Curvature::Included))?;
        if let Ok(f) = Factorised::with_analysis(analysis, &exact, what, Pivots::Positive) {
            return Ok((exact, f, Tangent::At(Curvature::Included)));
        }
        if contact.is_some() {
            let plain = self.tangent_at(body, u, with(Curvature::Left))?;
            if let Ok(f) = Factorised::with_analysis(analysis, &plain, what, Pivots::Positive) {
                return Ok((plain, f, Tangent::At(Curvature::Left)));
            }
        }
        if let Ok(f) = Factorised::with_analysis(analysis, &exact, what, Pivots::AnySign) {
            return Ok((exact, f, Tangent::At(Curvature::Included)));
        }
        let rest = self.tangent_at(body, &vec![0.0; u.len()], with(Curvature::Left))?;
        let what = "the neo-Hookean stiffness at rest";
        let f = Factorised::with_analysis(analysis, &rest, what, Pivots::Positive)?;
        Ok((rest, f, Tangent::AtRest))
    }

    /// The linear predictor of a depth step: from `u`, in equilibrium with
    /// the probe of `contact`, one Newton step with the tangent there for
    /// the probe moved on by `advance` (`Contact::advance_residual`).
    fn predict(
        &self,
        body: &Body,
        u: &[f64],
        contact: &Contact,
        advance: f64,
    ) -> Result<Vec<f64>, SynthError> {
        let set = contact.touching(&body.nodes, body.dim, u);
        let (_, factorised, _) = self.factorise_at(body, u, Some((contact, &set)))?;
        let mut r = contact.advance_residual(&body.nodes, body.dim, u, advance);
        let mut internal = self.internal_forces(body, u);
        contact.add_forces(&body.nodes, body.dim, u, &mut internal);
        for ((ri, fi), held) in r.iter_mut().zip(&internal).zip(&self.held) {
            *ri = if *held { 0.0 } else { *ri - fi };
        }
        let step = factorised.solve(&[&r]).pop().expect("one solution");
        Ok(u.iter().zip(&step).map(|(a, b)| a + b).collect())
    }

    /// The Newton step at `u` (residual `r`) under the probe of `contact`:
    /// the linear model's set of pressed nodes revised by the step's
    /// linearised penetrations until it no longer changes
    /// (`Contact::revise`). A step taken with the set at `u` alone would
    /// push a node about to touch the probe deep into it, and one about to
    /// leave it would be held.
    ///
    /// The tangent factorised in `kept` (made here at `u` when there is
    /// none) serves every revision and may be an earlier iterate's: the
    /// contact blocks that differ from the ones it was factorised with
    /// (nodes joining or leaving the set, nodes turning round an edge) are
    /// applied at solve time (`low_rank`), so only the elastic part may be
    /// stale. A stiffness-at-rest fallback is refactorised for each
    /// revision instead and not kept.
    fn contact_step(
        &self,
        body: &Body,
        u: &[f64],
        r: &[f64],
        contact: &Contact,
        kept: &mut Option<Kept>,
    ) -> Result<Vec<f64>, SynthError> {
        let (nodes, dim) = (&body.nodes, body.dim);
        let mut set = contact.touching(nodes, dim, u);
        let load = |set: &[bool], misses: &[f64]| -> Vec<f64> {
            let correction = contact.set_correction(nodes, dim, u, set, misses);
            r.iter()
                .zip(&correction)
                .zip(&self.held)
                .map(|((a, b), &held)| if held { 0.0 } else { a + b })
                .collect()
        };
        let factorise = |set: &[bool]| -> Result<Kept, SynthError> {
            let (_, factorised, tangent) = self.factorise_at(body, u, Some((contact, set)))?;
            Ok(Kept {
                factorised,
                compliances: Compliances::default(),
                tangent,
                set: set.to_vec(),
                at: u.to_vec(),
            })
        };
        let mut current = match kept.take() {
            Some(k) => k,
            None => factorise(&set)?,
        };
        let mut revisions = 0;
        loop {
            let updated = match current.tangent {
                Tangent::At(curvature) => {
                    let factored = Pressed {
                        at: &current.at,
                        set: &current.set,
                    };
                    let now = Pressed { at: u, set: &set };
                    let change =
                        contact.set_change(nodes, dim, curvature, factored, now, &self.held);
                    Updated::new(&current.factorised, &mut current.compliances, &change)
                }
                Tangent::AtRest => Updated::new(
                    &current.factorised,
                    &mut current.compliances,
                    &Blocks::none(),
                ),
            };
            let mut step = updated.solve(&load(&set, &[]));
            revisions += 1;
            if revisions < MAX_SET_REVISIONS && contact.revise(nodes, dim, u, &step, &mut set) {
                if current.tangent == Tangent::AtRest {
                    drop(updated);
                    current = factorise(&set)?;
                }
                continue;
            }
            // A node entering the probe round its edge lands on the plane
            // tangent where it stood, outside the curve by its second-order
            // miss: aim it that much further in (a second-order correction,
            // with the same tangent).
            for _ in 0..SECOND_ORDER_CORRECTIONS {
                let misses = contact.misses(nodes, dim, u, &step, &set);
                if misses.iter().all(|&m| m == 0.0) {
                    break;
                }
                step = updated.solve(&load(&set, &misses));
            }
            drop(updated);
            if current.tangent != Tangent::AtRest {
                *kept = Some(current);
            }
            return Ok(step);
        }
    }

    /// Solves $f_{int}(u) = f$ with held components at `prescribed` (zero
    /// when empty), starting from `start`.
    ///
    /// Newton's method from `start` goes straight for the whole load when
    /// it can. Where it stalls (a concentrated load moved on by a step
    /// strains a few elements far, and the tangent along the way turns
    /// indefinite), the load is reached along the straight path
    /// $f(\lambda) = (1 - \lambda) f_{int}(u_0) + \lambda f$, $u_0$ = `start`
    /// (the held components likewise from their values in `start`), which
    /// `start` satisfies exactly at $\lambda = 0$: the increment of
    /// $\lambda$ is halved after a stall and doubled after a success, each
    /// intermediate state solved to [`INTERMEDIATE_TOLERANCE`].
    pub fn solve(
        &self,
        body: &Body,
        loads: &[f64],
        start: &[f64],
        prescribed: &[f64],
    ) -> Result<Vec<f64>, SynthError> {
        let held_value = |dof: usize| prescribed.get(dof).copied().unwrap_or(0.0);
        let mut guard = self.tangent.lock().expect("tangent lock");
        // Only needed once the whole load has failed.
        let mut at_start: Option<Vec<f64>> = None;
        let mut reached = start.to_vec();
        let mut done = 0.0;
        let mut increment = 1.0f64;
        loop {
            let to = (done + increment).min(1.0);
            let last = to == 1.0;
            let target: Vec<f64> = match &at_start {
                None => loads.to_vec(),
                Some(base) => base
                    .iter()
                    .zip(loads)
                    .map(|(b, f)| b + to * (f - b))
                    .collect(),
            };
            // The whole load holds the prescribed values exactly.
            let held: Vec<f64> = (0..start.len())
                .map(|dof| {
                    if last {
                        held_value(dof)
                    } else {
                        start[dof] + to * (held_value(dof) - start[dof])
                    }
                })
                .collect();
            let tolerance = if last {
                RELATIVE_TOLERANCE
            } else {
                INTERMEDIATE_TOLERANCE
            };
            match self.newton(body, &mut guard, &reached, &target, &held, tolerance, None) {
                Ok(u) if last => return Ok(u),
                Ok(u) => {
                    reached = u;
                    done = to;
                    increment = (2.0 * increment).min(1.0 - done);
                }
                Err(stalled) => {
                    increment *= 0.5;
                    if increment < SMALLEST_INCREMENT {
                        let (stretch, at) = self.most_compressed(body, &reached);
                        return Err(SynthError::NoConvergence {
                            what: format!(
                                "the neo-Hookean phantom (stalled at {done:.4} of the load; \
                                 most compressed at x = {:.2} mm, y = {:.2} mm, z = {:.2} mm, \
                                 least principal stretch {stretch:.3})",
                                1e3 * at[0],
                                1e3 * at[1],
                                1e3 * at[2],
                            ),
                            residual: stalled.residual,
                            iterations: stalled.iterations,
                        });
                    }
                    if at_start.is_none() {
                        let base = self.internal_forces(body, start);
                        if base.iter().any(|v| !v.is_finite()) {
                            return Err(SynthError::NoConvergence {
                                what: "the neo-Hookean phantom (inverted elements at the start)"
                                    .into(),
                                residual: stalled.residual,
                                iterations: stalled.iterations,
                            });
                        }
                        at_start = Some(base);
                    }
                    // The stored tangent belongs to the failed attempt.
                    *guard = None;
                }
            }
        }
    }

    /// Presses the probe of `contact` from `from` (the state with the probe
    /// at `from_depth`) to its depth, no other load applied. Each depth
    /// step starts from a linear predictor (`predict`), the nodes pressed
    /// at the last depth carried on with the probe: evaluated at the new
    /// depth instead, the nodes near an edge would start inside the probe
    /// past its edge's centre and be pushed out sideways. Newton's method
    /// on the penalty energy (`contact`) then converges from there, its
    /// steps' lengths chosen along the energy (`along_the_energy`); the
    /// depth step is halved after a stall and doubled after a success.
    pub(crate) fn press(
        &self,
        body: &Body,
        from: &[f64],
        from_depth: f64,
        contact: &mut Contact,
    ) -> Result<Vec<f64>, SynthError> {
        let target = contact.punch.depth;
        let loads = vec![0.0; from.len()];
        let mut reached = (from.to_vec(), from_depth);
        let mut increment = target - from_depth;
        loop {
            let depth = (reached.1 + increment).min(target);
            contact.punch.depth = reached.1;
            let start = self.predict(body, &reached.0, contact, depth - reached.1)?;
            contact.punch.depth = depth;
            let outcome = self.newton(
                body,
                &mut None,
                &start,
                &loads,
                &start,
                RELATIVE_TOLERANCE,
                Some(contact),
            );
            match outcome {
                Ok(u) if depth == target => return Ok(u),
                Ok(u) => {
                    reached = (u, depth);
                    increment = (2.0 * increment).min(target - depth);
                }
                Err(stalled) => {
                    increment *= 0.5;
                    if increment < SMALLEST_INCREMENT * (target - from_depth) {
                        let (stretch, at) = self.most_compressed(body, &reached.0);
                        return Err(SynthError::NoConvergence {
                            what: format!(
                                "the neo-Hookean phantom under the probe (stalled at {:.4} mm \
                                 of {:.4} mm; most compressed at x = {:.2} mm, y = {:.2} mm, \
                                 z = {:.2} mm, least principal stretch {stretch:.3})",
                                1e3 * reached.1,
                                1e3 * target,
                                1e3 * at[0],
                                1e3 * at[1],
                                1e3 * at[2],
                            ),
                            residual: stalled.residual,
                            iterations: stalled.iterations,
                        });
                    }
                }
            }
        }
    }

    /// The least principal stretch over every element's quadrature points
    /// at `u`, and the centroid of its element (rest coordinates): where a
    /// solve that stalls has gone furthest into compression.
    pub(crate) fn most_compressed(&self, body: &Body, u: &[f64]) -> (f64, [f64; 3]) {
        match body.dim {
            2 => most_compressed_kind::<2, 6>(body, u),
            _ => most_compressed_kind::<3, 10>(body, u),
        }
    }

    /// Newton's method for $f_{int}(u) = f$ (`loads`) from `from`, with the
    /// held components moved to `held`: converged when the largest residual
    /// is below `tolerance` times the force scale, stalled when a step
    /// halved ten times lowers no residual or after
    /// [`MAX_ITERATIONS`] iterations. Under a probe's `contact` its forces
    /// join the internal ones, each step is `contact_step`'s with its
    /// length chosen along the energy (`along_the_energy`; `stored` is
    /// not used), and a step no larger than [`CONTACT_STEP_TOLERANCE`]
    /// also counts as converged. There the tangent is refactorised only
    /// when the longest step has not halved since the last iteration, or
    /// when a kept tangent's step finds no lower energy: while steps
    /// halve, what is left of the error is below the last step.
    fn newton(
        &self,
        body: &Body,
        stored: &mut Option<Factorised>,
        from: &[f64],
        loads: &[f64],
        held: &[f64],
        tolerance: f64,
        contact: Option<&Contact>,
    ) -> Result<Vec<f64>, Stalled> {
        let mut u = from.to_vec();
        let jump: Vec<f64> = (0..u.len())
            .map(|dof| {
                if self.held[dof] {
                    held[dof] - from[dof]
                } else {
                    0.0
                }
            })
            .collect();
        if jump.iter().any(|&j| j != 0.0) {
            // Carry the prescribed increment into the body with the tangent
            // at the start (a linear predictor): moving the held components
            // alone would shear the elements at their edge far into the
            // nonlinear range before the first iteration.
            let stall = |_| Stalled {
                residual: f64::INFINITY,
                iterations: 0,
            };
            let (tangent, factorised, _) = self.factorise_at(body, from, None).map_err(stall)?;
            let predicted = factorised.solve_prescribed(&tangent, &jump);
            for (ui, di) in u.iter_mut().zip(&predicted) {
                *ui += di;
            }
            *stored = Some(factorised);
        }
        // The residual on the free components, and the force scale: the
        // largest external load or internal force (reactions included).
        let residual = |u: &[f64]| -> (Vec<f64>, f64, f64) {
            let mut internal = self.internal_forces(body, u);
            let mut scale = 0.0f64;
            for (fi, fe) in internal.iter().zip(loads) {
                scale = scale.max(fi.abs()).max(fe.abs());
            }
            // The scale is the elastic forces': at a node on the probe they
            // and the contact's cancel.
            if let Some(c) = contact {
                c.add_forces(&body.nodes, body.dim, u, &mut internal);
            }
            let mut r: Vec<f64> = internal.iter().zip(loads).map(|(fi, fe)| fe - fi).collect();
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
        let mut kept: Option<Kept> = None;
        let mut last_longest = f64::INFINITY;
        for iteration in 0..MAX_ITERATIONS {
            if norm <= tolerance * scale {
                return Ok(u);
            }
            let stalled = Stalled {
                residual: norm,
                iterations: iteration,
            };
            if !norm.is_finite() {
                return Err(stalled);
            }
            let step = match contact {
                Some(c) => self
                    .contact_step(body, &u, &r, c, &mut kept)
                    .map_err(|_| stalled)?,
                None => {
                    if stored.is_none() {
                        *stored = Some(self.factorise_at(body, &u, None).map_err(|_| stalled)?.1);
                    }
                    stored
                        .as_ref()
                        .expect("factorised above")
                        .solve(&[&r])
                        .pop()
                        .expect("one solution")
                }
            };
            if contact.is_some() && step.iter().all(|d| d.abs() <= CONTACT_STEP_TOLERANCE) {
                return Ok(u);
            }
            let found = match contact {
                None => backtrack(&u, &step, norm, &residual),
                Some(_) => along_the_energy(&u, &step, &r, &residual),
            };
            let longest = step.iter().fold(0.0f64, |m, d| m.max(d.abs()));
            let kept_was_fresh = kept.as_ref().is_some_and(|k| k.at == u);
            let Some((next, next_r, next_norm, next_scale)) = found else {
                if contact.is_some() && kept.is_some() && !kept_was_fresh {
                    // An earlier tangent's step: retry with the tangent here.
                    kept = None;
                    continue;
                }
                return Err(stalled);
            };
            // Under a probe, a kept tangent serves while the steps at
            // least halve; past that it is stale.
            if longest > 0.5 * last_longest {
                kept = None;
            }
            last_longest = longest;
            // A slowly falling residual means the stored tangent is stale.
            if next_norm > 0.1 * norm || iteration % 10 == 9 {
                *stored = None;
            }
            u = next;
            r = next_r;
            norm = next_norm;
            scale = next_scale;
        }
        if norm <= tolerance * scale {
            return Ok(u);
        }
        Err(Stalled {
            residual: norm,
            iterations: MAX_ITERATIONS,
        })
    }
}

/// A trial state: displacements, residual, its largest component and
/// the force scale.
type Trial = (Vec<f64>, Vec<f64>, f64, f64);

/// The residual at a state, its largest component and the force scale.
type Residual<'a> = dyn Fn(&[f64]) -> (Vec<f64>, f64, f64) + 'a;

/// The first of the steps `u + step`, `u + step / 2`, ... down to a
/// thousandth whose largest residual is below `norm`.
fn backtrack(u: &[f64], step: &[f64], norm: f64, residual: &Residual<'_>) -> Option<Trial> {
    let mut length = 1.0;
    while length >= 1e-3 {
        let trial: Vec<f64> = u.iter().zip(step).map(|(a, b)| a + length * b).collect();
        let (r, n, scale) = residual(&trial);
        if n < norm {
            return Some((trial, r, n, scale));
        }
        length *= 0.5;
    }
    None
}

/// The step `u + s step` near the minimum of the energy along `step`
/// (`r` the residual at `u`): the energy's slope along the step is
/// $\phi'(s) = -r(u + s\,\text{step}) \cdot \text{step}$, and $s$ is
/// accepted once $|\phi'(s)| \le \tfrac12 |\phi'(0)|$, or at $s = 1$ if
/// the energy still falls there; otherwise the minimum is bracketed and
/// found by safeguarded secant steps. A probe's penalty energy is only
/// once differentiable: a full step that pushes a node far into the
/// probe raises the largest residual by orders of magnitude though the
/// energy fell most of the way, so halving the step until the largest
/// residual falls would stall.
fn along_the_energy(u: &[f64], step: &[f64], r: &[f64], residual: &Residual<'_>) -> Option<Trial> {
    let slope = |r: &[f64]| -> f64 { -r.iter().zip(step).map(|(a, b)| a * b).sum::<f64>() };
    let start = slope(r);
    if start.is_nan() || start >= 0.0 {
        return None;
    }
    let (mut low, mut low_slope) = (0.0, start);
    let mut high: Option<(f64, f64, Trial)> = None;
    let mut length: f64 = 1.0;
    for _ in 0..60 {
        let trial: Vec<f64> = u.iter().zip(step).map(|(a, b)| a + length * b).collect();
        let (tr, tn, scale) = residual(&trial);
        let s = if tn.is_finite() {
            slope(&tr)
        } else {
            f64::INFINITY
        };
        if s.abs() <= 0.5 * start.abs() || (length == 1.0 && s < 0.0) {
            return Some((trial, tr, tn, scale));
        }
        if s > 0.0 {
            high = Some((length, s, (trial, tr, tn, scale)));
        } else {
            (low, low_slope) = (length, s);
        }
        let (top, top_slope, _) = high.as_ref()?;
        let (top, top_slope) = (*top, *top_slope);
        if top - low < KINK_LENGTH && top_slope.is_finite() {
            // The step turns at a kink: a node about to touch the probe
            // (or leave it). Stop just past it, where the next tangent
            // carries that node's penalty.
            return high.map(|(_, _, trial)| trial);
        }
        let secant = if top_slope.is_finite() {
            low - low_slope * (top - low) / (top_slope - low_slope)
        } else {
            0.5 * (low + top)
        };
        let margin = 0.1 * (top - low);
        length = secant.clamp(low + margin, top - margin);
    }
    None
}

/// Revisions of the set of pressed nodes in one Newton step under a
/// probe (`NeoHookean::contact_step`); past them the last set is used.
const MAX_SET_REVISIONS: usize = 8;

/// Second-order corrections of a Newton step under a probe
/// (`NeoHookean::contact_step`).
const SECOND_ORDER_CORRECTIONS: usize = 2;

/// The length of a bracket on a Newton step below which its minimum is
/// taken to be at a kink of the penalty energy (`along_the_energy`).
const KINK_LENGTH: f64 = 1e-6;

/// A Newton solve that stopped short: its last residual and iterations.
#[derive(Debug, Clone, Copy)]
struct Stalled {
    residual: f64,
    iterations: usize,
}

fn most_compressed_kind<const D: usize, const N: usize>(body: &Body, u: &[f64]) -> (f64, [f64; 3]) {
    let reference = ReferenceGradients::<D, N>::for_degree(2);
    let mut least = (f64::INFINITY, 0);
    for e in 0..body.element_count() {
        let nodes = body.element(e);
        let coordinates = nalgebra::SMatrix::<f64, D, N>::from_fn(|i, a| body.nodes[nodes[a]][i]);
        for (grad_ref, _) in &reference.points {
            let (grad, _) = physical_gradients(&coordinates, grad_ref);
            let mut f = nalgebra::DMatrix::<f64>::identity(D, D);
            for a in 0..N {
                for i in 0..D {
                    for j in 0..D {
                        f[(i, j)] += u[nodes[a] * D + i] * grad[(j, a)];
                    }
                }
            }
            // Principal stretches: square roots of the eigenvalues of F^T F.
            let stretch = (f.transpose() * &f)
                .symmetric_eigenvalues()
                .min()
                .max(0.0)
                .sqrt();
            if stretch < least.0 {
                least = (stretch, e);
            }
        }
    }
    let nodes = body.element(least.1);
    let mut centroid = [0.0; 3];
    for &n in nodes {
        for (c, x) in centroid.iter_mut().zip(body.nodes[n]) {
            *c += x / nodes.len() as f64;
        }
    }
    (least.0, centroid)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::effect::Effects;
    use crate::scenario::Scenario;
    use crate::world::World;

    /// The quick scenario's plane phantom, coarse, neo-Hookean.
    fn small_neo_hookean() -> Scenario {
        let mut s = Scenario::quick();
        s.phantom.markers = (6, 6);
        s.resolution.refinement = 1;
        s.effects = Effects::none();
        s.effects.material_nonlinearity = Some(MaterialNonlinearity);
        s
    }

    /// The node nearest the phantom's centre.
    fn central_node(s: &Scenario, body: &Body) -> usize {
        let centre = [s.phantom.width / 2.0, s.phantom.depth / 2.0];
        let distance =
            |n: usize| (body.nodes[n][0] - centre[0]).hypot(body.nodes[n][1] - centre[1]);
        (0..body.nodes.len())
            .min_by(|&a, &b| distance(a).total_cmp(&distance(b)))
            .unwrap()
    }

    /// $u_y = -a y^2 / (2D)$ compresses along y by the stretch $1 - a y / D$,
    /// least at the back face $y = D$.
    #[test]
    fn the_most_compressed_element_is_where_a_manufactured_field_compresses_most() {
        let s = small_neo_hookean();
        let world = World::new(&s).unwrap();
        let body = &world.body;
        let (a, depth) = (0.4, s.phantom.depth);
        let mut u = vec![0.0; body.dof_count()];
        for (n, x) in body.nodes.iter().enumerate() {
            u[n * body.dim + 1] = -a * x[1] * x[1] / (2.0 * depth);
        }
        let solver = world.neo_hookean(1.0, &[], &[]).unwrap();
        let (stretch, at) = solver.most_compressed(body, &u);
        let h = body.element_size;
        assert!(
            stretch > 1.0 - a && stretch < 1.0 - a * (depth - h) / depth,
            "least stretch {stretch}"
        );
        assert!(depth - at[1] < h, "found at y = {} of {depth}", at[1]);
    }

    /// A load beyond what the phantom can carry is a typed error that says
    /// how far along the load the solve got and where it is most
    /// compressed.
    #[test]
    fn a_stalled_solve_names_where_the_phantom_is_most_compressed() {
        let s = small_neo_hookean();
        let world = World::new(&s).unwrap();
        let body = &world.body;
        let solver = world.neo_hookean(1.0, &[], &[]).unwrap();
        let mut loads = vec![0.0; body.dof_count()];
        loads[central_node(&s, body) * body.dim + 1] = 25.6;
        let rest = vec![0.0; body.dof_count()];
        match solver.solve(body, &loads, &rest, &[]) {
            Err(SynthError::NoConvergence { what, .. }) => {
                assert!(
                    what.contains("of the load") && what.contains("least principal stretch"),
                    "{what}"
                );
                // Beside the loaded node, which is crushed against the
                // clamped back face.
                let millimetres = |key: &str| -> f64 {
                    let rest = &what[what.find(key).unwrap() + key.len()..];
                    rest[..rest.find(" mm").unwrap()].parse().unwrap()
                };
                let at = [millimetres("x = ") * 1e-3, millimetres("y = ") * 1e-3];
                let node = body.nodes[central_node(&s, body)];
                let distance = (at[0] - node[0]).hypot(at[1] - node[1]);
                assert!(distance < body.element_size, "{what}");
            }
            other => panic!("expected a stall, got {:?}", other.map(|_| ())),
        }
    }

    /// A point load of 10 N at the centre of the small neo-Hookean phantom
    /// (75 x 75 mm, E = 25.3 kPa), towards the free front face: far beyond
    /// any experiment (the point moves 67 mm), chosen because Newton's
    /// method from rest stalls on it. `solve` must reach it along the load
    /// path, to the solution that 16 equal load steps, each solved from
    /// the last, arrive at.
    #[test]
    fn a_load_newton_cannot_reach_at_once_is_reached_along_its_path() {
        let s = small_neo_hookean();
        let world = World::new(&s).unwrap();
        let body = &world.body;
        let solver = world.neo_hookean(1.0, &[], &[]).unwrap();
        let node = central_node(&s, body);
        let dofs = body.dof_count();
        let mut loads = vec![0.0; dofs];
        loads[node * body.dim + 1] = -10.0;
        let rest = vec![0.0; dofs];

        let direct = solver.newton(
            body,
            &mut None,
            &rest,
            &loads,
            &rest,
            RELATIVE_TOLERANCE,
            None,
        );
        assert!(
            direct.is_err(),
            "Newton's method from rest reached the load"
        );

        let u = solver.solve(body, &loads, &rest, &[]).unwrap();
        let internal = solver.internal_forces(body, &u);
        let residual = (0..dofs)
            .filter(|&d| !world.fixed[d])
            .map(|d| (internal[d] - loads[d]).abs())
            .fold(0.0, f64::max);
        assert!(residual < 1e-9, "residual {residual} N");

        let steps = 16;
        let mut stepped = rest.clone();
        for k in 1..=steps {
            let part: Vec<f64> = loads.iter().map(|f| f * k as f64 / steps as f64).collect();
            stepped = solver
                .newton(
                    body,
                    &mut None,
                    &stepped,
                    &part,
                    &rest,
                    RELATIVE_TOLERANCE,
                    None,
                )
                .unwrap();
        }
        let largest = stepped.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let difference = u
            .iter()
            .zip(&stepped)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(
            largest > 0.05 && difference < 1e-9 * largest,
            "largest displacement {largest} m, the two paths differ by {difference} m"
        );
    }
}
