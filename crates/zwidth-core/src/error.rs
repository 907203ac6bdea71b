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
    if let Some(dup) = duplicate_key(text.as_bytes()) {
        return Err(dup.error(what));
    }
    let mut de = serde_json::Deserializer::from_str(text);
    let parsed: T = serde_path_to_error::deserialize(&mut de).map_err(|e| {
        let path = e.path().to_string();
        let field = match path.as_str() {
            "" | "." | "?" => what.to_string(),
            p => format!("{what}.{p}"),
        };
        let inner = e.inner().to_string();
        // A refusal a hand-written Deserialize wrote as SpecError writes
        // one (`estimators::kind_error`): the field below this path.
        if let Some(nested) = refusal_in(&inner) {
            return nested.within(&field);
        }
        SpecError::new(
            field,
            "(as written)",
            format!("is not a valid {noun}: {inner}"),
        )
    })?;
    de.end()
        .map_err(|e| SpecError::new(what, "(document)", format!("is not a valid {noun}: {e}")))?;
    Ok(parsed)
}

/// `"key = value is not allowed: why"` (a field name of lower-case letters,
/// digits and `_`, as `SpecError` displays one, then serde's " at line …"
/// cut), as a `SpecError` for `key`.
fn refusal_in(message: &str) -> Option<SpecError> {
    let (key, rest) = message.split_once(" = ")?;
    let plain = |c: char| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_';
    if key.is_empty() || !key.chars().all(plain) {
        return None;
    }
    let (value, allowed) = rest.split_once(" is not allowed: ")?;
    let allowed = match allowed.rfind(" at line ") {
        Some(i) => &allowed[..i],
        None => allowed,
    };
    Some(SpecError::new(key, value, allowed))
}

/// A key written twice in one JSON object: the object's path (`""` the
/// document, `scene.device`, `b[2]`) and the key.
#[derive(Debug, Clone, PartialEq)]
pub struct DuplicateKey {
    pub object: String,
    pub key: String,
}

impl DuplicateKey {
    /// The refusal, naming the key's field below `what` (a document
    /// parsed as `what`: "scene", "estimator"; `""`: none).
    pub fn error(&self, what: &str) -> SpecError {
        let field = [what, &self.object, &self.key]
            .iter()
            .filter(|p| !p.is_empty())
            .copied()
            .collect::<Vec<_>>()
            .join(".")
            .replace(".[", "[");
        SpecError::new(
            field,
            format!("{:?} (written twice)", clip(&self.key, 128)),
            "each key once in an object: parsers differ on which of two counts",
        )
    }
}

/// The first key some object of JSON `text` repeats, if any (duplicate
/// keys are refused everywhere a document is read: serde would keep the
/// last silently). None too when `text` is not JSON: its parse says why.
pub fn duplicate_key(text: &[u8]) -> Option<DuplicateKey> {
    use serde::de::{DeserializeSeed, Deserializer, MapAccess, SeqAccess, Visitor};
    use std::cell::RefCell;

    struct Walk<'a> {
        path: String,
        found: &'a RefCell<Option<DuplicateKey>>,
    }
    impl<'de> DeserializeSeed<'de> for Walk<'_> {
        type Value = ();
        fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<(), D::Error> {
            d.deserialize_any(self)
        }
    }
    impl<'de> Visitor<'de> for Walk<'_> {
        type Value = ();
        fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
            f.write_str("any JSON value")
        }
        fn visit_bool<E>(self, _: bool) -> Result<(), E> {
            Ok(())
        }
        fn visit_i64<E>(self, _: i64) -> Result<(), E> {
            Ok(())
        }
        fn visit_u64<E>(self, _: u64) -> Result<(), E> {
            Ok(())
        }
        fn visit_f64<E>(self, _: f64) -> Result<(), E> {
            Ok(())
        }
        fn visit_str<E>(self, _: &str) -> Result<(), E> {
            Ok(())
        }
        fn visit_unit<E>(self) -> Result<(), E> {
            Ok(())
        }
        fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<(), A::Error> {
            let mut i = 0usize;
            loop {
                let path = format!("{}[{i}]", self.path);
                let walk = Walk {
                    path,
                    found: self.found,
                };
                if seq.next_element_seed(walk)?.is_none() {
                    return Ok(());
                }
                i += 1;
            }
        }
        fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<(), A::Error> {
            let mut seen = std::collections::HashSet::new();
            while let Some(key) = map.next_key::<String>()? {
                if seen.contains(&key) {
                    *self.found.borrow_mut() = Some(DuplicateKey {
                        object: self.path,
                        key,
                    });
                    return Err(serde::de::Error::custom("duplicate key"));
                }
                let path = match self.path.as_str() {
                    "" => key.clone(),
                    p => format!("{p}.{key}"),
                };
                seen.insert(key);
                map.next_value_seed(Walk {
                    path,
                    found: self.found,
                })?;
            }
            Ok(())
        }
    }
    let found = RefCell::new(None);
    let mut de = serde_json::Deserializer::from_slice(text);
    let _ = Walk {
        path: String::new(),
        found: &found,
    }
    .deserialize(&mut de);
    found.into_inner()
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

#[cfg(test)]
mod duplicate_tests {
    use super::*;

    /// A hand-written Deserialize's refusal is read back only in
    /// `SpecError`'s own form with a plain field name (serde's own texts,
    /// which contain " = " too, are not taken for one).
    #[test]
    fn a_refusal_is_read_back_only_with_a_plain_field_name() {
        let r = refusal_in("max_window = -1 is not allowed: a whole number at line 1 column 9")
            .unwrap();
        assert_eq!(
            (r.field.as_str(), r.value.as_str(), r.allowed.as_str()),
            ("max_window", "-1", "a whole number")
        );
        assert_eq!(refusal_in(" = -1 is not allowed: x"), None, "no field name");
        assert_eq!(
            refusal_in("a b = -1 is not allowed: x"),
            None,
            "not a field name"
        );
        assert_eq!(refusal_in("Max = -1 is not allowed: x"), None, "upper case");
        assert_eq!(
            refusal_in("max = -1 is refused"),
            None,
            "not SpecError's words"
        );
        assert_eq!(refusal_in("invalid type: map, expected a string"), None);
    }

    #[test]
    fn a_key_written_twice_is_found_with_its_object() {
        // Issue 45 item 11: `{"kind":"map","kind":"compare"}` was run as a
        // compare (serde keeps the last).
        let d = duplicate_key(br#"{"kind":"map","kind":"compare"}"#).unwrap();
        assert_eq!((d.object.as_str(), d.key.as_str()), ("", "kind"));
        assert_eq!(d.error("").field, "kind");
        let d = duplicate_key(br#"{"scene":{"device":{"mass":1,"mass":2}}}"#).unwrap();
        assert_eq!(d.error("").field, "scene.device.mass");
        assert_eq!(d.error("experiment").field, "experiment.scene.device.mass");
        // Inside an array, and a key spelled with an escape is the same key.
        let d = duplicate_key(br#"{"estimators":[{},{"kind":"fdm","k\u0069nd":"x"}]}"#).unwrap();
        assert_eq!(d.error("").field, "estimators[1].kind");
        assert!(d.error("").value.contains("written twice"));
        // The same key in different objects, and no object at all: none.
        for ok in [
            &br#"{"a":{"k":1},"b":{"k":1},"c":[{"k":1},{"k":2}]}"#[..],
            b"[1, 2.5, -3, true, null, \"s\"]",
            b"not json",
            b"{\"a\":1,",
        ] {
            assert_eq!(duplicate_key(ok), None, "{}", String::from_utf8_lossy(ok));
        }
        // Through parse_json, before any field is read.
        let e =
            parse_json::<serde_json::Value>(r#"{"q":1,"q":2}"#, "estimator", "spec").unwrap_err();
        assert_eq!(e.field, "estimator.q");
    }
}
