//! Shaft force density against insertion velocity (the paper's Fig. 14):
//! the mean density on the shaft behind the tip peak, per velocity.

use serde::{Deserialize, Serialize};

use crate::error::ForceError;
use crate::estimate::ShaftDistribution;

/// Which part of the shaft is "behind the force peak at the tip".
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ShaftWindow {
    /// Length excluded behind the entry (m): the entry region carries the
    /// plane model's spurious force and the front face's free-edge effect.
    pub skip_entry: f64,
    /// Length excluded before the tip (m): the tip peak.
    pub skip_tip: f64,
    /// Frames with a shorter shaft are not used (m).
    pub min_depth: f64,
}

impl Default for ShaftWindow {
    /// 5 mm behind the entry, 10 mm before the tip, shafts of 30 mm or more.
    fn default() -> Self {
        Self {
            skip_entry: 5e-3,
            skip_tip: 10e-3,
            min_depth: 30e-3,
        }
    }
}

/// The mean shaft density of one velocity.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct VelocityPoint {
    /// Insertion velocity (m/s).
    pub velocity: f64,
    /// Mean density over the window, frames and trials (N/m).
    pub density: f64,
    /// Standard deviation of the per-trial means (N/m); zero for one trial.
    pub spread: f64,
    /// Number of trials at this velocity.
    pub trials: usize,
}

/// Mean density of one distribution over the window, or `None` when the
/// shaft is too short for it.
pub fn window_density(distribution: &ShaftDistribution, window: ShaftWindow) -> Option<f64> {
    let (a, b) = (window.skip_entry, distribution.length - window.skip_tip);
    if distribution.length < window.min_depth || b <= a {
        return None;
    }
    let steps = 200;
    let h = (b - a) / steps as f64;
    let sum: f64 = (0..steps)
        .map(|k| distribution.density_at(a + (k as f64 + 0.5) * h))
        .sum();
    Some(sum * h / (b - a))
}

/// Density against velocity from the distributions of several insertions:
/// `trials` holds `(velocity, distributions of that trial's frames)`.
/// Trials whose velocities agree to 1e-9 m/s are pooled. Trials with no frame
/// deep enough for the window are left out; if none remains, an error.
pub fn density_vs_velocity(
    trials: &[(f64, Vec<ShaftDistribution>)],
    window: ShaftWindow,
) -> Result<Vec<VelocityPoint>, ForceError> {
    let mut per_trial: Vec<(f64, f64)> = Vec::new();
    for (velocity, distributions) in trials {
        let values: Vec<f64> = distributions
            .iter()
            .filter_map(|d| window_density(d, window))
            .collect();
        if !values.is_empty() {
            per_trial.push((*velocity, values.iter().sum::<f64>() / values.len() as f64));
        }
    }
    if per_trial.is_empty() {
        return Err(ForceError::Empty(
            "density against velocity (no frame deep enough for the window)",
        ));
    }
    per_trial.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut points: Vec<VelocityPoint> = Vec::new();
    let mut start = 0;
    while start < per_trial.len() {
        let v = per_trial[start].0;
        let end = start
            + per_trial[start..]
                .iter()
                .take_while(|p| (p.0 - v).abs() <= 1e-9)
                .count();
        let group: Vec<f64> = per_trial[start..end].iter().map(|p| p.1).collect();
        let mean = group.iter().sum::<f64>() / group.len() as f64;
        let spread = if group.len() > 1 {
            (group.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (group.len() - 1) as f64)
                .sqrt()
        } else {
            0.0
        };
        points.push(VelocityPoint {
            velocity: v,
            density: mean,
            spread,
            trials: group.len(),
        });
        start = end;
    }
    Ok(points)
}
