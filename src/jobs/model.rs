//! The job model: what describes a job rather than acts on it.
//!
//! The public resource ([`Job`]) and its parts ([`JobState`], [`Priority`],
//! [`ResultRef`]), the body of a submission ([`SubmitJob`]), where an output
//! array is stored ([`StoredOutput`]), the problems a job ends with, job ids
//! and the millisecond times of the `geodex_jobs` table.

use std::fmt;
use std::str::FromStr;
use std::time::Duration;

use chrono::{DateTime, TimeZone, Utc};
use serde::{Deserialize, Serialize};
use serde_json::Value;
use utoipa::ToSchema;

use super::db::JobRow;
use crate::io::DType;
use crate::problem::{ApiError, Kind, Problem};

/// Priority of a job: interactive jobs are claimed before batch jobs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum Priority {
    /// Someone is waiting: claimed first.
    Interactive,
    /// Background work (the default of `POST /v1/jobs`).
    Batch,
}

impl Priority {
    /// The `priority` column: 1 interactive, 0 batch (higher is claimed first).
    pub(crate) fn rank(self) -> i64 {
        match self {
            Priority::Interactive => 1,
            Priority::Batch => 0,
        }
    }

    /// The priority of a `priority` column value.
    pub(crate) fn from_rank(r: i64) -> Self {
        if r > 0 {
            Priority::Interactive
        } else {
            Priority::Batch
        }
    }
}

/// State of a job.
// The doc line above is this schema's description in api/openapi.json; the
// note on the names is on `as_str`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum JobState {
    /// Waiting for a worker.
    Queued,
    /// A worker runs it.
    Running,
    /// Done; `result` holds the answer.
    Succeeded,
    /// Ended with `error`.
    Failed,
    /// Cancelled on request; `error` says so.
    Cancelled,
}

impl JobState {
    /// Every state, in the order of a job's life.
    pub const ALL: [JobState; 5] = [
        JobState::Queued,
        JobState::Running,
        JobState::Succeeded,
        JobState::Failed,
        JobState::Cancelled,
    ];

    /// The wire (and database) name: the one mapping to the names in the
    /// `state` column and in JSON ([`FromStr`] reads it back; serde's names
    /// are the same, which a test checks).
    pub const fn as_str(self) -> &'static str {
        match self {
            JobState::Queued => "queued",
            JobState::Running => "running",
            JobState::Succeeded => "succeeded",
            JobState::Failed => "failed",
            JobState::Cancelled => "cancelled",
        }
    }

    /// True once the job can no longer change.
    pub fn is_final(self) -> bool {
        matches!(
            self,
            JobState::Succeeded | JobState::Failed | JobState::Cancelled
        )
    }
}

impl fmt::Display for JobState {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// A `state` value that names no [`JobState`].
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown job state '{0}'")]
pub struct UnknownState(pub String);

impl FromStr for JobState {
    type Err = UnknownState;

    fn from_str(s: &str) -> Result<Self, UnknownState> {
        JobState::ALL
            .into_iter()
            .find(|state| state.as_str() == s)
            .ok_or_else(|| UnknownState(s.to_string()))
    }
}

/// Body of `POST /v1/jobs`.
#[derive(Debug, Clone, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({
    "operation": "grid.distance",
    "params": {"cost": {"constant": 1.0, "shape": [256, 256]}, "sources": [{"point": [128.0, 128.0]}]},
    "priority": "batch",
    "time_limit_secs": 600
}))]
pub struct SubmitJob {
    /// The operation: `grid.distance`, `grid.metric`, `grid.paths`, `grid.edt`, `grid.segment`,
    /// `grid.skeleton`, `grid.offset`, `grid.plan`, `grid.tensor_distance`, `grid.tensor_metric`,
    /// `mesh.distance`, `mesh.voronoi`, `mesh.paths` or `mesh.sample`.
    pub operation: String,
    /// The same body as the operation's synchronous endpoint.
    #[schema(value_type = Object)]
    pub params: Value,
    /// `interactive` jobs are claimed before `batch` ones. Default: `batch`.
    #[serde(default)]
    pub priority: Option<Priority>,
    /// Time limit of one attempt in seconds; past it the job ends `failed`.
    /// Default: the service's `--job-time-limit-secs`.
    #[serde(default)]
    #[schema(minimum = 0.0)]
    pub time_limit_secs: Option<f64>,
}

/// A stored result array of a job.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct ResultRef {
    /// URL of the array (`?format=npy|tiff|png16|png|json`, default NPY).
    pub url: String,
    /// Shape, axis 0 first.
    pub shape: Vec<usize>,
    /// Element type.
    pub dtype: DType,
    /// Bytes of the NPY object.
    pub byte_size: u64,
}

/// Where an output array is stored (the `outputs` column).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StoredOutput {
    /// Object key.
    pub key: String,
    /// Shape.
    pub shape: Vec<usize>,
    /// Element type.
    pub dtype: DType,
    /// Bytes.
    pub byte_size: u64,
    /// Physical spacing, if any.
    pub spacing: Option<Vec<f64>>,
}

/// A job, as `GET /v1/jobs/{id}` shows it.
#[derive(Debug, Clone, Serialize, ToSchema)]
#[schema(example = json!({
    "id": "job_0192f1b27c1e7d3a9d553c0f2b8a1e44",
    "url": "/v1/jobs/job_0192f1b27c1e7d3a9d553c0f2b8a1e44",
    "operation": "grid.distance",
    "state": "succeeded",
    "priority": "batch",
    "progress": 1.0,
    "attempts": 1,
    "max_attempts": 3,
    "time_limit_secs": 3600.0,
    "cancel_requested": false,
    "created_at": "2026-11-22T10:00:00Z",
    "started_at": "2026-11-22T10:00:00.010Z",
    "finished_at": "2026-11-22T10:00:02Z",
    "expires_at": "2026-11-29T10:00:02Z",
    "params": {"cost": {"constant": 1.0, "shape": [256, 256]}, "sources": [{"point": [128.0, 128.0]}]},
    "result": {
        "distance": {"url": "/v1/jobs/job_0192f1b27c1e7d3a9d553c0f2b8a1e44/results/distance", "shape": [256, 256], "dtype": "f64", "byte_size": 524416},
        "stats": {"cells": 65536, "frozen": 65536, "stop": "completed", "solve_seconds": 0.012}
    }
}))]
pub struct Job {
    /// `job_` followed by 32 hex digits.
    pub id: String,
    /// This resource.
    pub url: String,
    /// The operation.
    pub operation: String,
    /// `queued`, `running`, `succeeded`, `failed` or `cancelled`.
    pub state: JobState,
    /// `interactive` or `batch`.
    pub priority: Priority,
    /// Fraction done, 0..1, reported by the solver (1 when succeeded).
    pub progress: f64,
    /// Attempts started (more than 1 when a worker died and the job ran again).
    pub attempts: i64,
    /// Attempts allowed.
    pub max_attempts: i64,
    /// Time limit of one attempt, seconds.
    pub time_limit_secs: f64,
    /// Cancellation was asked for.
    pub cancel_requested: bool,
    /// Submission time (UTC).
    pub created_at: DateTime<Utc>,
    /// Start of the latest attempt.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub started_at: Option<DateTime<Utc>>,
    /// End time.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub finished_at: Option<DateTime<Utc>>,
    /// When the record and its results are removed.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub expires_at: Option<DateTime<Utc>>,
    /// The request.
    #[schema(value_type = Object)]
    pub params: Value,
    /// When succeeded: the operation's document, with one [`ResultRef`] per
    /// output array under the array's name.
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schema(value_type = Object)]
    pub result: Option<Value>,
    /// When failed or cancelled: why, as a problem.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<Problem>,
}

/// A time of the table (ms since the epoch) as a UTC date.
fn time(ms: i64) -> DateTime<Utc> {
    Utc.timestamp_millis_opt(ms).single().unwrap_or_default()
}

impl From<&JobRow> for Job {
    fn from(r: &JobRow) -> Self {
        Job {
            url: format!("/v1/jobs/{}", r.id),
            id: r.id.clone(),
            operation: r.operation.clone(),
            state: r.state,
            priority: Priority::from_rank(r.priority),
            progress: r.progress,
            attempts: r.attempts,
            max_attempts: r.max_attempts,
            time_limit_secs: r.time_limit_ms as f64 / 1000.0,
            cancel_requested: r.cancel_requested,
            created_at: time(r.created_at),
            started_at: r.started_at.map(time),
            finished_at: r.finished_at.map(time),
            expires_at: r.expires_at.map(time),
            params: serde_json::from_str(&r.params).unwrap_or(Value::Null),
            result: r
                .result
                .as_deref()
                .and_then(|s| serde_json::from_str(s).ok()),
            error: r
                .error
                .as_deref()
                .and_then(|s| serde_json::from_str(s).ok()),
        }
    }
}

/// Milliseconds since the epoch, now.
pub fn now_ms() -> i64 {
    Utc::now().timestamp_millis()
}

/// A duration in milliseconds, as the table stores it (saturating).
pub(crate) fn ms(d: Duration) -> i64 {
    i64::try_from(d.as_millis()).unwrap_or(i64::MAX)
}

/// True if `id` has the shape of a job id (and so is safe in a key).
pub fn valid_id(id: &str) -> bool {
    id.len() == 36
        && id.starts_with("job_")
        && id[4..]
            .bytes()
            .all(|b| b.is_ascii_hexdigit() && !b.is_ascii_uppercase())
}

/// Builds the problem stored in a job record.
pub fn problem_json(e: &ApiError, job: &str) -> String {
    let mut p = (*e.problem).clone();
    p.instance = (!job.is_empty()).then(|| format!("/v1/jobs/{job}"));
    serde_json::to_string(&p).unwrap_or_default()
}

/// The problem of a cancelled job.
pub fn cancelled_problem() -> ApiError {
    ApiError::of(
        Kind::Cancelled,
        "the job was cancelled on request before it finished",
    )
}

/// The problem of a job stopped at its time limit.
pub fn time_limit_problem(limit_ms: i64) -> ApiError {
    ApiError::of(
        Kind::TimeLimit,
        format!(
            "the job ran past its time limit of {} s and was stopped; submit it again with a larger \
             time_limit_secs or a smaller problem",
            limit_ms as f64 / 1000.0
        ),
    )
    .with_field("time_limit_secs")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn state_names_are_one_mapping() {
        for state in JobState::ALL {
            assert_eq!(state.as_str().parse::<JobState>(), Ok(state));
            assert_eq!(state.to_string(), state.as_str());
            let wire = serde_json::to_value(state).unwrap();
            assert_eq!(wire, Value::String(state.as_str().into()));
            assert_eq!(serde_json::from_value::<JobState>(wire).unwrap(), state);
        }
        assert_eq!("done".parse::<JobState>(), Err(UnknownState("done".into())));
    }

    #[test]
    fn ids() {
        assert!(valid_id("job_0192f1b27c1e7d3a9d553c0f2b8a1e44"));
        assert!(!valid_id("job_0192F1B27C1E7D3A9D553C0F2B8A1E44"));
        assert!(!valid_id("job_../../etc"));
    }
}
