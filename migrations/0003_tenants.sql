-- geodex API keys and tenants (issue 20). A key belongs to one tenant; every
-- job and collection row carries its tenant ('' when auth is off), and the
-- queries of another tenant do not see it. Datasets keep their tenant in
-- their meta.json. Portable SQL, as 0001_jobs.sql; times are milliseconds
-- since the Unix epoch (UTC).
CREATE TABLE geodex_api_keys (
    id            TEXT PRIMARY KEY,        -- key_<16 hex>: the public half of the key
    tenant        TEXT NOT NULL,           -- what the key's requests own and see
    name          TEXT NOT NULL,           -- the operator's label
    secret_sha256 TEXT NOT NULL,           -- hex SHA-256 of the secret half (never the secret)
    admin         BOOLEAN NOT NULL DEFAULT FALSE, -- may read /metrics and /readyz details
    quota_bytes   BIGINT,                  -- storage of the tenant; NULL: --tenant-quota-bytes
    rate_per_sec  DOUBLE PRECISION,        -- token bucket refill; NULL: --rate-limit-per-sec
    burst         BIGINT,                  -- token bucket size; NULL: --rate-limit-burst
    created_at    BIGINT NOT NULL,
    revoked_at    BIGINT                   -- set by `geodex keys revoke`
);

ALTER TABLE geodex_jobs ADD COLUMN tenant TEXT NOT NULL DEFAULT '';
ALTER TABLE geodex_collections ADD COLUMN tenant TEXT NOT NULL DEFAULT '';
CREATE INDEX geodex_jobs_tenant ON geodex_jobs (tenant, id);
CREATE INDEX geodex_collections_tenant ON geodex_collections (tenant, id);
