//! The needle trials of the 3-D slab settled on a second, finer mesh
//! than the one their consistency iteration starts on, and their markers
//! read there.
//!
//! On the paper default's slab the final markers of a 1 mm/s insertion
//! are 4.5 um (0.57 of the marker noise) from the convergence test's
//! reference. Most of that is the field's error, not the placement's
//! (the same loads applied to the reference mesh give markers 0.5 um
//! from the reference's own), so up to session 37 the truth only read
//! the markers of the placed load on the finer mesh. That left the
//! placement's own error, which is largest just after the entry when the
//! tip's cutting force sits next to the free front face: 1.8 um on the
//! fine paper default's placement mesh, more than a micrometre from one
//! placement mesh to the next with no steady trend (`docs/truth-world.md`,
//! The 3-D slab).
//!
//! So with `resolution.marker_grading` set, the truth places the needle
//! on the slab of `resolution.slab_grading` first, where the kept columns
//! of $K^{-1}$ make the consistency iteration cheap, and then goes on
//! with the same iteration on the slab of `marker_grading`, from the
//! loads found (their material points and forces) until the placement on
//! that slab is consistent: every state $d$ satisfies
//! $$X_j + u_f(X_j) = p_j(d),\qquad u_f = K_f^{-1} f_f(X, d),$$
//! on the finer mesh, to [`crate::needle::CONSISTENCY_TOLERANCE`]. The
//! states are independent, so the iterations of up to
//! [`SOLVE_BLOCK`] of them share each back-substitution; the fields are
//! full vectors of the finer mesh, kept only while their state is open.
//! Markers, entry, base force, loads and the last state's tip material
//! point are those of the finer mesh; probes and strains stay those of
//! the placement mesh.
//!
//! A `marker_grading` refined locally (`SlabGrading::local`) is refined
//! towards where the loads acted in the material, which the placement
//! has found: every point each state's shaft held, and the path of its
//! entry on the front face ([`material_paths`]). Refined on the needle's
//! line instead, the entry's rim leaves the fine cells as the tissue is
//! carried sideways (3.6 mm on the paper default's last insertion), and
//! the base force changed by up to 3e-4 from one grading to the next
//! with no trend; along the material path, grading 1, 0.7 and 0.5 move
//! the markers by 1.57 um and then 0.32 um (`docs/truth-world.md`, The
//! 3-D slab). Each insertion then has a slab of its own, meshed with no
//! lines of the other trials ([`insertion_alone`]) and factorised one
//! after the other: one slab along all ten of the fine paper default's
//! needle lines has 2.9 M dofs, against 0.7 M for one.
//!
//! Every state is solved on the finer mesh: reading the correction
//! $m_f - m_c$ between every fifth state by cubics was 1.7 um off at some
//! states, because the placement mesh's error jumps as the loaded points
//! cross its elements (every second state: 0.6 um).

use rayon::prelude::*;

use crate::error::SynthError;
use crate::needle::{NeedleRun, Placement, Rim, StateIteration, material_point, place};
use crate::scenario::{NeedlePlan, Scenario};
use crate::slab_mesh::MaterialPaths;
use crate::world::{Response, World};

/// States whose iterations share a back-substitution of the finer mesh:
/// blocks are solved in parallel, and each state's fields (full vectors of
/// the finer mesh) are dropped once it is settled.
const SOLVE_BLOCK: usize = 32;

/// The scenario of the marker mesh, when `scenario` has one: a 3-D slab
/// (`out_of_plane`) of linear material with `resolution.marker_grading`
/// set. It differs from `scenario` in its slab grading only.
pub(crate) fn marker_scenario(scenario: &Scenario) -> Option<Scenario> {
    let e = &scenario.effects;
    let grading = scenario.resolution.marker_grading?;
    if e.out_of_plane.is_none() || e.material_nonlinearity.is_some() {
        return None;
    }
    let mut fine = scenario.clone();
    fine.resolution.slab_grading = Some(grading);
    fine.resolution.marker_grading = None;
    Some(fine)
}

/// Whether the marker mesh of `marker_scenario` is refined locally, and
/// so towards the needles' material paths: it can only be meshed once
/// the needles are placed.
pub(crate) fn follows_paths(marker_scenario: &Scenario) -> bool {
    marker_scenario
        .resolution
        .slab_grading
        .is_some_and(|g| g.local.is_some())
}

/// `marker_scenario` with the insertion `plan` alone and no probes: the
/// scenario of the slab that insertion is settled on when the marker
/// mesh follows the material paths, so that the slab's grid has no lines
/// of other trials and is the same in whatever campaign the insertion
/// is run.
pub(crate) fn insertion_alone(marker_scenario: &Scenario, plan: &NeedlePlan) -> Scenario {
    let mut alone = marker_scenario.clone();
    alone.probes.clear();
    alone.needles.velocities = vec![plan.velocity];
    alone.needles.days = vec![plan.day];
    alone.needles.first_line = plan.line;
    alone
}

/// The material paths of the loads of `runs` (`MaterialPaths`): each
/// loaded state's material points, led by the front-face point ahead of
/// the first (the entry's, to within half a shaft step of its depth).
pub(crate) fn material_paths(runs: &[NeedleRun]) -> MaterialPaths {
    let line = |loads: &[([f64; 3], f64)]| -> Vec<[f64; 2]> {
        let entry = loads.first().map(|(x, _)| [x[0], 0.0]);
        entry
            .into_iter()
            .chain(loads.iter().map(|(x, _)| [x[0], x[1]]))
            .collect()
    };
    MaterialPaths {
        insertions: runs
            .iter()
            .map(|run| {
                run.loads
                    .iter()
                    .filter(|loads| !loads.is_empty())
                    .map(|loads| line(loads))
                    .collect()
            })
            .collect(),
    }
}

/// What a state settled on the finer mesh records.
struct Settled {
    markers: Vec<[f64; 3]>,
    entry: f64,
    force: f64,
    loads: Vec<([f64; 3], f64)>,
    /// The tip's material point, read on the last state only.
    tip_material: Option<[f64; 3]>,
}

/// Settles every state of `runs` (placed on another mesh of the same
/// slab) on `fine`: the consistency iteration goes on from their loads
/// until their placement on `fine` is consistent, and their markers,
/// entry, base force, loads and the last state's tip material point are
/// replaced by those on `fine`. Returns the back-substitutions made.
pub(crate) fn settle_on(fine: &World, runs: &mut [NeedleRun]) -> Result<usize, SynthError> {
    let mut days: Vec<f64> = runs.iter().map(|r| r.plan.day).collect();
    days.sort_by(f64::total_cmp);
    days.dedup();
    let responses = days
        .iter()
        .map(|&day| fine.response(day))
        .collect::<Result<Vec<_>, _>>()?;
    // Every loaded state (the first carries no load), grouped by day so
    // that a block shares one response.
    let mut jobs: Vec<(usize, usize)> = (0..runs.len())
        .flat_map(|r| (1..runs[r].depths.len()).map(move |k| (r, k)))
        .collect();
    jobs.sort_by(|a, b| runs[a.0].plan.day.total_cmp(&runs[b.0].plan.day));
    let settled: Vec<(Vec<Settled>, usize)> = jobs
        .par_chunk_by(|a, b| runs[a.0].plan.day == runs[b.0].plan.day)
        .flat_map(|same_day| same_day.par_chunks(SOLVE_BLOCK))
        .map(|block| {
            let day = days.partition_point(|&d| d < runs[block[0].0].plan.day);
            settle_block(fine, &responses[day], runs, block)
        })
        .collect::<Result<Vec<_>, _>>()?;
    let mut solves = 0;
    let states = settled.into_iter().flat_map(|(states, block_solves)| {
        solves += block_solves;
        states
    });
    for (&(r, k), state) in jobs.iter().zip(states) {
        let run = &mut runs[r];
        run.markers[k] = state.markers;
        run.entry[k] = state.entry;
        run.force[k] = state.force;
        run.loads[k] = state.loads;
        if let Some(tip) = state.tip_material {
            run.tip_material = tip;
        }
    }
    Ok(solves)
}

/// Settles the states `block` (run, state) of one day on `fine`, all
/// iterations of the block's open states in one back-substitution;
/// returns them and the number of right-hand sides solved.
fn settle_block(
    fine: &World,
    response: &Response,
    runs: &[NeedleRun],
    block: &[(usize, usize)],
) -> Result<(Vec<Settled>, usize), SynthError> {
    let body = &fine.body;
    let rim = Rim::new(body, fine.scenario.needles.radius);
    let shaft_step = fine.scenario.resolution.shaft_step;
    let mut states: Vec<StateIteration> = block
        .iter()
        .map(|&(r, k)| {
            let run = &runs[r];
            let placed = Placement::on(body, run.entry[k], &run.loads[k]);
            StateIteration::from_placement(run.depths[k], placed)
        })
        .collect();
    let mut settled: Vec<Option<Settled>> = block.iter().map(|_| None).collect();
    let mut open: Vec<usize> = (0..block.len()).collect();
    let mut solves = 0;
    while !open.is_empty() {
        let loads: Vec<Vec<f64>> = open.iter().map(|&i| states[i].placed.loads(body)).collect();
        solves += loads.len();
        let fields = response.solve(body, &loads, &[])?;
        let mut still_open = Vec::new();
        for (&i, u) in open.iter().zip(fields) {
            let (r, k) = block[i];
            let run = &runs[r];
            let tip = run.depths[k];
            let next = place(body, &rim, run, tip, &u, shaft_step);
            let state = &mut states[i];
            let consistent = state
                .advance(body, &rim, run, &u, &next, shaft_step)
                .map_err(|e| {
                    e.during(|| {
                        format!(
                            "the needle on the line x = {} m at {tip} m deep, on the marker mesh",
                            run.plan.line
                        )
                    })
                })?;
            if !consistent {
                still_open.push(i);
                continue;
            }
            let placed = &state.placed;
            let last = k + 1 == run.depths.len();
            settled[i] = Some(Settled {
                markers: fine.marker_displacements(&u),
                entry: placed.entry,
                force: placed.force(),
                loads: placed.points.iter().map(|p| (p.0, p.1)).collect(),
                tip_material: last
                    .then(|| material_point(body, &rim, [run.plan.line, tip, 0.0], &u)),
            });
        }
        open = still_open;
    }
    let settled = settled
        .into_iter()
        .map(|s| s.expect("every state of the block settled"))
        .collect();
    Ok((settled, solves))
}
