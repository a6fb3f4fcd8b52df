//! `geodex mesh-distance`: per-vertex geodesic distance on a mesh file for
//! batch users, written as a 1D f64 NPY in the file's vertex order (after
//! welding, which is reported on stderr).
//!
//! The command builds a [`MeshDistanceRequest`], the schema of
//! `POST /v1/mesh/distance`, and runs it through the same operation.
//!
//! ```text
//! geodex mesh-distance --mesh bunny.ply --source-vertex 0 --method heat --out D.npy --labels L.npy
//! geodex mesh-distance --mesh part.stl --source-face 12,0.2,0.3,0.5 --out D.npy
//! geodex mesh-distance --mesh scan.ply --source-vertex 0 --out D.npy \
//!     --metric '{"kind": "curvature", "feature": "ridges"}'
//! geodex mesh-distance --mesh scan.ply --source-vertex 0 --out D.npy \
//!     --metric '{"kind": "field", "field": "texture.npy", "mode": "follow"}'
//! ```
//!
//! `--metric` takes the `metric` section of the request as JSON; where the
//! service names a dataset by id (`field`, `dataset`), the command reads that
//! file (NPY, TIFF, PNG, NIfTI, JSON), as `--weights` does.
//!
//! Errors are one line on stderr and a non-zero exit status.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use clap::{Args, ValueEnum};

use super::distance::method_value;
use super::run::{run_operation, FlagMap};
use crate::io::mesh::{read_mesh, MeshFormat, MeshLimits};
use crate::io::{self, ArrayData};
use crate::ops::spec::mesh::MeshDistanceRequest;
use crate::ops::spec::mesh::{HeatSpec, LaplacianSpec, MeshInput, MeshMethodSpec, MeshPointSpec};
use crate::ops::spec::mesh_metric::SurfaceMetricSpec;
use crate::ops::{InputArray, Inputs};
use crate::problem::ApiError;
use crate::runner::LoadInputs;

/// Flags of `geodex mesh-distance`.
#[derive(Debug, Clone, Args)]
pub struct MeshDistanceArgs {
    /// The mesh: OBJ, PLY (ASCII or binary), OFF or STL (by extension, else detected).
    #[arg(long, value_name = "MESH")]
    pub mesh: PathBuf,
    /// A source vertex (0-based, in the file's order after welding); repeat for several.
    #[arg(long = "source-vertex", value_name = "V")]
    pub source_vertices: Vec<u32>,
    /// A source inside a face: face index and its three barycentric coordinates; repeat for several.
    #[arg(long = "source-face", value_name = "F,B0,B1,B2")]
    pub source_faces: Vec<String>,
    /// The method.
    #[arg(long, value_parser = method_value::<MeshMethodArg>, default_value = "fast_marching")]
    pub method: MeshMethodArg,
    /// Heat method time step factor m (t = m h²).
    #[arg(long, default_value_t = 1.0)]
    pub heat_m: f64,
    /// Heat method Laplacian.
    #[arg(long, value_enum, default_value_t = LaplacianArg::Robust)]
    pub laplacian: LaplacianArg,
    /// Heat method: lower t on surfaces curved at the scale of their edges
    /// (the request's `heat.adapt`); false gives t = m h².
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set, value_name = "BOOL")]
    pub heat_adapt: bool,
    /// Vertices farther than this get +inf.
    #[arg(long)]
    pub max_distance: Option<f64>,
    /// A file with one weight W > 0 per vertex (cost per unit length).
    #[arg(long, value_name = "W.npy")]
    pub weights: Option<PathBuf>,
    /// The request's `metric` section as JSON (designs from curvature or a
    /// field, face tensors); dataset ids in it are file paths.
    #[arg(long, value_name = "JSON")]
    pub metric: Option<String>,
    /// Output: f64 distance per vertex (NPY).
    #[arg(long, value_name = "D.npy")]
    pub out: PathBuf,
    /// Output: i32 index of the nearest source per vertex (NPY), -1 where unreached.
    #[arg(long, value_name = "L.npy")]
    pub labels: Option<PathBuf>,
}

/// `--laplacian` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum LaplacianArg {
    /// Intrinsic Delaunay Laplacian of the mollified mesh (tufted cover when non-manifold).
    Robust,
    /// Plain cotangent Laplacian of the mesh's own triangles.
    Cotangent,
}

impl LaplacianArg {
    /// The request's heat options with `m` and `adapt`.
    pub fn heat(self, m: f64, adapt: bool) -> HeatSpec {
        HeatSpec {
            m,
            laplacian: match self {
                LaplacianArg::Robust => LaplacianSpec::Robust,
                LaplacianArg::Cotangent => LaplacianSpec::Cotangent,
            },
            adapt,
        }
    }
}

/// `--method` values, spelled as in the request JSON (`fast_marching`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
#[value(rename_all = "snake_case")]
pub enum MeshMethodArg {
    /// Kimmel–Sethian fast marching.
    FastMarching,
    /// The heat method.
    Heat,
    /// Exact polyhedral distance.
    Exact,
    /// Dijkstra on the edges.
    Dijkstra,
}

/// The one mesh of a mesh command, whatever id its request names.
pub(crate) struct One(pub(crate) Arc<MeshInput>);

impl LoadInputs for One {
    async fn load(&mut self, _ids: Vec<(String, String)>) -> Result<(), ApiError> {
        Ok(())
    }
}

impl Inputs for One {
    fn get(&self, _id: &str) -> Option<InputArray> {
        None
    }
    fn mesh(&self, _id: &str) -> Option<Arc<MeshInput>> {
        Some(self.0.clone())
    }
}

/// One mesh and the array files its request names (ids are paths).
pub(crate) struct WithFiles(
    pub(crate) Arc<MeshInput>,
    pub(crate) std::collections::HashMap<String, InputArray>,
);

impl LoadInputs for WithFiles {
    async fn load(&mut self, _ids: Vec<(String, String)>) -> Result<(), ApiError> {
        Ok(())
    }
}

impl Inputs for WithFiles {
    fn get(&self, id: &str) -> Option<InputArray> {
        self.1.get(id).cloned()
    }
    fn mesh(&self, _id: &str) -> Option<Arc<MeshInput>> {
        Some(self.0.clone())
    }
}

fn parse_face(s: &str, i: usize) -> Result<MeshPointSpec, String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    let bad = || format!("--source-face {}: expected F,B0,B1,B2, got '{s}'", i + 1);
    if parts.len() != 4 {
        return Err(bad());
    }
    let face: u32 = parts[0].parse().map_err(|_| bad())?;
    let mut bary = [0.0; 3];
    for k in 0..3 {
        bary[k] = parts[k + 1].parse().map_err(|_| bad())?;
    }
    Ok(MeshPointSpec {
        vertex: None,
        face: Some(face),
        bary: Some(bary),
    })
}

pub(crate) fn write_npy(path: &Path, array: &ArrayData, flag: &str) -> Result<(), String> {
    let bytes = io::encode_npy(array).map_err(|e| format!("{flag}: {e}"))?;
    std::fs::write(path, bytes).map_err(|e| format!("{flag} {}: {e}", path.display()))
}

/// Reads a mesh file (format by extension, else detected) and prints its
/// report (welding, dropped faces, components) on stderr.
pub(crate) fn load_mesh_file(path: &Path) -> Result<MeshInput, String> {
    let bytes = std::fs::read(path).map_err(|e| format!("--mesh {}: {e}", path.display()))?;
    let format = path
        .file_name()
        .and_then(|n| MeshFormat::from_name(&n.to_string_lossy()));
    let loaded = read_mesh(&bytes, format, &MeshLimits::default())
        .map_err(|e| format!("--mesh {}: {e}", path.display()))?;
    let r = &loaded.report;
    eprintln!(
        "geodex: {}: {} vertices ({} welded), {} faces ({} degenerate and {} duplicate dropped), \
         {} components, {} boundary loops, {} non-manifold edges",
        path.display(),
        r.vertices,
        r.welded_vertices,
        r.faces,
        r.degenerate_faces,
        r.duplicate_faces,
        r.components,
        r.boundary_loops,
        r.non_manifold_edges
    );
    Ok(MeshInput {
        mesh: loaded.mesh,
        topology: loaded.topology,
        report: loaded.report,
    })
}

/// Runs the command.
pub fn run(args: &MeshDistanceArgs) -> Result<(), String> {
    let started = Instant::now();
    let input = load_mesh_file(&args.mesh)?;
    let read_seconds = started.elapsed().as_secs_f64();
    let mut sources: Vec<MeshPointSpec> = args
        .source_vertices
        .iter()
        .map(|&v| MeshPointSpec {
            vertex: Some(v),
            face: None,
            bary: None,
        })
        .collect();
    for (i, s) in args.source_faces.iter().enumerate() {
        sources.push(parse_face(s, i)?);
    }
    if sources.is_empty() {
        return Err("give at least one --source-vertex or --source-face".into());
    }
    let metric = MetricFiles::read(args.weights.as_deref(), args.metric.as_deref())?;
    let request = MeshDistanceRequest {
        mesh: "file".into(),
        sources,
        method: match args.method {
            MeshMethodArg::FastMarching => MeshMethodSpec::FastMarching,
            MeshMethodArg::Heat => MeshMethodSpec::Heat,
            MeshMethodArg::Exact => MeshMethodSpec::Exact,
            MeshMethodArg::Dijkstra => MeshMethodSpec::Dijkstra,
        },
        max_distance: args.max_distance,
        weights: metric.weights,
        metric: metric.metric,
        heat: args.laplacian.heat(args.heat_m, args.heat_adapt),
    };
    let files = metric.files;
    let vertices = args.source_vertices.len();
    let flags = FlagMap::new()
        .each_in("sources", "--source-vertex", 0..vertices)
        .each_in("sources", "--source-face", vertices..usize::MAX)
        .field("sources", "--source-vertex")
        .field("heat.m", "--heat-m")
        .field("heat", "--laplacian")
        .field("weights", "--weights")
        .field("metric", "--metric");
    let inputs = WithFiles(Arc::new(input), files);
    let output = run_operation(Box::new(request), inputs, &flags).map_err(|e| e.to_string())?;
    let written = Instant::now();
    for a in &output.arrays {
        match a.name.as_str() {
            "distance" => write_npy(&args.out, &a.array, "--out")?,
            "labels" => {
                if let Some(p) = &args.labels {
                    write_npy(p, &a.array, "--labels")?;
                }
            }
            _ => {}
        }
    }
    let write_seconds = written.elapsed().as_secs_f64();
    let doc = &output.document;
    let solve = doc["stats"]["solve_seconds"].as_f64().unwrap_or(f64::NAN);
    let factor = doc["heat"]["factor_seconds"].as_f64().unwrap_or(0.0);
    let setup = &doc["heat"]["setup"];
    let part = |k: &str| setup[k].as_f64().unwrap_or(0.0);
    eprintln!(
        "geodex: phases: read {read_seconds:.4} s (parse, weld, topology), setup {factor:.4} s \
         (heat: guard {:.4} s, Laplacian {:.4} s, factorisations {:.4} s), solve {:.4} s, \
         write {write_seconds:.4} s",
        part("underflow_guard_seconds"),
        part("laplacian_seconds"),
        part("factorisation_seconds"),
        solve - factor
    );
    if let Some(t) = doc["heat"]["t"].as_f64() {
        eprintln!(
            "geodex: heat: t {t:.4e} (m {}, curvature roughness {:.3e}, estimated in {:.4} s)",
            doc["heat"]["m"],
            doc["heat"]["roughness"].as_f64().unwrap_or(0.0),
            part("curvature_seconds"),
        );
    }
    Ok(())
}

/// `--weights` and `--metric` of a mesh command: the request's `weights`
/// and `metric` fields (dataset ids are the file paths) and the arrays read
/// from those files, by path.
pub(super) struct MetricFiles {
    pub weights: Option<String>,
    pub metric: Option<SurfaceMetricSpec>,
    pub files: std::collections::HashMap<String, InputArray>,
}

impl MetricFiles {
    /// Parses `--metric` and reads every file it and `--weights` name;
    /// errors name the flag.
    pub fn read(weights: Option<&Path>, metric: Option<&str>) -> Result<Self, String> {
        let weights = weights.map(|p| p.display().to_string());
        let metric = metric
            .map(|json| {
                serde_json::from_str::<SurfaceMetricSpec>(json)
                    .map_err(|e| format!("--metric: not a metric section: {e}"))
            })
            .transpose()?;
        let mut files = std::collections::HashMap::new();
        let named = weights.iter().map(|w| ("--weights", w.clone())).chain(
            metric
                .iter()
                .flat_map(|m| m.dataset_ids())
                .map(|(_, id)| ("--metric", id)),
        );
        for (flag, path) in named {
            let d =
                super::distance::read_array(flag, Path::new(&path)).map_err(|e| e.to_string())?;
            files.insert(
                path,
                InputArray {
                    array: Arc::new(d.array),
                    spacing: d.spacing,
                },
            );
        }
        Ok(Self {
            weights,
            metric,
            files,
        })
    }
}

/// Flags of `geodex mesh-curvature`.
#[derive(Debug, Clone, Args)]
pub struct MeshCurvatureArgs {
    /// The mesh: OBJ, PLY (ASCII or binary), OFF or STL.
    #[arg(long, value_name = "MESH")]
    pub mesh: PathBuf,
    /// Passes of one-ring smoothing of the curvature tensor (0-1024; 2-4 for noisy scans).
    #[arg(long, default_value_t = 1)]
    pub smoothing: usize,
    /// Output: the mesh with per-vertex `k1`, `k2`, `mean`, `gaussian` (`.ply`, `.json` or `.glb`).
    #[arg(long, value_name = "OUT.ply")]
    pub out: PathBuf,
    /// Output: an N × 4 f64 NPY of the columns k1, k2, mean, gaussian.
    #[arg(long, value_name = "C.npy")]
    pub npy: Option<PathBuf>,
}

/// Runs `geodex mesh-curvature` (the request of `POST /v1/mesh/curvature`).
pub fn run_curvature(args: &MeshCurvatureArgs) -> Result<(), String> {
    use crate::io::mesh::write::{encode_by_extension, VertexProperty};
    use crate::ops::mesh_curvature::MeshCurvatureRequest;
    let input = load_mesh_file(&args.mesh)?;
    let request = MeshCurvatureRequest {
        mesh: "file".into(),
        smoothing: args.smoothing,
    };
    let output = run_operation(Box::new(request), One(Arc::new(input)), &FlagMap::new())
        .map_err(|e| e.to_string())?;
    let column = |name: &str| -> Vec<f64> {
        output
            .arrays
            .iter()
            .find(|a| a.name == name)
            .and_then(|a| match &a.array {
                ArrayData::F64(x) => Some(x.iter().copied().collect()),
                _ => None,
            })
            .unwrap_or_default()
    };
    let (k1, k2, mean, gaussian) = (
        column("k1"),
        column("k2"),
        column("mean_curvature"),
        column("gaussian_curvature"),
    );
    let Some(mesh) = &output.mesh else {
        return Err("geodex: the operation returned no mesh".into());
    };
    let props = [
        VertexProperty::F64("k1", &k1),
        VertexProperty::F64("k2", &k2),
        VertexProperty::F64("mean", &mean),
        VertexProperty::F64("gaussian", &gaussian),
    ];
    if args.out.extension().and_then(|e| e.to_str()) == Some("obj") {
        return Err(
            "--out: OBJ has no place for per-vertex values: use .ply, .json or .glb".into(),
        );
    }
    let bytes = encode_by_extension(&mesh.mesh.mesh, &props, &args.out)
        .map_err(|e| format!("--out: {e}"))?;
    std::fs::write(&args.out, bytes)
        .map_err(|e| format!("--out: cannot write '{}': {e}", args.out.display()))?;
    if let Some(p) = &args.npy {
        let n = k1.len();
        let table: Vec<f64> = (0..n)
            .flat_map(|v| [k1[v], k2[v], mean[v], gaussian[v]])
            .collect();
        let a = ndarray::ArrayD::from_shape_vec(vec![n, 4], table).map_err(|e| e.to_string())?;
        write_npy(p, &ArrayData::F64(a), "--npy")?;
    }
    let doc = &output.document;
    println!(
        "geodex: wrote {} ({} vertices; mean curvature min {}, median {}, max {})",
        args.out.display(),
        doc["vertices"],
        doc["stats"]["mean"]["min"],
        doc["stats"]["mean"]["median"],
        doc["stats"]["mean"]["max"]
    );
    Ok(())
}
