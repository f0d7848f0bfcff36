//! Boundary probing: a flat, frictionless, rigid probe of width $w$ pushed
//! into the front face $y = 0$ at $x_p$ (over the whole thickness) by a
//! prescribed indentation $\delta$ along +y.
//!
//! The front-face nodes under the probe have $u_y = \delta$ and are free
//! along x (and z); the force the probe applies is the sum of the
//! reactions $r_y = (f_{int}(u))_y$ at those nodes, and its moment about
//! the probe centre is $\sum (x_n - x_p)\,r_{y,n}$. The linear truth is
//! exactly proportional to $\delta$, so one solve at unit indentation
//! gives every frame; the nonlinear truth is solved by Newton iteration on
//! a grid of indentations and interpolated between them.

use crate::error::SynthError;
use crate::scenario::ProbeTrial;
use crate::world::{Response, World};

/// The solved states of one probing trial.
#[derive(Debug, Clone)]
pub(crate) struct ProbeRun {
    /// The trial.
    pub probe: ProbeTrial,
    /// Indentation of each state (m).
    pub indentations: Vec<f64>,
    /// Marker displacements (x, y) of each state (m).
    pub markers: Vec<Vec<[f64; 2]>>,
    /// Probe force along +y (N).
    pub force: Vec<f64>,
    /// Moment about z at the probe centre (N m).
    pub moment: Vec<f64>,
    /// Displacement field at full indentation.
    pub last_displacement: Vec<f64>,
}

/// Simulates one probing trial.
pub(crate) fn press(world: &World, probe: &ProbeTrial) -> Result<ProbeRun, SynthError> {
    let body = &world.body;
    let tol = 1e-9 * world.scenario.phantom.width;
    let half = probe.width / 2.0 + tol;
    let contact = body.nodes_where(|x| x[1].abs() < tol && (x[0] - probe.x).abs() <= half);
    let held: Vec<usize> = contact.iter().map(|&n| n * body.dim + 1).collect();
    let response = world.response(probe.day, &held)?;
    let linear = matches!(response, Response::Linear { .. });
    let states = if linear {
        1
    } else {
        (probe.indentation / world.scenario.resolution.indentation_step)
            .ceil()
            .max(1.0) as usize
    };
    let dofs = body.dof_count();
    let mut run = ProbeRun {
        probe: *probe,
        indentations: vec![0.0],
        markers: vec![vec![[0.0; 2]; world.markers.len()]],
        force: vec![0.0],
        moment: vec![0.0],
        last_displacement: vec![0.0; dofs],
    };
    let mut u = vec![0.0; dofs];
    for k in 1..=states {
        let delta = probe.indentation * k as f64 / states as f64;
        let mut prescribed = vec![0.0; dofs];
        for &d in &held {
            prescribed[d] = delta;
        }
        u = response
            .solve(
                body,
                &[vec![0.0; dofs]],
                std::slice::from_ref(&u),
                &prescribed,
            )?
            .pop()
            .expect("one load, one solution");
        let reactions = response.internal_forces(body, &u);
        let force: f64 = contact.iter().map(|&n| reactions[n * body.dim + 1]).sum();
        let moment: f64 = contact
            .iter()
            .map(|&n| (body.nodes[n][0] - probe.x) * reactions[n * body.dim + 1])
            .sum();
        run.indentations.push(delta);
        run.markers.push(world.marker_displacements(&u));
        run.force.push(force);
        run.moment.push(moment);
    }
    run.last_displacement = u;
    Ok(run)
}
