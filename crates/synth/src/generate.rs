//! Runs a scenario's campaign in the truth world and writes the bundle
//! (through needle-data, atomically) and the ground truth.

use std::path::{Path, PathBuf};
use std::time::Instant;

use needle_data::{
    BundleBuilder, CompressionPoint, Face, MarkerRest, Noise, Phantom, ToolSample, Trial,
    TrialKind, WriteOptions,
};
use rayon::prelude::*;

use crate::camera::TrueCamera;
use crate::effect::material_nonlinearity::uniaxial_nominal_stress;
use crate::error::SynthError;
use crate::frames::{Staging, render_trial_frames, selected_frames, write_calibration};
use crate::needle::{NeedleRun, insert};
use crate::probe::{ProbeRun, press};
use crate::scenario::Scenario;
use crate::sensor::{Instruments, bracket, sample_times, stated_force_sigma};
use crate::strain::peak_strain;
use crate::truth::{Discretisation, GroundTruth, TrialTruth};
use crate::world::World;

/// What a generation did.
#[derive(Debug, Clone, PartialEq)]
pub struct Summary {
    /// Trials written.
    pub trials: usize,
    /// Rows of all `markers.csv` files.
    pub marker_rows: usize,
    /// Rows of all `tool.csv` files.
    pub tool_rows: usize,
    /// Rendered camera frames of all trials.
    pub frames: usize,
    /// Degrees of freedom of the truth.
    pub dofs: usize,
    /// Linear (or Newton) solves of the needle insertions.
    pub needle_solves: usize,
    /// Wall time of the whole generation (s).
    pub seconds: f64,
    /// The ground truth that was written.
    pub truth: GroundTruth,
}

/// A stage of the generation, for progress display.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stage {
    /// Meshing the phantom.
    Mesh,
    /// Probing trials, `done` of `total`.
    Probes {
        /// Finished.
        done: usize,
        /// All.
        total: usize,
    },
    /// Needle insertions, `done` days of `total` (all days advance
    /// together, so this is reported once, when they are all done).
    Needles {
        /// Finished days.
        done: usize,
        /// All days.
        total: usize,
    },
    /// Writing the bundle and the truth.
    Write,
}

/// Generates the campaign of `scenario`: the bundle at `bundle_out` (which
/// must not exist) and the ground truth at `truth_out` (which must not
/// exist and must lie outside the bundle folder).
pub fn generate(
    scenario: &Scenario,
    bundle_out: &Path,
    truth_out: &Path,
    progress: impl Fn(Stage) + Sync,
) -> Result<Summary, SynthError> {
    let started = Instant::now();
    scenario.validate(&scenario.name)?;
    check_truth_path(bundle_out, truth_out)?;
    if bundle_out.exists() {
        return Err(SynthError::Bundle(
            needle_data::BundleError::AlreadyExists {
                path: bundle_out.to_path_buf(),
            },
        ));
    }
    progress(Stage::Mesh);
    let world = World::new(scenario)?;
    let probes = run_probes(&world, &progress)?;
    let (needles, needle_solves) = run_needles(&world, &progress)?;
    progress(Stage::Write);
    let p = &scenario.phantom;
    let s = &scenario.sensors;
    let mut builder = BundleBuilder::new(
        scenario.name.clone(),
        Phantom {
            width: p.width,
            depth: p.depth,
            thickness: p.thickness,
            fixed: vec![Face::Back],
        },
    );
    let stated = (s.marker_sigma, stated_force_sigma(s));
    builder.noise(Noise {
        marker_sigma: stated.0,
        force_sigma: stated.1,
    });
    builder.markers_rest(
        world
            .markers
            .iter()
            .enumerate()
            .map(|(id, m)| MarkerRest {
                id: id as u32,
                x: m[0],
                y: m[1],
            })
            .collect(),
    );
    let mut compression_modulus = None;
    if let Some(test) = &scenario.compression {
        let modulus = p.youngs_modulus
            * scenario
                .effects
                .material_stiffening
                .map_or(1.0, |m| m.factor(test.day));
        compression_modulus = Some(modulus);
        let mut instruments = Instruments::new(*s, scenario.seed, u64::MAX);
        let area = test.side * test.side;
        let curve = (0..test.samples)
            .map(|k| {
                let strain = test.max_strain * k as f64 / (test.samples - 1) as f64;
                // Stress as the paper plots it: force over the current area
                // of an incompressible sample (area A0 / stretch).
                let stretch = 1.0 - strain;
                let nominal = if scenario.effects.material_nonlinearity.is_some() {
                    uniaxial_nominal_stress(modulus, p.poisson_ratio, stretch)
                } else {
                    modulus * strain
                };
                let force = instruments.force(nominal * area);
                let stress = if scenario.effects.material_nonlinearity.is_some() {
                    force / area * stretch
                } else {
                    force / area
                };
                CompressionPoint { strain, stress }
            })
            .collect();
        builder.compression(curve);
    }
    let mut truths = Vec::new();
    let (mut marker_rows, mut tool_rows, mut frame_count) = (0, 0, 0);
    // Frames and calibration images are rendered here first; the bundle
    // writer copies them.
    let staging = match &scenario.frames {
        Some(_) => Some(Staging::beside(bundle_out)?),
        None => None,
    };
    let camera = TrueCamera::new(scenario);
    let mut camera_truth = None;
    if let (Some(frames), Some(staging)) = (&scenario.frames, &staging) {
        let dir = staging.path().join(needle_data::layout::CALIBRATION);
        camera_truth = Some(write_calibration(scenario, frames, &camera, &dir)?);
        builder.calibration_dir(dir);
    }
    let order = campaign_order(&probes, &needles);
    let mut seen = [0, 0];
    for (stream, &(kind, i)) in order.iter().enumerate() {
        let mut instruments = Instruments::new(*s, scenario.seed, stream as u64);
        let (mut trial, truth) = if kind == TrialKind::Probe {
            probe_trial(&world, &probes[i], i, &mut instruments)
        } else {
            needle_trial(&world, &needles[i], i, &mut instruments)
        };
        let k = usize::from(kind == TrialKind::Needle);
        seen[k] += 1;
        if let (Some(frames), Some(staging)) = (&scenario.frames, &staging) {
            let selection = [frames.probes, frames.needles][k];
            if seen[k] <= selection.count {
                let (grid, table, velocity, end) = if kind == TrialKind::Probe {
                    let r = &probes[i];
                    (
                        &r.indentations,
                        &r.markers,
                        r.probe.velocity,
                        r.probe.indentation,
                    )
                } else {
                    let r = &needles[i];
                    (
                        &r.depths,
                        &r.markers,
                        r.plan.velocity,
                        scenario.needles.depth,
                    )
                };
                let times = sample_times(s.camera_rate, end / velocity);
                let numbers = selected_frames(times.len(), selection.every);
                let dir = staging.path().join(&trial.trial.id);
                render_trial_frames(
                    &camera,
                    &frames.render_options(),
                    scenario.seed,
                    stream as u64,
                    &numbers,
                    |number| {
                        let (j, w) = bracket(grid, (velocity * times[number as usize]).min(end));
                        positions_at(&world, table, j, w).collect()
                    },
                    &dir,
                    &mut trial,
                )?;
                frame_count += numbers.len();
            }
        }
        marker_rows += trial.markers.as_ref().map_or(0, |m| m.row_count());
        tool_rows += trial.tool.len();
        let slot = builder.trial(trial.trial.clone());
        *slot = trial;
        truths.push(truth);
    }
    let truth = GroundTruth {
        bundle: scenario.name.clone(),
        effects: scenario.effects.present(),
        scenario: scenario.clone(),
        discretisation: Discretisation {
            dimension: world.body.dim,
            nodes: world.body.nodes.len(),
            elements: world.body.element_count(),
            element_size: world.body.element_size,
        },
        stated_noise: stated,
        trials: truths,
        compression_modulus,
        camera: camera_truth,
    };
    builder.write(bundle_out, WriteOptions::default())?;
    let text = ron::ser::to_string_pretty(&truth, ron::ser::PrettyConfig::default())
        .expect("the ground truth always serialises");
    write_new(truth_out, &text)?;
    Ok(Summary {
        trials: order.len(),
        marker_rows,
        tool_rows,
        frames: frame_count,
        dofs: world.body.dof_count(),
        needle_solves,
        seconds: started.elapsed().as_secs_f64(),
        truth,
    })
}

/// The noise-free response of one trial: its solved states.
#[derive(Debug, Clone, PartialEq)]
pub struct TrialResponse {
    /// Trial id, as in the bundle.
    pub id: String,
    /// Probe or needle.
    pub kind: TrialKind,
    /// State coordinate: probe indentation or needle tip depth (m).
    pub states: Vec<f64>,
    /// Marker displacements (x, y) at each state (m), markers row-major.
    pub markers: Vec<Vec<[f64; 2]>>,
    /// True force at the tool base at each state (N).
    pub force: Vec<f64>,
    /// Largest principal strain at the last state.
    pub peak_strain: f64,
}

/// The noise-free responses of every trial of `scenario`, in campaign
/// order (no file is written): what the bundle's measurements sample.
pub fn respond(scenario: &Scenario) -> Result<Vec<TrialResponse>, SynthError> {
    scenario.validate(&scenario.name)?;
    let world = World::new(scenario)?;
    let probes = run_probes(&world, &|_| {})?;
    let (needles, _) = run_needles(&world, &|_| {})?;
    Ok(campaign_order(&probes, &needles)
        .into_iter()
        .map(|(kind, i)| match kind {
            TrialKind::Probe => {
                let r = &probes[i];
                TrialResponse {
                    id: probe_id(i),
                    kind,
                    states: r.indentations.clone(),
                    markers: in_plane(&r.markers),
                    force: r.force.clone(),
                    peak_strain: peak_strain(&world.body, &r.last_displacement),
                }
            }
            _ => {
                let r = &needles[i];
                TrialResponse {
                    id: needle_id(i, &r.plan),
                    kind,
                    states: r.depths.clone(),
                    markers: in_plane(&r.markers),
                    force: r.force.clone(),
                    peak_strain: peak_strain(&world.body, &r.last_displacement),
                }
            }
        })
        .collect())
}

/// The in-plane (x, y) part of marker displacement tables.
fn in_plane(table: &[Vec<[f64; 3]>]) -> Vec<Vec<[f64; 2]>> {
    table
        .iter()
        .map(|state| state.iter().map(|d| [d[0], d[1]]).collect())
        .collect()
}

/// Campaign order: by day, probes before needles on the same day; each
/// entry is the kind and the index in its list.
fn campaign_order(probes: &[ProbeRun], needles: &[NeedleRun]) -> Vec<(TrialKind, usize)> {
    let mut order: Vec<(f64, usize, usize)> = probes
        .iter()
        .enumerate()
        .map(|(i, r)| (r.probe.day, 0, i))
        .collect();
    order.extend(needles.iter().enumerate().map(|(i, r)| (r.plan.day, 1, i)));
    order.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2)));
    order
        .into_iter()
        .map(|(_, k, i)| {
            (
                if k == 0 {
                    TrialKind::Probe
                } else {
                    TrialKind::Needle
                },
                i,
            )
        })
        .collect()
}

fn probe_id(index: usize) -> String {
    format!("probe-{:02}", index + 1)
}

fn needle_id(index: usize, plan: &crate::scenario::NeedlePlan) -> String {
    format!(
        "needle-{:02}-v{}",
        index + 1,
        (plan.velocity * 1e3).round() as i64
    )
}

fn check_truth_path(bundle_out: &Path, truth_out: &Path) -> Result<(), SynthError> {
    let absolute = |p: &Path| -> PathBuf {
        if p.is_absolute() {
            p.to_path_buf()
        } else {
            std::env::current_dir()
                .map(|d| d.join(p))
                .unwrap_or_else(|_| p.to_path_buf())
        }
    };
    if absolute(truth_out).starts_with(absolute(bundle_out)) {
        return Err(SynthError::TruthPath {
            path: truth_out.to_path_buf(),
            reason: "lies inside the bundle folder".into(),
        });
    }
    if truth_out.exists() {
        return Err(SynthError::TruthPath {
            path: truth_out.to_path_buf(),
            reason: "already exists; refusing to overwrite".into(),
        });
    }
    Ok(())
}

fn write_new(path: &Path, text: &str) -> Result<(), SynthError> {
    use std::io::Write;
    let io = |source| SynthError::Io {
        path: path.to_path_buf(),
        source,
    };
    let mut file = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(path)
        .map_err(io)?;
    file.write_all(text.as_bytes()).map_err(io)
}

fn run_probes(
    world: &World,
    progress: &(impl Fn(Stage) + Sync),
) -> Result<Vec<ProbeRun>, SynthError> {
    let total = world.scenario.probes.len();
    let done = std::sync::atomic::AtomicUsize::new(0);
    world
        .scenario
        .probes
        .par_iter()
        .map(|probe| {
            let run = press(world, probe);
            let d = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
            progress(Stage::Probes { done: d, total });
            run
        })
        .collect()
}

fn run_needles(
    world: &World,
    progress: &(impl Fn(Stage) + Sync),
) -> Result<(Vec<NeedleRun>, usize), SynthError> {
    let scenario = world.scenario;
    let mut plans = scenario.needles.plan();
    plans.sort_by(|a, b| a.day.total_cmp(&b.day));
    let mut days: Vec<f64> = plans.iter().map(|p| p.day).collect();
    days.dedup();
    let responses = days
        .iter()
        .map(|&day| world.response(day))
        .collect::<Result<Vec<_>, _>>()?;
    // Every trial advances together, so that days sharing a factorisation
    // share each back-substitution.
    let trials: Vec<_> = plans
        .iter()
        .map(|plan| {
            let d = days.partition_point(|&day| day < plan.day);
            (*plan, &responses[d])
        })
        .collect();
    let runs = insert(
        world,
        &trials,
        scenario.needles.depth,
        scenario.resolution.depth_step,
    )?;
    progress(Stage::Needles {
        done: days.len(),
        total: days.len(),
    });
    let solves = runs.iter().map(|r| r.solves).sum();
    Ok((runs, solves))
}

/// Interpolated marker positions (rest + displacement) between states:
/// x, y on the top face and the lift z out of it.
fn positions_at<'a>(
    world: &'a World,
    table: &'a [Vec<[f64; 3]>],
    i: usize,
    w: f64,
) -> impl Iterator<Item = [f64; 3]> + 'a {
    let (a, b) = (&table[i], &table[(i + 1).min(table.len() - 1)]);
    world
        .markers
        .iter()
        .zip(a.iter().zip(b))
        .map(move |(m, (a, b))| {
            [
                m[0] + (1.0 - w) * a[0] + w * b[0],
                m[1] + (1.0 - w) * a[1] + w * b[1],
                (1.0 - w) * a[2] + w * b[2],
            ]
        })
}

fn lerp(table: &[f64], i: usize, w: f64) -> f64 {
    (1.0 - w) * table[i] + w * table[(i + 1).min(table.len() - 1)]
}

/// Writes the markers of one trial: camera frames at `times`, each at the
/// state coordinate `coordinate(t)` on `grid`.
fn track(
    world: &World,
    grid: &[f64],
    table: &[Vec<[f64; 3]>],
    times: &[f64],
    coordinate: impl Fn(f64) -> f64,
    instruments: &mut Instruments,
    trial: &mut needle_data::TrialData,
) {
    let lens = world.scenario.effects.lens_distortion;
    let markers = trial.markers_mut();
    for (frame, &t) in times.iter().enumerate() {
        let (i, w) = bracket(grid, coordinate(t));
        let rows: Vec<(u32, [f64; 2])> = positions_at(world, table, i, w)
            .enumerate()
            .map(|(id, p)| {
                let p = [p[0], p[1]];
                let seen = lens.map_or(p, |l| l.distort(p));
                (id as u32, instruments.marker(seen))
            })
            .collect();
        markers
            .push_frame(frame as u64, t, rows)
            .expect("rows without sigma throughout");
    }
}

fn probe_trial(
    world: &World,
    run: &ProbeRun,
    index: usize,
    instruments: &mut Instruments,
) -> (needle_data::TrialData, TrialTruth) {
    let s = &world.scenario.sensors;
    let probe = &run.probe;
    let id = probe_id(index);
    let mut trial = needle_data::TrialData::new(Trial {
        id: id.clone(),
        kind: TrialKind::Probe,
        velocity: probe.velocity,
        day: probe.day,
    });
    let duration = probe.indentation / probe.velocity;
    let indentation = |t: f64| (probe.velocity * t).min(probe.indentation);
    for t in sample_times(s.force_rate, duration) {
        let (i, w) = bracket(&run.indentations, indentation(t));
        trial.tool.push(ToolSample {
            t,
            tip_x: probe.x,
            tip_y: indentation(t),
            theta: 0.0,
            fx: instruments.force(0.0),
            fy: instruments.force(lerp(&run.force, i, w)),
            mz: lerp(&run.moment, i, w),
        });
    }
    let frames = sample_times(s.camera_rate, duration);
    track(
        world,
        &run.indentations,
        &run.markers,
        &frames,
        indentation,
        instruments,
        &mut trial,
    );
    let truth = TrialTruth {
        id,
        day: probe.day,
        youngs_moduli: world.moduli(probe.day),
        x: probe.x,
        shaft_density: None,
        final_entry: None,
        final_tip_material: None,
        final_force: *run.force.last().expect("at least the rest state"),
        peak_strain: peak_strain(&world.body, &run.last_displacement),
    };
    (trial, truth)
}

fn needle_trial(
    world: &World,
    run: &NeedleRun,
    index: usize,
    instruments: &mut Instruments,
) -> (needle_data::TrialData, TrialTruth) {
    let s = &world.scenario.sensors;
    let plan = &run.plan;
    let id = needle_id(index, plan);
    let mut trial = needle_data::TrialData::new(Trial {
        id: id.clone(),
        kind: TrialKind::Needle,
        velocity: plan.velocity,
        day: plan.day,
    });
    let depth = world.scenario.needles.depth;
    let duration = depth / plan.velocity;
    let tip = |t: f64| (plan.velocity * t).min(depth);
    for t in sample_times(s.force_rate, duration) {
        let (i, w) = bracket(&run.depths, tip(t));
        trial.tool.push(ToolSample {
            t,
            tip_x: plan.line,
            tip_y: tip(t),
            theta: 0.0,
            fx: instruments.force(0.0),
            fy: instruments.force(lerp(&run.force, i, w)),
            mz: 0.0,
        });
    }
    let frames = sample_times(s.camera_rate, duration);
    track(
        world,
        &run.depths,
        &run.markers,
        &frames,
        tip,
        instruments,
        &mut trial,
    );
    let truth = TrialTruth {
        id,
        day: plan.day,
        youngs_moduli: world.moduli(plan.day),
        x: plan.line,
        shaft_density: Some(run.load.density),
        final_entry: run.entry.last().copied(),
        final_tip_material: Some(run.tip_material),
        final_force: *run.force.last().expect("at least the rest state"),
        peak_strain: peak_strain(&world.body, &run.last_displacement),
    };
    (trial, truth)
}
