//! Serde defaults of the request fields, defined once.

/// Scheme order: 2.
pub fn default_order() -> u8 {
    2
}

/// A switch on by default (factoring, early stop).
pub fn default_true() -> bool {
    true
}

/// Runge–Kutta step of the path descent, in cells: 0.5.
pub fn default_step() -> f64 {
    0.5
}
