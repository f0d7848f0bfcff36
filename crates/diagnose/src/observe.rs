//! Extract what the model predicts from a bundle: marker positions per
//! camera frame with the load at that instant, and needle base forces per
//! sensor sample.
//!
//! The load at a frame comes from `tool.csv` interpolated linearly at the
//! frame time. A probe's force is the mean of the `probe_force_samples`
//! sensor samples nearest in time, so its noise is `force_sigma / sqrt(k)`.
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
    /// component, on the material point `contact` of the boundary.
    Probe {
        contact: [f64; 2],
        force: [f64; 2],
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
}

impl Observations {
    /// The observations of every probe and needle trial of `campaign`,
    /// keeping at most `frames_per_trial` camera frames of each (evenly
    /// spaced, the last always kept; 0 keeps all).
    pub fn from_campaign(
        campaign: &Campaign,
        probe_force_samples: usize,
        force_sigma: f64,
        frames_per_trial: usize,
    ) -> Result<Self, DiagnoseError> {
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
                            let (force, count) =
                                mean_force_near(&data.tool, frame.t, probe_force_samples);
                            Load::Probe {
                                contact: nearest_boundary_point(
                                    [pose.tip_x, pose.tip_y],
                                    campaign.phantom.width,
                                    campaign.phantom.depth,
                                ),
                                force,
                                force_sigma: force_sigma / (count as f64).sqrt(),
                            }
                        }
                        _ => match shaft(&interpolate(&data.tool, frame.t)).map_err(fail)? {
                            Some(s) => Load::Needle(s),
                            None => Load::Free,
                        },
                    };
                    let mut markers = Vec::with_capacity(frame.len());
                    for (id, position) in frame.iter() {
                        let marker = campaign.markers_rest.index_of(id).ok_or_else(|| {
                            fail(format!("marker {id} is not in markers_rest.csv"))
                        })?;
                        markers.push((marker, position));
                    }
                    out.frames.push(Frame {
                        trial: index,
                        t: frame.t,
                        load,
                        markers,
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

/// Mean force of the `count` samples nearest to `t`, and how many there were.
fn mean_force_near(tool: &[ToolSample], t: f64, count: usize) -> ([f64; 2], usize) {
    let mut order: Vec<usize> = (0..tool.len()).collect();
    order.sort_by(|&a, &b| (tool[a].t - t).abs().total_cmp(&(tool[b].t - t).abs()));
    order.truncate(count);
    let n = order.len();
    let mut force = [0.0; 2];
    for &k in &order {
        force[0] += tool[k].fx / n as f64;
        force[1] += tool[k].fy / n as f64;
    }
    (force, n)
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
    use super::{nearest_boundary_point, thinned};

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
