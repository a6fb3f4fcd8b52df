-- geodex jobs: one table that is both the queue and the public job resource.
-- Portable SQL: the same file migrates SQLite and PostgreSQL, so both engines
-- have the same shape. Times are milliseconds since the Unix epoch (UTC).
CREATE TABLE geodex_jobs (
    id               TEXT PRIMARY KEY,             -- job_<uuid v7>, time-ordered
    operation        TEXT NOT NULL,                -- ops::Operation::NAME (grid.distance)
    params           TEXT NOT NULL,                -- the request, canonical JSON
    state            TEXT NOT NULL,                -- queued | running | succeeded | failed | cancelled
    priority         BIGINT NOT NULL,              -- 1 interactive, 0 batch; higher runs first
    time_limit_ms    BIGINT NOT NULL,              -- per attempt
    attempts         BIGINT NOT NULL DEFAULT 0,    -- claims so far; also the lease's fencing token
    max_attempts     BIGINT NOT NULL,
    lease_owner      TEXT,                         -- worker id holding the lease
    lease_until      BIGINT,                       -- renewed by the heartbeat
    cancel_requested BOOLEAN NOT NULL DEFAULT FALSE,
    progress         DOUBLE PRECISION NOT NULL DEFAULT 0,
    idempotency_key  TEXT UNIQUE,                  -- several NULLs are allowed by both engines
    request_hash     TEXT,                         -- fingerprint of the request sent with the key
    result           TEXT,                         -- JSON document when succeeded
    outputs          TEXT,                         -- JSON: name -> object key, shape, dtype, bytes
    error            TEXT,                         -- problem+json when failed or cancelled
    created_at       BIGINT NOT NULL,
    started_at       BIGINT,
    finished_at      BIGINT,
    updated_at       BIGINT NOT NULL,
    expires_at       BIGINT                        -- retention: set when the job ends
);

CREATE INDEX geodex_jobs_claim ON geodex_jobs (state, priority DESC, id);
CREATE INDEX geodex_jobs_lease ON geodex_jobs (state, lease_until);
CREATE INDEX geodex_jobs_expiry ON geodex_jobs (expires_at);
