//! The probes of the 3-D slab pressed on slabs of their own, graded
//! towards their edges, and rounded probes on meshes of their own.
//!
//! A probe is a rigid flat punch: the strain grows like $r^{-1/2}$ towards
//! its two edges on the front face, along the whole thickness, and towards
//! the corners where those edges meet the top face, on which the markers
//! lie. On the paper default's slab, which is graded towards the faces
//! and the needle lines but not the probe edges, the four probes'
//! markers are 39 to 77 um (4.8 to 9.7 times the marker noise) from
//! those of a slab graded nine levels towards the probe's edges
//! (`docs/truth-world.md`, The 3-D slab, session 37). Grading every probe's
//! edges in the one slab multiplies its grid lines (each level adds two
//! lines per edge across the whole phantom, and a tensor grid cannot stop
//! them short), and the needle trials would pay for them. With
//! `resolution.probe_grading` set, each probe is instead pressed on a slab
//! of its own graded as that field asks: the scenario's slab with that
//! probe alone, no needle lines, factorised with the probe's face held
//! (`probe::Factorisation::Own`). Markers, force, moment and peak strain
//! are read there; every other trial stays on the scenario's slab.
//!
//! A probe with rounded edges (neo-Hookean, in contact) beside other
//! trials is likewise pressed on a mesh of its own: the scenario's with
//! that probe alone. Its mesh is graded over twice its width, lines a
//! quarter of its edge radius apart (`world::edge_lines`), and those
//! lines cross the whole phantom: on the one mesh of all four probes and
//! the needle lines of `material-nonlinearity.ron` with its probes
//! rounded to 1 mm, none of them had finished after an hour of CPU,
//! where the first alone solves in 18 minutes (session 49). The
//! scenario's mesh leaves such probes' lines out, so the needles do not
//! pay for them either.
//!
//! Since the edges are singular uniformly through the thickness, the fine
//! paper default refines that slab in the plan alone
//! (`LocalRefinement::plan_only`: a quadtree graded towards the edges,
//! extruded through node planes graded towards the top face), where the
//! octree's cubes at the edges would cost some four times the nodes
//! (session 42).

use crate::scenario::{ProbeTrial, Scenario};

/// Whether `probe` has rounded edges and `scenario` other trials on its
/// mesh: such a probe is pressed on a mesh of its own, and the scenario's
/// mesh does not carry its lines (`World::new`). The compression test
/// needs no mesh.
pub(crate) fn pressed_apart(scenario: &Scenario, probe: &ProbeTrial) -> bool {
    let alone = scenario.probes.len() == 1 && scenario.needles.plan().is_empty();
    probe.edge_radius.is_some() && !alone
}

/// The scenario of the mesh `probe` is pressed on, when it has one of its
/// own: a 3-D slab (`out_of_plane`) of linear material with
/// `resolution.probe_grading` set, which differs from `scenario` in its
/// slab grading; or a rounded probe beside other trials
/// ([`pressed_apart`]). Either has that probe as its only trial.
pub(crate) fn probe_scenario(scenario: &Scenario, probe: &ProbeTrial) -> Option<Scenario> {
    let mut own = scenario.clone();
    if !pressed_apart(scenario, probe) {
        let e = &scenario.effects;
        let grading = scenario.resolution.probe_grading?;
        if probe.edge_radius.is_some()
            || e.out_of_plane.is_none()
            || e.material_nonlinearity.is_some()
        {
            return None;
        }
        own.resolution.slab_grading = Some(grading);
        own.resolution.probe_grading = None;
        own.resolution.marker_grading = None;
    }
    own.probes = vec![*probe];
    own.needles.velocities.clear();
    own.compression = None;
    own.frames = None;
    Some(own)
}
