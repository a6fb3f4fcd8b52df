//! The collection tables over the jobs' connection pool
//! (`migrations/0002_collections.sql`, migrated with the job table by
//! [`crate::jobs::JobDb`]): every statement is written once with `$n`
//! placeholders, which SQLite and PostgreSQL both accept.

use sqlx::Row;

use crate::jobs::db::on_pool;
use crate::jobs::{DbError, JobDb};

/// One row of `geodex_collections`, with its shape count.
#[derive(Debug, Clone, PartialEq)]
pub struct CollectionRow {
    /// `col_` + 32 hex digits.
    pub id: String,
    /// The client's name.
    pub name: String,
    /// Descriptor landmarks.
    pub landmarks: i64,
    /// Descriptor bins.
    pub bins: i64,
    /// Distance method (`fast_marching`, …).
    pub method: String,
    /// ms since the epoch.
    pub created_at: i64,
    /// Shapes in the collection.
    pub shapes: i64,
    /// The tenant that made it (`''` when auth is off).
    pub tenant: String,
}

/// One row of `geodex_collection_shapes`.
#[derive(Debug, Clone, PartialEq)]
pub struct ShapeRow {
    /// `shp_` + 32 hex digits.
    pub id: String,
    /// The collection.
    pub collection_id: String,
    /// The client's name.
    pub name: Option<String>,
    /// The client's class label.
    pub label: Option<String>,
    /// The mesh dataset the descriptor was computed from.
    pub dataset_id: String,
    /// The descriptor vector as a JSON array.
    pub descriptor: String,
    /// Vertices of the mesh.
    pub vertices: i64,
    /// ms since the epoch.
    pub created_at: i64,
}

const COLLECTION: &str =
    "SELECT c.id, c.name, c.landmarks, c.bins, c.method, c.created_at, c.tenant, \
(SELECT COUNT(*) FROM geodex_collection_shapes s WHERE s.collection_id = c.id) AS shapes \
FROM geodex_collections c";

const SHAPE: &str = "SELECT id, collection_id, name, label, dataset_id, descriptor, vertices, \
created_at FROM geodex_collection_shapes";

macro_rules! collection_row {
    ($r:expr) => {{
        let r = $r;
        CollectionRow {
            id: r.try_get("id")?,
            name: r.try_get("name")?,
            landmarks: r.try_get("landmarks")?,
            bins: r.try_get("bins")?,
            method: r.try_get("method")?,
            created_at: r.try_get("created_at")?,
            shapes: r.try_get("shapes")?,
            tenant: r.try_get("tenant")?,
        }
    }};
}

macro_rules! shape_row {
    ($r:expr) => {{
        let r = $r;
        ShapeRow {
            id: r.try_get("id")?,
            collection_id: r.try_get("collection_id")?,
            name: r.try_get("name")?,
            label: r.try_get("label")?,
            dataset_id: r.try_get("dataset_id")?,
            descriptor: r.try_get("descriptor")?,
            vertices: r.try_get("vertices")?,
            created_at: r.try_get("created_at")?,
        }
    }};
}

/// Inserts a collection (no shapes yet).
pub async fn insert_collection(db: &JobDb, row: &CollectionRow) -> Result<(), DbError> {
    let q = "INSERT INTO geodex_collections (id, name, landmarks, bins, method, created_at, \
             tenant) VALUES ($1, $2, $3, $4, $5, $6, $7)";
    on_pool!(db, p => sqlx::query(q)
        .bind(&row.id)
        .bind(&row.name)
        .bind(row.landmarks)
        .bind(row.bins)
        .bind(&row.method)
        .bind(row.created_at)
        .bind(&row.tenant)
        .execute(p)
        .await?
        .rows_affected());
    Ok(())
}

/// The collection of `tenant` with this id.
pub async fn get_collection(
    db: &JobDb,
    id: &str,
    tenant: &str,
) -> Result<Option<CollectionRow>, DbError> {
    let q = sqlx::AssertSqlSafe(format!("{COLLECTION} WHERE c.id = $1 AND c.tenant = $2"));
    Ok(on_pool!(db, p => {
        match sqlx::query(q).bind(id).bind(tenant).fetch_optional(p).await? {
            Some(r) => Some(collection_row!(&r)),
            None => None,
        }
    }))
}

/// Collections of `tenant`, newest first, with ids below `before`.
pub async fn list_collections(
    db: &JobDb,
    tenant: &str,
    before: Option<&str>,
    limit: i64,
) -> Result<Vec<CollectionRow>, DbError> {
    let q = sqlx::AssertSqlSafe(format!(
        "{COLLECTION} WHERE c.tenant = $1 AND ($2 IS NULL OR c.id < $2) ORDER BY c.id DESC LIMIT $3"
    ));
    Ok(on_pool!(db, p => {
        let rows = sqlx::query(q).bind(tenant).bind(before).bind(limit).fetch_all(p).await?;
        let mut out = Vec::with_capacity(rows.len());
        for r in &rows {
            out.push(collection_row!(r));
        }
        out
    }))
}

/// Deletes a collection of `tenant` and its shapes; false if it has none
/// with this id.
pub async fn delete_collection(db: &JobDb, id: &str, tenant: &str) -> Result<bool, DbError> {
    let shapes = "DELETE FROM geodex_collection_shapes WHERE collection_id = $1 AND EXISTS \
                  (SELECT 1 FROM geodex_collections WHERE id = $1 AND tenant = $2)";
    let collection = "DELETE FROM geodex_collections WHERE id = $1 AND tenant = $2";
    let done = on_pool!(db, p => {
        let mut tx = p.begin().await?;
        sqlx::query(shapes).bind(id).bind(tenant).execute(&mut *tx).await?;
        let n = sqlx::query(collection)
            .bind(id)
            .bind(tenant)
            .execute(&mut *tx)
            .await?
            .rows_affected();
        tx.commit().await?;
        n
    });
    Ok(done == 1)
}

/// Inserts a shape into its collection; false (and nothing inserted) when
/// the collection does not exist.
pub async fn insert_shape(db: &JobDb, row: &ShapeRow) -> Result<bool, DbError> {
    let q = "INSERT INTO geodex_collection_shapes (id, collection_id, name, label, dataset_id, \
             descriptor, vertices, created_at) \
             SELECT $1, id, $3, $4, $5, $6, $7, $8 FROM geodex_collections WHERE id = $2";
    let n = on_pool!(db, p => sqlx::query(q)
        .bind(&row.id)
        .bind(&row.collection_id)
        .bind(&row.name)
        .bind(&row.label)
        .bind(&row.dataset_id)
        .bind(&row.descriptor)
        .bind(row.vertices)
        .bind(row.created_at)
        .execute(p)
        .await?
        .rows_affected());
    Ok(n == 1)
}

/// Every shape of a collection, oldest first.
pub async fn shapes(db: &JobDb, collection_id: &str) -> Result<Vec<ShapeRow>, DbError> {
    let q = sqlx::AssertSqlSafe(format!("{SHAPE} WHERE collection_id = $1 ORDER BY id"));
    Ok(on_pool!(db, p => {
        let rows = sqlx::query(q).bind(collection_id).fetch_all(p).await?;
        let mut out = Vec::with_capacity(rows.len());
        for r in &rows {
            out.push(shape_row!(r));
        }
        out
    }))
}
