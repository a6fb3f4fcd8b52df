//! Bucketing by a small integer key (a counting sort): the values of `m`
//! items with keys below `n` grouped by key in `O(n + m)`, each bucket
//! keeping the items' order. Meshes use it wherever they gather something
//! per vertex or per column (edge graphs, Laplacian columns, duplicate
//! faces, boundary edges) instead of sorting or hashing every item.

/// The values of `items` grouped by key: bucket `k` is
/// `values[start[k]..start[k + 1]]`, in the order the items came. The
/// iterator is walked twice (once to count, once to place); every key must
/// be below `n`.
///
/// # Examples
///
/// ```
/// use geodex::numerics::buckets::bucket;
///
/// let (start, values) = bucket(3, [(2, 'a'), (0, 'b'), (2, 'c')].into_iter());
/// assert_eq!(start, [0, 1, 1, 3]);
/// assert_eq!(values, ['b', 'a', 'c']);
/// ```
pub fn bucket<V, I>(n: usize, items: I) -> (Vec<usize>, Vec<V>)
where
    V: Copy + Default,
    I: Iterator<Item = (usize, V)> + Clone,
{
    let mut start = vec![0usize; n + 1];
    for (k, _) in items.clone() {
        start[k + 1] += 1;
    }
    for k in 0..n {
        start[k + 1] += start[k];
    }
    let mut next = start.clone();
    let mut values = vec![V::default(); start[n]];
    for (k, v) in items {
        values[next[k]] = v;
        next[k] += 1;
    }
    (start, values)
}

/// The triangles around each of `n` vertices: those of vertex `v` are
/// `around[start[v]..start[v + 1]]`, in increasing order.
///
/// # Examples
///
/// ```
/// use geodex::numerics::buckets::triangles_by_vertex;
///
/// let (start, around) = triangles_by_vertex(4, &[[0, 1, 2], [0, 2, 3]]);
/// assert_eq!(&around[start[0]..start[1]], &[0, 1]);
/// assert_eq!(&around[start[3]..start[4]], &[1]);
/// ```
pub fn triangles_by_vertex(n: usize, triangles: &[[u32; 3]]) -> (Vec<usize>, Vec<u32>) {
    bucket(
        n,
        triangles
            .iter()
            .enumerate()
            .flat_map(|(t, tri)| tri.map(|v| (v as usize, t as u32))),
    )
}
