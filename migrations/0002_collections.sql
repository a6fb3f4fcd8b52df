-- geodex shape collections: named sets of shape descriptors that queries
-- rank by descriptor distance (POST /v1/collections/{id}/query). They live in
-- the jobs' database (SQLite by default, PostgreSQL when scaled out), so
-- every replica sees the same collections. Portable SQL, as 0001_jobs.sql;
-- times are milliseconds since the Unix epoch (UTC).
CREATE TABLE geodex_collections (
    id          TEXT PRIMARY KEY,          -- col_<uuid v7>, time-ordered
    name        TEXT NOT NULL,
    landmarks   BIGINT NOT NULL,           -- descriptor options, the same for every shape
    bins        BIGINT NOT NULL,
    method      TEXT NOT NULL,             -- fast_marching | heat | exact | dijkstra
    created_at  BIGINT NOT NULL
);

CREATE TABLE geodex_collection_shapes (
    id            TEXT PRIMARY KEY,        -- shp_<uuid v7>, time-ordered
    collection_id TEXT NOT NULL REFERENCES geodex_collections (id) ON DELETE CASCADE,
    name          TEXT,                    -- the client's name of the shape
    label         TEXT,                    -- the client's class of the shape
    dataset_id    TEXT NOT NULL,           -- the mesh dataset it was computed from (may expire)
    descriptor    TEXT NOT NULL,           -- JSON array of 2·bins + 9 numbers
    vertices      BIGINT NOT NULL,
    created_at    BIGINT NOT NULL
);

CREATE INDEX geodex_collection_shapes_of ON geodex_collection_shapes (collection_id, id);
