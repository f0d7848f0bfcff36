//! Frictionless contact with a rigid probe whose edges are rounded.
//!
//! A flat punch with sharp edges, its contact nodes held, makes the strain
//! singular at its edges. In a linear material that singularity is
//! integrable and grading resolves it; in the neo-Hookean truth, a punch
//! pressed as deep as it is wide crushes the elements at its corners, the
//! free surface beside it folds into the punch, and finer meshes stop
//! solving before they converge (`docs/truth-world.md`, "The neo-Hookean
//! truth's mesh"). A real blunt probe has rounded edges, and the surface
//! that wraps round them touches the probe instead of passing through it.
//!
//! **The probe.** In the plane of the front face (x along it, y into the
//! phantom) the probe at depth $\delta$ occupies the half-strip
//! $|x - x_p| \le a$, $y \le \delta$ with its two lower corners rounded to
//! radius $r$; it spans the thickness, so z plays no part. With
//! $q = (|x - x_p| - (a - r),\; y - (\delta - r))$ its signed penetration
//! (positive inside, minus the distance outside) is
//! $$g(p) = \begin{cases} r - |q| & q_x > 0,\ q_y > 0 \text{ (the rounded edge)}\\
//! r - q_x & q_x > 0 \ge q_y \text{ (a side)}\\
//! r - q_y & q_y > 0 \ge q_x \text{ (the face)}\\
//! r + \min(-q_x, -q_y) & \text{otherwise (deep inside)} \end{cases}$$
//! at the current position $p = X + u$ of a node.
//!
//! **The contact.** Every candidate node $n$ (every node of the front
//! face) carries the penalty energy
//! $$\Pi_n = \tfrac{k_n}{2}\, \langle g(p_n) \rangle_+^2,$$
//! at its current position $p_n = X_n + u_n$, on the probe's exact
//! surface: its force $t_n \nabla g$, $t_n = k_n \langle g \rangle_+$,
//! joins the internal forces, and its Hessian
//! $$k_n \nabla g\, \nabla g^T + t_n \nabla^2 g, \qquad
//! \nabla^2 g = -\kappa\, (I - \nabla g\, \nabla g^T)$$
//! ($\kappa$ the surface's curvature, $1/|q|$ on an edge and zero
//! elsewhere) joins the tangent. The curvature term keeps the step on
//! the curve for a node sliding round an edge (without it, a full step
//! along the edge's tangent leaves the node a distance $\kappa s^2/2$
//! inside the probe, which the stiff penalty turns into a large force);
//! it is negative, and where a node has gone deep inside the probe it can
//! make the tangent indefinite, so the solver may leave it out
//! ([`Curvature`]).
//!
//! **A Newton step.** The energy is only once differentiable: a node's
//! stiffness jumps from nothing to $k_n$ as it touches the probe. A step
//! computed with the nodes pressed where it starts would push a node
//! about to touch deep into the probe (and hold one about to leave), so
//! the step's set of pressed nodes is revised by each node's linearised
//! penetration $g + \nabla g \cdot d$ until it no longer changes
//! ([`Contact::revise`]; a node the set adds carries the linear model's
//! force $k_n (g + \nabla g \cdot d)$, [`Contact::set_correction`]). A
//! node entering round an edge then lands on the plane tangent where it
//! stood, outside the curve by its second-order miss, with no force, and
//! the next step would miss again: the step is solved once more with
//! each entering node aimed that much further in ([`Contact::misses`], a
//! second-order correction). The solver chooses each step's length
//! along the energy, not by the largest residual, which the penalty makes
//! jump (`effect::material_nonlinearity`).
//!
//! **The penalty's error.** At equilibrium a pressed node is inside the
//! probe by $t_n / k_n$. With $k_n$ [`PENALTY_FACTOR`] times the node's
//! own diagonal stiffness at rest, that is $10^{-3}$ of the displacement
//! the node's force would make alone. A stiffer penalty is no more
//! accurate where it matters and harder to solve: against $10^5$ (the
//! file's first probe with 1 mm edges at refinement 2, 4 mm deep) no
//! marker moved by more than 0.01 um and the force agreed to 1 uN, while
//! the solve took 122 s instead of 747 s. The stiffer a node's penalty,
//! the more its force jumps when a step carries it a few nanometres in or
//! out, and the more often a depth step stalls and is halved
//! (`docs/truth-world.md`, session 47).

use crate::low_rank::Blocks;

/// A node's penalty, in units of its own diagonal stiffness at rest.
pub(crate) const PENALTY_FACTOR: f64 = 1e3;

/// Whether a contact's tangent carries the curved surface's term.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Curvature {
    /// The exact Hessian of the penalty energy.
    Included,
    /// Without $t_n \nabla^2 g$: positive semi-definite.
    Left,
}

/// The rigid probe at one depth.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Punch {
    /// Centre of the face along x (m).
    pub centre: f64,
    /// Half the width along x (m).
    pub half_width: f64,
    /// Radius of the rounded edges (m), above zero and at most
    /// `half_width`.
    pub edge_radius: f64,
    /// How far the face has moved into the phantom along +y (m).
    pub depth: f64,
}

/// The nodes a tangent presses and the state it was evaluated at.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Pressed<'a> {
    /// The displacements.
    pub at: &'a [f64],
    /// Per candidate node, whether it carries its penalty block.
    pub set: &'a [bool],
}

/// The signed penetration of a point and its gradient.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Penetration {
    /// Positive inside the probe, minus the distance outside (m).
    pub depth: f64,
    /// $\nabla g$ with respect to (x, y): minus the outward normal of the
    /// nearest surface.
    pub gradient: [f64; 2],
    /// Curvature of the nearest surface (1/m): zero but on an edge.
    pub curvature: f64,
}

impl Punch {
    /// The penetration of the point `p` = (x, y).
    pub fn penetration_of(&self, p: [f64; 2]) -> Penetration {
        self.penetration(p[0], p[1])
    }

    /// The penetration of the point (x, y) in the plane of the front face.
    pub fn penetration(&self, x: f64, y: f64) -> Penetration {
        let side = if x >= self.centre { 1.0 } else { -1.0 };
        let r = self.edge_radius;
        let qx = (x - self.centre).abs() - (self.half_width - r);
        let qy = y - (self.depth - r);
        let on_side = Penetration {
            depth: r - qx,
            gradient: [-side, 0.0],
            curvature: 0.0,
        };
        let on_face = Penetration {
            depth: r - qy,
            gradient: [0.0, -1.0],
            curvature: 0.0,
        };
        if qx > 0.0 && qy > 0.0 {
            let length = qx.hypot(qy);
            Penetration {
                depth: r - length,
                gradient: [-side * qx / length, -qy / length],
                curvature: 1.0 / length,
            }
        } else if qx > 0.0 {
            on_side
        } else if qy > 0.0 || qy > qx {
            on_face
        } else {
            on_side
        }
    }
}

/// The contact of a probe with the candidate nodes of a body.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Contact {
    /// The probe's position.
    pub punch: Punch,
    /// Candidate nodes.
    pub nodes: Vec<usize>,
    /// $k_n$ per node (N/m).
    pub penalties: Vec<f64>,
}

impl Contact {
    /// The current (x, y) of candidate `k`.
    fn position(&self, k: usize, nodes: &[[f64; 3]], dim: usize, u: &[f64]) -> [f64; 2] {
        let n = self.nodes[k];
        [nodes[n][0] + u[n * dim], nodes[n][1] + u[n * dim + 1]]
    }

    /// Candidate `k`'s force magnitude $t_n$ at `p`, and its penetration.
    fn pressure(&self, k: usize, p: [f64; 2]) -> (f64, Penetration) {
        let at = self.punch.penetration(p[0], p[1]);
        (self.penalties[k] * at.depth.max(0.0), at)
    }

    /// Adds `magnitude(k, g)` times $\nabla g$ of each candidate `k` at `u`
    /// to its node's components of `f`.
    fn add_along_gradients(
        &self,
        nodes: &[[f64; 3]],
        dim: usize,
        u: &[f64],
        f: &mut [f64],
        magnitude: impl Fn(usize, &Penetration) -> f64,
    ) {
        for (k, &n) in self.nodes.iter().enumerate() {
            let at = self.punch.penetration_of(self.position(k, nodes, dim, u));
            let m = magnitude(k, &at);
            for i in 0..2 {
                f[n * dim + i] += m * at.gradient[i];
            }
        }
    }

    /// Adds the contact's internal forces $t_n \nabla g$ at `u` to `f`.
    pub fn add_forces(&self, nodes: &[[f64; 3]], dim: usize, u: &[f64], f: &mut [f64]) {
        self.add_along_gradients(nodes, dim, u, f, |k, at| {
            self.penalties[k] * at.depth.max(0.0)
        });
    }

    /// The change of the residual $f - f_{int}$ at `u` when the probe moves
    /// on by `advance` along +y, to first order: a node inside the probe
    /// goes deeper by $-\partial_y g\, \Delta$, so its force
    /// $t_n \nabla g$ grows by $-k_n\, \partial_y g\, \Delta\, \nabla g$.
    /// It drives the linear predictor of a depth step (`NeoHookean::press`):
    /// evaluated at the new depth instead, the nodes near an edge would be
    /// inside the probe past its edge's centre, nearest to its side, and
    /// pushed out sideways.
    pub fn advance_residual(
        &self,
        nodes: &[[f64; 3]],
        dim: usize,
        u: &[f64],
        advance: f64,
    ) -> Vec<f64> {
        let mut r = vec![0.0; u.len()];
        self.add_along_gradients(nodes, dim, u, &mut r, |k, at| {
            if at.depth >= 0.0 {
                self.penalties[k] * at.gradient[1] * advance
            } else {
                0.0
            }
        });
        r
    }

    /// The nodes inside the probe or on its surface at `u`.
    pub fn touching(&self, nodes: &[[f64; 3]], dim: usize, u: &[f64]) -> Vec<bool> {
        (0..self.nodes.len())
            .map(|k| {
                let p = self.position(k, nodes, dim, u);
                self.punch.penetration_of(p).depth >= 0.0
            })
            .collect()
    }

    /// Candidate `k`'s tangent block at `u` in the x-y plane, as if it
    /// were pressed: $k_n \nabla g\, \nabla g^T - t_n \kappa\, (I -
    /// \nabla g\, \nabla g^T)$, the curvature term as asked.
    fn block(
        &self,
        k: usize,
        nodes: &[[f64; 3]],
        dim: usize,
        u: &[f64],
        curvature: Curvature,
    ) -> [[f64; 2]; 2] {
        let (t, at) = self.pressure(k, self.position(k, nodes, dim, u));
        let (g, kappa) = (at.gradient, at.curvature);
        let bent = match curvature {
            Curvature::Included => t * kappa,
            Curvature::Left => 0.0,
        };
        let mut b = [[0.0; 2]; 2];
        for (i, row) in b.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                let identity = if i == j { 1.0 } else { 0.0 };
                *v = self.penalties[k] * g[i] * g[j] - bent * (identity - g[i] * g[j]);
            }
        }
        b
    }

    /// The contact's tangent blocks at `u` for the nodes of `set`, node by
    /// node, each `dim` x `dim` row-major (zero outside x-y and for a node
    /// outside the set). The curvature term needs a node pressed.
    pub fn tangent_blocks(
        &self,
        nodes: &[[f64; 3]],
        dim: usize,
        u: &[f64],
        curvature: Curvature,
        set: &[bool],
        values: &mut Vec<f64>,
    ) {
        for (k, &inside) in set.iter().enumerate() {
            let b = inside.then(|| self.block(k, nodes, dim, u, curvature));
            for i in 0..dim {
                for j in 0..dim {
                    values.push(match b {
                        Some(b) if i < 2 && j < 2 => b[i][j],
                        _ => 0.0,
                    });
                }
            }
        }
    }

    /// How the contact's part of a tangent changes from `factored` to
    /// `now`: each node whose block differs (it joins or leaves the set,
    /// or it is pressed in both on a curved edge, where its block turns
    /// with it) adds its block at `now` and takes back its block at
    /// `factored` (`low_rank`). Components `held` are left out, as the
    /// factorisation leaves them.
    pub fn set_change(
        &self,
        nodes: &[[f64; 3]],
        dim: usize,
        curvature: Curvature,
        factored: Pressed<'_>,
        now: Pressed<'_>,
        held: &[bool],
    ) -> Blocks {
        let mut change = Blocks::none();
        let block = |k: usize, pressed: Pressed<'_>| {
            pressed.set[k].then(|| self.block(k, nodes, dim, pressed.at, curvature))
        };
        for (k, &n) in self.nodes.iter().enumerate() {
            let (before, after) = (block(k, factored), block(k, now));
            if before == after {
                continue;
            }
            let (before, after) = (before.unwrap_or_default(), after.unwrap_or_default());
            let free: Vec<usize> = (0..2).filter(|&i| !held[n * dim + i]).collect();
            change
                .dofs
                .push(free.iter().map(|&i| n * dim + i).collect());
            change.values.push(
                free.iter()
                    .flat_map(|&i| free.iter().map(move |&j| after[i][j] - before[i][j]))
                    .collect(),
            );
        }
        change
    }

    /// What turns the residual at `u` into that of the linear model in
    /// which the nodes of `set`, and only they, carry the penalty force
    /// $k_n (g + \nabla g \cdot d)$ of their linearised penetration: the
    /// force $-k_n g \nabla g$ of a node in the set but outside the probe,
    /// and back the force of a node inside it but out of the set.
    ///
    /// `misses` (per node, or empty) shift an entering node's linearised
    /// penetration by what the last step's second-order terms added to it
    /// (`NeoHookean::contact_step`).
    pub fn set_correction(
        &self,
        nodes: &[[f64; 3]],
        dim: usize,
        u: &[f64],
        set: &[bool],
        misses: &[f64],
    ) -> Vec<f64> {
        let mut r = vec![0.0; u.len()];
        self.add_along_gradients(nodes, dim, u, &mut r, |k, at| {
            let miss = misses.get(k).copied().unwrap_or(0.0);
            match (set[k], at.depth >= 0.0) {
                (true, false) => -self.penalties[k] * (at.depth + miss),
                (false, true) => self.penalties[k] * at.depth,
                _ => 0.0,
            }
        });
        r
    }

    /// What the step `d` from `u` adds to each node's penetration beyond
    /// its linearisation, $g(u + d) - g(u) - \nabla g \cdot d$, for the
    /// nodes of `set` outside the probe at `u` (zero for the others).
    pub fn misses(
        &self,
        nodes: &[[f64; 3]],
        dim: usize,
        u: &[f64],
        d: &[f64],
        set: &[bool],
    ) -> Vec<f64> {
        (0..self.nodes.len())
            .map(|k| {
                let p = self.position(k, nodes, dim, u);
                let at = self.punch.penetration_of(p);
                if !set[k] || at.depth >= 0.0 {
                    return 0.0;
                }
                let n = self.nodes[k];
                let step = [d[n * dim], d[n * dim + 1]];
                let after = self.punch.penetration_of([p[0] + step[0], p[1] + step[1]]);
                after.depth - at.depth - at.gradient[0] * step[0] - at.gradient[1] * step[1]
            })
            .collect()
    }

    /// Revises `set` after the step `d` from `u` by the linearised
    /// penetration $g + \nabla g \cdot d$: a node in the set that it
    /// would leave outside the probe leaves, one out of it that it would
    /// put inside joins. Returns whether the set changed.
    pub fn revise(
        &self,
        nodes: &[[f64; 3]],
        dim: usize,
        u: &[f64],
        d: &[f64],
        set: &mut [bool],
    ) -> bool {
        let mut changed = false;
        for (k, &n) in self.nodes.iter().enumerate() {
            let at = self.punch.penetration_of(self.position(k, nodes, dim, u));
            let after = at.depth + at.gradient[0] * d[n * dim] + at.gradient[1] * d[n * dim + 1];
            let inside = after >= 0.0;
            if inside != set[k] {
                set[k] = inside;
                changed = true;
            }
        }
        changed
    }

    /// The force the probe applies, `[along +x, along +y]`, and its moment
    /// about z at the centre of its face, from the contact forces at `u`
    /// (per copy of the body). The x part comes from the rounded edges and
    /// sides: where the face slides under the probe, the edge it slides
    /// towards pushes it back, a force a flat frictionless punch cannot
    /// make.
    pub fn resultant(&self, nodes: &[[f64; 3]], dim: usize, u: &[f64]) -> ([f64; 2], f64) {
        let (mut force, mut moment) = ([0.0; 2], 0.0);
        for k in 0..self.nodes.len() {
            let p = self.position(k, nodes, dim, u);
            let (t, at) = self.pressure(k, p);
            let applied = [-t * at.gradient[0], -t * at.gradient[1]];
            force[0] += applied[0];
            force[1] += applied[1];
            moment +=
                (p[0] - self.punch.centre) * applied[1] - (p[1] - self.punch.depth) * applied[0];
        }
        (force, moment)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn punch() -> Punch {
        Punch {
            centre: 0.03,
            half_width: 0.002,
            edge_radius: 0.0005,
            depth: 0.001,
        }
    }

    #[test]
    fn penetration_is_the_signed_distance_to_each_part_of_the_probe() {
        let p = punch();
        // Under the face, beside a side, off a rounded edge, and outside.
        let face = p.penetration(0.0302, 0.0007);
        assert!((face.depth - 0.0003).abs() < 1e-15);
        assert_eq!(face.gradient, [0.0, -1.0]);
        let side = p.penetration(0.0319, -0.001);
        assert!((side.depth - 0.0001).abs() < 1e-15);
        assert_eq!(side.gradient, [-1.0, 0.0]);
        let left = p.penetration(0.0281, -0.001);
        assert!((left.depth - 0.0001).abs() < 1e-15);
        assert_eq!(left.gradient, [1.0, 0.0]);
        // The edge's centre is at (x_p + a - r, delta - r); 45 degrees
        // down and out from it, 0.6 mm away: 0.1 mm outside.
        let d = 0.0006 / 2f64.sqrt();
        let edge = p.penetration(0.0315 + d, 0.0005 + d);
        assert!((edge.depth + 0.0001).abs() < 1e-15);
        let h = 1.0 / 2f64.sqrt();
        assert!((edge.gradient[0] + h).abs() < 1e-12 && (edge.gradient[1] + h).abs() < 1e-12);
        // Deep inside, the nearer of the face and the side.
        let deep = p.penetration(0.0318, -0.003);
        assert!((deep.depth - 0.0002).abs() < 1e-15);
    }

    proptest! {
        /// The gradient is the derivative of the penetration wherever it
        /// is smooth (away from the borders between the probe's parts).
        #[test]
        fn the_gradient_is_the_derivative_of_the_penetration(
            x in 0.026f64..0.034,
            y in -0.002f64..0.0014,
        ) {
            let p = punch();
            let qx = (x - p.centre).abs() - (p.half_width - p.edge_radius);
            let qy = y - (p.depth - p.edge_radius);
            prop_assume!(qx.abs() > 1e-7 && qy.abs() > 1e-7 && (qx - qy).abs() > 1e-7);
            prop_assume!((x - p.centre).abs() > 1e-7);
            let at = p.penetration(x, y);
            let h = 1e-9;
            let slopes = [
                (p.penetration(x + h, y).depth - p.penetration(x - h, y).depth) / (2.0 * h),
                (p.penetration(x, y + h).depth - p.penetration(x, y - h).depth) / (2.0 * h),
            ];
            for i in 0..2 {
                prop_assert!((slopes[i] - at.gradient[i]).abs() < 1e-5, "{slopes:?} {at:?}");
            }
            // A unit gradient: the penetration is a distance.
            prop_assert!((at.gradient[0].hypot(at.gradient[1]) - 1.0).abs() < 1e-12);
        }
    }

    /// Three nodes in the plane of a 3-D body: one under the face, one
    /// beside the rounded edge, one clear of the probe.
    fn three_nodes() -> ([[f64; 3]; 3], Contact) {
        let nodes = [[0.0302, 0.0, 0.0], [0.0318, 0.0, 0.0], [0.0400, 0.0, 0.0]];
        let contact = Contact {
            punch: punch(),
            nodes: vec![0, 1, 2],
            penalties: vec![2e4, 3e4, 4e4],
        };
        (nodes, contact)
    }

    #[test]
    fn a_node_inside_is_pushed_out_along_the_normal_and_one_clear_is_not_touched() {
        let (nodes, contact) = three_nodes();
        let dim = 3;
        // Node 0 0.3 mm inside the face; node 1 0.1 mm inside the rounded
        // edge, 45 degrees round it; node 2 clear.
        let mut u = vec![0.0; 9];
        u[1] = 0.0007;
        let c = 1.0 / 2f64.sqrt();
        let edge = [0.0315 + 0.0004 * c, 0.0005 + 0.0004 * c];
        u[3] = edge[0] - nodes[1][0];
        u[4] = edge[1];
        let mut f = vec![0.0; 9];
        contact.add_forces(&nodes, dim, &u, &mut f);
        // Internal forces are minus the probe's push.
        assert!(f[0].abs() < 1e-15 && (f[1] + 2e4 * 0.0003).abs() < 1e-12);
        assert!((f[3] + 3e4 * 0.0001 * c).abs() < 1e-12);
        assert!((f[4] + 3e4 * 0.0001 * c).abs() < 1e-12);
        assert_eq!(&f[6..], &[0.0; 3]);
        // The resultant is the pushes' sum, the edge's push sideways too,
        // and their moment about the face's centre.
        let (force, moment) = contact.resultant(&nodes, dim, &u);
        assert!((force[0] - 3.0 * c).abs() < 1e-12, "{force:?}");
        assert!((force[1] - (6.0 + 3.0 * c)).abs() < 1e-12, "{force:?}");
        let arms = [
            (0.0302 - 0.03, 0.0007 - 0.001),
            (edge[0] - 0.03, edge[1] - 0.001),
        ];
        let pushes = [(0.0, 6.0), (3.0 * c, 3.0 * c)];
        let expected: f64 = arms
            .iter()
            .zip(pushes)
            .map(|(a, p)| a.0 * p.1 - a.1 * p.0)
            .sum();
        assert!((moment - expected).abs() < 1e-15, "{moment} {expected}");
    }

    /// The forces' finite-difference derivative at `u`, block by block.
    fn force_slopes(contact: &Contact, nodes: &[[f64; 3]], u: &[f64]) -> Vec<f64> {
        let dim = 3;
        let h = 1e-9;
        let mut slopes = Vec::new();
        for n in 0..nodes.len() {
            let mut block = vec![0.0; dim * dim];
            for j in 0..dim {
                let mut forces = [vec![0.0; u.len()], vec![0.0; u.len()]];
                for (side, f) in [1.0, -1.0].into_iter().zip(forces.iter_mut()) {
                    let mut moved = u.to_vec();
                    moved[n * dim + j] += side * h;
                    contact.add_forces(nodes, dim, &moved, f);
                }
                for i in 0..dim {
                    block[i * dim + j] =
                        (forces[0][n * dim + i] - forces[1][n * dim + i]) / (2.0 * h);
                }
            }
            slopes.extend(block);
        }
        slopes
    }

    #[test]
    fn the_tangent_with_curvature_is_the_derivative_of_the_forces_and_without_it_is_not() {
        let (nodes, contact) = three_nodes();
        let mut u = vec![0.0; 9];
        u[1] = 0.0008;
        u[3] = 0.0001;
        u[4] = 0.0007;
        let slopes = force_slopes(&contact, &nodes, &u);
        let set = contact.touching(&nodes, 3, &u);
        assert_eq!(set, [true, true, false]);
        let mut exact = Vec::new();
        contact.tangent_blocks(&nodes, 3, &u, Curvature::Included, &set, &mut exact);
        for (k, (slope, block)) in slopes.iter().zip(&exact).enumerate() {
            assert!(
                (slope - block).abs() < 1e-5 * (1.0 + block.abs()),
                "entry {k}: {slope} against {block}"
            );
        }
        // Leaving the curvature out changes only the edge node's block,
        // by t kappa along the tangent of the edge.
        let mut left = Vec::new();
        contact.tangent_blocks(&nodes, 3, &u, Curvature::Left, &set, &mut left);
        let p = [0.0319, 0.0007];
        let at = contact.punch.penetration(p[0], p[1]);
        assert!(at.depth > 0.0 && at.curvature > 0.0);
        let bent = 3e4 * at.depth * at.curvature;
        let g = at.gradient;
        let tangent_direction = [-g[1], g[0]];
        let along = |blocks: &[f64]| -> f64 {
            (0..2)
                .flat_map(|i| (0..2).map(move |j| (i, j)))
                .map(|(i, j)| tangent_direction[i] * blocks[9 + i * 3 + j] * tangent_direction[j])
                .sum()
        };
        assert!(
            (along(&left) - along(&exact) - bent).abs() < 1e-9 * bent,
            "{bent}"
        );
        for k in (0..9).chain(18..27) {
            assert_eq!(left[k], exact[k]);
        }
    }

    #[test]
    fn the_set_follows_the_linearised_penetration_and_corrects_the_residual() {
        let (nodes, contact) = three_nodes();
        let dim = 3;
        // Node 0 0.3 mm inside the face; node 1 0.2 mm beside the probe's
        // side (x = 32 mm); node 2 clear.
        let mut u = vec![0.0; 9];
        u[1] = 0.0007;
        u[3] = 0.0004;
        let mut set = contact.touching(&nodes, dim, &u);
        assert_eq!(set, [true, false, false]);
        // A step moving node 0 0.4 mm on along +y, out of the probe, and
        // pushing node 1 onto the side and 0.1 mm past it.
        let mut d = vec![0.0; 9];
        d[1] = 0.0004;
        d[3] = -0.0003;
        assert!(contact.revise(&nodes, dim, &u, &d, &mut set));
        assert_eq!(set, [false, true, false]);
        assert!(!contact.revise(&nodes, dim, &u, &d, &mut set));
        // Node 0 leaves the set: its force is taken back; node 1 joins it
        // 0.2 mm outside: the linear model's force k g grad g draws it in
        // along -x.
        let correction = contact.set_correction(&nodes, dim, &u, &set, &[]);
        let mut forces = vec![0.0; 9];
        contact.add_forces(&nodes, dim, &u, &mut forces);
        assert!((correction[1] - forces[1]).abs() < 1e-15);
        assert!(
            (correction[3] + 3e4 * 0.0002).abs() < 1e-12,
            "{}",
            correction[3]
        );
        assert_eq!(correction[4], 0.0);
        // Moving the probe on by 0.1 mm pushes node 0 (on the face) along
        // +y by k times that; nodes clear of it feel nothing.
        let advance = contact.advance_residual(&nodes, dim, &u, 0.0001);
        assert!((advance[1] - 2e4 * 0.0001).abs() < 1e-12);
        assert!(advance[3..].iter().all(|&r| r == 0.0));
    }

    #[test]
    fn a_set_change_carries_one_tangents_contact_blocks_to_anothers() {
        let (nodes, contact) = three_nodes();
        let dim = 3;
        // Factored: node 0 on the face, node 1 round the edge, both
        // pressed. Now: node 0 pressed where it was, node 1 further round
        // the edge, node 2 (clear, nearest the probe's side) in the set;
        // node 2's y held.
        let at = |angle: f64| {
            let (s, co) = angle.sin_cos();
            [0.0315 + 0.0004 * co - nodes[1][0], 0.0005 + 0.0004 * s]
        };
        let mut factored_u = vec![0.0; 9];
        factored_u[1] = 0.0007;
        [factored_u[3], factored_u[4]] = at(std::f64::consts::FRAC_PI_4);
        let mut now_u = factored_u.clone();
        [now_u[3], now_u[4]] = at(1.0);
        assert!((now_u[3] - factored_u[3]).abs() > 1e-5);
        let factored_set = [true, true, false];
        let now_set = [true, true, true];
        let held: Vec<bool> = (0..9).map(|dof| dof == 7).collect();
        let change = contact.set_change(
            &nodes,
            dim,
            Curvature::Included,
            Pressed {
                at: &factored_u,
                set: &factored_set,
            },
            Pressed {
                at: &now_u,
                set: &now_set,
            },
            &held,
        );
        // Node 0's block is the same in both and is left out; node 2 has
        // its x component only.
        assert_eq!(change.dofs, vec![vec![3, 4], vec![6]]);
        let blocks = |u: &[f64], set: &[bool]| {
            let mut values = Vec::new();
            contact.tangent_blocks(&nodes, dim, u, Curvature::Included, set, &mut values);
            values
        };
        let mut carried = blocks(&factored_u, &factored_set);
        for (dofs, values) in change.dofs.iter().zip(&change.values) {
            for (i, &a) in dofs.iter().enumerate() {
                for (j, &b) in dofs.iter().enumerate() {
                    // Node n's block starts at n * dim * dim, row-major.
                    let (n, ri, rj) = (a / dim, a % dim, b % dim);
                    carried[n * dim * dim + ri * dim + rj] += values[i * dofs.len() + j];
                }
            }
        }
        let expected = blocks(&now_u, &now_set);
        for (k, (got, want)) in carried.iter().zip(&expected).enumerate() {
            assert!(
                (got - want).abs() <= 1e-9 * 4e4,
                "entry {k}: {got} against {want}"
            );
        }
        // Node 2, clear of the probe, joins with its penalty along the
        // side's normal and no curvature term.
        assert!((carried[18] - 4e4).abs() < 1e-9);
    }

    #[test]
    fn a_step_along_an_edge_misses_the_curve_by_half_its_curvature_times_its_square() {
        let nodes = [[0.0, 0.0, 0.0]];
        let contact = Contact {
            punch: punch(),
            nodes: vec![0],
            penalties: vec![1e4],
        };
        // 1 um outside the rounded edge at 45 degrees, then 10 um along
        // the edge's tangent.
        let (c, r) = ([0.0315, 0.0005], 0.0005);
        let h = 1.0 / 2f64.sqrt();
        let p = [c[0] + (r + 1e-6) * h, c[1] + (r + 1e-6) * h];
        let u = vec![p[0], p[1], 0.0];
        let s = 1e-5;
        let d = vec![-s * h, s * h, 0.0];
        let miss = contact.misses(&nodes, 3, &u, &d, &[true])[0];
        let expected = -s * s / (2.0 * (r + 1e-6));
        assert!(
            (miss / expected - 1.0).abs() < 1e-3,
            "{miss} against {expected}"
        );
        // Only entering nodes (in the set, outside) are corrected.
        assert_eq!(contact.misses(&nodes, 3, &u, &d, &[false]), [0.0]);
    }
}
