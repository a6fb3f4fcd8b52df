//! `geodex distance-matrix`, `geodex embed`, `geodex descriptor` and
//! `geodex correspond`: geodesic distance matrices, canonical forms and
//! shape descriptors of a mesh file, and the correspondence between two
//! mesh files, for batch users.
//!
//! Each builds the request of its endpoint (`POST /v1/mesh/distance-matrix`,
//! `POST /v1/mesh/embed`, `POST /v1/mesh/descriptor`,
//! `POST /v1/mesh/correspond`) and runs it through the same operation.
//!
//! ```text
//! geodex distance-matrix --mesh bunny.ply --landmarks 500 --method heat --out D.npy
//! geodex embed --mesh cat.off --landmarks 300 --out form.ply --coordinates X.npy
//! geodex descriptor --mesh cat.off --landmarks 32 --bins 32 --out cat.json
//! geodex correspond --a cat0.off --b cat1.off --out matched.ply --face F.npy --bary L.npy
//! ```

use std::path::PathBuf;
use std::sync::Arc;

use clap::Args;

use super::mesh_distance::{
    load_mesh_file, write_npy, LaplacianArg, MeshMethodArg, MetricFiles, One, WithFiles,
};
use super::run::{run_operation, FlagMap};
use crate::io::mesh::write::encode_by_extension;
use crate::io::mesh::write::VertexProperty;
use crate::io::ArrayData;
use crate::ops::mesh_correspond::MeshCorrespondRequest;
use crate::ops::mesh_descriptor::MeshDescriptorRequest;
use crate::ops::mesh_distance_matrix::MeshDistanceMatrixRequest;
use crate::ops::mesh_embed::{MeshEmbedRequest, SmacofSpec};
use crate::ops::spec::mesh::MeshInput;
use crate::ops::spec::mesh::MeshMethodSpec;
use crate::ops::spec::shape::SymmetrySpec;
use crate::ops::{DynOperation, InputArray, Inputs, OpOutput};
use crate::problem::ApiError;
use crate::runner::LoadInputs;

/// Flags of `geodex distance-matrix`.
#[derive(Debug, Clone, Args)]
pub struct DistanceMatrixArgs {
    /// The mesh: OBJ, PLY, OFF or STL.
    #[arg(long, value_name = "MESH")]
    pub mesh: PathBuf,
    /// Rows from this many farthest-point landmarks (default: all pairs, up to 5000 vertices).
    #[arg(long)]
    pub landmarks: Option<usize>,
    /// A source vertex (a row); repeat for several. Replaces --landmarks.
    #[arg(long = "source-vertex", value_name = "V")]
    pub sources: Vec<u32>,
    /// The method.
    #[arg(long, value_parser = super::distance::method_value::<MeshMethodArg>, default_value = "fast_marching")]
    pub method: MeshMethodArg,
    /// Heat method time step factor m (t = m h²).
    #[arg(long, default_value_t = 1.0)]
    pub heat_m: f64,
    /// Heat method: lower t on surfaces curved at the scale of their edges
    /// (the request's `heat.adapt`); false gives t = m h².
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set, value_name = "BOOL")]
    pub heat_adapt: bool,
    /// Heat method Laplacian.
    #[arg(long, value_enum, default_value_t = LaplacianArg::Robust)]
    pub laplacian: LaplacianArg,
    /// A file with one weight W > 0 per vertex: W-weighted rows
    /// (fast_marching or dijkstra).
    #[arg(long, value_name = "W.npy")]
    pub weights: Option<PathBuf>,
    /// The request's `metric` section as JSON, as for `geodex mesh-distance`
    /// (dataset ids in it are file paths).
    #[arg(long, value_name = "JSON")]
    pub metric: Option<String>,
    /// Take the smaller of d(i, j) and d(j, i) instead of their average.
    #[arg(long)]
    pub min: bool,
    /// Output: the rows × vertices f64 matrix (NPY).
    #[arg(long, value_name = "D.npy")]
    pub out: PathBuf,
}

/// Flags of `geodex embed`.
#[derive(Debug, Clone, Args)]
pub struct EmbedArgs {
    /// The mesh (one connected component): OBJ, PLY, OFF or STL.
    #[arg(long, value_name = "MESH")]
    pub mesh: PathBuf,
    /// Embedding dimension, 2 or 3.
    #[arg(long, default_value_t = 3)]
    pub dimensions: usize,
    /// Landmark MDS from this many farthest-point landmarks (default: all pairs).
    #[arg(long)]
    pub landmarks: Option<usize>,
    /// Refine the all-pairs embedding by this many SMACOF iterations.
    #[arg(long, value_name = "N")]
    pub smacof: Option<usize>,
    /// The method.
    #[arg(long, value_parser = super::distance::method_value::<MeshMethodArg>, default_value = "fast_marching")]
    pub method: MeshMethodArg,
    /// Heat method time step factor m (t = m h²).
    #[arg(long, default_value_t = 1.0)]
    pub heat_m: f64,
    /// Heat method: lower t on surfaces curved at the scale of their edges
    /// (the request's `heat.adapt`); false gives t = m h².
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set, value_name = "BOOL")]
    pub heat_adapt: bool,
    /// Heat method Laplacian.
    #[arg(long, value_enum, default_value_t = LaplacianArg::Robust)]
    pub laplacian: LaplacianArg,
    /// Output: the canonical form, the input's faces at the embedded positions
    /// (`.ply`, `.obj`, `.json` or `.glb`, after the extension).
    #[arg(long, value_name = "FORM.ply")]
    pub out: PathBuf,
    /// Output: the vertices × dimensions f64 coordinates (NPY).
    #[arg(long, value_name = "X.npy")]
    pub coordinates: Option<PathBuf>,
}

/// Flags of `geodex descriptor`.
#[derive(Debug, Clone, Args)]
pub struct DescriptorArgs {
    /// The mesh (one connected component): OBJ, PLY, OFF or STL.
    #[arg(long, value_name = "MESH")]
    pub mesh: PathBuf,
    /// Farthest-point landmarks, 4 to 1000.
    #[arg(long, default_value_t = 32)]
    pub landmarks: usize,
    /// Bins of each histogram, 2 to 1024.
    #[arg(long, default_value_t = 32)]
    pub bins: usize,
    /// The method.
    #[arg(long, value_parser = super::distance::method_value::<MeshMethodArg>, default_value = "fast_marching")]
    pub method: MeshMethodArg,
    /// Heat method time step factor m (t = m h²).
    #[arg(long, default_value_t = 1.0)]
    pub heat_m: f64,
    /// Heat method: lower t on surfaces curved at the scale of their edges
    /// (the request's `heat.adapt`); false gives t = m h².
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set, value_name = "BOOL")]
    pub heat_adapt: bool,
    /// Heat method Laplacian.
    #[arg(long, value_enum, default_value_t = LaplacianArg::Robust)]
    pub laplacian: LaplacianArg,
    /// Output: the descriptor as JSON (the `descriptor` of the endpoint's
    /// answer); standard output when absent.
    #[arg(long, value_name = "D.json")]
    pub out: Option<PathBuf>,
}

fn method(m: MeshMethodArg) -> MeshMethodSpec {
    match m {
        MeshMethodArg::FastMarching => MeshMethodSpec::FastMarching,
        MeshMethodArg::Heat => MeshMethodSpec::Heat,
        MeshMethodArg::Exact => MeshMethodSpec::Exact,
        MeshMethodArg::Dijkstra => MeshMethodSpec::Dijkstra,
    }
}

/// Runs `request` on the mesh file; a refused field is named as its flag.
fn run_on_mesh(request: Box<dyn DynOperation>, mesh: &std::path::Path) -> Result<OpOutput, String> {
    let input = load_mesh_file(mesh)?;
    run_operation(request, One(Arc::new(input)), &mesh_flags()).map_err(|e| e.to_string())
}

/// The request fields of these commands and the flags that set them.
fn mesh_flags() -> FlagMap {
    FlagMap::new()
        .field("sources", "--source-vertex")
        .field("heat", "--heat-m")
        .field("landmarks", "--landmarks")
        .field("bins", "--bins")
}

/// Runs `geodex distance-matrix`.
pub fn run_distance_matrix(args: &DistanceMatrixArgs) -> Result<(), String> {
    let metric = MetricFiles::read(args.weights.as_deref(), args.metric.as_deref())?;
    let request = MeshDistanceMatrixRequest {
        mesh: "file".into(),
        landmarks: args.landmarks,
        sources: (!args.sources.is_empty()).then(|| args.sources.clone()),
        method: method(args.method),
        weights: metric.weights,
        metric: metric.metric,
        symmetry: if args.min {
            SymmetrySpec::Min
        } else {
            SymmetrySpec::Average
        },
        heat: args.laplacian.heat(args.heat_m, args.heat_adapt),
    };
    let input = load_mesh_file(&args.mesh)?;
    let flags = mesh_flags()
        .field("weights", "--weights")
        .field("metric", "--metric");
    let inputs = WithFiles(Arc::new(input), metric.files);
    let output = run_operation(Box::new(request), inputs, &flags).map_err(|e| e.to_string())?;
    let matrix = output
        .array("matrix")
        .ok_or("the operation returned no matrix")?;
    write_npy(&args.out, matrix, "--out")?;
    eprintln!(
        "geodex: {} × {} distances written to {}",
        output.document["rows"],
        output.document["columns"],
        args.out.display()
    );
    Ok(())
}

/// Runs `geodex embed`.
pub fn run_embed(args: &EmbedArgs) -> Result<(), String> {
    let request = MeshEmbedRequest {
        mesh: "file".into(),
        dimensions: args.dimensions,
        landmarks: args.landmarks,
        smacof: args.smacof.map(|iterations| SmacofSpec {
            iterations,
            tolerance: 1e-6,
        }),
        method: method(args.method),
        heat: args.laplacian.heat(args.heat_m, args.heat_adapt),
    };
    let output = run_on_mesh(Box::new(request), &args.mesh)?;
    let form = output
        .mesh
        .as_ref()
        .ok_or("the operation returned no mesh")?;
    let bytes = encode_by_extension(&form.mesh.mesh, &[], &args.out)
        .map_err(|e| format!("--out {}: {e}", args.out.display()))?;
    std::fs::write(&args.out, bytes).map_err(|e| format!("--out {}: {e}", args.out.display()))?;
    if let Some(p) = &args.coordinates {
        let x = output
            .array("coordinates")
            .ok_or("the operation returned no coordinates")?;
        write_npy(p, x, "--coordinates")?;
    }
    eprintln!(
        "geodex: canonical form written to {} (explained variance {}, stress {})",
        args.out.display(),
        output.document["explained_variance"],
        output.document["stress"]
    );
    Ok(())
}

/// Runs `geodex descriptor`.
pub fn run_descriptor(args: &DescriptorArgs) -> Result<(), String> {
    let request = MeshDescriptorRequest {
        mesh: "file".into(),
        landmarks: args.landmarks,
        bins: args.bins,
        method: method(args.method),
        heat: args.laplacian.heat(args.heat_m, args.heat_adapt),
    };
    let output = run_on_mesh(Box::new(request), &args.mesh)?;
    let text = serde_json::to_string_pretty(&output.document["descriptor"])
        .map_err(|e| format!("descriptor: {e}"))?;
    match &args.out {
        Some(p) => {
            std::fs::write(p, text + "\n").map_err(|e| format!("--out {}: {e}", p.display()))?;
            eprintln!(
                "geodex: descriptor ({} values) written to {}",
                2 * args.bins + crate::numerics::shape::descriptor::MOMENTS,
                p.display()
            );
        }
        None => println!("{text}"),
    }
    Ok(())
}

/// Flags of `geodex correspond`.
#[derive(Debug, Clone, Args)]
pub struct CorrespondArgs {
    /// The first mesh (one connected component): every vertex gets a match.
    #[arg(long, value_name = "MESH")]
    pub a: PathBuf,
    /// The second mesh (one connected component), a near-isometric pose of the first.
    #[arg(long, value_name = "MESH")]
    pub b: PathBuf,
    /// Farthest-point landmarks on each mesh (8 to 500).
    #[arg(long, default_value_t = 60)]
    pub landmarks: usize,
    /// Rescale the second mesh to the area of the first before matching.
    #[arg(long)]
    pub scale: bool,
    /// Output: the first mesh with per-vertex `match_face`, `match_vertex`,
    /// `match_bary0..2` and `confidence` (`.ply`, `.json`, after the extension).
    #[arg(long, value_name = "MATCHED.ply")]
    pub out: PathBuf,
    /// Output: the face of the second mesh holding each match (int32 NPY).
    #[arg(long, value_name = "F.npy")]
    pub face: Option<PathBuf>,
    /// Output: the barycentric coordinates of each match, n × 3 f64 NPY.
    #[arg(long, value_name = "L.npy")]
    pub bary: Option<PathBuf>,
    /// Output: the vertex of the second mesh nearest each match (int32 NPY).
    #[arg(long, value_name = "V.npy")]
    pub vertex: Option<PathBuf>,
    /// Output: the confidence of each match (f64 NPY).
    #[arg(long, value_name = "C.npy")]
    pub confidence: Option<PathBuf>,
}

/// The two meshes of `geodex correspond`, under the ids `a` and `b`.
struct Two(Arc<MeshInput>, Arc<MeshInput>);

impl LoadInputs for Two {
    async fn load(&mut self, _ids: Vec<(String, String)>) -> Result<(), ApiError> {
        Ok(())
    }
}

impl Inputs for Two {
    fn get(&self, _id: &str) -> Option<InputArray> {
        None
    }
    fn mesh(&self, id: &str) -> Option<Arc<MeshInput>> {
        match id {
            "a" => Some(self.0.clone()),
            "b" => Some(self.1.clone()),
            _ => None,
        }
    }
}

/// Runs `geodex correspond`.
pub fn run_correspond(args: &CorrespondArgs) -> Result<(), String> {
    let a = load_mesh_file(&args.a).map_err(|e| e.replacen("--mesh", "--a", 1))?;
    let b = load_mesh_file(&args.b).map_err(|e| e.replacen("--mesh", "--b", 1))?;
    let request = MeshCorrespondRequest {
        a: "a".into(),
        b: "b".into(),
        landmarks: args.landmarks,
        scale: args.scale,
    };
    let flags = FlagMap::new().field("a", "--a").field("b", "--b");
    let output = run_operation(Box::new(request), Two(Arc::new(a), Arc::new(b)), &flags)
        .map_err(|e| e.to_string())?;
    let matched = output
        .mesh
        .as_ref()
        .ok_or("the operation returned no mesh")?;
    let mut props: Vec<VertexProperty<'_>> = Vec::new();
    for (property, array) in &matched.vertex_properties {
        match output.array(array) {
            Some(ArrayData::F64(x)) => {
                if let Some(s) = x.as_slice() {
                    props.push(VertexProperty::F64(property, s));
                }
            }
            Some(ArrayData::I32(x)) => {
                if let Some(s) = x.as_slice() {
                    props.push(VertexProperty::I32(property, s));
                }
            }
            _ => {}
        }
    }
    let bytes = encode_by_extension(&matched.mesh.mesh, &props, &args.out)
        .map_err(|e| format!("--out {}: {e}", args.out.display()))?;
    std::fs::write(&args.out, bytes).map_err(|e| format!("--out {}: {e}", args.out.display()))?;
    for (path, name, flag) in [
        (&args.face, "face", "--face"),
        (&args.bary, "bary", "--bary"),
        (&args.vertex, "vertex", "--vertex"),
        (&args.confidence, "confidence", "--confidence"),
    ] {
        if let Some(p) = path {
            let x = output
                .array(name)
                .ok_or_else(|| format!("the operation returned no {name}"))?;
            write_npy(p, x, flag)?;
        }
    }
    eprintln!(
        "geodex: {} matches written to {} (symmetric {}, distortion {}, alternative {}, mean confidence {})",
        output.document["stats"]["vertices_a"],
        args.out.display(),
        output.document["symmetric"],
        output.document["distortion"],
        output.document["alternative_distortion"],
        output.document["mean_confidence"],
    );
    Ok(())
}
