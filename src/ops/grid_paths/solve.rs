//! The run of `grid.paths`: one distance map per leg (from the cache when it
//! holds it), one descent per end point, the chain of the legs.

use std::sync::Arc;
use std::time::Instant;

use super::render::{geojson, svg};
use super::*;
use crate::numerics::anisotropic::descent::Riemannian;
use crate::numerics::paths::{
    CellCost, DescentOptions, DistanceMap, Isotropic, PathError, SourceSet,
};
use crate::numerics::{self, Control, EikonalProblem, Source, StopRules};
use crate::ops::spec::cost::resolve_cost;
use crate::ops::spec::errors::eikonal_error;
use crate::ops::spec::map_cache::{CachedCost, CachedMap, MapCache};
use crate::ops::spec::scheme::{stop_name, SourceSpec};
use crate::ops::spec::tensor::{resolve_tensor, solve_tensor, TensorSolveSpec, TensorSpec};
use crate::ops::{Inputs, OpError, OpLimits};

fn path_error(e: PathError, end_field: &str, source_field: &dyn Fn(usize) -> String) -> OpError {
    match e {
        PathError::EndPoint { reason, .. } => OpError::invalid(end_field, reason),
        PathError::Unreached { .. } => OpError::invalid(
            end_field,
            "the point is not reached from the sources (on a wall, or cut off by walls)",
        ),
        PathError::Source { index, reason } => OpError::invalid(source_field(index), reason),
        PathError::NoSources => OpError::invalid("sources", e.to_string()),
        PathError::Option { field, reason } => OpError::invalid(field, reason),
        PathError::Length { .. } | PathError::Stalled { .. } => {
            OpError::invalid(end_field, e.to_string())
        }
    }
}

/// Runs `grid.paths`. With a `cache`, designed costs and distance maps are
/// looked up there first and kept there afterwards; `cost` is a cost the
/// caller already fetched from that cache (so that it needs no inputs).
pub fn execute(
    req: &GridPathsRequest,
    inputs: &dyn Inputs,
    limits: &OpLimits,
    control: &Control<'_>,
    cache: Option<&dyn MapCache>,
    cost: Option<Arc<CachedCost>>,
) -> Result<GridPathsResult, OpError> {
    req.validate(limits)?;
    let cost_spec = match (&req.cost, &req.metric) {
        (Some(c), _) => c,
        (None, Some(metric)) => return execute_tensor(req, metric, inputs, limits, control),
        (None, None) => return Err(OpError::invalid("cost", "missing")),
    };
    let cost_key = req.cost_key();
    let started = Instant::now();
    let cached_cost = cost.or_else(|| cache.and_then(|c| c.cost(&cost_key)));
    let cost_cached = cached_cost.is_some();
    let cost = match cached_cost {
        Some(c) => c,
        None => {
            let resolved = resolve_cost(
                cost_spec,
                req.spacing.as_deref(),
                req.obstacles.as_deref(),
                inputs,
                limits,
                control,
            )?;
            let c = Arc::new(CachedCost {
                w: resolved.cost_values()?,
                grid: resolved.grid,
                spacing: resolved.spacing,
            });
            if let Some(cache) = cache {
                cache.put_cost(cost_key.clone(), c.clone());
            }
            c
        }
    };
    let cost_seconds = if cost_cached {
        0.0
    } else {
        started.elapsed().as_secs_f64()
    };
    let grid = &cost.grid;
    if req.format != PathFormat::Json && grid.ndim() == 3 {
        return Err(OpError::invalid(
            "format",
            "geojson and svg are for 2D grids; use json in 3D",
        ));
    }
    let descent = DescentOptions {
        step: req.step,
        ..DescentOptions::default()
    };
    let mut maps = Vec::new();
    let mut paths = Vec::new();
    let mut descent_seconds = 0.0;
    let chain_mode = req.ends.is_empty();
    for (leg_index, leg) in req.legs().into_iter().enumerate() {
        let key = req.map_key(&cost_key, &leg.sources);
        let ends_reached = |m: &CachedMap| {
            m.complete
                || leg.ends.iter().all(|(_, p)| {
                    grid.point3(p)
                        .ok()
                        .filter(|q| grid.contains_point3(*q))
                        .is_none_or(|q| m.u[grid.linear(q.map(|v| v.round() as usize))].is_finite())
                })
        };
        let hit = cache.and_then(|c| c.map(&key)).filter(|m| ends_reached(m));
        let (map, stats) = match hit {
            Some(m) => {
                let s = LegStats {
                    cached: true,
                    frozen: m.frozen,
                    stop: m.stop.clone(),
                    solve_seconds: 0.0,
                };
                (m, s)
            }
            None => {
                // A miss after a partial map: the user explores, compute all of it.
                let early = req.early_stop && cache.and_then(|c| c.map(&key)).is_none();
                let m = solve_leg(req, &cost, &leg, early, control)?;
                let s = LegStats {
                    cached: false,
                    frozen: m.0.frozen,
                    stop: m.0.stop.clone(),
                    solve_seconds: m.1,
                };
                let m = Arc::new(m.0);
                if let Some(cache) = cache {
                    cache.put_map(key, m.clone());
                }
                (m, s)
            }
        };
        maps.push(stats);
        let t = Instant::now();
        let dm = DistanceMap::new(grid, &map.u, map.cost.w.as_slice())
            .map_err(|e| OpError::invalid("cost", e.to_string()))?;
        for (end_index, (field, end)) in leg.ends.iter().enumerate() {
            if control.is_cancelled() {
                return Err(OpError::Cancelled);
            }
            let path = dm
                .descend(&map.sources, end, &Isotropic, &descent)
                .map_err(|e| path_error(e, field, &*leg.source_field))?;
            let index = if chain_mode { leg_index } else { end_index };
            paths.push(PathOut::new(index, end, &path, grid, req.simplify));
        }
        descent_seconds += t.elapsed().as_secs_f64();
    }
    let stats = PathsStats {
        cells: grid.len() as u64,
        cost_cached,
        cost_seconds,
        maps,
        descent_seconds,
    };
    assemble(req, inputs, &cost, paths, stats)
}

/// `grid.paths` with a tensor `metric`: one anisotropic solve per leg and
/// the descent along `−M⁻¹∇U`, without the cache (see the module docs).
fn execute_tensor(
    req: &GridPathsRequest,
    metric: &TensorSpec,
    inputs: &dyn Inputs,
    limits: &OpLimits,
    control: &Control<'_>,
) -> Result<GridPathsResult, OpError> {
    let started = Instant::now();
    let resolved = resolve_tensor(
        metric,
        "metric",
        req.spacing.as_deref(),
        req.obstacles.as_deref(),
        inputs,
        limits,
        control,
    )?;
    if req.format != PathFormat::Json && resolved.grid.ndim() == 3 {
        return Err(OpError::invalid(
            "format",
            "geojson and svg are for 2D grids; use json in 3D",
        ));
    }
    // A scalar picture of the metric (sqrt(tr M / d), +inf on walls): only
    // the SVG background reads it, so other formats skip the pass over the grid.
    let cost = {
        let w = if req.format == PathFormat::Svg {
            let r = Riemannian::new(&resolved.grid, &resolved.metric);
            (0..resolved.grid.len()).map(|i| r.cost_at(i)).collect()
        } else {
            Vec::new()
        };
        CachedCost {
            w,
            grid: resolved.grid.clone(),
            spacing: resolved.spacing.clone(),
        }
    };
    let cost_seconds = started.elapsed().as_secs_f64();
    let (mut problem, _) = resolved.into_problem(Vec::new());
    let descent = DescentOptions {
        step: req.step,
        ..DescentOptions::default()
    };
    let (mut maps, mut paths, mut descent_seconds) = (Vec::new(), Vec::new(), 0.0);
    let chain_mode = req.ends.is_empty();
    for (leg_index, leg) in req.legs().into_iter().enumerate() {
        let grid = &problem.grid;
        let targets: Vec<Vec<f64>> = if req.early_stop {
            leg.ends
                .iter()
                .filter(|(_, p)| grid.point3(p).is_ok_and(|q| grid.contains_point3(q)))
                .map(|(_, p)| p.clone())
                .collect()
        } else {
            Vec::new()
        };
        problem.sources = leg.sources.iter().map(SourceSpec::to_source).collect();
        let spec = TensorSolveSpec {
            order: req.order,
            factoring: req.factoring,
            stop: StopRules {
                targets,
                ..StopRules::default()
            },
            record_order: false,
        };
        let solved = solve_tensor(&problem, &spec, "metric", control)
            .map_err(|e| rename_leg_source(e, &leg))?;
        let out = &solved.out.output;
        maps.push(LegStats {
            cached: false,
            frozen: out.frozen as u64,
            stop: stop_name(out.stop).to_string(),
            solve_seconds: solved.seconds,
        });
        let t = Instant::now();
        // The solver's array is in standard layout: borrow it, copy only otherwise.
        let owned: Vec<f64>;
        let u: &[f64] = match out.distance.as_slice() {
            Some(u) => u,
            None => {
                owned = out.distance.iter().copied().collect();
                &owned
            }
        };
        let grid = &problem.grid;
        let set = SourceSet::new(grid, &problem.sources)
            .map_err(|e| path_error(e, "ends", &*leg.source_field))?;
        let riemannian = Riemannian::new(grid, &problem.metric);
        let dm = DistanceMap::new(grid, u, &riemannian)
            .map_err(|e| OpError::invalid("metric", e.to_string()))?;
        for (end_index, (field, end)) in leg.ends.iter().enumerate() {
            if control.is_cancelled() {
                return Err(OpError::Cancelled);
            }
            let path = dm
                .descend(&set, end, &riemannian, &descent)
                .map_err(|e| path_error(e, field, &*leg.source_field))?;
            let index = if chain_mode { leg_index } else { end_index };
            paths.push(PathOut::new(index, end, &path, grid, req.simplify));
        }
        descent_seconds += t.elapsed().as_secs_f64();
    }
    let stats = PathsStats {
        cells: problem.grid.len() as u64,
        cost_cached: false,
        cost_seconds,
        maps,
        descent_seconds,
    };
    assemble(req, inputs, &cost, paths, stats)
}

/// Renames a `sources[i]` error of a leg's solve to the leg's own field (a
/// way-point, a contour point).
fn rename_leg_source(e: OpError, leg: &Leg) -> OpError {
    match e.field().and_then(|f| f.strip_prefix("sources[")) {
        Some(rest) => {
            let index = rest
                .split(']')
                .next()
                .and_then(|i| i.parse().ok())
                .unwrap_or(0);
            match e {
                OpError::Invalid { reason, .. } => {
                    OpError::invalid((leg.source_field)(index), reason)
                }
                other => other,
            }
        }
        None => e,
    }
}

/// The answer of [`execute`]: the chain (way-point and contour modes) and
/// the formats, from the paths of every leg.
fn assemble(
    req: &GridPathsRequest,
    inputs: &dyn Inputs,
    cost: &CachedCost,
    paths: Vec<PathOut>,
    stats: PathsStats,
) -> Result<GridPathsResult, OpError> {
    let chain = (!req.waypoints.is_empty() || !req.contour.is_empty()).then(|| {
        let mut points: Vec<Vec<f64>> = Vec::new();
        let mut world: Vec<Vec<f64>> = Vec::new();
        for p in &paths {
            let skip = usize::from(!points.is_empty());
            points.extend(p.points.iter().skip(skip).cloned());
            world.extend(p.world.iter().skip(skip).cloned());
        }
        ChainOut {
            closed: !req.contour.is_empty(),
            points,
            world,
            geodesic_length: paths.iter().map(|p| p.geodesic_length).sum(),
            euclidean_length: paths.iter().map(|p| p.euclidean_length).sum(),
        }
    });
    let geojson = (req.format == PathFormat::Geojson).then(|| geojson(&paths, chain.as_ref()));
    let svg = match req.format {
        PathFormat::Svg => Some(svg(req, inputs, cost, &paths, chain.as_ref())?),
        _ => None,
    };
    Ok(GridPathsResult {
        paths,
        chain,
        stats,
        geojson,
        svg,
    })
}

/// Solves the distance map of one leg; returns it with the solve time.
fn solve_leg(
    req: &GridPathsRequest,
    cost: &Arc<CachedCost>,
    leg: &Leg,
    early: bool,
    control: &Control<'_>,
) -> Result<(CachedMap, f64), OpError> {
    let grid = &cost.grid;
    let targets = if early {
        // Only the targets inside the grid: the others are refused by the descent, naming them.
        leg.ends
            .iter()
            .filter(|(_, p)| grid.point3(p).is_ok_and(|q| grid.contains_point3(q)))
            .map(|(_, p)| p.clone())
            .collect()
    } else {
        Vec::new()
    };
    let dreq = req.distance_request(leg.sources.clone(), targets.clone());
    let mut options = dreq.options();
    options.stop = StopRules {
        targets,
        ..StopRules::default()
    };
    let sources: Vec<Source> = leg.sources.iter().map(SourceSpec::to_source).collect();
    let iso = cost.isotropic()?;
    let problem = EikonalProblem {
        grid: grid.clone(),
        cost: iso,
        sources,
    };
    let started = Instant::now();
    // Source errors name this leg's own field (a way-point, a contour point).
    let out = numerics::solve(&problem, &options, control)
        .map_err(|e| rename_leg_source(eikonal_error(e), leg))?;
    let solve_seconds = started.elapsed().as_secs_f64();
    let sources = SourceSet::new(grid, &problem.sources)
        .map_err(|e| path_error(e, "ends", &*leg.source_field))?;
    let complete = out.stop == numerics::StopReason::Completed;
    Ok((
        CachedMap {
            cost: cost.clone(),
            sources,
            u: out.distance.iter().copied().collect(),
            complete,
            frozen: out.frozen as u64,
            stop: stop_name(out.stop).to_string(),
        },
        solve_seconds,
    ))
}
