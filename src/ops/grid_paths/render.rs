//! The answer formats of `grid.paths` besides JSON: GeoJSON (positions
//! `[x, y] = [axis 1, axis 0] × spacing`, as the standard wants) and SVG
//! (the paths over a grey PNG of the image).

use std::fmt::Write as _;

use base64::Engine as _;

use super::{ChainOut, GridPathsRequest, PathOut};
use crate::io::{render_png, ArrayData, Colormap, RenderOptions, RenderStyle};
use crate::ops::spec::map_cache::CachedCost;
use crate::ops::{Inputs, OpError};

/// GeoJSON FeatureCollection: one LineString per path (and one for the
/// chain), positions `[x, y] = [axis 1, axis 0] × spacing`.
pub(super) fn geojson(paths: &[PathOut], chain: Option<&ChainOut>) -> serde_json::Value {
    let line =
        |world: &[Vec<f64>]| -> Vec<[f64; 2]> { world.iter().map(|p| [p[1], p[0]]).collect() };
    let mut features: Vec<serde_json::Value> = paths
        .iter()
        .map(|p| {
            serde_json::json!({
                "type": "Feature",
                "geometry": {"type": "LineString", "coordinates": line(&p.world)},
                "properties": {
                    "kind": "path",
                    "index": p.index,
                    "source": p.source,
                    "end": p.end,
                    "geodesic_length": p.geodesic_length,
                    "euclidean_length": p.euclidean_length,
                }
            })
        })
        .collect();
    if let Some(c) = chain {
        features.push(serde_json::json!({
            "type": "Feature",
            "geometry": {"type": "LineString", "coordinates": line(&c.world)},
            "properties": {
                "kind": if c.closed { "contour" } else { "chain" },
                "closed": c.closed,
                "geodesic_length": c.geodesic_length,
                "euclidean_length": c.euclidean_length,
            }
        }));
    }
    serde_json::json!({"type": "FeatureCollection", "features": features})
}

/// SVG document: a grey PNG of the image (the `cost.dataset` array when the
/// inputs hold it, else `W`) with the paths drawn over it, in world units.
pub(super) fn svg(
    req: &GridPathsRequest,
    inputs: &dyn Inputs,
    cost: &CachedCost,
    paths: &[PathOut],
    chain: Option<&ChainOut>,
) -> Result<String, OpError> {
    let grid = &cost.grid;
    let shape = grid.shape();
    let h = grid.spacing();
    let image = req
        .cost
        .as_ref()
        .and_then(|c| c.dataset.as_deref())
        .and_then(|id| inputs.get(id))
        .map(|a| a.array)
        .filter(|a| a.shape() == shape);
    let w_array;
    let shown: &ArrayData = match &image {
        Some(a) => a,
        None => {
            let w: Vec<f64> = cost
                .w
                .iter()
                .map(|&v| if v.is_finite() { v } else { f64::NAN })
                .collect();
            w_array = ArrayData::F64(
                ndarray::ArrayD::from_shape_vec(ndarray::IxDyn(shape), w)
                    .map_err(|e| OpError::invalid("cost", e.to_string()))?,
            );
            &w_array
        }
    };
    let options = RenderOptions {
        style: RenderStyle::Continuous,
        colormap: Colormap::Grey,
        ..RenderOptions::default()
    };
    // A constant image has no range to map: the paths are drawn alone.
    let png = render_png(shown, &options).ok();
    let (wx, wy) = (shape[1] as f64 * h[1], shape[0] as f64 * h[0]);
    let (x0, y0) = (-0.5 * h[1], -0.5 * h[0]);
    let stroke = 0.004 * wx.max(wy);
    let mut s = String::new();
    // Writing to a String cannot fail.
    let _ = write!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" viewBox="{x0} {y0} {wx} {wy}" width="{}" height="{}">"#,
        shape[1].max(1) as f64 * h[1] / h[0].min(h[1]),
        shape[0].max(1) as f64 * h[0] / h[0].min(h[1]),
    );
    if let Some(png) = png {
        let _ = write!(
            s,
            r#"<image x="{x0}" y="{y0}" width="{wx}" height="{wy}" preserveAspectRatio="none" style="image-rendering:pixelated" href="data:image/png;base64,{}"/>"#,
            base64::engine::general_purpose::STANDARD.encode(&png)
        );
    }
    let polyline = |s: &mut String, world: &[Vec<f64>], colour: &str, closed: bool| {
        let pts: Vec<String> = world.iter().map(|p| format!("{},{}", p[1], p[0])).collect();
        let tag = if closed { "polygon" } else { "polyline" };
        let _ = write!(
            s,
            r#"<{tag} points="{}" fill="none" stroke="{colour}" stroke-width="{stroke}" stroke-linejoin="round"/>"#,
            pts.join(" ")
        );
    };
    match chain {
        Some(c) => polyline(&mut s, &c.world, "#ff3b30", c.closed),
        None => {
            for p in paths {
                polyline(&mut s, &p.world, "#ff3b30", false);
            }
        }
    }
    for p in paths {
        for (q, colour) in [(p.world.first(), "#34c759"), (p.world.last(), "#0a84ff")] {
            if let Some(q) = q {
                let _ = write!(
                    s,
                    r#"<circle cx="{}" cy="{}" r="{}" fill="{colour}"/>"#,
                    q[1],
                    q[0],
                    2.0 * stroke
                );
            }
        }
    }
    s.push_str("</svg>");
    Ok(s)
}
