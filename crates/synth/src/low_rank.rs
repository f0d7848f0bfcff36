//! Solves with a factorised matrix changed by a few small symmetric
//! blocks, without refactorising it (Woodbury's identity).
//!
//! A probe's Newton step revises which nodes it presses, and each revision
//! adds or removes a node's 2 x 2 penalty block (`contact`); refactorising
//! the whole tangent for that is most of a step's cost. With $K$
//! factorised ($L L^T$, or $L D L^T$) and the change $E B E^T$ ($E$ the
//! unit columns of the $m$ components the blocks touch, $B$ their
//! $m \times m$ values),
//! $$(K + E B E^T)\, x = r$$
//! is solved as $x = x_0 - Z y$ with $x_0 = K^{-1} r$, $Z = K^{-1} E$ and
//! $$(I + B C)\, y = B E^T x_0, \qquad C = E^T Z,$$
//! which follows from $y = B E^T x$. This form needs no $B^{-1}$: a node's
//! penalty block $k\, \nabla g\, \nabla g^T$ is singular. The $m$ solves
//! for $Z$ are made once per change, together, and each further right-hand
//! side costs one solve and an $m \times m$ back-substitution.
//!
//! Written here because faer updates dense Cholesky factors by low rank
//! but not its sparse supernodal ones, and because an update in place
//! would change the factor itself, while one Newton step tries several
//! sets of pressed nodes, and later steps other ones, against the same
//! factorisation.

use nalgebra::{DMatrix, DVector};

use crate::system::Factorised;

/// A change $E B E^T$ of a factorised matrix: blocks of components and
/// their symmetric values, row-major.
pub(crate) struct Blocks {
    /// The components each block touches (free components only).
    pub dofs: Vec<Vec<usize>>,
    /// Each block's values, `dofs.len()` squared, row-major.
    pub values: Vec<Vec<f64>>,
}

impl Blocks {
    /// No change.
    pub fn none() -> Self {
        Self {
            dofs: Vec::new(),
            values: Vec::new(),
        }
    }
}

/// A factorisation with a low-rank change applied at solve time.
pub(crate) struct Updated<'a> {
    factorised: &'a Factorised,
    dofs: Vec<usize>,
    /// $Z = K^{-1} E$, one full-size column per component.
    responses: Vec<Vec<f64>>,
    /// $B$, block diagonal.
    coupling: DMatrix<f64>,
    /// $I + B C$, factorised.
    system: nalgebra::LU<f64, nalgebra::Dyn, nalgebra::Dyn>,
}

impl<'a> Updated<'a> {
    /// `factorised` changed by `blocks`.
    pub fn new(factorised: &'a Factorised, blocks: &Blocks) -> Self {
        let dofs: Vec<usize> = blocks.dofs.iter().flatten().copied().collect();
        let m = dofs.len();
        let mut coupling = DMatrix::zeros(m, m);
        let mut at = 0;
        for (block, values) in blocks.dofs.iter().zip(&blocks.values) {
            let b = block.len();
            for i in 0..b {
                for j in 0..b {
                    coupling[(at + i, at + j)] = values[i * b + j];
                }
            }
            at += b;
        }
        let size = factorised.size();
        let units: Vec<Vec<f64>> = dofs
            .iter()
            .map(|&dof| {
                let mut e = vec![0.0; size];
                e[dof] = 1.0;
                e
            })
            .collect();
        let refs: Vec<&[f64]> = units.iter().map(Vec::as_slice).collect();
        let responses = if m == 0 {
            Vec::new()
        } else {
            factorised.solve(&refs)
        };
        let compliance = DMatrix::from_fn(m, m, |i, j| responses[j][dofs[i]]);
        let system = (DMatrix::identity(m, m) + &coupling * compliance).lu();
        Self {
            factorised,
            dofs,
            responses,
            coupling,
            system,
        }
    }

    /// Solves the changed system for `r` (full size; held components are
    /// ignored and come back zero, as `Factorised::solve`'s).
    pub fn solve(&self, r: &[f64]) -> Vec<f64> {
        let mut x = self.factorised.solve(&[r]).pop().expect("one solution");
        if self.dofs.is_empty() {
            return x;
        }
        let picked = DVector::from_iterator(self.dofs.len(), self.dofs.iter().map(|&d| x[d]));
        let y = self
            .system
            .solve(&(&self.coupling * picked))
            .expect("I + B C is regular for a change that keeps the matrix regular");
        for (column, &yj) in self.responses.iter().zip(y.iter()) {
            for (xi, zi) in x.iter_mut().zip(column) {
                *xi -= zi * yj;
            }
        }
        x
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::system::Stiffness;
    use faer::sparse::SparseColMat;
    use faer::sparse::Triplet;
    use proptest::prelude::*;

    /// A chain of springs, fixed at component 0: stiffness `k` between
    /// neighbours.
    fn chain(k: &[f64], extra: &[(usize, usize, f64)]) -> Stiffness {
        let n = k.len() + 1;
        let mut t = Vec::new();
        for (i, &ki) in k.iter().enumerate() {
            t.push(Triplet::new(i, i, ki));
            t.push(Triplet::new(i + 1, i + 1, ki));
            t.push(Triplet::new(i, i + 1, -ki));
            t.push(Triplet::new(i + 1, i, -ki));
        }
        t.extend(extra.iter().map(|&(i, j, v)| Triplet::new(i, j, v)));
        let elastic = SparseColMat::try_new_from_triplets(n, n, &t).expect("valid triplets");
        Stiffness::new(&elastic, &[]).expect("no springs")
    }

    fn held(n: usize) -> Vec<bool> {
        (0..n).map(|i| i == 0).collect()
    }

    /// The blocks as triplets of the full matrix (zero where the base
    /// matrix has them, so that both share one pattern).
    fn as_triplets(blocks: &Blocks) -> Vec<(usize, usize, f64)> {
        let mut t = Vec::new();
        for (dofs, values) in blocks.dofs.iter().zip(&blocks.values) {
            let b = dofs.len();
            for i in 0..b {
                for j in 0..b {
                    t.push((dofs[i], dofs[j], values[i * b + j]));
                }
            }
        }
        t
    }

    proptest! {
        /// A penalty-like block added and a block removed, solved through
        /// the update, equal the changed matrix factorised afresh.
        #[test]
        fn an_updated_solve_equals_a_fresh_factorisation_of_the_changed_matrix(
            k in prop::collection::vec(1.0f64..100.0, 8..16),
            (a, b) in (1usize..4, 4usize..8),
            penalty in 1.0f64..1e6,
            direction in -1.0f64..1.0,
            removed in 0.1f64..0.9,
            r in prop::collection::vec(-1.0f64..1.0, 17),
        ) {
            let n = k.len() + 1;
            // The base holds a spring between a and b that the change
            // takes back in part, and the change presses a node pair by a
            // singular penalty block, as a contact node does.
            let c = (1.0 - direction * direction).sqrt();
            let base_spring = [(a, a, 50.0), (b, b, 50.0), (a, b, -50.0), (b, a, -50.0)];
            let change = Blocks {
                dofs: vec![vec![a, b], vec![n - 2, n - 1]],
                values: vec![
                    vec![-50.0 * removed, 50.0 * removed, 50.0 * removed, -50.0 * removed],
                    vec![
                        penalty * direction * direction,
                        penalty * direction * c,
                        penalty * direction * c,
                        penalty * c * c,
                    ],
                ],
            };
            let base = chain(&k, &base_spring);
            let mut changed_entries = base_spring.to_vec();
            changed_entries.extend(as_triplets(&change));
            let changed = chain(&k, &changed_entries);
            let held = held(n);
            let factorised = Factorised::new(&base, &held, "base").expect("positive");
            let fresh = Factorised::new(&changed, &held, "changed").expect("positive");
            let rhs = &r[..n];
            let expected = fresh.solve(&[rhs]).pop().expect("one");
            let got = Updated::new(&factorised, &change).solve(rhs);
            let scale = expected.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            for (g, e) in got.iter().zip(&expected) {
                prop_assert!((g - e).abs() <= 1e-9 * scale, "{g} against {e}");
            }
        }
    }

    #[test]
    fn no_change_solves_as_the_factorisation() {
        let base = chain(&[3.0, 5.0, 7.0], &[]);
        let held = held(4);
        let factorised = Factorised::new(&base, &held, "base").expect("positive");
        let none = Blocks::none();
        let r = [0.0, 1.0, -2.0, 0.5];
        assert_eq!(
            Updated::new(&factorised, &none).solve(&r),
            factorised.solve(&[&r]).pop().expect("one")
        );
    }
}
