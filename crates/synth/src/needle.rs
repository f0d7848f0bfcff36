//! Needle insertions: the shaft load at the material points that lie on
//! the needle, solved consistently with the displacement it causes.
//!
//! The needle is rigid and straight; its tip is at $(x_l, y_t)$ in space
//! (the mid-plane), pushed along +y. The tissue it holds is the material
//! line whose deformed image is the needle: a shaft point at spatial
//! position $p$ carries the load at the material point $X$ with
//! $X + u(X) = p$. The inserted shaft runs from the spatial entry point
//! (where the deformed front face crosses the needle: $y_e = u_y(X_e)$ with
//! $X_e = (x_e, 0)$ and $x_e + u_x(X_e) = x_l$) to the tip. Since $u$
//! depends on where the load acts, each state is a fixed-point iteration:
//! place the loads at $X^k$, solve $u^k$, move the points to
//! $X^{k+1} = p - u^k(X^{k+1})$ (itself a fixed point, solved by
//! Newton's method), until no material point moves by more than
//! [`CONSISTENCY_TOLERANCE`]; the field that places the next loads is
//! mixed with the previous one (a secant step, see `Mixing`), which
//! removes the slowest mode of the plain substitution. The tip's material
//! point comes out of the same relation.
//!
//! States are solved on a uniform grid of tip depths; the first guess of
//! each is the displacement extrapolated linearly from the two previous
//! states, so that one or two solves usually suffice. All trials advance
//! together: those whose days share a factorisation (see [`World`]) are
//! solved as one back-substitution with several right-hand sides, and the
//! placements of the trials are computed in parallel.

use rayon::prelude::*;

use crate::body::{Body, invert3};
use crate::error::SynthError;
use crate::scenario::NeedlePlan;
use crate::shaft::ShaftLoad;
use crate::world::{Response, World, solve_each};

/// Largest allowed move of a loaded material point between the last two
/// iterations of a state (m): 0.1 µm, far below any marker noise.
pub const CONSISTENCY_TOLERANCE: f64 = 1e-7;

/// Iterations of the consistency loop before giving up.
const MAX_CONSISTENCY_ITERATIONS: usize = 60;

/// The solved states of one insertion, on the grid of tip depths.
#[derive(Debug, Clone)]
pub(crate) struct NeedleRun {
    /// The trial.
    pub plan: NeedlePlan,
    /// Its shaft force distribution.
    pub load: ShaftLoad,
    /// Tip depth (spatial y) of each state (m).
    pub depths: Vec<f64>,
    /// Marker displacements (x, y, z) of each state (m); z is zero in
    /// the plane-strain truth.
    pub markers: Vec<Vec<[f64; 3]>>,
    /// Spatial y of the entry point of each state (m).
    pub entry: Vec<f64>,
    /// Force at the base, the integral of the shaft load (N).
    pub force: Vec<f64>,
    /// Material point of the tip at the last state.
    pub tip_material: [f64; 3],
    /// Displacement field of the last state.
    pub last_displacement: Vec<f64>,
    /// Linear solves (or Newton solves) done.
    pub solves: usize,
}

/// One trial while it is being advanced.
struct Advance {
    run: NeedleRun,
    previous: Vec<Vec<f64>>,
}

/// Simulates the insertions `trials`, each a plan and the response of the
/// phantom on its day, to `depth` in states `step` apart.
pub(crate) fn insert(
    world: &World,
    trials: &[(NeedlePlan, &Response)],
    depth: f64,
    step: f64,
) -> Result<Vec<NeedleRun>, SynthError> {
    let responses: Vec<&Response> = trials.iter().map(|t| t.1).collect();
    let body = &world.body;
    let dofs = body.dof_count();
    let states = (depth / step).ceil().max(1.0) as usize;
    let shaft_step = world.scenario.resolution.shaft_step;
    let mut trials: Vec<Advance> = trials
        .iter()
        .map(|(plan, _)| {
            let load = ShaftLoad::of(world.scenario, plan);
            let mut run = NeedleRun {
                plan: *plan,
                load,
                depths: vec![0.0],
                markers: vec![vec![[0.0; 3]; world.markers.len()]],
                entry: vec![0.0],
                force: vec![0.0],
                tip_material: [plan.line, 0.0, 0.0],
                last_displacement: vec![0.0; dofs],
                solves: 0,
            };
            run.depths.reserve(states);
            Advance {
                run,
                previous: vec![vec![0.0; dofs]],
            }
        })
        .collect();
    for k in 1..=states {
        let tip = depth * k as f64 / states as f64;
        // Guesses: the displacement extrapolated from the last two states.
        let mut guesses: Vec<Vec<f64>> = trials
            .iter()
            .map(|t| match t.previous.as_slice() {
                [.., a, b] => a.iter().zip(b).map(|(a, b)| 2.0 * b - a).collect(),
                [.., b] => b.clone(),
                [] => vec![0.0; dofs],
            })
            .collect();
        let mut placed: Vec<Placement> = trials
            .par_iter()
            .zip(&guesses)
            .map(|(t, u)| place(body, &t.run, tip, u, shaft_step))
            .collect();
        let mut done = vec![false; trials.len()];
        let mut mixing: Vec<Mixing> = trials.iter().map(|_| Mixing::default()).collect();
        let mut solutions: Vec<Vec<f64>> = vec![Vec::new(); trials.len()];
        let mut largest_move = f64::INFINITY;
        for iteration in 0.. {
            let active: Vec<usize> = (0..trials.len()).filter(|&i| !done[i]).collect();
            if active.is_empty() {
                break;
            }
            if iteration == MAX_CONSISTENCY_ITERATIONS {
                return Err(SynthError::NoConvergence {
                    what: format!("the needle tip consistency iteration at depth {tip} m"),
                    residual: largest_move,
                    iterations: iteration,
                });
            }
            let loads: Vec<Vec<f64>> = active
                .par_iter()
                .map(|&i| placed[i].loads(body, dofs))
                .collect();
            let jobs: Vec<(&Response, &[f64], &[f64])> = active
                .iter()
                .zip(&loads)
                .map(|(&i, f)| (responses[i], f.as_slice(), guesses[i].as_slice()))
                .collect();
            let solved = solve_each(body, &jobs)?;
            let nexts: Vec<Placement> = active
                .par_iter()
                .zip(&solved)
                .map(|(&i, u)| place(body, &trials[i].run, tip, u, shaft_step))
                .collect();
            largest_move = 0.0;
            let mut moving = Vec::new();
            for ((&i, u), next) in active.iter().zip(solved).zip(nexts) {
                trials[i].run.solves += 1;
                let moved = next.moved_from(&placed[i]);
                largest_move = largest_move.max(moved);
                if moved < CONSISTENCY_TOLERANCE {
                    // Keep the placement that was applied, so that u
                    // answers exactly the recorded load.
                    done[i] = true;
                    solutions[i] = u;
                } else {
                    let applied = std::mem::take(&mut guesses[i]);
                    guesses[i] = mixing[i].next(applied, u);
                    moving.push(i);
                }
            }
            let replaced: Vec<Placement> = moving
                .par_iter()
                .map(|&i| place(body, &trials[i].run, tip, &guesses[i], shaft_step))
                .collect();
            for (&i, p) in moving.iter().zip(replaced) {
                placed[i] = p;
            }
        }
        for ((t, u), p) in trials.iter_mut().zip(solutions).zip(&placed) {
            t.run.depths.push(tip);
            t.run.markers.push(world.marker_displacements(&u));
            t.run.entry.push(p.entry);
            t.run.force.push(p.force());
            if k == states {
                t.run.tip_material = material_point(body, [t.run.plan.line, tip, 0.0], &u);
                t.run.last_displacement = u.clone();
            }
            if t.previous.len() == 2 {
                t.previous.remove(0);
            }
            t.previous.push(u);
        }
    }
    Ok(trials.into_iter().map(|t| t.run).collect())
}

/// Anderson mixing of depth one for the consistency iteration of one state
/// (a secant step): the map $T(v) = K^{-1} f(\mathrm{place}(v))$ from the
/// field that places the loads to the field they cause has its fixed point
/// at the consistent state. Plain substitution $v_{k+1} = T(v_k)$ contracts
/// by about the strain along the needle per step; with the residuals
/// $r_k = T(v_k) - v_k$, the next field
/// $$v_{k+1} = T(v_k) - \gamma\,(T(v_k) - T(v_{k-1})),\qquad
/// \gamma = \frac{r_k\cdot(r_k - r_{k-1})}{\lVert r_k - r_{k-1}\rVert^2},$$
/// removes the slowest mode. It only chooses where the loads go next: a
/// state is accepted, as without mixing, when the placement of its solution
/// differs from the applied one by less than [`CONSISTENCY_TOLERANCE`].
#[derive(Default)]
struct Mixing {
    /// $(T(v_{k-1}), r_{k-1})$.
    last: Option<(Vec<f64>, Vec<f64>)>,
}

impl Mixing {
    /// The next field to place the loads with, after `applied` ($v_k$)
    /// gave `solved` ($T(v_k)$).
    fn next(&mut self, applied: Vec<f64>, solved: Vec<f64>) -> Vec<f64> {
        let residual: Vec<f64> = solved.iter().zip(&applied).map(|(t, v)| t - v).collect();
        let mut next = solved.clone();
        if let Some((last_solved, last_residual)) = &self.last {
            let (mut num, mut den) = (0.0, 0.0);
            for (r, q) in residual.iter().zip(last_residual) {
                num += r * (r - q);
                den += (r - q) * (r - q);
            }
            if den > 0.0 {
                let gamma = num / den;
                for (n, l) in next.iter_mut().zip(last_solved) {
                    *n -= gamma * (*n - l);
                }
            }
        }
        self.last = Some((solved, residual));
        next
    }
}

/// The loaded material points of one state for one displacement field.
struct Placement {
    entry: f64,
    points: Vec<([f64; 3], f64)>,
}

impl Placement {
    fn force(&self) -> f64 {
        self.points.iter().map(|p| p.1).sum()
    }

    fn loads(&self, body: &Body, dofs: usize) -> Vec<f64> {
        let mut f = vec![0.0; dofs];
        for &(x, force) in &self.points {
            let at = body
                .locate(x)
                .expect("material points are kept inside the body");
            body.add_point_force(&at, [0.0, force, 0.0], &mut f);
        }
        f
    }

    /// Largest move of a material point (or of the entry) between two
    /// placements of the same state.
    fn moved_from(&self, other: &Placement) -> f64 {
        self.points
            .iter()
            .zip(&other.points)
            .map(|(a, b)| (0..3).map(|c| (a.0[c] - b.0[c]).abs()).fold(0.0, f64::max))
            .fold((self.entry - other.entry).abs(), f64::max)
    }
}

/// Where the shaft load of `run` acts at tip depth `tip` if the phantom
/// is displaced by `u`.
fn place(body: &Body, run: &NeedleRun, tip: f64, u: &[f64], shaft_step: f64) -> Placement {
    let line = run.plan.line;
    let mut x_entry = [line, 0.0, 0.0];
    for _ in 0..50 {
        clamp_inside(body, &mut x_entry);
        let (d, gradient) = body
            .value_and_gradient(x_entry, u)
            .expect("the entry lies on the front face");
        let step = (x_entry[0] + d[0] - line) / (1.0 + gradient[0][0]);
        x_entry[0] -= step;
        if step.abs() < 1e-13 {
            break;
        }
    }
    let entry = displacement(body, x_entry, u)[1];
    let segments = (tip / shaft_step).ceil().max(1.0) as usize;
    let points = run
        .load
        .points(entry, tip, segments)
        .into_iter()
        .map(|p| (material_point(body, [line, p.y, 0.0], u), p.force))
        .collect();
    Placement { entry, points }
}

/// The material point $X$ with $X + u(X) = p$, by Newton's method on
/// $X + u(X) - p = 0$ with the Jacobian $I + \nabla u$ (substitution
/// alone converges too slowly, or not at all, where the displacement
/// gradient ahead of the tip approaches -1). Only x and y are solved: the
/// needle's material line stays in the mid-plane by the slab's symmetry
/// (the mesh's small asymmetry would otherwise make z hop between the
/// elements above and below the loaded plane).
fn material_point(body: &Body, p: [f64; 3], u: &[f64]) -> [f64; 3] {
    let mut x = p;
    for _ in 0..50 {
        clamp_inside(body, &mut x);
        let (d, mut jacobian) = body
            .value_and_gradient(x, u)
            .expect("points are clamped into the body");
        let r = [x[0] + d[0] - p[0], x[1] + d[1] - p[1], 0.0];
        jacobian[2] = [0.0; 3];
        for k in 0..3 {
            jacobian[k][2] = 0.0;
            jacobian[k][k] += 1.0;
        }
        let inverse = invert3(&jacobian);
        let step: Vec<f64> = (0..3)
            .map(|i| (0..3).map(|j| inverse[i][j] * r[j]).sum())
            .collect();
        for c in 0..3 {
            x[c] -= step[c];
        }
        if step.iter().fold(0.0f64, |m, s| m.max(s.abs())) < 1e-13 {
            break;
        }
    }
    clamp_inside(body, &mut x);
    x
}

/// The displacement at a point of the body.
fn displacement(body: &Body, x: [f64; 3], u: &[f64]) -> [f64; 3] {
    let mut inside = x;
    clamp_inside(body, &mut inside);
    let at = body
        .locate(inside)
        .expect("points are clamped into the body");
    body.value(&at, u)
}

/// Moves a point onto the body if it lies (by rounding) just outside.
fn clamp_inside(body: &Body, x: &mut [f64; 3]) {
    let (lo, hi) = body.bounds();
    for c in 0..3 {
        x[c] = x[c].clamp(lo[c], hi[c]);
    }
}
