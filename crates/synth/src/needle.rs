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
//! States are solved on a grid of tip depths ([`depth_grid`]: every
//! `depth_step`, halved over the first [`ENTRY_DEPTH`]); the first guess
//! of each is the displacement extrapolated linearly from the two previous
//! states. The trials are independent and run in parallel. On a linear
//! phantom an iteration does not back-substitute: the load of one line
//! only reaches the dofs around it, and the kept columns of $K^{-1}$ for
//! those dofs (`line_response.rs`) give the field there and at the markers
//! exactly; a full solve is made only for the whole field of the last
//! state, or when a state leaves the band of kept rows.
//!
//! A needle of radius $a > 0$ (`Needles::radius`, 3-D slab only) drags
//! the tissue on its surface, not on its axis: $u(X)$ above is the mean
//! displacement over the `Rim`, points at angles
//! $\theta_k = (k + \tfrac12)\pi/n$ on the half circle of radius $a$
//! around the axis in the upper half's x-z plane (the lower half mirrors
//! them). The load stays on the axis: outside the needle an axial load
//! on its axis and the same load on its surface give the same shear,
//! $\tau = q/(2\pi r)$ for $r \ge a$, so they differ only inside the
//! needle, where there is no tissue. In 3-D a line load's displacement
//! grows as $\ln r$ towards the line, so a drag read on the axis, and the
//! markers near the needle, change with every refinement towards it, and
//! refined far enough the consistency iteration fails; read at $r = a$
//! they converge (`docs/truth-world.md`, The 3-D slab).

use rayon::prelude::*;

use crate::body::{Body, Location, invert3};
use crate::error::SynthError;
use crate::line_response::{LineResponse, Missing};
use crate::scenario::NeedlePlan;
use crate::shaft::ShaftLoad;
use crate::world::{Response, World};

/// Largest allowed move of a loaded material point between the last two
/// iterations of a state (m): 0.1 µm, far below any marker noise.
pub const CONSISTENCY_TOLERANCE: f64 = 1e-7;

/// Tip depth over which needle states are solved at half the depth step
/// (m). While the tip and its force peak are within a few millimetres of
/// the front face, the front row of markers is in their near field and the
/// marker displacements change on the scale of the peak's width (1.5 mm
/// in the paper default) rather than of the phantom: read by cubics from
/// states 1 mm apart they err by up to 1.4 um there, against 0.4 um
/// deeper; from states 0.5 mm apart by at most 0.12 um
/// (`docs/truth-world.md`, interpolation between states).
pub const ENTRY_DEPTH: f64 = 0.008;

/// The tip depths of the states of an insertion to `depth` (m): `depth`
/// split into `ceil(depth / step)` equal intervals, of which those that
/// start within [`ENTRY_DEPTH`] are halved. When the spacing divides
/// [`ENTRY_DEPTH`] (as the default 1 mm does), halving `step` gives a grid
/// whose even states are this one's, which is how the interpolation error
/// between states is measured.
pub fn depth_grid(depth: f64, step: f64) -> Vec<f64> {
    let intervals = (depth / step).ceil().max(1.0) as usize;
    let spacing = depth / intervals as f64;
    let halved = ((ENTRY_DEPTH / spacing - 1e-9).ceil() as usize).min(intervals);
    let mut grid = vec![0.0];
    for k in 0..intervals {
        let end = depth * (k + 1) as f64 / intervals as f64;
        if k < halved {
            grid.push(depth * (2 * k + 1) as f64 / (2 * intervals) as f64);
        }
        grid.push(end);
    }
    grid
}

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
    /// The shaft load of each state: its loaded material points and
    /// their forces along +y (N); none at the first state.
    pub loads: Vec<Vec<([f64; 3], f64)>>,
    /// Linear solves (or Newton solves) done: kept columns and full
    /// solves.
    pub solves: usize,
    /// Of those, solves of a whole load (the last state's field, states
    /// that left the band, every iteration of a nonlinear phantom).
    pub full_solves: usize,
}

/// How the states of one insertion are solved.
enum Solver<'a> {
    /// A linear phantom: the kept columns of its line, with the response
    /// for the states that leave their band.
    Columns(LineResponse, &'a Response),
    /// Every iteration a full solve (a nonlinear phantom, or on request).
    Full(&'a Response),
}

/// A solved field of one consistency iteration.
struct Solved {
    /// The displacement: exact on the band's elements at least.
    u: Vec<f64>,
    /// Marker displacements.
    markers: Vec<[f64; 3]>,
}

impl Solver<'_> {
    fn response(&self) -> &Response {
        match self {
            Solver::Columns(_, r) | Solver::Full(r) => r,
        }
    }

    /// Solves the load of `placed` (starting from `start` if nonlinear) and
    /// places the shaft again with the result; from the kept columns
    /// (adding the ones the load needs) when both the load and the new
    /// placement stay in the band, otherwise by a full solve, counted in
    /// `solves`.
    #[allow(clippy::too_many_arguments)]
    fn solve_and_place(
        &mut self,
        world: &World,
        rim: &Rim,
        run: &NeedleRun,
        tip: f64,
        placed: &Placement,
        start: &[f64],
        shaft_step: f64,
        solves: &mut usize,
    ) -> Result<(Solved, Placement), SynthError> {
        let body = &world.body;
        let f = placed.loads(body);
        if let Solver::Columns(line, response) = self {
            let mut answer = line.solve(&f);
            if let Err(Missing::Columns(dofs)) = &answer {
                line.add_columns(world, response, dofs)?;
                answer = line.solve(&f);
            }
            if let Ok((u, markers)) = answer {
                let next = place(body, rim, run, tip, &u, shaft_step);
                if next.elements().all(|e| line.covers(e)) {
                    return Ok((Solved { u, markers }, next));
                }
            }
        }
        *solves += 1;
        let u = self
            .response()
            .solve(body, &[f], &[start.to_vec()])?
            .pop()
            .expect("one load gives one solution");
        let next = place(body, rim, run, tip, &u, shaft_step);
        let markers = world.marker_displacements(&u);
        Ok((Solved { u, markers }, next))
    }
}

/// Simulates the insertions `trials`, each a plan and the response of the
/// phantom on its day, to `depth` in states `step` apart. The trials are
/// independent and run in parallel; a linear phantom's states are solved
/// from kept columns of $K^{-1}$ ([`LineResponse`]).
pub(crate) fn insert(
    world: &World,
    trials: &[(NeedlePlan, &Response)],
    depth: f64,
    step: f64,
) -> Result<Vec<NeedleRun>, SynthError> {
    // Rows on the elements within an element of the line: near the entry
    // the loaded points move up to about a millimetre sideways.
    let band = Band {
        margin: world.body.element_size,
        depth,
    };
    insert_with(world, trials, depth, step, Some(band))
}

/// The band of elements around a needle line whose rows are kept.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Band {
    /// How far beyond the line it reaches (m).
    pub margin: f64,
    /// Depth of the segment of the line it covers (m).
    pub depth: f64,
}

/// [`insert`] with the kept rows on `band`, or with a full solve in every
/// iteration when `band` is `None`.
pub(crate) fn insert_with(
    world: &World,
    trials: &[(NeedlePlan, &Response)],
    depth: f64,
    step: f64,
    band: Option<Band>,
) -> Result<Vec<NeedleRun>, SynthError> {
    trials
        .par_iter()
        .map(|&(plan, response)| {
            let line = match band {
                Some(b) => LineResponse::new(world, response, plan.line, b.depth, b.margin)?,
                None => None,
            };
            let solver = match line {
                Some(line) => Solver::Columns(line, response),
                None => Solver::Full(response),
            };
            insert_one(world, plan, solver, depth, step)
        })
        .collect()
}

/// One insertion, state by state.
fn insert_one(
    world: &World,
    plan: NeedlePlan,
    mut solver: Solver,
    depth: f64,
    step: f64,
) -> Result<NeedleRun, SynthError> {
    let body = &world.body;
    let rim = Rim::new(body, world.scenario.needles.radius);
    let dofs = body.dof_count();
    let depths = depth_grid(depth, step);
    let shaft_step = world.scenario.resolution.shaft_step;
    let mut run = NeedleRun {
        plan,
        load: ShaftLoad::of(world.scenario, &plan),
        depths: vec![0.0],
        markers: vec![vec![[0.0; 3]; world.markers.len()]],
        entry: vec![0.0],
        force: vec![0.0],
        tip_material: [plan.line, 0.0, 0.0],
        last_displacement: vec![0.0; dofs],
        loads: vec![Vec::new()],
        solves: 0,
        full_solves: 0,
    };
    let mut solves = 0;
    let mut previous: Vec<Vec<f64>> = vec![vec![0.0; dofs]];
    let last = depths.len() - 1;
    for (k, &tip) in depths.iter().enumerate().skip(1) {
        // The guess: the displacement extrapolated from the last two states.
        let guess: Vec<f64> = match previous.as_slice() {
            [.., a, b] => {
                let d = &run.depths[run.depths.len() - 2..];
                let ratio = (tip - d[1]) / (d[1] - d[0]);
                a.iter().zip(b).map(|(a, b)| b + ratio * (b - a)).collect()
            }
            [.., b] => b.clone(),
            [] => vec![0.0; dofs],
        };
        let mut state = StateIteration::from_guess(body, &rim, &run, tip, guess, shaft_step);
        let during = |e: SynthError| {
            e.during(|| format!("the needle on the line x = {} m at {tip} m deep", plan.line))
        };
        let solved = loop {
            let (solved, next) = solver
                .solve_and_place(
                    world,
                    &rim,
                    &run,
                    tip,
                    &state.placed,
                    &state.guess,
                    shaft_step,
                    &mut solves,
                )
                .map_err(during)?;
            if state
                .advance(body, &rim, &run, &solved.u, &next, shaft_step)
                .map_err(during)?
            {
                break solved;
            }
        };
        let placed = state.placed;
        run.depths.push(tip);
        run.markers.push(solved.markers);
        run.entry.push(placed.entry);
        run.force.push(placed.force());
        run.loads
            .push(placed.points.iter().map(|p| (p.0, p.1)).collect());
        if k == last {
            // The whole field of the last state, for strains and the tip.
            let u = match solver {
                Solver::Columns(..) => {
                    solves += 1;
                    solver
                        .response()
                        .solve(body, &[placed.loads(body)], &[])?
                        .pop()
                        .expect("one load gives one solution")
                }
                Solver::Full(_) => solved.u.clone(),
            };
            run.tip_material = material_point(body, &rim, [plan.line, tip, 0.0], &u);
            run.last_displacement = u;
        }
        if previous.len() == 2 {
            previous.remove(0);
        }
        previous.push(solved.u);
    }
    // Every kept column was one back-substitution.
    run.full_solves = solves;
    run.solves = solves
        + match &solver {
            Solver::Columns(line, _) => line.columns,
            Solver::Full(_) => 0,
        };
    Ok(run)
}

/// The consistency iteration of one state, solve by solve: the caller
/// solves the load of `placed` and hands the field and its placement to
/// [`StateIteration::advance`], until that accepts `placed`.
pub(crate) struct StateIteration {
    tip: f64,
    /// The field that placed the loads of `placed`; empty when they were
    /// placed otherwise (on another mesh of the slab).
    guess: Vec<f64>,
    /// The loads applied next.
    pub placed: Placement,
    mixing: Mixing,
    iterations: usize,
}

impl StateIteration {
    /// The iteration at tip depth `tip` from the loads placed by `guess`.
    pub fn from_guess(
        body: &Body,
        rim: &Rim,
        run: &NeedleRun,
        tip: f64,
        guess: Vec<f64>,
        shaft_step: f64,
    ) -> Self {
        let placed = place(body, rim, run, tip, &guess, shaft_step);
        Self {
            tip,
            guess,
            placed,
            mixing: Mixing::default(),
            iterations: 0,
        }
    }

    /// The iteration at tip depth `tip` from loads placed already.
    pub fn from_placement(tip: f64, placed: Placement) -> Self {
        Self {
            tip,
            guess: Vec::new(),
            placed,
            mixing: Mixing::default(),
            iterations: 0,
        }
    }

    /// Takes the field `u` that the load of `placed` caused, and `next`,
    /// the placement it gives: true when that differs from `placed` by
    /// less than [`CONSISTENCY_TOLERANCE`] (`placed` is then the state's),
    /// otherwise places the next loads by the mixed field.
    pub fn advance(
        &mut self,
        body: &Body,
        rim: &Rim,
        run: &NeedleRun,
        u: &[f64],
        next: &Placement,
        shaft_step: f64,
    ) -> Result<bool, SynthError> {
        self.iterations += 1;
        if let Some(y) = self.placed.lost.or(next.lost) {
            return Err(SynthError::NoConvergence {
                what: format!(
                    "finding the material point of the needle shaft at y = {y:e} m (a step \
                     that is not finite: the displacement or its gradient overflows, the \
                     phantom far too soft for its load) at tip depth {} m",
                    self.tip
                ),
                residual: f64::INFINITY,
                iterations: self.iterations,
            });
        }
        let largest_move = next.moved_from(&self.placed);
        if largest_move < CONSISTENCY_TOLERANCE {
            // Keep the placement that was applied, so that the field
            // answers exactly the recorded load.
            return Ok(true);
        }
        if self.iterations == MAX_CONSISTENCY_ITERATIONS {
            return Err(SynthError::NoConvergence {
                what: format!(
                    "the needle tip consistency iteration at depth {} m",
                    self.tip
                ),
                residual: largest_move,
                iterations: self.iterations,
            });
        }
        self.guess = if self.guess.is_empty() {
            u.to_vec()
        } else {
            self.mixing
                .next(std::mem::take(&mut self.guess), u.to_vec())
        };
        self.placed = place(body, rim, run, self.tip, &self.guess, shaft_step);
        Ok(false)
    }
}

/// Anderson mixing of depth one for the consistency iteration of one state
/// (a secant step): the map $T(v) = K^{-1} f(\mathrm{place}(v))$ from the
/// field that places the loads to the field they cause has its fixed point
/// at the consistent state. Plain substitution $v_{k+1} = T(v_k)$ contracts
/// by about the strain along the needle per step; with the residuals
/// $r_k = T(v_k) - v_k$, the next field
/// $$v_{k+1} = T(v_k) - \gamma\,(T(v_k) - T(v_{k-1})),\qquad
/// \gamma = \frac{r_k\cdot(r_k - r_{k-1})}{\lVert r_k - r_{k-1}\rVert^2},$$
/// removes the slowest mode. (From kept columns the fields are the band's
/// rows, zero elsewhere, so the products run over the band.) It only
/// chooses where the loads go next: a
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
pub(crate) struct Placement {
    /// Spatial y of the entry point (m).
    pub entry: f64,
    /// The loaded material points, their forces along +y (N) and where
    /// they lie in the mesh.
    pub points: Vec<([f64; 3], f64, Location)>,
    /// Every element the displacement was read in: the loaded points' and
    /// the entry's rims.
    read: Vec<usize>,
    /// Spatial y of the first shaft point (0 for the entry) whose material
    /// point could not be found, its loads left out: the state fails with
    /// a typed error ([`StateIteration::advance`]) rather than load a
    /// field that has overflowed.
    lost: Option<f64>,
}

impl Placement {
    /// The loads `points` (material points and forces along +y) of a state
    /// whose entry is at `entry`, placed on another mesh of the same slab,
    /// located on `body`.
    pub fn on(body: &Body, entry: f64, points: &[([f64; 3], f64)]) -> Self {
        let points: Vec<_> = points
            .iter()
            .map(|&(x, force)| {
                let at = body.locate(x).expect("the two meshes cover the same slab");
                (x, force, at)
            })
            .collect();
        let read = points.iter().map(|p| p.2.element).collect();
        Self {
            entry,
            points,
            read,
            lost: None,
        }
    }

    /// Force at the base, the integral of the shaft load (N).
    pub fn force(&self) -> f64 {
        self.points.iter().map(|p| p.1).sum()
    }

    /// The load vector of the points.
    pub fn loads(&self, body: &Body) -> Vec<f64> {
        let mut f = vec![0.0; body.dof_count()];
        for (_, force, at) in &self.points {
            body.add_point_force(at, [0.0, *force, 0.0], &mut f);
        }
        f
    }

    /// Every element the placement read the displacement in.
    fn elements(&self) -> impl Iterator<Item = usize> + '_ {
        self.read.iter().copied()
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
pub(crate) fn place(
    body: &Body,
    rim: &Rim,
    run: &NeedleRun,
    tip: f64,
    u: &[f64],
    shaft_step: f64,
) -> Placement {
    let line = run.plan.line;
    let Some((x_entry, entry)) = entry_point(body, rim, line, u) else {
        return Placement {
            entry: 0.0,
            points: Vec::new(),
            read: Vec::new(),
            lost: Some(0.0),
        };
    };
    let segments = (tip / shaft_step).ceil().max(1.0) as usize;
    let mut read = rim.elements(body, x_entry, None);
    let mut points = Vec::new();
    let mut lost = None;
    for p in run.load.points(entry, tip, segments) {
        let found = find_material_point(body, rim, [line, p.y, 0.0], u)
            .and_then(|x| Some((x, body.locate(x)?)));
        match found {
            Some((x, located)) => {
                read.extend(rim.elements(body, x, Some(&located)));
                points.push((x, p.force, located));
            }
            None => {
                lost.get_or_insert(p.y);
            }
        }
    }
    Placement {
        entry,
        points,
        read,
        lost,
    }
}

/// The material point $X_e$ of the entry on the front face, with
/// $x_e + u_x(X_e) = x_l$, and the spatial y of the entry, $u_y(X_e)$;
/// `None` if a Newton step or the entry is not finite.
fn entry_point(body: &Body, rim: &Rim, line: f64, u: &[f64]) -> Option<([f64; 3], f64)> {
    let mut x_entry = [line, 0.0, 0.0];
    for _ in 0..50 {
        clamp_inside(body, &mut x_entry);
        let (d, gradient) = rim.value_and_gradient(body, x_entry, u)?;
        let step = (x_entry[0] + d[0] - line) / (1.0 + gradient[0][0]);
        if !step.is_finite() {
            return None;
        }
        x_entry[0] -= step;
        if step.abs() < 1e-13 {
            break;
        }
    }
    clamp_inside(body, &mut x_entry);
    let entry = rim.value_and_gradient(body, x_entry, u)?.0[1];
    entry.is_finite().then_some((x_entry, entry))
}

/// The material point $X$ with $X + u(X) = p$ (see [`find_material_point`])
/// in the field of a state the consistency iteration accepted, whose
/// placement found every shaft point up to the tip.
pub(crate) fn material_point(body: &Body, rim: &Rim, p: [f64; 3], u: &[f64]) -> [f64; 3] {
    find_material_point(body, rim, p, u)
        .expect("an accepted state's field, which placed the shaft, places its tip")
}

/// The material point $X$ with $X + u(X) = p$, by Newton's method on
/// $X + u(X) - p = 0$ with the Jacobian $I + \nabla u$ (substitution
/// alone converges too slowly, or not at all, where the displacement
/// gradient ahead of the tip approaches -1). Only x and y are solved: the
/// needle's material line stays in the mid-plane by the slab's symmetry
/// (the mesh's small asymmetry would otherwise make z hop between the
/// elements above and below the loaded plane). `None` if a step is not
/// finite: a field, or its gradient, so large that $I + \nabla u$
/// overflows (a phantom far too soft for its load), which no point of the
/// body answers.
fn find_material_point(body: &Body, rim: &Rim, p: [f64; 3], u: &[f64]) -> Option<[f64; 3]> {
    let mut x = p;
    for _ in 0..50 {
        clamp_inside(body, &mut x);
        let (d, mut jacobian) = rim.value_and_gradient(body, x, u)?;
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
        if !step.iter().all(|s| s.is_finite()) {
            return None;
        }
        for c in 0..3 {
            x[c] -= step[c];
        }
        if step.iter().fold(0.0f64, |m, s| m.max(s.abs())) < 1e-13 {
            break;
        }
    }
    clamp_inside(body, &mut x);
    Some(x)
}

/// Points on the needle's surface per reading of the drag.
const RIM_POINTS: usize = 6;

/// Where on a needle of some radius around a point of its axis the drag
/// is read: offsets from the axis point, evenly weighted. A needle of
/// radius 0 (or any needle in the plane-strain truth) is its axis alone.
pub(crate) struct Rim {
    offsets: Vec<[f64; 3]>,
}

impl Rim {
    pub fn new(body: &Body, radius: f64) -> Self {
        if radius == 0.0 || body.dim == 2 {
            return Self {
                offsets: vec![[0.0; 3]],
            };
        }
        // In the upper half the half circle above the mid-plane stands for
        // the whole (u_x and u_y are even in z); in the whole mirrored slab
        // (a foundation under it) both halves are listed.
        let n = RIM_POINTS;
        let halves: &[f64] = if body.upper_half {
            &[1.0]
        } else {
            &[1.0, -1.0]
        };
        let offsets = halves
            .iter()
            .flat_map(|&side| {
                (0..n).map(move |k| {
                    let t = (k as f64 + 0.5) * std::f64::consts::PI / n as f64;
                    [radius * t.cos(), 0.0, side * radius * t.sin()]
                })
            })
            .collect();
        Self { offsets }
    }

    fn points(&self, body: &Body, axis: [f64; 3]) -> impl Iterator<Item = [f64; 3]> + '_ {
        let (lo, hi) = body.bounds();
        self.offsets
            .iter()
            .map(move |o| std::array::from_fn(|c| (axis[c] + o[c]).clamp(lo[c], hi[c])))
    }

    /// The mean displacement over the rim around `axis` and its gradient.
    fn value_and_gradient(
        &self,
        body: &Body,
        axis: [f64; 3],
        u: &[f64],
    ) -> Option<([f64; 3], [[f64; 3]; 3])> {
        let weight = 1.0 / self.offsets.len() as f64;
        let mut value = [0.0; 3];
        let mut gradient = [[0.0; 3]; 3];
        for point in self.points(body, axis) {
            let (v, g) = body.value_and_gradient(point, u)?;
            for i in 0..3 {
                value[i] += weight * v[i];
                for j in 0..3 {
                    gradient[i][j] += weight * g[i][j];
                }
            }
        }
        Some((value, gradient))
    }

    /// The elements the rim around `axis` is read in; a needle without
    /// radius reads its axis, whose location the caller may have already.
    fn elements(&self, body: &Body, axis: [f64; 3], located: Option<&Location>) -> Vec<usize> {
        if let (Some(at), [[0.0, 0.0, 0.0]]) = (located, self.offsets.as_slice()) {
            return vec![at.element];
        }
        self.points(body, axis)
            .map(|p| {
                body.locate(p)
                    .expect("rim points are clamped into the body")
                    .element
            })
            .collect()
    }
}

/// Moves a point onto the body if it lies (by rounding) just outside.
fn clamp_inside(body: &Body, x: &mut [f64; 3]) {
    let (lo, hi) = body.bounds();
    for c in 0..3 {
        x[c] = x[c].clamp(lo[c], hi[c]);
    }
}
