//! Which estimator library a rig runs, and whether its estimators are this
//! build's to the bit: the library's version and, per kind, the
//! fingerprint of a reference configuration's coefficients
//! (`zwidth_dsp::identity`), as the rig's agent advertises them in its
//! capabilities (`dsp`) and as the server compares them with its own.

use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

use crate::error::SpecError;
/// Every estimator kind, by the name the API and the capabilities use.
pub use zwidth_dsp::identity::KINDS;

/// An estimator library's identity: what `zw_dsp_identity` (C),
/// `zwidth.dsp_identity()` (Python) and the Rust agent write.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct DspIdentity {
    /// The library's version (`zwidth-dsp`'s crate version).
    pub version: String,
    /// Per estimator kind, its reference fingerprint as 16 hex digits.
    pub fingerprints: BTreeMap<String, String>,
}

/// A fingerprint as it travels: 16 lower-case hex digits.
pub fn hex(fingerprint: u64) -> String {
    format!("{fingerprint:016x}")
}

impl DspIdentity {
    /// This build's.
    pub fn ours() -> Self {
        Self {
            version: zwidth_dsp::VERSION.into(),
            fingerprints: zwidth_dsp::identity::KINDS
                .iter()
                .filter_map(|k| {
                    Some((
                        k.to_string(),
                        hex(zwidth_dsp::identity::reference_fingerprint(k)?),
                    ))
                })
                .collect(),
        }
    }

    /// Bounded and well formed: a version of 1–64 characters, at most 32
    /// kinds named in at most 64 characters, each with 16 hex digits.
    pub fn validate(&self) -> Result<(), SpecError> {
        if self.version.is_empty() || self.version.len() > 64 {
            return Err(SpecError::new(
                "capabilities.dsp.version",
                crate::error::clip(&self.version, 80),
                "a version of 1 to 64 characters",
            ));
        }
        if self.fingerprints.len() > 32 {
            return Err(SpecError::new(
                "capabilities.dsp.fingerprints",
                self.fingerprints.len(),
                "at most 32 kinds",
            ));
        }
        for (kind, print) in &self.fingerprints {
            if kind.is_empty() || kind.len() > 64 {
                return Err(SpecError::new(
                    "capabilities.dsp.fingerprints",
                    crate::error::clip(kind, 80),
                    "kind names of 1 to 64 characters",
                ));
            }
            if print.len() != 16 || !print.bytes().all(|b| b.is_ascii_hexdigit()) {
                return Err(SpecError::new(
                    format!("capabilities.dsp.fingerprints.{kind}"),
                    crate::error::clip(print, 80),
                    "16 hex digits",
                ));
            }
        }
        Ok(())
    }

    /// How the rig's estimators (`self`, for the kinds it advertises)
    /// compare with this build's.
    pub fn check(rig: Option<&Self>, kinds: &[String]) -> EstimatorCheck {
        // This build's identity never changes: computed once, not on every
        // view of a rig (the check runs under the rig's lock).
        static OURS: std::sync::OnceLock<DspIdentity> = std::sync::OnceLock::new();
        let ours = OURS.get_or_init(Self::ours);
        let Some(rig) = rig else {
            return EstimatorCheck {
                identical: false,
                server_version: ours.version.clone(),
                rig_version: None,
                differing: Vec::new(),
                summary: "the rig does not say which estimator library it runs: its velocities \
                          may differ from the simulator's"
                    .into(),
            };
        };
        let differing: Vec<FingerprintDiff> = kinds
            .iter()
            .filter_map(|kind| {
                let server = ours.fingerprints.get(kind).cloned();
                let theirs = rig.fingerprints.get(kind).map(|p| p.to_ascii_lowercase());
                (server.is_none() || server != theirs).then(|| FingerprintDiff {
                    kind: kind.clone(),
                    server,
                    rig: theirs,
                })
            })
            .collect();
        let summary = if differing.is_empty() {
            format!(
                "bit-identical: zwidth-dsp {} on the rig, {} here, every advertised kind's \
                 fingerprint equal",
                rig.version, ours.version
            )
        } else {
            let list: Vec<String> = differing
                .iter()
                .map(|d| {
                    format!(
                        "{} (rig {}, server {})",
                        d.kind,
                        d.rig.as_deref().unwrap_or("none"),
                        d.server.as_deref().unwrap_or("unknown kind")
                    )
                })
                .collect();
            format!(
                "not bit-identical: zwidth-dsp {} on the rig, {} here; fingerprints differ for {}",
                rig.version,
                ours.version,
                list.join(", ")
            )
        };
        EstimatorCheck {
            identical: differing.is_empty(),
            server_version: ours.version.clone(),
            rig_version: Some(rig.version.clone()),
            differing,
            summary,
        }
    }
}

/// Whether a rig runs this build's estimators to the bit.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct EstimatorCheck {
    /// Every kind the rig advertises has this build's fingerprint.
    pub identical: bool,
    /// zwidth-dsp's version here and on the rig (null: the rig did not say).
    pub server_version: String,
    pub rig_version: Option<String>,
    /// The advertised kinds whose fingerprints differ (or are missing).
    pub differing: Vec<FingerprintDiff>,
    /// In words, with both values where they differ.
    pub summary: String,
}

/// One kind's fingerprints, where they differ.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct FingerprintDiff {
    pub kind: String,
    /// Null: a kind this build does not know.
    pub server: Option<String>,
    /// Null: the rig gave none.
    pub rig: Option<String>,
}

#[cfg(test)]
mod tests {
    use super::*;

    fn kinds() -> Vec<String> {
        ["fdm", "foaw"].map(String::from).to_vec()
    }

    #[test]
    fn our_identity_checks_as_identical() {
        let ours = DspIdentity::ours();
        ours.validate().unwrap();
        assert_eq!(ours.fingerprints.len(), zwidth_dsp::identity::KINDS.len());
        let c = DspIdentity::check(Some(&ours), &kinds());
        assert!(c.identical, "{c:?}");
        assert!(c.differing.is_empty());
        assert!(c.summary.starts_with("bit-identical"), "{}", c.summary);
    }

    #[test]
    fn a_changed_fingerprint_is_named_with_both_values() {
        let mut rig = DspIdentity::ours();
        let server = rig.fingerprints["foaw"].clone();
        rig.fingerprints
            .insert("foaw".into(), "00000000000000ff".into());
        let c = DspIdentity::check(Some(&rig), &kinds());
        assert!(!c.identical);
        assert_eq!(
            c.differing,
            vec![FingerprintDiff {
                kind: "foaw".into(),
                server: Some(server.clone()),
                rig: Some("00000000000000ff".into()),
            }]
        );
        assert!(
            c.summary
                .contains(&format!("foaw (rig 00000000000000ff, server {server})")),
            "{}",
            c.summary
        );
        // A kind it does not advertise does not count.
        assert!(DspIdentity::check(Some(&rig), &["fdm".into()]).identical);
        // Upper-case hex is the same fingerprint.
        let mut upper = DspIdentity::ours();
        for p in upper.fingerprints.values_mut() {
            *p = p.to_ascii_uppercase();
        }
        assert!(DspIdentity::check(Some(&upper), &kinds()).identical);
    }

    #[test]
    fn a_missing_fingerprint_or_library_is_not_identical() {
        let mut rig = DspIdentity::ours();
        rig.fingerprints.remove("fdm");
        let c = DspIdentity::check(Some(&rig), &kinds());
        assert_eq!(c.differing.len(), 1);
        assert_eq!(c.differing[0].rig, None);
        let c = DspIdentity::check(None, &kinds());
        assert!(!c.identical);
        assert_eq!(c.rig_version, None);
        assert!(c.summary.contains("does not say"), "{}", c.summary);
        let c = DspIdentity::check(Some(&DspIdentity::ours()), &["pid".into()]);
        assert!(!c.identical);
        assert!(
            c.summary.contains("pid (rig none, server unknown kind)"),
            "{}",
            c.summary
        );
    }

    #[test]
    fn a_malformed_identity_is_refused_naming_the_field() {
        let mut rig = DspIdentity::ours();
        rig.fingerprints.insert("fdm".into(), "xyz".into());
        let e = rig.validate().unwrap_err().to_string();
        assert!(e.contains("capabilities.dsp.fingerprints.fdm"), "{e}");
        let mut rig = DspIdentity::ours();
        rig.version = "v".repeat(65);
        assert!(rig
            .validate()
            .unwrap_err()
            .to_string()
            .contains("capabilities.dsp.version"));
        let mut rig = DspIdentity::ours();
        for i in 0..40 {
            rig.fingerprints.insert(format!("k{i}"), "0".repeat(16));
        }
        assert!(rig
            .validate()
            .unwrap_err()
            .to_string()
            .contains("at most 32"));
    }
}
