//! Triangle-mesh codecs: OBJ, PLY (ASCII, binary little and big endian,
//! through `ply-rs-bw`), OFF and STL (ASCII and binary, duplicate vertices
//! welded) in; PLY with per-vertex properties, OBJ and JSON out.
//!
//! Every reader checks declared counts against [`MeshLimits`] before it
//! allocates, never panics on malformed input, triangulates polygons as
//! fans, and repairs what can be repaired without changing the surface:
//! faces that repeat a vertex or have zero area are dropped, exact duplicate
//! faces are dropped, and both are counted in the [`MeshReport`]. What
//! cannot be repaired is refused with a [`MeshIoError`] naming the culprit
//! (an index out of range, a non-finite coordinate, no face left).
//!
//! * [`obj`], [`off`], [`stl`], [`ply`]: the readers.
//! * [`write`]: PLY / OBJ / JSON writers; [`glb`]: glTF binary.

pub mod glb;
pub mod obj;
pub mod off;
pub mod ply;
pub mod stl;
pub mod write;

use serde::{Deserialize, Serialize};

use crate::numerics::buckets::bucket;
use crate::numerics::mesh::{cross, norm, sub, MeshError, Topology, TriMesh};

/// A mesh file format.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(rename_all = "lowercase")]
pub enum MeshFormat {
    /// Wavefront OBJ (`v` and `f` records; polygons triangulated).
    Obj,
    /// Stanford PLY, ASCII or binary (either byte order).
    Ply,
    /// Object File Format.
    Off,
    /// STL, ASCII or binary (vertices welded).
    Stl,
}

impl MeshFormat {
    /// Every format.
    pub const ALL: [MeshFormat; 4] = [
        MeshFormat::Obj,
        MeshFormat::Ply,
        MeshFormat::Off,
        MeshFormat::Stl,
    ];

    /// The format of a media type (`model/obj`, `model/ply`, `model/stl`,
    /// `model/off`, and the common `application/…` aliases), if it names one.
    pub fn from_media_type(media_type: &str) -> Option<Self> {
        let essence = media_type
            .split(';')
            .next()
            .unwrap_or_default()
            .trim()
            .to_ascii_lowercase();
        Some(match essence.as_str() {
            "model/obj" | "text/x-obj" | "application/x-tgif" => MeshFormat::Obj,
            "model/ply" | "application/ply" | "application/x-ply" => MeshFormat::Ply,
            "model/stl"
            | "model/x.stl-binary"
            | "model/x.stl-ascii"
            | "application/sla"
            | "application/vnd.ms-pki.stl" => MeshFormat::Stl,
            "model/off" | "application/x-off" => MeshFormat::Off,
            _ => return None,
        })
    }

    /// The format of a name (`obj`, `.PLY`, `bunny.off`), if known.
    pub fn from_name(name: &str) -> Option<Self> {
        let lower = name.trim().to_ascii_lowercase();
        Some(match lower.rsplit('.').next().unwrap_or_default() {
            "obj" => MeshFormat::Obj,
            "ply" => MeshFormat::Ply,
            "off" => MeshFormat::Off,
            "stl" => MeshFormat::Stl,
            _ => return None,
        })
    }

    /// The media type to send it with.
    pub fn media_type(self) -> &'static str {
        match self {
            MeshFormat::Obj => "model/obj",
            MeshFormat::Ply => "model/ply",
            MeshFormat::Off => "model/off",
            MeshFormat::Stl => "model/stl",
        }
    }

    /// The format announced by the first bytes, if any (`ply`, `OFF`,
    /// `solid` or a binary STL whose length matches its triangle count).
    pub fn sniff(bytes: &[u8]) -> Option<Self> {
        let head = &bytes[..bytes.len().min(256)];
        let text = String::from_utf8_lossy(head);
        let t = text.trim_start();
        if t.starts_with("ply") {
            Some(MeshFormat::Ply)
        } else if t.starts_with("OFF") || t.starts_with("COFF") || t.starts_with("NOFF") {
            Some(MeshFormat::Off)
        } else if stl::is_binary(bytes) || t.starts_with("solid") {
            Some(MeshFormat::Stl)
        } else if t.lines().any(|l| {
            let l = l.trim_start();
            l.starts_with("v ") || l.starts_with("f ") || l.starts_with('#') || l.starts_with("o ")
        }) {
            Some(MeshFormat::Obj)
        } else {
            None
        }
    }
}

/// Size limits checked before allocating.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MeshLimits {
    /// Most vertices.
    pub max_vertices: usize,
    /// Most triangles (after triangulating polygons).
    pub max_faces: usize,
}

impl Default for MeshLimits {
    fn default() -> Self {
        Self {
            max_vertices: 20_000_000,
            max_faces: 40_000_000,
        }
    }
}

impl MeshLimits {
    pub(crate) fn check(
        &self,
        format: MeshFormat,
        vertices: u64,
        faces: u64,
    ) -> Result<(), MeshIoError> {
        if vertices > self.max_vertices as u64 {
            return Err(MeshIoError::TooLarge {
                format,
                reason: format!(
                    "{vertices} vertices, more than the limit of {}",
                    self.max_vertices
                ),
            });
        }
        if faces > self.max_faces as u64 {
            return Err(MeshIoError::TooLarge {
                format,
                reason: format!("{faces} faces, more than the limit of {}", self.max_faces),
            });
        }
        Ok(())
    }
}

/// Why a mesh file was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MeshIoError {
    /// The bytes are in no known mesh format.
    #[error("unrecognised mesh format (expected OBJ, PLY, OFF or STL)")]
    UnknownFormat,
    /// The file is malformed; `line` when known (1-based).
    #[error("corrupt {format:?} file{}: {reason}", line.map(|l| format!(" at line {l}")).unwrap_or_default())]
    Corrupt {
        /// The format.
        format: MeshFormat,
        /// Line number, when the format is text.
        line: Option<usize>,
        /// What is wrong.
        reason: String,
    },
    /// Declared counts above the limits.
    #[error("{format:?} mesh too large: {reason}")]
    TooLarge {
        /// The format.
        format: MeshFormat,
        /// The numbers.
        reason: String,
    },
    /// The content is well-formed but not an acceptable mesh.
    #[error("invalid mesh: {0}")]
    Invalid(#[from] MeshError),
    /// Writing failed.
    #[error("cannot encode mesh: {0}")]
    Encode(String),
}

impl MeshIoError {
    pub(crate) fn corrupt(
        format: MeshFormat,
        line: Option<usize>,
        reason: impl Into<String>,
    ) -> Self {
        MeshIoError::Corrupt {
            format,
            line,
            reason: reason.into(),
        }
    }
}

/// What reading and repairing a mesh found: stored in the dataset metadata.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct MeshReport {
    /// Vertices kept (after welding).
    pub vertices: usize,
    /// Triangles kept.
    pub faces: usize,
    /// Triangles in the file (after triangulating polygons).
    pub input_faces: usize,
    /// Vertices merged because they had identical coordinates (STL), or
    /// were corners of a face of round-off size (its longest edge below
    /// 1e-12 of the mesh's extent, as marching cubes makes where the
    /// surface passes through a grid point): such a face is collapsed to
    /// one vertex, and the faces it thins out are dropped as degenerate.
    pub welded_vertices: usize,
    /// Triangles dropped because they repeat a vertex or have zero area.
    pub degenerate_faces: usize,
    /// Triangles dropped because they repeat another triangle's vertices.
    pub duplicate_faces: usize,
    /// Edges with one face.
    pub boundary_edges: usize,
    /// Closed loops of boundary edges (holes).
    pub boundary_loops: usize,
    /// Edges with more than two faces.
    pub non_manifold_edges: usize,
    /// Edges whose two faces are inconsistently oriented.
    pub misoriented_edges: usize,
    /// Connected components (through faces; unreferenced vertices excluded).
    pub components: usize,
    /// Vertices used by no face.
    pub isolated_vertices: usize,
}

/// A decoded mesh, its topology and the report of its repairs.
#[derive(Debug, Clone)]
pub struct LoadedMesh {
    /// The mesh.
    pub mesh: TriMesh,
    /// Its adjacency.
    pub topology: Topology,
    /// What was found and repaired.
    pub report: MeshReport,
    /// The format read.
    pub format: MeshFormat,
}

/// Raw parse result: positions and polygons, before repair.
#[derive(Debug, Default)]
pub(crate) struct RawMesh {
    pub positions: Vec<[f64; 3]>,
    pub triangles: Vec<[u32; 3]>,
    pub welded: usize,
}

impl RawMesh {
    /// Appends a polygon as a fan of triangles, checking indices.
    pub(crate) fn push_polygon(
        &mut self,
        format: MeshFormat,
        line: Option<usize>,
        poly: &[i64],
        limits: &MeshLimits,
    ) -> Result<(), MeshIoError> {
        if poly.len() < 3 {
            return Err(MeshIoError::corrupt(
                format,
                line,
                format!("a face needs at least 3 vertices, got {}", poly.len()),
            ));
        }
        let nv = self.positions.len() as i64;
        let mut idx = Vec::with_capacity(poly.len());
        for &i in poly {
            if i < 0 {
                return Err(MeshIoError::corrupt(
                    format,
                    line,
                    format!("vertex index {i} is negative"),
                ));
            }
            if i >= nv {
                return Err(MeshIoError::Invalid(MeshError::IndexOutOfRange {
                    face: self.triangles.len(),
                    index: i as u64,
                    vertices: nv as usize,
                }));
            }
            idx.push(i as u32);
        }
        if self.triangles.len() + poly.len() - 2 > limits.max_faces {
            limits.check(format, 0, (self.triangles.len() + poly.len() - 2) as u64)?;
        }
        for k in 1..idx.len() - 1 {
            self.triangles.push([idx[0], idx[k], idx[k + 1]]);
        }
        Ok(())
    }

    /// Checks coordinates, drops degenerate and duplicate triangles, builds
    /// the mesh and its topology.
    pub(crate) fn finish(self, format: MeshFormat) -> Result<LoadedMesh, MeshIoError> {
        if let Some(vertex) = self
            .positions
            .iter()
            .position(|p| p.iter().any(|c| !c.is_finite()))
        {
            return Err(MeshError::NonFinite { vertex }.into());
        }
        let extent = crate::numerics::mesh::check_scale(&self.positions, &self.triangles)?;
        let input_faces = self.triangles.len();
        let (triangles, collapsed) = weld_round_off_faces(&self.positions, self.triangles, extent);
        let mut degenerate = 0;
        let mut kept = Vec::with_capacity(triangles.len());
        for f in triangles {
            if f[0] == f[1] || f[1] == f[2] || f[0] == f[2] {
                degenerate += 1;
                continue;
            }
            let p = f.map(|v| self.positions[v as usize]);
            let (e1, e2) = (sub(p[1], p[0]), sub(p[2], p[0]));
            let area2 = norm(cross(e1, e2));
            let scale = norm(e1).max(norm(e2)).max(norm(sub(p[2], p[1])));
            if area2.is_nan() || area2 <= 1e-12 * scale * scale {
                degenerate += 1;
                continue;
            }
            kept.push(f);
        }
        let first = first_of_each_vertex_set(&kept, self.positions.len());
        let duplicate = kept.len() - first.iter().filter(|&&b| b).count();
        let faces: Vec<[u32; 3]> = kept
            .into_iter()
            .zip(first)
            .filter_map(|(f, keep)| keep.then_some(f))
            .collect();
        let mesh = TriMesh::new(self.positions, faces)?;
        mesh.check_representable()?;
        let topology = Topology::new(&mesh);
        let report = MeshReport {
            input_faces,
            welded_vertices: self.welded + collapsed,
            degenerate_faces: degenerate,
            duplicate_faces: duplicate,
            ..report_of(&mesh, &topology)
        };
        Ok(LoadedMesh {
            mesh,
            topology,
            report,
            format,
        })
    }
}

/// Collapses every face of round-off size (longest edge below
/// [`crate::numerics::mesh::MIN_FACE_RELATIVE`] times `extent`) to its
/// first corner, merging its vertices (union-find) and renaming them in
/// every face, until none is left (at most four rounds: a merge moves a
/// corner by less than the threshold). Returns the faces and the number of
/// vertices merged away; they stay in the vertex list, unreferenced, so
/// that vertex indices keep the file's order.
fn weld_round_off_faces(
    positions: &[[f64; 3]],
    mut faces: Vec<[u32; 3]>,
    extent: f64,
) -> (Vec<[u32; 3]>, usize) {
    fn find(p: &mut [u32], mut x: u32) -> u32 {
        while p[x as usize] != x {
            p[x as usize] = p[p[x as usize] as usize];
            x = p[x as usize];
        }
        x
    }
    let limit = crate::numerics::mesh::MIN_FACE_RELATIVE * extent;
    let dist = |a: u32, b: u32| norm(sub(positions[a as usize], positions[b as usize]));
    let mut merged = 0;
    for _ in 0..4 {
        let mut parent: Option<Vec<u32>> = None;
        for f in &faces {
            if f[0] == f[1] || f[1] == f[2] || f[0] == f[2] {
                continue;
            }
            let longest = dist(f[0], f[1]).max(dist(f[1], f[2])).max(dist(f[2], f[0]));
            if longest < limit {
                let p = parent.get_or_insert_with(|| (0..positions.len() as u32).collect());
                for &v in &f[1..] {
                    let (a, b) = (find(p, f[0]), find(p, v));
                    if a != b {
                        p[b as usize] = a;
                        merged += 1;
                    }
                }
            }
        }
        let Some(mut p) = parent else {
            break;
        };
        for f in faces.iter_mut() {
            for v in f.iter_mut() {
                *v = find(&mut p, *v);
            }
        }
    }
    (faces, merged)
}

/// The report of a mesh built in memory (nothing welded or dropped): its
/// counts, boundary loops, non-manifold and misoriented edges, components.
pub fn report_of(mesh: &TriMesh, topology: &Topology) -> MeshReport {
    let isolated = (0..mesh.num_vertices())
        .filter(|&v| topology.faces_of(v as u32).is_empty())
        .count();
    MeshReport {
        vertices: mesh.num_vertices(),
        faces: mesh.num_faces(),
        input_faces: mesh.num_faces(),
        welded_vertices: 0,
        degenerate_faces: 0,
        duplicate_faces: 0,
        boundary_edges: topology.boundary_edges,
        boundary_loops: boundary_loops(mesh, topology),
        non_manifold_edges: topology.non_manifold_edges,
        misoriented_edges: topology.misoriented_edges,
        components: topology.components - isolated,
        isolated_vertices: isolated,
    }
}

/// Number of connected components of the graph of boundary edges.
/// For each triangle, whether it is the first with its set of vertices (a
/// later one with the same three vertices, in any order, is a duplicate):
/// the triangles bucketed by their lowest vertex (a counting sort), each
/// bucket sorted by the other two and its index. `O(F)` plus sorts of a
/// few entries, and no hashing an upload could make collide.
fn first_of_each_vertex_set(faces: &[[u32; 3]], n: usize) -> Vec<bool> {
    let key = |f: &[u32; 3]| {
        let mut k = *f;
        k.sort_unstable();
        k
    };
    let (start, mut bucket) = bucket(
        n,
        faces.iter().enumerate().map(|(i, f)| {
            let k = key(f);
            (k[0] as usize, (k[1], k[2], i))
        }),
    );
    let mut first = vec![true; faces.len()];
    for v in 0..n {
        let row = &mut bucket[start[v]..start[v + 1]];
        row.sort_unstable();
        for w in row.windows(2) {
            if (w[0].0, w[0].1) == (w[1].0, w[1].1) {
                first[w[1].2] = false;
            }
        }
    }
    first
}

fn boundary_loops(mesh: &TriMesh, topo: &Topology) -> usize {
    let n = mesh.num_vertices();
    let mut parent: Vec<u32> = (0..n as u32).collect();
    fn find(p: &mut [u32], mut x: u32) -> u32 {
        while p[x as usize] != x {
            p[x as usize] = p[p[x as usize] as usize];
            x = p[x as usize];
        }
        x
    }
    let mut on = vec![false; n];
    // Count single-face edges only (non-manifold ones also have NONE
    // opposites): every face's edges bucketed by their lower vertex (a
    // counting sort), each bucket's upper vertices sorted, runs of one kept.
    let (start, mut upper) = bucket(
        n,
        mesh.faces().iter().flat_map(|&[a, b, c]| {
            let edge = |p: u32, q: u32| (p.min(q) as usize, p.max(q));
            [edge(a, b), edge(b, c), edge(c, a)]
        }),
    );
    for a in 0..n {
        let row = &mut upper[start[a]..start[a + 1]];
        row.sort_unstable();
        let mut k = 0;
        while k < row.len() {
            let b = row[k];
            let run = row[k..].iter().take_while(|&&x| x == b).count();
            if run == 1 {
                on[a] = true;
                on[b as usize] = true;
                let (ra, rb) = (find(&mut parent, a as u32), find(&mut parent, b));
                if ra != rb {
                    parent[ra as usize] = rb;
                }
            }
            k += run;
        }
    }
    let _ = topo;
    (0..n as u32)
        .filter(|&v| on[v as usize] && find(&mut parent, v) == v)
        .count()
}

/// Reads a mesh; `format` forces the format, else it is sniffed.
pub fn read_mesh(
    bytes: &[u8],
    format: Option<MeshFormat>,
    limits: &MeshLimits,
) -> Result<LoadedMesh, MeshIoError> {
    let format = match format {
        Some(f) => f,
        None => MeshFormat::sniff(bytes).ok_or(MeshIoError::UnknownFormat)?,
    };
    let raw = match format {
        MeshFormat::Obj => obj::read(bytes, limits)?,
        MeshFormat::Off => off::read(bytes, limits)?,
        MeshFormat::Stl => stl::read(bytes, limits)?,
        MeshFormat::Ply => ply::read(bytes, limits)?,
    };
    raw.finish(format)
}

/// Splits text into lines with their 1-based numbers, skipping blank lines
/// and `#` comments.
pub(crate) fn text_lines(bytes: &[u8]) -> impl Iterator<Item = (usize, &str)> {
    bytes
        .split(|&b| b == b'\n')
        .enumerate()
        .filter_map(|(i, l)| {
            // The comment cut on bytes ('#' is ASCII, never inside a UTF-8
            // sequence), then ASCII whitespace trimmed.
            let l = l.iter().position(|&b| b == b'#').map_or(l, |p| &l[..p]);
            let s = std::str::from_utf8(l.trim_ascii()).ok()?;
            (!s.is_empty()).then_some((i + 1, s))
        })
}

pub(crate) fn parse_f64(format: MeshFormat, line: usize, s: &str) -> Result<f64, MeshIoError> {
    s.parse::<f64>()
        .map_err(|_| MeshIoError::corrupt(format, Some(line), format!("'{s}' is not a number")))
}
