//! The needle shaft force distribution: the axial force per unit length
//! that the shaft applies to the tissue, and its quadrature.
//!
//! Along the inserted shaft, at distance $d$ behind the tip, the density is
//! $$q(d) = q_0\,g_v(v)\,g_t(d),$$
//! with $q_0$ the density at the reference velocity, $g_v$ the factor of
//! `velocity_dependent_friction` (1 without it) and $g_t$ the tip peak of
//! `tip_cutting_force` (1 without it). The force acts along the needle
//! axis (+y) on the tissue. The force the tool applies, measured at its
//! base, is its integral over the inserted length: the truth uses the same
//! quadrature for both, so the two agree exactly.

use crate::effect::TipCuttingForce;
use crate::scenario::{NeedlePlan, Scenario};

/// The shaft force density of one trial.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct ShaftLoad {
    /// Density behind the tip peak at this trial's velocity (N/m).
    pub density: f64,
    tip: Option<TipCuttingForce>,
}

/// One quadrature point of the shaft: spatial depth and weighted force.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct ShaftPoint {
    /// Spatial y of the point on the needle (m).
    pub y: f64,
    /// Force carried by the point, $w\,q(d)$ (N).
    pub force: f64,
}

impl ShaftLoad {
    /// The distribution of a needle trial of `scenario`.
    pub fn of(scenario: &Scenario, plan: &NeedlePlan) -> Self {
        let v_factor = scenario
            .effects
            .velocity_dependent_friction
            .map_or(1.0, |f| {
                f.factor(plan.velocity, scenario.shaft.reference_velocity)
            });
        Self {
            density: scenario.shaft.density * v_factor,
            tip: scenario.effects.tip_cutting_force,
        }
    }

    /// Density at `distance` behind the tip (N/m).
    pub fn at(&self, distance: f64) -> f64 {
        self.density * self.tip.map_or(1.0, |t| t.factor(distance))
    }

    /// Two-point Gauss quadrature of the shaft between the spatial entry
    /// point `entry` and the `tip` (y, m) in `segments` equal segments. A
    /// shaft not yet inside (entry at or beyond the tip) gives points
    /// without force, so that the number of points depends on `segments`
    /// alone.
    pub fn points(&self, entry: f64, tip: f64, segments: usize) -> Vec<ShaftPoint> {
        let length = (tip - entry).max(0.0);
        let h = length / segments as f64;
        let g = 0.5 / 3f64.sqrt();
        let mut points = Vec::with_capacity(2 * segments);
        for s in 0..segments {
            let mid = tip - length + (s as f64 + 0.5) * h;
            for y in [mid - g * h, mid + g * h] {
                points.push(ShaftPoint {
                    y,
                    force: 0.5 * h * self.at(tip - y),
                });
            }
        }
        points
    }
}
