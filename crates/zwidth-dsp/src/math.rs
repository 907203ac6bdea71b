//! The one maths library of every build (src/lib.rs, "Rules").

/// States below this magnitude (in their SI unit) are set to 0 (see
/// "Subnormals" in lib.rs).
pub const FLUSH: f64 = 1e-100;

/// `x`, or 0 when `|x| < FLUSH` (NaN passes through).
#[inline]
pub fn flush(x: f64) -> f64 {
    if abs(x) < FLUSH {
        0.0
    } else {
        x
    }
}

/// |x| by clearing the sign bit (IEEE-754 `abs`).
#[inline]
pub fn abs(x: f64) -> f64 {
    f64::from_bits(x.to_bits() & !(1u64 << 63))
}

#[inline]
pub fn sqrt(x: f64) -> f64 {
    libm::sqrt(x)
}

#[inline]
pub fn tan(x: f64) -> f64 {
    libm::tan(x)
}

#[inline]
pub fn sin(x: f64) -> f64 {
    libm::sin(x)
}

#[inline]
pub fn cos(x: f64) -> f64 {
    libm::cos(x)
}

#[inline]
pub fn hypot(x: f64, y: f64) -> f64 {
    libm::hypot(x, y)
}

/// `a^b` by the binary method of compiler-rt's `__powidf2` (what
/// `f64::powi` lowers to), so the bits equal std's `powi` on hosts where
/// it is not expanded otherwise.
pub fn powi(a: f64, b: i32) -> f64 {
    let recip = b < 0;
    let mut a = a;
    let mut b = b;
    let mut r = 1.0;
    loop {
        if b & 1 != 0 {
            r *= a;
        }
        b /= 2;
        if b == 0 {
            break;
        }
        a *= a;
    }
    if recip {
        1.0 / r
    } else {
        r
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn powi_is_repeated_multiplication_in_binary_order() {
        // 3^5 = 243, 2^-3 = 0.125, x^0 = 1: exact in binary.
        assert_eq!(powi(3.0, 5), 243.0);
        assert_eq!(powi(2.0, -3), 0.125);
        assert_eq!(powi(7.5, 0), 1.0);
        // The order: x^5 = x·(x²)² (r = x, then a = x², x⁴, r = x·x⁴).
        let x = 1.1f64;
        let x2 = x * x;
        assert_eq!(powi(x, 5).to_bits(), (x * (x2 * x2)).to_bits());
    }

    #[test]
    fn abs_clears_the_sign_only() {
        assert_eq!(abs(-0.0).to_bits(), 0);
        assert_eq!(abs(-2.5), 2.5);
        assert!(abs(f64::NAN).is_nan());
    }
}
