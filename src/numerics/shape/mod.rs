//! Geodesic analysis of shapes (the monograph's chapter 5): distance
//! matrices, their Euclidean embeddings and bending-invariant canonical
//! forms.
//!
//! * [`matrix`]: distance matrices on triangle meshes (all pairs, or landmark
//!   rows from farthest-point landmarks), many single-source solves sharing
//!   one setup and running in parallel on the caller's rayon pool.
//! * [`graph`]: weighted graphs in CSR form, parallel Dijkstra rows, farthest points.
//! * [`knn`]: k-nearest-neighbour graphs of point clouds (a kd-tree) and
//!   their shortest-path distance rows (Dijkstra), as Isomap measures.
//! * [`eigen`]: the top eigenpairs of a dense symmetric matrix (faer's
//!   dense decomposition for small sizes, subspace iteration above).
//! * [`mds`]: classical MDS, landmark MDS (de Silva and Tenenbaum) and
//!   weighted SMACOF stress majorisation.
//! * [`procrustes`]: rigid (orthogonal) alignment of two point sets.
//! * [`isomap`]: Isomap of a point cloud.
//! * [`canonical`]: the canonical form of a mesh (Elad and Kimmel).
//! * [`mask`]: inner distances of a 2D or 3D shape given as a mask, and its
//!   canonical form.
//! * [`descriptor`]: geodesic shape descriptors (distance distribution,
//!   eccentricity, canonical-form moments) and their distance, for retrieval.
//! * [`benchmark`]: a generated retrieval benchmark of articulated shapes
//!   (classes × poses, with noise and remeshing).
//! * [`correspond`]: correspondence between two near-isometric meshes
//!   (canonical forms, rigid alignment over every flip, refinement by
//!   geodesic distances to matched landmarks).

pub mod benchmark;
pub mod canonical;
pub mod correspond;
pub mod descriptor;
pub mod eigen;
pub mod graph;
pub mod isomap;
pub mod knn;
pub mod mask;
pub mod matrix;
pub mod mds;
pub mod procrustes;

use crate::numerics::mesh::MeshSolveError;

/// Why a shape computation was refused or stopped.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ShapeError {
    /// An option is out of range; `option` names it.
    #[error("{option}: {reason}")]
    InvalidOption {
        /// The option.
        option: &'static str,
        /// Why.
        reason: String,
    },
    /// The input is not connected, so some distances are infinite.
    #[error("the {what} has {components} connected components; {hint}")]
    Disconnected {
        /// What was disconnected (`mesh`, `neighbour graph`).
        what: &'static str,
        /// Number of components.
        components: usize,
        /// The way out.
        hint: &'static str,
    },
    /// A distance solve failed.
    #[error(transparent)]
    Solve(#[from] MeshSolveError),
    /// The eigendecomposition did not converge or the input is degenerate.
    #[error("numerical failure: {0}")]
    Numerical(String),
    /// The caller raised the cancel flag.
    #[error("cancelled")]
    Cancelled,
}

impl ShapeError {
    /// `Cancelled` for a cancelled inner solve, the error itself otherwise.
    fn from_solve(e: MeshSolveError) -> Self {
        match e {
            MeshSolveError::Cancelled => ShapeError::Cancelled,
            other => ShapeError::Solve(other),
        }
    }
}
