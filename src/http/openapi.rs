//! The API description, generated from the code: `zwidth openapi` prints
//! it; `api/openapi.json` is that output, and a test fails when they
//! differ. CI validates it (openapi-spec-validator) and drives the service
//! through a client generated from it (openapi-python-client).

use serde_json::Value;

use super::compare::*;
use super::experiments::*;
use super::problem::ProblemBody;
use super::queue::*;
use super::rigs::*;
use crate::jobs::window::Window;
use crate::jobs::ExperimentSpec;
use crate::report::Comparison;
use crate::zwidth::search::StoredTrial;

#[derive(utoipa::OpenApi)]
#[openapi(
    info(title = "zwidth", description = "Z-width experiments: queue, run and store maps and estimator comparisons"),
    paths(healthz, rigs, set_window, clear_window, submit, list, show, cancel, trials, evaluations, plot, points, compare_runs, queue, pause, resume, metrics),
    components(schemas(ProblemBody, ExperimentView, ExperimentPage, ExperimentSpec, RigView, Window, Comparison, StoredTrial, HealthView, crate::tune::TuneResult)),
    modifiers(&BearerAuth)
)]
pub struct ApiDoc;

struct BearerAuth;

impl utoipa::Modify for BearerAuth {
    fn modify(&self, api: &mut utoipa::openapi::OpenApi) {
        use utoipa::openapi::security::{HttpAuthScheme, HttpBuilder, SecurityScheme};
        let components = api.components.get_or_insert_with(Default::default);
        components.add_security_scheme(
            "bearer",
            SecurityScheme::Http(HttpBuilder::new().scheme(HttpAuthScheme::Bearer).build()),
        );
    }
}

/// The OpenAPI document as pretty JSON.
pub fn openapi_json() -> String {
    use utoipa::OpenApi;
    let mut v = serde_json::to_value(ApiDoc::openapi()).unwrap_or_default();
    // The experiment kinds are `{"kind": …} + MapSpec/CompareSpec` (allOf).
    // Their structs reject unknown fields, which utoipa writes as
    // `additionalProperties: false`; inside allOf that forbids `kind` itself
    // and makes the union unsatisfiable. The server still rejects unknown
    // fields; the schema just leaves them open.
    for name in ["MapSpec", "CompareSpec", "SweepSpec", "TuneSpec"] {
        if let Some(o) = v["components"]["schemas"][name].as_object_mut() {
            o.remove("additionalProperties");
        }
    }
    describe_responses(&mut v);
    serde_json::to_string_pretty(&v).unwrap_or_default()
}

/// OpenAPI requires a description on every response object.
fn describe_responses(v: &mut Value) {
    let Some(paths) = v["paths"].as_object_mut() else {
        return;
    };
    for ops in paths.values_mut() {
        let Some(ops) = ops.as_object_mut() else {
            continue;
        };
        for op in ops.values_mut() {
            let Some(resps) = op["responses"].as_object_mut() else {
                continue;
            };
            for (code, r) in resps.iter_mut() {
                let missing = r["description"].as_str().is_none_or(str::is_empty);
                if missing {
                    let text = code
                        .parse::<u16>()
                        .ok()
                        .and_then(|c| axum::http::StatusCode::from_u16(c).ok())
                        .and_then(|c| c.canonical_reason())
                        .unwrap_or("response");
                    r["description"] = Value::String(text.to_string());
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn committed_openapi_matches_the_code() {
        // Regenerate with: cargo run -- openapi > api/openapi.json
        let committed = include_str!("../../api/openapi.json");
        assert_eq!(
            committed.trim_end(),
            super::openapi_json().trim_end(),
            "api/openapi.json drifted from the code"
        );
        let v: serde_json::Value = serde_json::from_str(committed).unwrap();
        assert!(v["openapi"].as_str().unwrap().starts_with("3.1"));
        for path in [
            "/v1/experiments",
            "/v1/experiments/{id}",
            "/v1/experiments/{id}/cancel",
            "/healthz",
            "/metrics",
            "/v1/rigs",
            "/v1/rigs/{id}/window",
            "/v1/compare",
            "/v1/experiments/{id}/trials",
            "/v1/experiments/{id}/plot.svg",
            "/v1/experiments/{id}/points.csv",
            "/v1/experiments/{id}/evaluations",
        ] {
            assert!(v["paths"].get(path).is_some(), "{path} missing");
        }
        // Every response has a description (OpenAPI 3.1 requires one).
        for (path, ops) in v["paths"].as_object().unwrap() {
            for (method, op) in ops.as_object().unwrap() {
                for (code, r) in op["responses"].as_object().unwrap() {
                    let d = r["description"].as_str().unwrap_or("");
                    assert!(!d.is_empty(), "{method} {path} {code} has no description");
                }
            }
        }
    }
}
