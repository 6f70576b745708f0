//! Exact Euclidean distance transform of an occupancy grid.
//!
//! Felzenszwalb & Huttenlocher, "Distance Transforms of Sampled Functions", Theory of
//! Computing 8 (2012): the squared distance to the nearest feature cell is computed by two
//! passes of the 1-D lower-envelope-of-parabolas algorithm, columns then rows, in O(cells).
//! Distances are between cell centres, in cells; multiply by the resolution for metres.
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
    let (rows, cols) = (grid.rows + 2, grid.cols + 2);
    let mut padded = vec![true; rows * cols];
    for r in 0..grid.rows {
        let from = r * grid.cols;
        padded[(r + 1) * cols + 1..(r + 1) * cols + 1 + grid.cols]
            .copy_from_slice(&grid.cells[from..from + grid.cols]);
    }
    let d2 = squared_distance_to(&padded, rows, cols);
    (0..grid.rows)
        .flat_map(|r| {
            d2[(r + 1) * cols + 1..(r + 1) * cols + 1 + grid.cols]
                .iter()
                .copied()
        })
        .collect()
}

/// Squared distance, in cells², from every cell to the nearest cell where `feature` is true;
/// `f64::INFINITY` everywhere when there is no feature cell.
///
/// Lines are independent within a pass, so each pass runs them in parallel; every line's
/// result is the same whichever thread computes it.
pub fn squared_distance_to(feature: &[bool], rows: usize, cols: usize) -> Vec<f64> {
    // Pass 1, along each column, on the transpose so that a column is a contiguous line. The
    // input holds only 0 and ∞, so the lower envelope is the nearest feature cell above or
    // below: two sweeps give the same squares without the parabolas' divisions.
    let mut by_column = vec![0.0; rows * cols];
    by_column
        .par_chunks_mut(rows.max(1))
        .enumerate()
        .for_each(|(c, line)| {
            let mut above = None;
            for (r, out) in line.iter_mut().enumerate() {
                if feature[r * cols + c] {
                    above = Some(r);
                }
                *out = above.map_or(f64::INFINITY, |p| (r - p) as f64);
            }
            let mut below = None;
            for (r, out) in line.iter_mut().enumerate().rev() {
                if feature[r * cols + c] {
                    below = Some(r);
                }
                if let Some(p) = below {
                    *out = out.min((p - r) as f64);
                }
                *out *= *out;
            }
        });
    // Pass 2, along each row, on the column result.
    let mut d = vec![0.0; rows * cols];
    d.par_chunks_mut(cols.max(1)).enumerate().for_each_init(
        || Envelope::new(cols),
        |envelope, (r, line)| {
            for (c, out) in line.iter_mut().enumerate() {
                *out = by_column[c * rows + r];
            }
            envelope.transform(line);
        },
    );
    d
}

/// Work buffers of the 1-D transform, reused across lines.
struct Envelope {
    /// Positions of the parabolas in the lower envelope.
    v: Vec<usize>,
    /// Boundaries between consecutive parabolas.
    z: Vec<f64>,
    /// Copy of the input line.
    f: Vec<f64>,
}

impl Envelope {
    fn new(n: usize) -> Self {
        Self {
            v: vec![0; n],
            z: vec![0.0; n + 1],
            f: vec![0.0; n],
        }
    }

    /// In place: `line[q] = min_p (q − p)² + line[p]`.
    fn transform(&mut self, line: &mut [f64]) {
        let n = line.len();
        self.f[..n].copy_from_slice(line);
        let f = &self.f;
        // Skip the envelope while the line has no finite value: INF − INF would be NaN.
        let Some(first) = f[..n].iter().position(|x| x.is_finite()) else {
            return;
        };
        let (v, z) = (&mut self.v, &mut self.z);
        let mut k = 0usize;
        v[0] = first;
        z[0] = f64::NEG_INFINITY;
        z[1] = f64::INFINITY;
        for q in first + 1..n {
            if !f[q].is_finite() {
                continue;
            }
            let mut s = intersection(f, q, v[k]);
            while s <= z[k] {
                k -= 1;
                s = intersection(f, q, v[k]);
            }
            k += 1;
            v[k] = q;
            z[k] = s;
            z[k + 1] = f64::INFINITY;
        }
        k = 0;
        for (q, out) in line.iter_mut().enumerate() {
            let qf = q as f64;
            while z[k + 1] < qf {
                k += 1;
            }
            let p = v[k] as f64;
            *out = (qf - p) * (qf - p) + f[v[k]];
        }
    }
}

/// Where the parabolas rooted at `q` and `p` intersect.
#[inline]
fn intersection(f: &[f64], q: usize, p: usize) -> f64 {
    let (qf, pf) = (q as f64, p as f64);
    ((f[q] + qf * qf) - (f[p] + pf * pf)) / (2.0 * qf - 2.0 * pf)
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

    proptest! {
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
