//! Quantiles of the normal and one-degree-of-freedom chi-square laws, for
//! confidence intervals.

use crate::error::LsqError;

/// The standard normal quantile `z` with `Φ(z) = probability`, by Acklam's
/// rational approximation (relative error below `1.2e-9`).
pub fn normal_quantile(probability: f64) -> Result<f64, LsqError> {
    if !(probability > 0.0 && probability < 1.0) {
        return Err(LsqError::InvalidOption {
            field: "probability",
            reason: format!("{probability} is not in (0, 1)"),
        });
    }
    const A: [f64; 6] = [
        -3.969_683_028_665_376e1,
        2.209_460_984_245_205e2,
        -2.759_285_104_469_687e2,
        1.383_577_518_672_69e2,
        -3.066_479_806_614_716e1,
        2.506_628_277_459_239,
    ];
    const B: [f64; 5] = [
        -5.447_609_879_822_406e1,
        1.615_858_368_580_409e2,
        -1.556_989_798_598_866e2,
        6.680_131_188_771_972e1,
        -1.328_068_155_288_572e1,
    ];
    const C: [f64; 6] = [
        -7.784_894_002_430_293e-3,
        -3.223_964_580_411_365e-1,
        -2.400_758_277_161_838,
        -2.549_732_539_343_734,
        4.374_664_141_464_968,
        2.938_163_982_698_783,
    ];
    const D: [f64; 4] = [
        7.784_695_709_041_462e-3,
        3.224_671_290_700_398e-1,
        2.445_134_137_142_996,
        3.754_408_661_907_416,
    ];
    const LOW: f64 = 0.024_25;
    let tail = |q: f64| {
        let t = (-2.0 * q.ln()).sqrt();
        (((((C[0] * t + C[1]) * t + C[2]) * t + C[3]) * t + C[4]) * t + C[5])
            / ((((D[0] * t + D[1]) * t + D[2]) * t + D[3]) * t + 1.0)
    };
    let z = if probability < LOW {
        tail(probability)
    } else if probability > 1.0 - LOW {
        -tail(1.0 - probability)
    } else {
        let q = probability - 0.5;
        let t = q * q;
        (((((A[0] * t + A[1]) * t + A[2]) * t + A[3]) * t + A[4]) * t + A[5]) * q
            / (((((B[0] * t + B[1]) * t + B[2]) * t + B[3]) * t + B[4]) * t + 1.0)
    };
    Ok(z)
}

/// The two-sided normal multiplier for a confidence `level`: `z` with
/// `P(|Z| <= z) = level` (1.95996 for 0.95).
pub fn two_sided_normal(level: f64) -> Result<f64, LsqError> {
    if !(level > 0.0 && level < 1.0) {
        return Err(LsqError::InvalidOption {
            field: "level",
            reason: format!("confidence level {level} is not in (0, 1)"),
        });
    }
    normal_quantile(0.5 * (1.0 + level))
}

/// The chi-square (1 degree of freedom) quantile at `level`, i.e. the
/// likelihood-ratio threshold `Δχ²` of a profile interval (3.8415 for 0.95).
pub fn chi_square_one_dof(level: f64) -> Result<f64, LsqError> {
    two_sided_normal(level).map(|z| z * z)
}
