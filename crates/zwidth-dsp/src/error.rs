//! Why a configuration was refused: the parameter, its value and what is
//! allowed (the C ABI passes the parameter's name on).

#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Error {
    /// A parameter outside its range.
    Parameter {
        name: &'static str,
        value: f64,
        allowed: &'static str,
    },
    /// A window or order beyond what this build's state holds.
    Capacity {
        name: &'static str,
        value: usize,
        cap: usize,
    },
}

impl Error {
    pub fn parameter(&self) -> &'static str {
        match self {
            Error::Parameter { name, .. } | Error::Capacity { name, .. } => name,
        }
    }
}

impl core::fmt::Display for Error {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Error::Parameter {
                name,
                value,
                allowed,
            } if value.is_finite() => write!(f, "{name} = {value} is not allowed: {allowed}"),
            Error::Parameter { name, allowed, .. } => {
                write!(f, "{name} (not a finite number) is not allowed: {allowed}")
            }
            Error::Capacity { name, value, cap } => write!(
                f,
                "{name} = {value} is beyond this build's capacity of {cap}"
            ),
        }
    }
}

/// `value` finite and > 0.
pub(crate) fn positive(name: &'static str, value: f64) -> Result<f64, Error> {
    if value.is_finite() && value > 0.0 {
        Ok(value)
    } else {
        Err(Error::Parameter {
            name,
            value,
            allowed: "must be a finite number > 0",
        })
    }
}
