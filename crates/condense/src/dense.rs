//! Column-major dense storage with spare capacity, so that working nodes can be
//! added and removed without reallocating, and every column is one contiguous
//! slice (the O(N^2) updates are memory-bandwidth bound: they stream columns).

use faer::linalg::matmul::dot::inner_prod;
use faer::linalg::matmul::matmul;
use faer::{Accum, ColRef, Conj, MatMut, MatRef, Par, RowRef};

/// A `rows x cols` column-major matrix stored with column stride `stride >= rows`
/// and room for `col_capacity >= cols` columns.
#[derive(Debug, Clone, Default)]
pub(crate) struct Dense {
    data: Vec<f64>,
    rows: usize,
    cols: usize,
    stride: usize,
    col_capacity: usize,
}

impl Dense {
    /// A zero matrix of the given shape with at least the given capacities.
    pub(crate) fn zeros(
        rows: usize,
        cols: usize,
        row_capacity: usize,
        col_capacity: usize,
    ) -> Self {
        let stride = row_capacity.max(rows);
        let col_capacity = col_capacity.max(cols);
        Self {
            data: vec![0.0; stride * col_capacity],
            rows,
            cols,
            stride,
            col_capacity,
        }
    }

    pub(crate) fn cols(&self) -> usize {
        self.cols
    }

    pub(crate) fn col(&self, j: usize) -> &[f64] {
        let start = j * self.stride;
        &self.data[start..start + self.rows]
    }

    pub(crate) fn col_mut(&mut self, j: usize) -> &mut [f64] {
        let start = j * self.stride;
        &mut self.data[start..start + self.rows]
    }

    pub(crate) fn get(&self, i: usize, j: usize) -> f64 {
        self.data[j * self.stride + i]
    }

    pub(crate) fn set(&mut self, i: usize, j: usize, value: f64) {
        self.data[j * self.stride + i] = value;
    }

    /// Makes room for `rows x cols` without changing the visible matrix.
    pub(crate) fn reserve(&mut self, rows: usize, cols: usize) {
        if rows > self.stride || cols > self.col_capacity {
            let (visible_rows, visible_cols) = (self.rows, self.cols);
            let mut grown = Self::zeros(
                visible_rows,
                visible_cols,
                rows.max(self.stride),
                cols.max(self.col_capacity),
            );
            for j in 0..visible_cols {
                grown.col_mut(j).copy_from_slice(self.col(j));
            }
            *self = grown;
        }
    }

    /// Grows (or shrinks) to `rows x cols`; kept entries keep their values, new
    /// entries are zero. Capacity grows by a quarter when exceeded, so growth
    /// is amortised without doubling a large matrix.
    pub(crate) fn resize(&mut self, rows: usize, cols: usize) {
        if rows > self.stride || cols > self.col_capacity {
            let stride = if rows > self.stride {
                rows.max(grown(self.stride))
            } else {
                self.stride
            };
            let col_capacity = if cols > self.col_capacity {
                cols.max(grown(self.col_capacity))
            } else {
                self.col_capacity
            };
            let mut data = vec![0.0; stride * col_capacity];
            for j in 0..self.cols.min(cols) {
                let keep = self.rows.min(rows);
                data[j * stride..j * stride + keep].copy_from_slice(&self.col(j)[..keep]);
            }
            *self = Self {
                data,
                rows,
                cols,
                stride,
                col_capacity,
            };
            return;
        }
        // Zero what becomes visible, so stale values from earlier removals never leak in.
        if rows > self.rows {
            for j in 0..self.cols.min(cols) {
                let start = j * self.stride;
                self.data[start + self.rows..start + rows].fill(0.0);
            }
        }
        for j in self.cols..cols {
            let start = j * self.stride;
            self.data[start..start + rows].fill(0.0);
        }
        self.rows = rows;
        self.cols = cols;
    }

    /// Copies row `from` onto row `to` (all columns).
    pub(crate) fn copy_row(&mut self, from: usize, to: usize) {
        for j in 0..self.cols {
            let start = j * self.stride;
            self.data[start + to] = self.data[start + from];
        }
    }

    /// Copies column `from` onto column `to`.
    pub(crate) fn copy_col(&mut self, from: usize, to: usize) {
        let (rows, stride) = (self.rows, self.stride);
        self.data
            .copy_within(from * stride..from * stride + rows, to * stride);
    }

    pub(crate) fn as_ref(&self) -> MatRef<'_, f64> {
        MatRef::from_column_major_slice_with_stride(
            &self.data[..self.span()],
            self.rows,
            self.cols,
            self.stride,
        )
    }

    pub(crate) fn as_mut(&mut self) -> MatMut<'_, f64> {
        let span = self.span();
        MatMut::from_column_major_slice_with_stride_mut(
            &mut self.data[..span],
            self.rows,
            self.cols,
            self.stride,
        )
    }

    /// `self += column row^T` in one streaming pass (faer's SIMD kernel: the
    /// update is memory-bandwidth bound, one read and one write per entry).
    pub(crate) fn add_outer(&mut self, column: &[f64], row: &[f64]) {
        matmul(
            self.as_mut(),
            Accum::Add,
            ColRef::from_slice(column).as_mat(),
            RowRef::from_slice(row).as_mat(),
            1.0,
            Par::Seq,
        );
    }

    /// Length of the storage prefix that holds the visible matrix.
    fn span(&self) -> usize {
        if self.cols == 0 {
            0
        } else {
            (self.cols - 1) * self.stride + self.rows
        }
    }
}

/// Next capacity when growing: a quarter more (and a few slots for small matrices).
fn grown(capacity: usize) -> usize {
    capacity + capacity / 4 + 16
}

/// Dot product through faer's SIMD kernel, which picks AVX2/FMA or AVX-512
/// at run time (the crate is built for baseline x86-64, where a plain loop
/// would get SSE2 without FMA).
pub(crate) fn dot(a: &[f64], b: &[f64]) -> f64 {
    inner_prod(
        RowRef::from_slice(a),
        Conj::No,
        ColRef::from_slice(b),
        Conj::No,
    )
}
