//! Test and benchmark helpers for the mesh solvers: deterministic random
//! numbers and icospheres. Included with `#[path]`, not a test target.
#![allow(dead_code)]

use geodex::numerics::mesh::TriMesh;

/// Deterministic uniform numbers in [0, 1).
pub struct Lcg(pub u64);
impl Lcg {
    pub fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// Icosphere of radius 1 (`10 * 4^level + 2` vertices): the library's own oracle mesh.
pub fn icosphere(level: u32) -> TriMesh {
    geodex::numerics::mesh::shapes::icosphere(level, 1.0)
}
