//! The grid lines of the phantom's mesh, and the grading of the
//! plane-strain truth towards its singular lines.
//!
//! The plane truth's displacement is singular at three kinds of line:
//! the edges of a rigid probe whose contact nodes are held (the strain
//! grows like $r^{-1/2}$ towards each edge), and the corners where the
//! clamped back face meets the free sides. On a uniform grid of size $h$
//! the marker displacements near them converge only like $h^{1/2}$: at
//! refinement 6 the front-face marker 1.75 mm beside a probe edge was
//! some 15 µm from the converged value although refinement 12 moved it
//! by 4 µm (`docs/truth-world.md`, Discretisation error). Grid lines at
//! $c \pm h/2^k$, $k = 1, \dots, L$, around each singular coordinate $c$
//! (probe edges and sides in x, front and back faces in y) make the
//! elements there shrink geometrically to $h/2^L$, which restores the
//! convergence at the markers at little cost in a plane mesh.

/// Levels of grading of the plane-strain truth: elements shrink by halves
/// to $h/128$ at the probe edges, sides and faces (5 µm at refinement 6).
/// Measured against refinement 12 with 8 levels, the largest marker
/// difference at refinement 6 is 0.71, 0.45, 0.32, 0.26 µm with 5 to 8
/// levels (`docs/truth-world.md`).
pub(crate) const PLANE_GRADING_LEVELS: usize = 7;

/// Levels of grading of the plane truth when its material is neo-Hookean
/// (`material_nonlinearity`): elements shrink to $h/8$ (78 µm at
/// refinement 6), not $h/128$. The finite-strain Newton solve of a 4 mm
/// probe stagnates with inverted elements at the punch corner when the
/// elements there are much smaller than the indentation: on the
/// `material-nonlinearity.ron` phantom all four probes solve with 0 and
/// 3 levels and the first fails with 4 and with 7 (a 60 x 90 mm phantom
/// at refinement 2 solved with 4 levels, h/16 = 156 µm, and lost a probe
/// with 5). Three levels cut the largest marker difference from a finer
/// mesh (refinement 12, 2 levels) from 61 µm on the uniform mesh to
/// 12 µm (`docs/truth-world.md`, "The neo-Hookean truth's mesh").
pub(crate) const NEO_HOOKEAN_GRADING_LEVELS: usize = 3;

/// Grid lines over `[0, extent]`: `count` equally spaced marker lines plus
/// `extra` lines, every interval split into pieces no longer than `target`.
/// Extra lines closer than a twentieth of `target` to another are dropped.
pub(crate) fn grid_lines(extent: f64, count: usize, extra: &[f64], target: f64) -> Vec<f64> {
    let mut lines: Vec<f64> = (0..count)
        .map(|i| extent * i as f64 / (count - 1) as f64)
        .collect();
    for &x in extra {
        if x > 0.0 && x < extent && lines.iter().all(|&l| (l - x).abs() > 0.05 * target) {
            lines.push(x);
        }
    }
    lines.sort_by(f64::total_cmp);
    let mut out = vec![lines[0]];
    for w in lines.windows(2) {
        let pieces = ((w[1] - w[0]) / target - 1e-9).ceil().max(1.0) as usize;
        for k in 1..=pieces {
            out.push(w[0] + (w[1] - w[0]) * k as f64 / pieces as f64);
        }
    }
    out
}

/// Adds to the sorted grid `lines` (of elements at most `target` long) the
/// lines $c \pm$ `target` $/2^k$, $k = 1, \dots,$ `levels`, around each
/// coordinate $c$ of `singular` that fall strictly inside the grid; a line
/// closer than a quarter of the finest size to one already there is left
/// out, so no sliver elements appear.
pub(crate) fn grade(lines: &mut Vec<f64>, singular: &[f64], target: f64, levels: usize) {
    let (lo, hi) = (lines[0], lines[lines.len() - 1]);
    let tolerance = 0.25 * target / (1u64 << levels) as f64;
    for &c in singular {
        for k in 1..=levels {
            let h = target / (1u64 << k) as f64;
            for x in [c - h, c + h] {
                let inside = x > lo && x < hi;
                if inside && lines.iter().all(|&l| (l - x).abs() > tolerance) {
                    lines.push(x);
                }
            }
        }
    }
    lines.sort_by(f64::total_cmp);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grading_halves_the_elements_towards_each_singular_line() {
        let target = 1.0;
        let mut lines = grid_lines(8.0, 3, &[], target);
        assert_eq!(lines, [0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0]);
        grade(&mut lines, &[0.0, 3.0, 8.0], target, 3);
        let sizes: Vec<f64> = lines.windows(2).map(|w| w[1] - w[0]).collect();
        // From the side at 0: 1/8, 1/8, 1/4, 1/2, then the uniform grid.
        assert_eq!(&sizes[..4], [0.125, 0.125, 0.25, 0.5]);
        // Around 3: symmetric, down to 1/8 on both sides.
        let at = lines.iter().position(|&l| l == 3.0).unwrap();
        assert_eq!(
            &sizes[at - 4..at + 4],
            [0.5, 0.25, 0.125, 0.125, 0.125, 0.125, 0.25, 0.5]
        );
        // Nothing outside the grid, nothing repeated, still sorted.
        assert!(lines.windows(2).all(|w| w[1] > w[0]));
        assert_eq!((lines[0], *lines.last().unwrap()), (0.0, 8.0));
        assert_eq!(lines.len(), 9 + 3 + 6 + 3);
    }

    #[test]
    fn grading_leaves_out_lines_that_would_make_slivers() {
        let mut lines = vec![0.0, 0.5 + 1e-6, 1.0];
        grade(&mut lines, &[1.0], 1.0, 2);
        // 1 - 1/2 lies on a line already there; 1 - 1/4 is new.
        assert_eq!(lines, [0.0, 0.5 + 1e-6, 0.75, 1.0]);
    }
}
