//! From a measurement bundle to [`ProbeData`]: the `Probe` trials' camera
//! frames with the probe in contact, each with the force and tip position
//! synchronised to the frame time by linear interpolation of `tool.csv`,
//! and the marker displacements (tracked minus rest position).

use needle_data::{Face as BundleFace, LoadedBundle, ToolSample, TrialData, TrialKind};
use needle_fem::mesh::Face;

use crate::error::IdentifyError;
use crate::options::IdentifyOptions;
use crate::probe::{MarkerDisplacement, ProbeData, ProbeFrame, ProbeSetup, ProbeTrial};
use crate::result::FitFlag;

/// Contact threshold as a multiple of the stated force noise.
const CONTACT_NOISE_MULTIPLE: f64 = 5.0;
/// Contact threshold as a fraction of the trial's peak force when no force
/// noise is stated.
const CONTACT_PEAK_FRACTION: f64 = 0.02;

/// The probing data of a bundle, and flags for the trials or frames that
/// could not be used (a trial without `markers.csv`, with zero force, or
/// with no frame in contact is skipped and flagged; if every `Probe` trial
/// is skipped the result is an error listing why).
pub fn extract_probe_data(
    bundle: &LoadedBundle,
    options: &IdentifyOptions,
) -> Result<(ProbeData, Vec<FitFlag>), IdentifyError> {
    let campaign = &bundle.campaign;
    let phantom = &campaign.phantom;
    let markers_rest = &campaign.markers_rest;
    let setup = ProbeSetup {
        width: phantom.width,
        depth: phantom.depth,
        thickness: phantom.thickness,
        fixed: phantom.fixed.iter().map(|&f| fem_face(f)).collect(),
        markers: markers_rest.as_slice().iter().map(|m| [m.x, m.y]).collect(),
    };
    let probes: Vec<&TrialData> = campaign
        .trials
        .iter()
        .filter(|t| t.trial.kind == TrialKind::Probe)
        .collect();
    if probes.is_empty() {
        return Err(IdentifyError::NoProbeTrials);
    }
    let force_sigma = campaign.noise.map(|n| n.force_sigma);
    let mut trials = Vec::new();
    let mut frames = Vec::new();
    let mut flags = Vec::new();
    let mut reasons = Vec::new();
    for data in probes {
        let id = data.trial.id.clone();
        match contact_frames(
            data,
            trials.len(),
            force_sigma,
            options,
            |marker| markers_rest.index_of(marker),
            |i| markers_rest.as_slice()[i],
        ) {
            Ok((trial_frames, outside)) => {
                if outside > 0 {
                    flags.push(FitFlag::FramesOutsideForceRecord {
                        trial: id.clone(),
                        count: outside,
                    });
                }
                trials.push(ProbeTrial {
                    id,
                    day: data.trial.day,
                });
                frames.extend(trial_frames);
            }
            Err(reason) => {
                reasons.push(format!("trial `{id}`: {reason}"));
                flags.push(FitFlag::TrialSkipped { trial: id, reason });
            }
        }
    }
    if frames.is_empty() {
        return Err(IdentifyError::NoContactFrames {
            reason: reasons.join("; "),
        });
    }
    let data = ProbeData {
        setup,
        trials,
        frames,
        marker_sigma: campaign.noise.map(|n| n.marker_sigma),
    };
    Ok((data, flags))
}

/// The frames of one trial with the probe in contact, and the number of
/// frames whose time lies outside the force record; `Err` says why the
/// trial gives nothing.
fn contact_frames(
    data: &TrialData,
    trial_index: usize,
    force_sigma: Option<f64>,
    options: &IdentifyOptions,
    index_of: impl Fn(u32) -> Option<usize>,
    rest_of: impl Fn(usize) -> needle_data::MarkerRest,
) -> Result<(Vec<ProbeFrame>, usize), String> {
    let Some(track) = &data.markers else {
        return Err("no markers.csv (track the frames first)".into());
    };
    let tool = &data.tool;
    if tool.is_empty() {
        return Err("tool.csv has no samples".into());
    }
    let peak = tool.iter().map(|s| s.fx.hypot(s.fy)).fold(0.0, f64::max);
    if peak == 0.0 {
        return Err("the probe force is zero in every tool.csv sample".into());
    }
    let threshold = options
        .contact_force
        .or(force_sigma
            .filter(|s| *s > 0.0)
            .map(|s| CONTACT_NOISE_MULTIPLE * s))
        .unwrap_or(CONTACT_PEAK_FRACTION * peak);
    let mut frames = Vec::new();
    let mut outside = 0;
    for frame in track.frames() {
        let sample = match options.force_window {
            Some(half_width) => fitted_sample_at(tool, frame.t, half_width),
            None => sample_at(tool, frame.t),
        };
        let Some(sample) = sample else {
            outside += 1;
            continue;
        };
        if sample.fx.hypot(sample.fy) < threshold {
            continue;
        }
        let mut displacements = Vec::with_capacity(frame.len());
        for (k, (id, position)) in frame.iter().enumerate() {
            // The bundle reader has checked that every id is in markers_rest.csv.
            let Some(marker) = index_of(id) else { continue };
            let rest = rest_of(marker);
            displacements.push(MarkerDisplacement {
                marker,
                displacement: [position[0] - rest.x, position[1] - rest.y],
                sigma: frame.sigmas.map(|s| s[k]),
            });
        }
        frames.push(ProbeFrame {
            trial: trial_index,
            t: frame.t,
            tip: [sample.tip_x, sample.tip_y],
            force: [sample.fx, sample.fy],
            displacements,
        });
    }
    if frames.is_empty() {
        return Err(format!(
            "no camera frame with the probe in contact (force at least {threshold:.3e} N within the tool.csv time range; peak force {peak:.3e} N)"
        ));
    }
    Ok((frames, outside))
}

/// The tool sample at time `t`, linear in time between the two samples
/// around it; `None` outside the record.
pub fn sample_at(tool: &[ToolSample], t: f64) -> Option<ToolSample> {
    let (first, last) = (tool.first()?, tool.last()?);
    if !(t >= first.t && t <= last.t) {
        return None;
    }
    let after = tool.partition_point(|s| s.t < t);
    if after == 0 {
        return Some(*first);
    }
    let (a, b) = (tool[after - 1], tool[after.min(tool.len() - 1)]);
    let span = b.t - a.t;
    let w = if span > 0.0 { (t - a.t) / span } else { 1.0 };
    let mix = |p: f64, q: f64| p + w * (q - p);
    Some(ToolSample {
        t,
        tip_x: mix(a.tip_x, b.tip_x),
        tip_y: mix(a.tip_y, b.tip_y),
        theta: mix(a.theta, b.theta),
        fx: mix(a.fx, b.fx),
        fy: mix(a.fy, b.fy),
        mz: mix(a.mz, b.mz),
    })
}

/// The tool sample at time `t` from a straight line fitted by least
/// squares to the samples within `half_width` seconds of `t` (at least
/// three, else the two samples around `t` as in [`sample_at`]); `None`
/// outside the record.
///
/// Why: the force sensor's noise and quantisation (the paper's Nano-17
/// reads in steps of 12.5 mN) are large against a probe force of a few
/// tenths of a newton, and the fit takes the force as exact. Over a window
/// in which the force is linear in time (a probe ramp at constant
/// velocity on a linear material) the line's value at `t` is unbiased and
/// its noise is that of one sample divided by about $\sqrt n$.
pub fn fitted_sample_at(tool: &[ToolSample], t: f64, half_width: f64) -> Option<ToolSample> {
    let nearest = sample_at(tool, t)?;
    let lo = tool.partition_point(|s| s.t < t - half_width);
    let hi = tool.partition_point(|s| s.t <= t + half_width);
    let window = &tool[lo..hi];
    if window.len() < 3 {
        return Some(nearest);
    }
    let n = window.len() as f64;
    let mean_dt = window.iter().map(|s| s.t - t).sum::<f64>() / n;
    let spread: f64 = window.iter().map(|s| (s.t - t - mean_dt).powi(2)).sum();
    if spread <= 0.0 {
        return Some(nearest);
    }
    // Value at t of the least-squares line through (s.t - t, value).
    let at_t = |value: fn(&ToolSample) -> f64| {
        let mean = window.iter().map(value).sum::<f64>() / n;
        let slope = window
            .iter()
            .map(|s| (s.t - t - mean_dt) * (value(s) - mean))
            .sum::<f64>()
            / spread;
        mean - slope * mean_dt
    };
    Some(ToolSample {
        t,
        tip_x: at_t(|s| s.tip_x),
        tip_y: at_t(|s| s.tip_y),
        theta: at_t(|s| s.theta),
        fx: at_t(|s| s.fx),
        fy: at_t(|s| s.fy),
        mz: at_t(|s| s.mz),
    })
}

fn fem_face(face: BundleFace) -> Face {
    match face {
        BundleFace::Front => Face::Front,
        BundleFace::Back => Face::Back,
        BundleFace::Left => Face::Left,
        BundleFace::Right => Face::Right,
    }
}
