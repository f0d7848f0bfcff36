//! Dirichlet (essential) boundary conditions: prescribed values of
//! individual degrees of freedom.
//!
//! Constrained dofs are eliminated: with $u = [u_f; u_c]$ the solver
//! factorises $K_{ff}$ and solves $K_{ff} u_f = f_f - K_{fc} u_c$. The set of
//! constrained dofs fixes the factorisation's structure; the prescribed
//! values may change between solves without refactorising.

use std::collections::BTreeMap;

use crate::error::{FemError, finite};
use crate::mesh::{Face, Mesh};

/// Prescribed displacements, by global (interleaved) dof index.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Dirichlet {
    values: BTreeMap<usize, f64>,
}

impl Dirichlet {
    /// No constraint.
    pub fn new() -> Self {
        Self::default()
    }

    /// Every node on `face` fixed in every direction (e.g. the phantom's
    /// back face).
    pub fn fixed_face<const D: usize>(mesh: &Mesh<D>, face: Face) -> Self {
        let mut d = Self::new();
        for n in mesh.nodes_on_face(face) {
            for i in 0..D {
                d.values.insert(n * D + i, 0.0);
            }
        }
        d
    }

    /// Prescribes dof `dof` to `value` (m); a later call overrides.
    pub fn set(&mut self, dof: usize, value: f64) -> Result<&mut Self, FemError> {
        self.values
            .insert(dof, finite("prescribed displacement", value)?);
        Ok(self)
    }

    /// Prescribes component `component` of the displacement of each node.
    pub fn set_nodes<const D: usize>(
        &mut self,
        mesh: &Mesh<D>,
        nodes: &[usize],
        component: usize,
        value: f64,
    ) -> Result<&mut Self, FemError> {
        if component >= D {
            return Err(FemError::DofOutOfRange {
                context: "prescribed component",
                dof: component,
                dof_count: D,
            });
        }
        for &n in nodes {
            if n >= mesh.node_count() {
                return Err(FemError::NodeOutOfRange {
                    context: "prescribed node",
                    node: n,
                    node_count: mesh.node_count(),
                });
            }
            self.set(n * D + component, value)?;
        }
        Ok(self)
    }

    /// Fixes every component of each node to zero.
    pub fn fix_nodes<const D: usize>(
        &mut self,
        mesh: &Mesh<D>,
        nodes: &[usize],
    ) -> Result<&mut Self, FemError> {
        for i in 0..D {
            self.set_nodes(mesh, nodes, i, 0.0)?;
        }
        Ok(self)
    }

    /// Constrained dofs, ascending, with their values.
    pub fn iter(&self) -> impl Iterator<Item = (usize, f64)> + '_ {
        self.values.iter().map(|(&d, &v)| (d, v))
    }

    /// Number of constrained dofs.
    pub fn len(&self) -> usize {
        self.values.len()
    }

    /// True if nothing is constrained.
    pub fn is_empty(&self) -> bool {
        self.values.is_empty()
    }

    /// Whether `dof` is constrained.
    pub fn contains(&self, dof: usize) -> bool {
        self.values.contains_key(&dof)
    }

    /// The prescribed value of `dof`, if constrained.
    pub fn value(&self, dof: usize) -> Option<f64> {
        self.values.get(&dof).copied()
    }
}
