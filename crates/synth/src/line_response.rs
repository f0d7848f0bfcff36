//! The response of a linear phantom to loads on one needle line: columns of
//! $K^{-1}$, computed once per insertion, so that each iteration of the
//! needle-tip consistency loop costs a small dense product instead of a
//! back-substitution through the whole factor.
//!
//! The shaft load of a state is a sum of point forces along +y at material
//! points near the needle line (in the mid-plane of the slab), spread to
//! the nodes of their elements: $f = \sum_j f_j e_j$ over the y components
//! $j$ of the nodes of the elements around the line (in the slab, the nodes
//! on the mid-plane; the others get shape values of zero there, up to
//! round-off). The consistency loop reads the displacement only on those
//! elements (to move the material points) and, once a state is accepted,
//! at the markers. So with the columns $c_j = K^{-1} e_j$ kept on the rows
//! of the band's elements and as marker displacements,
//! $$u_{\text{band}} = \sum_j f_j\,(c_j)_{\text{band}},\qquad
//! u_{\text{markers}} = \sum_j f_j\,M c_j,$$
//! exactly the same numbers as a back-substitution of $f$ up to round-off.
//!
//! The columns are made as the loads ask for them: first those of the nodes
//! on the line, then, when a load reaches a node beside it, those of that
//! whole side of the line (the loaded points stay on one side for long
//! stretches), and when it reaches a node further out, those of that
//! node's whole line parallel to the needle; each set as one block of
//! right-hand sides, which streams the factor once for up to
//! [`COLUMN_BLOCK`] of them. The paper default's ten insertions make 1,642
//! columns (164 each on average; near the entry of the lines nearest the
//! slab's sides the points move a few millimetres sideways), against some
//! 215 back-substitutions of the whole load per insertion (4.3 per state)
//! when every iteration solved.
//!
//! The rows kept are those of the band of elements on the loaded plane
//! (for a needle of some radius, also those its rim reaches above it,
//! where the drag is read) within a margin of the line. Whether a state
//! stayed inside it is checked, never assumed: a load that reaches a dof
//! outside the band (beyond round-off) or a reading of the displacement
//! in an element outside it makes the caller fall back to a full
//! back-substitution (`needle.rs`).

use crate::error::SynthError;
use crate::world::{Response, World};

/// Columns solved per back-substitution while building the response: a
/// block this wide streams the factor once for all of them. On the paper
/// default the sets of columns asked for at once (the nodes on a line, a
/// side of it, a node line beside it) hold 35 to 74 columns; at 64, 18 of
/// its 28 sets took a second pass for their last 6 to 10. In one pass
/// each the campaign generates about 5% faster (CPU and wall, side by
/// side) with the same responses to the bit and the same peak resident
/// memory, 1.1 GB; 256 leaves room for the larger sets of finer meshes.
const COLUMN_BLOCK: usize = 256;

/// A load entry outside the columns is ignored when it is below this
/// fraction of the largest entry: shape values of nodes off the face a
/// point lies on, round-off of order 1e-16.
const ROUND_OFF_LOAD: f64 = 1e-12;

/// Kept columns of $K^{-1}$ for the loads of one needle line.
pub(crate) struct LineResponse {
    /// Whether each element lies in the band (its rows are kept).
    band: Vec<bool>,
    /// Column of each dof, `usize::MAX` for dofs without one.
    column_of: Vec<usize>,
    /// Whether a dof may get a column: the y component of a band node
    /// on the loaded plane.
    loadable: Vec<bool>,
    /// Side of the line (-1, 0 on it, +1) of each node of an element
    /// touching the line; `None` for the other nodes.
    side: Vec<Option<i8>>,
    /// The dofs of the band's elements: the rows kept.
    rows: Vec<usize>,
    /// `rows.len()` x columns, column-major.
    values: Vec<f64>,
    /// Marker displacements (x, y, z per marker) of each column,
    /// column-major.
    markers: Vec<f64>,
    /// Number of columns (back-substitutions done to build the response).
    pub columns: usize,
}

/// Why [`LineResponse::solve`] could not answer a load.
#[derive(Debug)]
pub(crate) enum Missing {
    /// The load reaches band dofs without a column yet: add them
    /// ([`LineResponse::add_columns`]) and solve again.
    Columns(Vec<usize>),
    /// The load reaches beyond the band: solve it in full.
    Band,
}

impl LineResponse {
    /// The response of the linear phantom `response` to loads on the line
    /// `x = line`, `0 <= y <= depth`: rows kept on the band of elements
    /// reaching `margin` beyond it, columns at first for the loadable dofs
    /// of the elements touching the line; `None` for a nonlinear response
    /// (no columns to keep).
    pub fn new(
        world: &World,
        response: &Response,
        line: f64,
        depth: f64,
        margin: f64,
    ) -> Result<Option<Self>, SynthError> {
        if !response.is_linear() {
            return Ok(None);
        }
        let body = &world.body;
        let dim = body.dim;
        let dofs = body.dof_count();
        let tolerance = 1e-9 * body.thickness;
        let touching = 1e-3 * body.element_size;
        // A needle of some radius reads its drag in the elements its rim
        // reaches above the mid-plane too (`needle.rs`, `Rim`).
        let radius = if dim == 3 {
            world.scenario.needles.radius
        } else {
            0.0
        };
        let mut band = vec![false; body.element_count()];
        let mut in_rows = vec![false; body.nodes.len()];
        let mut first = vec![false; body.nodes.len()];
        for (e, inside) in band.iter_mut().enumerate() {
            let nodes = body.element(e);
            let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
            for &n in nodes {
                for c in 0..3 {
                    lo[c] = lo[c].min(body.nodes[n][c]);
                    hi[c] = hi[c].max(body.nodes[n][c]);
                }
            }
            let near = |m: f64| lo[0] <= line + m && hi[0] >= line - m && lo[1] <= depth + m;
            let on_plane = dim == 2 || (lo[2] <= radius + tolerance && hi[2] >= -tolerance);
            *inside = on_plane && near(margin);
            if *inside {
                nodes.iter().for_each(|&n| in_rows[n] = true);
                if near(touching) {
                    nodes.iter().for_each(|&n| first[n] = true);
                }
            }
        }
        let on_plane = |n: usize| dim == 2 || body.nodes[n][2].abs() <= tolerance;
        let mut loadable = vec![false; dofs];
        for n in (0..body.nodes.len()).filter(|&n| in_rows[n] && on_plane(n)) {
            loadable[n * dim + 1] = true;
        }
        let rows: Vec<usize> = (0..body.nodes.len())
            .filter(|&n| in_rows[n])
            .flat_map(|n| (0..dim).map(move |c| n * dim + c))
            .collect();
        let side = (0..body.nodes.len())
            .map(|n| {
                first[n].then(|| {
                    let x = body.nodes[n][0] - line;
                    if x.abs() <= touching {
                        0
                    } else {
                        x.signum() as i8
                    }
                })
            })
            .collect();
        let mut response_of_line = Self {
            band,
            column_of: vec![usize::MAX; dofs],
            loadable,
            side,
            rows,
            values: Vec::new(),
            markers: Vec::new(),
            columns: 0,
        };
        // The nodes on the line carry load from the start.
        let on_line: Vec<usize> = (0..body.nodes.len())
            .filter(|&n| response_of_line.side[n] == Some(0))
            .map(|n| n * dim + 1)
            .filter(|&d| response_of_line.loadable[d])
            .collect();
        response_of_line.solve_columns(world, response, &on_line)?;
        Ok(Some(response_of_line))
    }

    /// Adds the columns a load found `missing`. The loaded points lie on
    /// one side of the line, or both, for long stretches: a missing dof of
    /// an element touching the line brings the whole side's, in one block.
    /// Points pushed further sideways (near the entry, on lines near the
    /// slab's sides) reach the next node lines parallel to the needle one
    /// depth after another as the tip advances: a missing dof there brings
    /// its whole node line. A back-substitution streams the factor once
    /// whatever its width, so a block of one column costs about as much as
    /// one of ten (on the paper default, one thread: 72 ms for one column,
    /// 140 ms for ten, 450 ms for 64), and the columns of a node line are
    /// cheaper together than as the few each state asks for.
    pub fn add_columns(
        &mut self,
        world: &World,
        response: &Response,
        missing: &[usize],
    ) -> Result<(), SynthError> {
        let body = &world.body;
        let dim = body.dim;
        let same_line = 1e-3 * body.element_size;
        let mut wanted = vec![false; self.column_of.len()];
        for &d in missing {
            wanted[d] = true;
            match self.side[d / dim] {
                Some(side) => {
                    for (n, s) in self.side.iter().enumerate() {
                        wanted[n * dim + 1] |= *s == Some(side);
                    }
                }
                None => {
                    let at = body.nodes[d / dim];
                    for (n, node) in body.nodes.iter().enumerate() {
                        wanted[n * dim + 1] |= (node[0] - at[0]).abs() <= same_line
                            && (node[2] - at[2]).abs() <= same_line;
                    }
                }
            }
        }
        let dofs: Vec<usize> = (0..wanted.len())
            .filter(|&d| wanted[d] && self.loadable[d] && self.column_of[d] == usize::MAX)
            .collect();
        self.solve_columns(world, response, &dofs)
    }

    /// Solves for unit loads on `dofs` (loadable, without a column yet)
    /// and keeps the results.
    fn solve_columns(
        &mut self,
        world: &World,
        response: &Response,
        dofs: &[usize],
    ) -> Result<(), SynthError> {
        let body = &world.body;
        for block in dofs.chunks(COLUMN_BLOCK) {
            let units: Vec<Vec<f64>> = block
                .iter()
                .map(|&d| {
                    let mut f = vec![0.0; body.dof_count()];
                    f[d] = 1.0;
                    f
                })
                .collect();
            for (&d, u) in block.iter().zip(response.solve(body, &units, &[])?) {
                debug_assert!(self.loadable[d] && self.column_of[d] == usize::MAX);
                self.column_of[d] = self.columns;
                self.columns += 1;
                self.values.extend(self.rows.iter().map(|&r| u[r]));
                self.markers
                    .extend(world.marker_displacements(&u).into_iter().flatten());
            }
        }
        Ok(())
    }

    /// Whether element `e` lies in the band (the field from
    /// [`LineResponse::solve`] is exact on it).
    pub fn covers(&self, element: usize) -> bool {
        self.band[element]
    }

    /// The displacement for the full-size load `f` (exact on the band's
    /// elements, zero elsewhere) and the marker displacements, or what is
    /// missing to answer it. Entries below round-off of the largest are
    /// ignored where there is no column.
    pub fn solve(&self, f: &[f64]) -> Result<(Vec<f64>, Vec<[f64; 3]>), Missing> {
        let largest = f.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let mut missing = Vec::new();
        for (d, &load) in f.iter().enumerate() {
            if self.column_of[d] == usize::MAX && load.abs() > ROUND_OFF_LOAD * largest {
                if !self.loadable[d] {
                    return Err(Missing::Band);
                }
                missing.push(d);
            }
        }
        if !missing.is_empty() {
            return Err(Missing::Columns(missing));
        }
        let marker_rows = self.markers.len() / self.columns.max(1);
        let mut u_rows = vec![0.0; self.rows.len()];
        let mut m = vec![0.0; marker_rows];
        for (d, &load) in f.iter().enumerate() {
            let k = self.column_of[d];
            if load == 0.0 || k == usize::MAX {
                continue;
            }

            let column = &self.values[k * self.rows.len()..(k + 1) * self.rows.len()];
            u_rows
                .iter_mut()
                .zip(column)
                .for_each(|(u, c)| *u += load * c);
            let column = &self.markers[k * marker_rows..(k + 1) * marker_rows];
            m.iter_mut().zip(column).for_each(|(u, c)| *u += load * c);
        }
        let mut u = vec![0.0; f.len()];
        for (&r, v) in self.rows.iter().zip(u_rows) {
            u[r] = v;
        }
        let markers = m.chunks(3).map(|c| [c[0], c[1], c[2]]).collect();
        Ok((u, markers))
    }
}
