//! Extract what the model predicts from a bundle: marker positions per
//! camera frame with the load at that instant, and needle base forces per
//! sensor sample.
//!
//! The load at a frame comes from `tool.csv` interpolated linearly at the
//! frame time. A probe's force and moment are the means of the
//! `probe_force_samples` sensor samples nearest in time, so the force's
//! noise is `force_sigma / sqrt(k)`; the moment, measured about the tip, is
//! moved to the contact point on the outline.
//! A needle's shaft runs along its axis $\hat d = (-\sin\theta, \cos\theta)$
//! from the line's crossing of the front face $y = 0$ to the tip, a length
//! $L = y_\text{tip} / \cos\theta$ (the forward model shortens it by the
//! drag of the entry, see `place`).

use needle_data::{Campaign, ToolSample, TrialKind};

use crate::effect::TrialContext;
use crate::error::DiagnoseError;

/// The load on the slab at one instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Load {
    /// Nothing touches the slab (needle not inserted yet).
    Free,
    /// A probe pushing with `force` (N), whose noise is `force_sigma` per
    /// component, and `moment` about z (N m, about `contact`), on the
    /// material point `contact` of the boundary.
    Probe {
        contact: [f64; 2],
        force: [f64; 2],
        moment: f64,
        force_sigma: f64,
    },
    /// A needle inserted by `length` along `direction` from `entry`.
    Needle(Shaft),
}

/// The inserted part of a needle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Shaft {
    pub entry: [f64; 2],
    pub direction: [f64; 2],
    pub length: f64,
}

/// One camera frame of one trial.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Frame {
    pub trial: usize,
    pub t: f64,
    pub load: Load,
    /// `(marker index in the rest set, measured position)`.
    pub markers: Vec<(usize, [f64; 2])>,
    /// The tracking standard deviations `(sx, sy)` of those rows (m), when
    /// `markers.csv` gives them.
    pub row_sigmas: Option<Vec<[f64; 2]>>,
}

/// One needle force sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct ForceSample {
    pub trial: usize,
    pub t: f64,
    pub shaft: Option<Shaft>,
    pub measured: [f64; 2],
}

/// Everything the model is compared with, in residual order: marker
/// coordinates frame by frame (x then y per marker), then force components.
#[derive(Debug, Clone)]
pub(crate) struct Observations {
    pub trial_ids: Vec<String>,
    pub trials: Vec<TrialContext>,
    pub rest: Vec<[f64; 2]>,
    pub frames: Vec<Frame>,
    pub forces: Vec<ForceSample>,
    /// Per trial, the marker positions of probe frames left out as too
    /// near the contact (see [`crate::DiagnoseOptions::probe_near_field`]).
    pub near_field_left_out: Vec<usize>,
}

impl Observations {
    /// The observations of every probe and needle trial of `campaign`,
    /// keeping at most `frames_per_trial` camera frames of each (evenly
    /// spaced, the last always kept; 0 keeps all), and leaving out a probe
    /// frame's markers closer to the contact than `probe_near_field` times
    /// the phantom's thickness.
    pub fn from_campaign(
        campaign: &Campaign,
        probe_force_samples: usize,
        force_sigma: f64,
        frames_per_trial: usize,
        probe_near_field: f64,
    ) -> Result<Self, DiagnoseError> {
        // Markers at exactly the radius (a grid spaced at half the
        // thickness has some) stay in.
        let near_field = probe_near_field * campaign.phantom.thickness * (1.0 - 1e-9);
        let rest: Vec<[f64; 2]> = campaign
            .markers_rest
            .as_slice()
            .iter()
            .map(|m| [m.x, m.y])
            .collect();
        let mut out = Self {
            trial_ids: Vec::new(),
            trials: Vec::new(),
            rest,
            frames: Vec::new(),
            forces: Vec::new(),
            near_field_left_out: Vec::new(),
        };
        for data in &campaign.trials {
            let trial = &data.trial;
            if trial.kind == TrialKind::Compression || data.tool.is_empty() {
                continue;
            }
            let index = out.trials.len();
            out.trial_ids.push(trial.id.clone());
            out.trials.push(TrialContext {
                kind: trial.kind,
                velocity: trial.velocity,
                day: trial.day,
            });
            out.near_field_left_out.push(0);
            let fail = |message: String| DiagnoseError::TrialGeometry {
                bundle: campaign.name.clone(),
                trial: trial.id.clone(),
                message,
            };
            if let Some(track) = &data.markers {
                let frames: Vec<_> = track.frames().collect();
                for frame in thinned(frames.len(), frames_per_trial)
                    .into_iter()
                    .map(|i| &frames[i])
                {
                    let load = match trial.kind {
                        TrialKind::Probe => {
                            let pose = interpolate(&data.tool, frame.t);
                            let (force, tip_moment, count) =
                                mean_load_near(&data.tool, frame.t, probe_force_samples);
                            let tip = [pose.tip_x, pose.tip_y];
                            let contact = nearest_boundary_point(
                                tip,
                                campaign.phantom.width,
                                campaign.phantom.depth,
                            );
                            // The bundle's moment is about the tip; move it
                            // to the contact point the load is spread about.
                            let arm = [tip[0] - contact[0], tip[1] - contact[1]];
                            Load::Probe {
                                contact,
                                force,
                                moment: tip_moment + arm[0] * force[1] - arm[1] * force[0],
                                force_sigma: force_sigma / (count as f64).sqrt(),
                            }
                        }
                        _ => match shaft(&interpolate(&data.tool, frame.t)).map_err(fail)? {
                            Some(s) => Load::Needle(s),
                            None => Load::Free,
                        },
                    };
                    let mut markers = Vec::with_capacity(frame.len());
                    let mut row_sigmas = frame.sigmas.map(|_| Vec::with_capacity(frame.len()));
                    for (row, (id, position)) in frame.iter().enumerate() {
                        let marker = campaign.markers_rest.index_of(id).ok_or_else(|| {
                            fail(format!("marker {id} is not in markers_rest.csv"))
                        })?;
                        if let Load::Probe { contact, .. } = load {
                            let rest = out.rest[marker];
                            if (rest[0] - contact[0]).hypot(rest[1] - contact[1]) < near_field {
                                out.near_field_left_out[index] += 1;
                                continue;
                            }
                        }
                        markers.push((marker, position));
                        if let (Some(kept), Some(given)) = (&mut row_sigmas, frame.sigmas) {
                            kept.push(given[row]);
                        }
                    }
                    out.frames.push(Frame {
                        trial: index,
                        t: frame.t,
                        load,
                        markers,
                        row_sigmas,
                    });
                }
            }
            if trial.kind == TrialKind::Needle {
                for sample in &data.tool {
                    out.forces.push(ForceSample {
                        trial: index,
                        t: sample.t,
                        shaft: shaft(sample).map_err(fail)?,
                        measured: [sample.fx, sample.fy],
                    });
                }
            }
        }
        if out.frames.iter().all(|f| f.markers.is_empty()) && out.forces.is_empty() {
            return Err(DiagnoseError::NoObservations(campaign.name.clone()));
        }
        Ok(out)
    }

    /// Whether any frame has a probe on the slab.
    pub fn has_probe_frames(&self) -> bool {
        self.frames
            .iter()
            .any(|f| matches!(f.load, Load::Probe { .. }))
    }

    /// Number of marker residuals (two per marker per frame).
    pub fn marker_count(&self) -> usize {
        2 * self.frames.iter().map(|f| f.markers.len()).sum::<usize>()
    }

    /// Per marker residual slot, the row's own tracking sigma (NaN where
    /// its row gives none, or zero, which no tracker can mean); empty when
    /// no row does.
    pub fn row_sigmas(&self) -> Vec<f64> {
        if self.frames.iter().all(|f| f.row_sigmas.is_none()) {
            return Vec::new();
        }
        let mut out = Vec::with_capacity(self.marker_count());
        for frame in &self.frames {
            match &frame.row_sigmas {
                Some(sigmas) => out.extend(
                    sigmas
                        .iter()
                        .flatten()
                        .map(|&s| if s > 0.0 { s } else { f64::NAN }),
                ),
                None => out.extend(std::iter::repeat_n(f64::NAN, 2 * frame.markers.len())),
            }
        }
        out
    }

    /// The trial of every residual, in residual order.
    pub fn row_trials(&self) -> Vec<usize> {
        let markers = self
            .frames
            .iter()
            .flat_map(|f| std::iter::repeat_n(f.trial, 2 * f.markers.len()));
        let forces = self
            .forces
            .iter()
            .flat_map(|s| std::iter::repeat_n(s.trial, 2));
        markers.chain(forces).collect()
    }

    /// Number of force residuals (two per needle sample).
    pub fn force_count(&self) -> usize {
        2 * self.forces.len()
    }

    /// The measured vector in residual order: marker displacements from
    /// rest, then forces.
    pub fn measured(&self) -> Vec<f64> {
        let mut out = Vec::with_capacity(self.marker_count() + self.force_count());
        for frame in &self.frames {
            for &(m, p) in &frame.markers {
                out.push(p[0] - self.rest[m][0]);
                out.push(p[1] - self.rest[m][1]);
            }
        }
        for sample in &self.forces {
            out.extend_from_slice(&sample.measured);
        }
        out
    }
}

/// Indices of at most `count` of `n` items, evenly spaced and ending with
/// the last (all of them when `count` is 0 or not smaller than `n`).
fn thinned(n: usize, count: usize) -> Vec<usize> {
    if count == 0 || count >= n {
        return (0..n).collect();
    }
    (1..=count).map(|k| (k * n).div_ceil(count) - 1).collect()
}

/// The tool pose at time `t`, linear between samples, held beyond the ends.
fn interpolate(tool: &[ToolSample], t: f64) -> ToolSample {
    let k = tool.partition_point(|s| s.t <= t);
    if k == 0 {
        return tool[0];
    }
    if k == tool.len() {
        return tool[k - 1];
    }
    let (a, b) = (tool[k - 1], tool[k]);
    let w = if b.t > a.t {
        (t - a.t) / (b.t - a.t)
    } else {
        0.0
    };
    let mix = |x: f64, y: f64| x + w * (y - x);
    ToolSample {
        t,
        tip_x: mix(a.tip_x, b.tip_x),
        tip_y: mix(a.tip_y, b.tip_y),
        theta: mix(a.theta, b.theta),
        fx: mix(a.fx, b.fx),
        fy: mix(a.fy, b.fy),
        mz: mix(a.mz, b.mz),
    }
}

/// Mean force and moment of the `count` samples nearest to `t`, and how
/// many there were.
fn mean_load_near(tool: &[ToolSample], t: f64, count: usize) -> ([f64; 2], f64, usize) {
    let mut order: Vec<usize> = (0..tool.len()).collect();
    order.sort_by(|&a, &b| (tool[a].t - t).abs().total_cmp(&(tool[b].t - t).abs()));
    order.truncate(count);
    let n = order.len();
    let (mut force, mut moment) = ([0.0; 2], 0.0);
    for &k in &order {
        force[0] += tool[k].fx / n as f64;
        force[1] += tool[k].fy / n as f64;
        moment += tool[k].mz / n as f64;
    }
    (force, moment, n)
}

/// The point of the phantom's outline $[0, w] \times [0, d]$ nearest to
/// `tip`: where a blunt probe's force acts in the reference configuration.
/// The tip itself sits inside the outline by the indentation, and a load
/// applied there would be a load inside the body, not on its boundary.
fn nearest_boundary_point(tip: [f64; 2], width: f64, depth: f64) -> [f64; 2] {
    let [x, y] = [tip[0].clamp(0.0, width), tip[1].clamp(0.0, depth)];
    let candidates = [[0.0, y], [width, y], [x, 0.0], [x, depth]];
    let distance = |p: &[f64; 2]| (p[0] - x).abs() + (p[1] - y).abs();
    candidates
        .into_iter()
        .min_by(|a, b| distance(a).total_cmp(&distance(b)))
        .unwrap_or([x, y])
}

/// The inserted shaft of a needle pose, `None` before it enters.
fn shaft(pose: &ToolSample) -> Result<Option<Shaft>, String> {
    let direction = [-pose.theta.sin(), pose.theta.cos()];
    if direction[1] < 0.1 {
        return Err(format!(
            "needle angle {} rad at t = {} s does not point into the front face",
            pose.theta, pose.t
        ));
    }
    let length = pose.tip_y / direction[1];
    if length <= 0.0 {
        return Ok(None);
    }
    Ok(Some(Shaft {
        entry: [
            pose.tip_x - length * direction[0],
            pose.tip_y - length * direction[1],
        ],
        direction,
        length,
    }))
}

#[cfg(test)]
mod tests {
    use needle_data::{
        BundleBuilder, Campaign, MarkerRest, MarkerTrack, Phantom, ToolSample, Trial, TrialKind,
    };

    use super::{Load, Observations, nearest_boundary_point, thinned};

    /// A probe indented 1 mm at x = 30 mm (force (0.05, 0.2) N, moment
    /// 1e-5 N m about its tip) and a needle trial, each with one frame of
    /// four markers: on the contact, at exactly one thickness (7.5 mm)
    /// from it along the face, 5.8 mm from it, and 20 mm deep.
    fn probe_campaign() -> Campaign {
        let mut builder = BundleBuilder::new(
            "near",
            Phantom {
                width: 0.075,
                depth: 0.075,
                thickness: 0.0075,
                fixed: vec![needle_data::Face::Back],
            },
        );
        let points = [[0.03, 0.0], [0.0375, 0.0], [0.035, 0.003], [0.03, 0.02]];
        builder.markers_rest(
            points
                .iter()
                .enumerate()
                .map(|(id, p)| MarkerRest {
                    id: id as u32,
                    x: p[0],
                    y: p[1],
                })
                .collect(),
        );
        for (id, kind) in [("probe", TrialKind::Probe), ("needle", TrialKind::Needle)] {
            let trial = builder.trial(Trial {
                id: id.into(),
                kind,
                velocity: 0.001,
                day: 0.0,
            });
            trial.tool.push(ToolSample {
                t: 0.0,
                tip_x: 0.03,
                tip_y: 0.001,
                theta: 0.0,
                fx: 0.05,
                fy: 0.2,
                mz: 1e-5,
            });
            let frame = points.iter().enumerate().map(|(id, p)| (id as u32, *p));
            trial.markers_mut().push_frame(0, 0.0, frame).unwrap();
        }
        builder.finish()
    }

    #[test]
    fn probe_frames_leave_out_the_markers_within_the_near_field() {
        let campaign = probe_campaign();
        let kept = |obs: &Observations, trial: usize| -> Vec<usize> {
            let frame = obs.frames.iter().find(|f| f.trial == trial).unwrap();
            frame.markers.iter().map(|&(m, _)| m).collect()
        };
        let obs = Observations::from_campaign(&campaign, 1, 0.005, 0, 1.0).unwrap();
        // The marker at exactly one thickness stays; the needle keeps all.
        assert_eq!(kept(&obs, 0), vec![1, 3]);
        assert_eq!(kept(&obs, 1), vec![0, 1, 2, 3]);
        assert_eq!(obs.near_field_left_out, vec![2, 0]);
        let all = Observations::from_campaign(&campaign, 1, 0.005, 0, 0.0).unwrap();
        assert_eq!(kept(&all, 0), vec![0, 1, 2, 3]);
        assert_eq!(all.near_field_left_out, vec![0, 0]);
        let wider = Observations::from_campaign(&campaign, 1, 0.005, 0, 2.0).unwrap();
        assert_eq!(kept(&wider, 0), vec![3]);
    }

    /// The probe trial's rows give their own sigmas (marker 1's sy zero),
    /// the needle trial's none: slots of the markers kept, in order.
    #[test]
    fn row_sigmas_follow_the_markers_kept() {
        let mut campaign = probe_campaign();
        let rows: Vec<_> = (0..4u32)
            .map(|id| {
                let p = campaign.markers_rest.as_slice()[id as usize];
                let sy = if id == 1 { 0.0 } else { 2e-6 * f64::from(id) };
                (id, [p.x, p.y], [1e-6 * f64::from(id + 1), sy])
            })
            .collect();
        let track = campaign.trials[0].markers.as_mut().unwrap();
        *track = MarkerTrack::default();
        track.push_frame_with_sigma(0, 0.0, rows).unwrap();
        let obs = Observations::from_campaign(&campaign, 1, 0.005, 0, 1.0).unwrap();
        let sigmas = obs.row_sigmas();
        assert_eq!(sigmas.len(), obs.marker_count());
        // Probe frame: markers 1 and 3 kept; then the needle's four, none given.
        assert_eq!(sigmas[0], 2e-6);
        assert!(sigmas[1].is_nan());
        assert_eq!(sigmas[2..4], [4e-6, 6e-6]);
        assert!(sigmas[4..].iter().all(|s| s.is_nan()));
        let plain = Observations::from_campaign(&probe_campaign(), 1, 0.005, 0, 1.0).unwrap();
        assert!(plain.row_sigmas().is_empty());
    }

    /// The bundle's moment is about the tip, 1 mm inside the face; about
    /// the contact point on the face it gains $-d_y F_x$.
    #[test]
    fn probe_moment_is_moved_to_the_contact() {
        let obs = Observations::from_campaign(&probe_campaign(), 1, 0.005, 0, 1.0).unwrap();
        let Load::Probe {
            contact,
            force,
            moment,
            ..
        } = obs.frames[0].load
        else {
            panic!("the first frame is the probe's");
        };
        assert_eq!(contact, [0.03, 0.0]);
        assert_eq!(force, [0.05, 0.2]);
        assert!((moment - (1e-5 - 0.001 * 0.05)).abs() < 1e-15, "{moment}");
    }

    #[test]
    fn probe_contact_is_the_nearest_point_of_the_outline() {
        // Indented 3 mm into the front face, 2 mm into the left face, outside.
        assert_eq!(
            nearest_boundary_point([0.03, 0.003], 0.075, 0.06),
            [0.03, 0.0]
        );
        assert_eq!(
            nearest_boundary_point([0.002, 0.03], 0.075, 0.06),
            [0.0, 0.03]
        );
        assert_eq!(
            nearest_boundary_point([0.08, 0.059], 0.075, 0.06),
            [0.075, 0.059]
        );
        assert_eq!(
            nearest_boundary_point([0.03, -0.001], 0.075, 0.06),
            [0.03, 0.0]
        );
    }

    #[test]
    fn thinning_spreads_frames_and_keeps_the_last() {
        assert_eq!(thinned(10, 0), (0..10).collect::<Vec<_>>());
        assert_eq!(thinned(3, 5), vec![0, 1, 2]);
        assert_eq!(thinned(10, 3), vec![3, 6, 9]);
        assert_eq!(thinned(12, 4), vec![2, 5, 8, 11]);
    }
}
