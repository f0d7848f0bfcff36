//! The forward model: from a parameter vector to the predicted marker
//! displacements at every frame and the needle base force at every sample.
//!
//! The baseline body is a plane-strain T6 mesh of the slab with a node on
//! every marker (when the markers form a grid), fixed faces from the
//! manifest. The `out_of_plane` effect adds a Tet10 slab through the
//! thickness (see `body`) and blends the two predictions,
//! $u = (1 - w)\,u_\text{plane} + w\,u_\text{slab}$ with its weight $w$.
//! Each element has its own material region so that effects can set any
//! modulus field $E_e = E \prod_k f_k(\text{centroid}_e, \text{trial})$.
//! Trials that share a material field and supports share one Cholesky
//! factorisation per body (fields differing by a uniform factor too), so a
//! finite-difference Jacobian column that changes only a load parameter or
//! $E$ costs triangular solves and no factorisation. All frames of those
//! trials are solved as one block of right-hand sides.
//!
//! - Probe frame: the measured force $F$ and moment $M$ spread over the
//!   contact patch as under a rigid flat punch (width $a$, centred on the
//!   point of the outline nearest to the tip),
//!   $u = F_x g_x + F_y g_y + M g_M$
//!   with $g$ the responses to unit forces and to a unit moment (the force
//!   responses are kept to propagate the force noise into the marker
//!   covariance, see `whiten`). A rigid punch pressed near a free side
//!   tilts its pressure; the moment carries that (0.14 mm of eccentricity
//!   on the quick campaign's first probe, 15 mm from the side: with it
//!   that probe's chi-square per value fell from 1.057 to 1.018, the
//!   other probe's, 30 mm from the side, went from 0.923 to 0.930).
//! - Needle frame: a line load of density $q(s)\,\hat d$,
//!   $q(s) = (q_0 + \sum_k \Delta q_k(s)) \prod_k g_k(s)$ (effects add
//!   densities $\Delta q_k$ and multiply by factors $g_k$), on the material line
//!   whose deformed image is the needle, from the dragged-in entry point to
//!   the tip, $s$ the spatial arclength from the entry (see `place`). Each
//!   body finds that line in its own displacement: the plane model from the
//!   spatial line, the slab from the plane's placement
//!   ([`SLAB_PLACEMENT_ROUNDS`] rounds, each a back-substitution of the
//!   slab's factor). The slab's mid-plane is dragged along the needle
//!   differently from the plane model's (in 3-D the displacement grows
//!   like $\ln r$ towards a line load, in the plane it stays finite), and
//!   loading the plane's line instead misplaces the load by that
//!   difference: on the default 21 x 21 campaign the needle trials
//!   misfit the 3-D truth at $\chi^2/\nu = 7$ at its own parameters
//!   (18 on the lines nearest the free sides), against 1.07 with the
//!   slab's own placement. A needle of finite radius
//!   (`DiagnoseOptions::needle_radius`) places its load on the slab by
//!   the drag of its surface, not of its axis (`Body::needle_drag`): the
//!   axis's grows without bound as the slab is refined towards it, the
//!   surface's settles. The slab may be graded towards the needles
//!   (`graded_towards_needles`).
//!   The finite-difference columns of every fit and of the score test
//!   start each body from its own placement at the base point instead
//!   ([`Start::Near`]): the placement barely moves over a difference step.
//!   In `place::NEAR_ROUNDS` rounds (the fits that set the model) the
//!   columns' derivative stays within 1% of the model's own, in
//!   `place::RANKING_NEAR_ROUNDS` (the ranking) within 2.5% (a unit test
//!   checks every parameter that moves the load), for 3 or 2
//!   back-substitutions per frame instead of 5 on the plane and 4 on the
//!   slab. A column of a parameter that acts after the solves (the slab's
//!   weight, the lens) takes the solutions of the columns' map at the base
//!   point as they are ([`Start::Reuse`]) and solves nothing.
//! - Needle force sample: $F = \hat d \int_0^{L'} q(s)\,ds$ with the
//!   inserted length $L' = L - \delta$, the entry's drag $\delta$ per unit
//!   length interpolated in $L$ between the trial's frames.
//! - Markers: $p = x_\text{rest} + H u$, mapped through every effect's
//!   measurement map, minus $x_\text{rest}$.
//! - Material: with a nonlinear weight $w \ne 0$ (`material_nonlinearity`)
//!   every frame adds $w\,(u_2 + u_3)$, the neo-Hookean terms of second
//!   and third order in the load of the plane model's linear solution (see
//!   `series`), on the same factorisation: a probe frame's are forms in its
//!   measured force, solved once per tip; a needle frame's are solved for
//!   its final placement, which stays that of the linear solution, and the
//!   entry offset gains $w\,\hat d \cdot (u_2 + u_3)$ at the entry's
//!   material point. With $w = 0$ none of it is computed. The terms come
//!   from the plane body whatever the slab's weight: in the slab the probe
//!   patch and the needle are lines of force, next to which the strain
//!   grows without bound as the mesh is refined, so the series has almost
//!   no range there (on a coarse slab its third-order term overtakes the
//!   second beyond about 0.02 N, and Newton's method fails from 0.04 N).

use needle_fem::{ElementKind, Face, Formulation, Locator, MarkerGrid, RectangleMesh, SlabMesh};

use std::sync::{Arc, Mutex};

use rayon::prelude::*;

use crate::body::{Body, Factorized, Span};
use crate::effect::{Geometry, ShaftPoint, SupportSpec, TrialContext};
use crate::error::DiagnoseError;
use crate::model::Model;
use crate::observe::{Load, Observations, Shaft};
use crate::place::{Mixing, PLACEMENT_ROUNDS, Placement, SLAB_PLACEMENT_ROUNDS};
use crate::whiten::ProbeResponse;

/// Element layers through the thickness of the `out_of_plane` slab.
const SLAB_LAYERS: usize = 2;

/// How far beyond the needle's radius a re-placement of its load may read
/// the displacement in a partial solve (m): the load moves between rounds
/// by less (see `Forward::replace_near`).
const NEEDLE_REACH: f64 = 2.0e-3;

/// What the forward model predicts, in residual order.
pub(crate) struct Prediction {
    pub values: Vec<f64>,
    /// Every probe frame's unit responses, for the covariance of its
    /// force noise (see `whiten`).
    pub probe_responses: Vec<ProbeResponse>,
}

/// One right-hand side of a group of frames.
#[derive(Debug, Clone, Copy)]
enum Column {
    /// Unit force along `axis` 0 (x) or 1 (y), or unit moment about z
    /// (`axis` 2), at a probe's contact point, of a frame of `trial` whose
    /// measured force is `force`.
    Probe {
        trial: usize,
        contact: [f64; 2],
        axis: usize,
        force: [f64; 2],
    },
    /// The needle of frame `frame`.
    Needle { frame: usize },
}

/// The neo-Hookean part of one frame's marker displacements (see the
/// module doc), summed over the bodies with their weights; empty vectors
/// stand for zero.
#[derive(Debug, Clone, Default)]
struct Nonlinear {
    displacement: Vec<[f64; 2]>,
    /// Probe frames: the derivatives of `displacement` in $F_x$ and $F_y$.
    sensitivity: [Vec<[f64; 2]>; 2],
}

/// `weight * values` added to `target` (zero if empty).
fn accumulate(target: &mut Vec<[f64; 2]>, weight: f64, values: impl Iterator<Item = [f64; 2]>) {
    let values: Vec<[f64; 2]> = values.collect();
    if target.is_empty() {
        target.resize(values.len(), [0.0; 2]);
    }
    for (t, v) in target.iter_mut().zip(values) {
        t[0] += weight * v[0];
        t[1] += weight * v[1];
    }
}

/// Entry `m` of a marker vector that may be empty (zero).
fn at(values: &[[f64; 2]], m: usize) -> [f64; 2] {
    values.get(m).copied().unwrap_or([0.0; 2])
}

/// What one body's solutions give, or the bodies' add up to, per column
/// of a group.
#[derive(Debug, Clone)]
struct Columns {
    /// Marker displacements (probe columns: per unit force along the axis).
    displacement: Vec<Vec<[f64; 2]>>,
    /// Needle columns: the entry offset $\delta$ of the linear solution.
    entry_offsets: Vec<f64>,
    /// The first column of each frame: its neo-Hookean part.
    nonlinear: Vec<Nonlinear>,
    /// Needle columns: the neo-Hookean part of the entry offset.
    nonlinear_entry_offsets: Vec<f64>,
}

impl Columns {
    fn zeros(columns: usize, markers: usize) -> Self {
        Self {
            displacement: vec![vec![[0.0; 2]; markers]; columns],
            entry_offsets: vec![0.0; columns],
            nonlinear: vec![Nonlinear::default(); columns],
            nonlinear_entry_offsets: vec![0.0; columns],
        }
    }

    /// The prediction's columns: the plane body's and the slab's linear
    /// parts blended with their weights, plus the plane's neo-Hookean
    /// part (already weighted).
    fn blend(plane: &Columns, slab: Option<&Columns>, plane_weight: f64, slab_weight: f64) -> Self {
        let displacement = (0..plane.displacement.len())
            .map(|k| {
                let mut column: Vec<[f64; 2]> = plane.displacement[k]
                    .iter()
                    .map(|&[x, y]| [plane_weight * x, plane_weight * y])
                    .collect();
                if let Some(slab) = slab {
                    for (value, &[x, y]) in column.iter_mut().zip(&slab.displacement[k]) {
                        value[0] += slab_weight * x;
                        value[1] += slab_weight * y;
                    }
                }
                column
            })
            .collect();
        let entry_offsets = (0..plane.entry_offsets.len())
            .map(|k| {
                plane_weight * plane.entry_offsets[k]
                    + slab.map_or(0.0, |slab| slab_weight * slab.entry_offsets[k])
                    + plane.nonlinear_entry_offsets[k]
            })
            .collect();
        Self {
            displacement,
            entry_offsets,
            nonlinear: plane.nonlinear.clone(),
            nonlinear_entry_offsets: plane.nonlinear_entry_offsets.clone(),
        }
    }
}

/// One group of trials' solutions on each body, unweighted (the slab's
/// `None` where it was not solved): what [`Start::Reuse`] takes.
#[derive(Debug, Clone)]
struct GroupSolutions {
    plane: Columns,
    slab: Option<Columns>,
}

/// Where one evaluation placed the needle load of every needle frame, on
/// each body (by frame index; `None` for other frames and a body not
/// solved), and what each body's solves gave for each group of trials.
#[derive(Debug, Clone, Default)]
pub(crate) struct Placements {
    plane: Vec<Option<Placement>>,
    slab: Vec<Option<Placement>>,
    solutions: Vec<GroupSolutions>,
}

/// What the effects of `model` at `p` make of the bodies: their supports,
/// the slab's weight and the neo-Hookean terms' weight.
fn effects_on_bodies(model: &Model, p: &[f64]) -> (SupportSpec, f64, f64) {
    let mut supports = SupportSpec::default();
    let (mut slab_weight, mut nonlinear) = (0.0, 0.0);
    for (effect, own) in model.effects_with(p) {
        effect.supports(own, &mut supports);
        slab_weight += effect.slab_weight(own);
        nonlinear += effect.nonlinear_weight(own);
    }
    (supports, slab_weight, nonlinear)
}

impl Placements {
    /// Whether these solutions serve an evaluation of `model` at `p` whose
    /// parameters differ from theirs only in what acts after the solves
    /// ([`Model::solves_alike`]): they must hold the slab if `p` weighs it.
    pub fn serve(&self, model: &Model, p: &[f64]) -> bool {
        let (_, slab_weight, _) = effects_on_bodies(model, p);
        slab_weight == 0.0 || self.solutions.iter().all(|g| g.slab.is_some())
    }
}

/// Where the placement of the needle loads starts.
#[derive(Debug, Clone, Copy)]
pub(crate) enum Start<'a> {
    /// The model proper: the plane body from the spatial line in
    /// [`PLACEMENT_ROUNDS`] rounds, the slab from the plane's placement in
    /// [`SLAB_PLACEMENT_ROUNDS`].
    Cold,
    /// Each body from its own placement of an evaluation nearby, in
    /// `rounds` rounds, where that evaluation placed every needle frame
    /// of the group (else as `Cold`). For the columns of a
    /// finite-difference Jacobian (see `fit`).
    Near {
        placements: &'a Placements,
        rounds: usize,
    },
    /// The solutions and placements of an evaluation whose parameters
    /// differ only in what acts after the solves (the bodies' blend, the
    /// measurement map; see [`Model::solves_alike`] and
    /// [`Placements::serve`]), taken as they are: no solve at all. They
    /// are the very numbers a solve would give, so a finite-difference
    /// column of such a parameter costs nothing and differs from its
    /// solved value by nothing.
    Reuse { solved: &'a Placements },
}

impl Start<'_> {
    /// The start of `frames` on the body whose placements `body` selects,
    /// and its rounds; `(None, None)` for the cold start.
    fn on(
        &self,
        frames: &[usize],
        body: impl Fn(&Placements) -> &Vec<Option<Placement>>,
    ) -> (Option<Vec<Placement>>, Option<usize>) {
        let Start::Near { placements, rounds } = *self else {
            return (None, None);
        };
        let stored = body(placements);
        let start: Option<Vec<Placement>> = frames
            .iter()
            .map(|&f| stored.get(f).cloned().flatten())
            .collect();
        match start {
            Some(start) => (Some(start), Some(rounds)),
            None => (None, None),
        }
    }
}

pub(crate) struct Forward {
    pub geometry: Geometry,
    /// Re-placements of the needle load on the plane body, from the
    /// spatial line, and on the slab, from the plane's placement (see
    /// `place`).
    placement_rounds: usize,
    slab_placement_rounds: usize,
    /// The needle's radius, for its drag on the slab (`Body::needle_drag`).
    needle_radius: f64,
    /// Whether the rounds before the last solve near the needle alone
    /// (`Forward::replace_near`); off, they solve whole (a test's reference).
    near_solves: bool,
    plane: Body<2>,
    /// The `out_of_plane` slab's upper half (see `body`), and the whole
    /// mirrored slab, made on first use, for a foundation under it.
    slab: Arc<Body<3>>,
    whole_slab: Mutex<Option<Arc<Body<3>>>>,
    slab_plan: SlabMesh,
    fixed: Vec<Face>,
    rest: Vec<[f64; 2]>,
}

fn fem_face(face: needle_data::Face) -> Face {
    match face {
        needle_data::Face::Front => Face::Front,
        needle_data::Face::Back => Face::Back,
        needle_data::Face::Left => Face::Left,
        needle_data::Face::Right => Face::Right,
    }
}

/// Distinct values, sorted, merged within `tolerance`.
fn distinct(values: impl Iterator<Item = f64>, tolerance: f64) -> Vec<f64> {
    let mut v: Vec<f64> = values.collect();
    v.sort_by(f64::total_cmp);
    v.dedup_by(|a, b| (*a - *b).abs() <= tolerance);
    v
}

/// `plan` with node lines added towards every needle along x or y
/// (`needles`: entry points and directions): on the needle's line and
/// half the plan's largest spacing $h$ either side, and at $h/2$, $h/4$
/// and $h/8$ from its entry. In 3-D the field of the needle's load
/// varies fastest within a millimetre or two of its line and where it
/// meets the entry face; on the default campaign, with the needle's
/// surface drag, these lines took the final model's marker chi2/dof from
/// 1.029 to 1.018 (`docs/benchmarks.md`, session 15). An oblique needle
/// adds none. A new line closer than $h/16$ to a line already there (or
/// to a side) is left out.
fn graded_towards_needles(
    mut plan: RectangleMesh,
    needles: &[([f64; 2], [f64; 2])],
) -> RectangleMesh {
    let spacing = |lines: &[f64]| lines.windows(2).map(|w| w[1] - w[0]).fold(0.0, f64::max);
    let h = spacing(&plan.x_lines).max(spacing(&plan.y_lines));
    let aligned = 1e-6;
    let mut added = [Vec::new(), Vec::new()];
    for &(entry, direction) in needles {
        for across in 0..2 {
            let along = 1 - across;
            if direction[across].abs() > aligned {
                continue;
            }
            added[across].extend([-0.5 * h, 0.0, 0.5 * h].map(|d| entry[across] + d));
            let inward = direction[along].signum();
            added[along].extend([0.5, 0.25, 0.125].map(|f| entry[along] + inward * f * h));
        }
    }
    let tolerance = h / 16.0;
    for (lines, added) in [&mut plan.x_lines, &mut plan.y_lines]
        .into_iter()
        .zip(added)
    {
        let (first, last) = (lines[0], lines[lines.len() - 1]);
        for line in added {
            let clear = lines.iter().all(|l| (l - line).abs() > tolerance);
            if clear && line > first && line < last {
                lines.push(line);
            }
        }
        lines.sort_by(f64::total_cmp);
    }
    plan
}

/// The plan of a rectangle mesh with a node line through every marker when
/// the markers form a grid, else a uniform mesh of about the marker
/// spacing; elements `refinement` times smaller.
fn plan(
    width: f64,
    depth: f64,
    rest: &[[f64; 2]],
    refinement: usize,
) -> Result<RectangleMesh, DiagnoseError> {
    let tolerance = 1e-9 * width.max(depth);
    let xs = distinct(rest.iter().map(|p| p[0]), tolerance);
    let ys = distinct(rest.iter().map(|p| p[1]), tolerance);
    let inside = |v: &[f64], extent: f64| v.iter().all(|&x| x > 0.0 && x < extent);
    Ok(
        if xs.len() * ys.len() == rest.len() && inside(&xs, width) && inside(&ys, depth) {
            RectangleMesh::with_markers(width, depth, &MarkerGrid { x: xs, y: ys }, refinement)?
        } else {
            let per_side = ((rest.len() as f64).sqrt().ceil() as usize + 1).max(4);
            RectangleMesh::uniform(width, depth, per_side * refinement, per_side * refinement)?
        },
    )
}

impl Forward {
    /// The bodies for `phantom` with markers at `rest`: the plane model
    /// with elements `refinement` times smaller than the marker spacing,
    /// the slab `slab_refinement` times, graded towards the needles'
    /// lines and entries when `needles` (entry points and directions) are
    /// given; a needle of `needle_radius`.
    pub fn new(
        phantom: &needle_data::Phantom,
        rest: &[[f64; 2]],
        refinement: usize,
        slab_refinement: usize,
        needles: &[([f64; 2], [f64; 2])],
        needle_radius: f64,
    ) -> Result<Self, DiagnoseError> {
        let (width, depth, thickness) = (phantom.width, phantom.depth, phantom.thickness);
        if needle_radius >= 0.25 * thickness {
            return Err(DiagnoseError::InvalidOption {
                field: "needle_radius",
                reason: format!(
                    "{needle_radius} m must be below a quarter of the phantom's thickness, {thickness} m"
                ),
            });
        }
        let fixed: Vec<Face> = phantom.fixed.iter().map(|&f| fem_face(f)).collect();
        let plane = Body::new(
            plan(width, depth, rest, refinement)?.build(ElementKind::Tri6)?,
            Formulation::PlaneStrain { thickness },
            thickness,
            Span::Whole,
            fixed.clone(),
            rest,
        )?;
        let slab_plan = SlabMesh::new(
            graded_towards_needles(plan(width, depth, rest, slab_refinement)?, needles),
            thickness,
            SLAB_LAYERS,
        )?;
        let slab = Body::new(
            slab_plan.build_upper_half(ElementKind::Tet10)?,
            Formulation::Solid,
            thickness,
            Span::UpperHalf,
            fixed.clone(),
            rest,
        )?;
        let n = rest.len().max(1) as f64;
        let centre = [
            rest.iter().map(|p| p[0]).sum::<f64>() / n,
            rest.iter().map(|p| p[1]).sum::<f64>() / n,
        ];
        let radius = rest
            .iter()
            .map(|p| ((p[0] - centre[0]).powi(2) + (p[1] - centre[1]).powi(2)).sqrt())
            .fold(0.0, f64::max);
        Ok(Self {
            geometry: Geometry {
                width,
                depth,
                thickness,
                image_centre: centre,
                image_radius: if radius > 0.0 { radius } else { 0.5 * width },
            },
            plane,
            slab: Arc::new(slab),
            whole_slab: Mutex::new(None),
            slab_plan,
            fixed,
            rest: rest.to_vec(),
            placement_rounds: PLACEMENT_ROUNDS,
            slab_placement_rounds: SLAB_PLACEMENT_ROUNDS,
            needle_radius,
            near_solves: true,
        })
    }

    /// The slab body for `supports`: the upper half, or the whole mirrored
    /// slab when a foundation acts under it. With no foundation the two
    /// give the same displacement, so a finite-difference step off a
    /// foundation of zero differences the foundation alone.
    fn slab_for(&self, supports: SupportSpec) -> Result<Arc<Body<3>>, DiagnoseError> {
        if supports.foundation <= 0.0 {
            return Ok(Arc::clone(&self.slab));
        }
        let mut whole = self.whole_slab.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(body) = whole.as_ref() {
            return Ok(Arc::clone(body));
        }
        let body = Arc::new(Body::new(
            self.slab_plan.build_symmetric(ElementKind::Tet10)?,
            Formulation::Solid,
            self.geometry.thickness,
            Span::Whole,
            self.fixed.clone(),
            &self.rest,
        )?);
        *whole = Some(Arc::clone(&body));
        Ok(body)
    }

    /// Builds, ahead of need, what a foundation under the slab first costs
    /// with `model` at `p`: the whole mirrored slab and its spring
    /// template. Nothing if the model does not use the slab. A ranking
    /// differences `platform_friction` on the whole slab, and on the
    /// default campaign building them took 3 to 4 s of its critical path
    /// (`docs/benchmarks.md`, session 32); a fit that runs meanwhile
    /// leaves a core idle for part of its time.
    pub fn prepare_foundation(&self, model: &Model, p: &[f64]) -> Result<(), DiagnoseError> {
        let (supports, slab_weight, _) = effects_on_bodies(model, p);
        if slab_weight == 0.0 {
            return Ok(());
        }
        let founded = SupportSpec {
            foundation: 1.0,
            ..supports
        };
        let whole = self.slab_for(founded)?;
        whole.prepare_template([supports.fixed_face_compliance > 0.0, true])
    }

    /// Element moduli of a trial on `body`.
    fn moduli<const D: usize>(
        body: &Body<D>,
        model: &Model,
        p: &[f64],
        trial: &TrialContext,
    ) -> Vec<f64> {
        (0..body.centroids.len())
            .map(|e| Self::modulus(body, model, p, trial, e))
            .collect()
    }

    /// Modulus of element `e` of `body` in a trial.
    fn modulus<const D: usize>(
        body: &Body<D>,
        model: &Model,
        p: &[f64],
        trial: &TrialContext,
        e: usize,
    ) -> f64 {
        let e0 = model.baseline(p).youngs_modulus;
        model.effects_with(p).fold(e0, |acc, (effect, own)| {
            acc * effect.stiffness_factor(own, trial, body.centroids[e], body.element_y[e])
        })
    }

    /// Shaft density $q(s) = (q_0 + \sum_k \Delta q_k(s)) \prod_k g_k(s)$
    /// (N/m) of a trial: the effects' added densities, then their factors.
    fn density(&self, model: &Model, p: &[f64], trial: &TrialContext, point: ShaftPoint) -> f64 {
        let (added, factor) = model.effects_with(p).fold(
            (model.baseline(p).shaft_density, 1.0),
            |(added, factor), (effect, own)| {
                (
                    added + effect.shaft_density(own, trial, point),
                    factor * effect.shaft_density_factor(own, trial, point),
                )
            },
        );
        added * factor
    }

    fn breakpoints(&self, model: &Model, p: &[f64], length: f64) -> Vec<f64> {
        let mut out: Vec<f64> = model
            .effects_with(p)
            .flat_map(|(effect, own)| effect.shaft_breakpoints(own, length))
            .filter(|&s| s > 0.0 && s < length)
            .collect();
        out.sort_by(f64::total_cmp);
        out
    }

    /// $\int_0^L q(s)\,ds$ by 5-point Gauss-Legendre on pieces split at the
    /// density's breakpoints.
    fn shaft_force(&self, model: &Model, p: &[f64], trial: &TrialContext, length: f64) -> f64 {
        const NODES: [f64; 5] = [
            0.0,
            -0.538_469_310_105_683_1,
            0.538_469_310_105_683_1,
            -0.906_179_845_938_664,
            0.906_179_845_938_664,
        ];
        const WEIGHTS: [f64; 5] = [
            0.568_888_888_888_888_9,
            0.478_628_670_499_366_5,
            0.478_628_670_499_366_5,
            0.236_926_885_056_189_1,
            0.236_926_885_056_189_1,
        ];
        let mut cuts = vec![0.0];
        cuts.extend(self.breakpoints(model, p, length));
        cuts.push(length);
        let mut total = 0.0;
        for w in cuts.windows(2) {
            let (a, b) = (w[0], w[1]);
            for (x, g) in NODES.iter().zip(WEIGHTS) {
                let s = 0.5 * (a + b) + 0.5 * (b - a) * x;
                total +=
                    0.5 * (b - a) * g * self.density(model, p, trial, ShaftPoint { s, length });
            }
        }
        total
    }

    /// The in-plane displacement of every marker under every column on
    /// `body` added to `out.displacement[column][marker]`; for needle
    /// columns, the entry offset $\delta$ added to
    /// `out.entry_offsets[column]`; the neo-Hookean parts times `nonlinear`
    /// to `out.nonlinear` and `out.nonlinear_entry_offsets`. The needle
    /// loads are placed in `rounds` rounds from `start` (the spatial line
    /// if `None`); returns where. The columns' trials have the material
    /// field of `trial` up to a uniform factor each, and share its
    /// factorisation; every round solves all their needle loads at once.
    #[allow(clippy::too_many_arguments)]
    fn add_columns<const D: usize>(
        &self,
        body: &Body<D>,
        nonlinear: f64,
        model: &Model,
        p: &[f64],
        obs: &Observations,
        trial: usize,
        supports: SupportSpec,
        columns: &[Column],
        out: &mut Columns,
        start: Option<&[Placement]>,
        rounds: usize,
    ) -> Result<Vec<Placement>, DiagnoseError> {
        let context = &obs.trials[trial];
        let moduli = Self::moduli(body, model, p, context);
        let shared = body.factorized(&moduli, model.baseline(p).poisson_ratio, supports)?;
        // The columns' trials have this one's field times a factor of
        // their own (see `proportional`): its factorisation, their scale.
        let scale_of = |t: usize| Self::modulus(body, model, p, &obs.trials[t], 0);
        let locator = body.locator();
        let contacts: Vec<[f64; 2]> = columns
            .iter()
            .filter_map(|column| match *column {
                Column::Probe {
                    contact, axis: 0, ..
                } => Some(contact),
                _ => None,
            })
            .collect();
        let width = model.baseline(p).probe_width;
        body.solve_probe_responses(&locator, &shared, &contacts, width)?;
        let mut needles = Vec::new();
        for (k, column) in columns.iter().enumerate() {
            match *column {
                // All three come together from one tip (x first).
                Column::Probe {
                    trial,
                    contact,
                    axis: 0,
                    force,
                } => {
                    let factorized = Factorized {
                        entry: Arc::clone(&shared.entry),
                        scale: scale_of(trial),
                    };
                    let width = model.baseline(p).probe_width;
                    let responses = body.probe_responses(&locator, &factorized, contact, width)?;
                    for (axis, response) in responses.iter().enumerate() {
                        for (value, u) in out.displacement[k + axis].iter_mut().zip(response) {
                            value[0] += u[0];
                            value[1] += u[1];
                        }
                    }
                    if nonlinear != 0.0 {
                        let series = body.probe_series(&locator, &factorized, contact, width)?;
                        let [value, along_x, along_y] = series.at(force);
                        let w = nonlinear;
                        let part = &mut out.nonlinear[k];
                        accumulate(&mut part.displacement, w, value.into_iter());
                        accumulate(&mut part.sensitivity[0], w, along_x.into_iter());
                        accumulate(&mut part.sensitivity[1], w, along_y.into_iter());
                    }
                }
                Column::Probe { .. } => {}
                Column::Needle { frame } => {
                    let Load::Needle(shaft) = obs.frames[frame].load else {
                        unreachable!("needle columns are made from needle frames")
                    };
                    let trial = obs.frames[frame].trial;
                    needles.push((k, &obs.trials[trial], shaft, scale_of(trial)));
                }
            }
        }
        if needles.is_empty() {
            return Ok(Vec::new());
        }
        // Place the load consistently with the displacement it causes
        // (see `place`).
        let mut placements: Vec<Placement> = match start {
            Some(start) => start.to_vec(),
            None => needles
                .iter()
                .map(|(_, _, shaft, _)| Placement::spatial(shaft))
                .collect(),
        };
        let mut mixings: Vec<Mixing> = needles.iter().map(|_| Mixing::default()).collect();
        for round in 0..=rounds {
            // Frame by frame independent, and outside the thread pool (a
            // fit's trial point) the other core is idle meanwhile.
            let loads = needles
                .par_iter()
                .zip(&placements)
                .map(|(&(_, trial, shaft, _), placement)| {
                    let length = placement.inserted_length(&shaft);
                    let density =
                        move |s: f64| self.density(model, p, trial, ShaftPoint { s, length });
                    body.needle_load(
                        &locator,
                        &shaft,
                        placement,
                        &density,
                        &self.breakpoints(model, p, length),
                    )
                })
                .collect::<Result<Vec<_>, _>>()?;
            if round < rounds {
                let solved =
                    self.replace_near(body, &locator, &shared, &needles, &placements, &loads)?;
                placements = solved
                    .into_iter()
                    .zip(&placements)
                    .zip(&mut mixings)
                    .map(|((solved, placement), mixing)| {
                        mixing.next(placement, solved, body.extent())
                    })
                    .collect();
                continue;
            }
            let refs: Vec<&[f64]> = loads.iter().map(|l| l.as_slice()).collect();
            let solutions = shared.entry.problem.displacements_many(&refs)?;
            for ((u, &(k, _, _, scale)), placement) in
                solutions.iter().zip(&needles).zip(&placements)
            {
                for (value, d) in out.displacement[k].iter_mut().zip(body.markers(u, scale)) {
                    value[0] += d[0];
                    value[1] += d[1];
                }
                out.entry_offsets[k] += placement.entry_offset;
            }
            if nonlinear != 0.0 {
                let refs: Vec<&[f64]> = solutions.iter().map(|u| u.as_slice()).collect();
                let terms = body.nonlinear_terms(&shared, &refs)?;
                // The terms come as c^2 u_2 and c^3 u_3 (see `series`), c
                // the trial's scale.
                let w = nonlinear;
                for ((terms, &(k, _, shaft, c)), placement) in
                    terms.iter().zip(&needles).zip(&placements)
                {
                    let d = shaft.direction;
                    for (term, divisor) in terms.iter().zip([c * c, c * c * c]) {
                        let markers = body.markers(term, divisor);
                        accumulate(&mut out.nonlinear[k].displacement, w, markers.into_iter());
                        let entry = body.mid_plane_displacement(
                            &locator,
                            term,
                            divisor,
                            placement.material[0],
                        )?;
                        out.nonlinear_entry_offsets[k] += w * (d[0] * entry[0] + d[1] * entry[1]);
                    }
                }
            }
        }
        Ok(placements)
    }

    /// The needle loads `loads` re-placed in their solutions (see
    /// `place`), before mixing. A re-placement reads the displacement next
    /// to the shaft alone, so the frames of each needle line (a trial's)
    /// are solved over the part of the factor that their loads and the
    /// elements within [`NEEDLE_REACH`] of the shaft reach
    /// (`displacements_near`): on the default campaign's diagnosis, 29% of
    /// the half slab's rows and 17% of the plane body's. Should a
    /// re-placement read outside that part (`NaN`; the load moved
    /// further), that line's frames are solved whole: none of the slab's
    /// 1540 solves there, 65 of the plane's 5500.
    fn replace_near<const D: usize>(
        &self,
        body: &Body<D>,
        locator: &Locator<'_, D>,
        shared: &Factorized<D>,
        needles: &[(usize, &TrialContext, Shaft, f64)],
        placements: &[Placement],
        loads: &[Vec<f64>],
    ) -> Result<Vec<Placement>, DiagnoseError> {
        let line = |i: usize| (needles[i].2.entry, needles[i].2.direction);
        let mut lines: Vec<Vec<usize>> = Vec::new();
        for i in 0..needles.len() {
            match lines.iter_mut().find(|frames| line(frames[0]) == line(i)) {
                Some(frames) => frames.push(i),
                None => lines.push(vec![i]),
            }
        }
        let problem = &shared.entry.problem;
        let solved = lines
            .par_iter()
            .map(|frames| -> Result<Vec<(usize, Placement)>, DiagnoseError> {
                let refs: Vec<&[f64]> = frames.iter().map(|&i| loads[i].as_slice()).collect();
                let replace =
                    |solutions: &[Vec<f64>]| -> Result<Vec<(usize, Placement)>, DiagnoseError> {
                        frames
                            .iter()
                            .zip(solutions)
                            .map(|(&i, u)| {
                                let (_, _, shaft, scale) = needles[i];
                                let displacement = |xy: [f64; 2]| {
                                    body.needle_drag(
                                        locator,
                                        u,
                                        scale,
                                        xy,
                                        shaft.direction,
                                        self.needle_radius,
                                    )
                                };
                                Ok((
                                    i,
                                    placements[i].replaced(&shaft, &displacement, body.extent())?,
                                ))
                            })
                            .collect()
                    };
                if !self.near_solves {
                    return replace(&problem.displacements_many(&refs)?);
                }
                let wanted: Vec<usize> = frames
                    .iter()
                    .flat_map(|&i| {
                        body.needle_dofs(locator, &placements[i], self.needle_radius + NEEDLE_REACH)
                    })
                    .collect();
                let near = problem.displacements_near(&refs, &wanted)?;
                // A read of a `NaN` may also end in an error (a point
                // clamped to `NaN` is outside the mesh): the whole solve
                // then says whether it is one.
                match replace(&near) {
                    Ok(solved) if solved.iter().all(|(_, p)| p.is_finite()) => Ok(solved),
                    _ => replace(&problem.displacements_many(&refs)?),
                }
            })
            .collect::<Result<Vec<_>, _>>()?;
        let mut out: Vec<Option<Placement>> = vec![None; needles.len()];
        for (i, placement) in solved.into_iter().flatten() {
            out[i] = Some(placement);
        }
        Ok(out
            .into_iter()
            .map(|p| p.expect("every frame is on one line"))
            .collect())
    }

    /// Solves the `columns` of the group of trials led by `trial` on the
    /// plane body and, if `slab`, on the slab, the neo-Hookean part
    /// weighted by `nonlinear`; records the needle placements of
    /// `needle_frames` in `placements`.
    #[allow(clippy::too_many_arguments)]
    fn solve_group(
        &self,
        model: &Model,
        p: &[f64],
        obs: &Observations,
        trial: usize,
        supports: SupportSpec,
        slab: bool,
        nonlinear: f64,
        columns: &[Column],
        needle_frames: &[usize],
        start: Start<'_>,
        placements: &mut Placements,
    ) -> Result<GroupSolutions, DiagnoseError> {
        let markers = obs.rest.len();
        let mut plane_columns = Columns::zeros(columns.len(), markers);
        let (plane_start, plane_rounds) = start.on(needle_frames, |s| &s.plane);
        let plane_rounds = plane_rounds.unwrap_or(self.placement_rounds);
        // The plane model always runs (at weight 0 if need be): the
        // slab starts from its needle placement, and the neo-Hookean
        // terms are the plane's (see the module doc). The slab's
        // factorisation does not depend on the placement, so it is
        // made (and cached) on another thread meanwhile.
        let (placed, slab_factorized) = rayon::join(
            || {
                self.add_columns(
                    &self.plane,
                    nonlinear,
                    model,
                    p,
                    obs,
                    trial,
                    supports,
                    columns,
                    &mut plane_columns,
                    plane_start.as_deref(),
                    plane_rounds,
                )
            },
            || {
                slab.then(|| {
                    let body = self.slab_for(supports)?;
                    let moduli = Self::moduli(&body, model, p, &obs.trials[trial]);
                    let nu = model.baseline(p).poisson_ratio;
                    body.factorized(&moduli, nu, supports)
                })
                .transpose()
            },
        );
        let placed = placed?;
        slab_factorized?;
        for (&frame, placement) in needle_frames.iter().zip(&placed) {
            placements.plane[frame] = Some(placement.clone());
        }
        let slab_columns = if slab {
            let mut slab_columns = Columns::zeros(columns.len(), markers);
            let (slab_start, slab_rounds) = start.on(needle_frames, |s| &s.slab);
            let body = self.slab_for(supports)?;
            let slab_placed = self.add_columns(
                &body,
                0.0,
                model,
                p,
                obs,
                trial,
                supports,
                columns,
                &mut slab_columns,
                Some(slab_start.as_deref().unwrap_or(&placed)),
                slab_rounds.unwrap_or(self.slab_placement_rounds),
            )?;
            for (&frame, placement) in needle_frames.iter().zip(slab_placed) {
                placements.slab[frame] = Some(placement);
            }
            Some(slab_columns)
        } else {
            None
        };
        Ok(GroupSolutions {
            plane: plane_columns,
            slab: slab_columns,
        })
    }

    /// Predicts every observation at parameters `p`.
    pub fn predict(
        &self,
        model: &Model,
        p: &[f64],
        obs: &Observations,
    ) -> Result<Prediction, DiagnoseError> {
        Ok(self.predict_from(model, p, obs, Start::Cold)?.0)
    }

    /// Predicts every observation at parameters `p` with the needle loads
    /// placed from `start`, and returns where they ended up.
    pub fn predict_from(
        &self,
        model: &Model,
        p: &[f64],
        obs: &Observations,
        start: Start<'_>,
    ) -> Result<(Prediction, Placements), DiagnoseError> {
        let mut placements = Placements {
            plane: vec![None; obs.frames.len()],
            slab: vec![None; obs.frames.len()],
            solutions: Vec::new(),
        };
        let (supports, slab_weight, nonlinear) = effects_on_bodies(model, p);
        let plane_weight = 1.0 - slab_weight;
        let marker_count = obs.marker_count();
        let mut values = vec![0.0; marker_count + obs.force_count()];
        let mut probe_responses = Vec::new();
        let mut frame_offset = Vec::with_capacity(obs.frames.len());
        let mut offset = 0;
        for frame in &obs.frames {
            frame_offset.push(offset);
            offset += 2 * frame.markers.len();
        }
        // Group trials whose material fields differ by a uniform factor
        // (the plane body's stand for both): they share one factorisation
        // (see `Body::factorized`), and their loads are solved together.
        let moduli: Vec<Vec<f64>> = obs
            .trials
            .iter()
            .map(|t| Self::moduli(&self.plane, model, p, t))
            .collect();
        let mut done = vec![false; obs.trials.len()];
        // Per trial, (inserted length, entry offset / length) of its needle frames.
        let mut entries: Vec<Vec<(f64, f64)>> = vec![Vec::new(); obs.trials.len()];
        for first in 0..obs.trials.len() {
            if done[first] {
                continue;
            }
            let group: Vec<usize> = (first..obs.trials.len())
                .filter(|&t| !done[t] && proportional(&moduli[t], &moduli[first]))
                .collect();
            for &t in &group {
                done[t] = true;
            }
            let frames: Vec<usize> = (0..obs.frames.len())
                .filter(|&f| group.contains(&obs.frames[f].trial))
                .collect();
            let mut columns = Vec::new();
            let mut first_column = Vec::with_capacity(frames.len());
            for &f in &frames {
                first_column.push(columns.len());
                match obs.frames[f].load {
                    Load::Free => {}
                    Load::Probe { contact, force, .. } => {
                        for axis in 0..3 {
                            columns.push(Column::Probe {
                                trial: obs.frames[f].trial,
                                contact,
                                axis,
                                force,
                            });
                        }
                    }
                    Load::Needle(_) => columns.push(Column::Needle { frame: f }),
                }
            }
            if columns.is_empty() {
                continue;
            }
            let needle_frames: Vec<usize> = columns
                .iter()
                .filter_map(|c| match *c {
                    Column::Needle { frame } => Some(frame),
                    Column::Probe { .. } => None,
                })
                .collect();
            let solved = match start {
                Start::Reuse { solved } => {
                    for &frame in &needle_frames {
                        placements.plane[frame] = solved.plane[frame].clone();
                        placements.slab[frame] = solved.slab[frame].clone();
                    }
                    solved.solutions[placements.solutions.len()].clone()
                }
                Start::Cold | Start::Near { .. } => self.solve_group(
                    model,
                    p,
                    obs,
                    first,
                    supports,
                    slab_weight != 0.0,
                    nonlinear,
                    &columns,
                    &needle_frames,
                    start,
                    &mut placements,
                )?,
            };
            let out = Columns::blend(
                &solved.plane,
                solved.slab.as_ref(),
                plane_weight,
                slab_weight,
            );
            placements.solutions.push(solved);
            for (k, &f) in frames.iter().enumerate() {
                let frame = &obs.frames[f];
                let start = first_column[k];
                if let Load::Needle(shaft) = frame.load {
                    entries[frame.trial]
                        .push((shaft.length, out.entry_offsets[start] / shaft.length));
                }
                let part = &out.nonlinear[start];
                let mut response = match frame.load {
                    Load::Probe { force_sigma, .. } => Some(ProbeResponse {
                        start: frame_offset[f],
                        unit_x: Vec::with_capacity(2 * frame.markers.len()),
                        unit_y: Vec::with_capacity(2 * frame.markers.len()),
                        force_sigma,
                    }),
                    _ => None,
                };
                for (j, &(m, _)) in frame.markers.iter().enumerate() {
                    let nl = at(&part.displacement, m);
                    let u = match frame.load {
                        Load::Probe { force, moment, .. } => {
                            let gx = out.displacement[start][m];
                            let gy = out.displacement[start + 1][m];
                            let gm = out.displacement[start + 2][m];
                            if let Some(r) = response.as_mut() {
                                // d u / d F: the nonlinear part's share too.
                                let [sx, sy] = [0, 1].map(|a| at(&part.sensitivity[a], m));
                                r.unit_x.extend_from_slice(&[gx[0] + sx[0], gx[1] + sx[1]]);
                                r.unit_y.extend_from_slice(&[gy[0] + sy[0], gy[1] + sy[1]]);
                            }
                            [
                                force[0] * gx[0] + force[1] * gy[0] + moment * gm[0] + nl[0],
                                force[0] * gx[1] + force[1] * gy[1] + moment * gm[1] + nl[1],
                            ]
                        }
                        Load::Needle(_) => {
                            let d = out.displacement[start][m];
                            [d[0] + nl[0], d[1] + nl[1]]
                        }
                        Load::Free => [0.0; 2],
                    };
                    let rest = obs.rest[m];
                    let mut position = [rest[0] + u[0], rest[1] + u[1]];
                    for (effect, own) in model.effects_with(p) {
                        position = effect.measured_position(own, &self.geometry, position);
                    }
                    let slot = frame_offset[f] + 2 * j;
                    values[slot] = position[0] - rest[0];
                    values[slot + 1] = position[1] - rest[1];
                }
                probe_responses.extend(response);
            }
        }
        for table in &mut entries {
            table.sort_by(|a, b| a.0.total_cmp(&b.0));
        }
        for (k, sample) in obs.forces.iter().enumerate() {
            if let Some(shaft) = sample.shaft {
                let ratio = interpolate_ratio(&entries[sample.trial], shaft.length);
                let length = shaft.length * (1.0 - ratio);
                let total = self.shaft_force(model, p, &obs.trials[sample.trial], length);
                values[marker_count + 2 * k] = total * shaft.direction[0];
                values[marker_count + 2 * k + 1] = total * shaft.direction[1];
            }
        }
        probe_responses.sort_by_key(|r| r.start);
        Ok((
            Prediction {
                values,
                probe_responses,
            },
            placements,
        ))
    }
}

/// Whether two material fields differ by a uniform factor, to rounding:
/// the grouping must not hinge on the last bit of a ratio, or a
/// finite-difference step could regroup the trials.
fn proportional(a: &[f64], b: &[f64]) -> bool {
    let (Some(&a0), Some(&b0)) = (a.first(), b.first()) else {
        return a.len() == b.len();
    };
    a.len() == b.len()
        && a.iter()
            .zip(b)
            .all(|(x, y)| ((x / a0) - (y / b0)).abs() <= 1e-12 * (y / b0).abs())
}

/// The entry offset per unit length at `length`, interpolated linearly in
/// the `(length, ratio)` table of a trial's frames (sorted by length), held
/// constant beyond its ends; 0 for a trial without needle frames. The
/// force samples outnumber the frames; the offset grows smoothly with the
/// inserted length, as the load does.
fn interpolate_ratio(table: &[(f64, f64)], length: f64) -> f64 {
    match table {
        [] => 0.0,
        [(_, only)] => *only,
        [(first_length, first), ..] if length <= *first_length => *first,
        [.., (last_length, last)] if length >= *last_length => *last,
        _ => {
            let upper = table.partition_point(|&(l, _)| l < length);
            let (l0, r0) = table[upper - 1];
            let (l1, r1) = table[upper];
            if l1 > l0 {
                r0 + (r1 - r0) * (length - l0) / (l1 - l0)
            } else {
                r1
            }
        }
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use needle_data::{BundleBuilder, MarkerRest, Phantom, ToolSample, Trial, TrialKind};

    use super::*;
    use crate::effect::catalog;
    use crate::model::Baseline;
    use crate::spec::ModelSpec;

    /// A small campaign: one probe frame and one needle frame on a 5 x 5
    /// marker grid (positions are irrelevant: only predictions are compared).
    fn observations() -> Observations {
        observations_of(&[
            ("probe", TrialKind::Probe, 2.0, 0.0),
            ("needle", TrialKind::Needle, 3.0, 0.04),
        ])
    }

    /// A campaign of one frame per trial `(id, kind, day, tip y)` on the
    /// grid of [`observations`].
    pub(crate) fn observations_of(trials: &[(&str, TrialKind, f64, f64)]) -> Observations {
        let mut builder = BundleBuilder::new(
            "tiny",
            Phantom {
                width: 0.075,
                depth: 0.075,
                thickness: 0.0075,
                fixed: vec![needle_data::Face::Back],
            },
        );
        let grid = MarkerGrid::uniform(5, 5, (0.01, 0.01), (0.065, 0.065));
        builder.markers_rest(
            grid.points()
                .iter()
                .enumerate()
                .map(|(id, p)| MarkerRest {
                    id: id as u32,
                    x: p[0],
                    y: p[1],
                })
                .collect(),
        );
        let frame: Vec<(u32, [f64; 2])> = grid
            .points()
            .iter()
            .enumerate()
            .map(|(id, p)| (id as u32, *p))
            .collect();
        for &(id, kind, day, tip_y) in trials {
            let trial = builder.trial(Trial {
                id: id.into(),
                kind,
                velocity: 0.005,
                day,
            });
            trial.tool.push(ToolSample {
                t: 0.0,
                tip_x: 0.03,
                tip_y,
                theta: 0.1,
                fx: 0.05,
                fy: 0.2,
                mz: 0.0,
            });
            trial
                .markers_mut()
                .push_frame(0, 0.0, frame.clone())
                .unwrap();
        }
        Observations::from_campaign(&builder.finish(), 1, 0.005, 0, 1.0).unwrap()
    }

    pub(crate) fn paper_phantom() -> Phantom {
        Phantom {
            width: 0.075,
            depth: 0.075,
            thickness: 0.0075,
            fixed: vec![needle_data::Face::Back],
        }
    }

    #[test]
    fn the_slab_is_graded_towards_needles_along_an_axis_only() {
        let uniform = RectangleMesh::uniform(0.08, 0.08, 8, 8).unwrap();
        let h = 0.01;
        let along_y = ([0.03, 0.0], [0.0, 1.0]);
        let oblique = ([0.05, 0.0], [0.6, 0.8]);
        let graded = graded_towards_needles(uniform.clone(), &[along_y, oblique, along_y]);
        // The needle's line is already a line; half a spacing either side
        // is new, nothing for the oblique needle or for the repeat.
        let expected_x: Vec<f64> = {
            let mut v = uniform.x_lines.clone();
            v.extend([0.03 - 0.5 * h, 0.03 + 0.5 * h]);
            v.sort_by(f64::total_cmp);
            v
        };
        let close = |a: &[f64], b: &[f64]| {
            a.len() == b.len() && a.iter().zip(b).all(|(p, q)| (p - q).abs() < 1e-12)
        };
        assert!(close(&graded.x_lines, &expected_x), "{:?}", graded.x_lines);
        let mut expected_y = uniform.y_lines.clone();
        expected_y.extend([0.125 * h, 0.25 * h, 0.5 * h]);
        expected_y.sort_by(f64::total_cmp);
        assert!(close(&graded.y_lines, &expected_y), "{:?}", graded.y_lines);
        // A needle along x entering the side x = 0.08 grades y around its
        // line and x inwards from that side; sides are never moved.
        let along_x = ([0.08, 0.0401], [-1.0, 0.0]);
        let graded = graded_towards_needles(uniform.clone(), &[along_x]);
        assert_eq!(graded.x_lines.first(), Some(&0.0));
        assert_eq!(graded.x_lines.last(), Some(&0.08));
        for x in [0.08 - 0.5 * h, 0.08 - 0.25 * h, 0.08 - 0.125 * h] {
            assert!(graded.x_lines.iter().any(|l| (l - x).abs() < 1e-12), "{x}");
        }
        // 0.0401 is within h/16 of the line at 0.04: left out.
        assert!(!graded.y_lines.iter().any(|l| (l - 0.0401).abs() < 1e-12));
        assert!(
            graded
                .y_lines
                .iter()
                .any(|l| (l - (0.0401 + 0.5 * h)).abs() < 1e-12)
        );
        let plan = graded.build(ElementKind::Tri6);
        assert!(plan.is_ok());
    }

    #[test]
    fn a_needle_as_thick_as_a_quarter_of_the_phantom_is_refused() {
        let obs = observations();
        let refused = Forward::new(&paper_phantom(), &obs.rest, 1, 1, &[], 0.25 * 0.0075);
        assert!(matches!(
            refused,
            Err(DiagnoseError::InvalidOption {
                field: "needle_radius",
                ..
            })
        ));
    }

    /// The observations of [`observations`] on the paper's phantom, its
    /// forward model and a baseline start.
    fn paper_forward() -> (Observations, Forward, Baseline) {
        paper_forward_of(observations())
    }

    /// `obs` on the paper's phantom, its forward model and a baseline start.
    pub(crate) fn paper_forward_of(obs: Observations) -> (Observations, Forward, Baseline) {
        let forward = Forward::new(&paper_phantom(), &obs.rest, 1, 1, &[], 0.0).unwrap();
        let start = Baseline {
            youngs_modulus: 25.0e3,
            poisson_ratio: 0.45,
            shaft_density: 10.0,
            probe_width: 0.002,
        };
        (obs, forward, start)
    }

    #[test]
    fn every_effect_is_silent_at_its_null_and_acts_off_it() {
        let (obs, forward, start) = paper_forward();
        let baseline = Model::new(&ModelSpec::baseline(), &forward.geometry, start).unwrap();
        let p0: Vec<f64> = baseline.parameters.iter().map(|p| p.initial).collect();
        let reference = forward.predict(&baseline, &p0, &obs).unwrap().values;
        assert!(reference.iter().any(|v| v.abs() > 1e-5));
        for effect in catalog() {
            let model = with_effect(&forward, start, effect.id());
            let mut p = p0.clone();
            p.extend(model.parameters[p0.len()..].iter().map(|q| q.null));
            let at_null = forward.predict(&model, &p, &obs).unwrap().values;
            for (a, b) in at_null.iter().zip(&reference) {
                assert!(
                    (a - b).abs() <= 1e-12 + 1e-9 * b.abs(),
                    "{}: {a} vs {b}",
                    effect.id()
                );
            }
            for (k, q) in model.parameters.iter().enumerate().skip(p0.len()) {
                if q.tested {
                    p[k] = q.null + 0.5 * q.scale;
                }
            }
            let moved = forward.predict(&model, &p, &obs).unwrap().values;
            let change = moved
                .iter()
                .zip(&reference)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            assert!(
                change > 1e-7,
                "{} changes nothing off its null ({change})",
                effect.id()
            );
        }
    }

    #[test]
    fn trials_that_differ_by_a_stiffening_are_solved_together_as_each_alone() {
        // Days 2 and 3 stiffen the phantom by different uniform factors, so
        // the two trials share one factorisation and one solve; each alone
        // has its own.
        let (both, forward, start) = paper_forward();
        let ids = [
            "material_stiffening",
            "out_of_plane",
            "material_nonlinearity",
        ];
        let model = with_effects(&forward, start, &ids);
        let p = [25.0e3, 0.45, 10.0, 0.002, 0.05, 0.6, 0.5];
        let whole = forward.predict(&model, &p, &both).unwrap();
        let probe = observations_of(&[("probe", TrialKind::Probe, 2.0, 0.0)]);
        let needle = observations_of(&[("needle", TrialKind::Needle, 3.0, 0.04)]);
        let probe_alone = forward.predict(&model, &p, &probe).unwrap();
        let needle_alone = forward.predict(&model, &p, &needle).unwrap();
        // Markers of the probe frame, of the needle frame, then the needle's forces.
        let alone: Vec<f64> = [
            &probe_alone.values[..probe.marker_count()],
            &needle_alone.values[..],
        ]
        .concat();
        assert_eq!(whole.values.len(), alone.len());
        let largest = whole.values.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        assert!(largest > 1e-5);
        for (a, b) in whole.values.iter().zip(&alone) {
            assert!((a - b).abs() <= 1e-10 * largest, "{a} vs {b}");
        }
        assert_eq!(whole.probe_responses.len(), 1);
        let (together, apart) = (&whole.probe_responses[0], &probe_alone.probe_responses[0]);
        for (a, b) in together.unit_x.iter().zip(&apart.unit_x) {
            assert!((a - b).abs() <= 1e-10 * a.abs().max(1e-12), "{a} vs {b}");
        }
    }

    /// The baseline plus one effect.
    fn with_effect(forward: &Forward, start: Baseline, id: &str) -> Model {
        with_effects(forward, start, &[id])
    }

    /// The baseline plus the effects `ids`.
    fn with_effects(forward: &Forward, start: Baseline, ids: &[&str]) -> Model {
        Model::new(&ModelSpec::from_ids(ids).unwrap(), &forward.geometry, start).unwrap()
    }

    #[test]
    fn needle_force_integrates_the_density() {
        let (mut obs, forward, start) = paper_forward();
        // Without a needle frame nothing moves the entry: the whole
        // measured length is inserted.
        obs.frames.retain(|f| !matches!(f.load, Load::Needle(_)));
        let model = with_effect(&forward, start, "tip_cutting_force");
        // q0 = 10 N/m, peak twice that (relative 2) over 5 mm, so an
        // excess length of 5 mm: F = 10 L + 20 * 0.005 / 2.
        let p = [25.0e3, 0.45, 10.0, 0.002, 0.005, 0.005];
        let values = forward.predict(&model, &p, &obs).unwrap().values;
        let m = obs.marker_count();
        let length = 0.04 / 0.1f64.cos();
        let total = 10.0 * length + 0.05;
        assert!((values[m] - total * -(0.1f64.sin())).abs() < 1e-12);
        assert!((values[m + 1] - total * 0.1f64.cos()).abs() < 1e-12);
    }

    /// The tip peak multiplies the friction density: with friction that
    /// grows with speed the peak grows with it,
    /// $F = (q_0 + q_1 v)(L + e)$, $e = A w / 2$ the peak's excess length.
    #[test]
    fn the_tip_peak_scales_with_the_speed_dependent_friction() {
        let (_, forward, start) = paper_forward();
        let model = with_effects(
            &forward,
            start,
            &["velocity_dependent_friction", "tip_cutting_force"],
        );
        // q0 = 10 N/m, q1 = 500 N s/m^2, peak of relative height 1 over 6 mm
        // (an excess length of 3 mm).
        let p = [25.0e3, 0.45, 10.0, 0.002, 500.0, 0.003, 0.006];
        let length = 0.03;
        for velocity in [0.001, 0.009] {
            let trial = TrialContext {
                kind: TrialKind::Needle,
                velocity,
                day: 2.0,
            };
            let force = forward.shaft_force(&model, &p, &trial, length);
            let expected = (10.0 + 500.0 * velocity) * (length + 0.006 / 2.0);
            assert!(
                (force - expected).abs() < 1e-12,
                "{velocity}: {force} vs {expected}"
            );
        }
    }

    #[test]
    fn entry_ratio_is_interpolated_between_frames_and_held_beyond() {
        let table = [(0.01, 0.04), (0.03, 0.06), (0.03, 0.07), (0.05, 0.05)];
        assert_eq!(interpolate_ratio(&[], 0.02), 0.0);
        assert_eq!(interpolate_ratio(&table[..1], 0.5), 0.04);
        assert_eq!(interpolate_ratio(&table, 0.001), 0.04);
        assert_eq!(interpolate_ratio(&table, 0.08), 0.05);
        assert!((interpolate_ratio(&table, 0.02) - 0.05).abs() < 1e-15);
        assert!((interpolate_ratio(&table, 0.04) - 0.06).abs() < 1e-15);
    }

    #[test]
    fn the_dragged_entry_shortens_the_inserted_shaft() {
        let (obs, forward, start) = paper_forward();
        let model = with_effect(&forward, start, "tip_cutting_force");
        let p = [25.0e3, 0.45, 10.0, 0.002, 0.005, 0.005];
        let values = forward.predict(&model, &p, &obs).unwrap().values;
        let m = obs.marker_count();
        let length = 0.04 / 0.1f64.cos();
        let force = values[m].hypot(values[m + 1]);
        // The shaft drags the front face in by millimetres (a load of
        // 0.45 N on 25 kPa x 7.5 mm), so the base force falls short of the
        // whole length's by the density times the entry's offset.
        let shortfall = (10.0 * length + 0.05 - force) / 10.0;
        assert!(
            shortfall > 1e-3 && shortfall < 4e-3,
            "entry offset {shortfall} m"
        );
    }

    /// The largest differences between two predictions over the first `m`
    /// values (the markers) and over the rest (the forces).
    fn largest_gaps(a: &[f64], b: &[f64], m: usize) -> (f64, f64) {
        let gap =
            |range: std::ops::Range<usize>| range.map(|i| (a[i] - b[i]).abs()).fold(0.0, f64::max);
        (gap(0..m), gap(m..a.len()))
    }

    #[test]
    fn placement_rounds_have_converged_far_below_the_noise() {
        let (obs, mut forward, start) = paper_forward();
        let model = with_effect(&forward, start, "tip_cutting_force");
        // The paper's phantom and a tip peak: the shaft drags the entry
        // in by about 2 mm.
        let p = [25.0e3, 0.45, 10.0, 0.002, 0.005, 0.005];
        let m = obs.marker_count();
        let used = forward.predict(&model, &p, &obs).unwrap().values;
        forward.placement_rounds = 12;
        let converged = forward.predict(&model, &p, &obs).unwrap().values;
        let (marker_gap, force_gap) = largest_gaps(&used, &converged, m);
        // 0.05 um against micrometres of marker noise, 1 uN against
        // millinewtons of force noise.
        assert!(marker_gap < 5e-8, "marker gap {marker_gap} m");
        assert!(force_gap < 1e-6, "force gap {force_gap} N");
        // Loading the spatial line instead is off by far more than the
        // noise.
        forward.placement_rounds = 0;
        let spatial = forward.predict(&model, &p, &obs).unwrap().values;
        let (marker_change, force_change) = largest_gaps(&spatial, &converged, m);
        assert!(marker_change > 5e-5, "markers move {marker_change} m");
        assert!(force_change > 5e-3, "force changes {force_change} N");
    }

    #[test]
    fn the_slab_places_its_own_load_and_its_rounds_have_converged() {
        let (obs, mut forward, start) = paper_forward();
        let model = with_effect(&forward, start, "out_of_plane");
        let p = [25.0e3, 0.45, 10.0, 0.002, 1.0];
        let m = obs.marker_count();
        let used = forward.predict(&model, &p, &obs).unwrap().values;
        forward.slab_placement_rounds = 12;
        let converged = forward.predict(&model, &p, &obs).unwrap().values;
        let (marker_gap, force_gap) = largest_gaps(&used, &converged, m);
        // Measured 8.5 nm and 1.3 uN, against micrometres of marker noise
        // and millinewtons of force noise.
        assert!(marker_gap < 5e-8, "marker gap {marker_gap} m");
        assert!(force_gap < 5e-6, "force gap {force_gap} N");
        // The plane's placement loaded on the slab as it is (29 um at the
        // markers, 5.1 mN in the base force through the entry's drag):
        // the slab drags its mid-plane along the needle differently.
        forward.slab_placement_rounds = 0;
        let plane_placed = forward.predict(&model, &p, &obs).unwrap().values;
        let (marker_change, force_change) = largest_gaps(&plane_placed, &converged, m);
        assert!(marker_change > 1e-5, "markers move {marker_change} m");
        assert!(force_change > 2e-3, "force changes {force_change} N");
    }

    #[test]
    fn rounds_solved_near_the_needle_predict_as_rounds_solved_whole() {
        // A slab fine enough for faer's supernodal factor, which the near
        // solves need (a simplicial one, as the plane's here, is solved
        // whole); the slab's predictions differed by 3.5e-18 m.
        let (obs, _, start) = paper_forward();
        let mut forward = Forward::new(&paper_phantom(), &obs.rest, 8, 6, &[], 0.0).unwrap();
        let m = obs.marker_count();
        for spec in ["velocity_dependent_friction", "out_of_plane"] {
            let model = with_effect(&forward, start, spec);
            let p: Vec<f64> = (model.parameters.iter())
                .map(|q| {
                    if q.tested {
                        q.null + 0.5 * q.scale
                    } else {
                        q.initial
                    }
                })
                .collect();
            forward.near_solves = true;
            let near = forward.predict(&model, &p, &obs).unwrap().values;
            forward.near_solves = false;
            let whole = forward.predict(&model, &p, &obs).unwrap().values;
            // The same arithmetic in another order: rounding alone.
            let (marker_gap, force_gap) = largest_gaps(&near, &whole, m);
            assert!(marker_gap < 1e-13, "{spec}: marker gap {marker_gap} m");
            assert!(force_gap < 1e-11, "{spec}: force gap {force_gap} N");
        }
    }

    #[test]
    fn differences_placed_from_the_base_match_the_models_own() {
        // The model's rounds: measured at most 0.5% (the base force in E).
        differences_placed_from_the_base_are_within(crate::place::NEAR_ROUNDS, 0.01, 0.01);
    }

    #[test]
    fn the_ranking_s_differences_placed_from_the_base_match_the_models_own() {
        // Measured at most 0.6% at the markers (E) and 2.5% in the base
        // force (nu).
        differences_placed_from_the_base_are_within(crate::place::RANKING_NEAR_ROUNDS, 0.01, 0.03);
    }

    /// Finite-difference derivatives with the loads placed from the base
    /// point's placements in `rounds` rounds are within `marker` and
    /// `force` (relative to the largest) of the model's own.
    fn differences_placed_from_the_base_are_within(rounds: usize, marker: f64, force: f64) {
        let (obs, forward, start) = paper_forward();
        let model = with_effects(&forward, start, &["tip_cutting_force", "out_of_plane"]);
        let p = [25.0e3, 0.45, 10.0, 0.002, 0.005, 0.005, 0.7];
        let (cold, placements) = forward.predict_from(&model, &p, &obs, Start::Cold).unwrap();
        let near = |p: &[f64]| {
            let start = Start::Near {
                placements: &placements,
                rounds,
            };
            forward
                .predict_from(&model, p, &obs, start)
                .unwrap()
                .0
                .values
        };
        let m = obs.marker_count();
        let base = near(&p);
        let (marker_gap, force_gap) = largest_gaps(&base, &cold.values, m);
        assert!(marker_gap < 5e-8, "marker gap {marker_gap} m");
        assert!(force_gap < 5e-6, "force gap {force_gap} N");
        // Every parameter that moves the needle load or its placement: E, nu,
        // the shaft density, the tip peak and width, the slab's weight.
        for k in [0, 1, 2, 4, 5, 6] {
            let h = 1e-4 * p[k].abs();
            let mut moved = p.to_vec();
            moved[k] += h;
            let exact: Vec<f64> = forward
                .predict(&model, &moved, &obs)
                .unwrap()
                .values
                .iter()
                .zip(&cold.values)
                .map(|(a, b)| (a - b) / h)
                .collect();
            let approximate: Vec<f64> = near(&moved)
                .iter()
                .zip(&base)
                .map(|(a, b)| (a - b) / h)
                .collect();
            for (range, bound) in [(0..m, marker), (m..exact.len(), force)] {
                let size = range.clone().map(|i| exact[i].abs()).fold(0.0, f64::max);
                let error = range
                    .map(|i| (approximate[i] - exact[i]).abs())
                    .fold(0.0, f64::max);
                assert!(
                    error <= bound * size,
                    "{rounds} rounds, parameter {k}: derivative off by {error:e} of {size:e}"
                );
            }
        }
    }

    /// Every catalog effect's [`crate::effect::Effect::chain`] claims,
    /// checked on the whole forward model (with the slab at weight 0.7)
    /// against columns differenced as a fit differences them.
    #[test]
    fn columns_of_chained_parameters_are_multiples_of_the_baseline_s() {
        let mut obs = observations_of(&[
            ("probe", TrialKind::Probe, 2.0, 0.0),
            ("needle-slow", TrialKind::Needle, 1.0, 0.04),
            ("needle-fast", TrialKind::Needle, 5.0, 0.03),
        ]);
        obs.trials[1].velocity = 0.001;
        obs.trials[2].velocity = 0.009;
        let (obs, forward, start) = paper_forward_of(obs);
        let rows = obs.row_trials();
        let mut chained = Vec::new();
        for effect in catalog().iter().filter(|e| e.id() != "out_of_plane") {
            let model = with_effects(&forward, start, &[effect.id(), "out_of_plane"]);
            let mut p = vec![25.0e3, 0.45, 8.0, 0.002];
            let own = &model.parameters[p.len()..model.len() - 1];
            p.extend(own.iter().map(|q| {
                let v = q.initial + 0.3 * q.scale;
                v.clamp(q.lower.unwrap_or(v), q.upper.unwrap_or(v))
            }));
            p.push(0.7);
            let (_, placements) = forward.predict_from(&model, &p, &obs, Start::Cold).unwrap();
            let near = |p: &[f64]| {
                let start = Start::Near {
                    placements: &placements,
                    rounds: crate::place::NEAR_ROUNDS,
                };
                forward
                    .predict_from(&model, p, &obs, start)
                    .unwrap()
                    .0
                    .values
            };
            let base = near(&p);
            assert_eq!(rows.len(), base.len());
            let column = |k: usize| -> Vec<f64> {
                let h = 1e-5 * model.parameters[k].scale.max(p[k].abs());
                let mut moved = p.clone();
                moved[k] += h;
                near(&moved)
                    .iter()
                    .zip(&base)
                    .map(|(a, b)| (a - b) / h)
                    .collect()
            };
            for k in 0..model.len() {
                let Some((source, per_trial)) = model.chain(&p, k, &obs.trials) else {
                    continue;
                };
                chained.push((effect.id(), source));
                let (differenced, of_source) = (column(k), column(source));
                let size = differenced.iter().map(|d| d.abs()).fold(0.0, f64::max);
                assert!(size > 0.0, "{}", effect.id());
                let error = differenced
                    .iter()
                    .zip(&of_source)
                    .zip(&rows)
                    .map(|((d, s), &t)| (d - per_trial[t] * s).abs())
                    .fold(0.0, f64::max);
                assert!(
                    error < 1e-4 * size,
                    "{}: {error:e} of {size:e}",
                    effect.id()
                );
            }
        }
        assert_eq!(
            chained,
            [
                ("velocity_dependent_friction", 2),
                ("material_stiffening", 0)
            ]
        );
    }

    #[test]
    fn columns_of_parameters_acting_after_the_solves_take_the_base_s_solutions_to_the_bit() {
        let (obs, forward, start) = paper_forward();
        let model = with_effects(
            &forward,
            start,
            &["tip_cutting_force", "out_of_plane", "lens_distortion"],
        );
        let p = [25.0e3, 0.45, 10.0, 0.002, 0.005, 0.005, 0.7, 0.02];
        let (_, cold) = forward.predict_from(&model, &p, &obs, Start::Cold).unwrap();
        let near = Start::Near {
            placements: &cold,
            rounds: crate::place::RANKING_NEAR_ROUNDS,
        };
        let (_, solved) = forward.predict_from(&model, &p, &obs, near).unwrap();
        // The slab's weight and the lens: the solutions serve.
        for k in [6, 7] {
            let mut moved = p.to_vec();
            moved[k] += 1e-3;
            assert!(model.solves_alike(&p, &moved));
            assert!(solved.serve(&model, &moved));
            let (solving, _) = forward.predict_from(&model, &moved, &obs, near).unwrap();
            let reuse = Start::Reuse { solved: &solved };
            let (reusing, _) = forward.predict_from(&model, &moved, &obs, reuse).unwrap();
            assert_eq!(reusing.values, solving.values, "parameter {k}");
            for (a, b) in reusing.probe_responses.iter().zip(&solving.probe_responses) {
                assert_eq!((&a.unit_x, &a.unit_y), (&b.unit_x, &b.unit_y));
            }
        }
        // Everything else is solved again.
        for k in 0..6 {
            let mut moved = p.to_vec();
            moved[k] *= 1.001;
            assert!(!model.solves_alike(&p, &moved), "parameter {k}");
        }
        // Solutions without the slab do not serve a point that weighs it.
        let mut planar = p.to_vec();
        planar[6] = 0.0;
        let (_, without) = forward
            .predict_from(&model, &planar, &obs, Start::Cold)
            .unwrap();
        assert!(without.serve(&model, &planar));
        assert!(!without.serve(&model, &p));
    }

    /// Without a foundation the slab is its upper half; any foundation
    /// takes the whole mirrored slab. The two must agree at zero, or a
    /// finite-difference step off it would difference the meshes: the
    /// half's prediction at 0 against the whole's extrapolated from
    /// $\epsilon$ and $2\epsilon$.
    #[test]
    fn the_slab_halved_at_no_foundation_is_the_whole_slabs_limit() {
        let (obs, forward, start) = paper_forward();
        let model = with_effects(&forward, start, &["out_of_plane", "platform_friction"]);
        let scale = model.parameters[5].scale;
        let at = |foundation: f64| {
            forward
                .predict(&model, &[25.0e3, 0.45, 10.0, 0.002, 1.0, foundation], &obs)
                .unwrap()
                .values
        };
        let epsilon = 1e-6 * scale;
        let (half, once, twice) = (at(0.0), at(epsilon), at(2.0 * epsilon));
        assert!(forward.whole_slab.lock().unwrap().is_some());
        let largest = half.iter().map(|v| v.abs()).fold(0.0, f64::max);
        let (mut gap, mut step) = (0.0f64, 0.0f64);
        for ((h, a), b) in half.iter().zip(&once).zip(&twice) {
            gap = gap.max((h - (2.0 * a - b)).abs());
            step = step.max((b - a).abs());
        }
        println!("largest {largest:.3e}, step {step:.3e}, half vs whole at 0 {gap:.3e}");
        assert!(step > 0.0, "the foundation acts");
        assert!(gap <= 1e-9 * largest, "gap {gap} of {largest}");
        // At the step the score test takes, the mesh's rounding is far
        // below the foundation's own effect.
        let score_step = at(1e-3 * scale);
        let effect = score_step
            .iter()
            .zip(&half)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(gap < 1e-6 * effect, "gap {gap}, effect {effect}");
    }

    #[test]
    fn a_foundation_prepared_ahead_predicts_as_one_made_at_first_use() {
        let (obs, ahead, start) = paper_forward();
        let (_, at_first_use, _) = paper_forward();
        let plane_only = with_effect(&ahead, start, "platform_friction");
        ahead
            .prepare_foundation(&plane_only, &[25.0e3, 0.45, 10.0, 0.002, 0.0])
            .unwrap();
        assert!(ahead.whole_slab.lock().unwrap().is_none(), "no slab in use");
        let model = with_effects(&ahead, start, &["out_of_plane", "platform_friction"]);
        let p = [25.0e3, 0.45, 10.0, 0.002, 1.0, 0.0];
        ahead.prepare_foundation(&model, &p).unwrap();
        let whole = ahead.whole_slab.lock().unwrap().clone().unwrap();
        assert_eq!(whole.template_layouts(), [[false, true]]);
        let mut founded = p;
        founded[5] = 10.0 * model.parameters[5].scale;
        let predicted = ahead.predict(&model, &founded, &obs).unwrap().values;
        let fresh = at_first_use.predict(&model, &founded, &obs).unwrap().values;
        assert_eq!(predicted, fresh);
        // Made once: the prediction used the body and template prepared.
        assert!(Arc::ptr_eq(
            &whole,
            ahead.whole_slab.lock().unwrap().as_ref().unwrap()
        ));
        assert_eq!(whole.template_layouts(), [[false, true]]);
    }

    #[test]
    fn slab_weight_blends_the_plane_and_the_slab_linearly() {
        let (obs, forward, start) = paper_forward();
        let model = with_effect(&forward, start, "out_of_plane");
        // Marker values only: the base force does not depend on the kinematics.
        let at = |w: f64| {
            let mut values = forward
                .predict(&model, &[25.0e3, 0.45, 10.0, 0.002, w], &obs)
                .unwrap()
                .values;
            values.truncate(obs.marker_count());
            values
        };
        let (plane, slab, half) = (at(0.0), at(1.0), at(0.5));
        let largest = slab.iter().map(|v| v.abs()).fold(0.0, f64::max);
        // The slab's top face moves differently from the plane model.
        let gap = plane
            .iter()
            .zip(&slab)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(gap > 0.05 * largest, "gap {gap} of {largest}");
        for ((a, b), h) in plane.iter().zip(&slab).zip(&half) {
            assert!((0.5 * (a + b) - h).abs() <= 1e-12 * largest.max(1e-12));
        }
    }

    #[test]
    fn nonlinear_weight_adds_its_terms_linearly_to_every_channel() {
        let (obs, forward, start) = paper_forward();
        let model = with_effect(&forward, start, "material_nonlinearity");
        let at = |w: f64| {
            forward
                .predict(&model, &[25.0e3, 0.45, 10.0, 0.002, w], &obs)
                .unwrap()
        };
        let (linear, full, half) = (at(0.0), at(1.0), at(0.5));
        let m = obs.marker_count();
        let largest = |range: std::ops::Range<usize>, v: &[f64]| {
            range.map(|i| v[i].abs()).fold(0.0, f64::max)
        };
        let change = |range: std::ops::Range<usize>| {
            let gap: Vec<f64> = full
                .values
                .iter()
                .zip(&linear.values)
                .map(|(a, b)| a - b)
                .collect();
            largest(range, &gap)
        };
        // The 0.2 N probe and the needle strain the soft phantom by several
        // percent at the markers: micrometres of marker change, and the
        // entry's drag changes the base force.
        let marker_change = change(0..m);
        assert!(
            marker_change > 1e-6 && marker_change < 0.3 * largest(0..m, &linear.values),
            "markers move by {marker_change} m"
        );
        assert!(change(m..linear.values.len()) > 1e-6);
        for ((a, b), h) in linear.values.iter().zip(&full.values).zip(&half.values) {
            assert!((0.5 * (a + b) - h).abs() <= 1e-12 * (1.0 + a.abs()));
        }
        // The probe frame's force sensitivity includes the nonlinear terms.
        assert_ne!(linear.probe_responses, full.probe_responses);
        // With the slab's kinematics the same terms (the plane's) are added.
        let both = with_effects(&forward, start, &["out_of_plane", "material_nonlinearity"]);
        let slab = |w: f64| {
            forward
                .predict(&both, &[25.0e3, 0.45, 10.0, 0.002, 1.0, w], &obs)
                .unwrap()
                .values
        };
        let (slab_linear, slab_full) = (slab(0.0), slab(1.0));
        for i in 0..m {
            let on_plane = full.values[i] - linear.values[i];
            let on_slab = slab_full[i] - slab_linear[i];
            assert!(
                (on_plane - on_slab).abs() <= 1e-12,
                "{i}: {on_plane} vs {on_slab}"
            );
        }
    }
}
