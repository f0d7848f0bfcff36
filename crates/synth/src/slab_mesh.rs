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
use crate::local_mesh::{Feature, Split, mesh_locally, mirrored};
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

/// Where the needles' loads acted in the material, from a placement on
/// another mesh of the slab: for each insertion and each of its loaded
/// states, the material line of its shaft in the mid-plane (x, y), from
/// its entry on the front face to its tip.
///
/// The tissue the needle holds is carried with it: on the paper default's
/// last insertion the material entry point moves 3.6 mm sideways while
/// the front face is drawn in, so features on the needle's line leave
/// the entry's rim crossing cells graded from a point millimetres away,
/// and the base force changes by up to 3e-4 from one mesh to the next
/// with no trend (`docs/truth-world.md`, The 3-D slab).
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct MaterialPaths {
    /// Insertions, their states, the points of each state's line.
    pub insertions: Vec<Vec<Vec<[f64; 2]>>>,
}

/// The places `local` refines the slab's upper half towards: the path
/// of every needle of `scenario` on the mid-plane (its entry and final
/// tip finer), the edges of the probes `probe_edges` on the front face,
/// the edges of the clamped back face with the top face and the sides,
/// and the whole slab (its far field); sizes `target` halved as many
/// levels as `local` asks.
///
/// With `paths`, a needle's path is every point its shaft's material
/// line passed through, its entry every point its material entry passed
/// through and its tip the last state's material tip; without, they are
/// the needle's line, where it meets the front face and its final tip.
pub(crate) fn slab_features(
    scenario: &Scenario,
    probe_edges: &[f64],
    target: f64,
    local: &LocalRefinement,
    paths: Option<&MaterialPaths>,
) -> Vec<Feature> {
    let p = &scenario.phantom;
    let (w, d, top) = (p.width, p.depth, 0.5 * p.thickness);
    let size = |levels: usize| target / (1u64 << levels) as f64;
    let feature = |lo: [f64; 3], hi: [f64; 3], levels: usize| Feature {
        lo,
        hi,
        size: size(levels),
    };
    let mut features = vec![
        feature([0.0, 0.0, 0.0], [w, d, top], local.far_field),
        feature([0.0, d, top], [w, d, top], local.back_face),
        feature([0.0, d, 0.0], [0.0, d, top], local.back_face),
        feature([w, d, 0.0], [w, d, top], local.back_face),
    ];
    match paths {
        None => {
            let tip = scenario.needles.depth.min(d);
            for x in scenario.needles.plan().iter().map(|n| n.line) {
                features.push(feature([x, 0.0, 0.0], [x, tip, 0.0], local.needle_paths));
                for y in [0.0, tip] {
                    features.push(feature([x, y, 0.0], [x, y, 0.0], local.needle_ends));
                }
            }
        }
        Some(paths) => {
            let in_mid_plane = |levels: usize| {
                move |[lo, hi]: [[f64; 2]; 2]| {
                    feature([lo[0], lo[1], 0.0], [hi[0], hi[1], 0.0], levels)
                }
            };
            let lines = paths.insertions.iter().flatten().map(Vec::as_slice);
            let swept = covering_boxes(lines, 0.5 * size(local.needle_paths));
            features.extend(swept.into_iter().map(in_mid_plane(local.needle_paths)));
            let entries: Vec<Vec<[f64; 2]>> = paths
                .insertions
                .iter()
                .map(|states| {
                    states
                        .iter()
                        .filter_map(|line| line.first().copied())
                        .collect()
                })
                .collect();
            let entered = covering_boxes(
                entries.iter().map(Vec::as_slice),
                0.5 * size(local.needle_ends),
            );
            features.extend(entered.into_iter().map(in_mid_plane(local.needle_ends)));
            let tips = paths
                .insertions
                .iter()
                .filter_map(|states| states.last()?.last());
            features.extend(tips.map(|&t| in_mid_plane(local.needle_ends)([t, t])));
        }
    }
    for &x in probe_edges {
        features.push(feature([x, 0.0, 0.0], [x, 0.0, top], local.probe_edges));
    }
    features
}

/// Boxes (lower and upper corners) that together cover the polylines
/// `lines` and lie within a `pixel` of them: the pixels of a grid of that
/// size that the lines pass through, merged into runs along x, and runs
/// of equal extent in successive rows merged along y: their number grows
/// with the area the lines sweep, not with their segments.
pub(crate) fn covering_boxes<'a>(
    lines: impl Iterator<Item = &'a [[f64; 2]]>,
    pixel: f64,
) -> Vec<[[f64; 2]; 2]> {
    let mut pixels = Vec::new();
    let mut mark = |q: [f64; 2]| pixels.push(q.map(|c| (c / pixel).floor() as i64));
    for line in lines {
        for &vertex in line {
            mark(vertex);
        }
        for pair in line.windows(2) {
            let length =
                ((pair[1][0] - pair[0][0]).powi(2) + (pair[1][1] - pair[0][1]).powi(2)).sqrt();
            // Samples a quarter pixel apart: every point of the line is
            // within an eighth of a pixel of a marked one.
            let steps = (4.0 * length / pixel).ceil().max(1.0) as usize;
            for k in 1..steps {
                let t = k as f64 / steps as f64;
                mark(std::array::from_fn(|c| {
                    pair[0][c] + t * (pair[1][c] - pair[0][c])
                }));
            }
        }
    }
    // Runs along x within each row: (first column, last column, row).
    pixels.sort_unstable_by_key(|&[i, j]| (j, i));
    pixels.dedup();
    let mut runs: Vec<(i64, i64, i64)> = Vec::new();
    for &[i, j] in &pixels {
        match runs.last_mut() {
            Some(run) if run.2 == j && run.1 + 1 == i => run.1 = i,
            _ => runs.push((i, i, j)),
        }
    }
    // Equal runs in successive rows: one box.
    runs.sort_unstable();
    let mut boxes: Vec<(i64, i64, i64, i64)> = Vec::new();
    for (i0, i1, j) in runs {
        match boxes.last_mut() {
            Some(b) if (b.0, b.1) == (i0, i1) && b.3 + 1 == j => b.3 = j,
            _ => boxes.push((i0, i1, j, j)),
        }
    }
    boxes
        .into_iter()
        .map(|(i0, i1, j0, j1)| {
            [
                [i0 as f64 * pixel, j0 as f64 * pixel],
                [(i1 + 1) as f64 * pixel, (j1 + 1) as f64 * pixel],
            ]
        })
        .collect()
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
    let split = if local.plan_only {
        Split::Plan
    } else {
        Split::Octree
    };
    let upper = mesh_locally(lines, features, local.grading, split);
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

    #[test]
    fn covering_boxes_hold_the_lines_and_stay_within_a_pixel_of_them() {
        let pixel = 0.1;
        // A line along y, a bent one, and a short one near the corner.
        let lines: Vec<Vec<[f64; 2]>> = vec![
            vec![[1.05, 0.0], [1.05, 2.0]],
            vec![[2.0, 0.0], [1.7, 0.6], [1.65, 2.0]],
            vec![[0.01, 0.01], [0.02, 0.03]],
        ];
        let boxes = covering_boxes(lines.iter().map(Vec::as_slice), pixel);
        // To rounding: a pixel's bounds are its index times the pixel.
        let inside = |q: [f64; 2], b: &[[f64; 2]; 2]| {
            (0..2).all(|c| b[0][c] - 1e-12 <= q[c] && q[c] <= b[1][c] + 1e-12)
        };
        let along = |line: &[[f64; 2]], n: usize| -> Vec<[f64; 2]> {
            line.windows(2)
                .flat_map(|w| {
                    (0..=n).map(move |k| {
                        let t = k as f64 / n as f64;
                        [
                            w[0][0] + t * (w[1][0] - w[0][0]),
                            w[0][1] + t * (w[1][1] - w[0][1]),
                        ]
                    })
                })
                .collect()
        };
        let dense: Vec<[f64; 2]> = lines.iter().flat_map(|l| along(l, 400)).collect();
        for q in &dense {
            assert!(
                boxes.iter().any(|b| inside(*q, b)),
                "{q:?} is uncovered by {boxes:?}"
            );
        }
        // Every pixel of a box has a point of a line within it (to the
        // eighth of a pixel the sampling allows).
        for b in &boxes {
            let (nx, ny) = (
                ((b[1][0] - b[0][0]) / pixel).round() as usize,
                ((b[1][1] - b[0][1]) / pixel).round() as usize,
            );
            for i in 0..nx {
                for j in 0..ny {
                    let lo = [b[0][0] + i as f64 * pixel, b[0][1] + j as f64 * pixel];
                    let near = dense.iter().any(|q| {
                        (0..2)
                            .all(|c| q[c] >= lo[c] - 0.125 * pixel && q[c] <= lo[c] + 1.125 * pixel)
                    });
                    assert!(near, "pixel at {lo:?} of {b:?} holds no line");
                }
            }
        }
        // The straight line is one box, one pixel wide.
        let straight = covering_boxes(std::iter::once(&lines[0][..]), pixel);
        assert_eq!(straight.len(), 1);
        assert!((straight[0][1][0] - straight[0][0][0] - pixel).abs() < 1e-12);
    }
}
