//! Which grid cells a straight segment passes through.
//!
//! Amanatides & Woo, "A Fast Voxel Traversal Algorithm for Ray Tracing", Eurographics 1987:
//! step from cell to cell across whichever grid line the segment meets first. Where it passes
//! exactly through a cell corner both side cells are visited too (a supercover), so a segment
//! that is "clear" never squeezes between two diagonal obstacles.

/// The point of the segment `a`–`b` nearest `p` (`a` when the segment is a point).
pub fn nearest_point(p: (f64, f64), a: (f64, f64), b: (f64, f64)) -> (f64, f64) {
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let len2 = dx * dx + dy * dy;
    let t = if len2 > 0.0 {
        (((p.0 - a.0) * dx + (p.1 - a.1) * dy) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (a.0 + t * dx, a.1 + t * dy)
}

/// Visit every cell (column, row) that the segment from `a` to `b` touches; coordinates are in
/// cells: u along columns, v along rows (downward). Stops early and returns false when `visit`
/// does.
pub fn for_each_cell(
    a: (f64, f64),
    b: (f64, f64),
    mut visit: impl FnMut(i64, i64) -> bool,
) -> bool {
    let (mut cu, mut cv) = (a.0.floor() as i64, a.1.floor() as i64);
    let (eu, ev) = (b.0.floor() as i64, b.1.floor() as i64);
    let (du, dv) = (b.0 - a.0, b.1 - a.1);
    let step_u: i64 = if du > 0.0 { 1 } else { -1 };
    let step_v: i64 = if dv > 0.0 { 1 } else { -1 };
    let delta_u = if du != 0.0 {
        (1.0 / du).abs()
    } else {
        f64::INFINITY
    };
    let delta_v = if dv != 0.0 {
        (1.0 / dv).abs()
    } else {
        f64::INFINITY
    };
    let next_boundary = |p: f64, cell: i64, step: i64| {
        if step > 0 {
            (cell + 1) as f64 - p
        } else {
            p - cell as f64
        }
    };
    let mut t_u = if du != 0.0 {
        next_boundary(a.0, cu, step_u) * delta_u
    } else {
        f64::INFINITY
    };
    let mut t_v = if dv != 0.0 {
        next_boundary(a.1, cv, step_v) * delta_v
    } else {
        f64::INFINITY
    };
    if !visit(cu, cv) {
        return false;
    }
    let cells = (eu - cu).abs() + (ev - cv).abs();
    for _ in 0..cells {
        if t_u < t_v {
            cu += step_u;
            t_u += delta_u;
        } else if t_v < t_u {
            cv += step_v;
            t_v += delta_v;
        } else {
            // Through a corner: the two side cells are touched too.
            if !visit(cu + step_u, cv) || !visit(cu, cv + step_v) {
                return false;
            }
            cu += step_u;
            cv += step_v;
            t_u += delta_u;
            t_v += delta_v;
        }
        if !visit(cu, cv) {
            return false;
        }
        if cu == eu && cv == ev {
            break;
        }
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cells(a: (f64, f64), b: (f64, f64)) -> Vec<(i64, i64)> {
        let mut out = Vec::new();
        for_each_cell(a, b, |u, v| {
            out.push((u, v));
            true
        });
        out
    }

    #[test]
    fn a_horizontal_segment_visits_its_row() {
        assert_eq!(
            cells((0.5, 0.5), (3.5, 0.5)),
            vec![(0, 0), (1, 0), (2, 0), (3, 0)]
        );
    }

    #[test]
    fn a_corner_crossing_visits_both_sides() {
        let c = cells((0.5, 0.5), (1.5, 1.5));
        assert_eq!(c, vec![(0, 0), (1, 0), (0, 1), (1, 1)]);
    }

    #[test]
    fn a_shallow_diagonal_visits_a_connected_strip() {
        let c = cells((0.2, 0.3), (5.7, 2.9));
        assert_eq!(c.first(), Some(&(0, 0)));
        assert_eq!(c.last(), Some(&(5, 2)));
        for w in c.windows(2) {
            assert_eq!((w[0].0 - w[1].0).abs() + (w[0].1 - w[1].1).abs(), 1);
        }
    }
}
