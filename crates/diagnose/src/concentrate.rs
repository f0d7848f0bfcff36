//! Where the residual energy concentrates compared with where the markers
//! are: the concentration (Lorenz) curve of the per-marker residual energy.
//!
//! With $e_m = \sum_\text{frames} |r_m|^2$ the energy of marker $m$ and the
//! markers sorted from the worst down, the curve is
//! $\big(k/M,\ \sum_{j \le k} e_{(j)} / \sum_j e_j\big)$, $k = 0..M$. If
//! the residual were spread evenly over the markers (pure noise) it would
//! follow the diagonal; a local defect the model lacks (an inclusion, a
//! probe's contact patch) bows it up: a few markers hold most of the energy.

use std::collections::BTreeMap;

use crate::MarkerResidual;

/// The concentration curve of the marker residuals: points
/// `(share of markers, share of residual energy)` from `(0, 0)` to `(1, 1)`,
/// worst markers first. Empty when there is no residual.
pub fn residual_concentration(residuals: &[MarkerResidual]) -> Vec<(f64, f64)> {
    let mut energy: BTreeMap<usize, f64> = BTreeMap::new();
    for r in residuals {
        *energy.entry(r.marker).or_default() += r.rx * r.rx + r.ry * r.ry;
    }
    let mut sorted: Vec<f64> = energy.into_values().collect();
    sorted.sort_by(|a, b| b.total_cmp(a));
    let total: f64 = sorted.iter().sum();
    if sorted.is_empty() || total.is_nan() || total <= 0.0 {
        return Vec::new();
    }
    let count = sorted.len() as f64;
    let mut curve = vec![(0.0, 0.0)];
    let mut running = 0.0;
    for (k, e) in sorted.iter().enumerate() {
        running += e;
        curve.push(((k + 1) as f64 / count, running / total));
    }
    curve
}

/// The share of the residual energy held by the worst `fraction` of the
/// markers, read off the concentration curve (linear between its points).
pub fn energy_share_of_worst(curve: &[(f64, f64)], fraction: f64) -> f64 {
    let fraction = fraction.clamp(0.0, 1.0);
    curve
        .windows(2)
        .find(|w| w[1].0 >= fraction)
        .map_or(1.0, |w| {
            let (a, b) = (w[0], w[1]);
            a.1 + (b.1 - a.1) * (fraction - a.0) / (b.0 - a.0)
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn residual(marker: usize, r: f64) -> MarkerResidual {
        MarkerResidual {
            trial: 0,
            t: 0.0,
            marker,
            x: 0.0,
            y: 0.0,
            rx: r,
            ry: 0.0,
            velocity: 0.0,
            day: 0.0,
            tip_depth: 0.0,
            distance_from_tool: 0.0,
            radius: 0.0,
        }
    }

    #[test]
    fn an_even_residual_follows_the_diagonal() {
        let residuals: Vec<_> = (0..50).map(|m| residual(m, 1e-5)).collect();
        let curve = residual_concentration(&residuals);
        assert_eq!(curve.len(), 51);
        for (x, y) in &curve {
            assert!((x - y).abs() < 1e-12);
        }
        assert!((energy_share_of_worst(&curve, 0.1) - 0.1).abs() < 1e-12);
    }

    #[test]
    fn one_bad_marker_holds_its_share() {
        // Nine markers with energy 1, one with energy 91: the worst 10%
        // hold 91% of the total 100.
        let mut residuals: Vec<_> = (0..9).map(|m| residual(m, 1.0)).collect();
        residuals.push(residual(9, 91f64.sqrt()));
        let curve = residual_concentration(&residuals);
        assert!((energy_share_of_worst(&curve, 0.1) - 0.91).abs() < 1e-12);
        assert!((energy_share_of_worst(&curve, 0.05) - 0.455).abs() < 1e-12);
        assert_eq!(curve.last(), Some(&(1.0, 1.0)));
    }

    #[test]
    fn frames_of_one_marker_add_up() {
        let residuals = vec![residual(3, 1.0), residual(3, 1.0), residual(4, 2f64.sqrt())];
        let curve = residual_concentration(&residuals);
        let expected = [(0.0, 0.0), (0.5, 0.5), (1.0, 1.0)];
        assert_eq!(curve.len(), expected.len());
        for (got, want) in curve.iter().zip(expected) {
            assert!((got.0 - want.0).abs() < 1e-12 && (got.1 - want.1).abs() < 1e-12);
        }
        assert!(residual_concentration(&[]).is_empty());
    }
}
