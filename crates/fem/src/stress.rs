//! Strains and stresses from a displacement field.
//!
//! At a point of element $e$: $\varepsilon = B(\xi) u^e$ (Voigt, engineering
//! shear strains, see [`crate::material`]) and $\sigma = D\varepsilon$. In
//! plane strain the out-of-plane stress
//! $\sigma_{zz} = \lambda(\varepsilon_{xx} + \varepsilon_{yy})$ is not part
//! of the returned vector.

use nalgebra::SMatrix;

use crate::element::shape;
use crate::element::stiffness::determinant_and_inverse;
use crate::error::FemError;
use crate::locate::Location;
use crate::material::{Constitutive, Formulation, Materials};
use crate::mesh::Mesh;

/// Gradient of the displacement, $\partial u_i/\partial x_j$, at a location.
pub fn displacement_gradient<const D: usize>(
    mesh: &Mesh<D>,
    displacement: &[f64],
    location: &Location<D>,
) -> Result<SMatrix<f64, D, D>, FemError> {
    if displacement.len() != mesh.dof_count() {
        return Err(FemError::DimensionMismatch {
            context: "displacement",
            expected: mesh.dof_count(),
            actual: displacement.len(),
        });
    }
    let nodes = mesh.element(location.element);
    let (_, reference) = shape::values_and_gradients(D, nodes.len(), &location.reference);
    let mut jacobian = SMatrix::<f64, D, D>::zeros();
    for (a, &n) in nodes.iter().enumerate() {
        let x = mesh.node(n);
        for i in 0..D {
            for j in 0..D {
                jacobian[(i, j)] += x[i] * reference[a][j];
            }
        }
    }
    let (determinant, inverse) = determinant_and_inverse(&jacobian);
    if determinant.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return Err(FemError::DegenerateElement {
            element: location.element,
            determinant,
        });
    }
    let mut gradient = SMatrix::<f64, D, D>::zeros();
    for (a, &n) in nodes.iter().enumerate() {
        // Physical gradient of N_a: J^{-T} (dN_a/dxi).
        for j in 0..D {
            let dn: f64 = (0..D).map(|k| inverse[(k, j)] * reference[a][k]).sum();
            for i in 0..D {
                gradient[(i, j)] += displacement[n * D + i] * dn;
            }
        }
    }
    Ok(gradient)
}

/// Voigt strain (3 components in 2-D, 6 in 3-D) at a location.
pub fn strain<const D: usize>(
    mesh: &Mesh<D>,
    displacement: &[f64],
    location: &Location<D>,
) -> Result<Vec<f64>, FemError> {
    let g = displacement_gradient(mesh, displacement, location)?;
    Ok(if D == 2 {
        vec![g[(0, 0)], g[(1, 1)], g[(0, 1)] + g[(1, 0)]]
    } else {
        vec![
            g[(0, 0)],
            g[(1, 1)],
            g[(2, 2)],
            g[(1, 2)] + g[(2, 1)],
            g[(0, 2)] + g[(2, 0)],
            g[(0, 1)] + g[(1, 0)],
        ]
    })
}

/// Voigt stress $\sigma = D \varepsilon$ at a location, with the material of
/// the element's region.
pub fn stress<const D: usize>(
    mesh: &Mesh<D>,
    formulation: Formulation,
    materials: &Materials,
    displacement: &[f64],
    location: &Location<D>,
) -> Result<Vec<f64>, FemError> {
    let region = mesh.regions()[location.element];
    let material = materials.get(region).ok_or(FemError::MissingMaterial {
        element: location.element,
        region,
        region_count: materials.len(),
    })?;
    let eps = strain(mesh, displacement, location)?;
    Ok(match material.constitutive(formulation) {
        Constitutive::Plane(d) => (0..3)
            .map(|i| (0..3).map(|j| d[(i, j)] * eps[j]).sum())
            .collect(),
        Constitutive::Solid(d) => (0..6)
            .map(|i| (0..6).map(|j| d[(i, j)] * eps[j]).sum())
            .collect(),
    })
}

/// Stress at the centroid of every element.
pub fn centroid_stresses<const D: usize>(
    mesh: &Mesh<D>,
    formulation: Formulation,
    materials: &Materials,
    displacement: &[f64],
) -> Result<Vec<Vec<f64>>, FemError> {
    let centre = [1.0 / (D as f64 + 1.0); D];
    (0..mesh.element_count())
        .map(|element| {
            stress(
                mesh,
                formulation,
                materials,
                displacement,
                &Location {
                    element,
                    reference: centre,
                },
            )
        })
        .collect()
}
