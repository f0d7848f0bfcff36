//! Consistent nodal loads $f_a = \int N_a\, q$: point loads, line loads
//! along an arbitrary segment (the needle shaft), and boundary tractions.
//!
//! Load vectors are full, interleaved dof vectors of length
//! [`Mesh::dof_count`]. In 2-D, point and line loads are totals over the
//! thickness (N and N/m); tractions are stresses (Pa) multiplied by the
//! formulation's thickness.
//!
//! **Line loads.** The needle runs through element interiors, not along
//! edges. The segment $x(s) = a + s\,\hat t$, $0 \le s \le L$, is cut at every
//! element boundary it crosses (where a barycentric coordinate of a
//! candidate element changes sign) and at the breakpoints of the density
//! profile; each piece lies in one element, where
//! $f_a \mathrel{+}= \int N_a(x(s))\,q(s)\,ds$ is evaluated by 6-point Gauss
//! quadrature (exact for a polynomial density of degree 9 on quadratic
//! elements). A piece on a shared edge or face is given to one element only;
//! since the mesh is conforming, either neighbour gives the same nodal loads.

use std::sync::OnceLock;

use crate::element::facet::simplex_points;
use crate::element::quadrature::gauss_legendre_unit;
use crate::error::{FemError, finite};
use crate::locate::{Locator, weights_at};
use crate::material::Formulation;
use crate::mesh::{BoundaryFacet, Mesh};

/// A force density along a segment (N/m) as a function of arclength $s$
/// from its start.
pub enum LineDensity<'f, const D: usize> {
    /// Any function of $s \in [0, L]$, assumed smooth between `breakpoints`
    /// (arclengths where it may jump or kink, e.g. the tip peak).
    Function {
        /// $q(s)$.
        density: &'f (dyn Fn(f64) -> [f64; D] + Sync),
        /// Arclengths where the quadrature must split.
        breakpoints: Vec<f64>,
    },
    /// Samples $(s_k, q_k)$ with $s_k$ increasing, interpolated linearly and
    /// zero outside $[s_0, s_{last}]$.
    Sampled {
        /// Arclengths $s_k$.
        arclength: Vec<f64>,
        /// Densities $q_k$.
        density: Vec<[f64; D]>,
    },
}

impl<const D: usize> LineDensity<'_, D> {
    fn validate(&self) -> Result<(), FemError> {
        if let LineDensity::Sampled { arclength, density } = self {
            if arclength.len() != density.len() {
                return Err(FemError::DimensionMismatch {
                    context: "sampled line density (one density per arclength)",
                    expected: arclength.len(),
                    actual: density.len(),
                });
            }
            for w in arclength.windows(2) {
                if w[1].partial_cmp(&w[0]) != Some(std::cmp::Ordering::Greater) {
                    return Err(FemError::InvalidValue {
                        field: "line density arclength",
                        value: w[1],
                        reason: "must be strictly increasing",
                    });
                }
            }
            for &s in arclength {
                finite("line density arclength", s)?;
            }
            for q in density {
                for &v in q {
                    finite("line density value", v)?;
                }
            }
        }
        Ok(())
    }

    fn breakpoints(&self) -> &[f64] {
        match self {
            LineDensity::Function { breakpoints, .. } => breakpoints,
            LineDensity::Sampled { arclength, .. } => arclength,
        }
    }

    /// $q(s)$.
    pub fn at(&self, s: f64) -> [f64; D] {
        match self {
            LineDensity::Function { density, .. } => density(s),
            LineDensity::Sampled { arclength, density } => {
                let n = arclength.len();
                if n == 0 || s < arclength[0] || s > arclength[n - 1] {
                    return [0.0; D];
                }
                if n == 1 {
                    return density[0];
                }
                // First sample strictly beyond s, kept inside 1..n-1.
                let k = arclength.partition_point(|&a| a <= s).clamp(1, n - 1);
                let (s0, s1) = (arclength[k - 1], arclength[k]);
                let t = (s - s0) / (s1 - s0);
                let mut q = [0.0; D];
                for i in 0..D {
                    q[i] = (1.0 - t) * density[k - 1][i] + t * density[k][i];
                }
                q
            }
        }
    }
}

/// Adds a point force `force` (N) at node `node` to `loads`.
pub fn add_nodal_force<const D: usize>(
    loads: &mut [f64],
    node: usize,
    force: [f64; D],
) -> Result<(), FemError> {
    if (node + 1) * D > loads.len() {
        return Err(FemError::NodeOutOfRange {
            context: "nodal force",
            node,
            node_count: loads.len() / D,
        });
    }
    for i in 0..D {
        loads[node * D + i] += finite("nodal force", force[i])?;
    }
    Ok(())
}

/// Adds a point force at any point of the mesh, distributed consistently
/// ($f_a = N_a(x)\,F$).
pub fn add_point_force<const D: usize>(
    locator: &Locator<'_, D>,
    loads: &mut [f64],
    point: [f64; D],
    force: [f64; D],
) -> Result<(), FemError> {
    check_length(locator.mesh(), loads)?;
    for &f in &force {
        finite("point force", f)?;
    }
    let weights = locator
        .weights(point)
        .ok_or_else(|| FemError::PointOutsideMesh {
            index: 0,
            coordinates: point.to_vec(),
        })?;
    for (n, w) in weights {
        for i in 0..D {
            loads[n * D + i] += w * force[i];
        }
    }
    Ok(())
}

/// Adds the consistent nodal loads of a line load with density `density`
/// (N/m) along the segment from `start` to `end`; the segment must lie in
/// the mesh. Returns the total force applied, $\int_0^L q\,ds$, computed by
/// the same quadrature (useful to check equilibrium).
pub fn add_line_load<const D: usize>(
    locator: &Locator<'_, D>,
    loads: &mut [f64],
    start: [f64; D],
    end: [f64; D],
    density: &LineDensity<'_, D>,
) -> Result<[f64; D], FemError> {
    let mesh = locator.mesh();
    check_length(mesh, loads)?;
    density.validate()?;
    for i in 0..D {
        finite("line load start", start[i])?;
        finite("line load end", end[i])?;
    }
    let length = (0..D)
        .map(|i| (end[i] - start[i]).powi(2))
        .sum::<f64>()
        .sqrt();
    let mut total = [0.0; D];
    if length == 0.0 {
        return Ok(total);
    }
    let point_at = |t: f64| -> [f64; D] {
        let mut p = [0.0; D];
        for i in 0..D {
            p[i] = start[i] + t * (end[i] - start[i]);
        }
        p
    };
    let mut lo = [0.0; D];
    let mut hi = [0.0; D];
    for i in 0..D {
        lo[i] = start[i].min(end[i]);
        hi[i] = start[i].max(end[i]);
    }
    let candidates = locator.candidates(lo, hi);
    // Parameters t in [0, 1] where the segment enters or leaves a candidate.
    let mut breaks = vec![0.0, 1.0];
    for &e in &candidates {
        let l0 = locator.barycentric(e, start);
        let l1 = locator.barycentric(e, end);
        for k in 0..=D {
            let slope = l1[k] - l0[k];
            if slope.abs() > 1e-14 {
                let t = -l0[k] / slope;
                if t > 0.0 && t < 1.0 {
                    breaks.push(t);
                }
            }
        }
    }
    breaks.extend(
        density
            .breakpoints()
            .iter()
            .map(|s| s / length)
            .filter(|t| *t > 0.0 && *t < 1.0),
    );
    breaks.sort_by(f64::total_cmp);
    breaks.dedup_by(|a, b| (*a - *b).abs() < 1e-12);
    // The rule is the same for every call; line loads are added thousands
    // of times per fit, and its Newton iterations showed in profiles.
    static GAUSS: OnceLock<Vec<(f64, f64)>> = OnceLock::new();
    let gauss = GAUSS.get_or_init(|| gauss_legendre_unit(6));
    for w in breaks.windows(2) {
        let (t0, t1) = (w[0], w[1]);
        let middle = point_at(0.5 * (t0 + t1));
        let location = locator
            .locate(middle)
            .ok_or_else(|| FemError::PointOutsideMesh {
                index: 0,
                coordinates: middle.to_vec(),
            })?;
        for &(g, gw) in gauss {
            let t = t0 + g * (t1 - t0);
            let p = point_at(t);
            // Reference coordinates inside the owning element (affine map).
            let l = locator.barycentric(location.element, p);
            let mut reference = [0.0; D];
            reference.copy_from_slice(&l[1..=D]);
            let weights = weights_at(
                mesh,
                &crate::locate::Location {
                    element: location.element,
                    reference,
                },
            );
            let q = density.at(t * length);
            let ds = gw * (t1 - t0) * length;
            for i in 0..D {
                let qi = finite("line density value", q[i])?;
                total[i] += qi * ds;
                for &(n, nw) in &weights {
                    loads[n * D + i] += nw * qi * ds;
                }
            }
        }
    }
    Ok(total)
}

/// Adds boundary tractions $f_a = h \int_{\Gamma} N_a\, t(x)\, dA$ over
/// `facets` (Pa; $h$ is the thickness in 2-D, 1 in 3-D). Returns the total
/// force applied.
pub fn add_traction<const D: usize>(
    mesh: &Mesh<D>,
    formulation: Formulation,
    loads: &mut [f64],
    facets: &[BoundaryFacet],
    traction: impl Fn([f64; D]) -> [f64; D],
) -> Result<[f64; D], FemError> {
    check_length(mesh, loads)?;
    let scale = formulation.thickness();
    let mut total = [0.0; D];
    for facet in facets {
        if let Some(&node) = facet.nodes.iter().find(|&&n| n >= mesh.node_count()) {
            return Err(FemError::NodeOutOfRange {
                context: "traction facet",
                node,
                node_count: mesh.node_count(),
            });
        }
        let coordinates: Vec<[f64; 3]> = facet.nodes.iter().map(|&n| pad(mesh.node(n))).collect();
        let points = simplex_points(&coordinates, D - 1, 2 * mesh.kind().degree() + 2);
        for ((n, position), w) in points
            .shape
            .iter()
            .zip(&points.position)
            .zip(&points.weight)
        {
            let mut x = [0.0; D];
            x.copy_from_slice(&position[..D]);
            let t = traction(x);
            for i in 0..D {
                let ti = finite("traction", t[i])?;
                total[i] += scale * w * ti;
                for (a, &node) in facet.nodes.iter().enumerate() {
                    loads[node * D + i] += scale * w * n[a] * ti;
                }
            }
        }
    }
    Ok(total)
}

fn check_length<const D: usize>(mesh: &Mesh<D>, loads: &[f64]) -> Result<(), FemError> {
    if loads.len() != mesh.dof_count() {
        return Err(FemError::DimensionMismatch {
            context: "load vector",
            expected: mesh.dof_count(),
            actual: loads.len(),
        });
    }
    Ok(())
}

/// Pads a point to 3 coordinates.
pub(crate) fn pad<const D: usize>(p: [f64; D]) -> [f64; 3] {
    let mut q = [0.0; 3];
    q[..D].copy_from_slice(&p);
    q
}

/// Adds body-force loads $f_a = h \int_\Omega N_a\, b(x)\, d\Omega$ (N/m³;
/// $h$ the thickness in 2-D). Returns the total force applied.
pub fn add_body_force<const D: usize>(
    mesh: &Mesh<D>,
    formulation: Formulation,
    loads: &mut [f64],
    body_force: impl Fn([f64; D]) -> [f64; D],
) -> Result<[f64; D], FemError> {
    check_length(mesh, loads)?;
    let scale = formulation.thickness();
    let mut total = [0.0; D];
    for e in 0..mesh.element_count() {
        let nodes = mesh.element(e);
        let coordinates: Vec<[f64; 3]> = nodes.iter().map(|&n| pad(mesh.node(n))).collect();
        let points = simplex_points(&coordinates, D, 2 * mesh.kind().degree() + 2);
        for ((n, position), w) in points
            .shape
            .iter()
            .zip(&points.position)
            .zip(&points.weight)
        {
            let mut x = [0.0; D];
            x.copy_from_slice(&position[..D]);
            let b = body_force(x);
            for i in 0..D {
                let bi = finite("body force", b[i])?;
                total[i] += scale * w * bi;
                for (a, &node) in nodes.iter().enumerate() {
                    loads[node * D + i] += scale * w * n[a] * bi;
                }
            }
        }
    }
    Ok(total)
}
