//! The needle trials' markers of the 3-D slab read on a second, finer
//! mesh than the one the needle is placed on.
//!
//! On the paper default's slab the final markers of a 1 mm/s insertion
//! are 4.5 um (0.57 of the marker noise) from the convergence test's
//! reference, while the needle's placement on that slab (the material
//! points its shaft load acts at, found by the tip's consistency
//! iteration) is nearly converged already: the same loads applied to the
//! reference mesh give markers 0.5 um from the reference's own. The error
//! is the field's, not the placement's (`docs/truth-world.md`, The 3-D
//! slab). That holds for the null insertion; with the tip's cutting force
//! the markers just after the entry stay 1.8 to 2.5 um off on the
//! placement meshes tried, so the finer mesh helps most once the needle
//! is deeper. With `resolution.marker_grading` set, the truth places the
//! needle on the slab of `resolution.slab_grading`, whose kept columns of
//! $K^{-1}$ make the consistency iteration cheap, and solves the field of
//! every state's placed load on the slab of `marker_grading`, where the
//! markers are read:
//! $$m(d) = M_f\,K_f^{-1} f_f(d),$$
//! $f_f(d)$ the state's point forces at their material points spread to
//! the finer mesh's nodes. The base force is the load's integral and needs
//! no field.
//!
//! Every state is solved on the finer mesh. Solving every fifth and
//! reading the correction $m_f - m_c$ between them by cubics does not do:
//! the placement mesh's error jumps as the loaded points cross its
//! elements, and the correction read so was 1.7 um off at some states
//! (every second state: 0.6 um). Probes, strains and the tip's material
//! point stay those of the placement mesh.

use rayon::prelude::*;

use crate::error::SynthError;
use crate::needle::NeedleRun;
use crate::scenario::Scenario;
use crate::world::World;

/// Right-hand sides per back-substitution of the finer mesh: blocks are
/// solved in parallel, and each block's loads and fields (full vectors of
/// the finer mesh) are dropped once its markers are read.
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

/// Replaces the marker displacements of every state of `runs` (placed on
/// another mesh of the same slab) by those of `fine` under the same
/// loads.
pub(crate) fn read_markers_on(fine: &World, runs: &mut [NeedleRun]) -> Result<(), SynthError> {
    let body = &fine.body;
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
    let read_block = |block: &[(usize, usize)]| -> Result<Vec<Vec<[f64; 3]>>, SynthError> {
        let loads: Vec<Vec<f64>> = block
            .iter()
            .map(|&(r, k)| {
                let mut f = vec![0.0; body.dof_count()];
                for &(point, force) in &runs[r].loads[k] {
                    let at = body
                        .locate(point)
                        .expect("the two meshes cover the same slab");
                    body.add_point_force(&at, [0.0, force, 0.0], &mut f);
                }
                f
            })
            .collect();
        let day = days.partition_point(|&d| d < runs[block[0].0].plan.day);
        let fields = responses[day].solve(body, &loads, &[])?;
        Ok(fields
            .iter()
            .map(|u| fine.marker_displacements(u))
            .collect())
    };
    let readings: Vec<Vec<[f64; 3]>> = jobs
        .par_chunk_by(|a, b| runs[a.0].plan.day == runs[b.0].plan.day)
        .flat_map(|same_day| same_day.par_chunks(SOLVE_BLOCK))
        .map(read_block)
        .collect::<Result<Vec<_>, _>>()?
        .into_iter()
        .flatten()
        .collect();
    for (&(r, k), markers) in jobs.iter().zip(readings) {
        runs[r].markers[k] = markers;
    }
    Ok(())
}
