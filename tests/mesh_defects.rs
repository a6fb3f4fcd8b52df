//! Issue 24 item 5, "never crash on a real mesh": the defects of real scans
//! (non-manifold edges and vertices, unreferenced and duplicate vertices,
//! zero-area and needle triangles, several components, open boundaries,
//! inconsistent orientation) and a marching-tetrahedra surface, alone and
//! combined by a property test, read back through the OBJ reader and fed to
//! every surface method, the paths, the curvature and the metric designs.
//!
//! Each either works (no NaN; a distance is finite exactly where a label is
//! set; the exact method, Dijkstra and the robust heat method reach every
//! vertex connected to the source) or returns an error with a message;
//! none panics.

use std::collections::HashMap;

use geodex::io::mesh::{read_mesh, MeshFormat, MeshLimits};
use geodex::numerics::mesh::curvature::{curvature, face_tensors_from_curvature};
use geodex::numerics::mesh::design::{design, CurvatureFeature, FieldMode, MeshDesign};
use geodex::numerics::mesh::exact::exact_paths;
use geodex::numerics::mesh::paths::{trace_path, trace_path_in};
use geodex::numerics::mesh::shapes::{flat_square, icosphere, torus};
use geodex::numerics::mesh::{
    mesh_distance, HeatOptions, Laplacian, MeshDistance, MeshDistanceOptions, MeshMethod,
    SurfacePoint, Topology, TriMesh,
};
use geodex::numerics::Control;
use proptest::prelude::*;

/// A triangle soup as the readers see it (no checks).
#[derive(Debug, Clone)]
struct Soup {
    pos: Vec<[f64; 3]>,
    faces: Vec<[u32; 3]>,
}

impl Soup {
    fn of(m: &TriMesh) -> Self {
        Self {
            pos: m.positions().to_vec(),
            faces: m.faces().to_vec(),
        }
    }

    fn add(&mut self, p: [f64; 3]) -> u32 {
        self.pos.push(p);
        (self.pos.len() - 1) as u32
    }

    fn edge_length(&self) -> f64 {
        let f = self.faces[0];
        let (a, b) = (self.pos[f[0] as usize], self.pos[f[1] as usize]);
        ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
    }
}

/// One defect of real meshes; `k` picks where it goes.
#[derive(Debug, Clone, Copy)]
enum Defect {
    /// A fin: a third face on an existing edge.
    NonManifoldEdge,
    /// A flap touching the surface at one vertex only.
    NonManifoldVertex,
    /// Vertices no face uses.
    Unreferenced,
    /// A vertex duplicated and some of its faces moved to the copy (a seam
    /// the reader welds).
    Duplicate,
    /// A face whose three corners are collinear.
    ZeroArea,
    /// A vertex moved to 1e-9 of an edge from its neighbour.
    Needle,
    /// A second, disjoint component.
    Component,
    /// Faces removed: a hole with a boundary.
    Hole,
    /// Faces flipped: inconsistent orientation.
    Flipped,
}

const DEFECTS: [Defect; 9] = [
    Defect::NonManifoldEdge,
    Defect::NonManifoldVertex,
    Defect::Unreferenced,
    Defect::Duplicate,
    Defect::ZeroArea,
    Defect::Needle,
    Defect::Component,
    Defect::Hole,
    Defect::Flipped,
];

fn apply(s: &mut Soup, d: Defect, k: usize) {
    let nf = s.faces.len();
    let f = s.faces[k % nf];
    let h = s.edge_length().max(1e-3);
    let mid = |a: [f64; 3], b: [f64; 3]| std::array::from_fn::<f64, 3, _>(|j| 0.5 * (a[j] + b[j]));
    match d {
        Defect::NonManifoldEdge => {
            let (a, b) = (s.pos[f[0] as usize], s.pos[f[1] as usize]);
            let m = mid(a, b);
            let c = s.add([m[0] + 0.3 * h, m[1] - 0.4 * h, m[2] + 0.9 * h]);
            s.faces.push([f[0], f[1], c]);
        }
        Defect::NonManifoldVertex => {
            let p = s.pos[f[0] as usize];
            let a = s.add([p[0] + h, p[1] + 0.2 * h, p[2] + 1.5 * h]);
            let b = s.add([p[0] - 0.2 * h, p[1] + h, p[2] + 1.5 * h]);
            s.faces.push([f[0], a, b]);
        }
        Defect::Unreferenced => {
            for i in 0..3 {
                s.add([10.0 + i as f64, -5.0, 3.0]);
            }
        }
        Defect::Duplicate => {
            let v = f[0];
            let copy = s.add(s.pos[v as usize]);
            for face in s.faces.iter_mut().filter(|x| x.contains(&v)).step_by(2) {
                for c in face.iter_mut() {
                    if *c == v {
                        *c = copy;
                    }
                }
            }
        }
        Defect::ZeroArea => {
            let (a, b) = (s.pos[f[0] as usize], s.pos[f[1] as usize]);
            let m = s.add(mid(a, b));
            s.faces.push([f[0], m, f[1]]);
        }
        Defect::Needle => {
            let (a, b) = (s.pos[f[0] as usize], s.pos[f[1] as usize]);
            s.pos[f[0] as usize] = std::array::from_fn(|j| b[j] + 1e-9 * (a[j] - b[j]));
        }
        Defect::Component => {
            let small = icosphere(1, 0.5);
            let base = s.pos.len() as u32;
            for p in small.positions() {
                s.pos.push([p[0] + 5.0, p[1], p[2]]);
            }
            for t in small.faces() {
                s.faces.push(t.map(|v| v + base));
            }
        }
        Defect::Hole => {
            let keep: Vec<[u32; 3]> = s
                .faces
                .iter()
                .enumerate()
                .filter(|(i, _)| (*i + nf - k % nf) % nf >= 3)
                .map(|(_, t)| *t)
                .collect();
            if !keep.is_empty() {
                s.faces = keep;
            }
        }
        Defect::Flipped => {
            for t in s.faces.iter_mut().skip(k % 7).step_by(5) {
                t.swap(1, 2);
            }
        }
    }
}

/// The surface `|p| = r` by marching tetrahedra on a `g³` grid over
/// `[-1.2, 1.2]³`: the slivers, near-duplicate vertices and grid-aligned
/// zero-area faces of iso-surface extraction (vertices on grid edges,
/// shared between cells; the radius may put grid points exactly on the
/// surface).
fn marching_tetrahedra(g: usize, r: f64) -> Soup {
    let at = |i: usize| -1.2 + 2.4 * i as f64 / g as f64;
    let f = |p: [f64; 3]| (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt() - r;
    let mut pos = Vec::new();
    let mut faces = Vec::new();
    let mut on_edge: HashMap<([usize; 3], [usize; 3]), u32> = HashMap::new();
    // The six tetrahedra of a cube around its diagonal 0-6.
    const C: [[usize; 3]; 8] = [
        [0, 0, 0],
        [1, 0, 0],
        [1, 1, 0],
        [0, 1, 0],
        [0, 0, 1],
        [1, 0, 1],
        [1, 1, 1],
        [0, 1, 1],
    ];
    const T: [[usize; 4]; 6] = [
        [0, 5, 1, 6],
        [0, 1, 2, 6],
        [0, 2, 3, 6],
        [0, 3, 7, 6],
        [0, 7, 4, 6],
        [0, 4, 5, 6],
    ];
    for i in 0..g {
        for j in 0..g {
            for l in 0..g {
                let corner = |c: usize| [i + C[c][0], j + C[c][1], l + C[c][2]];
                for t in T {
                    let v: Vec<[usize; 3]> = t.iter().map(|&c| corner(c)).collect();
                    let p = |x: [usize; 3]| [at(x[0]), at(x[1]), at(x[2])];
                    let inside: Vec<bool> = v.iter().map(|&x| f(p(x)) < 0.0).collect();
                    let mut cut = Vec::new();
                    for a in 0..4 {
                        for b in a + 1..4 {
                            if inside[a] != inside[b] {
                                let key = if v[a] < v[b] {
                                    (v[a], v[b])
                                } else {
                                    (v[b], v[a])
                                };
                                let id = *on_edge.entry(key).or_insert_with(|| {
                                    let (pa, pb) = (p(key.0), p(key.1));
                                    let (fa, fb) = (f(pa), f(pb));
                                    let s = fa / (fa - fb);
                                    pos.push(std::array::from_fn(|k| pa[k] + s * (pb[k] - pa[k])));
                                    (pos.len() - 1) as u32
                                });
                                cut.push(id);
                            }
                        }
                    }
                    let tris: Vec<[u32; 3]> = match cut.len() {
                        3 => vec![[cut[0], cut[1], cut[2]]],
                        // Edges in the order (01, 02, 03, 12, 13, 23) minus
                        // the uncut ones: the quad is 0-1-3-2.
                        4 => vec![[cut[0], cut[1], cut[3]], [cut[0], cut[3], cut[2]]],
                        _ => vec![],
                    };
                    for mut tri in tris {
                        // Outward: the normal along the position.
                        let q = tri.map(|x| pos[x as usize]);
                        let e1: [f64; 3] = std::array::from_fn(|k| q[1][k] - q[0][k]);
                        let e2: [f64; 3] = std::array::from_fn(|k| q[2][k] - q[0][k]);
                        let n = [
                            e1[1] * e2[2] - e1[2] * e2[1],
                            e1[2] * e2[0] - e1[0] * e2[2],
                            e1[0] * e2[1] - e1[1] * e2[0],
                        ];
                        if n[0] * q[0][0] + n[1] * q[0][1] + n[2] * q[0][2] < 0.0 {
                            tri.swap(1, 2);
                        }
                        if tri[0] != tri[1] && tri[1] != tri[2] && tri[0] != tri[2] {
                            faces.push(tri);
                        }
                    }
                }
            }
        }
    }
    Soup { pos, faces }
}

/// The soup through the OBJ writer and reader (which weld, drop and count).
fn read_back(s: &Soup) -> Option<TriMesh> {
    let mut text = String::new();
    for p in &s.pos {
        text.push_str(&format!("v {} {} {}\n", p[0], p[1], p[2]));
    }
    for f in &s.faces {
        text.push_str(&format!("f {} {} {}\n", f[0] + 1, f[1] + 1, f[2] + 1));
    }
    match read_mesh(
        text.as_bytes(),
        Some(MeshFormat::Obj),
        &MeshLimits::default(),
    ) {
        Ok(m) => Some(m.mesh),
        Err(e) => {
            // A refusal must say why.
            assert!(!e.to_string().is_empty());
            eprintln!("refused: {e}");
            None
        }
    }
}

fn check_field(d: &MeshDistance, what: &str) {
    assert!(d.distance.iter().all(|x| !x.is_nan()), "{what}: NaN");
    assert!(
        d.distance
            .iter()
            .zip(&d.labels)
            .all(|(x, &l)| x.is_finite() == (l >= 0)),
        "{what}: a finite distance without a label or the reverse"
    );
}

/// Every method, the paths, the curvature and the designs on `mesh`.
fn run_everything(mesh: &TriMesh) {
    let topo = Topology::new(mesh);
    let ctl = Control::new();
    let source = mesh.faces()[0][0];
    let sources = [SurfacePoint::Vertex(source)];
    let connected: Vec<bool> = {
        let mut in_face = vec![false; mesh.num_vertices()];
        for f in mesh.faces() {
            for &v in f {
                in_face[v as usize] = true;
            }
        }
        (0..mesh.num_vertices())
            .map(|v| in_face[v] && topo.component[v] == topo.component[source as usize])
            .collect()
    };
    let far = (0..mesh.num_vertices() as u32)
        .rev()
        .find(|&v| connected[v as usize])
        .unwrap_or(source);
    let curv = curvature(mesh, &topo, 1, &ctl).expect("curvature never fails");
    if let Some((v, c)) = curv
        .iter()
        .enumerate()
        .find(|(_, c)| !(c.k1.is_finite() && c.k2.is_finite() && c.k1 >= c.k2))
    {
        panic!("curvature of vertex {v}: {c:?}");
    }
    let weights = design(
        mesh,
        &topo,
        &MeshDesign::Curvature {
            feature: CurvatureFeature::Both,
            epsilon: 0.01,
            power: 1.0,
            smoothing: 1,
        },
        &ctl,
    )
    .expect("a curvature design never fails");
    assert!(weights.iter().all(|w| w.is_finite() && *w > 0.0));
    let texture: Vec<f64> = mesh.positions().iter().map(|p| p[0] + p[2]).collect();
    let textured = design(
        mesh,
        &topo,
        &MeshDesign::Field {
            values: &texture,
            mode: FieldMode::Follow,
            epsilon: 0.01,
            power: 1.0,
        },
        &ctl,
    )
    .expect("a field design never fails");
    assert!(textured.iter().all(|w| w.is_finite() && *w > 0.0));
    let tensors = face_tensors_from_curvature(mesh, &topo, 10.0);

    let runs: [(&str, MeshDistanceOptions<'_>, bool); 8] = [
        ("fast marching", MeshDistanceOptions::default(), false),
        (
            "fast marching, curvature design",
            MeshDistanceOptions {
                weights: Some(&weights),
                ..Default::default()
            },
            false,
        ),
        (
            "fast marching, curvature tensors",
            MeshDistanceOptions {
                tensors: Some(&tensors),
                ..Default::default()
            },
            false,
        ),
        (
            "heat, robust",
            MeshDistanceOptions {
                method: MeshMethod::Heat,
                ..Default::default()
            },
            true,
        ),
        (
            "heat, cotangent",
            MeshDistanceOptions {
                method: MeshMethod::Heat,
                heat: HeatOptions {
                    laplacian: Laplacian::Cotangent,
                    ..Default::default()
                },
                ..Default::default()
            },
            false,
        ),
        (
            "exact",
            MeshDistanceOptions {
                method: MeshMethod::Exact,
                ..Default::default()
            },
            true,
        ),
        (
            "dijkstra",
            MeshDistanceOptions {
                method: MeshMethod::Dijkstra,
                ..Default::default()
            },
            true,
        ),
        (
            "dijkstra, texture design",
            MeshDistanceOptions {
                method: MeshMethod::Dijkstra,
                weights: Some(&textured),
                ..Default::default()
            },
            true,
        ),
    ];
    for (what, opts, strict) in runs {
        match mesh_distance(mesh, &topo, &sources, &opts, None, &ctl) {
            Ok(d) => {
                check_field(&d, what);
                if strict {
                    for (v, x) in d.distance.iter().enumerate() {
                        assert!(
                            !connected[v] || x.is_finite(),
                            "{what}: vertex {v} is connected to the source but at {x}"
                        );
                    }
                }
                if d.distance[far as usize].is_finite() {
                    let path = if opts.tensors.is_some() {
                        trace_path_in(
                            mesh,
                            &topo,
                            &d.distance,
                            &sources,
                            SurfacePoint::Vertex(far),
                            opts.tensors,
                        )
                    } else {
                        trace_path(
                            mesh,
                            &topo,
                            &d.distance,
                            &sources,
                            SurfacePoint::Vertex(far),
                        )
                    };
                    if let Ok(p) = path {
                        assert!(p.length.is_finite(), "{what}: path length {}", p.length);
                    }
                }
            }
            Err(e) => assert!(!e.to_string().is_empty(), "{what}: an empty error"),
        }
    }
    match exact_paths(mesh, &topo, &sources, &[SurfacePoint::Vertex(far)], &ctl) {
        Ok((d, paths)) => {
            check_field(&d, "exact paths");
            for p in paths.into_iter().flatten() {
                assert!(p.length.is_finite());
                assert!(
                    (p.length - d.distance[far as usize]).abs()
                        <= 1e-6 * (1.0 + d.distance[far as usize]),
                    "exact path {} vs distance {}",
                    p.length,
                    d.distance[far as usize]
                );
            }
        }
        Err(e) => assert!(!e.to_string().is_empty()),
    }
}

/// Each defect alone on each base mesh.
#[test]
fn every_defect_alone_on_every_base() {
    let bases = [
        ("icosphere", Soup::of(&icosphere(2, 1.0))),
        ("square", Soup::of(&flat_square(8, 1.0, 0.2))),
        ("torus", Soup::of(&torus(16, 8, 1.0, 0.35))),
        ("marching tetrahedra", marching_tetrahedra(8, 0.9)),
    ];
    for (name, base) in &bases {
        assert!(!base.faces.is_empty(), "{name}");
        run_everything(&read_back(base).expect(name));
        for (i, d) in DEFECTS.iter().enumerate() {
            let mut s = base.clone();
            apply(&mut s, *d, 7 * i + 3);
            if let Some(m) = read_back(&s) {
                run_everything(&m);
            }
        }
    }
}

/// The marching-tetrahedra sphere, with a radius that puts grid points on
/// the surface (zero-area faces, welded vertices), read and solved.
#[test]
fn a_marching_tetrahedra_sphere_with_grid_points_on_it() {
    // 1.2 is a grid coordinate at g = 8 (step 0.3): points (±1.2, 0, 0) etc.
    let s = marching_tetrahedra(8, 1.2);
    let m = read_back(&s).expect("readable");
    run_everything(&m);
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, ..ProptestConfig::default() })]

    /// Defects combined: a random subset, at random places, on a random base.
    #[test]
    fn defects_combined_never_crash(
        base in 0usize..4,
        picks in proptest::collection::vec((0usize..9, 0usize..1000), 1..6),
    ) {
        let mut s = match base {
            0 => Soup::of(&icosphere(1, 1.0)),
            1 => Soup::of(&flat_square(6, 1.0, 0.3)),
            2 => Soup::of(&torus(12, 6, 1.0, 0.35)),
            _ => marching_tetrahedra(6, 0.85),
        };
        for (d, k) in picks {
            apply(&mut s, DEFECTS[d], k);
        }
        if let Some(m) = read_back(&s) {
            run_everything(&m);
        }
    }
}
