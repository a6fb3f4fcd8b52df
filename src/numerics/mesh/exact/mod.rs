//! Exact polyhedral geodesic distance by window propagation: the
//! Chen–Han / Xin–Wang ("ICH") scheme with MMP's pseudo-sources and an
//! interval-trimming filter against the vertex distances.
//!
//! # The math
//! The geodesic distance on a polyhedral surface is realised by paths that
//! are straight inside every face and across every edge when the two faces
//! are unfolded into one plane; they bend only at *saddle* vertices (total
//! angle `> 2π`) and boundary vertices, which act as new point sources
//! (*pseudo-sources*). A **window** is a set of such straight rays crossing
//! an edge, all coming from one (pseudo-)source whose image, unfolded into
//! the plane of the face the window enters, is `I = (sx, sy)`. In the frame
//! of a half-edge `a → b` (length `L`, `a` at the origin, `b = (L, 0)`, the
//! face being entered on `y > 0`, `sy ≤ 0`), a window is
//! `w = (b0, b1, I, σ)`: the rays cross the edge at `x ∈ [b0, b1]` and the
//! distance there is `d_w(x) = σ + sqrt((x − sx)² + sy²)`, `σ` being the
//! distance of the pseudo-source. (Surazhsky et al. store `(b0, b1, d0,
//! d1, σ)`; `d0`, `d1` are the distances from `I` to the interval's ends,
//! equivalent to `(sx, sy)`.)
//!
//! **Propagation.** A window entering face `(a, b, c)`, `c = (cx, cy)`,
//! `cy > 0`, meets the ray through `c` at `xc = sx + (cx − sx)(−sy)/(cy −
//! sy)`. Rays with `x < xc` leave through edge `c → a`, the others through
//! `b → c`; each part is a child window on that edge, whose source image
//! is re-expressed in the edge's frame and then reflected (`y ↦ −y`, and
//! `x ↦ L − x` when the neighbour traverses the edge the other way) into
//! the frame of the neighbouring face: this is the unfolding. Boundary and
//! non-manifold edges have no neighbour: their windows stop there.
//!
//! **Vertex distances** `U(v)` are only ever lowered to lengths of real
//! surface paths: `σ + |I − p| + |p − v|` with `p` the point of the window
//! nearest to `v` (`p = (clamp(xc, b0, b1), 0)` for `c`, the interval's
//! ends for `a` and `b`), and `U(v) + |v u|` along edges from pseudo-sources.
//! Hence `U` never underestimates, and equals the geodesic distance once
//! the window carrying a vertex's shortest path has been processed.
//!
//! **Filtering (trimming).** For a window on edge `p → q` the path through
//! the vertex `p`, of length `U(p) + x`, competes with `d_w(x)`; their
//! difference `g(x) = d_w(x) − U(p) − x` is non-increasing in `x` (because
//! `|∂x d_w| ≤ 1`), so the points where the vertex path is strictly
//! shorter form an interval `[0, x*)`, `x*` solving `x + D = sqrt((x −
//! sx)² + sy²)`, `D = U(p) − σ`: `x* = (sx² + sy² − D²) / (2 (D + sx))`.
//! The same holds for `q` mirrored. Every ray through a dominated point is
//! dominated beyond it too (the path `p → x → Q` is at most `U(p) + |px| +
//! |xQ| < σ + |Ix| + |xQ|`), so cutting `[0, x*)` and `(x*_q, L]` off the
//! window, or dropping it when nothing is left, never removes a shortest
//! path. This is Xin and Wang's filtering theorem in interval form: a window
//! is tested against both vertices of its edge when created and again when
//! processed, and the third vertex of the face is tested when the children
//! land on the edges incident to it. The same argument holds against any
//! window `w'` already propagated across the same edge (in either
//! direction): where `d_{w'}(x) < d_w(x)` the window loses, and the
//! crossings solve `σ + |I x| = σ' + |I' x|`, a quadratic once squared
//! twice (MMP's intersection, used here only to cut the new window's
//! ends), whose roots, with the linear equation's once squared, split the
//! overlap into pieces tested at their midpoints (a crossing of two
//! windows of one source distance is a double root of the quadratic, which
//! rounding can lose: see `trim_by_window`).
//! Any subset of those windows gives valid cuts; only the latest one per
//! half-edge, in the window's own direction, is kept and compared with,
//! when a window is processed: comparing with every earlier window (a list
//! per edge) removed under 0.1 % more windows on icospheres, for a cache
//! miss per comparison and 60 bytes per propagated window (2 GB at 164k
//! vertices); the windows that crossed the other way cut 0.4 % of the
//! windows they were compared with on a sliver sphere (none on an
//! icosphere) for half of the comparisons; the latest two instead of one
//! left fewer windows but took 5-8 % longer end to end on the sliver
//! sphere.
//! Finally Chen and Han's *one angle, one split*: when the distance of `c`
//! was set by a straight path entering the same face through the same edge
//! at `x1`, and `w` reaches `c` with a larger distance, the rays of `w`
//! entering between `x1` and `xc` cross that path inside the face and lose
//! beyond the crossing, so that part of the child is not created. A small
//! relative tolerance makes every cut conservative, so rounding can only
//! keep a window, never lose one.
//!
//! **Order.** Windows are processed in increasing order of their minimum
//! distance `σ + dist(I, [b0, b1])` up to a relative `1.5e-5` (a radix
//! heap on the key's bits, see `RadixQueue`), interleaved with the vertex
//! events of pseudo-sources keyed by `U(v)` (a binary heap). Children are
//! never closer than their parent, so a pseudo-source emits with its final
//! distance up to that approximation: its windows cover the opposite edges
//! of its faces, and its neighbours get `U(v) + |vu|`. Exactness does not
//! rest on the order: every cut above compares with a real path, whatever
//! was processed before, and a pseudo-source whose `U(v)` is lowered after
//! it emitted emits again; the order only keeps the windows few.
//!
//! **Saddles emit into their shadow only.** A shortest path bends at a
//! vertex only where both angles between its incoming and outgoing
//! segments are at least `π` (Mitchell, Mount and Papadimitriou): an
//! interior saddle of total angle `Θ > 2π`, reached by a straight segment
//! whose back-direction lies at angle `p` around it, emits only into the
//! sector `[p + π, p + Θ − π]` (MMP's rule; Chen–Han and Xin–Wang emit
//! around the whole vertex). Every other direction is covered by the
//! windows passing beside the vertex. On a sliver sphere, where 45 % of
//! the vertices are saddles with a small excess, this removed 8 % of the
//! windows with the same distances to rounding. Vertices reached by a bent
//! path, sources, and boundary or non-manifold vertices emit everywhere.
//!
//! Pseudo-sources are saddle vertices,
//! boundary and non-manifold-edge vertices, vertices whose faces form
//! several fans, and vertices of degenerate (zero-area) faces, which no
//! window crosses.
//!
//! **Two halves (`exact_distance_threads`, the default on a pool of two
//! threads or more).** The propagation can be split in two halves by a
//! plane through the first source (see `split`): each propagates the
//! windows entering its own faces and keeps its own vertices' distances
//! (and emits them as pseudo-sources); a window entering the other's
//! face, or a distance lowered for the other's vertex (with how it was
//! reached), is sent to it in batches. Each keeps its own copy of the
//! distances for its cuts: the other's may be late, hence larger, which
//! only makes a cut weaker, never wrong, since exactness does not rest on
//! the order. A half is not stepped more than two mean edge lengths ahead
//! of the other (windows far out of order are mostly cut later). The
//! distances are the one worker's to rounding (asserted).
//!
//! Each half sits behind a lock, and whichever of the two threads of a
//! `rayon::join` is free steps a half that is not ahead (see `drive`):
//! with two cores each thread mostly keeps one half; when the second
//! thread is late (the pool is busy) or loses its core (the machine is
//! loaded), the first steps both in turn, always the one behind, and a
//! thread waiting for the half held by the other sleeps. (Before, each
//! thread owned a half and an idle one gave up after 2 ms: on a loaded
//! machine the halves then ran alone in turn, each far ahead of the other,
//! and the 437k-vertex dragon took 100 s against 11.5 s on one worker.
//! Now, split by force beside two busy loops, it takes 6.5-7.2 s against
//! 7.7-8.1 s on one worker.)
//!
//! The split is made only where it pays: `split` estimates the time of
//! the halves kept in step as the sum, over 64 bands of distance from the
//! sources (an edge-graph Dijkstra pass, run beside the frames), of the
//! larger half's work, and splits when one worker's work is at least
//! 1.4 times that. The sliver sphere (41k vertices, estimate 1.7-2.0
//! from three sources) and the icosphere of 41k vertices take 1.6-1.7x
//! less time on two cores; the dragon and
//! its decimations (estimate 1.27-1.29: the fronts run through the halves
//! at different speeds) took 0.9-1.1x one worker's time when split, and
//! are not split. One thread stepping both halves in turn takes 6 % more
//! than one worker (the sliver sphere), hence one worker on a pool of one
//! thread.
//!
//! **Sources** at vertices are pseudo-sources at distance 0; a source
//! inside a face sends one window across each edge of its face (a source on
//! an edge into both faces of the edge). With several sources every window
//! carries the index of its source, and `U(v)` keeps the label of the path
//! that set it: the nearest source per vertex, ties broken by processing
//! order.
//!
//! **Why this algorithm.** MMP (as implemented by Surazhsky et al.) keeps
//! the windows of every edge disjoint by intersecting new and old windows
//! both ways and re-sorting the edge, which is where its implementations
//! fail (the asserts reported on `libigl#1013` and `openep-core#55`).
//! Chen–Han with Xin and Wang's filter never modifies a window once
//! propagated: a new window is only cut, against two vertex distances (a
//! few flops) and, one-sidedly, against the latest windows of its edge,
//! and every cut is justified by a real shorter path, so a bad cut can cost
//! time but never a wrong distance. Paths ([`exact_paths`]) are not read
//! off a window tree: each vertex keeps only how it got its final distance
//! (the window's crossing and source image, or the vertex before it), and
//! the path is traced back along that straight unfolded ray
//! (`backtrack`). VTP's test of a window against the third vertex
//! of the face it enters (and of the face it leaves: `U(v) + |vx|` through
//! the straight segment in that face) was tried and removed no windows on
//! icospheres beyond the tests above (97.7 per vertex at 41k either way),
//! so it is not done; with the filters above about 21 windows per vertex
//! are processed on an icosphere of 2,562 vertices (see the benchmark for
//! larger meshes).
//!
//! **Complexity.** Worst case `O(n²)` windows and `O(n² log n)` time (as
//! for Chen–Han). Measured on icospheres (`tests/bench/mesh_exact.rs`):
//! 47, 98 and 197 windows per vertex at 10k, 41k and 164k vertices, i.e.
//! `O(n^1.5)` windows (on a convex surface the rays crossing an edge are
//! split by every vertex between it and the source). Each window costs
//! `O(1)`: one window comparison at most and a radix-heap push and pop, so the
//! time grows like the windows (0.12 s, 0.84 s and 5.1 s on the shared VM,
//! 5-10x faster than pygeodesic's MMP at 41k-164k).
//! Memory: the vertex arrays (per half), one window (40 bytes) per
//! half-edge for the comparison filter (each half keeps its own faces'),
//! 64 bytes per half-edge of precomputed frames (one cache line) and 16 of
//! corner angles, `O(n)`, plus the pending windows (56 bytes each, 77k at
//! most at 164k vertices): with one worker 432-445 MB peak on the
//! 437k-vertex Stanford dragon, mesh and process included (1.0 kB per
//! vertex; 359 MB before the frames were one record per half-edge), 494 MB
//! split in two halves (604 MB when each half kept the filter's windows of
//! every half-edge).
//!
//! **Robustness.** Degenerate faces are never entered; a final
//! `O(E)` check verifies `U(v) ≤ U(u) + |uv|` on every edge and, only if
//! it fails somewhere (which exact propagation excludes on non-degenerate
//! meshes), repairs it with a Dijkstra pass along edges. No operation can
//! produce NaN: lengths are clamped before square roots and divisions by
//! edge lengths happen only on non-degenerate faces.

use std::cmp::Ordering;
use std::collections::{BinaryHeap, HashMap};
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering as AtomicOrdering};
use std::sync::Mutex;

mod backtrack;
pub use backtrack::exact_paths;

use super::{norm, sub, MeshDistance, MeshSolveError, SurfacePoint, Topology, TriMesh, NONE};
use crate::numerics::Control;

/// Relative tolerance of the dominance test (conservative: windows that
/// tie within it are kept).
const TRIM_TOL: f64 = 1e-11;
/// A face is degenerate when its smallest height is below this fraction of
/// its longest edge.
const DEGENERATE: f64 = 1e-12;
/// Windows narrower than this fraction of their edge carry no ray worth
/// following (the vertex update of their ends is done by their parent).
const MIN_WIDTH: f64 = 1e-13;
/// How many of the latest propagated windows of each half-edge are kept
/// for the comparison filter (see [`Propagation::recent`]).
const RECENT: usize = 1;
/// How many heap pops between two cancellation checks / progress reports.
const POLL: usize = 4096;
/// Steps between two exchanges of messages by the workers of a split
/// propagation.
const EXCHANGE: usize = 64;
/// How long a thread of a split propagation with nothing to step spins
/// (yielding) before it sleeps between its checks.
const SPIN_WAIT: std::time::Duration = std::time::Duration::from_micros(200);
/// How long such a thread sleeps between its checks once it stopped
/// spinning.
const IDLE_SLEEP: std::time::Duration = std::time::Duration::from_micros(50);
/// The fewest vertices for which [`exact_distance_with_stats`] considers
/// splitting the propagation: below, one worker answers in a few
/// milliseconds (the 1.8k-vertex bunny in 9 ms end to end), which a
/// Dijkstra pass and a second thread's wake-up would not shorten much.
const MIN_SPLIT_VERTICES: usize = 10_000;
/// Bands of distance from the source by which [`split`] estimates how
/// the two halves share the work.
const BANDS: usize = 64;
/// The least estimated gain (one worker's work over the sum per band of
/// the larger half's) for which [`split`] splits.
const MIN_SPLIT_GAIN: f64 = 1.4;
/// How far (in mean edge lengths) one half of a split propagation may run
/// ahead of the other.
const PACE: f64 = 2.0;
/// Angle (radians) by which the sector a saddle pseudo-source emits into is
/// widened on each side (see [`Propagation::shadow_sector`]): far above
/// the rounding of the arrival direction, far below the angles that matter.
const SECTOR_SLACK: f64 = 1e-6;

/// Which vertex of half-edge `h`'s face an [`Arrival`] reached.
#[derive(Debug, Clone, Copy, PartialEq)]
enum ArrivalAt {
    /// The half-edge's origin `a`.
    Origin,
    /// Its end `b`.
    End,
    /// The face's third vertex `c`.
    Third,
}

/// The last straight segment of the path that set a vertex's distance:
/// it came from the point `(x, y)` in the frame of half-edge `h` (`h ==
/// NONE`: unknown, or the path was not straight there).
#[derive(Debug, Clone, Copy)]
struct Arrival {
    h: u32,
    at: ArrivalAt,
    x: f64,
    y: f64,
}

impl Arrival {
    const NONE: Arrival = Arrival {
        h: NONE,
        at: ArrivalAt::Origin,
        x: 0.0,
        y: 0.0,
    };

    fn at(h: usize, at: ArrivalAt, x: f64, y: f64) -> Self {
        Arrival {
            h: h as u32,
            at,
            x,
            y,
        }
    }
}

/// One window: rays from the source image `(sx, sy)` (with `sy <= 0`)
/// crossing half-edge `h` at `x ∈ [b0, b1]`, entering the face of `h`.
#[derive(Debug, Clone, Copy)]
struct Window {
    /// Minimum distance over the interval (heap key).
    key: f64,
    b0: f64,
    b1: f64,
    sx: f64,
    sy: f64,
    sigma: f64,
    h: u32,
    label: u32,
}

/// Low bits of a key's `f64` pattern that the window queue ignores: keys
/// within a relative `2^(KEY_SHIFT − 52)` (1.5e-5) of each other may be
/// processed in any order. On icospheres this added 0.4 % windows and saved
/// a fifth of the time (fewer radix-heap levels to move windows through).
const KEY_SHIFT: u32 = 36;

/// The order of non-negative `f64` keys as `u64`: the bit patterns of
/// non-negative floats sort like the floats, here rounded down to a
/// multiple of `2^KEY_SHIFT` (`-0.0`, NaN and negatives map to 0).
#[inline]
fn key_bits(key: f64) -> u64 {
    if key > 0.0 {
        key.to_bits() >> KEY_SHIFT
    } else {
        0
    }
}

/// Monotone priority queue of windows (a radix heap on the bits of the
/// key): bucket `i > 0` holds the keys whose highest bit differing from the
/// last popped key `last` is bit `i − 1`, bucket 0 the keys equal to it.
/// A pop that finds bucket 0 empty moves the first non-empty bucket down
/// relative to its minimum; every window moves at most `64 − KEY_SHIFT`
/// times, in practice a few, and always through sequential `Vec`s, where a
/// binary heap of 56-byte windows spent a third of the solve in cache
/// misses. Windows of one bucket-0 key pop last-in first-out.
///
/// It needs keys never below the last popped one: children are never
/// closer than their parent, and a key that rounding put below is raised
/// to `last` (this only reorders windows within rounding; the
/// propagation's exactness does not depend on the order, see the module
/// documentation).
struct RadixQueue {
    last: u64,
    len: usize,
    buckets: Vec<Vec<Window>>,
}

impl RadixQueue {
    fn new() -> Self {
        Self {
            last: 0,
            len: 0,
            buckets: (0..65).map(|_| Vec::new()).collect(),
        }
    }

    #[inline]
    fn bucket(last: u64, key: u64) -> usize {
        (64 - (key ^ last).leading_zeros()) as usize
    }

    #[inline]
    fn push(&mut self, mut w: Window) {
        let mut key = key_bits(w.key);
        if key < self.last {
            key = self.last;
            w.key = f64::from_bits(key << KEY_SHIFT);
        }
        self.buckets[Self::bucket(self.last, key)].push(w);
        self.len += 1;
    }

    /// The smallest key, after moving it to bucket 0.
    fn peek_key(&mut self) -> Option<f64> {
        if self.buckets[0].is_empty() {
            let i = self.buckets.iter().position(|b| !b.is_empty())?;
            let mut items = std::mem::take(&mut self.buckets[i]);
            let last = items
                .iter()
                .map(|w| key_bits(w.key))
                .min()
                .unwrap_or(self.last);
            self.last = last;
            for w in items.drain(..) {
                let key = key_bits(w.key);
                self.buckets[Self::bucket(last, key)].push(w);
            }
            // Keep the allocation of the emptied bucket.
            self.buckets[i] = items;
        }
        self.buckets[0].last().map(|w| w.key)
    }

    fn pop(&mut self) -> Option<Window> {
        self.peek_key()?;
        self.len -= 1;
        self.buckets[0].pop()
    }
}

/// The distance field `σ + |I x|` of a propagated window over `[b0, b1]`,
/// in the frame of its half-edge: what the comparison filter needs.
#[derive(Debug, Clone, Copy)]
struct Field {
    b0: f64,
    b1: f64,
    sx: f64,
    sy: f64,
    sigma: f64,
}

impl Field {
    /// An empty slot: overlaps nothing.
    const EMPTY: Field = Field {
        b0: f64::INFINITY,
        b1: f64::NEG_INFINITY,
        sx: 0.0,
        sy: 0.0,
        sigma: 0.0,
    };

    fn of(w: &Window) -> Self {
        Field {
            b0: w.b0,
            b1: w.b1,
            sx: w.sx,
            sy: w.sy,
            sigma: w.sigma,
        }
    }
}

/// What one worker of a split propagation hands to the other.
#[derive(Debug, Clone, Copy)]
enum Message {
    /// A window entering one of the other worker's faces.
    Window(Window),
    /// A distance lowered for one of the other worker's vertices, with how
    /// it was reached.
    Distance {
        v: u32,
        label: u32,
        d: f64,
        arrival: Arrival,
        via: (u32, f64),
    },
}

/// The two halves' mailboxes and fronts.
#[derive(Default)]
struct Mail {
    inbox: [Mutex<Vec<Message>>; 2],
    /// Set when a half failed (cancelled, or out of steps).
    stop: AtomicBool,
    /// Vertices each half has reached (for progress).
    reached: [AtomicUsize; 2],
    /// Each half's front: the `f64` bits of its next key (the bits of
    /// non-negative floats order like the floats), lowered by the other
    /// half to the keys of the messages it sends until the owner takes
    /// them.
    front: [AtomicU64; 2],
}

/// A propagation split in two halves, each behind a lock: whichever thread
/// holds a half steps it (see [`drive`]).
struct Halves<'a> {
    half: [Mutex<Propagation<'a>>; 2],
    mail: Mail,
    /// Set when both halves have settled.
    done: AtomicBool,
}

/// Holds half `i`, unless another thread does.
fn try_hold<'h, 'a>(
    halves: &'h Halves<'a>,
    i: usize,
) -> Option<std::sync::MutexGuard<'h, Propagation<'a>>> {
    match halves.half[i].try_lock() {
        Ok(g) => Some(g),
        Err(std::sync::TryLockError::Poisoned(e)) => Some(e.into_inner()),
        Err(std::sync::TryLockError::WouldBlock) => None,
    }
}

/// One thread's share of a split propagation: it steps whichever half it
/// can hold and is not ahead (the one it stepped last first, to keep its
/// caches), until both halves have settled. With one thread it alternates
/// between the halves, keeping them within [`PACE`] of each other; with
/// two each mostly keeps one half; a thread that finds the half behind held
/// by the other waits for it, spinning shortly, then sleeping: on a loaded
/// machine the thread holding it needs the core more.
fn drive(halves: &Halves<'_>, first: usize, control: &Control<'_>) -> Result<(), MeshSolveError> {
    let mail = &halves.mail;
    let mut batch = Vec::new();
    let mut last = first;
    let mut waiting: Option<std::time::Instant> = None;
    loop {
        if halves.done.load(AtomicOrdering::Acquire) || mail.stop.load(AtomicOrdering::Relaxed) {
            return Ok(());
        }
        if control.is_cancelled() {
            mail.stop.store(true, AtomicOrdering::Relaxed);
            return Err(MeshSolveError::Cancelled);
        }
        let mut stepped = false;
        for i in [last, 1 - last] {
            let Some(mut p) = try_hold(halves, i) else {
                continue;
            };
            match p.work(control, mail, &mut batch) {
                Ok(0) => {}
                Ok(_) => {
                    last = i;
                    stepped = true;
                    break;
                }
                Err(e) => {
                    mail.stop.store(true, AtomicOrdering::Relaxed);
                    return Err(e);
                }
            }
        }
        if stepped {
            waiting = None;
            continue;
        }
        // Nothing to step here: both halves settled (holding both, with
        // their messages taken, nothing can be pending), or the half behind
        // is held by the other thread.
        if let (Some(mut p0), Some(mut p1)) = (try_hold(halves, 0), try_hold(halves, 1)) {
            p0.receive(mail, &mut batch);
            p1.receive(mail, &mut batch);
            let (f0, f1) = (p0.publish(mail), p1.publish(mail));
            if !f0.is_finite() && !f1.is_finite() {
                halves.done.store(true, AtomicOrdering::Release);
                return Ok(());
            }
            continue;
        }
        let since = *waiting.get_or_insert_with(std::time::Instant::now);
        if since.elapsed() < SPIN_WAIT {
            std::thread::yield_now();
        } else {
            std::thread::sleep(IDLE_SLEEP);
        }
    }
}

/// How a propagation is split in two halves: by a plane through the first
/// source, so that the front runs through both halves at once, among the
/// 13 directions of the `{-1, 0, 1}³` lattice the one under which the
/// halves kept in step take the least time. Each face weighs its distance
/// `d` from the sources along the edge graph (the rays crossing an edge
/// are split by the vertices between it and the source); the time is the
/// sum over [`BANDS`] bands of `d` of the larger half's weight. Faces go
/// by their centroid, vertices by their position. `None` when the
/// estimated gain (the total weight over that time) is below
/// [`MIN_SPLIT_GAIN`], or the sources reach nothing.
///
/// Estimates and gains measured on two cores: the sliver sphere 1.74-1.98
/// (1.6-1.7x less time), the Stanford dragon and its decimations to 11k,
/// 21k and 51k vertices 1.27-1.29 (0.9-1.1x when split). Euclidean
/// distances from the source estimated 1.5 on the dragons: its curled
/// parts are far along the surface from what is near in space.
fn split(mesh: &TriMesh, sources: &[SurfacePoint], control: &Control<'_>) -> Option<Owners> {
    let origin = sources.first()?.position(mesh);
    let mut normals = Vec::with_capacity(13);
    for a in -1i32..=1 {
        for b in -1i32..=1 {
            for c in -1i32..=1 {
                // One of each opposite pair: the first non-zero is positive.
                let first = [a, b, c].into_iter().find(|&x| x != 0);
                if first == Some(1) {
                    normals.push([a, b, c].map(f64::from));
                }
            }
        }
    }
    let faces = mesh.faces();
    let offsets: Vec<[f64; 3]> = faces
        .iter()
        .map(|f| {
            let p = f.map(|v| mesh.position(v));
            [0, 1, 2].map(|c| (p[0][c] + p[1][c] + p[2][c]) / 3.0 - origin[c])
        })
        .collect();
    let side = |q: [f64; 3], n: [f64; 3]| u8::from(q[0] * n[0] + q[1] * n[1] + q[2] * n[2] > 0.0);
    // A face's work grows with its distance from the source (the rays
    // crossing an edge are split by the vertices between it and the
    // source): weigh faces by their distance. The halves keep pace band
    // by band of distance, so the time is about the sum over the bands
    // of the larger half's work.
    // The fronts' distances from the sources, approximated along edges
    // (Euclidean distances from the source misjudge a curled-up shape).
    let graph =
        super::dijkstra::dijkstra_distance(mesh, sources, None, f64::INFINITY, control).ok()?;
    let dist: Vec<f64> = faces
        .iter()
        .map(|f| {
            let d = f.map(|v| graph.distance[v as usize]);
            let mean = (d[0] + d[1] + d[2]) / 3.0;
            if mean.is_finite() {
                mean
            } else {
                0.0
            }
        })
        .collect();
    let far = dist.iter().copied().fold(0.0f64, f64::max);
    if !(far.is_finite() && far > 0.0) {
        return None;
    }
    let band: Vec<u8> = dist
        .iter()
        .map(|&d| ((d / far * BANDS as f64) as usize).min(BANDS - 1) as u8)
        .collect();
    let total: f64 = dist.iter().sum();
    let (best, time) = normals
        .iter()
        .map(|&n| {
            let mut work = [[0.0f64; BANDS]; 2];
            for ((q, &d), &b) in offsets.iter().zip(&dist).zip(&band) {
                work[side(*q, n) as usize][b as usize] += d;
            }
            let time: f64 = (0..BANDS).map(|b| work[0][b].max(work[1][b])).sum();
            (n, time)
        })
        .min_by(|a, b| a.1.total_cmp(&b.1))?;
    if total < MIN_SPLIT_GAIN * time {
        return None;
    }
    let mut count = [0u32; 2];
    Some(Owners {
        face: offsets
            .iter()
            .map(|&q| {
                let o = side(q, best);
                let local = count[o as usize];
                count[o as usize] += 1;
                (u32::from(o) << 31) | local
            })
            .collect(),
        faces: count,
        vertex: (0..mesh.num_vertices() as u32)
            .map(|v| side(sub(mesh.position(v), origin), best))
            .collect(),
    })
}

/// A pseudo-source whose distance was lowered to `key`.
#[derive(Debug, Clone, Copy)]
struct VertexEvent {
    key: f64,
    v: u32,
}
impl PartialEq for VertexEvent {
    fn eq(&self, other: &Self) -> bool {
        self.key.total_cmp(&other.key) == Ordering::Equal
    }
}
impl Eq for VertexEvent {}
impl PartialOrd for VertexEvent {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for VertexEvent {
    fn cmp(&self, other: &Self) -> Ordering {
        other.key.total_cmp(&self.key)
    }
}

/// Counters of one propagation (for benchmarks and tests).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ExactStats {
    /// Windows pushed on the heap.
    pub windows_created: u64,
    /// Windows popped and propagated (after trimming).
    pub windows_propagated: u64,
    /// Pseudo-source emissions (vertex sources included).
    pub pseudo_sources: u64,
    /// Of those, the emissions of saddle vertices restricted to the sector
    /// a shortest path can leave them in (see `shadow_sector`).
    pub sector_emissions: u64,
    /// Largest number of pending windows.
    pub max_queue: usize,
    /// Whether the final edge check had to repair a violation.
    pub repaired: bool,
}

/// Exact geodesic distance from `sources` to every vertex of `mesh`, with
/// the index of the nearest source per vertex.
///
/// Vertices farther than `max_distance` (use `f64::INFINITY` for no limit)
/// or in components without a source get `+inf` and label `-1`. See the
/// module documentation for the algorithm.
///
/// # Examples
/// ```
/// use geodex::numerics::mesh::{exact::exact_distance, SurfacePoint, Topology, TriMesh};
/// use geodex::numerics::Control;
/// let m = TriMesh::new(
///     vec![[0., 0., 0.], [1., 0., 0.], [1., 1., 0.], [0., 1., 0.]],
///     vec![[0, 1, 2], [0, 2, 3]],
/// )?;
/// let t = Topology::new(&m);
/// let d = exact_distance(&m, &t, &[SurfacePoint::Vertex(1)], f64::INFINITY, &Control::new())?;
/// assert!((d.distance[3] - 2f64.sqrt()).abs() < 1e-12);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn exact_distance(
    mesh: &TriMesh,
    topo: &Topology,
    sources: &[SurfacePoint],
    max_distance: f64,
    control: &Control<'_>,
) -> Result<MeshDistance, MeshSolveError> {
    exact_distance_with_stats(mesh, topo, sources, max_distance, control).map(|(d, _)| d)
}

/// [`exact_distance`] and the propagation's counters: on two halves (see
/// [`exact_distance_threads`]) when the mesh has [`MIN_SPLIT_VERTICES`] or
/// more, the caller's pool two threads or more and the split pays, else on
/// one worker.
pub fn exact_distance_with_stats(
    mesh: &TriMesh,
    topo: &Topology,
    sources: &[SurfacePoint],
    max_distance: f64,
    control: &Control<'_>,
) -> Result<(MeshDistance, ExactStats), MeshSolveError> {
    let threads = if mesh.num_vertices() >= MIN_SPLIT_VERTICES {
        rayon::current_num_threads().min(2)
    } else {
        1
    };
    exact_distance_threads(mesh, topo, sources, max_distance, threads, control)
}

/// [`exact_distance_with_stats`] on `threads` workers: 1 never splits;
/// from 2 the propagation is split in two halves when a plane through the
/// first source shares the work well enough (see "Two halves" in the
/// module documentation), stepped by up to two threads of the caller's
/// pool (one steps both in turn when no other is free). The distances
/// agree with one worker's to rounding. Callers that already run many
/// solves in parallel (a distance matrix's rows) ask for 1.
pub fn exact_distance_threads(
    mesh: &TriMesh,
    topo: &Topology,
    sources: &[SurfacePoint],
    max_distance: f64,
    threads: usize,
    control: &Control<'_>,
) -> Result<(MeshDistance, ExactStats), MeshSolveError> {
    check_inputs(mesh, topo, sources)?;
    if max_distance.is_nan() || max_distance < 0.0 {
        return Err(MeshSolveError::InvalidOption {
            option: "max_distance",
            reason: format!("must be >= 0, got {max_distance}"),
        });
    }
    let geo = if threads >= 2 {
        // The split's estimate (a Dijkstra pass) beside the frames.
        let (mut geo, owner) = rayon::join(
            || Geometry::new(mesh, topo),
            || split(mesh, sources, &control.cancel_only()),
        );
        geo.owner = owner;
        geo
    } else {
        Geometry::new(mesh, topo)
    };
    if geo.owner.is_none() {
        let mut p = Propagation::new(&geo, max_distance, 0);
        p.seed(sources);
        p.run(control)?;
        return Ok(p.finish());
    }
    let mut p0 = Propagation::new(&geo, max_distance, 0);
    let mut p1 = Propagation::new(&geo, max_distance, 1);
    p0.seed(sources);
    p1.seed(sources);
    let halves = Halves {
        half: [Mutex::new(p0), Mutex::new(p1)],
        mail: Mail::default(),
        done: AtomicBool::new(false),
    };
    for (i, h) in halves.half.iter().enumerate() {
        let mut p = h.lock().unwrap_or_else(|e| e.into_inner());
        p.publish(&halves.mail);
        debug_assert_eq!(p.me as usize, i);
    }
    // The second thread joins if the pool has one free (now or later); the
    // first does everything otherwise.
    let (r0, r1) = rayon::join(|| drive(&halves, 0, control), || drive(&halves, 1, control));
    r0?;
    r1?;
    let [h0, h1] = halves.half;
    let mut p0 = h0.into_inner().unwrap_or_else(|e| e.into_inner());
    let p1 = h1.into_inner().unwrap_or_else(|e| e.into_inner());
    // Every lowered distance was sent to its vertex's owner: the owner's
    // values are the smallest.
    let owners = geo.owner.as_ref().map(|o| &o.vertex);
    if let Some(owner) = owners {
        for (v, &o) in owner.iter().enumerate() {
            if o == 1 {
                p0.dist[v] = p1.dist[v];
                p0.label[v] = p1.label[v];
            }
        }
    }
    let s1 = p1.stats;
    let st = &mut p0.stats;
    st.windows_created += s1.windows_created;
    st.windows_propagated += s1.windows_propagated;
    st.pseudo_sources += s1.pseudo_sources;
    st.sector_emissions += s1.sector_emissions;
    st.max_queue = st.max_queue.max(s1.max_queue);
    Ok(p0.finish())
}

/// The checks shared by [`exact_distance_with_stats`] and [`exact_paths`]:
/// at least one source, every source on the mesh, and a topology built
/// from this mesh.
fn check_inputs(
    mesh: &TriMesh,
    topo: &Topology,
    sources: &[SurfacePoint],
) -> Result<(), MeshSolveError> {
    if sources.is_empty() {
        return Err(MeshSolveError::NoSources);
    }
    for (index, s) in sources.iter().enumerate() {
        s.validate(mesh)
            .map_err(|reason| MeshSolveError::InvalidSource { index, reason })?;
    }
    if 3 * mesh.num_faces() >= REVERSED as usize {
        return Err(MeshSolveError::InvalidOption {
            option: "mesh",
            reason: format!(
                "{} faces are more than the exact method indexes ({}); use the method \
                 fast_marching or heat",
                mesh.num_faces(),
                REVERSED / 3
            ),
        });
    }
    if topo.opposite.len() != 3 * mesh.num_faces() || topo.component.len() != mesh.num_vertices() {
        return Err(MeshSolveError::InvalidOption {
            option: "topology",
            reason: "was not built from this mesh".into(),
        });
    }
    Ok(())
}

/// Most steps (window and vertex pops) of one propagation before it is
/// declared unsettled: 128 times the `O(n^1.5)` growth measured on
/// icospheres (about `0.5·√n` windows per vertex: 197 at 164k vertices),
/// plus a floor. No real mesh comes near it (at 164k vertices it allows
/// ~10^10 steps, hours of work); it makes the propagation terminate on
/// every input, deadline or not.
fn step_budget(vertices: usize, faces: usize) -> usize {
    let n = vertices as f64;
    let steps = 128.0 * (vertices + faces) as f64 * (1.0 + n.sqrt()) + 1e6;
    if steps >= usize::MAX as f64 {
        usize::MAX
    } else {
        steps as usize
    }
}

/// Frame of edge `k` of a face: its length `l`, and the third vertex at
/// `(cx, cy)`, `cy >= 0`, with what a window crossing the edge needs to
/// make its children, in one cache line per half-edge: a window's
/// propagation reads one record instead of six scattered arrays (1-2 %
/// faster on the sliver sphere, within the noise, for 32 more bytes per
/// half-edge than the arrays; the half-edges across are what two workers
/// route windows by).
#[derive(Debug, Clone, Copy)]
#[repr(C, align(64))]
struct Frame {
    l: f64,
    cx: f64,
    cy: f64,
    /// Length of edge `k + 1` (`b → c`).
    lbc: f64,
    /// Length of edge `k + 2` (`c → a`).
    lca: f64,
    /// `1 / lbc` and `1 / lca` (0 for a zero length), precomputed.
    inv_lbc: f64,
    inv_lca: f64,
    /// Where windows leaving through edges `k + 1` and `k + 2` go: the
    /// half-edge across, in the face beyond, with [`REVERSED`] set when it
    /// runs the other way (the usual case), or [`NONE`] when no window
    /// goes there (a boundary, non-manifold or degenerate neighbour).
    across: [u32; 2],
}

/// The bit of [`Frame::across`] saying that the half-edge across runs the
/// other way.
const REVERSED: u32 = 1 << 31;

/// How a vertex (or a target point) got its distance, for backtracking a
/// path (kept only by [`exact_paths`]).
#[derive(Debug, Clone, Copy, PartialEq)]
enum Parent {
    /// Not reached.
    None,
    /// A source vertex.
    Root,
    /// A straight segment (along an edge, or inside one face) to this
    /// vertex, then that vertex's own path.
    Vertex(u32),
    /// A straight segment inside the source's face to the point of source
    /// `label`.
    SourcePoint(u32),
    /// A straight segment to the point at `x` on half-edge `h`, then the
    /// unfolded straight ray from there towards the source image `(sx, sy)`
    /// (in the frame of `h`, `sy <= 0`) of a (pseudo-)source at distance
    /// `sigma`.
    Ray {
        h: u32,
        x: f64,
        sx: f64,
        sy: f64,
        sigma: f64,
    },
}

/// A point inside a face whose distance and path are wanted: updated like
/// a vertex by every window crossing an edge of its face, but never
/// propagated further.
#[derive(Debug, Clone, Copy)]
struct Target {
    face: u32,
    bary: [f64; 3],
    dist: f64,
    label: u32,
    parent: Parent,
}

/// What every propagation over one mesh shares, read only: the frames,
/// the pseudo-sources, the fans of the saddles, and (for a propagation
/// split between two workers) who owns which face and vertex.
struct Geometry<'a> {
    mesh: &'a TriMesh,
    topo: &'a Topology,
    /// Per half-edge `3 f + k`, its [`Frame`] (length, the face's third
    /// vertex, the lengths of the two other edges and where windows
    /// leaving through them go), computed once instead of a division and a
    /// square root per window.
    frames: Vec<Frame>,
    degenerate: Vec<bool>,
    pseudo: Vec<bool>,
    /// Per corner `3 f + j` (the corner of face `f` at its vertex `j`), the
    /// corner's angle.
    corner_angle: Vec<f64>,
    /// Per corner, the angular position around its vertex where the corner
    /// starts (at the edge towards vertex `j + 1`; counterclockwise, the
    /// faces' orientation), for vertices whose fan is walked once around
    /// (see [`fans`]); NaN elsewhere.
    fan_start: Vec<f64>,
    /// Per vertex, its total angle `Θ` when its fan was walked (saddle
    /// interior vertices only), else NaN: the vertices whose emission is
    /// restricted to the shadow sector.
    fan_total: Vec<f64>,
    /// Which worker owns each face and vertex when the propagation is split
    /// (see [`split`]); `None` for one worker.
    owner: Option<Owners>,
    /// The mean edge length.
    mean_edge: f64,
}

/// The halves of a mesh split between two workers: a window belongs to
/// the owner of the face it enters, a vertex's distance to its owner.
struct Owners {
    /// Per face, its owner (bit 31) and its index among its owner's faces
    /// (the low bits): each half keeps the latest windows of its own
    /// faces' half-edges only.
    face: Vec<u32>,
    /// How many faces each half owns.
    faces: [u32; 2],
    vertex: Vec<u8>,
}

struct Propagation<'a> {
    geo: &'a Geometry<'a>,
    mesh: &'a TriMesh,
    topo: &'a Topology,
    max_distance: f64,
    /// This worker's index (0 with one worker).
    me: u8,
    /// While seeding, every worker makes the sources' windows and
    /// distances itself, and keeps only its own.
    seeding: bool,
    /// Messages for the other worker, sent in batches.
    out: Vec<Message>,
    /// Vertices of the other worker whose distance this one lowered while
    /// processing the current window or vertex.
    dirty: Vec<u32>,
    dist: Vec<f64>,
    label: Vec<u32>,
    emitted: Vec<f64>,
    /// The straight segment by which each vertex got its distance, when it
    /// did (see [`Arrival`]): a saddle pseudo-source emits only into the
    /// directions a shortest path can continue in.
    arrival: Vec<Arrival>,
    /// Whether saddles emit into their shadow sector only (always, but for
    /// the test that compares with emitting everywhere).
    sectors: bool,
    /// For each vertex, the half-edge and crossing of the straight path that
    /// set its distance (`NONE` when set otherwise).
    via: Vec<(u32, f64)>,
    windows: RadixQueue,
    vertices: BinaryHeap<VertexEvent>,
    /// The latest [`RECENT`] windows propagated across each half-edge
    /// (newest first), the only ones a new window is compared with: on
    /// icospheres comparing with every earlier window (as before) removed
    /// no more than 0.1 % more windows, for `O(windows per edge)` time per
    /// comparison and `O(windows)` memory.
    recent: Vec<[Field; RECENT]>,
    reached: usize,
    reachable: usize,
    /// Steps taken by [`Propagation::work`], over all its calls.
    pops: usize,
    /// The smallest key of the messages in `out`.
    out_min: f64,
    stats: ExactStats,
    /// Per vertex, how it got its distance (empty unless paths are wanted).
    parents: Vec<Parent>,
    targets: Vec<Target>,
    /// Face → indices into `targets`.
    face_targets: HashMap<u32, Vec<u32>>,
}

impl<'a> Geometry<'a> {
    fn new(mesh: &'a TriMesh, topo: &'a Topology) -> Self {
        let nf = mesh.num_faces();
        let nv = mesh.num_vertices();
        let faces = mesh.faces();
        let mut len = vec![0.0; 3 * nf];
        let mut degenerate = vec![false; nf];
        let mut angle = vec![0.0f64; nv];
        let mut corner_angle = vec![0.0f64; 3 * nf];
        let mut pseudo = vec![false; nv];
        for (f, face) in faces.iter().enumerate() {
            let p = face.map(|v| mesh.position(v));
            let l = [0, 1, 2].map(|k| norm(sub(p[(k + 1) % 3], p[k])));
            len[3 * f..3 * f + 3].copy_from_slice(&l);
            let lmax = l[0].max(l[1]).max(l[2]);
            let twice_area = norm(super::cross(sub(p[1], p[0]), sub(p[2], p[0])));
            // Smallest height = 2 area / longest edge.
            // Written so that NaN counts as degenerate.
            let sound = lmax > 0.0 && twice_area > DEGENERATE * lmax * lmax;
            if !sound {
                degenerate[f] = true;
                for &v in face {
                    pseudo[v as usize] = true;
                }
                continue;
            }
            // Angle at vertex k, between edges k (k → k+1) and k+2 (k+2 → k).
            for k in 0..3 {
                let (a, b, c) = (l[k], l[(k + 2) % 3], l[(k + 1) % 3]);
                let cos = ((a * a + b * b - c * c) / (2.0 * a * b)).clamp(-1.0, 1.0);
                let theta = cos.acos();
                corner_angle[3 * f + k] = theta;
                angle[face[k] as usize] += theta;
            }
        }
        let two_pi = 2.0 * std::f64::consts::PI;
        for (h, &o) in topo.opposite.iter().enumerate() {
            if o == NONE {
                let f = h / 3;
                let k = h % 3;
                pseudo[faces[f][k] as usize] = true;
                pseudo[faces[f][(k + 1) % 3] as usize] = true;
            }
        }
        // Saddles that are pseudo-sources for their angle alone; `fans`
        // checks that their faces close up once around them.
        let mut saddle = vec![false; nv];
        let mut scratch = (Vec::new(), Vec::new());
        for v in 0..nv {
            if angle[v] > two_pi * (1.0 + 1e-9) {
                saddle[v] = !pseudo[v];
                pseudo[v] = true;
            } else if !single_fan(faces, topo, v as u32, &mut scratch) {
                pseudo[v] = true;
            }
        }
        let (fan_start, fan_total) = fans(faces, topo, &corner_angle, &saddle);
        let inv = |l: f64| if l > 0.0 { 1.0 / l } else { 0.0 };
        // Where a window leaving face f through its edge k goes.
        let across = |f: usize, k: usize| {
            let h = topo.opposite[3 * f + k];
            if h == NONE || degenerate[h as usize / 3] {
                return NONE;
            }
            let reversed = faces[h as usize / 3][h as usize % 3] == faces[f][(k + 1) % 3];
            if reversed {
                h | REVERSED
            } else {
                h
            }
        };
        let frames = (0..3 * nf)
            .map(|h| {
                let (f, k) = (h / 3, h % 3);
                let (k1, k2) = ((k + 1) % 3, (k + 2) % 3);
                let l = len[h];
                let lbc = len[3 * f + k1];
                let lca = len[3 * f + k2];
                let cx = (lca * lca + l * l - lbc * lbc) / (2.0 * l);
                let cy = (lca * lca - cx * cx).max(0.0).sqrt();
                Frame {
                    l,
                    cx,
                    cy,
                    lbc,
                    lca,
                    inv_lbc: inv(lbc),
                    inv_lca: inv(lca),
                    across: [across(f, k1), across(f, k2)],
                }
            })
            .collect();
        Geometry {
            mesh,
            topo,
            frames,
            degenerate,
            pseudo,
            corner_angle,
            fan_start,
            fan_total,
            owner: None,
            mean_edge: len.iter().sum::<f64>() / len.len().max(1) as f64,
        }
    }
}

impl<'a> Propagation<'a> {
    fn new(geo: &'a Geometry<'a>, max_distance: f64, me: u8) -> Self {
        let nv = geo.mesh.num_vertices();
        let nf = geo.mesh.num_faces();
        Self {
            geo,
            mesh: geo.mesh,
            topo: geo.topo,
            max_distance,
            me,
            seeding: false,
            out: Vec::new(),
            dirty: Vec::new(),
            dist: vec![f64::INFINITY; nv],
            label: vec![NONE; nv],
            emitted: vec![f64::INFINITY; nv],
            via: vec![(NONE, 0.0); nv],
            arrival: vec![Arrival::NONE; nv],
            sectors: true,
            windows: RadixQueue::new(),
            vertices: BinaryHeap::new(),
            recent: vec![
                [Field::EMPTY; RECENT];
                3 * geo
                    .owner
                    .as_ref()
                    .map_or(nf, |o| o.faces[me as usize] as usize)
            ],
            reached: 0,
            reachable: 0,
            pops: 0,
            out_min: f64::INFINITY,
            stats: ExactStats::default(),
            parents: Vec::new(),
            targets: Vec::new(),
            face_targets: HashMap::new(),
        }
    }

    #[inline(always)]
    fn frame(&self, f: usize, k: usize) -> Frame {
        self.geo.frames[3 * f + k]
    }

    /// Length of half-edge `h`.
    #[inline]
    fn len(&self, h: usize) -> f64 {
        self.geo.frames[h].l
    }

    /// Whether this worker propagates the windows entering face `f`.
    #[inline(always)]
    fn owns_face(&self, f: usize) -> bool {
        match &self.geo.owner {
            None => true,
            Some(o) => (o.face[f] >> 31) as u8 == self.me,
        }
    }

    /// Where the latest windows of half-edge `h`, of one of this worker's
    /// faces, are kept in [`Propagation::recent`].
    #[inline(always)]
    fn recent_slot(&self, h: usize) -> usize {
        match &self.geo.owner {
            None => h,
            Some(o) => 3 * (o.face[h / 3] & !(1 << 31)) as usize + h % 3,
        }
    }

    /// Whether this worker keeps vertex `v`'s distance (and emits it).
    #[inline(always)]
    fn owns_vertex(&self, v: usize) -> bool {
        match &self.geo.owner {
            None => true,
            Some(o) => o.vertex[v] == self.me,
        }
    }

    /// Where a window leaving face `f` through its edge `k` goes (see
    /// [`Frame::across`]).
    #[inline]
    fn across(&self, f: usize, k: usize) -> u32 {
        self.geo.frames[3 * f + (k + 2) % 3].across[0]
    }

    #[inline]
    fn vertex(&self, f: usize, k: usize) -> u32 {
        self.mesh.faces()[f][k % 3]
    }

    /// Lowers `U(v)` to `d` (the length of a real path) if that is shorter.
    #[inline(always)]
    fn update(&mut self, v: u32, d: f64, label: u32) -> bool {
        let vi = v as usize;
        if d < self.dist[vi] {
            self.via[vi] = (NONE, 0.0);
            self.arrival[vi] = Arrival::NONE;
            if self.dist[vi] == f64::INFINITY && self.owns_vertex(vi) {
                self.reached += 1;
            }
            self.dist[vi] = d;
            self.label[vi] = label;
            if self.owns_vertex(vi) {
                if self.geo.pseudo[vi] && d <= self.max_distance {
                    self.vertices.push(VertexEvent { key: d, v });
                }
            } else if !self.seeding {
                self.dirty.push(v);
            }
            true
        } else {
            false
        }
    }

    fn seed(&mut self, sources: &[SurfacePoint]) {
        self.seeding = true;
        let mut has_source = vec![false; self.topo.components];
        for (i, s) in sources.iter().enumerate() {
            let label = i as u32;
            match *s {
                SurfacePoint::Vertex(v) => self.seed_vertex(v, label),
                SurfacePoint::Face { face, bary } => {
                    // Clean the coordinates: clamp tiny negatives, renormalise.
                    let mut b = bary.map(|x| x.max(0.0));
                    let sum: f64 = b.iter().sum();
                    b = b.map(|x| x / sum);
                    if let Some(k) = (0..3).find(|&k| b[k] >= 1.0 - 1e-12) {
                        self.seed_vertex(self.vertex(face as usize, k), label);
                    } else {
                        self.seed_face_point(face as usize, b, label, true);
                    }
                }
            }
            let v = match *s {
                SurfacePoint::Vertex(v) => v,
                SurfacePoint::Face { face, .. } => self.vertex(face as usize, 0),
            };
            has_source[self.topo.component[v as usize] as usize] = true;
        }
        self.reachable = self
            .topo
            .component
            .iter()
            .filter(|&&c| has_source[c as usize])
            .count()
            .max(1);
        self.seeding = false;
        self.dirty.clear();
    }

    fn seed_vertex(&mut self, v: u32, label: u32) {
        if self.dist[v as usize] > 0.0 && self.update(v, 0.0, label) {
            self.set_parent(v, Parent::Root);
            // A source emits like a pseudo-source (`update` queued it if
            // it is one).
            if !self.geo.pseudo[v as usize] && self.owns_vertex(v as usize) {
                self.vertices.push(VertexEvent { key: 0.0, v });
            }
        }
    }

    /// Records how `v` got its distance (when paths are wanted).
    #[inline]
    fn set_parent(&mut self, v: u32, p: Parent) {
        if let Some(slot) = self.parents.get_mut(v as usize) {
            *slot = p;
        }
    }

    /// Lowers the distance of the targets in face `f` through `point`
    /// (a function of the target's barycentric coordinates returning the
    /// path length and its parent).
    #[inline]
    fn update_targets(&mut self, f: usize, label: u32, point: impl Fn([f64; 3]) -> (f64, Parent)) {
        let Some(list) = self.face_targets.get(&(f as u32)) else {
            return;
        };
        for &t in list {
            let t = &mut self.targets[t as usize];
            let (d, parent) = point(t.bary);
            if d < t.dist {
                t.dist = d;
                t.label = label;
                t.parent = parent;
            }
        }
    }

    /// A source at barycentric `b` of face `f`: windows across the face's
    /// edges; when the point lies on an edge, also from the neighbouring face.
    fn seed_face_point(&mut self, f: usize, b: [f64; 3], label: u32, spread: bool) {
        let mesh = self.mesh;
        let face = mesh.faces()[f];
        let pos = {
            let mut p = [0.0; 3];
            for k in 0..3 {
                let q = mesh.position(face[k]);
                for c in 0..3 {
                    p[c] += b[k] * q[c];
                }
            }
            p
        };
        for &v in &face {
            let d = norm(sub(mesh.position(v), pos));
            if self.update(v, d, label) {
                self.set_parent(v, Parent::SourcePoint(label));
            }
        }
        if !self.face_targets.is_empty() {
            let corners = face.map(|v| mesh.position(v));
            self.update_targets(f, label, |t| {
                let q = barycentric_point(&corners, t);
                (norm(sub(q, pos)), Parent::SourcePoint(label))
            });
        }
        if self.geo.degenerate[f] {
            return;
        }
        for k in 0..3 {
            let fr = self.frame(f, k);
            // Barycentric coordinates are affine: the same in the edge frame.
            let (bb, bc) = (b[(k + 1) % 3], b[(k + 2) % 3]);
            let px = bb * fr.l + bc * fr.cx;
            let py = bc * fr.cy;
            if py > DEGENERATE * fr.l {
                let ends = (
                    self.dist[face[k] as usize],
                    self.dist[face[(k + 1) % 3] as usize],
                );
                let across = self.across(f, k);
                self.push_child(across, fr.l, ends, 0.0, fr.l, px, py, 0.0, label);
            } else if spread {
                // On edge k: the neighbouring face sees the point too.
                let h = self.topo.opposite[3 * f + k];
                if h == NONE {
                    continue;
                }
                let g = h as usize / 3;
                let kg = h as usize % 3;
                let t = (px / fr.l).clamp(0.0, 1.0);
                let mut bg = [0.0; 3];
                if self.vertex(g, kg) == face[k] {
                    bg[kg] = 1.0 - t;
                    bg[(kg + 1) % 3] = t;
                } else {
                    bg[kg] = t;
                    bg[(kg + 1) % 3] = 1.0 - t;
                }
                self.seed_face_point(g, bg, label, false);
            }
        }
    }

    /// Vertex `v` (a pseudo-source at its final distance) sends a window
    /// across the opposite edge of each of its faces and relaxes its edges.
    fn emit(&mut self, v: u32) {
        let sigma = self.dist[v as usize];
        let label = self.label[v as usize];
        self.stats.pseudo_sources += 1;
        let topo = self.topo;
        let pv = self.mesh.position(v);
        let sector = self.shadow_sector(v);
        if sector.is_some() {
            self.stats.sector_emissions += 1;
        }
        for &f in topo.faces_of(v) {
            let f = f as usize;
            let face = self.mesh.faces()[f];
            let Some(j) = (0..3).find(|&j| face[j] == v) else {
                continue;
            };
            for (i, &u) in face.iter().enumerate() {
                if u != v {
                    let d = sigma + norm(sub(self.mesh.position(u), pv));
                    if self.update(u, d, label) {
                        self.set_parent(u, Parent::Vertex(v));
                        // Straight along the edge from v: u is the end of
                        // half-edge j (v → u) or the origin of half-edge i
                        // (u → v).
                        self.arrival[u as usize] = if i == (j + 1) % 3 {
                            Arrival::at(3 * f + j, ArrivalAt::End, 0.0, 0.0)
                        } else {
                            Arrival::at(3 * f + i, ArrivalAt::Origin, self.len(3 * f + i), 0.0)
                        };
                    }
                }
            }
            if !self.face_targets.is_empty() {
                let corners = face.map(|x| self.mesh.position(x));
                self.update_targets(f, label, |t| {
                    let q = barycentric_point(&corners, t);
                    (sigma + norm(sub(q, pv)), Parent::Vertex(v))
                });
            }
            if self.geo.degenerate[f] {
                continue;
            }
            let k = (j + 1) % 3;
            let fr = self.frame(f, k);
            let across = self.across(f, k);
            let ends = (
                self.dist[face[k] as usize],
                self.dist[face[(k + 1) % 3] as usize],
            );
            let Some((lo, hi, total)) = sector else {
                self.push_child(across, fr.l, ends, 0.0, fr.l, fr.cx, fr.cy, sigma, label);
                continue;
            };
            // The parts of the corner [s, s + θ] inside the sector (or one
            // turn before or after it), as rays from v across edge k.
            let (start, theta) = (
                self.geo.fan_start[3 * f + j],
                self.geo.corner_angle[3 * f + j],
            );
            for turn in [-total, 0.0, total] {
                let t0 = (lo + turn - start).max(0.0);
                let t1 = (hi + turn - start).min(theta);
                if t1 > t0 {
                    let x0 = corner_ray_hit(fr, t0, theta);
                    let x1 = corner_ray_hit(fr, t1, theta);
                    if x1 > x0 {
                        self.push_child(across, fr.l, ends, x0, x1, fr.cx, fr.cy, sigma, label);
                    }
                }
            }
        }
    }

    /// The directions around `v` (positions in its fan, see
    /// [`Propagation::fan_start`]) in which a shortest path through `v` can
    /// leave it, `[lo, hi]` with the fan's total angle, or `None` for
    /// every direction.
    ///
    /// A shortest path crosses a vertex only where both angles between its
    /// incoming and outgoing segments are at least `π` (Mitchell, Mount and
    /// Papadimitriou, 1987): elsewhere cutting the corner shortens it. With
    /// the incoming segment's back-direction at position `p` in a fan of
    /// total angle `Θ > 2π`, the outgoing one lies in `[p + π, p + Θ − π]`,
    /// a sector of width `Θ − 2π`. Any shortest path to `v` gives the same
    /// answer: two of them arriving from different directions would make a
    /// continuation beyond the one's sector a shortenable path as long as
    /// the other, so no shortest path goes there. The sector is widened by
    /// [`SECTOR_SLACK`] on each side against rounding; vertices reached
    /// otherwise (sources, bent paths, boundary and non-manifold vertices)
    /// emit in every direction.
    fn shadow_sector(&self, v: u32) -> Option<(f64, f64, f64)> {
        let total = self.geo.fan_total[v as usize];
        let a = self.arrival[v as usize];
        if !self.sectors || total.is_nan() || a.h == NONE {
            return None;
        }
        let h = a.h as usize;
        let (f, k) = (h / 3, h % 3);
        let Frame { l, cx, cy, .. } = self.geo.frames[h];
        let (x, y) = (a.x, a.y);
        let p = match a.at {
            ArrivalAt::Origin => {
                // Clockwise from the corner's first edge a → b.
                self.geo.fan_start[h] - (-y).atan2(x)
            }
            ArrivalAt::End => {
                // Counterclockwise past the corner's last edge b → a.
                let c = 3 * f + (k + 1) % 3;
                self.geo.fan_start[c] + self.geo.corner_angle[c] + (-y).atan2(l - x)
            }
            ArrivalAt::Third => {
                // Inside the corner, from its first edge c → a.
                let c = 3 * f + (k + 2) % 3;
                let (bx, by) = (x - cx, y - cy);
                self.geo.fan_start[c] + (cy * bx - cx * by).atan2(-cx * bx - cy * by)
            }
        };
        if !p.is_finite() {
            return None;
        }
        let p = p.rem_euclid(total);
        let pi = std::f64::consts::PI;
        Some((p + pi - SECTOR_SLACK, p + total - pi + SECTOR_SLACK, total))
    }

    /// A window on edge `k` of face `f` (of length `l`, its ends at
    /// distances `ends`), in that edge's frame (source on the side of `f`,
    /// `sy >= 0`), handed to the face across the edge (`across`, see
    /// [`Frame::across`]).
    #[allow(clippy::too_many_arguments)]
    #[inline]
    fn push_child(
        &mut self,
        across: u32,
        l: f64,
        ends: (f64, f64),
        x0: f64,
        x1: f64,
        sx: f64,
        sy: f64,
        sigma: f64,
        label: u32,
    ) {
        if across == NONE {
            return;
        }
        let h = across & !REVERSED;
        let (mut b0, mut b1, sx, up, uq) = if across & REVERSED != 0 {
            (l - x1, l - x0, l - sx, ends.1, ends.0)
        } else {
            (x0, x1, sx, ends.0, ends.1)
        };
        b0 = b0.max(0.0);
        b1 = b1.min(l);
        let mut w = Window {
            key: 0.0,
            b0,
            b1,
            sx,
            sy: -sy,
            sigma,
            h,
            label,
        };
        if !self.trim(&mut w, l, None, false, (up, uq)) {
            return;
        }
        // The nearest point of the interval to the source image: its foot
        // when inside (no square root), else the nearer end.
        w.key = if w.sx > w.b0 && w.sx < w.b1 {
            sigma + w.sy.abs()
        } else {
            sigma + len2(w.sx.clamp(w.b0, w.b1) - w.sx, w.sy)
        };
        if w.key > self.max_distance {
            return;
        }
        if !self.owns_face(h as usize / 3) {
            // The other worker's face (which makes its own while seeding).
            if !self.seeding {
                self.stats.windows_created += 1;
                self.out_min = self.out_min.min(w.key);
                self.out.push(Message::Window(w));
            }
            return;
        }
        self.stats.windows_created += 1;
        self.windows.push(w);
        self.stats.max_queue = self.stats.max_queue.max(self.windows.len);
    }

    /// Cuts off the parts of `w` (on its half-edge of length `l`) where the
    /// path through one of the edge's vertices is strictly shorter, and with
    /// `recent` also where one of the latest windows propagated across the
    /// edge is (done when the window is popped only: at creation it removed
    /// 0.002 % more windows on icospheres for 7 % of the time). Returns
    /// false when nothing is left.
    ///
    /// `ends`, when known, are `|I − (b0, 0)|` and `|I − (b1, 0)|` (the
    /// window's distances at its ends less `σ`); `(up, uq)` are the
    /// distances of the edge's origin and end.
    #[inline]
    fn trim(
        &self,
        w: &mut Window,
        l: f64,
        ends: Option<(f64, f64)>,
        recent: bool,
        (up, uq): (f64, f64),
    ) -> bool {
        let wide = w.b1 - w.b0 > MIN_WIDTH * l;
        if !wide {
            return false;
        }
        let (sx, sy) = (w.sx, w.sy);
        // e(x) = d_w(x) − σ at the two ends, kept up to date as they move.
        let (mut e0, e1) = match ends {
            Some(e) => e,
            None => (len2(w.b0 - sx, sy), len2(w.b1 - sx, sy)),
        };
        if up < f64::INFINITY {
            let dd = up - w.sigma + TRIM_TOL * (up + l);
            // g(x) = d_w(x) - U(p) - x, non-increasing; dominated where > 0.
            if e1 > w.b1 + dd {
                return false;
            }
            if e0 > w.b0 + dd {
                let den = 2.0 * (dd + sx);
                if den != 0.0 {
                    let x = (sx * sx + sy * sy - dd * dd) / den;
                    if x.is_finite() && x > w.b0 {
                        if x >= w.b1 {
                            return false;
                        }
                        w.b0 = x;
                        e0 = len2(x - sx, sy);
                    }
                }
            }
        }
        if uq < f64::INFINITY {
            let dd = uq - w.sigma + TRIM_TOL * (uq + l);
            // Mirrored: y = l - x.
            if e0 > (l - w.b0) + dd {
                return false;
            }
            if e1 > (l - w.b1) + dd {
                let sxm = l - sx;
                let den = 2.0 * (dd + sxm);
                if den != 0.0 {
                    let y = (sxm * sxm + sy * sy - dd * dd) / den;
                    let x = l - y;
                    if x.is_finite() && x < w.b1 {
                        if x <= w.b0 {
                            return false;
                        }
                        w.b1 = x;
                    }
                }
            }
        }
        let wide = w.b1 - w.b0 > MIN_WIDTH * l;
        if !wide {
            return false;
        }
        // Against the latest windows propagated across this edge in the
        // same direction (see the module documentation).
        if recent {
            for o in self.recent[self.recent_slot(w.h as usize)] {
                if !trim_by_window(w, &o, l) {
                    return false;
                }
            }
        }
        true
    }

    fn propagate(&mut self, mut w: Window) {
        let f = w.h as usize / 3;
        let k = w.h as usize % 3;
        let fr = self.frame(f, k);
        let (a, b, c) = (
            self.vertex(f, k),
            self.vertex(f, k + 1),
            self.vertex(f, k + 2),
        );
        let (sx, sy, sigma, label) = (w.sx, w.sy, w.sigma, w.label);
        // Vertices a and b through the ends of the interval.
        let (e0, e1) = (len2(w.b0 - sx, sy), len2(w.b1 - sx, sy));
        let (d0, d1) = (sigma + e0, sigma + e1);
        let h = w.h;
        if self.update(a, d0 + w.b0, label) {
            if w.b0 == 0.0 {
                self.arrival[a as usize] = Arrival::at(h as usize, ArrivalAt::Origin, sx, sy);
            }
            let x = w.b0;
            self.set_parent(
                a,
                Parent::Ray {
                    h,
                    x,
                    sx,
                    sy,
                    sigma,
                },
            );
        }
        if self.update(b, d1 + (fr.l - w.b1), label) {
            if w.b1 == fr.l {
                self.arrival[b as usize] = Arrival::at(h as usize, ArrivalAt::End, sx, sy);
            }
            let x = w.b1;
            self.set_parent(
                b,
                Parent::Ray {
                    h,
                    x,
                    sx,
                    sy,
                    sigma,
                },
            );
        }
        let ends = (self.dist[a as usize], self.dist[b as usize]);
        if !self.trim(&mut w, fr.l, Some((e0, e1)), true, ends) {
            return;
        }
        if !self.face_targets.is_empty() {
            let (b0, b1) = (w.b0, w.b1);
            self.update_targets(f, label, |t| {
                // The target in this edge's frame (barycentric coordinates
                // are affine), and the ray of the window nearest to it.
                let (px, py) = (
                    t[(k + 1) % 3] * fr.l + t[(k + 2) % 3] * fr.cx,
                    t[(k + 2) % 3] * fr.cy,
                );
                let xt = sx + (px - sx) * (-sy) / (py - sy);
                let x = if xt.is_finite() { xt.clamp(b0, b1) } else { b0 };
                let d = sigma + len2(x - sx, sy) + len2(px - x, py);
                (
                    d,
                    Parent::Ray {
                        h,
                        x,
                        sx,
                        sy,
                        sigma,
                    },
                )
            });
        }
        self.stats.windows_propagated += 1;
        let slot = self.recent_slot(w.h as usize);
        let slots = &mut self.recent[slot];
        slots.copy_within(0..RECENT - 1, 1);
        slots[0] = Field::of(&w);
        let (b0, b1) = (w.b0, w.b1);
        // The ray through c crosses the edge at xc.
        let xc = sx + (fr.cx - sx) * (-sy) / (fr.cy - sy);
        let xp = xc.clamp(b0, b1);
        let dc = sigma + len2(xp - sx, sy) + len2(fr.cx - xp, fr.cy);
        let improved = self.update(c, dc, label);
        if improved {
            self.set_parent(
                c,
                Parent::Ray {
                    h,
                    x: xp,
                    sx,
                    sy,
                    sigma,
                },
            );
        }
        let (ua, ub, uc) = (
            self.dist[a as usize],
            self.dist[b as usize],
            self.dist[c as usize],
        );
        let mut left = (b0, xc.min(b1));
        let mut right = (xc.max(b0), b1);
        if improved && xp == xc {
            self.via[c as usize] = (w.h, xc);
            self.arrival[c as usize] = Arrival::at(w.h as usize, ArrivalAt::Third, xc, 0.0);
        } else if !improved {
            // One angle, one split (Chen and Han): c is reached more cheaply
            // by a path entering this face at x1 on the same edge. Rays of
            // this window entering between x1 and xc cross that path's
            // segment x1 -> c inside the face, and lose to it beyond the
            // crossing X: if they won, d_w(c) <= d_w(X) + |Xc| <= U(c).
            let (vh, x1) = self.via[c as usize];
            let uc = self.dist[c as usize];
            if vh == w.h && dc > uc + TRIM_TOL * (uc + fr.l) {
                if x1 < xc {
                    left.1 = left.1.min(x1);
                } else {
                    right.0 = right.0.max(x1);
                }
            }
        }
        // Left part: rays with x < xc leave through edge k+2 (c -> a).
        if left.0 < left.1 {
            let (ox, oy) = (fr.cx, fr.cy);
            let (dx, dy) = (-fr.cx * fr.inv_lca, -fr.cy * fr.inv_lca);
            let s_end = if left.1 == xc {
                0.0
            } else {
                ray_hit(sx, sy, left.1, ox, oy, dx, dy, fr.lca)
            };
            let s_start = ray_hit(sx, sy, left.0, ox, oy, dx, dy, fr.lca);
            let (nx, ny) = to_frame(sx, sy, ox, oy, dx, dy);
            self.push_child(
                fr.across[1],
                fr.lca,
                (uc, ua),
                s_end.min(s_start),
                s_end.max(s_start),
                nx,
                ny,
                sigma,
                label,
            );
        }
        // Right part: rays with x > xc leave through edge k+1 (b -> c).
        if right.0 < right.1 {
            let (ox, oy) = (fr.l, 0.0);
            let (dx, dy) = ((fr.cx - fr.l) * fr.inv_lbc, fr.cy * fr.inv_lbc);
            let s_start = if right.0 == xc {
                fr.lbc
            } else {
                ray_hit(sx, sy, right.0, ox, oy, dx, dy, fr.lbc)
            };
            let s_end = ray_hit(sx, sy, right.1, ox, oy, dx, dy, fr.lbc);
            let (nx, ny) = to_frame(sx, sy, ox, oy, dx, dy);
            self.push_child(
                fr.across[0],
                fr.lbc,
                (ub, uc),
                s_end.min(s_start),
                s_end.max(s_start),
                nx,
                ny,
                sigma,
                label,
            );
        }
    }

    /// Processes the nearest pending window or pseudo-source; false when
    /// nothing is pending.
    #[inline]
    fn step(&mut self) -> bool {
        let wk = self.windows.peek_key();
        let vk = self.vertices.peek().map(|e| e.key);
        let take_vertex = match (wk, vk) {
            (None, None) => return false,
            (Some(_), None) => false,
            (None, Some(_)) => true,
            (Some(a), Some(b)) => b <= a,
        };
        if take_vertex {
            if let Some(e) = self.vertices.pop() {
                let vi = e.v as usize;
                // Stale, or already emitted at this distance.
                if e.key <= self.dist[vi] && e.key < self.emitted[vi] {
                    self.emitted[vi] = e.key;
                    self.emit(e.v);
                }
            }
        } else if let Some(w) = self.windows.pop() {
            self.propagate(w);
        }
        true
    }

    /// The checks made every [`POLL`] steps: cancellation and the step
    /// budget.
    fn poll(&self, pops: usize, control: &Control<'_>) -> Result<(), MeshSolveError> {
        if control.is_cancelled() {
            return Err(MeshSolveError::Cancelled);
        }
        if pops > step_budget(self.mesh.num_vertices(), self.mesh.num_faces()) {
            return Err(MeshSolveError::Numerical(format!(
                "the exact method's window propagation took {pops} steps without \
                 settling, far beyond what a mesh of {} vertices needs (its lengths \
                 span too many orders of magnitude, or its faces are degenerate); use \
                 the method fast_marching or heat",
                self.mesh.num_vertices()
            )));
        }
        Ok(())
    }

    fn run(&mut self, control: &Control<'_>) -> Result<(), MeshSolveError> {
        let mut pops = 0usize;
        while self.step() {
            pops += 1;
            if pops.is_multiple_of(POLL) {
                self.poll(pops, control)?;
                control.report(self.reached as f64 / self.reachable as f64);
            }
        }
        if control.is_cancelled() {
            return Err(MeshSolveError::Cancelled);
        }
        Ok(())
    }

    /// Sends the lowered distances of the other worker's vertices.
    #[inline]
    fn flush_dirty(&mut self) {
        for v in self.dirty.drain(..) {
            let vi = v as usize;
            self.out_min = self.out_min.min(self.dist[vi]);
            self.out.push(Message::Distance {
                v,
                label: self.label[vi],
                d: self.dist[vi],
                arrival: self.arrival[vi],
                via: self.via[vi],
            });
        }
    }

    /// Hands the batch of messages to the other half, and lowers its
    /// published front to their smallest key (until it takes them and
    /// publishes its own).
    fn send(&mut self, mail: &Mail) {
        if !self.out.is_empty() {
            let other = 1 - self.me as usize;
            {
                let mut inbox = mail.inbox[other].lock().unwrap_or_else(|e| e.into_inner());
                inbox.append(&mut self.out);
            }
            let key = key_bits(self.out_min) << KEY_SHIFT;
            mail.front[other].fetch_min(key, AtomicOrdering::Relaxed);
            self.out_min = f64::INFINITY;
        }
    }

    /// Takes this half's messages: windows into its queue, distances of
    /// its vertices (queued as pseudo-sources where they are). False when
    /// there were none.
    fn receive(&mut self, mail: &Mail, batch: &mut Vec<Message>) -> bool {
        {
            let mut inbox = mail.inbox[self.me as usize]
                .lock()
                .unwrap_or_else(|e| e.into_inner());
            if inbox.is_empty() {
                return false;
            }
            std::mem::swap(&mut *inbox, batch);
        }
        for m in batch.drain(..) {
            match m {
                Message::Window(w) => {
                    self.windows.push(w);
                    self.stats.max_queue = self.stats.max_queue.max(self.windows.len);
                }
                Message::Distance {
                    v,
                    label,
                    d,
                    arrival,
                    via,
                } => {
                    if self.update(v, d, label) {
                        self.arrival[v as usize] = arrival;
                        self.via[v as usize] = via;
                    }
                }
            }
        }
        true
    }

    /// The key of the next window or pseudo-source.
    fn front(&mut self) -> f64 {
        let w = self.windows.peek_key().unwrap_or(f64::INFINITY);
        let v = self.vertices.peek().map_or(f64::INFINITY, |e| e.key);
        w.min(v)
    }

    /// Publishes this half's front (infinite when nothing is pending) and
    /// returns it.
    fn publish(&mut self, mail: &Mail) -> f64 {
        let front = self.front();
        mail.front[self.me as usize].store(front.to_bits(), AtomicOrdering::Relaxed);
        front
    }

    /// Steps this half of a split propagation (see [`split`]) while it is
    /// not more than [`PACE`] mean edge lengths ahead of the other (windows
    /// processed far out of order are mostly cut later by the other's, so
    /// running ahead costs windows), exchanging messages every
    /// [`EXCHANGE`] steps. Returns the steps taken: 0 when it is idle or
    /// ahead.
    fn work(
        &mut self,
        control: &Control<'_>,
        mail: &Mail,
        batch: &mut Vec<Message>,
    ) -> Result<usize, MeshSolveError> {
        let (me, other) = (self.me as usize, 1 - self.me as usize);
        let slack = PACE * self.geo.mean_edge;
        self.receive(mail, batch);
        let mut steps = 0usize;
        loop {
            if steps.is_multiple_of(EXCHANGE) {
                if steps > 0 {
                    self.send(mail);
                    self.receive(mail, batch);
                }
                let front = self.publish(mail);
                let theirs = f64::from_bits(mail.front[other].load(AtomicOrdering::Relaxed));
                if !front.is_finite()
                    || front > theirs + slack
                    || mail.stop.load(AtomicOrdering::Relaxed)
                {
                    break;
                }
            }
            if !self.step() {
                break;
            }
            self.pops += 1;
            steps += 1;
            self.flush_dirty();
            if self.pops.is_multiple_of(POLL) {
                self.poll(self.pops, control)?;
                mail.reached[me].store(self.reached, AtomicOrdering::Relaxed);
                let reached = self.reached + mail.reached[other].load(AtomicOrdering::Relaxed);
                control.report(reached as f64 / self.reachable as f64);
            }
        }
        self.send(mail);
        self.publish(mail);
        Ok(steps)
    }

    /// Repairs the vertex distances if the final edge check fails.
    fn settle(&mut self) {
        if !self.stats.repaired && self.violates_edges() {
            self.stats.repaired = true;
            self.repair();
        }
    }

    fn finish(mut self) -> (MeshDistance, ExactStats) {
        self.settle();
        let max = self.max_distance;
        let mut labels = Vec::with_capacity(self.dist.len());
        for (d, &l) in self.dist.iter_mut().zip(&self.label) {
            if *d > max || l == NONE {
                *d = f64::INFINITY;
                labels.push(-1);
            } else {
                labels.push(l as i32);
            }
        }
        (
            MeshDistance {
                distance: self.dist,
                labels,
            },
            self.stats,
        )
    }

    /// True when some edge has `U(v) > U(u) + |uv|` beyond rounding.
    fn violates_edges(&self) -> bool {
        let faces = self.mesh.faces();
        (0..self.geo.frames.len()).any(|h| {
            let (u, v) = (
                faces[h / 3][h % 3] as usize,
                faces[h / 3][(h + 1) % 3] as usize,
            );
            let (du, dv) = (self.dist[u], self.dist[v]);
            let l = self.len(h);
            let tol = 1e-9 * (du.min(dv) + l);
            (du.is_finite() && dv > du + l + tol) || (dv.is_finite() && du > dv + l + tol)
        })
    }

    /// Dijkstra along edges from the current values (a safety net for
    /// degenerate input).
    fn repair(&mut self) {
        let mut heap: BinaryHeap<VertexEvent> = self
            .dist
            .iter()
            .enumerate()
            .filter(|(_, d)| d.is_finite())
            .map(|(v, &d)| VertexEvent {
                key: d,
                v: v as u32,
            })
            .collect();
        let topo = self.topo;
        while let Some(e) = heap.pop() {
            if e.key > self.dist[e.v as usize] {
                continue;
            }
            let label = self.label[e.v as usize];
            let pv = self.mesh.position(e.v);
            for &f in topo.faces_of(e.v) {
                for &u in &self.mesh.faces()[f as usize] {
                    let d = e.key + norm(sub(self.mesh.position(u), pv));
                    if d < self.dist[u as usize] {
                        self.dist[u as usize] = d;
                        self.label[u as usize] = label;
                        if let Some(p) = self.parents.get_mut(u as usize) {
                            *p = Parent::Vertex(e.v);
                        }
                        heap.push(VertexEvent { key: d, v: u });
                    }
                }
            }
        }
    }
}

/// Cuts off the ends of `w` where the window `o` (same edge, same frame)
/// gives strictly shorter paths (by more than the tolerance). The crossing
/// points solve `σ + |I x| = σ' + |I' x|`, a quadratic after squaring;
/// its roots split the overlap into pieces of constant sign. Returns false
/// when nothing of `w` is left.
fn trim_by_window(w: &mut Window, o: &Field, l: f64) -> bool {
    let lo = w.b0.max(o.b0);
    let hi = w.b1.min(o.b1);
    let overlap = hi > lo;
    if !overlap {
        return true;
    }
    let tol = TRIM_TOL * (o.sigma.abs() + o.sx.abs() + o.sy.abs() + l);
    let dw = |x: f64| w.sigma + len2(x - w.sx, w.sy);
    let dominated = |x: f64| dw(x) > o.sigma + tol + len2(x - o.sx, o.sy);
    let touches_start = lo <= w.b0;
    let touches_end = hi >= w.b1;
    if !touches_start && !touches_end {
        return true;
    }
    // Crossings in (lo, hi).
    let (a, p, a2, p2) = (w.sx, w.sy, o.sx, o.sy);
    let delta = o.sigma + tol - w.sigma;
    let gamma = 2.0 * (a2 - a);
    let mu = a * a + p * p - a2 * a2 - p2 * p2 - delta * delta;
    let c2 = gamma * gamma - 4.0 * delta * delta;
    let c1 = 2.0 * gamma * mu + 8.0 * delta * delta * a2;
    let c0 = mu * mu - 4.0 * delta * delta * (a2 * a2 + p2 * p2);
    // Candidate crossings: the roots of the quadratic, and the root of the
    // linear equation once squared (`γ x + μ = 0`, exact for `δ = 0`).
    // Squaring twice turns the crossing of two windows of one source
    // distance (`δ ≈ 0`, the usual case) into a double root, which
    // rounding can push below a zero discriminant: the crossing was then
    // lost and the whole overlap cut, losing the rays where the window
    // wins (4.5e-5 relative on a vertex of a decimated dragon). So the
    // discriminant is clamped at 0 and the linear root is added. Extra
    // cut points are harmless: every piece is tested at its midpoint.
    let mut found = [f64::NAN; 3];
    let scale = c2.abs().max(c1.abs()).max(c0.abs());
    if c2.abs() > 1e-14 * scale {
        let disc = (c1 * c1 - 4.0 * c2 * c0).max(0.0);
        let sq = disc.sqrt();
        // Stable form of the two roots.
        let q = -0.5 * (c1 + c1.signum() * sq);
        let r1 = q / c2;
        let r2 = if q != 0.0 { c0 / q } else { r1 };
        found[0] = r1;
        found[1] = r2;
    } else if c1 != 0.0 {
        found[0] = -c0 / c1;
    }
    if gamma != 0.0 {
        found[2] = -mu / gamma;
    }
    let mut cuts = [lo, hi, hi, hi, hi];
    let mut n = 1;
    for r in found {
        if r.is_finite() && r > lo && r < hi {
            // Insertion into the sorted cuts[1..n].
            let mut k = n;
            while k > 1 && cuts[k - 1] > r {
                cuts[k] = cuts[k - 1];
                k -= 1;
            }
            cuts[k] = r;
            n += 1;
        }
    }
    cuts[n] = hi;
    let pieces = n; // pieces [cuts[i], cuts[i + 1]], i < pieces
    if touches_start {
        let mut end = w.b0;
        for i in 0..pieces {
            if dominated(0.5 * (cuts[i] + cuts[i + 1])) {
                end = cuts[i + 1];
            } else {
                break;
            }
        }
        if end >= w.b1 {
            return false;
        }
        w.b0 = w.b0.max(end);
    }
    if touches_end {
        let mut start = w.b1;
        for i in (0..pieces).rev() {
            if cuts[i + 1] > w.b1 || cuts[i] < w.b0 {
                break;
            }
            if dominated(0.5 * (cuts[i] + cuts[i + 1])) {
                start = cuts[i];
            } else {
                break;
            }
        }
        if start <= w.b0 {
            return false;
        }
        w.b1 = w.b1.min(start);
    }
    w.b1 - w.b0 > MIN_WIDTH * l
}

/// The point of barycentric coordinates `b` in the triangle `p`.
#[inline]
fn barycentric_point(p: &[[f64; 3]; 3], b: [f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|c| b[0] * p[0][c] + b[1] * p[1][c] + b[2] * p[2][c])
}

/// `sqrt(x² + y²)` (no overflow guard: coordinates are mesh-sized).
#[inline(always)]
fn len2(x: f64, y: f64) -> f64 {
    (x * x + y * y).sqrt()
}

/// Where the ray from `(sx, sy)` through `(x, 0)` meets the line `o + s d`
/// (unit `d`): the parameter `s`, clamped to `[0, l]`.
#[allow(clippy::too_many_arguments)]
#[inline]
fn ray_hit(sx: f64, sy: f64, x: f64, ox: f64, oy: f64, dx: f64, dy: f64, l: f64) -> f64 {
    // o + s d = I + t r, r = P - I  =>  s = cross(I - o, r) / cross(d, r).
    let (rx, ry) = (x - sx, -sy);
    let den = dx * ry - dy * rx;
    let num = (sx - ox) * ry - (sy - oy) * rx;
    let s = num / den;
    if s.is_finite() {
        s.clamp(0.0, l)
    } else if num >= 0.0 {
        l
    } else {
        0.0
    }
}

/// Coordinates of `(x, y)` in the frame with origin `o`, axis `d` (unit) and
/// normal `(-dy, dx)`.
#[inline]
fn to_frame(x: f64, y: f64, ox: f64, oy: f64, dx: f64, dy: f64) -> (f64, f64) {
    let (px, py) = (x - ox, y - oy);
    (px * dx + py * dy, -px * dy + py * dx)
}

/// Where the ray from the corner `c = (fr.cx, fr.cy)` at angle `t`
/// counterclockwise from `c → a` meets the edge `a = (0, 0)`, `b = (fr.l,
/// 0)` (`θ` being the corner's angle): `0` at `t = 0`, `l` at `t = θ`.
fn corner_ray_hit(fr: Frame, t: f64, theta: f64) -> f64 {
    if t <= 0.0 {
        return 0.0;
    }
    if t >= theta {
        return fr.l;
    }
    let (sin, cos) = t.sin_cos();
    let (ax, ay) = (-fr.cx, -fr.cy);
    let (dx, dy) = (ax * cos - ay * sin, ax * sin + ay * cos);
    if dy >= 0.0 {
        return fr.l;
    }
    (fr.cx - fr.cy / dy * dx).clamp(0.0, fr.l)
}

/// The angular positions of the corners around every vertex marked in
/// `walk` (interior saddles with one fan): per corner, where it starts
/// counting counterclockwise from the first face of the vertex, and per
/// vertex the total angle. A vertex whose faces are not consistently
/// oriented or do not close up gets NaN (and emits in every direction).
fn fans(
    faces: &[[u32; 3]],
    topo: &Topology,
    corner_angle: &[f64],
    walk: &[bool],
) -> (Vec<f64>, Vec<f64>) {
    let mut start = vec![f64::NAN; corner_angle.len()];
    let mut total = vec![f64::NAN; walk.len()];
    for (v, _) in walk.iter().enumerate().filter(|(_, &w)| w) {
        let ring = topo.faces_of(v as u32);
        let Some(&f0) = ring.first() else {
            continue;
        };
        let Some(j0) = (0..3).find(|&j| faces[f0 as usize][j] == v as u32) else {
            continue;
        };
        let (mut f, mut j) = (f0 as usize, j0);
        let mut pos = 0.0;
        let mut closed = false;
        for walked in 1..=ring.len() {
            start[3 * f + j] = pos;
            pos += corner_angle[3 * f + j];
            // Across the edge f[j + 2] → v to the next face counterclockwise,
            // where the same edge runs v → f[j + 2].
            let o = topo.opposite[3 * f + (j + 2) % 3];
            if o == NONE || faces[o as usize / 3][o as usize % 3] != v as u32 {
                break;
            }
            (f, j) = (o as usize / 3, o as usize % 3);
            if f == f0 as usize {
                closed = walked == ring.len();
                break;
            }
        }
        if closed {
            total[v] = pos;
        } else {
            for &g in ring {
                for k in 0..3 {
                    if faces[g as usize][k] == v as u32 {
                        start[3 * g as usize + k] = f64::NAN;
                    }
                }
            }
        }
    }
    (start, total)
}

/// True when the faces around `v` form one fan (connected through the edges
/// incident to `v`).
fn single_fan(
    faces: &[[u32; 3]],
    topo: &Topology,
    v: u32,
    (seen, stack): &mut (Vec<bool>, Vec<usize>),
) -> bool {
    let ring = topo.faces_of(v);
    if ring.len() <= 1 {
        return true;
    }
    seen.clear();
    seen.resize(ring.len(), false);
    stack.clear();
    stack.push(0);
    seen[0] = true;
    let mut count = 1;
    while let Some(i) = stack.pop() {
        let f = ring[i] as usize;
        let Some(j) = (0..3).find(|&j| faces[f][j] == v) else {
            continue;
        };
        for k in [j, (j + 2) % 3] {
            let h = topo.opposite[3 * f + k];
            if h == NONE {
                continue;
            }
            let g = h / 3;
            if let Ok(gi) = ring.binary_search(&g) {
                if !seen[gi] {
                    seen[gi] = true;
                    count += 1;
                    stack.push(gi);
                }
            }
        }
    }
    count == ring.len()
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(48))]
        /// Issue 20: a 7-vertex fan whose coordinates span 1e-160 to 1e133
        /// (and near-duplicate vertices) used to propagate windows forever.
        /// Every such mesh now ends: distances, or an error naming the
        /// mesh, within the step budget.
        #[test]
        fn terminates_on_extreme_coordinate_scales(
            exps in proptest::collection::vec(-160.0f64..133.0, 21),
            signs in proptest::collection::vec(any::<bool>(), 21),
            dup in 0usize..7,
        ) {
            let mut positions: Vec<[f64; 3]> = (0..7)
                .map(|v| {
                    std::array::from_fn(|a| {
                        let i = 3 * v + a;
                        let x = 10f64.powf(exps[i]);
                        if signs[i] { x } else { -x }
                    })
                })
                .collect();
            // A near-duplicate of vertex `dup` (one ulp away).
            positions[(dup + 1) % 7] = positions[dup].map(|c| c * (1.0 + f64::EPSILON));
            let faces = (1..7u32).map(|k| [0, k, k % 6 + 1]).collect();
            let mesh = TriMesh::new(positions, faces).expect("valid indices");
            let (tx, rx) = std::sync::mpsc::channel();
            std::thread::spawn(move || {
                let topo = Topology::new(&mesh);
                let run = exact_distance(
                    &mesh, &topo, &[SurfacePoint::Vertex(0)], f64::INFINITY, &Control::new(),
                );
                let _ = tx.send(run.map(|d| d.distance.iter().any(|x| x.is_nan())));
            });
            let ended = rx.recv_timeout(std::time::Duration::from_secs(60));
            prop_assert!(ended.is_ok(), "the exact propagation did not end within 60 s");
            if let Ok(Ok(has_nan)) = ended {
                prop_assert!(!has_nan, "NaN distance");
            }
        }
    }

    /// An icosphere of 2,562 vertices whose vertices are moved radially by
    /// up to ±12 %: hundreds of saddle vertices of every angle excess.
    fn bumpy_sphere() -> TriMesh {
        let ico = crate::numerics::mesh::shapes::icosphere(4, 1.0);
        let positions = (0..ico.num_vertices() as u32)
            .map(|v| {
                let h = (v as u64 + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 11;
                let r = 1.0 + 0.12 * (2.0 * (h as f64 / (1u64 << 53) as f64) - 1.0);
                ico.position(v).map(|c| c * r)
            })
            .collect();
        TriMesh::new(positions, ico.faces().to_vec()).expect("valid faces")
    }

    fn propagate(
        mesh: &TriMesh,
        topo: &Topology,
        sources: &[SurfacePoint],
        sectors: bool,
    ) -> (Vec<f64>, Vec<i32>, ExactStats) {
        let geo = Geometry::new(mesh, topo);
        let mut p = Propagation::new(&geo, f64::INFINITY, 0);
        p.sectors = sectors;
        p.seed(sources);
        p.run(&Control::new()).expect("propagation ends");
        let (d, stats) = p.finish();
        (d.distance, d.labels, stats)
    }

    /// The saddles' emission into their shadow sector only (a shortest
    /// path leaves a vertex only where both angles are at least π) gives
    /// the distances of emitting in every direction, to rounding, with
    /// fewer windows. A sector off by a sign or a turn loses windows and
    /// overestimates some vertices by percents (as a first version did).
    #[test]
    fn saddles_emitting_into_their_shadow_only_change_no_distance() {
        let mesh = bumpy_sphere();
        let topo = Topology::new(&mesh);
        let point = SurfacePoint::Face {
            face: 1000,
            bary: [0.2, 0.3, 0.5],
        };
        for sources in [
            vec![SurfacePoint::Vertex(0)],
            vec![SurfacePoint::Vertex(7), point, SurfacePoint::Vertex(2000)],
        ] {
            let (full, full_labels, full_stats) = propagate(&mesh, &topo, &sources, false);
            let (cut, cut_labels, cut_stats) = propagate(&mesh, &topo, &sources, true);
            assert_eq!(full_stats.sector_emissions, 0);
            assert!(
                cut_stats.sector_emissions > 200,
                "{} sector emissions",
                cut_stats.sector_emissions
            );
            assert!(cut_stats.windows_propagated < full_stats.windows_propagated);
            let worst = full
                .iter()
                .zip(&cut)
                .map(|(a, b)| (a - b).abs() / a.max(1e-3))
                .fold(0.0, f64::max);
            assert!(worst < 1e-12, "relative difference {worst:e}");
            let relabelled = full_labels
                .iter()
                .zip(&cut_labels)
                .filter(|(a, b)| a != b)
                .count();
            assert!(relabelled <= 2, "{relabelled} labels differ");
        }
    }

    /// A propagation split in two halves (by a plane through the first
    /// source, exchanging windows and distances) gives one worker's
    /// distances and labels, whether two threads step the halves at once
    /// or, on a pool of one thread, one thread steps both in turn.
    #[test]
    fn split_propagation_gives_one_workers_distances() {
        let mesh = bumpy_sphere();
        let topo = Topology::new(&mesh);
        let one_thread = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .expect("pool");
        let cases: [(&[SurfacePoint], f64); 3] = [
            (&[SurfacePoint::Vertex(0)], f64::INFINITY),
            (
                &[SurfacePoint::Face {
                    face: 100,
                    bary: [0.2, 0.3, 0.5],
                }],
                f64::INFINITY,
            ),
            (&[SurfacePoint::Vertex(0), SurfacePoint::Vertex(1500)], 1.5),
        ];
        for (sources, max) in cases {
            assert!(
                split(&mesh, sources, &Control::new()).is_some(),
                "the mesh is split"
            );
            let c = Control::new();
            let (one, _) = exact_distance_threads(&mesh, &topo, sources, max, 1, &c).expect("one");
            let (two, stats) =
                exact_distance_threads(&mesh, &topo, sources, max, 2, &c).expect("two");
            // One thread steps both halves in turn.
            let (alternating, _) = one_thread
                .install(|| exact_distance_threads(&mesh, &topo, sources, max, 2, &c))
                .expect("alternating");
            assert!(stats.windows_propagated > 0);
            for other in [&two, &alternating] {
                for v in 0..mesh.num_vertices() {
                    let (a, b) = (one.distance[v], other.distance[v]);
                    assert!(
                        a == b || (a - b).abs() <= 1e-12 * a,
                        "vertex {v}: {a} against {b}"
                    );
                    assert_eq!(one.labels[v], other.labels[v], "vertex {v}");
                }
            }
        }
        let cancelled = std::sync::atomic::AtomicBool::new(true);
        let c = Control::new().with_cancel(&cancelled);
        let r = exact_distance_threads(
            &mesh,
            &topo,
            &[SurfacePoint::Vertex(0)],
            f64::INFINITY,
            2,
            &c,
        );
        assert!(matches!(r, Err(MeshSolveError::Cancelled)), "{r:?}");
    }

    /// The default on the service's situation: solves large enough to
    /// split, several at once on one pool of two threads, so that each
    /// solve's second thread is sometimes busy with another solve, stolen
    /// late or not at all. Every solve ends with one worker's distances.
    #[test]
    fn concurrent_default_solves_on_one_pool_give_one_workers_distances() {
        let mesh = crate::numerics::mesh::shapes::icosphere(5, 1.0);
        assert!(mesh.num_vertices() >= MIN_SPLIT_VERTICES);
        let topo = Topology::new(&mesh);
        let sources = [0u32, 77, 5000, 10000].map(|v| [SurfacePoint::Vertex(v)]);
        let c = Control::new();
        assert!(split(&mesh, &sources[0], &c).is_some(), "the mesh is split");
        let one: Vec<MeshDistance> = sources
            .iter()
            .map(|s| {
                exact_distance_threads(&mesh, &topo, s, f64::INFINITY, 1, &c)
                    .expect("one")
                    .0
            })
            .collect();
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .expect("pool");
        let all: Vec<MeshDistance> = pool.install(|| {
            use rayon::prelude::*;
            sources
                .par_iter()
                .map(|s| exact_distance(&mesh, &topo, s, f64::INFINITY, &c).expect("default"))
                .collect()
        });
        for (a, b) in one.iter().zip(&all) {
            for v in 0..mesh.num_vertices() {
                let (x, y) = (a.distance[v], b.distance[v]);
                assert!(
                    x == y || (x - y).abs() <= 1e-12 * x,
                    "vertex {v}: {x} against {y}"
                );
            }
        }
    }

    /// Two windows of one source distance (`δ = 0`) cross where the
    /// twice-squared equation has a double root, which rounding pushed
    /// below a zero discriminant: the crossing was lost and the whole
    /// overlap cut, rays where the window wins included (a window of a
    /// decimated dragon; its vertex came out 4.5e-5 too far).
    #[test]
    fn crossing_of_windows_of_one_source_distance_is_kept() {
        let mut w = Window {
            key: 0.0,
            b0: 0.000602221716978629,
            b1: 0.0009176581738450696,
            sx: 0.0024479531832597365,
            sy: -0.0020670639798676216,
            sigma: 0.0,
            h: 0,
            label: 0,
        };
        let o = Field {
            b0: 0.0007595959916776342,
            b1: 0.0010050954619796758,
            sx: 0.0027686458600543395,
            sy: -0.001762332864857556,
            sigma: 0.0,
        };
        // |I x| = |I' x| where 2 (a' - a) x = a'² + p'² - a² - p².
        let cross = (o.sx * o.sx + o.sy * o.sy - w.sx * w.sx - w.sy * w.sy) / (2.0 * (o.sx - w.sx));
        assert!(cross > o.b0 && cross < w.b1);
        assert!(trim_by_window(&mut w, &o, 0.002));
        assert!(
            (w.b1 - cross).abs() < 1e-12,
            "the window ends at {} instead of the crossing {cross}",
            w.b1
        );
        assert_eq!(w.b0, 0.000602221716978629);
    }

    fn window(key: f64) -> Window {
        Window {
            key,
            b0: 0.0,
            b1: 1.0,
            sx: 0.0,
            sy: -1.0,
            sigma: 0.0,
            h: 0,
            label: 0,
        }
    }

    /// Pops come out sorted up to `KEY_SHIFT` while pushes interleave with
    /// them (each push at or above the last pop, as children of the popped
    /// window), and a key below the last pop is raised to it.
    #[test]
    fn radix_queue_pops_in_order() {
        let mut q = RadixQueue::new();
        let mut state = 12345u64;
        let mut next = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        for _ in 0..50 {
            q.push(window(3.0 * next()));
        }
        let mut last = 0.0f64;
        let mut popped = 0;
        while let Some(w) = q.pop() {
            assert!(key_bits(w.key) >= key_bits(last), "{} after {last}", w.key);
            last = last.max(w.key);
            popped += 1;
            if popped < 2000 {
                for _ in 0..2 {
                    if next() < 0.5 {
                        q.push(window(last + next() * next()));
                    }
                }
            }
        }
        assert_eq!(q.len, 0);
        assert!(popped > 50);
        let top = last + 1.0;
        q.push(window(top));
        assert_eq!(q.pop().map(|w| w.key), Some(top));
        let raised = q.last;
        assert_eq!(raised, key_bits(top));
        q.push(window(top - 0.5));
        assert_eq!(q.pop().map(|w| key_bits(w.key)), Some(raised));
        q.push(window(0.0));
        q.push(window(-0.0));
        assert_eq!(q.peek_key().map(key_bits), Some(raised));
        assert_eq!(q.len, 2);
    }
}
