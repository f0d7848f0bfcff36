//! Boundary probing: a flat, frictionless, rigid probe of width $w$ pushed
//! into the front face $y = 0$ at $x_p$ (over the whole thickness) by a
//! prescribed indentation $\delta$ along +y.
//!
//! The front-face nodes under the probe have $u_y = \delta$ and are free
//! along x (and z); the force the probe applies is the sum of the
//! reactions $r_y = (f_{int}(u))_y$ at those nodes, and its moment about
//! the probe centre is $\sum (x_n - x_p)\,r_{y,n}$ (both times
//! `Body::copies`: doubled on the upper half of the slab).
//!
//! The linear truth is exactly proportional to $\delta$, so one solve
//! gives every frame. It reuses the day's factorisation (supports held
//! only) through Lagrange multipliers instead of factorising with the
//! probe face held: with $C$ selecting the $m$ held components,
//! $$K u = C^T \lambda,\qquad C u = \delta\,\mathbf 1
//! \;\Rightarrow\; u = G\lambda,\quad G = K^{-1}C^T,\quad
//! (C G)\,\lambda = \delta\,\mathbf 1,$$
//! $m$ back-substitutions and an $m \times m$ Cholesky solve; $\lambda$ are
//! the reactions under the probe. A probe pressed on a slab of its own
//! (`probe_mesh`) has no factorisation to share: that slab is factorised
//! with the face held, and one solve gives $u$. The nonlinear truth holds
//! the face in its Newton solver on a grid of indentations, interpolated
//! between them.
//!
//! A probe with rounded edges (`ProbeTrial::edge_radius`, neo-Hookean
//! truth only) touches the front face in frictionless contact
//! (`contact`). Where the face slides under it, its edges push the face
//! back, so its force has a part along x too, which the force sensor
//! reads: the bundle's `fx`, zero (plus noise) for a flat punch.

use nalgebra::{DMatrix, DVector};

use crate::contact::Punch;
use crate::error::SynthError;
use crate::scenario::ProbeTrial;
use crate::strain::peak_strain;
use crate::world::World;

/// The solved states of one probing trial.
#[derive(Debug, Clone)]
pub(crate) struct ProbeRun {
    /// The trial.
    pub probe: ProbeTrial,
    /// Indentation of each state (m).
    pub indentations: Vec<f64>,
    /// Marker displacements (x, y, z) of each state (m); z is zero in
    /// the plane-strain truth.
    pub markers: Vec<Vec<[f64; 3]>>,
    /// Probe force along +y (N).
    pub force: Vec<f64>,
    /// Probe force along +x (N): zero for a flat frictionless punch, made
    /// by the rounded edges of one in contact.
    pub sideways: Vec<f64>,
    /// Moment about z at the probe centre (N m).
    pub moment: Vec<f64>,
    /// Displacement field at full indentation, on the mesh the probe was
    /// pressed on.
    pub last_displacement: Vec<f64>,
    /// Largest principal strain at full indentation.
    pub peak_strain: f64,
    /// Nodes of the slab of its own the probe was pressed on
    /// (`probe_mesh`), if any.
    pub mesh_nodes: Option<usize>,
}

/// Which factorisation a linear probe is solved with.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Factorisation {
    /// The day's, shared with the other trials on the same mesh, the face
    /// held through Lagrange multipliers.
    Shared,
    /// Its own, with the face held (a mesh made for this probe alone).
    Own,
}

/// Simulates one probing trial; a linear one solved with `factorisation`.
pub(crate) fn press(
    world: &World,
    probe: &ProbeTrial,
    factorisation: Factorisation,
) -> Result<ProbeRun, SynthError> {
    let body = &world.body;
    let tol = 1e-9 * world.scenario.phantom.width;
    let half = probe.width / 2.0 + tol;
    let contact = body.nodes_where(|x| x[1].abs() < tol && (x[0] - probe.x).abs() <= half);
    let held: Vec<usize> = contact.iter().map(|&n| n * body.dim + 1).collect();
    let dofs = body.dof_count();
    let mut run = ProbeRun {
        probe: *probe,
        indentations: vec![0.0],
        markers: vec![vec![[0.0; 3]; world.markers.len()]],
        force: vec![0.0],
        sideways: vec![0.0],
        moment: vec![0.0],
        last_displacement: vec![0.0; dofs],
        peak_strain: 0.0,
        mesh_nodes: None,
    };
    let mut record = |delta: f64, u: Vec<f64>, reactions: &[f64]| {
        let force: f64 = body.copies()
            * contact
                .iter()
                .map(|&n| reactions[n * body.dim + 1])
                .sum::<f64>();
        let moment: f64 = body.copies()
            * contact
                .iter()
                .map(|&n| (body.nodes[n][0] - probe.x) * reactions[n * body.dim + 1])
                .sum::<f64>();
        run.indentations.push(delta);
        run.markers.push(world.marker_displacements(&u));
        run.force.push(force);
        run.sideways.push(0.0);
        run.moment.push(moment);
        run.last_displacement = u;
    };
    let linear = world.scenario.effects.material_nonlinearity.is_none();
    if linear && factorisation == Factorisation::Own {
        let what = format!("the phantom pressed by the probe at x = {} m", probe.x);
        let (u, reactions) = world.press_linear(probe.day, &held, probe.indentation, &what)?;
        record(probe.indentation, u, &reactions);
        run.peak_strain = peak_strain(body, &run.last_displacement);
        return Ok(run);
    }
    if linear {
        let response = world.response(probe.day)?;
        let columns: Vec<Vec<f64>> = held
            .iter()
            .map(|&d| {
                let mut e = vec![0.0; dofs];
                e[d] = 1.0;
                e
            })
            .collect();
        let g = response.solve(body, &columns, &[])?;
        let m = held.len();
        let schur = DMatrix::from_fn(m, m, |i, j| g[j][held[i]]);
        let lambda = schur
            .cholesky()
            .ok_or_else(|| SynthError::Factorisation {
                what: format!("the probe at x = {} m", probe.x),
                reason: "the probe face compliance is not positive definite".into(),
            })?
            .solve(&DVector::from_element(m, probe.indentation));
        let mut u = vec![0.0; dofs];
        for (column, l) in g.iter().zip(lambda.iter()) {
            for (ui, gi) in u.iter_mut().zip(column) {
                *ui += l * gi;
            }
        }
        let reactions = response.internal_forces(body, &u);
        record(probe.indentation, u, &reactions);
        run.peak_strain = peak_strain(body, &run.last_displacement);
        return Ok(run);
    }
    let states = (probe.indentation / world.scenario.resolution.indentation_step)
        .ceil()
        .max(1.0) as usize;
    let during = |delta: f64| {
        move |e: SynthError| {
            e.during(|| {
                format!(
                    "pressed by the probe at x = {} m to {delta:.6} m of its {} m",
                    probe.x, probe.indentation
                )
            })
        }
    };
    let mut u = vec![0.0; dofs];
    if let Some(edge_radius) = probe.edge_radius {
        // Every front-face node may touch the probe: the surface beside it
        // is drawn in towards its sides.
        let front = body.nodes_where(|x| x[1].abs() < tol);
        let solver = world.neo_hookean(probe.day, &[], &front)?;
        let mut contact = solver.contact(Punch {
            centre: probe.x,
            half_width: probe.width / 2.0,
            edge_radius,
            depth: 0.0,
        });
        let mut from = 0.0;
        for k in 1..=states {
            let delta = probe.indentation * k as f64 / states as f64;
            contact.punch.depth = delta;
            u = solver
                .press(body, &u, from, &mut contact)
                .map_err(during(delta))?;
            from = delta;
            let (force, moment) = contact.resultant(&body.nodes, body.dim, &u);
            run.indentations.push(delta);
            run.markers.push(world.marker_displacements(&u));
            run.force.push(body.copies() * force[1]);
            run.sideways.push(body.copies() * force[0]);
            run.moment.push(body.copies() * moment);
            run.last_displacement = u.clone();
        }
        run.peak_strain = peak_strain(body, &run.last_displacement);
        return Ok(run);
    }
    let solver = world.neo_hookean(probe.day, &held, &[])?;
    for k in 1..=states {
        let delta = probe.indentation * k as f64 / states as f64;
        let mut prescribed = vec![0.0; dofs];
        for &d in &held {
            prescribed[d] = delta;
        }
        u = solver
            .solve(body, &vec![0.0; dofs], &u, &prescribed)
            .map_err(during(delta))?;
        let reactions = solver.internal_forces(body, &u);
        record(delta, u.clone(), &reactions);
    }
    run.peak_strain = peak_strain(body, &run.last_displacement);
    Ok(run)
}
