//! Shape retrieval on the generated benchmark of articulated shapes
//! (`numerics::shape::benchmark`): eleven classes × ten poses, each pose
//! bent at every joint, turned, scaled, remeshed to its own vertex count and
//! jittered. Every shape queries the others by descriptor distance
//! (`numerics::shape::descriptor`); nearest-neighbour accuracy, first tier,
//! second tier and DCG are printed (`--nocapture`) and NN accuracy is
//! asserted ≥ 90 %.
//!
//! `cargo test --test retrieval -- --nocapture`. `GEODEX_RETRIEVAL_POSES`
//! changes the poses per class (default 10).

use std::time::Instant;

use geodex::numerics::mesh::{MeshMethod, Topology};
use geodex::numerics::shape::benchmark::{
    benchmark_shape, classes, retrieval_scores, BenchmarkOptions,
};
use geodex::numerics::shape::descriptor::{descriptor, descriptor_distance, DescriptorOptions};
use geodex::numerics::Control;
use rayon::prelude::*;

#[test]
fn retrieval_of_articulated_shapes_in_new_poses() {
    let poses: usize = std::env::var("GEODEX_RETRIEVAL_POSES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(10);
    let bench = BenchmarkOptions {
        level: 4,
        max_bend: 1.0,
        min_vertices: 300,
        max_vertices: 600,
        noise: 0.1,
        seed: 7,
    };
    let options = DescriptorOptions {
        landmarks: 24,
        bins: 24,
        method: MeshMethod::FastMarching,
    };
    let classes = classes();
    let started = Instant::now();
    let jobs: Vec<(usize, usize)> = (0..classes.len())
        .flat_map(|c| (0..poses).map(move |p| (c, p)))
        .collect();
    let described: Vec<(usize, usize, _)> = jobs
        .par_iter()
        .map(|&(c, p)| {
            let mesh = benchmark_shape(&classes[c], c, p, &bench, &Control::new())
                .unwrap_or_else(|e| panic!("{} pose {p}: {e}", classes[c].name));
            let topo = Topology::new(&mesh);
            let d = descriptor(&mesh, &topo, &options, None, &Control::new())
                .unwrap_or_else(|e| panic!("{} pose {p}: {e}", classes[c].name));
            (c, mesh.num_vertices(), d)
        })
        .collect();
    let built = started.elapsed().as_secs_f64();
    let labels: Vec<usize> = described.iter().map(|(c, _, _)| *c).collect();
    let matrix: Vec<Vec<f64>> = described
        .iter()
        .map(|(_, _, a)| {
            described
                .iter()
                .map(|(_, _, b)| descriptor_distance(a, b).unwrap())
                .collect()
        })
        .collect();
    let s = retrieval_scores(&matrix, &labels);
    let sizes: Vec<usize> = described.iter().map(|(_, n, _)| *n).collect();
    let (lo, hi) = (
        sizes.iter().min().copied().unwrap_or(0),
        sizes.iter().max().copied().unwrap_or(0),
    );
    println!(
        "retrieval: {} classes × {poses} poses, {lo}..{hi} vertices, {} landmarks, {} bins: \
         NN {:.3}, FT {:.3}, ST {:.3}, DCG {:.3} ({:.1} s to build and describe)",
        classes.len(),
        options.landmarks,
        options.bins,
        s.nearest_neighbour,
        s.first_tier,
        s.second_tier,
        s.dcg,
        built
    );
    // Per class: the nearest neighbours that went astray.
    for (q, row) in matrix.iter().enumerate() {
        let nearest = (0..row.len())
            .filter(|&j| j != q)
            .min_by(|&a, &b| row[a].total_cmp(&row[b]));
        if let Some(j) = nearest {
            if labels[j] != labels[q] {
                println!(
                    "  {} pose {} -> {}",
                    classes[labels[q]].name,
                    q % poses,
                    classes[labels[j]].name
                );
            }
        }
    }
    assert!(classes.len() >= 10 && poses >= 2);
    assert_eq!(s.queries, classes.len() * poses);
    assert!(
        s.nearest_neighbour >= 0.9,
        "nearest-neighbour accuracy {}",
        s.nearest_neighbour
    );
    assert!(s.first_tier <= s.second_tier && s.dcg <= 1.0);
}
