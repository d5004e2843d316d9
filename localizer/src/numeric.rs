//! Small numeric helpers for the hot loops.

/// `v.floor()` as an integer, without the library call `floor` compiles to
/// on baseline x86-64 (no SSE4.1); saturates far outside the i64 range.
#[inline(always)]
pub fn floor_i64(v: f64) -> i64 {
    let t = v as i64;
    t - i64::from((t as f64) > v)
}

/// 1.5 · 2⁵²: added to a float of magnitude below 2³¹, it leaves that
/// float rounded to a whole number in the low 32 bits of the sum's bits.
const ROUNDING_SHIFTER: f64 = 6_755_399_441_055_744.0;

/// `v` rounded to the nearest whole number, ties to even, for `|v| < 2³¹`:
/// the float unit's own rounding, two instructions where a saturating `as`
/// takes six. Outside that range (or NaN) the result is some integer, not
/// a panic: callers bound-check what they index with it.
#[inline(always)]
pub fn round_i32(v: f64) -> i32 {
    // Truncating to the low 32 bits is the point.
    (v + ROUNDING_SHIFTER).to_bits() as u32 as i32
}

/// The cell index `floor(v)` for `|v| < 2³¹` by [`round_i32`], except
/// that a whole number (a point on the line between two cells) may give
/// either cell: for the table lookups, which correct for the offset from
/// the cell they chose, both are right.
#[inline(always)]
pub fn cell_i32(v: f64) -> i32 {
    round_i32(v - 0.5)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn floor_is_the_library_floor(v in -1.0e9f64..1.0e9) {
            prop_assert_eq!(floor_i64(v), v.floor() as i64);
        }
    }

    proptest! {
        #[test]
        fn rounding_is_the_library_round_off_the_ties(v in -2.0e9f64..2.0e9) {
            prop_assume!((v - v.floor() - 0.5).abs() > 1e-6);
            prop_assert_eq!(round_i32(v), v.round() as i32);
        }

        #[test]
        fn a_cell_is_the_floor_or_on_its_edge(v in -2.0e9f64..2.0e9) {
            let cell = cell_i32(v);
            if v.fract() == 0.0 {
                prop_assert!(cell == v as i32 || cell == v as i32 - 1);
            } else {
                prop_assert_eq!(cell, v.floor() as i32);
            }
        }
    }

    #[test]
    fn ties_go_to_even_and_edges_to_either_cell() {
        assert_eq!(round_i32(2.5), 2);
        assert_eq!(round_i32(3.5), 4);
        assert_eq!(round_i32(-2.5), -2);
        assert_eq!(round_i32(-0.4), 0);
        assert_eq!(cell_i32(0.999), 0);
        assert_eq!(cell_i32(-0.001), -1);
        assert!([2, 3].contains(&cell_i32(3.0)));
        assert!([-4, -3].contains(&cell_i32(-3.0)));
    }

    #[test]
    fn whole_numbers_and_halves() {
        assert_eq!(floor_i64(2.0), 2);
        assert_eq!(floor_i64(-2.0), -2);
        assert_eq!(floor_i64(-0.5), -1);
        assert_eq!(floor_i64(0.5), 0);
    }
}
