//! `/v1/datasets`: upload an array, read its metadata, download it in another
//! format, delete it.

use std::sync::Arc;

use axum::extract::{FromRequest, Multipart, Request, State};
use axum::http::{header, HeaderMap, HeaderValue, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::Json;
use serde::{Deserialize, Serialize};
use utoipa::{IntoParams, ToSchema};

use crate::datasets::{valid_id, DatasetMeta, StoreError};
use crate::http::auth::caller;
use crate::http::extract::{bytes_rejection, ApiPath, ApiQuery};
use crate::http::AppState;
use crate::io::mesh::{glb, read_mesh, write, MeshFormat, MeshLimits};
use crate::io::{self, ArrayData, DType, Decoded, Format};
use crate::problem::{io_error, ApiError};

/// Largest array offered as JSON.
pub const JSON_MAX_CELLS: usize = 65_536;

/// Format of an upload, overriding the `Content-Type`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum UploadFormat {
    /// NumPy `.npy`.
    Npy,
    /// PNG (8 or 16 bit).
    Png,
    /// JPEG.
    Jpeg,
    /// TIFF (including 32-bit float).
    Tiff,
    /// NIfTI-1 (`.nii` or `.nii.gz`).
    Nifti,
    /// Wavefront OBJ mesh.
    Obj,
    /// PLY mesh (ASCII or binary).
    Ply,
    /// OFF mesh.
    Off,
    /// STL mesh (ASCII or binary; vertices welded).
    Stl,
}

impl UploadFormat {
    /// The array format, or the mesh format.
    fn split(self) -> Result<Format, MeshFormat> {
        match self {
            UploadFormat::Npy => Ok(Format::Npy),
            UploadFormat::Png => Ok(Format::Png),
            UploadFormat::Jpeg => Ok(Format::Jpeg),
            UploadFormat::Tiff => Ok(Format::Tiff),
            UploadFormat::Nifti => Ok(Format::Nifti),
            UploadFormat::Obj => Err(MeshFormat::Obj),
            UploadFormat::Ply => Err(MeshFormat::Ply),
            UploadFormat::Off => Err(MeshFormat::Off),
            UploadFormat::Stl => Err(MeshFormat::Stl),
        }
    }
}

/// Query of an upload.
#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct UploadQuery {
    /// The file format; default: from `Content-Type`, else detected from the bytes.
    #[param(inline)]
    pub format: Option<UploadFormat>,
}

/// Representation of a download.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum OutputFormat {
    /// NumPy `.npy`, exact (`application/x-npy`).
    Npy,
    /// 32-bit float TIFF (`image/tiff`).
    Tiff,
    /// 16-bit grey PNG, values scaled to the finite range (`image/png`).
    Png16,
    /// Colour-mapped PNG for people, with iso-distance lines on distance maps (`image/png`).
    Png,
    /// JSON `{shape, dtype, data}` with `data` flat in C order (`null` for non-finite values);
    /// only for arrays of at most 65536 cells. Meshes: `{vertices, faces, properties}`.
    Json,
    /// Meshes: binary PLY with the per-vertex properties (`model/ply`); the default for meshes.
    Ply,
    /// Meshes: Wavefront OBJ, geometry only (`model/obj`).
    Obj,
    /// Meshes: glTF 2.0 binary for web viewers (`model/gltf-binary`): positions, normals,
    /// `COLOR_0` from the first vertex property and each property as `_DISTANCE`, `_LABEL`,
    /// `_VALUE`.
    Glb,
}

/// Query of a download. The parameters after `format` shape the picture of
/// `format=png` (they are ignored by the other formats); each is parsed
/// here, so that a bad value is a 400 naming it.
#[derive(Debug, Default, Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct DataQuery {
    /// The representation; default: from `Accept`, else `npy`.
    #[param(inline)]
    pub format: Option<OutputFormat>,
    /// png: the colour map of continuous values: `viridis` (default), `turbo`, `grey`,
    /// `magma` or `inferno`.
    #[param(value_type = Option<String>, example = "magma")]
    pub colormap: Option<String>,
    /// png: the value at the bottom of the colour map; default the finite minimum.
    #[param(value_type = Option<f64>)]
    pub vmin: Option<String>,
    /// png: the value at the top of the colour map; default the finite maximum.
    #[param(value_type = Option<f64>)]
    pub vmax: Option<String>,
    /// png: this many iso-value lines evenly spaced inside the range (0: none); default 10
    /// for float arrays, none otherwise.
    #[param(value_type = Option<u32>, minimum = 0, maximum = 1000)]
    pub levels: Option<String>,
    /// png: one iso-value line every this many value units from `vmin` (instead of `levels`).
    #[param(value_type = Option<f64>)]
    pub level_step: Option<String>,
    /// png: a colour bar with the range and the iso-line step beside continuous maps;
    /// default `true`.
    #[param(value_type = Option<bool>)]
    pub colorbar: Option<String>,
    /// png: `auto` (default: labels for integer arrays, tensor glyphs for float
    /// `(rows, cols, 3)` arrays, a colour map otherwise), `continuous`, `categorical` or
    /// `tensor`.
    #[param(value_type = Option<String>, example = "categorical")]
    pub style: Option<String>,
    /// png, 3D arrays: the slice shown, `axis:index` (e.g. `2:17`); default the middle
    /// slice along axis 0, named in the picture's caption.
    #[param(value_type = Option<String>, example = "0:32")]
    pub slice: Option<String>,
    /// png, 3D arrays: a grid of `count` evenly spaced slices along axis 0, or `axis:count`
    /// (at most 64), each with its index.
    #[param(value_type = Option<String>, example = "0:16")]
    pub montage: Option<String>,
    /// png: the id of an image dataset of the same shape to draw the map over (in grey).
    #[param(value_type = Option<String>)]
    pub over: Option<String>,
    /// png: the opacity of the map over `over`, in [0, 1]; default 0.5.
    #[param(value_type = Option<f64>)]
    pub alpha: Option<String>,
    /// png: points to mark (e.g. the seeds of a segmentation), index coordinates, axis 0
    /// first, `;` between points: `10,5;50,55` (3D: `k,i,j`, drawn on the slice they lie on).
    #[param(value_type = Option<String>, example = "10,5;50,55")]
    pub markers: Option<String>,
    /// npy, json: the element type sent for a float array, `f32` or `f64`; default the
    /// stored one. `f32` halves a distance map's download (values rounded to the nearest
    /// single-precision float, a relative error at most 6e-8; beyond ±3.4e38, ±inf), for
    /// viewers that draw it.
    #[param(value_type = Option<String>, example = "f32")]
    pub dtype: Option<String>,
}

/// The picture parameters of a [`DataQuery`], parsed.
#[derive(Debug, Clone, Default)]
pub struct Picture {
    /// Colours, range, iso lines, colour bar, view; `range` may be half given.
    pub options: io::RenderOptions,
    /// `vmin`, `vmax` as given (the missing end comes from the data).
    pub vmin: Option<f64>,
    /// See `vmin`.
    pub vmax: Option<f64>,
    /// Whether `levels` or `level_step` was given (else the default applies).
    pub levels_given: bool,
    /// The dataset to draw under the map.
    pub over: Option<String>,
    /// Opacity of the map over `over`.
    pub alpha: f64,
    /// Points to mark.
    pub markers: Vec<Vec<f64>>,
}

fn parse_f64(name: &str, v: &str) -> Result<f64, ApiError> {
    v.trim()
        .parse::<f64>()
        .ok()
        .filter(|x| x.is_finite())
        .ok_or_else(|| ApiError::bad_request(name, format!("{name}: '{v}' is not a finite number")))
}

fn parse_pair(name: &str, v: &str, what: &str) -> Result<(usize, usize), ApiError> {
    let bad = || ApiError::bad_request(name, format!("{name}: '{v}' is not {what}"));
    let (a, b) = v.split_once(':').ok_or_else(bad)?;
    Ok((
        a.trim().parse().map_err(|_| bad())?,
        b.trim().parse().map_err(|_| bad())?,
    ))
}

impl DataQuery {
    /// The element type a download in `format` converts to (`None`: as
    /// stored): `dtype`, for npy and json only, checked against the array's
    /// `stored` type. Datasets and job results both ask it.
    pub fn conversion(
        &self,
        format: OutputFormat,
        stored: DType,
    ) -> Result<Option<DType>, ApiError> {
        match format {
            OutputFormat::Npy | OutputFormat::Json => self.download_dtype(stored),
            _ if self.dtype.is_some() => Err(ApiError::bad_request(
                "dtype",
                "dtype applies to the npy and json downloads only; leave it out for pictures \
                 and TIFF (which is always f32)",
            )),
            _ => Ok(None),
        }
    }

    /// The float element type asked for by `dtype` (`None`: as stored),
    /// checked against the array's `stored` type.
    fn download_dtype(&self, stored: DType) -> Result<Option<DType>, ApiError> {
        let Some(v) = &self.dtype else {
            return Ok(None);
        };
        let asked = match v.trim().to_ascii_lowercase().as_str() {
            "f32" | "float32" => DType::F32,
            "f64" | "float64" => DType::F64,
            _ => {
                return Err(ApiError::bad_request(
                    "dtype",
                    format!("dtype: '{v}' is not offered; use f32 or f64 (float arrays only)"),
                ))
            }
        };
        if !matches!(stored, DType::F32 | DType::F64) {
            let name = format!("{stored:?}").to_ascii_lowercase();
            return Err(ApiError::bad_request(
                "dtype",
                format!("dtype: this array holds {name}, which is sent as stored; leave dtype out"),
            ));
        }
        Ok((asked != stored).then_some(asked))
    }

    /// The picture parameters, each checked on its own (against the array
    /// in [`check_picture`]).
    pub fn picture(&self) -> Result<Picture, ApiError> {
        let mut p = Picture {
            alpha: 0.5,
            ..Picture::default()
        };
        p.options.colorbar = true;
        if let Some(c) = &self.colormap {
            p.options.colormap = io::Colormap::ALL
                .into_iter()
                .find(|m| m.name() == c.trim().to_ascii_lowercase())
                .ok_or_else(|| {
                    ApiError::bad_request(
                        "colormap",
                        format!("colormap: '{c}' is none of viridis, turbo, grey, magma, inferno"),
                    )
                })?;
        }
        p.vmin = self
            .vmin
            .as_deref()
            .map(|v| parse_f64("vmin", v))
            .transpose()?;
        p.vmax = self
            .vmax
            .as_deref()
            .map(|v| parse_f64("vmax", v))
            .transpose()?;
        if let (Some(lo), Some(hi)) = (p.vmin, p.vmax) {
            if lo >= hi {
                return Err(ApiError::bad_request(
                    "vmin",
                    format!("vmin {lo} must be below vmax {hi}"),
                ));
            }
        }
        match (&self.levels, &self.level_step) {
            (Some(_), Some(_)) => {
                return Err(ApiError::bad_request(
                    "level_step",
                    "give levels (a count) or level_step (a spacing), not both",
                ))
            }
            (Some(n), None) => {
                let n: usize = n
                    .trim()
                    .parse()
                    .ok()
                    .filter(|&n| n <= 1000)
                    .ok_or_else(|| {
                        ApiError::bad_request(
                            "levels",
                            format!("levels: '{n}' is not a count 0..=1000"),
                        )
                    })?;
                p.levels_given = true;
                p.options.iso_lines = (n > 0).then_some(io::IsoLines::Count(n));
            }
            (None, Some(s)) => {
                let s = parse_f64("level_step", s)?;
                if s <= 0.0 {
                    return Err(ApiError::bad_request(
                        "level_step",
                        "level_step must be > 0",
                    ));
                }
                p.levels_given = true;
                p.options.iso_lines = Some(io::IsoLines::Spacing(s));
            }
            (None, None) => {}
        }
        if let Some(c) = &self.colorbar {
            p.options.colorbar = match c.trim() {
                "true" | "1" | "yes" => true,
                "false" | "0" | "no" => false,
                _ => {
                    return Err(ApiError::bad_request(
                        "colorbar",
                        format!("colorbar: '{c}' is not true or false"),
                    ))
                }
            };
        }
        if let Some(st) = &self.style {
            p.options.style = match st.trim() {
                "auto" => io::RenderStyle::Auto,
                "continuous" => io::RenderStyle::Continuous,
                "categorical" => io::RenderStyle::Categorical,
                "tensor" => io::RenderStyle::Tensor,
                _ => {
                    return Err(ApiError::bad_request(
                        "style",
                        format!("style: '{st}' is none of auto, continuous, categorical, tensor"),
                    ))
                }
            };
        }
        match (&self.slice, &self.montage) {
            (Some(_), Some(_)) => {
                return Err(ApiError::bad_request(
                    "montage",
                    "give slice (one plane) or montage (a grid of planes), not both",
                ))
            }
            (Some(v), None) => {
                let (axis, index) = parse_pair("slice", v, "axis:index")?;
                p.options.view = io::View::Slice { axis, index };
            }
            (None, Some(v)) => {
                let (axis, count) = if v.contains(':') {
                    parse_pair("montage", v, "count or axis:count")?
                } else {
                    let n = v.trim().parse().map_err(|_| {
                        ApiError::bad_request(
                            "montage",
                            format!("montage: '{v}' is not count or axis:count"),
                        )
                    })?;
                    (0, n)
                };
                p.options.view = io::View::Montage { axis, count };
            }
            (None, None) => {}
        }
        if let Some(id) = &self.over {
            check_id(id).map_err(|e| e.with_field("over"))?;
            p.over = Some(id.clone());
        }
        if let Some(a) = &self.alpha {
            p.alpha = parse_f64("alpha", a)?;
        }
        if let Some(m) = &self.markers {
            for point in m.split(';').filter(|s| !s.trim().is_empty()) {
                let coords: Result<Vec<f64>, ApiError> =
                    point.split(',').map(|c| parse_f64("markers", c)).collect();
                p.markers.push(coords?);
            }
        }
        Ok(p)
    }
}

/// The picture of `array` (over `under`, when `over` was given); a
/// parameter that does not fit the array is a 400 naming it.
pub fn render_picture(
    array: &ArrayData,
    picture: &Picture,
    under: Option<&ArrayData>,
) -> Result<Vec<u8>, ApiError> {
    let mut options = picture.options;
    // Float fields (distance maps) get iso-value lines by default.
    if !picture.levels_given {
        if let Some(lines) = io::default_iso_lines(array) {
            options.iso_lines = Some(lines);
        }
    }
    if picture.vmin.is_some() || picture.vmax.is_some() {
        let (lo, hi) = finite_min_max(array);
        let (lo, hi) = (picture.vmin.unwrap_or(lo), picture.vmax.unwrap_or(hi));
        if lo >= hi {
            let field = if picture.vmin.is_some() {
                "vmin"
            } else {
                "vmax"
            };
            return Err(ApiError::bad_request(
                field,
                format!("the range ({lo}, {hi}) is empty: vmin must be below vmax"),
            ));
        }
        options.range = Some((lo, hi));
    }
    let overlay = io::Overlay {
        image: under,
        alpha: picture.alpha,
        markers: &picture.markers,
    };
    io::render::check_options(array, &options, &overlay).map_err(|e| {
        let field = match e.option {
            "view" if matches!(options.view, io::View::Montage { .. }) => "montage",
            "view" => "slice",
            "overlay" => "over",
            "range" => "vmin",
            "iso_lines" => "levels",
            other => other,
        };
        ApiError::bad_request(field, format!("{field}: {}", e.reason))
    })?;
    io::render_png_over(array, &options, &overlay)
        .map_err(|e| ApiError::not_acceptable(format!("cannot encode this array: {e}")))
}

fn finite_min_max(array: &ArrayData) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for i in 0..array.len() {
        if let Some(v) = array.get_f64(i).filter(|v| v.is_finite()) {
            lo = lo.min(v);
            hi = hi.max(v);
        }
    }
    if lo <= hi {
        (lo, hi)
    } else {
        (0.0, 1.0)
    }
}

/// Which per-vertex values of a mesh result `?format=npy` downloads.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum MeshProperty {
    /// The geodesic distance per vertex (f64; `mesh.distance`, `mesh.voronoi`).
    Distance,
    /// The label per vertex (i32; `mesh.voronoi`, `mesh.distance` with several sources).
    Label,
    /// The value per vertex (f64; `grid.mesh`).
    Value,
}

impl MeshProperty {
    fn name(self) -> &'static str {
        match self {
            MeshProperty::Distance => "distance",
            MeshProperty::Label => "label",
            MeshProperty::Value => "value",
        }
    }
}

/// Query of a mesh download.
#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct MeshValuesQuery {
    /// Mesh datasets with `format=npy`: which per-vertex values; default the
    /// first the mesh carries of `distance`, `value`, `label`.
    #[param(inline)]
    pub property: Option<MeshProperty>,
}

/// A small array as JSON.
#[derive(Debug, Serialize, ToSchema)]
pub struct ArrayJson {
    /// Shape, axis 0 first.
    pub shape: Vec<usize>,
    /// Element type.
    pub dtype: io::DType,
    /// Values in C order (last axis fastest); `null` stands for a non-finite value.
    pub data: Vec<Option<f64>>,
}

/// The id of a dataset, in the path.
#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Path)]
pub struct DatasetPath {
    /// Dataset id (`ds_` followed by 32 hex digits).
    pub id: String,
}

/// The format named by a `Content-Type`: `Ok(None)` means "detect".
pub fn format_from_content_type(headers: &HeaderMap) -> Result<Option<Format>, ApiError> {
    let Some(ct) = headers.get(header::CONTENT_TYPE) else {
        return Ok(None);
    };
    Format::from_media_type(ct.to_str().unwrap_or("?"))
        .map_err(|e| ApiError::unsupported_media_type(e.to_string()))
}

/// Decodes uploaded bytes on the solver pool (admitted like a solve: 503 +
/// `Retry-After` when the pool is full, 504 past the deadline) and checks
/// that the array is 2D or 3D. Decoding a large or compressed file takes
/// the memory of its pixels: the size its header declares is read first
/// ([`io::declared_size`], off the async threads), and the decode is
/// admitted by that estimate against the pool's memory budget (503 +
/// `Retry-After` while other solves hold it, 413 beyond the whole budget),
/// so a small compressed file cannot inflate beyond it. `field` names the
/// input in errors.
pub async fn decode_upload(
    state: &AppState,
    bytes: bytes::Bytes,
    hint: Option<Format>,
    field: &'static str,
) -> Result<Decoded, ApiError> {
    if let Some(actual) = sniff_mismatch(&bytes, hint) {
        return Err(ApiError::unsupported_media_type(format!(
            "{field}: this is {}, not {}: send Content-Type {} or omit it (the format is then \
             detected from the bytes)",
            format_name(actual),
            hint.map_or("", format_name),
            actual.media_type()
        )));
    }
    let limits = state.io_limits;
    let probe = bytes.clone();
    let declared = tokio::task::spawn_blocking(move || io::declared_size(&probe, hint, &limits))
        .await
        .map_err(ApiError::internal)?
        .map_err(|e| io_error(e, field))?;
    // The decoder's own buffer (a NIfTI's inflated payload, an image's raw
    // pixels), the decoded array, its stored NPY copy, and the body itself:
    // measured at 50 MB for a gzipped 256^3 u8 NIfTI (tests/hostile).
    let estimate = declared.map_or(0, |(_, b)| 3 * b as u64) + bytes.len() as u64;
    let (decoded, _) = state
        .pool
        .run_sized("upload", state.solve_timeout, estimate, move |_| {
            io::decode(&bytes, hint, &limits)
        })
        .await?;
    let decoded = decoded.map_err(|e| io_error(e, field))?;
    let ndim = decoded.array.shape().len();
    if !(2..=3).contains(&ndim) {
        return Err(ApiError::invalid_field(
            field,
            format!(
                "the array has {ndim} axes (shape {:?}); only 2D and 3D arrays are accepted",
                decoded.array.shape()
            ),
        ));
    }
    Ok(decoded)
}

/// The array format the bytes announce when it contradicts `hint` (the
/// format a `Content-Type` or `?format=` named): a JPEG sent as
/// `image/png` is refused with the way out instead of failing in the PNG
/// decoder. Bytes with no known magic (or no hint) are left to the decoder.
pub fn sniff_mismatch(bytes: &[u8], hint: Option<Format>) -> Option<Format> {
    let said = hint?;
    let actual = Format::sniff(bytes)?;
    (actual != said).then_some(actual)
}

/// A format as people name it, with its article (`a JPEG`).
fn format_name(f: Format) -> &'static str {
    match f {
        Format::Npy => "an NPY file",
        Format::Png => "a PNG",
        Format::Jpeg => "a JPEG",
        Format::Tiff => "a TIFF",
        Format::Nifti => "a NIfTI file",
    }
}

/// The `?format=` value of an array format.
fn actual_format_value(f: Format) -> &'static str {
    match f {
        Format::Npy => "npy",
        Format::Png => "png",
        Format::Jpeg => "jpeg",
        Format::Tiff => "tiff",
        Format::Nifti => "nifti",
    }
}

/// The body of `POST /v1/datasets`: the raw file, or a `multipart/form-data`
/// form with a `file` part (its own `Content-Type` names the format, like the
/// raw body's) and an optional `format` part (text, the values of `?format=`).
#[derive(Debug)]
pub struct UploadBody {
    /// The file's bytes.
    pub bytes: bytes::Bytes,
    /// The headers that describe the file: the request's, or the `file`
    /// part's `Content-Type`.
    pub headers: HeaderMap,
    /// The form's `format` part.
    pub format: Option<UploadFormat>,
    /// Where the file was: `body` or `file`.
    pub field: &'static str,
}

impl<S: Send + Sync> FromRequest<S> for UploadBody {
    type Rejection = ApiError;

    async fn from_request(req: Request, state: &S) -> Result<Self, Self::Rejection> {
        let is_form = crate::http::extract::is_multipart(req.headers());
        if !is_form {
            let headers = req.headers().clone();
            let bytes = bytes::Bytes::from_request(req, state)
                .await
                .map_err(bytes_rejection)?;
            return Ok(Self {
                bytes,
                headers,
                format: None,
                field: "body",
            });
        }
        let mut form = Multipart::from_request(req, state)
            .await
            .map_err(|e| ApiError::bad_request("body", format!("body: {}", e.body_text())))?;
        let mut file = None;
        let mut format = None;
        while let Some(part) = form
            .next_field()
            .await
            .map_err(super::grid::multipart_error)?
        {
            match part.name().unwrap_or("") {
                "file" => {
                    let mut headers = HeaderMap::new();
                    if let Some(ct) = part.content_type().and_then(|c| c.parse().ok()) {
                        headers.insert(header::CONTENT_TYPE, ct);
                    }
                    let bytes = part.bytes().await.map_err(super::grid::multipart_error)?;
                    file = Some((bytes, headers));
                }
                "format" => {
                    let text = part.text().await.map_err(super::grid::multipart_error)?;
                    let value = serde_json::Value::String(text.trim().to_ascii_lowercase());
                    format = Some(serde_json::from_value::<UploadFormat>(value).map_err(|_| {
                        ApiError::invalid_field(
                            "format",
                            format!(
                                "'{}' is not one of npy, png, jpeg, tiff, nifti, obj, ply, off, stl",
                                text.trim()
                            ),
                        )
                    })?);
                }
                other => return Err(ApiError::invalid_field(
                    other.to_string(),
                    "unknown part; an upload form has a `file` part and an optional `format` part",
                )),
            }
        }
        let (bytes, headers) = file.ok_or_else(|| {
            ApiError::invalid_field("file", "the form has no `file` part (the file to store)")
        })?;
        Ok(Self {
            bytes,
            headers,
            format,
            field: "file",
        })
    }
}

/// The form of an upload (`multipart/form-data`).
#[derive(Debug, ToSchema)]
pub struct UploadForm {
    /// The file; its part's `Content-Type` names the format (else it is detected).
    #[schema(value_type = String, format = Binary)]
    pub file: Vec<u8>,
    /// The format, as `?format=` (overrides the part's `Content-Type`).
    pub format: Option<UploadFormat>,
}

/// Query of the listing.
#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct ListQuery {
    /// Most datasets on the page, 1 to 1000; default 100.
    pub limit: Option<usize>,
    /// The `next_cursor` of the previous page; omitted for the first page.
    pub cursor: Option<String>,
}

/// One page of datasets.
#[derive(Debug, Serialize, ToSchema)]
pub struct DatasetList {
    /// The datasets, newest first (id descending: ids are time-ordered UUIDv7).
    pub items: Vec<DatasetMeta>,
    /// Pass as `?cursor=` for the next page; `null` on the last page.
    pub next_cursor: Option<String>,
}

/// Most datasets on one page of the listing.
pub const LIST_MAX_LIMIT: usize = 1000;

/// Lists the datasets, a page at a time.
#[utoipa::path(
    get,
    path = "/v1/datasets",
    tag = "datasets",
    summary = "List datasets",
    description = "The live datasets (uploads and results, arrays and meshes), newest first: by id, \
descending, ids being time-ordered UUIDv7. Each item is the dataset's metadata (id, kind `image`, \
`volume` or `mesh`, shape (a mesh: `[vertices, 3]`), dtype, `byte_size`, `created_at`). A page holds \
`limit` items (default 100, at most 1000); `next_cursor`, also sent as a `Link: <...>; rel=\"next\"` \
header, is the last id of the page, and the next page lists the ids below it: the walk is stable \
while datasets are added (newer ones sort before the cursor) or removed.",
    params(ListQuery),
    responses(
        (status = 200, description = "One page.", body = DatasetList),
        (status = 400, response = crate::http::openapi::BadRequest),
        (status = 422, response = crate::http::openapi::Unprocessable),
        (status = 500, response = crate::http::openapi::InternalError),
    )
)]
pub async fn list(
    State(state): State<AppState>,
    ApiQuery(query): ApiQuery<ListQuery>,
) -> Result<Response, ApiError> {
    let limit = query.limit.unwrap_or(100);
    if !(1..=LIST_MAX_LIMIT).contains(&limit) {
        return Err(ApiError::invalid_field(
            "limit",
            format!("{limit} is not between 1 and {LIST_MAX_LIMIT}"),
        ));
    }
    if let Some(c) = &query.cursor {
        if !valid_id(c) {
            return Err(ApiError::invalid_field(
                "cursor",
                "not a cursor: pass the `next_cursor` of the previous page",
            ));
        }
    }
    let page = state
        .store
        .list(caller().tenant(), limit, query.cursor.as_deref());
    let link = page
        .next
        .as_ref()
        .map(|c| format!("</v1/datasets?limit={limit}&cursor={c}>; rel=\"next\""));
    let mut res = Json(DatasetList {
        items: page.items,
        next_cursor: page.next,
    })
    .into_response();
    if let Some(v) = link.and_then(|l| HeaderValue::from_str(&l).ok()) {
        res.headers_mut().insert(header::LINK, v);
    }
    Ok(res)
}

fn check_id(id: &str) -> Result<(), ApiError> {
    if valid_id(id) {
        Ok(())
    } else {
        Err(StoreError::NotFound(id.into()).into())
    }
}

/// Uploads an array and stores it as a dataset.
#[utoipa::path(
    post,
    path = "/v1/datasets",
    tag = "datasets",
    summary = "Upload an array",
    description = "Stores the raw body as a dataset: a 2D image or a 3D volume. The format comes from `?format=`, \
else from `Content-Type`, else it is detected from the first bytes (`application/octet-stream`, `application/gzip`). \
Colour images are converted to grey. NIfTI voxel sizes become the dataset's `spacing` (axis 0 first). \
The array is stored once as canonical NPY; sizes are checked before anything is allocated. \
A browser form works too: `multipart/form-data` with a `file` part (its `Content-Type` names the format) \
and an optional `format` part (a value of `?format=`). \
The bytes' magic is checked against the format named: a JPEG sent as `image/png` is a 415 that says so \
(`this is a JPEG, not a PNG: send Content-Type image/jpeg or omit it`), and against `?format=` a 422; \
bytes with no recognised magic are left to the decoder named.",
    params(UploadQuery),
    request_body(
        description = "The file: NPY, PNG, JPEG, TIFF or NIfTI (`.nii` or `.nii.gz`), or a mesh \
(OBJ, PLY, OFF, STL); raw, or as the `file` part of a form.",
        content(
            (UploadForm = "multipart/form-data"),
            (crate::http::openapi::FileBytes = "application/x-npy"),
            (crate::http::openapi::FileBytes = "image/png"),
            (crate::http::openapi::FileBytes = "image/jpeg"),
            (crate::http::openapi::FileBytes = "image/tiff"),
            (crate::http::openapi::FileBytes = "application/x-nifti"),
            (crate::http::openapi::FileBytes = "application/gzip"),
            (crate::http::openapi::FileBytes = "application/octet-stream"),
        )
    ),
    responses(
        (status = 201, description = "Stored; `Location` names the new dataset.", body = DatasetMeta,
            headers(("Location" = String, description = "URL of the new dataset."))),
        (status = 400, response = crate::http::openapi::BadRequest),
        (status = 413, response = crate::http::openapi::PayloadTooLarge),
        (status = 415, response = crate::http::openapi::UnsupportedMediaType),
        (status = 422, response = crate::http::openapi::Unprocessable),
        (status = 500, response = crate::http::openapi::InternalError),
        (status = 503, response = crate::http::openapi::Busy),
        (status = 504, response = crate::http::openapi::DeadlineExceeded),
        (status = 507, response = crate::http::openapi::InsufficientStorage),
    )
)]
pub async fn upload(
    State(state): State<AppState>,
    ApiQuery(query): ApiQuery<UploadQuery>,
    upload: UploadBody,
) -> Result<Response, ApiError> {
    let UploadBody {
        bytes: body,
        headers,
        format: form_format,
        field,
    } = upload;
    if body.is_empty() {
        return Err(ApiError::bad_request(
            field,
            format!("{field}: the file is empty"),
        ));
    }
    let format = match (query.format, form_format) {
        (Some(q), Some(f)) if q != f => {
            return Err(ApiError::invalid_field(
                "format",
                "`?format=` and the form's `format` part name different formats; give one",
            ))
        }
        (q, f) => q.or(f),
    };
    if let Some(mesh_format) = mesh_upload_format(format, &headers, &body) {
        return upload_mesh(state, body, mesh_format).await;
    }
    let hint = match format.map(UploadFormat::split) {
        Some(Ok(f)) => {
            if let Some(actual) = sniff_mismatch(&body, Some(f)) {
                return Err(ApiError::invalid_field(
                    "format",
                    format!(
                        "the file is {}, not {}: give format={} or omit it to let the bytes decide",
                        format_name(actual),
                        format_name(f),
                        actual_format_value(actual)
                    ),
                ));
            }
            Some(f)
        }
        Some(Err(_)) => None,
        None => format_from_content_type(&headers)?,
    };
    let decoded = decode_upload(&state, body, hint, field).await?;
    let meta = state
        .store
        .create(
            Arc::new(decoded.array),
            decoded.spacing,
            decoded.format.into(),
            caller().owner,
        )
        .await?;
    let location = format!("/v1/datasets/{}", meta.id);
    let mut res = (StatusCode::CREATED, Json(meta)).into_response();
    if let Ok(v) = HeaderValue::from_str(&location) {
        res.headers_mut().insert(header::LOCATION, v);
    }
    Ok(res)
}

/// Metadata of a dataset.
#[utoipa::path(
    get,
    path = "/v1/datasets/{id}",
    tag = "datasets",
    summary = "Dataset metadata",
    description = "Shape (axis 0 first), dtype, spacing, size, creation and expiry times of a dataset.",
    params(DatasetPath),
    responses(
        (status = 200, description = "The metadata.", body = DatasetMeta),
        (status = 404, response = crate::http::openapi::NotFound),
        (status = 500, response = crate::http::openapi::InternalError),
    )
)]
pub async fn get_meta(
    State(state): State<AppState>,
    ApiPath(path): ApiPath<DatasetPath>,
) -> Result<Json<DatasetMeta>, ApiError> {
    check_id(&path.id)?;
    Ok(Json(state.store.meta_of(&path.id, caller().tenant())?))
}

/// Deletes a dataset.
#[utoipa::path(
    delete,
    path = "/v1/datasets/{id}",
    tag = "datasets",
    summary = "Delete a dataset",
    description = "Removes the dataset and its files; its storage counts against the quota no more.",
    params(DatasetPath),
    responses(
        (status = 204, description = "Deleted."),
        (status = 404, response = crate::http::openapi::NotFound),
        (status = 500, response = crate::http::openapi::InternalError),
    )
)]
pub async fn delete(
    State(state): State<AppState>,
    ApiPath(path): ApiPath<DatasetPath>,
) -> Result<StatusCode, ApiError> {
    check_id(&path.id)?;
    state.store.meta_of(&path.id, caller().tenant())?;
    state.store.delete(&path.id).await?;
    Ok(StatusCode::NO_CONTENT)
}

/// The representation asked for by `?format=` or `Accept` (default NPY).
pub fn negotiate(query: Option<OutputFormat>, headers: &HeaderMap) -> OutputFormat {
    if let Some(f) = query {
        return f;
    }
    let accept = headers
        .get(header::ACCEPT)
        .and_then(|v| v.to_str().ok())
        .unwrap_or("")
        .to_ascii_lowercase();
    for item in accept.split(',') {
        let essence = item.split(';').next().unwrap_or("").trim();
        match essence {
            "application/x-npy" | "application/npy" | "application/octet-stream" => {
                return OutputFormat::Npy
            }
            "image/tiff" => return OutputFormat::Tiff,
            "image/png" => return OutputFormat::Png,
            "application/json" => return OutputFormat::Json,
            "model/ply" => return OutputFormat::Ply,
            "model/obj" => return OutputFormat::Obj,
            "model/gltf-binary" => return OutputFormat::Glb,
            _ => {}
        }
    }
    OutputFormat::Npy
}

fn to_json(array: &ArrayData) -> Result<Vec<u8>, ApiError> {
    if array.len() > JSON_MAX_CELLS {
        return Err(ApiError::not_acceptable(format!(
            "json is only offered for arrays of at most {JSON_MAX_CELLS} cells; this one has {}; use npy or tiff",
            array.len()
        )));
    }
    let data = (0..array.len())
        .map(|i| array.get_f64(i).filter(|v| v.is_finite()))
        .collect();
    let body = ArrayJson {
        shape: array.shape().to_vec(),
        dtype: array.dtype(),
        data,
    };
    serde_json::to_vec(&body).map_err(ApiError::internal)
}

/// Encodes an array in a download format; returns the bytes and media type.
pub fn encode(
    array: &ArrayData,
    format: OutputFormat,
) -> Result<(Vec<u8>, &'static str), ApiError> {
    let encoded =
        match format {
            OutputFormat::Npy => io::encode_npy(array).map(|b| (b, "application/x-npy")),
            OutputFormat::Json => return to_json(array).map(|b| (b, "application/json")),
            OutputFormat::Tiff => io::encode_tiff_f32(array).map(|b| (b, "image/tiff")),
            OutputFormat::Png16 => io::encode_png16(array, None).map(|b| (b, "image/png")),
            OutputFormat::Png => {
                // The default picture: iso lines on float fields, a colour bar.
                let picture = DataQuery::default().picture()?;
                return render_picture(array, &picture, None).map(|b| (b, "image/png"));
            }
            OutputFormat::Ply | OutputFormat::Obj | OutputFormat::Glb => return Err(ApiError::not_acceptable(
                "ply, obj and glb are offered for mesh datasets only; use npy, tiff, png16, png or json",
            )),
        };
    encoded.map_err(|e| ApiError::not_acceptable(format!("cannot encode this array: {e}")))
}

/// Downloads a dataset in the format asked for.
#[utoipa::path(
    get,
    path = "/v1/datasets/{id}/data",
    tag = "datasets",
    summary = "Download a dataset",
    description = "The array in the representation named by `?format=`, else by `Accept`, else NPY: \
`npy` (exact, any dtype), `tiff` (32-bit float), `png16` (16-bit grey scaled to the finite range), \
`png` (colour-mapped for people: distance maps get iso-distance lines and a colour bar with \
the range and the line step; labels a qualitative palette that keeps neighbours apart; 3D \
arrays a named slice or a montage; 2D tensor fields ellipse glyphs; see the picture \
parameters) or `json` \
(`{shape, dtype, data}` with data flat in C order, only up to 65536 cells; else 406). A mesh \
dataset is offered as `ply` (binary PLY with its vertex properties, the default), `obj`, `json` \
or `glb` (glTF binary, what web viewers load, with the vertex properties as colours and \
attributes); a mesh result's per-vertex values alone as `npy` (1D, one value per vertex, \
`?property=` picks `distance`, `label` or `value`). OBJ has no place for per-vertex values: a mesh \
that carries them is refused as `obj` (406, naming `ply`, `npy`, `glb` and `json`) rather than \
downloaded without them.",
    params(DatasetPath, DataQuery, MeshValuesQuery),
    responses(
        (status = 200, description = "The array (or the mesh).",
            content(
                (crate::http::openapi::FileBytes = "application/x-npy"),
                (crate::http::openapi::FileBytes = "image/tiff"),
                (crate::http::openapi::FileBytes = "image/png"),
                (crate::http::openapi::FileBytes = "model/ply"),
                (crate::http::openapi::FileBytes = "model/obj"),
                (crate::http::openapi::FileBytes = "model/gltf-binary"),
                (ArrayJson = "application/json", example = json!({"shape": [2, 2], "dtype": "f64", "data": [0.0, 1.0, 1.0, 1.5]})),
            )
        ),
        (status = 400, response = crate::http::openapi::BadRequest),
        (status = 404, response = crate::http::openapi::NotFound),
        (status = 406, response = crate::http::openapi::NotAcceptable),
        (status = 500, response = crate::http::openapi::InternalError),
    )
)]
pub async fn get_data(
    State(state): State<AppState>,
    ApiPath(path): ApiPath<DatasetPath>,
    ApiQuery(query): ApiQuery<DataQuery>,
    ApiQuery(mesh_query): ApiQuery<MeshValuesQuery>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    check_id(&path.id)?;
    let meta = state.store.meta_of(&path.id, caller().tenant())?;
    if meta.kind == crate::datasets::DatasetKind::Mesh {
        if query.dtype.is_some() {
            return Err(ApiError::bad_request(
                "dtype",
                "dtype applies to array datasets only; a mesh is sent as stored: leave it out",
            ));
        }
        return mesh_data(
            &state,
            &path.id,
            query.format,
            mesh_query.property,
            &headers,
        )
        .await;
    }
    let format = negotiate(query.format, &headers);
    let convert = query.conversion(format, meta.dtype)?;
    let store = state.store.clone();
    let id = path.id.clone();
    let (bytes, media) = if let Some(dtype) = convert {
        let input = state.store.load(&path.id).await?;
        tokio::task::spawn_blocking(move || encode(&cast_float(&input.array, dtype), format))
            .await
            .map_err(ApiError::internal)??
    } else if format == OutputFormat::Npy {
        let bytes = crate::datasets::blocking(move || store.read_npy_blocking(&id)).await?;
        (bytes, "application/x-npy")
    } else if format == OutputFormat::Png {
        let picture = query.picture()?;
        let input = state.store.load(&path.id).await?;
        let under = match &picture.over {
            Some(over) => {
                let over_field = |e: StoreError| ApiError::from(e).with_field("over");
                state
                    .store
                    .meta_of(over, caller().tenant())
                    .map_err(over_field)?;
                Some(state.store.load(over).await.map_err(over_field)?)
            }
            None => None,
        };
        let bytes = tokio::task::spawn_blocking(move || {
            render_picture(&input.array, &picture, under.as_ref().map(|u| &*u.array))
        })
        .await
        .map_err(ApiError::internal)??;
        (bytes, "image/png")
    } else {
        let input = state.store.load(&path.id).await?;
        tokio::task::spawn_blocking(move || encode(&input.array, format))
            .await
            .map_err(ApiError::internal)??
    };
    Ok(([(header::CONTENT_TYPE, media)], bytes).into_response())
}

/// A float array in the float type `dtype` (f64 → f32 rounds to nearest).
pub fn cast_float(array: &ArrayData, dtype: DType) -> ArrayData {
    match (array, dtype) {
        (ArrayData::F64(a), DType::F32) => ArrayData::F32(a.mapv(|v| v as f32)),
        (ArrayData::F32(a), DType::F64) => ArrayData::F64(a.mapv(f64::from)),
        _ => array.clone(),
    }
}

/// The mesh format of an upload: `?format=` naming a mesh format, a mesh
/// `Content-Type` (`model/obj`, `model/ply`, `model/stl`, `model/off`), or,
/// without either, bytes that no array codec recognises but a mesh reader does.
fn mesh_upload_format(
    query: Option<UploadFormat>,
    headers: &HeaderMap,
    body: &[u8],
) -> Option<MeshFormat> {
    if let Some(f) = query {
        return f.split().err();
    }
    let ct = headers
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .unwrap_or("");
    if let Some(f) = MeshFormat::from_media_type(ct) {
        return Some(f);
    }
    let essence = ct
        .split(';')
        .next()
        .unwrap_or("")
        .trim()
        .to_ascii_lowercase();
    let detect =
        essence.is_empty() || essence == "application/octet-stream" || essence == "text/plain";
    if detect && Format::sniff(body).is_none() {
        return MeshFormat::sniff(body);
    }
    None
}

/// Reads, repairs and stores an uploaded mesh.
async fn upload_mesh(
    state: AppState,
    body: bytes::Bytes,
    format: MeshFormat,
) -> Result<Response, ApiError> {
    let limits = MeshLimits::default();
    // On the pool, like an array upload (see `decode_upload`).
    // A mesh file holds at least 12 bytes per vertex (binary STL, 50 bytes
    // per 3 vertices); decoded with its topology a vertex takes about 100:
    // ten times the body bounds it.
    let estimate = 10 * body.len() as u64;
    let (loaded, _) = state
        .pool
        .run_sized("upload", state.solve_timeout, estimate, move |_| {
            read_mesh(&body, Some(format), &limits)
        })
        .await?;
    let loaded = loaded.map_err(|e| match e {
        io::mesh::MeshIoError::TooLarge { .. } => ApiError::too_large("body", format!("body: {e}")),
        _ => ApiError::invalid_field("body", e.to_string()),
    })?;
    let store = state.store.clone();
    let owner = caller().owner;
    let meta = crate::datasets::blocking(move || {
        store.create_mesh_blocking(
            &loaded.mesh,
            loaded.report.clone(),
            &[],
            format.into(),
            &owner,
        )
    })
    .await?;
    let location = format!("/v1/datasets/{}", meta.id);
    let mut res = (StatusCode::CREATED, Json(meta)).into_response();
    if let Ok(v) = HeaderValue::from_str(&location) {
        res.headers_mut().insert(header::LOCATION, v);
    }
    Ok(res)
}

/// Largest mesh offered as JSON or OBJ, in vertices.
pub const MESH_TEXT_MAX_VERTICES: usize = 2_000_000;

/// Downloads a mesh dataset: PLY (stored bytes, default), OBJ, JSON or GLB.
async fn mesh_data(
    state: &AppState,
    id: &str,
    query: Option<OutputFormat>,
    property: Option<MeshProperty>,
    headers: &HeaderMap,
) -> Result<Response, ApiError> {
    let format = match query {
        Some(f) => f,
        None => match negotiate(None, headers) {
            OutputFormat::Json => OutputFormat::Json,
            OutputFormat::Obj => OutputFormat::Obj,
            OutputFormat::Glb => OutputFormat::Glb,
            OutputFormat::Npy if accepts_npy(headers) => OutputFormat::Npy,
            _ => OutputFormat::Ply,
        },
    };
    let store = state.store.clone();
    let id = id.to_string();
    let bytes = crate::datasets::blocking(move || store.read_mesh_file_blocking(&id)).await?;
    let (body, media) = match format {
        OutputFormat::Ply => (bytes, "model/ply"),
        OutputFormat::Npy => tokio::task::spawn_blocking(move || mesh_values_npy(&bytes, property))
            .await
            .map_err(ApiError::internal)??,
        OutputFormat::Obj | OutputFormat::Json | OutputFormat::Glb => {
            tokio::task::spawn_blocking(move || -> Result<(Vec<u8>, &'static str), ApiError> {
                let loaded = read_mesh(&bytes, Some(MeshFormat::Ply), &MeshLimits::default())
                    .map_err(ApiError::internal)?;
                if format != OutputFormat::Glb && loaded.mesh.num_vertices() > MESH_TEXT_MAX_VERTICES {
                    return Err(ApiError::not_acceptable(format!(
                        "obj and json are offered for meshes of at most {MESH_TEXT_MAX_VERTICES} vertices; use ply or glb"
                    )));
                }
                let extra = io::mesh::ply::vertex_values(&bytes).unwrap_or_default();
                if format == OutputFormat::Obj {
                    let carried = carried_properties(&extra);
                    if !carried.is_empty() {
                        return Err(ApiError::not_acceptable(format!(
                            "this mesh carries per-vertex values ({}) that OBJ cannot hold: \
                             download ply (the mesh with them), npy (the values alone), glb or json",
                            carried.join(", ")
                        )));
                    }
                    return Ok((write::write_obj(&loaded.mesh), "model/obj"));
                }
                let mut props = Vec::new();
                if let Some(d) = &extra.distance {
                    props.push(write::VertexProperty::F64("distance", d));
                }
                if let Some(l) = &extra.label {
                    props.push(write::VertexProperty::I32("label", l));
                }
                if let Some(v) = &extra.value {
                    props.push(write::VertexProperty::F64("value", v));
                }
                if format == OutputFormat::Glb {
                    return Ok((glb::write_glb(&loaded.mesh, &props), "model/gltf-binary"));
                }
                let json = write::write_json(&loaded.mesh, &props);
                Ok((serde_json::to_vec(&json).map_err(ApiError::internal)?, "application/json"))
            })
            .await
            .map_err(ApiError::internal)??
        }
        _ => {
            return Err(ApiError::not_acceptable(
                "a mesh dataset is offered as ply (default), obj, json, glb, or npy (its per-vertex values)",
            ))
        }
    };
    Ok(([(header::CONTENT_TYPE, media)], body).into_response())
}

/// True when `Accept` names NPY itself (a mesh's default is PLY).
fn accepts_npy(headers: &HeaderMap) -> bool {
    headers
        .get(header::ACCEPT)
        .and_then(|v| v.to_str().ok())
        .is_some_and(|a| {
            a.split(',').any(|item| {
                let essence = item.split(';').next().unwrap_or("").trim();
                essence.eq_ignore_ascii_case("application/x-npy")
                    || essence.eq_ignore_ascii_case("application/npy")
            })
        })
}

/// The per-vertex properties a stored mesh carries, in the order
/// `distance`, `value`, `label`.
fn carried_properties(values: &io::mesh::ply::VertexValues) -> Vec<&'static str> {
    let mut carried = Vec::new();
    if values.distance.is_some() {
        carried.push("distance");
    }
    if values.value.is_some() {
        carried.push("value");
    }
    if values.label.is_some() {
        carried.push("label");
    }
    carried
}

/// One per-vertex property of a stored mesh as a 1D NPY array (f64
/// `distance` and `value`, i32 `label`), `property` or else the first it
/// carries of `distance`, `value`, `label`.
fn mesh_values_npy(
    ply: &[u8],
    property: Option<MeshProperty>,
) -> Result<(Vec<u8>, &'static str), ApiError> {
    let values = io::mesh::ply::vertex_values(ply).map_err(ApiError::internal)?;
    let carried = carried_properties(&values);
    let Some(first) = carried.first() else {
        return Err(ApiError::not_acceptable(
            "this mesh carries no per-vertex values (it was uploaded, not computed): \
             download it as ply, obj, json or glb",
        ));
    };
    let name = property.map_or(*first, MeshProperty::name);
    let vector = |v: &Vec<f64>| ArrayData::F64(ndarray::Array1::from(v.clone()).into_dyn());
    let array = match name {
        "distance" => values.distance.as_ref().map(vector),
        "value" => values.value.as_ref().map(vector),
        _ => values
            .label
            .as_ref()
            .map(|v| ArrayData::I32(ndarray::Array1::from(v.clone()).into_dyn())),
    };
    let Some(array) = array else {
        return Err(ApiError::invalid_field(
            "property",
            format!(
                "this mesh has no '{name}' values; it carries {}",
                carried.join(", ")
            ),
        ));
    };
    let bytes = io::encode_npy(&array).map_err(ApiError::internal)?;
    Ok((bytes, "application/x-npy"))
}
