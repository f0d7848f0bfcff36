//! Fits the paper's probing campaign (fine T6 truth, 4 µm noise) and writes
//! the same least-squares problem as CSV files for the scipy peer
//! `bench/peers/identify_least_squares.py`, with this crate's figures.
//!
//! ```text
//! cargo run --release -p needle-identify --example probe_peer_export -- /tmp/identify-peer
//! python3 bench/peers/identify_least_squares.py /tmp/identify-peer
//! ```

#[path = "../tests/support/mod.rs"]
mod support;

use std::fmt::Write as _;
use std::time::Instant;

use needle_identify::{IdentifyOptions, identify_from_data, project_to_boundary};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let dir = std::path::PathBuf::from(
        std::env::args()
            .nth(1)
            .unwrap_or_else(|| "/tmp/identify-peer".into()),
    );
    std::fs::create_dir_all(&dir)?;
    let scenario = support::Scenario::paper();
    let data = scenario.probe_data(4e-6, 1);
    // The peer models the probe as a point force, as the truth does.
    let options = IdentifyOptions {
        per_trial: false,
        ..support::point_force()
    };

    let mut ours = String::from("start_E,start_nu,E,nu,cost,evaluations,jacobians,seconds\n");
    let mut fit = None;
    for (start_e, start_nu) in [(30e3, 0.3), (1e6, 0.0), (1e3, 0.499)] {
        let options = IdentifyOptions {
            start_youngs_modulus: start_e,
            start_poisson_ratio: start_nu,
            ..options.clone()
        };
        let clock = Instant::now();
        let result = identify_from_data(&data, &options)?;
        let seconds = clock.elapsed().as_secs_f64();
        writeln!(
            ours,
            "{start_e},{start_nu},{},{},{},{},{},{seconds}",
            result.youngs_modulus.value,
            result.poisson_ratio.value,
            0.5 * result.chi2,
            result.evaluations,
            result.jacobians
        )?;
        fit = Some(result);
    }
    let fit = fit.expect("three fits ran");
    println!("{fit}");
    std::fs::write(dir.join("ours.csv"), &ours)?;

    // The same model mesh as the fit (T6, two mesh lines per marker spacing).
    let grid = scenario.grid();
    let plan = needle_fem::mesh::RectangleMesh::with_markers(
        scenario.width,
        scenario.depth,
        &grid,
        options.refinement,
    )?;
    let mesh = plan.build(options.element)?;
    let mut nodes = String::from("x,y\n");
    for p in mesh.nodes() {
        writeln!(nodes, "{},{}", p[0], p[1])?;
    }
    std::fs::write(dir.join("nodes.csv"), nodes)?;
    let mut elements = String::from("n0,n1,n2,n3,n4,n5\n");
    for e in 0..mesh.element_count() {
        let n = mesh.element(e);
        writeln!(
            elements,
            "{},{},{},{},{},{}",
            n[0], n[1], n[2], n[3], n[4], n[5]
        )?;
    }
    std::fs::write(dir.join("elements.csv"), elements)?;
    std::fs::write(
        dir.join("setup.csv"),
        format!(
            "width,depth,thickness,sigma,nu_lo,nu_hi,E_lo,E_hi\n{},{},{},{},{},{},{},{}\n",
            scenario.width,
            scenario.depth,
            scenario.thickness,
            4e-6,
            options.poisson_bounds.0,
            options.poisson_bounds.1,
            options.modulus_bounds.0,
            options.modulus_bounds.1
        ),
    )?;

    // Rows after the same exclusion as the fit: markers closer than one
    // marker spacing to the load point are left out.
    let spacing = grid.x[1] - grid.x[0];
    let mut frames = String::from("load_x,load_y,fx,fy\n");
    let mut rows = String::from("frame,node,component,value,weight\n");
    for (k, frame) in data.frames.iter().enumerate() {
        let load = project_to_boundary(&data.setup, frame.tip).map_err(|e| e.to_string())?;
        writeln!(
            frames,
            "{},{},{},{}",
            load[0], load[1], frame.force[0], frame.force[1]
        )?;
        for d in &frame.displacements {
            let rest = data.setup.markers[d.marker];
            if (rest[0] - load[0]).hypot(rest[1] - load[1]) < spacing {
                continue;
            }
            let node = mesh.nearest_node(rest).ok_or("empty mesh")?;
            for c in 0..2 {
                writeln!(rows, "{k},{node},{c},{},{}", d.displacement[c], 1.0 / 4e-6)?;
            }
        }
    }
    std::fs::write(dir.join("frames.csv"), frames)?;
    std::fs::write(dir.join("rows.csv"), rows)?;
    print!("{ours}");
    println!("wrote {}", dir.display());
    Ok(())
}
