//! The synchronous path of an operation: the request goes through the one
//! runner ([`crate::runner::Runner::run`]) with the dataset store's inputs,
//! and its outputs become datasets.
//!
//! A handler is: decode the body into the operation's request, [`run`] it,
//! then encode ([`store_output`] for the usual JSON answer with dataset
//! references, or a direct encoding such as NPY bytes or GeoJSON).

use std::collections::HashMap;
use std::sync::Arc;
use std::time::Instant;

use serde_json::{Map, Value};

use super::routes::grid::DatasetRef;
use super::AppState;
use crate::datasets::inputs::StoreInputs;
use crate::datasets::SourceFormat;
use crate::io::mesh::write::VertexProperty;
use crate::io::ArrayData;
use crate::ops::{DynOperation, InputArray, OpOutput, OutputMesh};
use crate::pool::JobTiming;
use crate::problem::ApiError;
use crate::runner::{Ran, RunOptions};

/// Runs `op` with the store's datasets (plus `uploads`, arrays that came
/// with the request under their own ids) and the interactive cache, under
/// the request deadline.
pub async fn run(
    state: &AppState,
    op: Box<dyn DynOperation>,
    uploads: HashMap<String, InputArray>,
) -> Result<Ran, ApiError> {
    let mut inputs =
        StoreInputs::new(Arc::clone(&state.store)).for_tenant(super::auth::caller().tenant());
    inputs.arrays.extend(uploads);
    let options = RunOptions::deadline(state.solve_timeout);
    Ok(state.runner.run(op, inputs, options).await?)
}

/// The usual JSON answer of `op`: [`run`], then [`store_output`], with
/// `queue_seconds` (waiting for a pool thread) and `total_seconds` (since
/// `started`) added to its `stats`.
pub async fn respond(
    state: &AppState,
    op: Box<dyn DynOperation>,
    started: Instant,
) -> Result<Map<String, Value>, ApiError> {
    let Ran { output, timing } = run(state, op, HashMap::new()).await?;
    let mut doc = store_output(state, output).await?;
    add_timing(&mut doc, &timing, started);
    Ok(doc)
}

/// Adds `queue_seconds` and `total_seconds` to the `stats` object of `doc`.
pub fn add_timing(doc: &mut Map<String, Value>, timing: &JobTiming, started: Instant) {
    if let Some(stats) = doc.get_mut("stats").and_then(Value::as_object_mut) {
        stats.insert("queue_seconds".into(), timing.queue_seconds.into());
        stats.insert(
            "total_seconds".into(),
            started.elapsed().as_secs_f64().into(),
        );
    }
}

/// Stores the outputs as result datasets of the caller's tenant and returns
/// the answer document:
/// the operation's document plus one [`DatasetRef`] per stored output under
/// its name. A mesh output is one mesh dataset carrying its arrays as
/// per-vertex properties; those arrays are not stored apart.
pub async fn store_output(
    state: &AppState,
    mut output: OpOutput,
) -> Result<Map<String, Value>, ApiError> {
    let owner = super::auth::caller().owner;
    let mut doc = output.document_map();
    let mut on_mesh: Vec<&'static str> = Vec::new();
    if let Some(mesh) = output.mesh.take() {
        on_mesh = mesh.vertex_properties.iter().map(|(_, a)| *a).collect();
        if let Some(reference) = store_mesh(state, &output, mesh.clone(), owner.clone()).await? {
            doc.insert(mesh.name, reference);
        }
    }
    for out in output.arrays {
        if on_mesh.contains(&out.name.as_str()) {
            continue;
        }
        let meta = state
            .store
            .create(
                Arc::new(out.array),
                out.spacing,
                SourceFormat::Result,
                owner.clone(),
            )
            .await?;
        doc.insert(out.name, to_value(DatasetRef::from(&meta))?);
    }
    Ok(doc)
}

/// Stores the mesh of `mesh` with its vertex properties; `None` when one of
/// its arrays is missing or of a type a PLY property cannot hold.
async fn store_mesh(
    state: &AppState,
    output: &OpOutput,
    mesh: OutputMesh,
    owner: crate::datasets::Owner,
) -> Result<Option<Value>, ApiError> {
    let mut columns: Vec<(&'static str, Column)> = Vec::new();
    for (property, array) in &mesh.vertex_properties {
        let column = match output.array(array) {
            Some(ArrayData::F64(a)) => Column::F64(a.iter().copied().collect()),
            Some(ArrayData::I32(a)) => Column::I32(a.iter().copied().collect()),
            _ => return Ok(None),
        };
        columns.push((property, column));
    }
    let store = Arc::clone(&state.store);
    let meta = crate::datasets::blocking(move || {
        let props: Vec<VertexProperty<'_>> = columns
            .iter()
            .map(|(name, c)| match c {
                Column::F64(v) => VertexProperty::F64(name, v),
                Column::I32(v) => VertexProperty::I32(name, v),
            })
            .collect();
        store.create_mesh_blocking(
            &mesh.mesh.mesh,
            mesh.mesh.report.clone(),
            &props,
            SourceFormat::Result,
            &owner,
        )
    })
    .await?;
    Ok(Some(to_value(DatasetRef::from(&meta))?))
}

/// One per-vertex property's values.
enum Column {
    F64(Vec<f64>),
    I32(Vec<i32>),
}

fn to_value(reference: DatasetRef) -> Result<Value, ApiError> {
    serde_json::to_value(reference).map_err(ApiError::internal)
}
