//! The compressible neo-Hookean material: strain energy, first
//! Piola–Kirchhoff stress and its consistent tangent.
//!
//! With the deformation gradient $F = I + \nabla_X u$, $J = \det F$ and
//! $I_1 = \operatorname{tr}(F^T F)$, the stored energy per unit reference
//! volume is
//!
//! $$W(F) = \frac{\mu}{2}(I_1 - 3) - \mu \ln J + \frac{\lambda}{2}(\ln J)^2 ,$$
//!
//! with the Lamé parameters $\mu$, $\lambda$ of the linear [`Material`] of
//! the same $E$, $\nu$. Using $\partial \ln J/\partial F = F^{-T}$ and
//! $\partial F^{-1}_{Ji}/\partial F_{kL} = -F^{-1}_{Jk} F^{-1}_{Li}$:
//!
//! $$P = \frac{\partial W}{\partial F} = \mu (F - F^{-T}) + \lambda \ln J \, F^{-T},$$
//!
//! $$\mathbb{A}_{iJkL} = \frac{\partial P_{iJ}}{\partial F_{kL}}
//!   = \mu\,\delta_{ik}\delta_{JL}
//!   + (\mu - \lambda\ln J)\, F^{-1}_{Li} F^{-1}_{Jk}
//!   + \lambda\, F^{-1}_{Ji} F^{-1}_{Lk},$$
//!
//! which has the major symmetry $\mathbb{A}_{iJkL} = \mathbb{A}_{kLiJ}$
//! (so the assembled tangent is symmetric).
//!
//! **Small-strain limit.** With $F = I + H$, $F^{-T} \approx I - H^T$ and
//! $\ln J \approx \operatorname{tr} H$, so
//! $P \approx \mu (H + H^T) + \lambda (\operatorname{tr} H) I
//! = 2\mu\varepsilon + \lambda \operatorname{tr}\varepsilon\, I$ and
//! $\mathbb{A}(I)_{iJkL} = \mu(\delta_{ik}\delta_{JL} + \delta_{iL}\delta_{Jk})
//! + \lambda\delta_{iJ}\delta_{kL}$: exactly the linear model's $D$.
//!
//! **Plane strain.** $F_{33} = 1$ and $F_{i3} = F_{3i} = 0$, so $F^{-1}$ is
//! block diagonal, $J = \det F_{2\times2}$ and $I_1 = \operatorname{tr}(F^T F)_{2\times2} + 1$;
//! the in-plane $P$ and $\mathbb{A}$ are the formulas above with 2x2
//! matrices. The out-of-plane stress $P_{33} = \lambda \ln J$ holds the
//! body in its plane ([`NeoHookean::out_of_plane_stress`]). Plane stress is
//! not provided.
//!
//! Every function takes the displacement gradient $H = \nabla_X u = F - I$
//! rather than $F$, and evaluates $P = \mu(H + F^{-T}H^T) + \lambda\ln J\,F^{-T}$
//! with $\ln J = \operatorname{ln1p}(J - 1)$ and $J - 1$ from the invariants
//! of $H$: the textbook form subtracts $O(1)$ terms and would lose all
//! digits of a $10^{-8}$ strain.
//!
//! Index convention: the `D*D x D*D` tangent is indexed by `i*D + J` and
//! `k*D + L` (row of $F$ first).

use nalgebra::SMatrix;
use serde::Serialize;

use crate::element::stiffness::determinant_and_inverse;
use crate::material::Material;

/// A compressible neo-Hookean material ($\mu$, $\lambda$ in Pa). Build it
/// from a linear [`Material`] so that both models agree at small strain.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct NeoHookean {
    shear_modulus: f64,
    lame_lambda: f64,
}

impl NeoHookean {
    /// The neo-Hookean material with the Lamé parameters of `material`.
    pub fn from_material(material: &Material) -> Self {
        Self {
            shear_modulus: material.shear_modulus(),
            lame_lambda: material.lame_lambda(),
        }
    }

    /// Shear modulus $\mu$.
    pub fn shear_modulus(&self) -> f64 {
        self.shear_modulus
    }

    /// Lamé's first parameter $\lambda$.
    pub fn lame_lambda(&self) -> f64 {
        self.lame_lambda
    }

    /// Stored energy $W$ per unit reference volume at displacement gradient
    /// $H = \nabla_X u$ (`D` = 2: plane strain, `D` = 3: solid). The error
    /// is $J = \det F$ when it is not positive (the energy is infinite).
    pub fn strain_energy<const D: usize>(&self, h: &SMatrix<f64, D, D>) -> Result<f64, f64> {
        let kinematics = Kinematics::new(h)?;
        // I_1 - 3 = 2 tr H + |H|^2 in both 3-D and plane strain (F_33 = 1).
        let i1_minus_3 = 2.0 * h.trace() + h.norm_squared();
        let ln_j = kinematics.ln_j;
        Ok(
            0.5 * self.shear_modulus * i1_minus_3 - self.shear_modulus * ln_j
                + 0.5 * self.lame_lambda * ln_j * ln_j,
        )
    }

    /// First Piola–Kirchhoff stress $P$ at displacement gradient $H$. The
    /// error is $J \le 0$.
    pub fn stress<const D: usize>(
        &self,
        h: &SMatrix<f64, D, D>,
    ) -> Result<SMatrix<f64, D, D>, f64> {
        Ok(self.stress_from(h, &Kinematics::new(h)?))
    }

    /// $P = \mu(H + F^{-T}H^T) + \lambda \ln J\, F^{-T}$: the same as
    /// $\mu(F - F^{-T}) + \dots$ (as $F^{-T} = I - F^{-T}H^T$) but free of the
    /// cancellation of $O(1)$ terms that would cost all digits at small strain.
    fn stress_from<const D: usize>(
        &self,
        h: &SMatrix<f64, D, D>,
        kinematics: &Kinematics<D>,
    ) -> SMatrix<f64, D, D> {
        let inverse_transpose = kinematics.inverse.transpose();
        (h + inverse_transpose * h.transpose()) * self.shear_modulus
            + inverse_transpose * (self.lame_lambda * kinematics.ln_j)
    }

    /// $P$ and the tangent $\mathbb{A} = \partial P/\partial F$ as a
    /// `DD x DD` matrix (`DD = D*D`, index `i*D + J`) at displacement
    /// gradient $H$. The error is $J \le 0$.
    pub fn stress_and_tangent<const D: usize, const DD: usize>(
        &self,
        h: &SMatrix<f64, D, D>,
    ) -> Result<(SMatrix<f64, D, D>, SMatrix<f64, DD, DD>), f64> {
        debug_assert_eq!(DD, D * D);
        let kinematics = Kinematics::new(h)?;
        let (mu, lambda) = (self.shear_modulus, self.lame_lambda);
        let inverse = &kinematics.inverse;
        let geometric = mu - lambda * kinematics.ln_j;
        let mut tangent = SMatrix::<f64, DD, DD>::zeros();
        for i in 0..D {
            for big_j in 0..D {
                for k in 0..D {
                    for l in 0..D {
                        let identity = if i == k && big_j == l { mu } else { 0.0 };
                        tangent[(i * D + big_j, k * D + l)] = identity
                            + geometric * inverse[(l, i)] * inverse[(big_j, k)]
                            + lambda * inverse[(big_j, i)] * inverse[(l, k)];
                    }
                }
            }
        }
        Ok((self.stress_from(h, &kinematics), tangent))
    }

    /// Out-of-plane stress $P_{33} = \lambda \ln J$ of a plane-strain state
    /// (the stress that keeps $F_{33} = 1$) at displacement gradient $H$.
    /// The error is $J \le 0$.
    pub fn out_of_plane_stress(&self, h: &SMatrix<f64, 2, 2>) -> Result<f64, f64> {
        Ok(self.lame_lambda * Kinematics::new(h)?.ln_j)
    }
}

/// $F^{-1}$ and $\ln J$ from $H$, with $J - 1$ summed from the invariants
/// of $H$ (so $\ln J$ keeps its relative accuracy at small strain).
struct Kinematics<const D: usize> {
    inverse: SMatrix<f64, D, D>,
    ln_j: f64,
}

impl<const D: usize> Kinematics<D> {
    /// The error is $J$ when it is not positive (or not finite).
    fn new(h: &SMatrix<f64, D, D>) -> Result<Self, f64> {
        let (_, inverse) = determinant_and_inverse(&(SMatrix::<f64, D, D>::identity() + h));
        let (determinant, _) = determinant_and_inverse(h);
        // det(I + H) = 1 + tr H + (sum of principal 2x2 minors) + det H (3-D).
        let trace = h.trace();
        let j_minus_1 = if D == 2 {
            trace + determinant
        } else {
            let minors = 0.5 * (trace * trace - (h * h).trace());
            trace + minors + determinant
        };
        let j = 1.0 + j_minus_1;
        if j > 0.0 && j.is_finite() {
            Ok(Self {
                inverse,
                ln_j: j_minus_1.ln_1p(),
            })
        } else {
            Err(j)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Matrix2, Matrix3};

    fn material() -> NeoHookean {
        NeoHookean::from_material(&Material::new(25.3e3, 0.48).unwrap())
    }

    /// A displacement gradient H = F - I of 8-20 % strain.
    fn gradient_3d() -> Matrix3<f64> {
        Matrix3::new(0.15, 0.08, -0.05, -0.03, -0.08, 0.1, 0.06, -0.07, 0.2)
    }

    /// Central differences of `g` in each entry of `f`, step `h`.
    fn central_difference<const D: usize, const R: usize>(
        f: &SMatrix<f64, D, D>,
        h: f64,
        g: impl Fn(&SMatrix<f64, D, D>) -> SMatrix<f64, R, 1>,
    ) -> Vec<SMatrix<f64, R, 1>> {
        let mut columns = Vec::new();
        for k in 0..D {
            for l in 0..D {
                let (mut plus, mut minus) = (*f, *f);
                plus[(k, l)] += h;
                minus[(k, l)] -= h;
                columns.push((g(&plus) - g(&minus)) / (2.0 * h));
            }
        }
        columns
    }

    #[test]
    fn stress_is_the_energy_gradient_in_3d_and_plane_strain() {
        let m = material();
        let f3 = gradient_3d();
        let numeric = central_difference(&f3, 1e-6, |f| {
            SMatrix::<f64, 1, 1>::new(m.strain_energy(f).unwrap())
        });
        let p = m.stress(&f3).unwrap();
        for k in 0..3 {
            for l in 0..3 {
                let value = numeric[k * 3 + l][0];
                assert!((value - p[(k, l)]).abs() < 1e-6 * p.norm(), "{k}{l}");
            }
        }
        let f2 = Matrix2::new(0.2, 0.1, -0.04, -0.1);
        let numeric = central_difference(&f2, 1e-6, |f| {
            SMatrix::<f64, 1, 1>::new(m.strain_energy(f).unwrap())
        });
        let p = m.stress(&f2).unwrap();
        for k in 0..2 {
            for l in 0..2 {
                assert!((numeric[k * 2 + l][0] - p[(k, l)]).abs() < 1e-6 * p.norm());
            }
        }
    }

    #[test]
    fn tangent_is_the_stress_derivative() {
        let m = material();
        let f = gradient_3d();
        let (_, tangent) = m.stress_and_tangent::<3, 9>(&f).unwrap();
        let numeric = central_difference(&f, 1e-6, |g| {
            let p = m.stress(g).unwrap();
            SMatrix::<f64, 9, 1>::from_fn(|r, _| p[(r / 3, r % 3)])
        });
        for (column, values) in numeric.iter().enumerate() {
            for row in 0..9 {
                let exact = tangent[(row, column)];
                assert!(
                    (values[row] - exact).abs() < 1e-6 * tangent.norm(),
                    "A[{row},{column}] = {exact}, numeric {}",
                    values[row]
                );
            }
        }
        assert!((tangent - tangent.transpose()).norm() < 1e-12 * tangent.norm());
    }

    #[test]
    fn reference_state_is_stress_free_with_the_linear_moduli() {
        let linear = Material::new(25.3e3, 0.48).unwrap();
        let m = NeoHookean::from_material(&linear);
        let (stress, tangent) = m.stress_and_tangent::<3, 9>(&Matrix3::zeros()).unwrap();
        assert_eq!(stress.norm(), 0.0);
        assert_eq!(m.strain_energy(&Matrix3::zeros()).unwrap(), 0.0);
        // A(I) applied to a symmetric gradient is D applied to its strain.
        let (mu, lambda) = (linear.shear_modulus(), linear.lame_lambda());
        let h = Matrix3::new(1.0, 0.2, -0.3, 0.2, -0.5, 0.7, -0.3, 0.7, 0.4) * 1e-3;
        let flat = SMatrix::<f64, 9, 1>::from_fn(|r, _| h[(r / 3, r % 3)]);
        let image = tangent * flat;
        let expected = h * (2.0 * mu) + Matrix3::identity() * (lambda * h.trace());
        for r in 0..9 {
            assert!((image[r] - expected[(r / 3, r % 3)]).abs() < 1e-9 * expected.norm());
        }
    }

    #[test]
    fn stress_keeps_its_relative_accuracy_at_tiny_strain() {
        // At strain 1e-9 the stress is linear to ~1e-9 relative; forming
        // F - F^{-T} from F = I + H would leave only ~1e-7.
        let linear = Material::new(25.3e3, 0.48).unwrap();
        let m = NeoHookean::from_material(&linear);
        let h = Matrix3::new(1.0, 0.3, -0.2, 0.1, -0.7, 0.4, 0.5, -0.2, 0.6) * 1e-9;
        let strain = (h + h.transpose()) * 0.5;
        let expected = strain * (2.0 * linear.shear_modulus())
            + Matrix3::identity() * (linear.lame_lambda() * strain.trace());
        let p = m.stress(&h).unwrap();
        assert!((p - expected).norm() < 1e-8 * expected.norm());
    }

    #[test]
    fn inverted_deformation_is_rejected() {
        let m = material();
        // F = diag(-1, 1).
        let flipped = Matrix2::new(-2.0, 0.0, 0.0, 0.0);
        assert_eq!(m.stress(&flipped), Err(-1.0));
        assert!(m.strain_energy(&(-Matrix3::identity())).is_err());
        assert!(m.out_of_plane_stress(&flipped).is_err());
    }
}
