//! Exact Euclidean distance transform of an occupancy grid.
//!
//! Felzenszwalb & Huttenlocher, "Distance Transforms of Sampled Functions", Theory of
//! Computing 8 (2012): the squared distance to the nearest feature cell is computed by two
//! passes, columns then rows, in O(cells). On a binary grid the column pass's lower envelope
//! of parabolas is the nearest feature above or below, found by two sweeps; the row pass is
//! the envelope, in whole numbers. Distances are between cell centres, in cells; multiply by
//! the resolution for metres.
//!
//! Written here rather than taken from an image library because it runs on the grid type
//! itself (no conversion of million-cell maps to image buffers and back), returns exact
//! `f64` squared distances, and is used by dilate/erode and by robot placement.

use rayon::prelude::*;

/// Squared distance, in cells², from every cell of `grid` to the nearest occupied cell or to
/// the ring of cells just outside the map: the world beyond a map's edge is a wall to the
/// simulator, so placement and planning treat it as one too. Maps with a border wall get the
/// same distances as from [`squared_distance_to`].
pub fn squared_distance_with_edge(grid: &super::OccupancyGrid) -> Vec<f64> {
    with_edge(
        &squared_distance_to(&grid.cells, grid.rows, grid.cols),
        grid.rows,
        grid.cols,
    )
}

/// [`squared_distance_with_edge`] from [`squared_distance_to`]'s result for the occupied cells
/// of the same `rows` × `cols` grid: the ring's nearest cell to a cell lies straight out across
/// the nearest edge, so each square is the least of the distance to the nearest occupied cell
/// and four whole numbers. Generation has the occupied cells' squares anyway (the run needs
/// them), so the ring costs no second transform.
pub fn with_edge(to_occupied: &[f64], rows: usize, cols: usize) -> Vec<f64> {
    let square = |k: usize| (k * k) as f64;
    let across: Vec<f64> = (0..cols)
        .map(|c| square(c + 1).min(square(cols - c)))
        .collect();
    to_occupied
        .chunks_exact(cols.max(1))
        .enumerate()
        .flat_map(|(r, line)| {
            let up_down = square(r + 1).min(square(rows - r));
            line.iter()
                .zip(&across)
                .map(move |(&d2, &side)| d2.min(up_down).min(side))
        })
        .collect()
}

/// Squared distance, in cells², from every cell to the nearest cell where `feature` is true;
/// `f64::INFINITY` everywhere when there is no feature cell.
///
/// Rows are independent in the row pass, so it runs them in parallel; every row's result is
/// the same whichever thread computes it.
pub fn squared_distance_to(feature: &[bool], rows: usize, cols: usize) -> Vec<f64> {
    // Pass 1, along each column. The input holds only 0 and ∞, so the lower envelope is the
    // nearest feature cell above or below: a sweep down and a sweep up the rows give the same
    // squares without the parabolas, and both read and write whole rows (no transpose, no
    // strided reads).
    const NONE: u32 = u32::MAX;
    let mut above = vec![NONE; rows * cols];
    for r in 0..rows {
        let (done, rest) = above.split_at_mut(r * cols);
        let row = &mut rest[..cols];
        let prev = (r > 0).then(|| &done[(r - 1) * cols..]);
        for (c, out) in row.iter_mut().enumerate() {
            *out = if feature[r * cols + c] {
                0
            } else {
                prev.map_or(NONE, |p| p[c].saturating_add(1))
            };
        }
    }
    // The column pass's squares stay whole numbers for the row pass ([`FAR`] where a column
    // has no feature), so the row pass converts nothing on the way in.
    let mut column = vec![FAR; rows * cols];
    let mut below = vec![NONE; cols];
    for r in (0..rows).rev() {
        for (c, below) in below.iter_mut().enumerate() {
            let k = r * cols + c;
            *below = if feature[k] {
                0
            } else {
                below.saturating_add(1)
            };
            let nearest = above[k].min(*below);
            if nearest != NONE {
                column[k] = i64::from(nearest) * i64::from(nearest);
            }
        }
    }
    // Pass 2, along each row, on the column result.
    let mut d = vec![0.0; rows * cols];
    crate::parallel::install(|| {
        d.par_chunks_mut(cols.max(1))
            .zip(column.par_chunks(cols.max(1)))
            .for_each_init(
                || Envelope::new(cols),
                |envelope, (out, line)| envelope.transform(line, out),
            );
    });
    d
}

/// A column pass's result where the column has no feature cell.
const FAR: i64 = i64::MAX;

/// Work buffers of the 1-D transform, reused across lines.
///
/// Its input is the first pass's squared distances: whole numbers of cells² (or [`FAR`]). So
/// the parabolas' intersections are fractions of whole numbers, kept as (numerator,
/// denominator) and compared by cross-multiplication: exact, and without a division on the
/// chain of each cell (a float division per intersection was most of the transform's time).
struct Envelope {
    /// Positions of the parabolas in the lower envelope.
    v: Vec<usize>,
    /// Boundaries between consecutive parabolas: z[k] = num / den with den > 0, for k ≥ 1
    /// (z[0] is −∞ and the boundary after the last parabola +∞).
    z: Vec<(i64, i64)>,
}

impl Envelope {
    fn new(n: usize) -> Self {
        Self {
            v: vec![0; n],
            z: vec![(0, 1); n + 1],
        }
    }

    /// `out[q] = min_p (q − p)² + f[p]`, for a line `f` of whole numbers and [`FAR`]; ∞ where
    /// every entry is [`FAR`].
    fn transform(&mut self, f: &[i64], out: &mut [f64]) {
        let Some(first) = f.iter().position(|&x| x != FAR) else {
            out.fill(f64::INFINITY);
            return;
        };
        let (v, z) = (&mut self.v, &mut self.z);
        let mut k = 0usize;
        v[0] = first;
        for (q, &x) in f.iter().enumerate().skip(first + 1) {
            if x == FAR {
                continue;
            }
            // Pop the parabolas the new one hides: while the intersection s ≤ z[k] (k ≥ 1).
            let mut s = intersection(f, q, v[k]);
            while k > 0 && s.0 * z[k].1 <= z[k].0 * s.1 {
                k -= 1;
                s = intersection(f, q, v[k]);
            }
            k += 1;
            v[k] = q;
            z[k] = s;
        }
        let last = k;
        k = 0;
        for (q, out) in out.iter_mut().enumerate() {
            // Move on while z[k + 1] < q.
            while k < last && z[k + 1].0 < q as i64 * z[k + 1].1 {
                k += 1;
            }
            let d = q as i64 - v[k] as i64;
            // Cells² on any grid that fits in memory are far below 2⁵³: exact.
            *out = (d * d + f[v[k]]) as f64;
        }
    }
}

/// Where the parabolas rooted at `q` and `p < q` intersect, as (numerator, denominator > 0).
#[inline]
fn intersection(f: &[i64], q: usize, p: usize) -> (i64, i64) {
    let (qi, pi) = (q as i64, p as i64);
    ((f[q] + qi * qi) - (f[p] + pi * pi), 2 * (qi - pi))
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn brute_force(feature: &[bool], rows: usize, cols: usize) -> Vec<f64> {
        (0..rows * cols)
            .map(|i| {
                let (r, c) = ((i / cols) as f64, (i % cols) as f64);
                feature
                    .iter()
                    .enumerate()
                    .filter(|(_, &f)| f)
                    .map(|(j, _)| {
                        let (rj, cj) = ((j / cols) as f64, (j % cols) as f64);
                        (r - rj).powi(2) + (c - cj).powi(2)
                    })
                    .fold(f64::INFINITY, f64::min)
            })
            .collect()
    }

    /// The ring as feature cells of a grid two cells larger: what `squared_distance_with_edge`
    /// computed before [`with_edge`].
    fn padded_with_edge(cells: &[bool], rows: usize, cols: usize) -> Vec<f64> {
        let (prows, pcols) = (rows + 2, cols + 2);
        let mut padded = vec![true; prows * pcols];
        for r in 0..rows {
            padded[(r + 1) * pcols + 1..(r + 1) * pcols + 1 + cols]
                .copy_from_slice(&cells[r * cols..(r + 1) * cols]);
        }
        let d2 = squared_distance_to(&padded, prows, pcols);
        (0..rows)
            .flat_map(|r| d2[(r + 1) * pcols + 1..(r + 1) * pcols + 1 + cols].to_vec())
            .collect()
    }

    proptest! {
        #[test]
        fn the_edge_is_the_ring_of_cells_about_the_map(rows in 1usize..14, cols in 1usize..14, bits in prop::collection::vec(prop::bool::weighted(0.08), 196)) {
            let cells = bits[..rows * cols].to_vec();
            let grid = crate::grid::OccupancyGrid { rows, cols, cells: cells.clone() };
            prop_assert_eq!(squared_distance_with_edge(&grid), padded_with_edge(&cells, rows, cols));
        }

        #[test]
        fn matches_brute_force(rows in 1usize..12, cols in 1usize..12, bits in prop::collection::vec(prop::bool::weighted(0.15), 144)) {
            let feature = &bits[..rows * cols];
            prop_assert_eq!(squared_distance_to(feature, rows, cols), brute_force(feature, rows, cols));
        }
    }

    #[test]
    fn no_feature_gives_infinity() {
        assert!(squared_distance_to(&[false; 6], 2, 3)
            .iter()
            .all(|d| d.is_infinite()));
    }
}
