//! Where a needle's load acts: on the material line whose deformed image is
//! the needle.
//!
//! The tool reports the needle in space. The tissue it holds has been
//! dragged along with it, so the shaft point at spatial position $p$ loads
//! the material point $X$ with
//! $$X + u(X) = p,$$
//! and the inserted shaft starts where the deformed front face crosses the
//! needle: at the material point $X_e = (x_e, 0)$ whose image lies on the
//! needle's line, $\hat n \cdot (X_e + u(X_e) - p_0) = 0$ ($p_0$ the line's
//! crossing of $y = 0$, $\hat n \perp \hat d$). The entry has moved into the
//! slab by $\delta = \hat d \cdot (X_e + u(X_e) - p_0)$, so the inserted
//! length is $L' = L - \delta$ and the base force $\int_0^{L'} q\,ds$.
//! Loading the spatial line instead misplaces the load by the displacement
//! at the needle, millimetres in a soft phantom, which the markers near the
//! shaft see at many times their noise.
//!
//! $u$ depends on where the load acts, so the placement is a fixed point
//! of $v \mapsto T(v)$: place the load by $v$, solve, re-place it in the
//! solution (the entry by Newton steps, every material point by
//! [`SUBSTITUTIONS`] substitutions $X \leftarrow p - u(X)$). The forward
//! model starts from the spatial line ($X = p$, $\delta = 0$) and does
//! [`PLACEMENT_ROUNDS`] rounds on the plane body; the `out_of_plane` slab
//! starts from the plane's placement and does [`SLAB_PLACEMENT_ROUNDS`].
//! Plain substitution contracts slowly: a deeper entry shortens the
//! shaft, which lowers the load, which draws the entry back out. Each round therefore takes the secant (Anderson,
//! depth one) step over its last two, [`Mixing`]. The count is fixed,
//! never a tolerance, so that the prediction is a smooth function of the
//! parameters for the finite-difference Jacobian.
//!
//! The shaft is cut into pieces of about [`PIECE_LENGTH`] in space (their
//! number depends on the measured length alone, for the same reason); the
//! load of each runs along the straight material segment between the
//! images of its ends, with the density rescaled so that the piece carries
//! $\int q\,ds$ over its spatial length.

use crate::error::DiagnoseError;
use crate::observe::Shaft;

/// The mid-plane displacement at a point of the outline.
pub(crate) type Displacement<'a> = dyn Fn([f64; 2]) -> Result<[f64; 2], DiagnoseError> + 'a;

/// Re-placements of the load after the first solve on the spatial line.
pub(crate) const PLACEMENT_ROUNDS: usize = 4;

/// Re-placements of the `out_of_plane` slab's load after its first solve
/// on the plane model's placement. The plane drags the tissue along the
/// needle nearly as far as the slab does, so from that start fewer rounds
/// reach the accuracy of [`PLACEMENT_ROUNDS`] from the spatial line; each
/// costs a back-substitution of the slab's large factor. On the default
/// 21 x 21 campaign 3 rounds are within 0.19 um of 12 at the markers
/// (4 rounds from the spatial line: 0.10 um), 2 rounds within 1.4 um,
/// 1 round within 13 um (marker noise 8 um).
pub(crate) const SLAB_PLACEMENT_ROUNDS: usize = 3;

/// Rounds on each body from the base point's own placements in the
/// finite-difference columns of the fits that set the current model (see
/// `fit::Precision`). The rounds contract the placement's error about
/// tenfold each (1 round 13 um, 2 rounds 1.4 um, 3 rounds 0.19 um above),
/// so the columns' derivative of the placement part is off by about a
/// hundredth: on the default campaign's final model the fitted parameters
/// move by a thousandth of their standard errors against the model's own
/// differences, and the standard errors by less than 0.01%. The cold
/// start's rounds are still what every residual the fit weighs is
/// evaluated with.
pub(crate) const NEAR_ROUNDS: usize = 2;

/// Rounds from the base point's placements in the columns of the ranking:
/// the score tests and the candidates' refits (see `fit::Precision`). One
/// round leaves the placement part a tenth off: derivatives within 0.6% at
/// the markers and 2.5% in the base force (a unit test bounds both), for
/// two back-substitutions per needle frame instead of three. A refit's
/// misfit is still the model's own, and its likelihood ratio a lower
/// bound.
pub(crate) const RANKING_NEAR_ROUNDS: usize = 1;

/// Substitutions $X \leftarrow p - u(X)$ per round, per material point.
const SUBSTITUTIONS: usize = 2;

/// Newton steps on the entry point per round.
const ENTRY_STEPS: usize = 3;

/// Spatial length of a shaft piece (m), at most.
const PIECE_LENGTH: f64 = 1.0e-3;

/// Where the load of one needle frame acts.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Placement {
    /// How far the deformed entry lies inside along the needle, $\delta$ (m).
    pub entry_offset: f64,
    /// Material points of the piece ends, from the entry to the tip.
    pub material: Vec<[f64; 2]>,
}

/// One piece of the shaft: its material ends and spatial arclengths from
/// the deformed entry.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Piece {
    pub start: [f64; 2],
    pub end: [f64; 2],
    pub s_start: f64,
    pub s_end: f64,
}

/// A point clamped into the outline `[0, extent[0]] x [0, extent[1]]`.
fn clamp(point: [f64; 2], extent: [f64; 2]) -> [f64; 2] {
    [
        point[0].clamp(0.0, extent[0]),
        point[1].clamp(0.0, extent[1]),
    ]
}

impl Placement {
    /// The needle's spatial line taken as material: the first guess.
    pub fn spatial(shaft: &Shaft) -> Self {
        let pieces = Self::piece_count(shaft);
        let material = (0..=pieces)
            .map(|k| Self::spatial_point(shaft, 0.0, k, pieces))
            .collect();
        Self {
            entry_offset: 0.0,
            material,
        }
    }

    fn piece_count(shaft: &Shaft) -> usize {
        (shaft.length / PIECE_LENGTH).ceil().max(1.0) as usize
    }

    /// The spatial position of piece end `k` of `pieces` when the entry
    /// lies `offset` inside.
    fn spatial_point(shaft: &Shaft, offset: f64, k: usize, pieces: usize) -> [f64; 2] {
        let s = offset + (shaft.length - offset) * k as f64 / pieces as f64;
        [
            shaft.entry[0] + s * shaft.direction[0],
            shaft.entry[1] + s * shaft.direction[1],
        ]
    }

    /// Whether every coordinate is a number (a re-placement in a partial
    /// solution may have read outside it).
    pub fn is_finite(&self) -> bool {
        self.entry_offset.is_finite() && self.material.iter().flatten().all(|x| x.is_finite())
    }

    /// The inserted length $L' = L - \delta$.
    pub fn inserted_length(&self, shaft: &Shaft) -> f64 {
        shaft.length - self.entry_offset
    }

    /// The pieces of the shaft, entry first.
    pub fn pieces(&self, shaft: &Shaft) -> impl Iterator<Item = Piece> + '_ {
        let length = self.inserted_length(shaft);
        let count = self.material.len() - 1;
        self.material
            .windows(2)
            .enumerate()
            .map(move |(k, ends)| Piece {
                start: ends[0],
                end: ends[1],
                s_start: length * k as f64 / count as f64,
                s_end: length * (k + 1) as f64 / count as f64,
            })
    }

    /// The next placement in the displacement field `displacement` (in the
    /// mid-plane, for points inside the outline of `extent`).
    pub fn replaced(
        &self,
        shaft: &Shaft,
        displacement: &Displacement<'_>,
        extent: [f64; 2],
    ) -> Result<Self, DiagnoseError> {
        let entry_offset = self.entry_offset_in(shaft, displacement, extent)?;
        let pieces = self.material.len() - 1;
        let material = self
            .material
            .iter()
            .enumerate()
            .map(|(k, &guess)| {
                let target = Self::spatial_point(shaft, entry_offset, k, pieces);
                let mut x = guess;
                for _ in 0..SUBSTITUTIONS {
                    let u = displacement(x)?;
                    x = clamp([target[0] - u[0], target[1] - u[1]], extent);
                }
                Ok(x)
            })
            .collect::<Result<_, DiagnoseError>>()?;
        Ok(Self {
            entry_offset,
            material,
        })
    }

    /// $\delta$ for the field `displacement`: Newton's method on the
    /// front-face abscissa $x_e$ with a central-difference slope, from the
    /// current entry's material point.
    fn entry_offset_in(
        &self,
        shaft: &Shaft,
        displacement: &Displacement<'_>,
        extent: [f64; 2],
    ) -> Result<f64, DiagnoseError> {
        let d = shaft.direction;
        let normal = [d[1], -d[0]];
        let image = |x: f64| -> Result<[f64; 2], DiagnoseError> {
            let u = displacement([x, 0.0])?;
            Ok([x + u[0] - shaft.entry[0], u[1] - shaft.entry[1]])
        };
        let miss = |x: f64| -> Result<f64, DiagnoseError> {
            let r = image(x)?;
            Ok(normal[0] * r[0] + normal[1] * r[1])
        };
        let h = 1.0e-7 * extent[0].max(1e-3);
        let mut x = self.material[0][0];
        for _ in 0..ENTRY_STEPS {
            let slope = (miss(x + h)? - miss(x - h)?) / (2.0 * h);
            if slope.abs() < 1e-6 {
                break;
            }
            x = (x - miss(x)? / slope).clamp(0.0, extent[0]);
        }
        let r = image(x)?;
        Ok(d[0] * r[0] + d[1] * r[1])
    }
}

/// Anderson mixing of depth one over the rounds of one needle frame: with
/// $r_k = T(v_k) - v_k$ the next placement is
/// $$v_{k+1} = T(v_k) - \gamma\,\big(T(v_k) - T(v_{k-1})\big),\qquad
/// \gamma = \frac{r_k \cdot (r_k - r_{k-1})}{\lVert r_k - r_{k-1}\rVert^2},$$
/// which removes the slowest mode of the substitution; the placement is
/// the vector of $\delta$ and every material coordinate.
#[derive(Default)]
pub(crate) struct Mixing {
    /// $(T(v_{k-1}), r_{k-1})$, flattened.
    last: Option<(Vec<f64>, Vec<f64>)>,
}

impl Placement {
    fn flat(&self) -> Vec<f64> {
        std::iter::once(self.entry_offset)
            .chain(self.material.iter().flatten().copied())
            .collect()
    }
}

impl Mixing {
    /// The placement to apply next, after `applied` ($v_k$) gave
    /// `solved` ($T(v_k)$).
    pub fn next(&mut self, applied: &Placement, solved: Placement, extent: [f64; 2]) -> Placement {
        let t = solved.flat();
        let residual: Vec<f64> = t.iter().zip(applied.flat()).map(|(t, v)| t - v).collect();
        let mut next = t.clone();
        if let Some((last_t, last_residual)) = &self.last {
            let (mut num, mut den) = (0.0, 0.0);
            for (r, q) in residual.iter().zip(last_residual) {
                num += r * (r - q);
                den += (r - q) * (r - q);
            }
            if den > 0.0 {
                let gamma = num / den;
                for (n, l) in next.iter_mut().zip(last_t) {
                    *n -= gamma * (*n - l);
                }
            }
        }
        self.last = Some((t, residual));
        Placement {
            entry_offset: next[0],
            material: next[1..]
                .chunks_exact(2)
                .map(|c| clamp([c[0], c[1]], extent))
                .collect(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shaft() -> Shaft {
        Shaft {
            entry: [0.03, 0.0],
            direction: [0.0, 1.0],
            length: 0.04,
        }
    }

    #[test]
    fn a_uniform_shift_is_undone_exactly() {
        // u = (0.5 mm, 2 mm) everywhere: the entry moves in by 2 mm, and
        // each material point is its spatial point minus u.
        let u = |_: [f64; 2]| Ok([0.0005, 0.002]);
        let shaft = shaft();
        let placement = Placement::spatial(&shaft)
            .replaced(&shaft, &u, [0.075, 0.075])
            .unwrap();
        assert!((placement.entry_offset - 0.002).abs() < 1e-12);
        let pieces = placement.material.len() - 1;
        for (k, x) in placement.material.iter().enumerate() {
            let p = Placement::spatial_point(&shaft, 0.002, k, pieces);
            let expected = [p[0] - 0.0005, p[1] - 0.002];
            assert!((x[0] - expected[0]).abs() < 1e-12, "{k}: {x:?}");
            assert!((x[1] - expected[1]).abs() < 1e-12, "{k}: {x:?}");
        }
        let total: f64 = placement
            .pieces(&shaft)
            .map(|piece| piece.s_end - piece.s_start)
            .sum();
        assert!((total - 0.038).abs() < 1e-12);
    }

    #[test]
    fn rounds_converge_to_the_material_line_of_a_linear_field() {
        // u = G X + c with a shear and a stretch along the needle: the
        // consistent material points solve (I + G) X = p - c.
        let g = [[0.02, 0.15], [0.05, 0.1]];
        let c = [0.0002, 0.001];
        let u = |x: [f64; 2]| {
            [
                g[0][0] * x[0] + g[0][1] * x[1] + c[0],
                g[1][0] * x[0] + g[1][1] * x[1] + c[1],
            ]
        };
        let field = |x: [f64; 2]| Ok(u(x));
        let shaft = shaft();
        let mut placement = Placement::spatial(&shaft);
        for _ in 0..12 {
            placement = placement.replaced(&shaft, &field, [0.075, 0.075]).unwrap();
        }
        for (k, x) in placement.material.iter().enumerate().skip(1) {
            let image = [x[0] + u(*x)[0], x[1] + u(*x)[1]];
            let pieces = placement.material.len() - 1;
            let p = Placement::spatial_point(&shaft, placement.entry_offset, k, pieces);
            assert!((image[0] - p[0]).abs() < 1e-12, "{k}");
            assert!((image[1] - p[1]).abs() < 1e-12, "{k}");
        }
        // The entry: on y = 0, its image on the line x = 0.03.
        let xe = (0.03 - c[0]) / (1.0 + g[0][0]);
        let expected = g[1][0] * xe + c[1];
        assert!((placement.entry_offset - expected).abs() < 1e-12);
    }
}
