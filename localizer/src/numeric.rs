//! Small numeric helpers for the hot loops.

/// `v.floor()` as an integer, without the library call `floor` compiles to
/// on baseline x86-64 (no SSE4.1); saturates far outside the i64 range.
#[inline(always)]
pub fn floor_i64(v: f64) -> i64 {
    let t = v as i64;
    t - i64::from((t as f64) > v)
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

    #[test]
    fn whole_numbers_and_halves() {
        assert_eq!(floor_i64(2.0), 2);
        assert_eq!(floor_i64(-2.0), -2);
        assert_eq!(floor_i64(-0.5), -1);
        assert_eq!(floor_i64(0.5), 0);
    }
}
