//! `geodex keys create|list|revoke`: the API keys of a service, in its jobs'
//! database (the same `--data-dir` / `--queue` as `geodex serve`).

use std::path::PathBuf;

use anyhow::Context;
use clap::{Args, Subcommand};

use crate::auth::{KeyDefaults, Keys, NewKey};
use crate::jobs::JobDb;

/// `geodex keys`.
#[derive(Debug, Args)]
pub struct KeysArgs {
    /// What to do.
    #[command(subcommand)]
    pub action: KeysAction,
    /// The service's data directory (its `jobs.sqlite` holds the keys with
    /// `--queue sqlite`).
    #[arg(
        long,
        env = "GEODEX_DATA_DIR",
        default_value = "geodex-data",
        global = true
    )]
    pub data_dir: PathBuf,
    /// The service's job database: `sqlite`, `sqlite:///path/jobs.db` or
    /// `postgres://user@host:port/db` (its value is never printed).
    #[arg(
        long,
        env = "GEODEX_QUEUE",
        default_value = "sqlite",
        hide_env_values = true,
        global = true
    )]
    pub queue: String,
}

/// The key commands.
#[derive(Debug, Subcommand)]
pub enum KeysAction {
    /// Create a key and print it (once: only its hash is stored).
    Create {
        /// The tenant the key acts for: what its requests store belongs to
        /// it, and it sees nothing of other tenants (a-z, 0-9, '_', '.', '-').
        #[arg(long)]
        tenant: String,
        /// A label for the operator (`geodex keys list` shows it).
        #[arg(long, default_value = "")]
        name: String,
        /// The key may read /metrics and the details of /readyz.
        #[arg(long)]
        admin: bool,
        /// Storage quota of the tenant in bytes (default: the service's
        /// `--tenant-quota-bytes`).
        #[arg(long)]
        quota_bytes: Option<u64>,
        /// Requests per second (default: the service's `--rate-limit-per-sec`).
        #[arg(long)]
        rate_per_sec: Option<f64>,
        /// Requests at once above the rate (token bucket size).
        #[arg(long)]
        burst: Option<u64>,
    },
    /// List the keys (never their secrets), revoked ones too.
    List {
        /// One JSON object per key instead of a table.
        #[arg(long)]
        json: bool,
    },
    /// Revoke a key (`key_<id>` as listed, or the key itself); it stops
    /// working within 2 seconds on every replica.
    Revoke {
        /// The key's id or the key.
        id: String,
    },
}

/// Runs `geodex keys ...`.
pub fn run(args: &KeysArgs) -> anyhow::Result<()> {
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    runtime.block_on(async {
        if args.queue == "sqlite" {
            std::fs::create_dir_all(&args.data_dir).with_context(|| {
                format!("creating the data directory {}", args.data_dir.display())
            })?;
        }
        let db = JobDb::open_queue(&args.queue, &args.data_dir, 2)
            .await
            .context("opening the job database that holds the keys")?;
        let keys = Keys::new(db, KeyDefaults::default());
        match &args.action {
            KeysAction::Create {
                tenant,
                name,
                admin,
                quota_bytes,
                rate_per_sec,
                burst,
            } => {
                let (record, key) = keys
                    .create(&NewKey {
                        tenant: tenant.clone(),
                        name: name.clone(),
                        admin: *admin,
                        quota_bytes: *quota_bytes,
                        rate_per_sec: *rate_per_sec,
                        burst: *burst,
                    })
                    .await?;
                eprintln!(
                    "created {} for tenant '{}'{}. The key is printed once, below; only its \
                     hash is stored. Send it as `Authorization: Bearer <key>`; a running \
                     service started without --auth turns auth on at its next start.",
                    record.id,
                    record.tenant,
                    if record.admin { " (admin)" } else { "" }
                );
                println!("{key}");
            }
            KeysAction::List { json } => {
                let all = keys.list().await?;
                if *json {
                    for k in &all {
                        println!("{}", serde_json::to_string(k)?);
                    }
                } else {
                    println!(
                        "{:<21} {:<20} {:<16} {:<5} state",
                        "id", "tenant", "name", "admin"
                    );
                    for k in &all {
                        println!(
                            "{:<21} {:<20} {:<16} {:<5} {}",
                            k.id,
                            k.tenant,
                            k.name,
                            k.admin,
                            if k.revoked_at.is_some() {
                                "revoked"
                            } else {
                                "active"
                            }
                        );
                    }
                }
            }
            KeysAction::Revoke { id } => match keys.revoke(id).await? {
                Some(revoked) => eprintln!("revoked {revoked}"),
                None => anyhow::bail!("no active key with this id (see `geodex keys list`)"),
            },
        }
        Ok(())
    })
}
