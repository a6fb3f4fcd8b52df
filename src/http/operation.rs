//! The generic synchronous path of an [`Operation`]: fetch its input
//! datasets, run it on the solver pool, store its arrays as datasets.
//!
//! Endpoint handlers of new operations are three lines over these two
//! functions; the job queue uses the same [`OpOutput`] and stores it its way.

use std::collections::HashMap;
use std::sync::Arc;

use serde_json::{Map, Value};

use super::error::ApiError;
use super::routes::grid::DatasetRef;
use super::AppState;
use crate::datasets::{SourceFormat, StoreError};
use crate::ops::{InputArray, OpError, OpOutput, Operation};
use crate::pool::JobTiming;

/// Validates `request`, loads the datasets it names (those already in
/// `inputs`, such as an uploaded file, are kept), and runs it on the pool
/// under the request deadline.
pub async fn run_on_pool<O: Operation>(
    state: &AppState,
    request: O,
    mut inputs: HashMap<String, InputArray>,
) -> Result<(OpOutput, JobTiming), ApiError> {
    request.validate(&state.op_limits)?;
    for (field, id) in request.dataset_ids() {
        if inputs.contains_key(&id) {
            continue;
        }
        match state.store.load(&id).await {
            Ok(input) => {
                inputs.insert(id, input);
            }
            Err(StoreError::NotFound(_)) => {
                return Err(OpError::UnknownDataset { field, id }.into());
            }
            Err(e) => return Err(e.into()),
        }
    }
    let limits = state.op_limits;
    let (result, timing) = state
        .pool
        .run(O::NAME, state.solve_timeout, move |control| {
            request.run(&inputs, &limits, control)
        })
        .await?;
    Ok((result?, timing))
}

/// Stores every array of `output` as a result dataset and returns the
/// answer document: `output.document` with one [`DatasetRef`] per array,
/// under the array's name.
pub async fn store_output(state: &AppState, output: OpOutput) -> Result<Value, ApiError> {
    let mut doc = match output.document {
        Value::Object(map) => map,
        Value::Null => Map::new(),
        other => {
            let mut map = Map::new();
            map.insert("result".into(), other);
            map
        }
    };
    for out in output.arrays {
        let meta = state
            .store
            .create(Arc::new(out.array), out.spacing, SourceFormat::Result)
            .await?;
        let reference =
            serde_json::to_value(DatasetRef::from(&meta)).map_err(ApiError::internal)?;
        doc.insert(out.name, reference);
    }
    Ok(Value::Object(doc))
}
