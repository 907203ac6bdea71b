//! The one validation error every spec returns: it names the field, the
//! offending value and what is allowed, so the CLI (exit 2) and the service
//! (a 4xx problem+json) can show it as it is.

use std::fmt;

/// A rejected input: `field` is a dotted path (`estimator.cutoff_hz`),
/// `value` the value as given, `allowed` a sentence saying what would be valid.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub struct SpecError {
    pub field: String,
    pub value: String,
    pub allowed: String,
}

impl SpecError {
    pub fn new(
        field: impl Into<String>,
        value: impl fmt::Display,
        allowed: impl Into<String>,
    ) -> Self {
        Self {
            field: field.into(),
            value: value.to_string(),
            allowed: allowed.into(),
        }
    }

    /// Prefix the field path, e.g. `cutoff_hz` -> `estimator.cutoff_hz`.
    pub fn within(mut self, parent: &str) -> Self {
        self.field = format!("{parent}.{}", self.field);
        self
    }
}

/// Parse JSON `text` as a `noun` ("scene", "estimator spec"), naming the
/// field a parse error is in below `what` (`scene.probe.method`), or `what`
/// itself when it is the whole document.
pub fn parse_json<T: serde::de::DeserializeOwned>(
    text: &str,
    what: &str,
    noun: &str,
) -> Result<T, SpecError> {
    let mut de = serde_json::Deserializer::from_str(text);
    let parsed: T = serde_path_to_error::deserialize(&mut de).map_err(|e| {
        let path = e.path().to_string();
        let field = match path.as_str() {
            "" | "." | "?" => what.to_string(),
            p => format!("{what}.{p}"),
        };
        SpecError::new(
            field,
            "(as written)",
            format!("is not a valid {noun}: {}", e.inner()),
        )
    })?;
    de.end()
        .map_err(|e| SpecError::new(what, "(document)", format!("is not a valid {noun}: {e}")))?;
    Ok(parsed)
}

impl fmt::Display for SpecError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} = {} is not allowed: {}",
            self.field, self.value, self.allowed
        )
    }
}

/// `s` cut to at most `max` bytes at a character boundary; a cut text
/// ends with `… (N bytes)` naming its whole length.
pub fn clip(s: &str, max: usize) -> std::borrow::Cow<'_, str> {
    if s.len() <= max {
        return s.into();
    }
    let mut end = max.saturating_sub(24);
    while !s.is_char_boundary(end) {
        end -= 1;
    }
    format!("{}… ({} bytes)", &s[..end], s.len()).into()
}

/// A number as a message shows it: never "NaN" or "inf" (an input from
/// the command line, the C ABI or Python can be either).
pub fn shown(value: f64) -> String {
    if value.is_nan() {
        "(not a number)".into()
    } else if value.is_infinite() {
        if value > 0.0 {
            "(+infinity)"
        } else {
            "(−infinity)"
        }
        .into()
    } else {
        value.to_string()
    }
}

/// `Ok(())` when `value` is finite and strictly positive.
pub fn require_positive(field: &str, value: f64, unit: &str) -> Result<(), SpecError> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(SpecError::new(
            field,
            shown(value),
            format!("must be a finite number > 0 ({unit})"),
        ))
    }
}

/// `Ok(())` when `value` is finite and not negative.
pub fn require_non_negative(field: &str, value: f64, unit: &str) -> Result<(), SpecError> {
    if value.is_finite() && value >= 0.0 {
        Ok(())
    } else {
        Err(SpecError::new(
            field,
            shown(value),
            format!("must be a finite number >= 0 ({unit})"),
        ))
    }
}

/// `Ok(())` when `lo <= value <= hi` (finite). Bounds inputs whose products
/// and quotients must stay finite.
pub fn require_range(
    field: &str,
    value: f64,
    lo: f64,
    hi: f64,
    unit: &str,
) -> Result<(), SpecError> {
    if value.is_finite() && (lo..=hi).contains(&value) {
        Ok(())
    } else {
        Err(SpecError::new(
            field,
            shown(value),
            format!("must be {lo:e} to {hi:e} ({unit})"),
        ))
    }
}

/// What went wrong on the command line, and so the exit code: bad input
/// exits 2, anything else 1. (Here, not in `cli`, so the HTTP client and
/// the CLI both use it without importing each other.)
#[derive(Debug)]
pub enum CliError {
    /// Bad input: exit 2.
    Input(String),
    /// I/O or internal failure: exit 1.
    Failure(String),
}

impl CliError {
    pub fn exit_code(&self) -> i32 {
        match self {
            CliError::Input(_) => 2,
            CliError::Failure(_) => 1,
        }
    }
}

impl std::fmt::Display for CliError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            CliError::Input(m) | CliError::Failure(m) => f.write_str(m),
        }
    }
}

impl From<SpecError> for CliError {
    fn from(e: SpecError) -> Self {
        CliError::Input(e.to_string())
    }
}
