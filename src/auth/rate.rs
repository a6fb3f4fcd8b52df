//! Per-key rate limits: one token bucket per key.
//!
//! A bucket of size `burst` refills at `rate` tokens per second; a request
//! takes one token, and an empty bucket refuses it with the time until the
//! next token (the `Retry-After` of a 429). The buckets live in the process:
//! with several replicas each applies the limit to the requests it serves.

use std::collections::HashMap;
use std::sync::Mutex;
use std::time::{Duration, Instant};

#[derive(Debug, Clone, Copy)]
struct Bucket {
    tokens: f64,
    at: Instant,
}

/// The buckets of every key seen.
#[derive(Debug, Default)]
pub struct Buckets {
    buckets: Mutex<HashMap<String, Bucket>>,
}

impl Buckets {
    /// Takes one token from `key`'s bucket (`rate` per second, at most
    /// `burst`), or says how long until one is there.
    pub fn take(&self, key: &str, rate: f64, burst: f64, now: Instant) -> Result<(), Duration> {
        let burst = burst.max(1.0);
        let mut buckets = self.buckets.lock().unwrap_or_else(|p| p.into_inner());
        let bucket = buckets.entry(key.to_string()).or_insert(Bucket {
            tokens: burst,
            at: now,
        });
        let elapsed = now.saturating_duration_since(bucket.at).as_secs_f64();
        bucket.tokens = (bucket.tokens + elapsed * rate).min(burst);
        bucket.at = now;
        if bucket.tokens >= 1.0 {
            bucket.tokens -= 1.0;
            Ok(())
        } else {
            let wait = (1.0 - bucket.tokens) / rate.max(f64::MIN_POSITIVE);
            Err(Duration::try_from_secs_f64(wait).unwrap_or(Duration::MAX))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_bucket_allows_its_burst_then_its_rate() {
        let b = Buckets::default();
        let t0 = Instant::now();
        for _ in 0..5 {
            assert!(b.take("k", 2.0, 5.0, t0).is_ok());
        }
        let wait = b.take("k", 2.0, 5.0, t0).expect_err("empty");
        assert!((wait.as_secs_f64() - 0.5).abs() < 1e-9, "{wait:?}");
        // Half a second later one token is back, and only one.
        let t1 = t0 + Duration::from_millis(500);
        assert!(b.take("k", 2.0, 5.0, t1).is_ok());
        assert!(b.take("k", 2.0, 5.0, t1).is_err());
        // Another key has its own bucket.
        assert!(b.take("other", 2.0, 5.0, t1).is_ok());
        // A long pause refills to the burst, not beyond.
        let t2 = t1 + Duration::from_secs(60);
        for _ in 0..5 {
            assert!(b.take("k", 2.0, 5.0, t2).is_ok());
        }
        assert!(b.take("k", 2.0, 5.0, t2).is_err());
    }
}
