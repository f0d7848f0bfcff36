//! Cubic B-spline interpolation of image patches.
//!
//! The interpolant is $f(x, y) = \sum_{k,l} c_{kl}\,\beta^3(x - k)\,\beta^3(y - l)$
//! with $\beta^3$ the cubic B-spline; the coefficients $c$ make $f$ pass
//! through the samples and are found by the recursive prefilter of Unser
//! (pole $z_1 = \sqrt 3 - 2$, mirror boundaries). It reproduces cubic
//! polynomials and, unlike cubic convolution, has no resampling ripple at the
//! frequencies a blurred dot contains, so subpixel estimates show no
//! quantisation and little bias.

/// Pole of the cubic B-spline prefilter.
const POLE: f64 = -0.267_949_192_431_122_7; // sqrt(3) - 2

/// Cubic B-spline weights of the four nodes `floor(x) - 1 ..= floor(x) + 2`
/// for fractional part `t`.
pub(crate) fn weights(t: f64) -> [f64; 4] {
    let s = 1.0 - t;
    let t2 = t * t;
    let t3 = t2 * t;
    [
        s * s * s / 6.0,
        (3.0 * t3 - 6.0 * t2 + 4.0) / 6.0,
        (-3.0 * t3 + 3.0 * t2 + 3.0 * t + 1.0) / 6.0,
        t3 / 6.0,
    ]
}

/// Derivatives of [`weights`] with respect to `t`.
pub(crate) fn derivative_weights(t: f64) -> [f64; 4] {
    let s = 1.0 - t;
    [
        -0.5 * s * s,
        (3.0 * t * t - 4.0 * t) / 2.0,
        (-3.0 * t * t + 2.0 * t + 1.0) / 2.0,
        0.5 * t * t,
    ]
}

/// In-place prefilter along the columns of a row-major `width` x `height`
/// array: every step updates a whole row, so the recursion vectorises
/// across columns.
fn prefilter_columns(data: &mut [f64], width: usize, height: usize) {
    if height < 2 {
        return;
    }
    // Causal initialisation: mirror-boundary sum truncated where z^k < 1e-12.
    let mut first = vec![0.0; width];
    let mut zk = 1.0;
    for k in 0..height.min(22) {
        for (a, b) in first.iter_mut().zip(&data[k * width..(k + 1) * width]) {
            *a += zk * b;
        }
        zk *= POLE;
    }
    data[..width].copy_from_slice(&first);
    for r in 1..height {
        let (done, rest) = data.split_at_mut(r * width);
        for (c, p) in rest[..width].iter_mut().zip(&done[(r - 1) * width..]) {
            *c += POLE * p;
        }
    }
    let (before, last) = data.split_at_mut((height - 1) * width);
    let factor = POLE / (POLE * POLE - 1.0);
    for (l, b) in last.iter_mut().zip(&before[(height - 2) * width..]) {
        *l = factor * (*l + POLE * b);
    }
    for r in (0..height - 1).rev() {
        let (head, next) = data.split_at_mut((r + 1) * width);
        for (c, n) in head[r * width..].iter_mut().zip(&next[..width]) {
            *c = POLE * (n - *c);
        }
    }
    for v in data.iter_mut() {
        *v *= 6.0;
    }
}

fn transpose(data: &[f64], width: usize, height: usize) -> Vec<f64> {
    let mut out = vec![0.0; data.len()];
    for r in 0..height {
        for c in 0..width {
            out[c * height + r] = data[r * width + c];
        }
    }
    out
}

/// B-spline coefficients of a row-major patch.
#[derive(Debug, Clone)]
pub(crate) struct SplinePatch {
    pub width: usize,
    pub coefficients: Vec<f64>,
}

impl SplinePatch {
    /// Coefficients interpolating `samples` (`width` x `height`, row-major).
    pub fn new(samples: Vec<f64>, width: usize, height: usize) -> SplinePatch {
        let mut c = samples;
        prefilter_columns(&mut c, width, height);
        let mut t = transpose(&c, width, height);
        prefilter_columns(&mut t, height, width);
        SplinePatch {
            width,
            coefficients: transpose(&t, height, width),
        }
    }

    /// Value and gradient at `(x, y)` in patch pixel coordinates; the caller
    /// keeps `1 <= x < width - 2` and likewise for `y`.
    pub fn sample_with_gradient(&self, x: f64, y: f64) -> (f64, f64, f64) {
        let (fx, fy) = (x.floor(), y.floor());
        let (wx, wy) = (weights(x - fx), weights(y - fy));
        let (dx, dy) = (derivative_weights(x - fx), derivative_weights(y - fy));
        let (c0, r0) = (fx as usize - 1, fy as usize - 1);
        let (mut v, mut gx, mut gy) = (0.0, 0.0, 0.0);
        for j in 0..4 {
            let row = &self.coefficients[(r0 + j) * self.width + c0..][..4];
            let (mut a, mut b) = (0.0, 0.0);
            for i in 0..4 {
                a += wx[i] * row[i];
                b += dx[i] * row[i];
            }
            v += wy[j] * a;
            gx += wy[j] * b;
            gy += dy[j] * a;
        }
        (v, gx, gy)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn samples() -> (Vec<f64>, usize, usize) {
        let (w, h) = (23, 19);
        let values = (0..w * h)
            .map(|i| ((i % w) as f64 * 0.7).sin() * 50.0 + ((i / w) as f64 * 0.45).cos() * 30.0)
            .collect();
        (values, w, h)
    }

    #[test]
    fn the_spline_passes_through_its_samples() {
        let (values, w, h) = samples();
        let spline = SplinePatch::new(values.clone(), w, h);
        for y in 1..h - 2 {
            for x in 1..w - 2 {
                let (v, _, _) = spline.sample_with_gradient(x as f64, y as f64);
                assert!((v - values[y * w + x]).abs() < 1e-9);
            }
        }
    }

    #[test]
    fn the_gradient_agrees_with_differences_of_the_values() {
        let (values, w, h) = samples();
        let spline = SplinePatch::new(values, w, h);
        for j in 0..7 {
            for i in 0..9 {
                let (x, y) = (3.37 + i as f64, 2.81 + j as f64);
                let (_, gx, gy) = spline.sample_with_gradient(x, y);
                let e = 1e-6;
                let dx = (spline.sample_with_gradient(x + e, y).0
                    - spline.sample_with_gradient(x - e, y).0)
                    / (2.0 * e);
                let dy = (spline.sample_with_gradient(x, y + e).0
                    - spline.sample_with_gradient(x, y - e).0)
                    / (2.0 * e);
                assert!((gx - dx).abs() < 1e-6 && (gy - dy).abs() < 1e-6);
            }
        }
    }
}
