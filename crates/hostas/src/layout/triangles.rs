//! Reading stored triangles in either layout: direct (three vertices per triangle) or
//! indexed ([`TriRecord`]s into shared vertices; written by [`super::indexed`]).
//!
//! Both give the same three vertices, in index order, for a slot, so every test computes the
//! same bits whichever layout a structure has. Traversal's hot loop is instantiated per
//! layout (reading direct triangles in place, gathering indexed ones with
//! [`Indexed::leaf_rows`]); other readers go through [`Triangles`].

use super::TriRecord;

/// The vertices of indexed triangles, [`View`](super::view::View)-checked: every record's
/// three vertex numbers are in range.
#[derive(Clone, Copy, Debug)]
pub struct Indexed<'a> {
    pub records: &'a [TriRecord],
    pub vertices: &'a [[f32; 3]],
}

/// The stored triangles of a structure, in leaf order.
#[derive(Clone, Copy, Debug)]
pub enum Triangles<'a> {
    Direct(&'a [[f32; 9]]),
    Indexed(Indexed<'a>),
}

impl Default for Triangles<'_> {
    fn default() -> Self {
        Triangles::Direct(&[])
    }
}

/// Stored triangles as the traversal prefetches them (a pushed leaf's first lines).
pub trait TriangleSource: Copy {
    /// Requests the first cache lines of the `count` triangles from `first`.
    fn prefetch(&self, first: usize, count: usize);
}

impl TriangleSource for &[[f32; 9]] {
    #[inline(always)]
    fn prefetch(&self, first: usize, count: usize) {
        // The first and last triangle: a leaf's 36-byte triangles span at most a few lines.
        if let Some(t) = self.get(first) {
            crate::math::prefetch(t);
        }
        if let Some(t) = self.get(first + count.saturating_sub(1)) {
            crate::math::prefetch(t);
        }
    }
}

impl Indexed<'_> {
    /// The `count` triangles from `first` (none when out of range), each gathered as the
    /// caller reaches it, as rows: the x coordinates of its three vertices in index order,
    /// then their y, then their z, each row padded to four floats (see
    /// [`ShearedRay::intersect_rows`](crate::traverse::triangle::ShearedRay::intersect_rows):
    /// a row is sheared without a shuffle). Gathering as the tests go, rather than a leaf
    /// first, spares a loop whose exit leaf sizes make unpredictable and the stores and loads
    /// of a buffer between them.
    #[inline(always)]
    pub fn leaf_rows(&self, first: usize, count: usize) -> impl Iterator<Item = [f32; 12]> {
        let records = self.records.get(first..first + count).unwrap_or_default();
        let v = self.vertices;
        // A vertex out of range (which a checked view never has) reads as NaNs, which no
        // ray hits: the loop then has no exit but its end.
        let vertex = move |i: usize| v.get(i).unwrap_or(&[f32::NAN; 3]);
        records.iter().map(move |r| {
            let [a, b, c] = r.vertices().map(vertex);
            [
                a[0], b[0], c[0], 0.0, a[1], b[1], c[1], 0.0, a[2], b[2], c[2], 0.0,
            ]
        })
    }
}

/// From this many shared vertices (3 MiB of them, past the L2 caches of current cores) a
/// pushed leaf's vertices are requested with its records.
const PREFETCH_VERTICES_FROM: usize = 1 << 18;

impl TriangleSource for Indexed<'_> {
    #[inline(always)]
    fn prefetch(&self, first: usize, _count: usize) {
        // A leaf's records (at most 15 of 8 bytes), and in a large structure the line of its
        // first vertex (a leaf's vertices are numbered together, so that line holds most of
        // them). That request waits for the record: where the vertices stay in the caches it
        // only costs (primary rays on the Xeon: bunny, Sponza, conference 8-14% slower), past
        // them it saves a miss per leaf tested (incoherent rays: the 1M sphere +11%, boxes +8%).
        if let Some(r) = self.records.get(first) {
            crate::math::prefetch(r);
            if self.vertices.len() >= PREFETCH_VERTICES_FROM
                && let Some(v) = self.vertices.get(r.a as usize)
            {
                crate::math::prefetch(v);
            }
        }
    }
}

impl TriangleSource for Triangles<'_> {
    #[inline]
    fn prefetch(&self, first: usize, count: usize) {
        match self {
            Triangles::Direct(t) => t.prefetch(first, count),
            Triangles::Indexed(t) => t.prefetch(first, count),
        }
    }
}

impl Triangles<'_> {
    /// The vertices of stored triangle `slot` as nine floats, in index order.
    pub fn get(&self, slot: usize) -> Option<[f32; 9]> {
        match self {
            Triangles::Direct(t) => t.get(slot).copied(),
            Triangles::Indexed(t) => {
                let [a, b, c] = t.records.get(slot)?.vertices();
                let v = t.vertices;
                let [a, b, c] = [v.get(a)?, v.get(b)?, v.get(c)?];
                Some([a[0], a[1], a[2], b[0], b[1], b[2], c[0], c[1], c[2]])
            }
        }
    }
}
