//! The complex arithmetic of the filter design, written out as
//! `num-complex` 0.4 evaluates it (so the coefficients keep their bits).

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cx {
    pub re: f64,
    pub im: f64,
}

impl Cx {
    pub const ZERO: Cx = Cx { re: 0.0, im: 0.0 };

    pub const fn new(re: f64, im: f64) -> Self {
        Self { re, im }
    }

    /// r·(cos θ + j sin θ).
    pub fn from_polar(r: f64, theta: f64) -> Self {
        Self::new(r * crate::math::cos(theta), r * crate::math::sin(theta))
    }

    pub fn scale(self, k: f64) -> Cx {
        Cx::new(self.re * k, self.im * k)
    }

    pub fn conj(self) -> Cx {
        Cx::new(self.re, -self.im)
    }

    pub fn norm(self) -> f64 {
        crate::math::hypot(self.re, self.im)
    }
}

impl core::ops::Add for Cx {
    type Output = Cx;
    fn add(self, o: Cx) -> Cx {
        Cx::new(self.re + o.re, self.im + o.im)
    }
}

impl core::ops::Sub for Cx {
    type Output = Cx;
    fn sub(self, o: Cx) -> Cx {
        Cx::new(self.re - o.re, self.im - o.im)
    }
}

impl core::ops::Mul for Cx {
    type Output = Cx;
    fn mul(self, o: Cx) -> Cx {
        Cx::new(
            self.re * o.re - self.im * o.im,
            self.re * o.im + self.im * o.re,
        )
    }
}

/// Division through |o|², as num-complex's `Div`.
impl core::ops::Div for Cx {
    type Output = Cx;
    fn div(self, o: Cx) -> Cx {
        let n = o.re * o.re + o.im * o.im;
        Cx::new(
            (self.re * o.re + self.im * o.im) / n,
            (self.im * o.re - self.re * o.im) / n,
        )
    }
}

impl core::ops::Neg for Cx {
    type Output = Cx;
    fn neg(self) -> Cx {
        Cx::new(-self.re, -self.im)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The operations against their definitions (num-complex's order of
    /// evaluation, so the bits match it): (a + bi) − (c + di) = (a − c) +
    /// (b − d)i, the sum and the negation likewise; the product and quotient
    /// by hand.
    #[test]
    fn arithmetic_is_complex_arithmetic() {
        let (x, y) = (Cx::new(1.0, 2.0), Cx::new(0.5, 3.0));
        assert_eq!(x - y, Cx::new(0.5, -1.0));
        assert_eq!(x + y, Cx::new(1.5, 5.0));
        assert_eq!(-x, Cx::new(-1.0, -2.0));
        assert_eq!(x * y, Cx::new(1.0 * 0.5 - 2.0 * 3.0, 1.0 * 3.0 + 2.0 * 0.5));
        let q = x / y;
        let back = q * y;
        assert!(
            (back.re - 1.0).abs() < 1e-15 && (back.im - 2.0).abs() < 1e-15,
            "{q:?}"
        );
    }
}
