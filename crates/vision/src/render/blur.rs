//! The defocus blur of a dot's patch: a separable sampled Gaussian.

/// Normalised, truncated (at 5 sigma) sampled Gaussian kernel.
pub(super) fn gaussian_kernel(sigma: f64) -> Vec<f64> {
    if sigma <= 0.0 {
        return vec![1.0];
    }
    let half = (5.0 * sigma).ceil() as i64;
    let weights: Vec<f64> = (-half..=half)
        .map(|i| (-0.5 * (i as f64 / sigma).powi(2)).exp())
        .collect();
    let total: f64 = weights.iter().sum();
    weights.into_iter().map(|w| w / total).collect()
}

/// Separable convolution of a row-major rectangle with zero outside it.
///
/// Each output is summed over the kernel in order from its first tap, as a
/// direct gather would; taps falling outside the rectangle meet padded zeros
/// or are left out, which adds exactly nothing, so the loops can run over
/// whole rows without bounds tests.
pub(super) fn blur(values: &[f64], width: usize, height: usize, kernel: &[f64]) -> Vec<f64> {
    let half = kernel.len() / 2;
    let mut line = vec![0.0; width + 2 * half];
    let mut rows = vec![0.0; values.len()];
    for (input, output) in values.chunks_exact(width).zip(rows.chunks_exact_mut(width)) {
        if input.iter().all(|&v| v == 0.0) {
            continue;
        }
        line[half..half + width].copy_from_slice(input);
        for (k, w) in kernel.iter().enumerate() {
            for (o, v) in output.iter_mut().zip(&line[k..k + width]) {
                *o += w * v;
            }
        }
    }
    let mut out = vec![0.0; values.len()];
    for (r, output) in out.chunks_exact_mut(width).enumerate() {
        for (k, w) in kernel.iter().enumerate() {
            let Some(source) = (r + k).checked_sub(half).filter(|&s| s < height) else {
                continue;
            };
            for (o, v) in output
                .iter_mut()
                .zip(&rows[source * width..(source + 1) * width])
            {
                *o += w * v;
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The separable convolution by a direct gather per output, skipping
    /// taps outside the rectangle.
    fn gathered(values: &[f64], width: usize, height: usize, kernel: &[f64]) -> Vec<f64> {
        let half = (kernel.len() / 2) as i64;
        let tap = |k: usize, at: usize, len: usize| {
            let i = at as i64 + k as i64 - half;
            (0..len as i64).contains(&i).then_some(i as usize)
        };
        let mut rows = vec![0.0; values.len()];
        for r in 0..height {
            for c in 0..width {
                let mut sum = 0.0;
                for (k, w) in kernel.iter().enumerate() {
                    if let Some(cc) = tap(k, c, width) {
                        sum += w * values[r * width + cc];
                    }
                }
                rows[r * width + c] = sum;
            }
        }
        let mut out = vec![0.0; values.len()];
        for r in 0..height {
            for c in 0..width {
                let mut sum = 0.0;
                for (k, w) in kernel.iter().enumerate() {
                    if let Some(rr) = tap(k, r, height) {
                        sum += w * rows[rr * width + c];
                    }
                }
                out[r * width + c] = sum;
            }
        }
        out
    }

    #[test]
    fn row_sweeps_equal_the_direct_gather_bit_for_bit() {
        let (width, height) = (23, 17);
        // A dot-like blob touching the left and bottom edges, zero rows on top.
        let values: Vec<f64> = (0..width * height)
            .map(|i| {
                let (c, r) = ((i % width) as f64, (i / width) as f64);
                let d = ((c - 3.3).powi(2) + (r - 14.2).powi(2)).sqrt();
                (7.7 - d).clamp(0.0, 1.0)
            })
            .collect();
        for sigma in [0.0, 0.7, 1.0, 2.5] {
            let kernel = gaussian_kernel(sigma);
            assert_eq!(
                blur(&values, width, height, &kernel),
                gathered(&values, width, height, &kernel),
                "sigma {sigma}"
            );
        }
    }
}
