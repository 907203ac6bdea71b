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
use crate::experiment::ExperimentSpec;
use crate::report::Comparison;
use crate::rig::window::Window;
use crate::zwidth::search::StoredTrial;

#[derive(utoipa::OpenApi)]
#[openapi(
    info(title = "zwidth", description = "Z-width experiments: queue, run and store maps and estimator comparisons"),
    paths(healthz, rigs, register, set_window, clear_window, release, audit, agent_audit, stop, agent_token, submit, list, show, cancel, trials, units, evaluations, plot, points, compare_runs, queue, pause, resume, metrics),
    components(schemas(ProblemBody, crate::rig::protocol::StopMode, ExperimentView, ExperimentPage, ExperimentSpec, RigView, AgentCredential, Window, Comparison, StoredTrial, crate::store::UnitRow, HealthView, crate::tune::TuneResult)),
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

/// The OpenAPI document as pretty JSON, shaped so that a standard
/// validator accepts it and generated clients resolve every schema.
pub fn openapi_json() -> String {
    use utoipa::OpenApi;
    let mut v = serde_json::to_value(ApiDoc::openapi()).unwrap_or_default();
    describe_responses(&mut v);
    if let Some(schemas) = v["components"]["schemas"].as_object_mut() {
        hoist_union_members(schemas);
        distribute_allof_over_unions(schemas);
        tags_as_const(schemas);
        open_allof_members(schemas);
        close_variants(schemas, &["ExperimentSpec", "EstimatorSpec"]);
    }
    serde_json::to_string_pretty(&v).unwrap_or_default()
}

type Schemas = serde_json::Map<String, Value>;

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

fn pascal(s: &str) -> String {
    s.split(['_', '-'])
        .filter(|p| !p.is_empty())
        .map(|p| {
            let mut c = p.chars();
            c.next()
                .map(|f| f.to_uppercase().chain(c).collect::<String>())
                .unwrap_or_default()
        })
        .collect()
}

fn ref_name(m: &Value) -> Option<&str> {
    m["$ref"].as_str().and_then(|r| r.rsplit('/').next())
}

fn schema_ref(name: &str) -> Value {
    serde_json::json!({ "$ref": format!("#/components/schemas/{name}") })
}

/// A union member's variant name: its `kind` tag (serde's internal tag),
/// or its one required property (serde's external tag).
fn tag_of(m: &Value, schemas: &Schemas) -> Option<String> {
    fn kind_in(s: &Value, schemas: &Schemas, depth: usize) -> Option<String> {
        if depth > 8 {
            return None;
        }
        let s = match ref_name(s) {
            Some(n) => schemas.get(n)?,
            None => s,
        };
        let k = &s["properties"]["kind"];
        if let Some(c) = k["const"].as_str() {
            return Some(c.to_string());
        }
        if let Some([one]) = k["enum"].as_array().map(Vec::as_slice) {
            return one.as_str().map(str::to_owned);
        }
        s["allOf"]
            .as_array()?
            .iter()
            .find_map(|sub| kind_in(sub, schemas, depth + 1))
    }
    if let Some(t) = kind_in(m, schemas, 0) {
        return Some(t);
    }
    let req = m["required"].as_array()?;
    let props = m["properties"].as_object()?;
    match req.as_slice() {
        [one] if props.len() == 1 => one.as_str().map(str::to_owned),
        _ => None,
    }
}

/// Inline object members of a `oneOf`/`anyOf` become components of their
/// own (`ExperimentSpecMap`), referenced from the union: same schema, but
/// generators that build inline members before the models they `allOf`
/// (openapi-python-client) resolve them.
fn hoist_union_members(schemas: &mut Schemas) {
    let names: Vec<String> = schemas.keys().cloned().collect();
    for name in names {
        for key in ["oneOf", "anyOf"] {
            let Some(members) = schemas[&name][key].as_array().cloned() else {
                continue;
            };
            let mut changed = members.clone();
            for (i, m) in members.iter().enumerate() {
                let inline = m.get("$ref").is_none()
                    && (m.get("properties").is_some() || m.get("allOf").is_some());
                if !inline {
                    continue;
                }
                let tag = tag_of(m, schemas).unwrap_or_else(|| format!("variant_{i}"));
                let new = format!("{name}{}", pascal(&tag));
                schemas.insert(new.clone(), m.clone());
                changed[i] = schema_ref(&new);
            }
            schemas[&name][key] = Value::Array(changed);
        }
    }
}

/// `S = allOf[U, X…]` with `U` a union of `U1…Un` becomes
/// `S = oneOf[S1…Sn]`, `Si = allOf[Ui, X…]`: the same set of documents, in
/// a form generators can make classes of (`EstimatorSpec` = the estimator
/// kind, flattened, plus the median prefilter fields).
fn distribute_allof_over_unions(schemas: &mut Schemas) {
    let names: Vec<String> = schemas.keys().cloned().collect();
    for name in names {
        let Some(all) = schemas[&name]["allOf"].as_array().cloned() else {
            continue;
        };
        for (j, m) in all.iter().enumerate() {
            let Some(u) = ref_name(m).and_then(|n| schemas.get(n)).cloned() else {
                continue;
            };
            let Some((key, members)) = ["oneOf", "anyOf"]
                .iter()
                .find_map(|k| u[*k].as_array().map(|a| (*k, a.clone())))
            else {
                continue;
            };
            let rest: Vec<Value> = all
                .iter()
                .enumerate()
                .filter(|(i, _)| *i != j)
                .map(|(_, x)| x.clone())
                .collect();
            let mut variants = Vec::new();
            for um in &members {
                let Some(un) = ref_name(um) else { continue };
                let tag = tag_of(um, schemas).unwrap_or_else(|| un.to_string());
                let new = format!("{name}{}", pascal(&tag));
                let mut parts = vec![um.clone()];
                parts.extend(rest.iter().cloned());
                let mut v = serde_json::json!({ "allOf": parts });
                if let Some(d) = schemas[un].get("description") {
                    v["description"] = d.clone();
                }
                schemas.insert(new.clone(), v);
                variants.push(schema_ref(&new));
            }
            let s = schemas[&name].as_object_mut().expect("a schema object");
            s.remove("allOf");
            s.insert(key.to_string(), Value::Array(variants));
            break;
        }
    }
}

/// A one-value `kind` enum is a `const`: clients type it as that literal.
fn tags_as_const(schemas: &mut Schemas) {
    fn fix(s: &mut Value) {
        let Some(k) = s.get_mut("properties").and_then(|p| p.get_mut("kind")) else {
            return;
        };
        if let Some([one]) = k.get("enum").and_then(Value::as_array).map(Vec::as_slice) {
            *k = serde_json::json!({ "type": "string", "const": one.clone() });
        }
    }
    for s in schemas.values_mut() {
        if s.get("properties").is_some() {
            fix(s);
        }
        if let Some(all) = s.get_mut("allOf").and_then(Value::as_array_mut) {
            for sub in all.iter_mut().filter(|x| x.get("properties").is_some()) {
                fix(sub);
            }
        }
    }
}

/// A schema used as an `allOf` member must not forbid extra properties:
/// serde's `deny_unknown_fields` becomes `additionalProperties: false`,
/// which inside allOf forbids the sibling `kind` and makes the whole
/// unsatisfiable. (The variants are closed again below.)
fn open_allof_members(schemas: &mut Schemas) {
    let mut targets = std::collections::BTreeSet::new();
    fn walk(x: &Value, out: &mut std::collections::BTreeSet<String>) {
        match x {
            Value::Object(o) => {
                if let Some(all) = o.get("allOf").and_then(Value::as_array) {
                    out.extend(all.iter().filter_map(ref_name).map(str::to_owned));
                }
                o.values().for_each(|v| walk(v, out));
            }
            Value::Array(a) => a.iter().for_each(|v| walk(v, out)),
            _ => {}
        }
    }
    for s in schemas.values() {
        walk(s, &mut targets);
    }
    for t in targets {
        if let Some(o) = schemas.get_mut(&t).and_then(Value::as_object_mut) {
            if o.get("additionalProperties") == Some(&Value::Bool(false)) {
                o.remove("additionalProperties");
            }
        }
    }
}

/// The server rejects unknown fields: each variant of these unions says so
/// with `unevaluatedProperties: false`, which (unlike additionalProperties)
/// sees the properties of every allOf member.
fn close_variants(schemas: &mut Schemas, unions: &[&str]) {
    for u in unions {
        let members: Vec<String> = schemas
            .get(*u)
            .and_then(|s| s["oneOf"].as_array())
            .map(|a| a.iter().filter_map(ref_name).map(str::to_owned).collect())
            .unwrap_or_default();
        for m in members {
            if let Some(o) = schemas.get_mut(&m).and_then(Value::as_object_mut) {
                o.insert("unevaluatedProperties".into(), Value::Bool(false));
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
