//! Rotate the local frame of a working node: equation (9) for a node whose
//! coordinates share one condition, equation (10) (with the closed-form inverse
//! of the appendix) for a node with mixed conditions, e.g. a node slipping
//! along the needle.

use faer::{Mat, MatRef};

use crate::system::Frame;
use crate::{CondenseError, CondensedSystem};

/// Tolerance on `R^T R = I` and `det R = 1` for a rotation given by the caller.
const ROTATION_TOLERANCE: f64 = 1e-10;

/// Below this |det| the node block of `(M - S N)` is treated as singular.
const SLIP_DET_TOLERANCE: f64 = 1e-14;

impl CondensedSystem {
    /// Rotates the frame of a 2-D working node by `angle` (radians,
    /// counter-clockwise): see [`CondensedSystem::rotate_node`].
    pub fn rotate_node_by_angle(&mut self, node: usize, angle: f64) -> Result<(), CondenseError> {
        if self.dim != 2 {
            return Err(CondenseError::Dimension(self.dim));
        }
        let (s, c) = angle.sin_cos();
        let mut rotation = crate::system::IDENTITY_FRAME;
        rotation[0][0] = c;
        rotation[0][1] = -s;
        rotation[1][0] = s;
        rotation[1][1] = c;
        self.rotate_node(node, &rotation)
    }

    /// Rotates the frame of a working node by `rotation` (top-left `d x d` block
    /// used), expressed in the node's current frame: `v_old = R v_new`, so the
    /// node frame becomes `F R`. The physical state is kept: the prescribed
    /// values are re-expressed in the new frame (the caller then prescribes what
    /// the needle imposes).
    ///
    /// Uniform node (all coordinates force-given or all displacement-given),
    /// equation (9): `x` and `y` of the node both rotate, so
    /// $$ S' = A^T S A, $$
    /// `A` the identity but for `R` on the node block. It is applied as O(N) row
    /// and column operations on the node's `d` rows and columns (and on the rows
    /// of the pending buffer), never as a product.
    ///
    /// Mixed node, equation (10): with `P` the diagonal selector of the node's
    /// displacement-given coordinates, the old variables are
    /// `x^0 = M x^1 + N y^1` and `y^0 = M y^1 + N x^1` with node blocks
    /// `M = (I-P) R (I-P) + P R P`, `N = (I-P) R P + P R (I-P)`, hence
    /// $$ x^1 = (M - S N)^{-1} (S M - N)\, y^1 . $$
    /// `T = M - S N` differs from the identity in the node columns only, so its
    /// inverse does too: with `D = T_{BB}^{-1}` (closed form: the appendix's
    /// `a_(2i,2i)...` entries in 2-D), `T^{-1}[k, B] = S[k, B] N D` for `k` off the
    /// node. `S' = S + Z E_B^T + Y S[B, :]` with `X = S[:, B](M - I) - E_B N`,
    /// `Y = T^{-1}[:, B] - E_B`, `Z = X + Y X_{BB}`: a rank-`d` update, O(d N^2)
    /// (O(d N) buffered). In 2-D with the first axis displacement-given this is
    /// exactly the paper's `M = diag(cos θ)`, `N = [[0, -sin θ], [sin θ, 0]]`.
    pub fn rotate_node(&mut self, node: usize, rotation: &Frame) -> Result<(), CondenseError> {
        let d = self.dim;
        check_rotation(rotation, d)?;
        let slot = self.slot(node)?;
        let b0 = slot * d;
        // Physical state of the node in the new frame.
        let mut displacement = [0.0; 3];
        let mut force = [0.0; 3];
        for a in 0..d {
            let unknown = self.unknown(b0 + a);
            let given = self.prescribed[b0 + a];
            if self.displacement_given[b0 + a] {
                displacement[a] = given;
                force[a] = unknown;
            } else {
                displacement[a] = unknown;
                force[a] = given;
            }
        }
        let displacement = transpose_times(rotation, &displacement, d);
        let force = transpose_times(rotation, &force, d);

        let first = self.displacement_given[b0];
        let uniform = (0..d).all(|a| self.displacement_given[b0 + a] == first);
        if self.is_capacitance() {
            // G rotates by equation (9) whatever the conditions; σ keeps its
            // local coordinates, so only the factor of G[σ, σ] must follow.
            self.rotate_uniform(b0, rotation);
            if (0..d).any(|a| self.displacement_given[b0 + a]) {
                self.refactor_capacitance()?;
            }
        } else if uniform {
            self.rotate_uniform(b0, rotation);
        } else {
            self.rotate_mixed(node, b0, rotation)?;
        }

        let frame = &mut self.frames[slot];
        let old = *frame;
        for r in 0..d {
            for c in 0..d {
                frame[r][c] = (0..d).map(|k| old[r][k] * rotation[k][c]).sum();
            }
        }
        for a in 0..d {
            self.prescribed[b0 + a] = if self.displacement_given[b0 + a] {
                displacement[a]
            } else {
                force[a]
            };
        }
        Ok(())
    }

    /// Equation (9) on the node block starting at `b0`.
    pub(crate) fn rotate_uniform(&mut self, b0: usize, rotation: &Frame) {
        let d = self.dim;
        let n = self.len();
        // Columns: S[:, B] <- S[:, B] R.
        let block = &mut self.scratch.block[..n * d];
        for a in 0..d {
            block[a * n..(a + 1) * n].copy_from_slice(self.base.col(b0 + a));
        }
        for a in 0..d {
            let col = self.base.col_mut(b0 + a);
            col.fill(0.0);
            for b in 0..d {
                let weight = rotation[b][a];
                if weight != 0.0 {
                    for (s, v) in col.iter_mut().zip(&block[b * n..(b + 1) * n]) {
                        *s += weight * v;
                    }
                }
            }
        }
        // Rows: S[B, :] <- R^T S[B, :], and the same on the rows of U and W.
        rotate_rows(&mut self.base, b0, rotation, d, n);
        let pending = self.pending;
        rotate_rows(&mut self.pending_u, b0, rotation, d, pending);
        rotate_rows(&mut self.pending_w, b0, rotation, d, pending);
    }

    /// Equation (10) on the mixed node block starting at `b0`.
    fn rotate_mixed(
        &mut self,
        node: usize,
        b0: usize,
        rotation: &Frame,
    ) -> Result<(), CondenseError> {
        let d = self.dim;
        let n = self.len();
        let mut given = [false; 3];
        for (a, g) in given.iter_mut().enumerate().take(d) {
            *g = self.displacement_given[b0 + a];
        }
        let mut m = [[0.0; 3]; 3];
        let mut nn = [[0.0; 3]; 3];
        for a in 0..d {
            for b in 0..d {
                if given[a] == given[b] {
                    m[a][b] = rotation[a][b];
                } else {
                    nn[a][b] = rotation[a][b];
                }
            }
        }
        let mut block = std::mem::take(&mut self.scratch.block);
        let (columns, rest) = block.split_at_mut(n * d);
        let (rows, rest) = rest.split_at_mut(n * d);
        let (y, rest) = rest.split_at_mut(n * d);
        let z = &mut rest[..n * d];
        for a in 0..d {
            self.current_column_into(b0 + a, &mut columns[a * n..(a + 1) * n]);
            let sign_a = self.sign(b0 + a);
            for j in 0..n {
                rows[a * n + j] = sign_a * self.sign(j) * columns[a * n + j];
            }
        }
        let s_at = |k: usize, b: usize| columns[b * n + k];
        // T_BB = M - S_BB N and its inverse D.
        let mut t = [[0.0; 3]; 3];
        for a in 0..d {
            for b in 0..d {
                t[a][b] = m[a][b] - (0..d).map(|c| s_at(b0 + a, c) * nn[c][b]).sum::<f64>();
            }
        }
        let Some(inverse) = invert_small(&t, d) else {
            self.scratch.block = block;
            return Err(CondenseError::SingularSlipTransform {
                node,
                det: determinant(&t, d),
            });
        };
        let mut n_inverse = [[0.0; 3]; 3];
        for a in 0..d {
            for b in 0..d {
                n_inverse[a][b] = (0..d).map(|c| nn[a][c] * inverse[c][b]).sum();
            }
        }
        // Y = T^{-1}[:, B] - E_B and X = S[:, B](M - I) - E_B N (kept in z for now).
        for k in 0..n {
            let in_block = (b0..b0 + d).contains(&k);
            for a in 0..d {
                let (mut yk, mut xk) = (0.0, 0.0);
                for b in 0..d {
                    let s_kb = s_at(k, b);
                    yk += s_kb * n_inverse[b][a];
                    xk += s_kb * (m[b][a] - if a == b { 1.0 } else { 0.0 });
                }
                if in_block {
                    let r = k - b0;
                    yk = inverse[r][a] - if r == a { 1.0 } else { 0.0 };
                    xk -= nn[r][a];
                }
                y[a * n + k] = yk;
                z[a * n + k] = xk;
            }
        }
        // Z = X + Y X_BB.
        let mut x_bb = [[0.0; 3]; 3];
        for b in 0..d {
            for a in 0..d {
                x_bb[b][a] = z[a * n + b0 + b];
            }
        }
        for a in 0..d {
            for b in 0..d {
                let weight = x_bb[b][a];
                if weight != 0.0 {
                    for k in 0..n {
                        z[a * n + k] += y[b * n + k] * weight;
                    }
                }
            }
        }
        for a in 0..d {
            for (s, v) in self
                .base
                .col_mut(b0 + a)
                .iter_mut()
                .zip(&z[a * n..(a + 1) * n])
            {
                *s += v;
            }
        }
        for a in 0..d {
            self.add_rank_one(&y[a * n..(a + 1) * n], &rows[a * n..(a + 1) * n]);
        }
        self.scratch.block = block;
        Ok(())
    }
}

/// `rows[b0..b0+d, j] <- R^T rows[b0..b0+d, j]` for the first `cols` columns.
fn rotate_rows(
    matrix: &mut crate::dense::Dense,
    b0: usize,
    rotation: &Frame,
    d: usize,
    cols: usize,
) {
    for j in 0..cols {
        let col = matrix.col_mut(j);
        let mut old = [0.0; 3];
        old[..d].copy_from_slice(&col[b0..b0 + d]);
        let new = transpose_times(rotation, &old, d);
        col[b0..b0 + d].copy_from_slice(&new[..d]);
    }
}

fn transpose_times(rotation: &Frame, v: &[f64; 3], d: usize) -> [f64; 3] {
    let mut out = [0.0; 3];
    for a in 0..d {
        out[a] = (0..d).map(|b| rotation[b][a] * v[b]).sum();
    }
    out
}

fn check_rotation(rotation: &Frame, d: usize) -> Result<(), CondenseError> {
    let mut deviation: f64 = 0.0;
    for a in 0..d {
        for b in 0..d {
            let dot: f64 = (0..d).map(|k| rotation[k][a] * rotation[k][b]).sum();
            deviation = deviation.max((dot - if a == b { 1.0 } else { 0.0 }).abs());
        }
    }
    deviation = deviation.max((determinant(rotation, d) - 1.0).abs());
    if deviation > ROTATION_TOLERANCE || deviation.is_nan() {
        return Err(CondenseError::InvalidRotation { dim: d, deviation });
    }
    Ok(())
}

fn determinant(t: &[[f64; 3]; 3], d: usize) -> f64 {
    if d == 2 {
        t[0][0] * t[1][1] - t[0][1] * t[1][0]
    } else {
        t[0][0] * (t[1][1] * t[2][2] - t[1][2] * t[2][1])
            - t[0][1] * (t[1][0] * t[2][2] - t[1][2] * t[2][0])
            + t[0][2] * (t[1][0] * t[2][1] - t[1][1] * t[2][0])
    }
}

/// Closed-form inverse (adjugate over determinant) of a 2x2 or 3x3 block.
fn invert_small(t: &[[f64; 3]; 3], d: usize) -> Option<[[f64; 3]; 3]> {
    let det = determinant(t, d);
    if det.abs() <= SLIP_DET_TOLERANCE || det.is_nan() {
        return None;
    }
    let mut inv = [[0.0; 3]; 3];
    if d == 2 {
        inv[0][0] = t[1][1] / det;
        inv[0][1] = -t[0][1] / det;
        inv[1][0] = -t[1][0] / det;
        inv[1][1] = t[0][0] / det;
    } else {
        for r in 0..3 {
            for c in 0..3 {
                // Cofactor of (c, r) (transposed) over the determinant.
                let (r1, r2) = ((c + 1) % 3, (c + 2) % 3);
                let (c1, c2) = ((r + 1) % 3, (r + 2) % 3);
                inv[r][c] = (t[r1][c1] * t[r2][c2] - t[r1][c2] * t[r2][c1]) / det;
            }
        }
    }
    Some(inv)
}

/// The appendix's closed form of the two non-trivial columns of
/// `(M - K_W^{-1} N)^{-1}` for a 2-D slipping node whose coordinates are `a`
/// (displacement-given, the needle's lateral axis) and `a + 1` (force-given,
/// axial), rotated by `theta`; `s` is the current system matrix. Returns the
/// `N x 2` matrix of columns `a` and `a + 1` (all other columns are unit vectors).
///
/// With `b = a + 1`, `c = cos θ`, `s = sin θ`, `k` the entries of `s`:
/// $$ a_{(j,a)} = \frac{-s\,k_{jb}(c + k_{ba}s) + s\,k_{ja}k_{bb}s}{\Sigma},\quad
///    a_{(j,b)} = \frac{s\,k_{ja}(c - k_{ab}s) + s\,k_{jb}k_{aa}s}{\Sigma}, $$
/// $$ a_{(a,a)} = -\frac{c + k_{ba}s}{\Sigma},\ a_{(a,b)} = \frac{k_{aa}s}{\Sigma},\
///    a_{(b,a)} = -\frac{k_{bb}s}{\Sigma},\ a_{(b,b)} = \frac{-c + k_{ab}s}{\Sigma}, $$
/// $$ \Sigma = -c^2 + cs\,(k_{ab} - k_{ba}) + s^2 (k_{ab}k_{ba} - k_{aa}k_{bb}) = -\det T_{BB}. $$
/// The paper prints the last term as `s^2 (k_ab k_ba) - k_aa k_bb`, dropping the
/// `s^2` on `k_aa k_bb` (a misplaced parenthesis; see `docs/condense.md`).
/// This function is the paper's formula, checked against a direct inverse in
/// the tests; [`CondensedSystem::rotate_node`] uses the same algebra for any
/// split of conditions in 2-D and 3-D.
pub fn appendix_slip_inverse_columns(
    s: MatRef<'_, f64>,
    a: usize,
    theta: f64,
) -> Result<Mat<f64>, CondenseError> {
    let n = s.nrows();
    let b = a + 1;
    if s.ncols() != n || b >= n {
        return Err(CondenseError::CoordinateOutOfRange {
            coordinate: b,
            len: n.min(s.ncols()),
        });
    }
    let (sn, c) = theta.sin_cos();
    let k = |i: usize, j: usize| s[(i, j)];
    let sigma =
        -c * c + c * sn * (k(a, b) - k(b, a)) + sn * sn * (k(a, b) * k(b, a) - k(a, a) * k(b, b));
    if sigma.abs() <= SLIP_DET_TOLERANCE || sigma.is_nan() {
        return Err(CondenseError::SingularSlipTransform {
            node: a / 2,
            det: -sigma,
        });
    }
    let mut out = Mat::<f64>::zeros(n, 2);
    for j in 0..n {
        out[(j, 0)] = (-sn * k(j, b) * (c + k(b, a) * sn) + sn * k(j, a) * k(b, b) * sn) / sigma;
        out[(j, 1)] = (sn * k(j, a) * (c - k(a, b) * sn) + sn * k(j, b) * k(a, a) * sn) / sigma;
    }
    out[(a, 0)] = -(c + k(b, a) * sn) / sigma;
    out[(a, 1)] = k(a, a) * sn / sigma;
    out[(b, 0)] = -k(b, b) * sn / sigma;
    out[(b, 1)] = (-c + k(a, b) * sn) / sigma;
    Ok(out)
}
