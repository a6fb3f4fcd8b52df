//! Surface solvers against exact distances: icospheres (great circles), the
//! flat square (Euclidean), sources inside faces, Voronoi cells, paths and
//! farthest-point sampling.

#![allow(clippy::needless_range_loop)] // tests compare several per-vertex arrays by index
use geodex::numerics::mesh::paths::{trace_path, PathLocation};
use geodex::numerics::mesh::sampling::{farthest_point_sampling, SamplingOptions};
use geodex::numerics::mesh::shapes::{flat_square, great_circle, icosphere};
use geodex::numerics::mesh::{
    mesh_distance, norm, sub, HeatOptions, HeatSolver, MeshDistanceOptions, MeshMethod,
    SurfacePoint, Topology, TriMesh,
};
use geodex::numerics::Control;

fn solve(mesh: &TriMesh, sources: &[SurfacePoint], method: MeshMethod) -> Vec<f64> {
    let topo = Topology::new(mesh);
    let opts = MeshDistanceOptions {
        method,
        ..Default::default()
    };
    mesh_distance(mesh, &topo, sources, &opts, None, &Control::new())
        .unwrap()
        .distance
}

/// Mean relative error against the great-circle distance from vertex 0,
/// over vertices farther than 0.1 (relative error is undefined at 0).
fn sphere_error(level: u32, method: MeshMethod) -> f64 {
    let m = icosphere(level, 1.0);
    let d = solve(&m, &[SurfacePoint::Vertex(0)], method);
    let p0 = m.position(0);
    let mut sum = 0.0;
    let mut count = 0;
    for (v, &dv) in d.iter().enumerate() {
        assert!(dv.is_finite(), "vertex {v} not reached");
        let exact = great_circle(p0, m.position(v as u32), 1.0);
        if exact > 0.1 {
            sum += (dv - exact).abs() / exact;
            count += 1;
        }
    }
    sum / count as f64
}

#[test]
fn icosphere_convergence_fast_marching_and_heat() {
    for method in [MeshMethod::FastMarching, MeshMethod::Heat] {
        let errs: Vec<f64> = (2..=5).map(|l| sphere_error(l, method)).collect();
        let orders: Vec<f64> = errs.windows(2).map(|w| (w[0] / w[1]).log2()).collect();
        eprintln!("{method:?}: mean relative errors {errs:?}, observed orders {orders:?}");
        // Level 5 has 10,242 vertices: the bound is 2 %.
        assert!(errs[3] <= 0.02, "{method:?} at 10k vertices: {}", errs[3]);
        // Converges: the error falls at every refinement, and the order
        // observed between the two finest levels (2,562 -> 10,242 vertices)
        // is at least 0.5 (it rises towards 1 as h shrinks: pre-asymptotic).
        assert!(errs.windows(2).all(|w| w[1] < w[0]), "{method:?}: {errs:?}");
        assert!(orders[2] > 0.5, "{method:?}: orders {orders:?}");
    }
}

#[test]
fn dijkstra_overestimates_and_does_not_converge() {
    let e4 = sphere_error(4, MeshMethod::Dijkstra);
    assert!(e4 > 0.02, "{e4}");
    let m = icosphere(3, 1.0);
    let d = solve(&m, &[SurfacePoint::Vertex(0)], MeshMethod::Dijkstra);
    for (v, &dv) in d.iter().enumerate() {
        let exact = great_circle(m.position(0), m.position(v as u32), 1.0);
        // Edge paths are longer than geodesics; chords shorten them by < 1 %.
        assert!(dv >= 0.99 * exact - 1e-12, "{v}: {dv} < {exact}");
    }
}

#[test]
fn flat_square_fast_marching_is_close_to_euclidean() {
    // Jittered: obtuse and skinny triangles exercise the unfolding.
    let m = flat_square(40, 1.0, 0.3);
    let src = 20 * 41 + 20; // centre vertex
    let d = solve(&m, &[SurfacePoint::Vertex(src)], MeshMethod::FastMarching);
    let pc = m.position(src);
    let mut max_err: f64 = 0.0;
    for (v, &dv) in d.iter().enumerate() {
        max_err = max_err.max((dv - norm(sub(m.position(v as u32), pc))).abs());
    }
    // First order: a few percent of the half-width 0.5 at h = 1/40.
    assert!(max_err < 0.03, "max error {max_err}");
}

#[test]
fn weights_scale_the_distance() {
    let m = icosphere(3, 1.0);
    let topo = Topology::new(&m);
    let w = vec![2.0; m.num_vertices()];
    for method in [MeshMethod::FastMarching, MeshMethod::Dijkstra] {
        let unit = solve(&m, &[SurfacePoint::Vertex(5)], method);
        let opts = MeshDistanceOptions {
            method,
            weights: Some(&w),
            ..Default::default()
        };
        let d = mesh_distance(
            &m,
            &topo,
            &[SurfacePoint::Vertex(5)],
            &opts,
            None,
            &Control::new(),
        )
        .unwrap();
        for v in 0..m.num_vertices() {
            assert!((d.distance[v] - 2.0 * unit[v]).abs() <= 1e-9 * (1.0 + unit[v]));
        }
    }
}

/// Splits face `f` of `m` at barycentric `b` (the point stays in the face's plane).
fn insert_point(m: &TriMesh, f: usize, b: [f64; 3]) -> (TriMesh, u32) {
    let p = SurfacePoint::Face {
        face: f as u32,
        bary: b,
    }
    .position(m);
    let mut pos = m.positions().to_vec();
    pos.push(p);
    let c = (pos.len() - 1) as u32;
    let [a, bb, cc] = m.faces()[f];
    let mut faces: Vec<[u32; 3]> = m
        .faces()
        .iter()
        .enumerate()
        .filter(|(i, _)| *i != f)
        .map(|(_, x)| *x)
        .collect();
    faces.extend([[a, bb, c], [bb, cc, c], [cc, a, c]]);
    (TriMesh::new(pos, faces).unwrap(), c)
}

#[test]
fn face_source_matches_inserted_vertex() {
    let m = icosphere(4, 1.0);
    let (f, b) = (123usize, [0.2, 0.3, 0.5]);
    let (m2, c) = insert_point(&m, f, b);
    let h = m.mean_edge_length();
    // The corner of the face nearest to the point: snapping the source
    // there is the mistake this test must catch.
    let p = SurfacePoint::Face {
        face: f as u32,
        bary: b,
    }
    .position(&m);
    let corner = *m.faces()[f]
        .iter()
        .min_by(|&&x, &&y| {
            let dx: f64 = (0..3).map(|k| (m.position(x)[k] - p[k]).powi(2)).sum();
            let dy: f64 = (0..3).map(|k| (m.position(y)[k] - p[k]).powi(2)).sum();
            dx.total_cmp(&dy)
        })
        .unwrap();
    let n = m.num_vertices();
    let gap = |a: &[f64], b: &[f64]| {
        let mean: f64 = (0..n).map(|v| (a[v] - b[v]).abs()).sum::<f64>() / n as f64;
        let max = (0..n).map(|v| (a[v] - b[v]).abs()).fold(0.0, f64::max);
        (mean, max)
    };
    // (method, bound on the max gap in edge lengths, whether the bound must
    // also reject the snapped source). The heat method's `t = h²` follows
    // the mean edge length, which the split changes: its two answers differ
    // by its own error (a fifth of an edge here), as much as snapping does.
    for (method, bound, sharp) in [
        (MeshMethod::FastMarching, 0.05, true),
        (MeshMethod::Heat, 0.3, false),
        (MeshMethod::Dijkstra, 0.05, true),
        (MeshMethod::Exact, 1e-9, true),
    ] {
        let d1 = solve(
            &m,
            &[SurfacePoint::Face {
                face: f as u32,
                bary: b,
            }],
            method,
        );
        let d2 = solve(&m2, &[SurfacePoint::Vertex(c)], method);
        let snapped = solve(&m, &[SurfacePoint::Vertex(corner)], method);
        let (mean, max) = gap(&d1, &d2);
        let (snap_mean, snap_max) = gap(&snapped, &d2);
        eprintln!(
            "{method:?}: face vs inserted vertex mean {mean:.2e}, max {max:.2e}; \
             snapped to a corner: mean {snap_mean:.2e}, max {snap_max:.2e} (h = {h:.3})"
        );
        // The face source agrees with the inserted vertex to a small
        // fraction of an edge, and the bound rejects a source snapped to
        // the nearest corner (this test can fail).
        assert!(max < bound * h, "{method:?}: mean {mean}, max {max}");
        if sharp {
            assert!(
                snap_mean > 2.0 * bound * h,
                "{method:?}: the bound cannot tell a snapped source"
            );
        }
    }
}

#[test]
fn antipodal_voronoi_splits_at_the_equator() {
    let m = icosphere(4, 1.0);
    let topo = Topology::new(&m);
    let zs: Vec<f64> = m.positions().iter().map(|p| p[2]).collect();
    let north = (0..zs.len())
        .max_by(|&a, &b| zs[a].total_cmp(&zs[b]))
        .unwrap() as u32;
    let south = (0..zs.len())
        .min_by(|&a, &b| zs[a].total_cmp(&zs[b]))
        .unwrap() as u32;
    assert!((zs[north as usize] + zs[south as usize]).abs() < 1e-12);
    let h = m.mean_edge_length();
    for method in [
        MeshMethod::FastMarching,
        MeshMethod::Heat,
        MeshMethod::Dijkstra,
    ] {
        let opts = MeshDistanceOptions {
            method,
            ..Default::default()
        };
        let src = [SurfacePoint::Vertex(north), SurfacePoint::Vertex(south)];
        let d = mesh_distance(&m, &topo, &src, &opts, None, &Control::new()).unwrap();
        let mut wrong = 0;
        for v in 0..m.num_vertices() {
            // Beyond one ring of the equator the cell is known.
            if zs[v] > h {
                wrong += usize::from(d.labels[v] != 0);
            } else if zs[v] < -h {
                wrong += usize::from(d.labels[v] != 1);
            } else {
                assert!(d.labels[v] == 0 || d.labels[v] == 1);
            }
        }
        assert_eq!(wrong, 0, "{method:?}");
    }
}

#[test]
fn components_are_infinite_never_nan() {
    let a = icosphere(2, 1.0);
    let mut pos = a.positions().to_vec();
    let n = pos.len() as u32;
    pos.extend(a.positions().iter().map(|p| [p[0] + 5.0, p[1], p[2]]));
    let mut faces = a.faces().to_vec();
    faces.extend(a.faces().iter().map(|f| f.map(|v| v + n)));
    let m = TriMesh::new(pos, faces).unwrap();
    for method in [
        MeshMethod::FastMarching,
        MeshMethod::Heat,
        MeshMethod::Dijkstra,
    ] {
        let topo = Topology::new(&m);
        let opts = MeshDistanceOptions {
            method,
            ..Default::default()
        };
        let d = mesh_distance(
            &m,
            &topo,
            &[SurfacePoint::Vertex(0)],
            &opts,
            None,
            &Control::new(),
        )
        .unwrap();
        for v in 0..m.num_vertices() {
            assert!(!d.distance[v].is_nan());
            if v < n as usize {
                assert!(
                    d.distance[v].is_finite() && d.labels[v] == 0,
                    "{method:?} {v}"
                );
            } else {
                assert!(
                    d.distance[v] == f64::INFINITY && d.labels[v] == -1,
                    "{method:?} {v}"
                );
            }
        }
    }
}

#[test]
fn max_distance_cuts_the_front() {
    let m = icosphere(3, 1.0);
    for method in [
        MeshMethod::FastMarching,
        MeshMethod::Heat,
        MeshMethod::Dijkstra,
    ] {
        let topo = Topology::new(&m);
        let full = solve(&m, &[SurfacePoint::Vertex(0)], method);
        let opts = MeshDistanceOptions {
            method,
            max_distance: 1.0,
            ..Default::default()
        };
        let d = mesh_distance(
            &m,
            &topo,
            &[SurfacePoint::Vertex(0)],
            &opts,
            None,
            &Control::new(),
        )
        .unwrap();
        for v in 0..m.num_vertices() {
            if full[v] <= 1.0 {
                assert_eq!(d.distance[v], full[v], "{method:?}");
            } else {
                assert_eq!(d.distance[v], f64::INFINITY, "{method:?}");
            }
        }
    }
}

#[test]
fn heat_factorisation_is_reused_and_t_is_m_h2() {
    let m = icosphere(3, 1.0);
    let topo = Topology::new(&m);
    let opts = HeatOptions {
        m: 2.0,
        underflow_guard: false,
    };
    let solver = HeatSolver::new(&m, &topo, &opts, &Control::new()).unwrap();
    let h = m.mean_edge_length();
    assert!((solver.t() - 2.0 * h * h).abs() < 1e-15);
    let a = solver
        .distance(
            &m,
            &[SurfacePoint::Vertex(0)],
            f64::INFINITY,
            &Control::new(),
        )
        .unwrap();
    let b = solver
        .distance(
            &m,
            &[SurfacePoint::Vertex(7)],
            f64::INFINITY,
            &Control::new(),
        )
        .unwrap();
    // Symmetry of the two answers: d(0 -> 7) ≈ d(7 -> 0).
    assert!((a.distance[7] - b.distance[0]).abs() < 0.05 * a.distance[7]);
    assert!(a.distance[0] == 0.0 && b.distance[7] == 0.0);
}

#[test]
fn paths_descend_to_the_source_with_geodesic_length() {
    let m = icosphere(4, 1.0);
    let topo = Topology::new(&m);
    let src = [SurfacePoint::Vertex(0)];
    let d = solve(&m, &src, MeshMethod::FastMarching);
    let p0 = m.position(0);
    for start in [
        SurfacePoint::Vertex(100),
        SurfacePoint::Vertex(2000),
        SurfacePoint::Face {
            face: 3000,
            bary: [0.3, 0.3, 0.4],
        },
    ] {
        let path = trace_path(&m, &topo, &d, &src, start).unwrap();
        assert_eq!(path.source, Some(0));
        let exact = great_circle(start.position(&m), p0, 1.0);
        assert!(
            (path.length - exact).abs() < 0.03 * exact + 0.02,
            "length {} vs {exact}",
            path.length
        );
        // Every point is on the surface (inside the unit ball, near the sphere).
        for p in &path.points {
            let r = norm(p.position);
            assert!(r <= 1.0 + 1e-9 && r > 0.99, "{r}");
            if let PathLocation::Edge(a, b, t) = p.location {
                let q = m.position(a);
                let e = sub(m.position(b), q);
                let x = [q[0] + t * e[0], q[1] + t * e[1], q[2] + t * e[2]];
                assert!(norm(sub(x, p.position)) < 1e-9);
            }
        }
        assert_eq!(
            path.points.last().unwrap().location,
            PathLocation::Vertex(0)
        );
    }
}

#[test]
fn farthest_point_sampling_covers_the_sphere() {
    let m = icosphere(4, 1.0);
    let topo = Topology::new(&m);
    for method in [MeshMethod::FastMarching, MeshMethod::Dijkstra] {
        let s = farthest_point_sampling(
            &m,
            &topo,
            &SamplingOptions {
                count: Some(20),
                radius: None,
                first: Some(0),
                method,
            },
            None,
            &Control::new(),
        )
        .unwrap();
        assert_eq!(s.samples.len(), 20);
        assert_eq!(s.samples[0], 0);
        // Farthest from vertex 0 on a sphere is (nearly) its antipode.
        let p = m.position(s.samples[1]);
        assert!(great_circle(m.position(0), p, 1.0) > 3.0);
        // The labels are the nearest samples: distances agree with a full solve.
        let src: Vec<SurfacePoint> = s.samples.iter().map(|&v| SurfacePoint::Vertex(v)).collect();
        let opts = MeshDistanceOptions {
            method,
            ..Default::default()
        };
        let full = mesh_distance(&m, &topo, &src, &opts, None, &Control::new()).unwrap();
        // Dijkstra: the same numbers; fast marching: one march per sample
        // differs from the joint march only where fronts meet.
        let tol = if method == MeshMethod::Dijkstra {
            1e-9
        } else {
            0.02
        };
        for v in 0..m.num_vertices() {
            assert!(
                (full.distance[v] - s.field.distance[v]).abs() < tol,
                "{method:?} {v}"
            );
        }
        // 20 well-spread points on the unit sphere: covering radius ~ 0.6.
        assert!(s.covering_radius < 0.8, "{}", s.covering_radius);
        // Radius mode: every vertex within the radius at the end.
        let r = farthest_point_sampling(
            &m,
            &topo,
            &SamplingOptions {
                count: None,
                radius: Some(0.5),
                first: None,
                method,
            },
            None,
            &Control::new(),
        )
        .unwrap();
        assert!(r.covering_radius <= 0.5);
        assert!(r.field.distance.iter().all(|&x| x <= 0.5));
    }
}
