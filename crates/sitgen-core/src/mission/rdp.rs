//! Ramer–Douglas–Peucker polyline simplification.
//!
//! U. Ramer, "An iterative procedure for the polygonal approximation of plane curves", CGIP 1
//! (1972); D. Douglas & T. Peucker, *Cartographica* 10(2), 1973. Keep the two ends; find the
//! point farthest from the chord between them; if it is farther than ε, keep it and simplify
//! both halves, else drop everything between the ends.
//!
//! Rules (they decide the output on edge cases, and match simplify-js's high-quality mode,
//! checked against its outputs in the tests):
//! - distance is to the chord *segment* (not the infinite line), so a point beyond an end of
//!   the chord counts by its distance to that end;
//! - distances are compared squared, so equal distances tie exactly;
//! - among equally far points the *first* wins;
//! - a point is kept when its squared distance is strictly greater than ε²; so ε = 0 drops
//!   exactly the points that lie on their chord, and a negative ε acts as |ε|.

/// Indices of the points RDP keeps, in order; fewer than 3 points are all kept.
pub fn simplify_indices(points: &[(f64, f64)], epsilon: f64) -> Vec<usize> {
    let n = points.len();
    if n < 3 {
        return (0..n).collect();
    }
    let eps2 = epsilon * epsilon;
    let mut keep = vec![false; n];
    keep[0] = true;
    keep[n - 1] = true;
    // Explicit stack of chords (first, last): no recursion depth limit on long routes.
    let mut chords = vec![(0, n - 1)];
    while let Some((first, last)) = chords.pop() {
        let mut farthest = None;
        let mut max_d2 = eps2;
        for i in first + 1..last {
            let d2 = squared_segment_distance(points[i], points[first], points[last]);
            if d2 > max_d2 {
                max_d2 = d2;
                farthest = Some(i);
            }
        }
        if let Some(i) = farthest {
            keep[i] = true;
            chords.push((i, last));
            chords.push((first, i));
        }
    }
    (0..n).filter(|&i| keep[i]).collect()
}

/// The points RDP keeps.
pub fn simplify(points: &[(f64, f64)], epsilon: f64) -> Vec<(f64, f64)> {
    simplify_indices(points, epsilon)
        .into_iter()
        .map(|i| points[i])
        .collect()
}

/// Squared distance from `p` to the segment `a`–`b` (to `a` when they coincide), computed as
/// simplify-js does, so that ties on integer inputs are exact.
fn squared_segment_distance(p: (f64, f64), a: (f64, f64), b: (f64, f64)) -> f64 {
    let (mut x, mut y) = a;
    let (dx, dy) = (b.0 - x, b.1 - y);
    if dx != 0.0 || dy != 0.0 {
        let t = ((p.0 - x) * dx + (p.1 - y) * dy) / (dx * dx + dy * dy);
        if t > 1.0 {
            x = b.0;
            y = b.1;
        } else if t > 0.0 {
            x += dx * t;
            y += dy * t;
        }
    }
    let (ex, ey) = (p.0 - x, p.1 - y);
    ex * ex + ey * ey
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn upstream_examples() {
        let line = [
            (0.0, 0.0),
            (5.0, 4.0),
            (11.0, 5.5),
            (17.3, 3.2),
            (27.8, 0.1),
        ];
        assert_eq!(simplify_indices(&line, 1.0), vec![0, 1, 2, 4]);
        assert_eq!(simplify_indices(&line, 30.0), vec![0, 4]);
        let l_shape = [(5.0, 0.0), (4.0, 0.0), (3.0, 0.0), (3.0, 1.0), (3.0, 2.0)];
        assert_eq!(
            simplify(&l_shape, 0.0),
            vec![(5.0, 0.0), (3.0, 0.0), (3.0, 2.0)]
        );
        assert_eq!(simplify_indices(&[(1.0, 1.0)], 1.0), vec![0]);
        assert!(simplify_indices(&[], 1.0).is_empty());
    }

    #[test]
    fn the_first_of_equally_far_points_wins() {
        let tie = [(0.0, 0.0), (1.0, 2.0), (3.0, 2.0), (4.0, 0.0)];
        assert_eq!(simplify_indices(&tie, 1.5), vec![0, 1, 3]);
    }
}
