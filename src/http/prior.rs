//! A map's prior given as a finished run (`{"prior": {"run": "<id>"}}`,
//! issue 46): read when the spec is accepted, and stored in its place as
//! that run's boundary, so that the stored spec runs the same on any
//! worker and after any restart, whatever happens to the run it names.

use super::AppState;
use super::Problem;
use crate::error::SpecError;
use crate::experiment::ExperimentSpec;
use crate::store::ExperimentState;
use crate::zwidth::prior::Prior;
use crate::zwidth::search::BoundaryPoint;

/// Replace a map's `prior.run` by that run's boundary; a run that is not
/// a succeeded map is refused, naming `prior.run`.
pub async fn resolve_run_prior(st: &AppState, spec: &mut ExperimentSpec) -> Result<(), Problem> {
    let ExperimentSpec::Map(map) = spec else {
        return Ok(());
    };
    let Some(Prior::Run(id)) = &map.prior else {
        return Ok(());
    };
    let refuse = |why: String| Problem::from(SpecError::new("prior.run", format!("{id:?}"), why));
    let row = st
        .store
        .get(id)
        .await
        .map_err(|e| st.fail(e))?
        .ok_or_else(|| refuse("names no experiment: give a finished map run's id".into()))?;
    if row.kind != "map" {
        return Err(refuse(format!(
            "is a {} experiment: a prior is a map run's boundary",
            row.kind
        )));
    }
    let (ExperimentState::Succeeded, Some(result)) = (row.state, row.result.as_deref()) else {
        return Err(refuse(format!(
            "is {}: a prior is the boundary of a map that has succeeded",
            row.state
        )));
    };
    let boundary = serde_json::from_str::<serde_json::Value>(result)
        .ok()
        .and_then(|mut v| v.get_mut("boundary").map(serde_json::Value::take))
        .and_then(|b| serde_json::from_value::<Vec<BoundaryPoint>>(b).ok())
        .ok_or_else(|| refuse("has no boundary in its stored result".into()))?;
    map.prior = Some(Prior::Boundary(boundary));
    Ok(())
}
