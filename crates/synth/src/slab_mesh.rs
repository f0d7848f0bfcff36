//! The 3-D slab's mesh: the in-plane grid graded towards the faces (and,
//! if asked, the needle lines), and node planes through the thickness
//! graded towards the mid-plane and the top face.
//!
//! needle-fem's `SlabMesh` cuts the thickness into equal layers; the truth
//! moves each node plane of that linear mesh to its own height before the
//! quadratic nodes are added, so every edge stays straight and every
//! mid-side node sits at its edge's middle.
//!
//! The slab, its supports (except the platform's foundation under the
//! bottom face) and its loads (the needle in the mid-plane, a probe
//! evenly through the thickness) are symmetric about $z = 0$, and so is
//! the mesh: its lower half is the mirror image of the upper
//! (`SlabMesh::build_symmetric`). The displacement is then symmetric too,
//! and the upper half alone gives it exactly, with $u_z = 0$ held on the
//! mid-plane and half of every mid-plane load: [`Span::UpperHalf`], on
//! 3/5 of the unknowns for two layers (the paper default's campaign at
//! that resolution: 15.0 s to 9.3 s).
//!
//! Why grade: the needle's shaft force is a line load on the mid-plane
//! (displacement $\sim \ln r$ towards it) that ends at the free front
//! face, and the clamped back face meets the free sides and top face in
//! singular corners. Two levels towards the faces and sides halve the
//! largest marker error of the uniform mesh and cut its rms fourfold for
//! some 45% more time; four layers instead of two and one level towards
//! each needle line take the worst marker, beside the needle's entry,
//! from 18 um to 4.7 um for about twice the time (the paper default;
//! `docs/truth-world.md`, The 3-D slab).
//!
//! A grading with `local` set meshes the slab as an octree on the cells
//! of the graded grid instead (`local_mesh`), refined towards the
//! features [`slab_features`] lists: only near them, where the grid's
//! lines would refine whole rows, columns and layers of the slab.

use needle_fem::element::ElementKind;
use needle_fem::mesh::{Mesh, RectangleMesh, SlabMesh};

use crate::error::SynthError;
use crate::grid::grade;
use crate::local_mesh::{Feature, mesh_locally, mirrored};
use crate::scenario::{LocalRefinement, Scenario, SlabGrading};

/// Grades the in-plane grid lines `xs`, `ys` (elements at most `target`)
/// of a `width` x `depth` slab towards its faces and sides, the needle
/// lines `needles` (x) and the probe edges `probe_edges` (x, on the front
/// face y = 0).
pub(crate) fn grade_plan(
    xs: &mut Vec<f64>,
    ys: &mut Vec<f64>,
    (width, depth): (f64, f64),
    (needles, probe_edges): (&[f64], &[f64]),
    target: f64,
    grading: &SlabGrading,
) {
    grade(xs, &[0.0, width], target, grading.faces);
    grade(ys, &[0.0, depth], target, grading.faces);
    grade(xs, needles, target, grading.needle_lines);
    if !probe_edges.is_empty() {
        grade(xs, probe_edges, target, grading.probe_edges);
        grade(ys, &[0.0], target, grading.probe_edges);
    }
}

/// How much of the slab the mesh covers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Span {
    /// The whole thickness, the lower half the mirror image of the upper.
    Whole,
    /// The upper half $z \in [0, t/2]$ alone.
    UpperHalf,
}

/// Heights of the node planes of the upper half, from the mid-plane
/// $z = 0$ to the top face: those of `layers` equal layers through the
/// whole thickness (with the mid-plane added when `layers` is odd, since
/// the needle's load lies on it), graded towards the mid-plane and the
/// top face.
pub(crate) fn upper_planes(thickness: f64, layers: usize, grading: &SlabGrading) -> Vec<f64> {
    let half = 0.5 * thickness;
    let size = thickness / layers as f64;
    let mut zs = vec![0.0];
    zs.extend(
        (0..=layers)
            .map(|k| -half + size * k as f64)
            .filter(|&z| z > 1e-9 * half),
    );
    grade(&mut zs, &[0.0], size, grading.mid_plane);
    grade(&mut zs, &[half], size, grading.top_face);
    zs
}

/// The Tet10 slab over `plan` whose upper half has its node planes at
/// `upper` (ascending from 0): that half alone, or the whole slab with the
/// lower half its mirror image.
pub(crate) fn layered_slab(
    plan: RectangleMesh,
    upper: &[f64],
    span: Span,
) -> Result<Mesh<3>, SynthError> {
    let layers = upper.len() - 1;
    let top = upper[layers];
    let slab = SlabMesh::new(plan, 2.0 * top, 2 * layers)?;
    let uniform = match span {
        Span::Whole => slab.build_symmetric(ElementKind::Tet4)?,
        Span::UpperHalf => slab.build_upper_half(ElementKind::Tet4)?,
    };
    // needle-fem puts node plane k at z = k top / layers, k from -layers
    // (whole) or 0 (half) to layers.
    let nodes = uniform
        .nodes()
        .iter()
        .map(|n| {
            let k = (n[2] / top * layers as f64).round();
            [n[0], n[1], k.signum() * upper[k.abs() as usize]]
        })
        .collect();
    let linear = Mesh::new(
        ElementKind::Tet4,
        nodes,
        uniform.connectivity().to_vec(),
        uniform.regions().to_vec(),
    )?;
    Ok(linear.to_quadratic()?)
}

/// The places `local` refines the slab's upper half towards: the path
/// of every needle of `scenario` on the mid-plane (its entry and final
/// tip finer), the edges of the probes `probe_edges` on the front face,
/// and the edges of the clamped back face with the top face and the
/// sides; sizes `target` halved as many levels as `local` asks.
pub(crate) fn slab_features(
    scenario: &Scenario,
    probe_edges: &[f64],
    target: f64,
    local: &LocalRefinement,
) -> Vec<Feature> {
    let p = &scenario.phantom;
    let (w, d, top) = (p.width, p.depth, 0.5 * p.thickness);
    let feature = |lo: [f64; 3], hi: [f64; 3], levels: usize| Feature {
        lo,
        hi,
        size: target / (1u64 << levels) as f64,
    };
    let tip = scenario.needles.depth.min(d);
    let mut features = vec![
        feature([0.0, d, top], [w, d, top], local.back_face),
        feature([0.0, d, 0.0], [0.0, d, top], local.back_face),
        feature([w, d, 0.0], [w, d, top], local.back_face),
    ];
    for x in scenario.needles.plan().iter().map(|n| n.line) {
        features.push(feature([x, 0.0, 0.0], [x, tip, 0.0], local.needle_paths));
        for y in [0.0, tip] {
            features.push(feature([x, y, 0.0], [x, y, 0.0], local.needle_ends));
        }
    }
    for &x in probe_edges {
        features.push(feature([x, 0.0, 0.0], [x, 0.0, top], local.probe_edges));
    }
    features
}

/// The Tet10 slab of the octree over the grid `lines` (x, y and the
/// upper half's node planes) refined towards `features` as `local` says:
/// its upper half, or the whole slab with the lower half its mirror
/// image; and the largest octree cell.
pub(crate) fn local_slab(
    lines: [&[f64]; 3],
    features: &[Feature],
    local: &LocalRefinement,
    span: Span,
) -> Result<(Mesh<3>, f64), SynthError> {
    let upper = mesh_locally(lines, features, local.grading);
    let largest = upper.largest;
    let mesh = match span {
        Span::UpperHalf => upper,
        Span::Whole => mirrored(&upper),
    };
    let elements = mesh.tetrahedra.len();
    let linear = Mesh::new(
        ElementKind::Tet4,
        mesh.nodes,
        mesh.tetrahedra.concat(),
        vec![0; elements],
    )?;
    Ok((linear.to_quadratic()?, largest))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn node_planes_are_graded_towards_the_mid_plane_and_the_top() {
        let grading = SlabGrading {
            faces: 0,
            needle_lines: 0,
            mid_plane: 2,
            top_face: 1,
            probe_edges: 0,
            local: None,
        };
        // Layers of 4 from -4 to 4: the top one split twice towards 0.
        assert_eq!(upper_planes(8.0, 2, &grading), [0.0, 1.0, 2.0, 4.0]);
        let top_twice = SlabGrading {
            top_face: 2,
            ..grading
        };
        assert_eq!(upper_planes(8.0, 2, &top_twice), [0.0, 1.0, 2.0, 3.0, 4.0]);
        // Three layers have no plane at 0: it is added.
        let uniform = SlabGrading {
            mid_plane: 0,
            top_face: 0,
            ..grading
        };
        assert_eq!(upper_planes(6.0, 3, &uniform), [0.0, 1.0, 3.0]);
    }

    #[test]
    fn the_layered_slab_puts_its_nodes_on_the_planes_and_keeps_its_volume() {
        let plan = RectangleMesh {
            width: 2.0,
            depth: 3.0,
            x_lines: vec![0.0, 1.0, 2.0],
            y_lines: vec![0.0, 1.5, 3.0],
        };
        let upper = [0.0, 0.1, 0.4, 0.5];
        for (span, volume) in [(Span::Whole, 6.0), (Span::UpperHalf, 3.0)] {
            let mesh = layered_slab(plan.clone(), &upper, span).unwrap();
            assert_eq!(mesh.kind(), ElementKind::Tet10);
            // Corner and mid-side heights: the planes, their midpoints and
            // (whole) their mirror images.
            let mut heights: Vec<f64> = upper.to_vec();
            heights.extend(upper.windows(2).map(|w| 0.5 * (w[0] + w[1])));
            for n in mesh.nodes() {
                let z = match span {
                    Span::Whole => n[2].abs(),
                    Span::UpperHalf => n[2],
                };
                assert!(heights.iter().any(|&h| (h - z).abs() < 1e-12), "{n:?}");
            }
            // Straight-edged, positively oriented tetrahedra (the neo-Hookean
            // truth integrates with the signed Jacobian): volumes from the
            // corners sum to the box.
            let volumes: Vec<f64> = (0..mesh.element_count())
                .map(|e| {
                    let c: Vec<[f64; 3]> =
                        mesh.element(e)[..4].iter().map(|&n| mesh.node(n)).collect();
                    let d = |k: usize| [0, 1, 2].map(|i| c[k][i] - c[0][i]);
                    let (a, b, w) = (d(1), d(2), d(3));
                    (a[0] * (b[1] * w[2] - b[2] * w[1]) - a[1] * (b[0] * w[2] - b[2] * w[0])
                        + a[2] * (b[0] * w[1] - b[1] * w[0]))
                        / 6.0
                })
                .collect();
            assert!(volumes.iter().all(|&v| v > 0.0), "{span:?}");
            let sum: f64 = volumes.iter().sum();
            assert!((sum - volume).abs() < 1e-12, "{span:?}: {sum}");
            if span == Span::Whole {
                // The lower half mirrors the upper: every node has its image.
                for n in mesh.nodes() {
                    let image = [n[0], n[1], -n[2]];
                    assert!(mesh.nodes().iter().any(|m| m == &image), "{n:?}");
                }
            }
        }
    }
}
