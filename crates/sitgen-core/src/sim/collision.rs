//! Exact overlap tests between oriented rectangles and grid cells (separating axis theorem).
//!
//! Two convex shapes overlap exactly when no axis separates their projections; for rectangles
//! the candidate axes are their edge normals (Gottschalk, Lin & Manocha, "OBBTree", SIGGRAPH
//! 1996). Touching (projections meeting at a point) is not overlap, so robots may end a step
//! in contact with a wall or each other, never inside.

/// An oriented rectangle: centre, unit axes and half extents along them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rect {
    /// Centre (x, y), metres.
    pub centre: (f64, f64),
    /// Unit vector along the length (the robot's heading).
    pub u: (f64, f64),
    /// Half length along `u`.
    pub half_length: f64,
    /// Half width along the normal of `u`.
    pub half_width: f64,
}

impl Rect {
    /// Half the extent of the projection of the rectangle on unit axis `a`.
    #[inline]
    fn radius_on(&self, a: (f64, f64)) -> f64 {
        let (ux, uy) = self.u;
        self.half_length * (ux * a.0 + uy * a.1).abs()
            + self.half_width * (-uy * a.0 + ux * a.1).abs()
    }

    /// The two edge normals.
    #[inline]
    fn axes(&self) -> [(f64, f64); 2] {
        [self.u, (-self.u.1, self.u.0)]
    }

    /// Axis-aligned bounding box (x0, y0, x1, y1).
    pub fn bounds(&self) -> (f64, f64, f64, f64) {
        let rx = self.radius_on((1.0, 0.0));
        let ry = self.radius_on((0.0, 1.0));
        (
            self.centre.0 - rx,
            self.centre.1 - ry,
            self.centre.0 + rx,
            self.centre.1 + ry,
        )
    }

    /// Whether the interiors of two rectangles intersect.
    pub fn overlaps(&self, other: &Rect) -> bool {
        let d = (
            other.centre.0 - self.centre.0,
            other.centre.1 - self.centre.1,
        );
        self.axes()
            .into_iter()
            .chain(other.axes())
            .all(|a| (d.0 * a.0 + d.1 * a.1).abs() < self.radius_on(a) + other.radius_on(a))
    }

    /// The four corners, counter-clockwise.
    pub fn corners(&self) -> [(f64, f64); 4] {
        let (ux, uy) = self.u;
        let (lx, ly) = (ux * self.half_length, uy * self.half_length);
        let (wx, wy) = (-uy * self.half_width, ux * self.half_width);
        let (cx, cy) = self.centre;
        [
            (cx + lx - wx, cy + ly - wy),
            (cx + lx + wx, cy + ly + wy),
            (cx - lx + wx, cy - ly + wy),
            (cx - lx - wx, cy - ly - wy),
        ]
    }

    /// Clearance between two rectangles, metres: 0 when they touch or overlap. For disjoint
    /// convex polygons the nearest points include a vertex of one of them, so the smallest
    /// vertex-to-edge distance either way is exact.
    pub fn distance(&self, other: &Rect) -> f64 {
        if self.overlaps(other) {
            return 0.0;
        }
        let (a, b) = (self.corners(), other.corners());
        let mut best = f64::INFINITY;
        // The smallest of the 32 vertex-to-edge distances. A candidate's squared distance
        // settles most of them without libm's hypot: one whose square exceeds the best's by
        // more than the rounding of both cannot be nearer, so the least is the same bits.
        let mut beaten = f64::INFINITY;
        for (p, q) in [(&a, &b), (&b, &a)] {
            for &v in p {
                for k in 0..4 {
                    let n = crate::geometry::segment::nearest_point(v, q[k], q[(k + 1) % 4]);
                    let (dx, dy) = (v.0 - n.0, v.1 - n.1);
                    if dx * dx + dy * dy >= beaten {
                        continue;
                    }
                    let d = dx.hypot(dy);
                    if d < best {
                        best = d;
                        beaten = best * best * (1.0 + 1e-14);
                    }
                }
            }
        }
        best
    }

    /// Distance from point `p` to the rectangle, metres (0 inside).
    pub fn point_distance(&self, p: (f64, f64)) -> f64 {
        let (along, across) = self.point_offsets(p);
        along.hypot(across)
    }

    /// How far point `p` lies beyond the rectangle's edges along and across it, metres (0
    /// where it lies between them): [`Rect::point_distance`] is their `hypot`.
    pub fn point_offsets(&self, p: (f64, f64)) -> (f64, f64) {
        let d = (p.0 - self.centre.0, p.1 - self.centre.1);
        let along = (d.0 * self.u.0 + d.1 * self.u.1).abs() - self.half_length;
        let across = (d.1 * self.u.0 - d.0 * self.u.1).abs() - self.half_width;
        (along.max(0.0), across.max(0.0))
    }

    /// Whether the interior of the rectangle intersects the axis-aligned square with lower-left
    /// corner `(x0, y0)` and side `side`.
    pub fn overlaps_square(&self, x0: f64, y0: f64, side: f64) -> bool {
        let h = side / 2.0;
        let d = (x0 + h - self.centre.0, y0 + h - self.centre.1);
        let square_radius = |a: (f64, f64)| h * (a.0.abs() + a.1.abs());
        [(1.0, 0.0), (0.0, 1.0)]
            .into_iter()
            .chain(self.axes())
            .all(|a| (d.0 * a.0 + d.1 * a.1).abs() < self.radius_on(a) + square_radius(a))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The least of the 32 vertex-to-edge distances, every one by `hypot`.
    fn every_vertex_to_every_edge(a: &Rect, b: &Rect) -> f64 {
        if a.overlaps(b) {
            return 0.0;
        }
        let mut best = f64::INFINITY;
        for (p, q) in [(a.corners(), b.corners()), (b.corners(), a.corners())] {
            for v in p {
                for k in 0..4 {
                    let n = crate::geometry::segment::nearest_point(v, q[k], q[(k + 1) % 4]);
                    best = best.min((v.0 - n.0).hypot(v.1 - n.1));
                }
            }
        }
        best
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(4096))]
        #[test]
        fn clearance_is_the_least_vertex_to_edge_hypot(
            ha in -3.2f64..3.2, hb in -3.2f64..3.2, right_angle in proptest::bool::ANY,
            x in -2.5f64..2.5, y in -2.5f64..2.5,
            la in 0.05f64..0.6, wa in 0.05f64..0.4, lb in 0.05f64..0.6, wb in 0.05f64..0.4
        ) {
            // Parallel edges (equal distances from several pairs) as well as any angle.
            let hb = if right_angle { ha + std::f64::consts::FRAC_PI_2 } else { hb };
            let a = Rect { centre: (0.0, 0.0), u: (ha.cos(), ha.sin()), half_length: la, half_width: wa };
            let b = Rect { centre: (x, y), u: (hb.cos(), hb.sin()), half_length: lb, half_width: wb };
            proptest::prop_assert_eq!(a.distance(&b).to_bits(), every_vertex_to_every_edge(&a, &b).to_bits());
        }
    }

    fn rect(x: f64, y: f64, heading: f64) -> Rect {
        Rect {
            centre: (x, y),
            u: (heading.cos(), heading.sin()),
            half_length: 0.5,
            half_width: 0.25,
        }
    }

    #[test]
    fn touching_is_not_overlapping() {
        assert!(!rect(0.0, 0.0, 0.0).overlaps(&rect(1.0, 0.0, 0.0)));
        assert!(rect(0.0, 0.0, 0.0).overlaps(&rect(0.999, 0.0, 0.0)));
        assert!(!rect(0.0, 0.0, 0.0).overlaps_square(0.5, -0.1, 0.2));
        assert!(rect(0.0, 0.0, 0.0).overlaps_square(0.49, -0.1, 0.2));
    }

    #[test]
    fn rotated_rectangles_clear_a_corner_that_their_boxes_do_not() {
        let r = rect(0.0, 0.0, std::f64::consts::FRAC_PI_4);
        let (x0, y0, x1, y1) = r.bounds();
        // The bounding box's corner region is empty for a 45° rectangle.
        assert!(!r.overlaps_square(x1 - 0.05, y1 - 0.05, 0.05));
        assert!(x0 < 0.0 && y0 < 0.0);
    }

    #[test]
    fn clearance_between_rectangles_is_exact() {
        // Side by side along x: gap 1.5 − 1.0 = 0.5.
        let d = rect(0.0, 0.0, 0.0).distance(&rect(1.5, 0.0, 0.0));
        assert!((d - 0.5).abs() < 1e-12, "{d}");
        // A 45° rectangle whose corner points at the other's side: the corner is at
        // x = 2 − (0.5 + 0.25)/√2 and the side at x = 0.5.
        let d = rect(0.0, 0.0, 0.0).distance(&rect(2.0, 0.0, std::f64::consts::FRAC_PI_4));
        let expected = 2.0 - 0.75 * std::f64::consts::FRAC_1_SQRT_2 - 0.5;
        assert!((d - expected).abs() < 1e-12, "{d} vs {expected}");
        // Diagonal corner to corner.
        let d = rect(0.0, 0.0, 0.0).distance(&rect(2.0, 1.5, 0.0));
        assert!((d - 1.0f64.hypot(1.0)).abs() < 1e-12, "{d}");
        assert_eq!(rect(0.0, 0.0, 0.0).distance(&rect(0.9, 0.0, 0.0)), 0.0);
    }
}
