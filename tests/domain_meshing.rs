//! Domain meshing (issue 18, item 4): on a disc, an L-shape and a square
//! with two holes, given as polygons and as masks, at least 99 % of the
//! triangles have their smallest angle >= 25°, the triangles tile the
//! domain exactly (none outside, none in a hole: their areas add up to the
//! domain's and each centroid is inside), every boundary edge lies on an
//! input edge, and the mesh is a valid planar triangulation. (Every input
//! vertex is kept, so the polygons are not much finer than the meshes asked
//! for: a 96-gon disc at 300 vertices.)

use geodex::numerics::meshing::domain::{
    mesh_domain, min_angles, Domain, DomainMesh, DomainMeshOptions, MeshSize, SizeField,
};
use geodex::numerics::sampling::triangulation::check_planar;
use geodex::numerics::Control;

fn disc(c: [f64; 2], r: f64, n: usize) -> Vec<[f64; 2]> {
    (0..n)
        .map(|k| {
            let t = std::f64::consts::TAU * k as f64 / n as f64;
            [c[0] + r * t.cos(), c[1] + r * t.sin()]
        })
        .collect()
}

fn l_shape() -> Vec<[f64; 2]> {
    vec![
        [0.0, 0.0],
        [100.0, 0.0],
        [100.0, 40.0],
        [40.0, 40.0],
        [40.0, 100.0],
        [0.0, 100.0],
    ]
}

fn square_two_holes() -> Vec<Vec<[f64; 2]>> {
    vec![
        vec![[0.0, 0.0], [100.0, 0.0], [100.0, 100.0], [0.0, 100.0]],
        vec![[20.0, 20.0], [20.0, 45.0], [45.0, 45.0], [45.0, 20.0]],
        disc([70.0, 65.0], 15.0, 48),
    ]
}

/// Even-odd point-in-rings test.
fn inside(rings: &[Vec<[f64; 2]>], p: [f64; 2]) -> bool {
    let mut odd = false;
    for ring in rings {
        let n = ring.len();
        for k in 0..n {
            let (a, b) = (ring[k], ring[(k + 1) % n]);
            if (a[1] > p[1]) != (b[1] > p[1]) {
                let x = a[0] + (p[1] - a[1]) / (b[1] - a[1]) * (b[0] - a[0]);
                if x > p[0] {
                    odd = !odd;
                }
            }
        }
    }
    odd
}

fn ring_area(ring: &[[f64; 2]]) -> f64 {
    let n = ring.len();
    ((0..n)
        .map(|k| ring[k][0] * ring[(k + 1) % n][1] - ring[(k + 1) % n][0] * ring[k][1])
        .sum::<f64>()
        / 2.0)
        .abs()
}

/// Distance from `p` to the nearest input edge.
fn to_boundary(rings: &[Vec<[f64; 2]>], p: [f64; 2]) -> f64 {
    let mut best = f64::INFINITY;
    for ring in rings {
        let n = ring.len();
        for k in 0..n {
            let (a, b) = (ring[k], ring[(k + 1) % n]);
            let d = [b[0] - a[0], b[1] - a[1]];
            let t = (((p[0] - a[0]) * d[0] + (p[1] - a[1]) * d[1]) / (d[0] * d[0] + d[1] * d[1]))
                .clamp(0.0, 1.0);
            best = best.min((p[0] - a[0] - t * d[0]).hypot(p[1] - a[1] - t * d[1]));
        }
    }
    best
}

fn check(name: &str, rings: &[Vec<[f64; 2]>], area: f64, m: &DomainMesh, tol: f64) {
    assert!(
        check_planar(&m.points, &m.triangles).is_empty(),
        "{name}: not a triangulation"
    );
    let mut total = 0.0;
    for t in &m.triangles {
        let [a, b, c] = t.map(|v| m.points[v as usize]);
        let twice = (b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1]);
        assert!(twice > 0.0, "{name}: a triangle is not counter-clockwise");
        total += twice / 2.0;
        let g = [(a[0] + b[0] + c[0]) / 3.0, (a[1] + b[1] + c[1]) / 3.0];
        assert!(
            inside(rings, g),
            "{name}: triangle centred at {g:?} lies outside"
        );
    }
    assert!(
        (total - area).abs() <= 1e-9 * area,
        "{name}: triangles cover {total}, the domain {area}"
    );
    for e in &m.boundary_edges {
        let (a, b) = (m.points[e[0] as usize], m.points[e[1] as usize]);
        for t in [0.0, 0.25, 0.5, 0.75, 1.0] {
            let p = [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])];
            let d = to_boundary(rings, p);
            assert!(
                d <= tol,
                "{name}: boundary edge point {p:?} is {d} off the boundary"
            );
        }
    }
    let angles = min_angles(&m.points, &m.triangles);
    let good = angles.iter().filter(|&&a| a >= 25.0).count() as f64 / angles.len() as f64;
    let smallest = angles.iter().copied().fold(90.0, f64::min);
    assert!(good >= 0.99, "{name}: {:.2} % >= 25°", 100.0 * good);
    println!(
        "{name}: {} vertices, {} triangles, {} refined, smallest angle {smallest:.1}°, {:.2} % >= 25°",
        m.points.len(),
        m.triangles.len(),
        m.refined,
        100.0 * good
    );
}

#[test]
fn polygons_are_meshed_with_angles_of_25_degrees() {
    let cases: Vec<(&str, Vec<Vec<[f64; 2]>>)> = vec![
        ("disc", vec![disc([50.0, 50.0], 50.0, 96)]),
        ("L-shape", vec![l_shape()]),
        ("square with two holes", square_two_holes()),
    ];
    for (name, rings) in cases {
        let area = ring_area(&rings[0]) - rings[1..].iter().map(|r| ring_area(r)).sum::<f64>();
        let domain = Domain::new(rings.clone()).expect("domain");
        for count in [300, 2000] {
            let options = DomainMeshOptions {
                size: MeshSize::Count(count),
                ..Default::default()
            };
            let m = mesh_domain(&domain, &options, &Control::default()).expect("mesh");
            check(name, &rings, area, &m, 1e-9);
            let ratio = m.points.len() as f64 / count as f64;
            assert!(
                (0.9..1.1).contains(&ratio),
                "{name}: {} vertices for {count}",
                m.points.len()
            );
        }
    }
}

#[test]
fn masks_are_meshed_on_their_boundary() {
    let n = 120;
    type Inside = Box<dyn Fn(f64, f64) -> bool>;
    let shapes: Vec<(&str, Inside)> = vec![
        (
            "disc mask",
            Box::new(|i: f64, j: f64| (i - 60.0).hypot(j - 60.0) < 50.0),
        ),
        (
            "L mask",
            Box::new(|i: f64, j: f64| {
                (10.0..110.0).contains(&i) && (10.0..110.0).contains(&j) && (i < 50.0 || j < 50.0)
            }),
        ),
        (
            "holes mask",
            Box::new(|i: f64, j: f64| {
                (10.0..110.0).contains(&i)
                    && (10.0..110.0).contains(&j)
                    && !((30.0..55.0).contains(&i) && (30.0..55.0).contains(&j))
                    && (i - 80.0).hypot(j - 75.0) > 15.0
            }),
        ),
    ];
    for (name, f) in shapes {
        let mask: Vec<bool> = (0..n * n)
            .map(|k| f((k / n) as f64, (k % n) as f64))
            .collect();
        let cells = mask.iter().filter(|&&m| m).count() as f64;
        let domain = Domain::from_mask(&mask, [n, n], [1.0, 1.0], 0.36, &Control::default())
            .expect("domain");
        let rings = domain.rings().to_vec();
        let area = rings
            .iter()
            .map(|r| {
                // Holes are the rings inside another ring.
                let a = ring_area(r);
                let nested = rings
                    .iter()
                    .filter(|o| !std::ptr::eq(*o, r) && inside(std::slice::from_ref(*o), r[0]))
                    .count();
                if nested % 2 == 1 {
                    -a
                } else {
                    a
                }
            })
            .sum::<f64>();
        // The simplified boundary stays close to the cell edges: the area
        // within 2 % of the cell count.
        assert!(
            (area - cells).abs() < 0.02 * cells,
            "{name}: {area} vs {cells}"
        );
        let options = DomainMeshOptions {
            size: MeshSize::Count(1500),
            ..Default::default()
        };
        let m = mesh_domain(&domain, &options, &Control::default()).expect("mesh");
        check(name, &rings, area, &m, 1e-9);
    }
}

#[test]
fn a_metric_shortens_edges_where_it_is_large() {
    // W = 1 + 3 exp(-|x - c|² / 2σ²): edges near c about 4 times shorter.
    let n = 101;
    let cost: Vec<f64> = (0..n * n)
        .map(|k| {
            let (i, j) = ((k / n) as f64 - 50.0, (k % n) as f64 - 50.0);
            1.0 + 3.0 * (-(i * i + j * j) / (2.0 * 100.0)).exp()
        })
        .collect();
    let field = SizeField::from_metric(&cost, [n, n], [1.0, 1.0]).expect("field");
    let rings = vec![vec![[0.0, 0.0], [100.0, 0.0], [100.0, 100.0], [0.0, 100.0]]];
    let domain = Domain::new(rings.clone()).expect("domain");
    let options = DomainMeshOptions {
        size: MeshSize::EdgeLength(4.0),
        field,
        ..Default::default()
    };
    let m = mesh_domain(&domain, &options, &Control::default()).expect("mesh");
    check("metric", &rings, 10_000.0, &m, 1e-9);
    let mut near = (0.0, 0usize);
    let mut far = (0.0, 0usize);
    for t in &m.triangles {
        for k in 0..3 {
            let (a, b) = (m.points[t[k] as usize], m.points[t[(k + 1) % 3] as usize]);
            let mid = [(a[0] + b[0]) / 2.0 - 50.0, (a[1] + b[1]) / 2.0 - 50.0];
            let len = (a[0] - b[0]).hypot(a[1] - b[1]);
            let r = mid[0].hypot(mid[1]);
            if r < 5.0 {
                near = (near.0 + len, near.1 + 1);
            } else if r > 40.0 {
                far = (far.0 + len, far.1 + 1);
            }
        }
    }
    let (near, far) = (near.0 / near.1 as f64, far.0 / far.1 as f64);
    // W ≈ 3.6 to 4 near the centre, ≈ 1 far: the ratio of edge lengths.
    assert!(
        far / near > 2.8 && far / near < 4.8,
        "near {near}, far {far}"
    );
    // Far from the bump, edges are about edge_length long.
    assert!((far - 4.0).abs() < 0.8, "far {far}");
}
