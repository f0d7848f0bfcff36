//! Recording a trial: the measurements the instruments take of its solved
//! states (force readings, marker tracks with their noise) and, when the
//! scenario asks for them, its camera frames, with its ground truth.
//!
//! Every trial draws its noise from its own stream (its place in the
//! campaign), so trials can be recorded in any order and in parallel with
//! the same result.

use needle_data::{ToolSample, Trial, TrialKind};

use crate::camera::TrueCamera;
use crate::error::SynthError;
use crate::frames::{Staging, render_trial_frames, selected_frames};
use crate::generate::{needle_id, probe_id};
use crate::interpolate::{Stencil, stencil};
use crate::needle::NeedleRun;
use crate::probe::ProbeRun;
use crate::sensor::{Instruments, sample_times};
use crate::strain::peak_strain;
use crate::truth::TrialTruth;
use crate::world::World;

/// What a trial is recorded from: its solved run and its index in its
/// list.
pub(crate) enum Source<'r> {
    /// A probing trial.
    Probe(&'r ProbeRun, usize),
    /// A needle insertion.
    Needle(&'r NeedleRun, usize),
}

/// A recorded trial.
pub(crate) struct Recorded {
    /// Its place in the campaign (and noise stream).
    pub stream: usize,
    /// Its data for the bundle.
    pub trial: needle_data::TrialData,
    /// Its ground truth.
    pub truth: TrialTruth,
    /// Camera frames rendered.
    pub frames: usize,
}

/// What recording needs besides the trial.
pub(crate) struct Recorder<'a> {
    /// The truth world.
    pub world: &'a World<'a>,
    /// The true camera.
    pub camera: &'a TrueCamera,
    /// Where frames are rendered, when the scenario has frames.
    pub staging: Option<&'a Staging>,
}

impl Recorder<'_> {
    /// Records the trial at place `stream` of the campaign, the `rank`-th
    /// of its kind (the first ones of each kind get frames).
    pub fn record(
        &self,
        stream: usize,
        rank: usize,
        source: Source,
    ) -> Result<Recorded, SynthError> {
        let world = self.world;
        let scenario = world.scenario;
        let s = &scenario.sensors;
        let mut instruments = Instruments::new(*s, scenario.seed, stream as u64);
        let (mut trial, truth) = match source {
            Source::Probe(run, i) => probe_trial(world, run, i, &mut instruments),
            Source::Needle(run, i) => needle_trial(world, run, i, &mut instruments),
        };
        let mut frame_count = 0;
        if let (Some(frames), Some(staging)) = (&scenario.frames, self.staging) {
            let (selection, grid, table, velocity, end) = match source {
                Source::Probe(r, _) => (
                    frames.probes,
                    &r.indentations,
                    &r.markers,
                    r.probe.velocity,
                    r.probe.indentation,
                ),
                Source::Needle(r, _) => (
                    frames.needles,
                    &r.depths,
                    &r.markers,
                    r.plan.velocity,
                    scenario.needles.depth,
                ),
            };
            if rank < selection.count {
                let times = sample_times(s.camera_rate, end / velocity);
                let numbers = selected_frames(times.len(), selection.every);
                let dir = staging.path().join(&trial.trial.id);
                render_trial_frames(
                    self.camera,
                    &frames.render_options(),
                    scenario.seed,
                    stream as u64,
                    &numbers,
                    |number| {
                        let at = stencil(grid, (velocity * times[number as usize]).min(end));
                        positions_at(world, table, at).collect()
                    },
                    &dir,
                    &mut trial,
                )?;
                frame_count = numbers.len();
            }
        }
        Ok(Recorded {
            stream,
            trial,
            truth,
            frames: frame_count,
        })
    }
}

/// Interpolated marker positions (rest + displacement) between states
/// (`at` on the trial's state grid): x, y on the top face and the lift z
/// out of it.
pub(crate) fn positions_at<'a>(
    world: &'a World,
    table: &'a [Vec<[f64; 3]>],
    at: Stencil,
) -> impl Iterator<Item = [f64; 3]> + 'a {
    world.markers.iter().enumerate().map(move |(m, rest)| {
        let mut p = [rest[0], rest[1], 0.0];
        for (j, w) in at.terms() {
            for (c, u) in p.iter_mut().zip(table[j][m]) {
                *c += w * u;
            }
        }
        p
    })
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
        let rows: Vec<(u32, [f64; 2])> = positions_at(world, table, stencil(grid, coordinate(t)))
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
        let at = stencil(&run.indentations, indentation(t));
        trial.tool.push(ToolSample {
            t,
            tip_x: probe.x,
            tip_y: indentation(t),
            theta: 0.0,
            fx: instruments.force(at.apply(&run.sideways)),
            fy: instruments.force(at.apply(&run.force)),
            mz: at.apply(&run.moment),
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
        peak_strain: run.peak_strain,
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
        let at = stencil(&run.depths, tip(t));
        trial.tool.push(ToolSample {
            t,
            tip_x: plan.line,
            tip_y: tip(t),
            theta: 0.0,
            fx: instruments.force(0.0),
            fy: instruments.force(at.apply(&run.force)),
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
