//! The 3-D slab's mesh: the in-plane grid graded towards the faces (and,
//! if asked, the needle lines), and node planes through the thickness
//! graded towards the mid-plane and the top face.
//!
//! needle-fem's `SlabMesh` cuts the thickness into equal layers; the truth
//! moves each node plane of that linear mesh to its own height before the
//! quadratic nodes are added, so every edge stays straight and every
//! mid-side node sits at its edge's middle.
//!
//! Why grade: the needle's shaft force is a line load on the mid-plane
//! (displacement $\sim \ln r$ towards it) that ends at the free front
//! face, and the clamped back face meets the free sides and top face in
//! singular corners. Two levels towards the faces and sides halve the
//! largest marker error of the uniform mesh and cut its rms fourfold for
//! some 45% more time; what remains is mostly through the thickness,
//! where extra node planes are costly (`docs/truth-world.md`, The 3-D
//! slab).

use needle_fem::element::ElementKind;
use needle_fem::mesh::{Mesh, RectangleMesh, SlabMesh};

use crate::error::SynthError;
use crate::grid::grade;
use crate::scenario::SlabGrading;

/// Grades the in-plane grid lines `xs`, `ys` (elements at most `target`)
/// of a `width` x `depth` slab towards its faces and sides and towards the
/// needle lines `needles` (x).
pub(crate) fn grade_plan(
    xs: &mut Vec<f64>,
    ys: &mut Vec<f64>,
    (width, depth): (f64, f64),
    needles: &[f64],
    target: f64,
    grading: &SlabGrading,
) {
    grade(xs, &[0.0, width], target, grading.faces);
    grade(ys, &[0.0, depth], target, grading.faces);
    grade(xs, needles, target, grading.needle_lines);
}

/// Heights of the node planes: `layers` equal layers over
/// $[-t/2, t/2]$, graded towards the mid-plane and the top face.
pub(crate) fn node_planes(thickness: f64, layers: usize, grading: &SlabGrading) -> Vec<f64> {
    let half = 0.5 * thickness;
    let size = thickness / layers as f64;
    let mut zs: Vec<f64> = (0..=layers).map(|k| -half + size * k as f64).collect();
    grade(&mut zs, &[0.0], size, grading.mid_plane);
    grade(&mut zs, &[half], size, grading.top_face);
    zs
}

/// The Tet10 slab over `plan` whose node planes lie at `z_lines` (sorted,
/// from the bottom face to the top face).
pub(crate) fn layered_slab(plan: RectangleMesh, z_lines: &[f64]) -> Result<Mesh<3>, SynthError> {
    let (bottom, top) = (z_lines[0], z_lines[z_lines.len() - 1]);
    let layers = z_lines.len() - 1;
    let uniform = SlabMesh::new(plan, top - bottom, layers)?.build(ElementKind::Tet4)?;
    // The uniform builder puts node plane k at -t/2 + k t / layers.
    let nodes = uniform
        .nodes()
        .iter()
        .map(|n| {
            let k = ((n[2] + 0.5 * (top - bottom)) / (top - bottom) * layers as f64).round();
            [n[0], n[1], z_lines[k as usize]]
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
        };
        let zs = node_planes(8.0, 2, &grading);
        assert_eq!(zs, [-4.0, -2.0, -1.0, 0.0, 1.0, 2.0, 4.0]);
        let zs = node_planes(
            8.0,
            2,
            &SlabGrading {
                top_face: 2,
                ..grading
            },
        );
        assert_eq!(zs, [-4.0, -2.0, -1.0, 0.0, 1.0, 2.0, 3.0, 4.0]);
    }

    #[test]
    fn the_layered_slab_puts_its_nodes_on_the_planes_and_keeps_its_volume() {
        let plan = RectangleMesh {
            width: 2.0,
            depth: 3.0,
            x_lines: vec![0.0, 1.0, 2.0],
            y_lines: vec![0.0, 1.5, 3.0],
        };
        let zs = [-0.5, -0.1, 0.0, 0.3, 0.5];
        let mesh = layered_slab(plan, &zs).unwrap();
        assert_eq!(mesh.kind(), ElementKind::Tet10);
        // Corner and mid-side heights: the planes and their midpoints.
        let mut heights: Vec<f64> = zs.to_vec();
        heights.extend(zs.windows(2).map(|w| 0.5 * (w[0] + w[1])));
        for n in mesh.nodes() {
            assert!(heights.iter().any(|&z| (z - n[2]).abs() < 1e-12), "{n:?}");
        }
        // Straight-edged tetrahedra: volumes from the corners sum to the box.
        let volume: f64 = (0..mesh.element_count())
            .map(|e| {
                let c: Vec<[f64; 3]> = mesh.element(e)[..4].iter().map(|&n| mesh.node(n)).collect();
                let d = |k: usize| [0, 1, 2].map(|i| c[k][i] - c[0][i]);
                let (a, b, w) = (d(1), d(2), d(3));
                (a[0] * (b[1] * w[2] - b[2] * w[1]) - a[1] * (b[0] * w[2] - b[2] * w[0])
                    + a[2] * (b[0] * w[1] - b[1] * w[0]))
                    .abs()
                    / 6.0
            })
            .sum();
        assert!((volume - 6.0).abs() < 1e-12, "{volume}");
    }
}
