//! Shape collections (issue 19, item 4): named sets of geodesic shape
//! descriptors ([`crate::numerics::shape::descriptor`]) that a query mesh is
//! ranked against, best first.
//!
//! A collection fixes the descriptor options (landmarks, bins, method) of
//! all its shapes, so that every descriptor in it is comparable. Adding a
//! shape and querying both compute a descriptor with the operation
//! `mesh.descriptor` (through the one runner, on the solver pool: the HTTP
//! layer does that), then this store keeps or ranks the vector.
//!
//! The tables live in the jobs' database (`migrations/0002_collections.sql`,
//! migrated with the job table by [`crate::jobs::JobDb`]): SQLite by default,
//! PostgreSQL when the service is scaled out, so every replica answers for
//! every collection and collections survive restarts.

pub mod db;

use chrono::{DateTime, TimeZone, Utc};
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use crate::jobs::{now_ms, DbError, JobDb};
use crate::numerics::shape::descriptor::{descriptor_distance, Descriptor};
use crate::ops::mesh_descriptor::DescriptorSpec;
use crate::ops::spec::mesh::MeshMethodSpec;
use crate::problem::ApiError;
pub use db::{CollectionRow, ShapeRow};

/// Why a collection request failed outside the client's control.
#[derive(Debug, thiserror::Error)]
pub enum CollectionError {
    /// The database failed.
    #[error(transparent)]
    Db(#[from] DbError),
    /// A stored row does not decode (a descriptor or method written by
    /// another version).
    #[error("stored collection data: {0}")]
    Corrupt(String),
}

impl From<CollectionError> for ApiError {
    fn from(e: CollectionError) -> Self {
        match e {
            CollectionError::Db(e) => e.into(),
            CollectionError::Corrupt(e) => ApiError::internal(e),
        }
    }
}

/// A collection, as the API shows it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[schema(example = json!({
    "id": "col_0192f1b27c1e7d3a9d553c0f2b8a1e44",
    "url": "/v1/collections/col_0192f1b27c1e7d3a9d553c0f2b8a1e44",
    "name": "poses",
    "descriptor": {"landmarks": 32, "bins": 32, "method": "fast_marching"},
    "shapes": 2,
    "created_at": "2026-11-22T10:00:00Z"
}))]
pub struct Collection {
    /// `col_` followed by 32 hex digits.
    pub id: String,
    /// This resource.
    pub url: String,
    /// The name given at creation.
    pub name: String,
    /// How every shape's descriptor is computed.
    pub descriptor: DescriptorSpec,
    /// Shapes in the collection.
    pub shapes: i64,
    /// Creation time (UTC).
    pub created_at: DateTime<Utc>,
}

/// A shape of a collection.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct CollectionShape {
    /// `shp_` followed by 32 hex digits.
    pub id: String,
    /// The collection.
    pub collection: String,
    /// The name given when it was added.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// The class label given when it was added.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub label: Option<String>,
    /// The mesh dataset it was computed from (the dataset may have expired
    /// since: the descriptor is kept).
    pub dataset: String,
    /// Vertices of that mesh.
    pub vertices: i64,
    /// When it was added (UTC).
    pub created_at: DateTime<Utc>,
}

/// A shape and how close it is to the query.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct Match {
    /// The shape.
    pub shape: CollectionShape,
    /// Descriptor distance to the query, in `[0, 1]` (0: the same
    /// descriptor; see `numerics::shape::descriptor`).
    pub distance: f64,
    /// `1 − distance`: 1 for the same descriptor.
    pub score: f64,
}

/// A time of the tables (ms since the epoch) as a UTC date.
fn time(ms: i64) -> DateTime<Utc> {
    Utc.timestamp_millis_opt(ms).single().unwrap_or_default()
}

fn method_name(m: MeshMethodSpec) -> Result<String, CollectionError> {
    match serde_json::to_value(m) {
        Ok(serde_json::Value::String(s)) => Ok(s),
        other => Err(CollectionError::Corrupt(format!("method {other:?}"))),
    }
}

impl TryFrom<&CollectionRow> for Collection {
    type Error = CollectionError;

    fn try_from(r: &CollectionRow) -> Result<Self, CollectionError> {
        let method: MeshMethodSpec = serde_json::from_value(r.method.clone().into())
            .map_err(|e| CollectionError::Corrupt(format!("method '{}': {e}", r.method)))?;
        let count = |x: i64, what: &str| {
            usize::try_from(x).map_err(|_| CollectionError::Corrupt(format!("{what} {x}")))
        };
        Ok(Collection {
            url: format!("/v1/collections/{}", r.id),
            id: r.id.clone(),
            name: r.name.clone(),
            descriptor: DescriptorSpec {
                landmarks: count(r.landmarks, "landmarks")?,
                bins: count(r.bins, "bins")?,
                method,
            },
            shapes: r.shapes,
            created_at: time(r.created_at),
        })
    }
}

impl From<&ShapeRow> for CollectionShape {
    fn from(r: &ShapeRow) -> Self {
        CollectionShape {
            id: r.id.clone(),
            collection: r.collection_id.clone(),
            name: r.name.clone(),
            label: r.label.clone(),
            dataset: r.dataset_id.clone(),
            vertices: r.vertices,
            created_at: time(r.created_at),
        }
    }
}

/// True if `id` has the shape of an id with this prefix (`col_`, `shp_`).
pub fn valid_id(id: &str, prefix: &str) -> bool {
    id.len() == prefix.len() + 32
        && id.starts_with(prefix)
        && id[prefix.len()..]
            .bytes()
            .all(|b| b.is_ascii_hexdigit() && !b.is_ascii_uppercase())
}

/// A shape to add, its descriptor computed.
#[derive(Debug, Clone)]
pub struct NewShape {
    /// The client's name.
    pub name: Option<String>,
    /// The client's class label.
    pub label: Option<String>,
    /// The mesh dataset.
    pub dataset: String,
    /// Vertices of the mesh.
    pub vertices: i64,
    /// The descriptor vector.
    pub descriptor: Vec<f64>,
}

/// The collection store of one process (over the jobs' database).
#[derive(Debug, Clone)]
pub struct Collections {
    db: JobDb,
}

impl Collections {
    /// The store over the database the jobs opened (and migrated).
    pub fn new(db: JobDb) -> Self {
        Self { db }
    }

    /// Creates an empty collection.
    pub async fn create(
        &self,
        name: &str,
        spec: DescriptorSpec,
        tenant: &str,
    ) -> Result<Collection, CollectionError> {
        let row = CollectionRow {
            id: format!("col_{}", uuid::Uuid::now_v7().simple()),
            name: name.to_string(),
            landmarks: spec.landmarks as i64,
            bins: spec.bins as i64,
            method: method_name(spec.method)?,
            created_at: now_ms(),
            shapes: 0,
            tenant: tenant.to_string(),
        };
        db::insert_collection(&self.db, &row).await?;
        Collection::try_from(&row)
    }

    /// The collection of `tenant` with this id (another tenant's is `None`).
    pub async fn get(&self, id: &str, tenant: &str) -> Result<Option<Collection>, CollectionError> {
        match db::get_collection(&self.db, id, tenant).await? {
            Some(r) => Ok(Some(Collection::try_from(&r)?)),
            None => Ok(None),
        }
    }

    /// Collections of `tenant`, newest first, with ids below `before`.
    pub async fn list(
        &self,
        tenant: &str,
        before: Option<&str>,
        limit: i64,
    ) -> Result<Vec<Collection>, CollectionError> {
        db::list_collections(&self.db, tenant, before, limit)
            .await?
            .iter()
            .map(Collection::try_from)
            .collect()
    }

    /// Deletes a collection of `tenant` and its shapes; false if it has
    /// none with this id.
    pub async fn delete(&self, id: &str, tenant: &str) -> Result<bool, CollectionError> {
        Ok(db::delete_collection(&self.db, id, tenant).await?)
    }

    /// The shapes of a collection, oldest first (the caller checked, with
    /// [`Self::get`], that the collection is its tenant's).
    pub async fn shapes(&self, id: &str) -> Result<Vec<CollectionShape>, CollectionError> {
        Ok(db::shapes(&self.db, id)
            .await?
            .iter()
            .map(CollectionShape::from)
            .collect())
    }

    /// Adds a shape; `None` when the collection does not exist (any more).
    pub async fn add(
        &self,
        collection: &str,
        shape: NewShape,
    ) -> Result<Option<CollectionShape>, CollectionError> {
        let row = ShapeRow {
            id: format!("shp_{}", uuid::Uuid::now_v7().simple()),
            collection_id: collection.to_string(),
            name: shape.name,
            label: shape.label,
            dataset_id: shape.dataset,
            descriptor: serde_json::to_string(&shape.descriptor)
                .map_err(|e| CollectionError::Corrupt(e.to_string()))?,
            vertices: shape.vertices,
            created_at: now_ms(),
        };
        if db::insert_shape(&self.db, &row).await? {
            Ok(Some(CollectionShape::from(&row)))
        } else {
            Ok(None)
        }
    }

    /// The `k` shapes of a collection nearest to the descriptor `query`,
    /// nearest first (ties by age). The ranking runs on a blocking thread.
    pub async fn nearest(
        &self,
        collection: &str,
        query: Vec<f64>,
        k: usize,
    ) -> Result<Vec<Match>, CollectionError> {
        let rows = db::shapes(&self.db, collection).await?;
        tokio::task::spawn_blocking(move || rank(&rows, &query, k))
            .await
            .map_err(|e| CollectionError::Corrupt(format!("ranking: {e}")))?
    }
}

/// The `k` rows nearest to `query` by descriptor distance.
pub fn rank(rows: &[ShapeRow], query: &[f64], k: usize) -> Result<Vec<Match>, CollectionError> {
    let q = Descriptor::from_vector(query).map_err(|e| CollectionError::Corrupt(e.to_string()))?;
    let mut scored = Vec::with_capacity(rows.len());
    for (i, r) in rows.iter().enumerate() {
        let v: Vec<f64> = serde_json::from_str(&r.descriptor)
            .map_err(|e| CollectionError::Corrupt(format!("descriptor of {}: {e}", r.id)))?;
        let d = Descriptor::from_vector(&v)
            .and_then(|d| descriptor_distance(&q, &d))
            .map_err(|e| CollectionError::Corrupt(format!("descriptor of {}: {e}", r.id)))?;
        scored.push((d, i));
    }
    scored.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    Ok(scored
        .into_iter()
        .take(k)
        .map(|(d, i)| Match {
            shape: CollectionShape::from(&rows[i]),
            distance: d,
            score: 1.0 - d,
        })
        .collect())
}
