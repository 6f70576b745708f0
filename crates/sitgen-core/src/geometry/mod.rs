//! Geometry shared by the stages: robot bodies and grid traversal of segments.

pub mod body;
pub mod segment;

pub use body::Body;

/// Whether a distance lies beyond a bound, decided by squares where rounding cannot matter:
/// `d2` is the squared distance and `bound2` the bound squared, each as computed. Away from the
/// bound by more than a relative 10⁻¹² (far beyond the few ulps either square is rounded by),
/// the squares decide; nearer, `exact` gives the answer (the `hypot`-based test the caller
/// would otherwise make everywhere), so decisions are those of `exact` bit for bit while libm's
/// `hypot`, several times slower than the squares, runs only for the few near the bound.
#[inline]
pub fn beyond_by_squares(d2: f64, bound2: f64, exact: impl FnOnce() -> bool) -> bool {
    if d2 > bound2 * (1.0 + 1e-12) {
        true
    } else if d2 < bound2 * (1.0 - 1e-12) {
        false
    } else {
        exact()
    }
}

#[cfg(test)]
mod tests {
    use super::beyond_by_squares;
    use proptest::prelude::*;

    proptest! {
        /// The squares give `hypot`'s decision wherever they decide alone, for bounds a few
        /// ulps either side of the distance as well as far from it.
        #[test]
        fn squares_decide_as_hypot_would(
            dx in -50.0f64..50.0, dy in -50.0f64..50.0, ulps in -8i64..8, scale in 0.5f64..2.0,
            near in proptest::bool::ANY,
        ) {
            let d = dx.hypot(dy);
            let bound = if near {
                f64::from_bits((d.to_bits() as i64 + ulps).max(0) as u64)
            } else {
                d * scale
            };
            let exact = d > bound;
            prop_assert_eq!(beyond_by_squares(dx * dx + dy * dy, bound * bound, || exact), exact);
        }
    }
}
