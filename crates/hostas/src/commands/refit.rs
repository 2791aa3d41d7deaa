//! Update (`mode = UPDATE`): re-reads every primitive through the application's buffers (index
//! values included: the CTS changes them between build and update, so nothing is cached from
//! the build), rewrites the stored primitives and refits every node's bounds.
//!
//! The fast path walks the tree depth-first in one pass: each leaf decodes its primitives
//! straight from the application's bytes into the stored primitive section while computing
//! the leaf's box, and each node's boxes are set once its children are done; large subtrees
//! run in parallel. For one triangle geometry on one thread (and for scattered ones on a few)
//! the stored triangles are instead rewritten first, and the walk then only computes the
//! boxes: in primitive order (the application's buffers read in sequence, the stored
//! triangles written where the ids say), or, for small and large meshes on one thread, in
//! stored order (each triangle gathered by id; in a large one, its indices and vertices
//! requested well ahead). It relies on
//! the layout the encoder writes (nodes in depth-first preorder, primitives in leaf order) and
//! checks it as it goes. Anything it does not expect (an invalid primitive, an unusual layout)
//! makes it give up, and the general path below redoes the whole update from the start: it
//! reports the first error in stored order, exactly as before, and handles any layout
//! [`View::parse`](crate::layout::view::View::parse) accepts. Both paths compute every box
//! with the same operations in the same order, so the bytes written do not depend on the path
//! taken or the thread count.

use super::build::Reader;
use crate::error::{Error, Location, Result};
use crate::input::aabbs::AabbReader;
use crate::input::triangles::TriangleReader;
use crate::layout::{
    EMPTY_CHILD, GEOMETRY_RECORD_SIZE, GeometryRecord, Header, InstanceRecord, LEAF_BIT, MAX_DEPTH,
    MAX_LEAF_SIZE, NODE_SIZE, Node, PrimKind, WIDTH,
};
use crate::math::{Aabb, Box4, fmax4, fmin4, prefetch, prefetch_for_write};
use rayon::prelude::*;
use wide::f32x4;

/// Refits the structure in `bytes`, whose header (`h`), sections and geometry records
/// `View::parse_sections` accepted. `validate` is the rest of `View::parse` (ids, tree): the
/// fast path checks the same as it goes, and anything else runs `validate` first, so that an
/// invalid structure is reported as such before any other error.
#[allow(clippy::too_many_arguments)] // the update's inputs, each used once
pub(super) fn refit(
    bytes: &mut [u8],
    h: &Header,
    prim_kind: PrimKind,
    readers: &[Reader],
    instances: &[(InstanceRecord, Aabb)],
    at: Location,
    validate: &dyn Fn(&[u8]) -> Result<()>,
    scratch: &mut [u8],
) -> Result<()> {
    if matches!(prim_kind, PrimKind::Triangles | PrimKind::Aabbs) {
        if h.stored_count < h.primitive_count {
            validate(bytes)?;
            check_still_inactive(bytes, h, readers, at)?;
        }
        if let Some(root) = fused(bytes, h, prim_kind, readers, scratch) {
            let mut header = *h;
            header.bounds = root;
            bytes[..256].copy_from_slice(bytemuck::bytes_of(&header));
            return Ok(());
        }
    }
    validate(bytes)?;
    general(bytes, h, prim_kind, readers, instances, at)
}

fn misaligned(e: bytemuck::PodCastError) -> Error {
    Error::NotSupported(format!("alignment: {e}"))
}

/// The stored primitive ids, in place.
fn prim_ids<'b>(bytes: &'b [u8], h: &Header) -> Result<&'b [u32]> {
    let start = h.prim_ids_offset as usize;
    bytemuck::try_cast_slice(&bytes[start..start + 4 * h.stored_count as usize]).map_err(misaligned)
}

/// The geometry records, in place.
fn geometry_records<'b>(bytes: &'b [u8], h: &Header) -> Result<&'b [GeometryRecord]> {
    let start = h.geometries_offset as usize;
    let len = GEOMETRY_RECORD_SIZE as usize * h.geometry_count as usize;
    bytemuck::try_cast_slice(&bytes[start..start + len]).map_err(misaligned)
}

/// VUID-03663: the primitives that are not stored were inactive and must still be. Checked
/// first, in primitive order, and only when some primitive is not stored.
fn check_still_inactive(bytes: &[u8], h: &Header, readers: &[Reader], at: Location) -> Result<()> {
    if h.stored_count >= h.primitive_count {
        return Ok(());
    }
    let ids = prim_ids(bytes, h)?;
    let geoms = geometry_records(bytes, h)?;
    let mut stored = vec![false; h.primitive_count as usize];
    for &id in ids {
        stored[id as usize] = true;
    }
    for (g, r) in readers.iter().enumerate() {
        let first = geoms[g].first_primitive;
        let count = match r {
            Reader::Triangles(t) => t.primitive_count,
            Reader::Aabbs(a) => a.primitive_count,
            Reader::Instances(_) => 0,
        };
        for i in (0..count).filter(|&i| !stored[(first + i) as usize]) {
            let active = match r {
                Reader::Triangles(t) => t.triangle(i)?.is_some(),
                Reader::Aabbs(a) => a.aabb(i)?.is_some(),
                Reader::Instances(_) => false,
            };
            if active {
                return Err(Error::vuid(
                    "VUID-vkBuildAccelerationStructuresKHR-pInfos-03663",
                    at.geometry(g).primitive(i),
                    "an inactive primitive became active in an update",
                ));
            }
        }
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// Fast path.

/// A box as two four-lane arrays, lower and upper corner; the last lane is unspecified.
type Lanes = ([f32; 4], [f32; 4]);

/// [`crate::math::fmin`] lane by lane.
#[inline(always)]
fn min4(a: [f32; 4], b: [f32; 4]) -> [f32; 4] {
    fmin4(f32x4::new(a), f32x4::new(b)).to_array()
}

/// [`crate::math::fmax`] lane by lane.
#[inline(always)]
fn max4(a: [f32; 4], b: [f32; 4]) -> [f32; 4] {
    fmax4(f32x4::new(a), f32x4::new(b)).to_array()
}

/// The empty box ([`Aabb::EMPTY`]) as lanes.
const EMPTY_LANES: Lanes = ([f32::INFINITY; 4], [f32::NEG_INFINITY; 4]);

#[inline(always)]
fn to_aabb((lo, hi): Lanes) -> Aabb {
    Aabb {
        lo: [lo[0], lo[1], lo[2]],
        hi: [hi[0], hi[1], hi[2]],
    }
}

/// A stored primitive, and how a leaf's box follows from the stored primitives.
trait StoredPrim: bytemuck::Pod + Send {
    /// The union, in order from [`Aabb::EMPTY`], of the boxes of `prims` as the general path
    /// computes them.
    fn leaf_box(prims: &[Self]) -> Lanes;
}

/// Grows `g` by the triangle `a, b, c` (its box as `Aabb::point(a)`, `grow(b)`, `grow(c)`,
/// then `union`): the same operations in the same order as the general path's.
#[inline(always)]
fn grow_triangle(g: &mut Box4, a: [f32; 3], b: [f32; 3], c: [f32; 3]) {
    let v = |p: [f32; 3]| f32x4::new([p[0], p[1], p[2], p[2]]);
    g.grow(&Box4::triangle(v(a), v(b), v(c)));
}

#[inline(always)]
fn lanes(b: Box4) -> Lanes {
    (b.lo.to_array(), b.hi.to_array())
}

impl StoredPrim for [f32; 9] {
    #[inline(always)]
    fn leaf_box(prims: &[[f32; 9]]) -> Lanes {
        let Some(last) = prims.len().checked_sub(1) else {
            return EMPTY_LANES;
        };
        let triangle = |f: &[f32; 9]| {
            // Each vertex from one 16-byte load (a box's lane 3 is unspecified, so the
            // neighbouring float may fill it): the same lanes 0-2, so the same bits as
            // `grow_triangle`.
            let bytes: &[u8; 36] = bytemuck::cast_ref(f);
            let four = |at: usize| bytemuck::pod_read_unaligned::<[f32; 4]>(&bytes[at..at + 16]);
            let a = f32x4::new(four(0));
            let b = f32x4::new(four(12));
            let c = f32x4::new([f[6], f[7], f[8], f[8]]);
            Box4::triangle(a, b, c)
        };
        // The first two triangles, then the next two, without a loop, the leaf's last
        // triangle repeated where it has fewer: a union with a box already taken in changes
        // no bit, and leaf sizes (mostly 1-4, in no predictable order) would otherwise cost
        // a mispredicted loop exit per leaf.
        // (The union of the empty box with a box is that box, NaN lanes included:
        // `fmin(+inf, x)` is `x`.)
        let first = &prims[0];
        let mut g = triangle(first);
        g.grow(&triangle(prims.get(1).unwrap_or(first)));
        if last >= 2 {
            let third = &prims[2];
            g.grow(&triangle(third));
            g.grow(&triangle(prims.get(3).unwrap_or(third)));
            if last >= 4 {
                for f in &prims[4..] {
                    g.grow(&triangle(f));
                }
            }
        }
        lanes(g)
    }
}

impl StoredPrim for [f32; 6] {
    /// The stored form of a box is the box.
    #[inline(always)]
    fn leaf_box(prims: &[[f32; 6]]) -> Lanes {
        let (mut lo, mut hi) = EMPTY_LANES;
        for f in prims {
            lo = min4(lo, [f[0], f[1], f[2], f[2]]);
            hi = max4(hi, [f[3], f[4], f[5], f[5]]);
        }
        (lo, hi)
    }
}

/// A triangle's box, as the general path computes it.
#[inline(always)]
fn triangle_box(v: &[f32; 9]) -> Aabb {
    let mut b = Aabb::point([v[0], v[1], v[2]]);
    b.grow([v[3], v[4], v[5]]);
    b.grow([v[6], v[7], v[8]]);
    b
}

/// Decodes primitives (by sequence number) into their stored form. `None` for anything but
/// valid, active primitives: the caller gives up and the general path reports what is wrong.
trait Source: Sync {
    type Prim: StoredPrim;
    /// Whether [`Self::leaf`] reads the leaf's ids (the walk then hands them over).
    const READS_IDS: bool = true;
    /// Primitive `id`'s stored form.
    fn get(&self, id: u32) -> Option<Self::Prim>;

    /// Decodes primitives `ids` into `out` (as long).
    #[inline]
    fn decode(&self, ids: &[u32], out: &mut [Self::Prim]) -> Option<()> {
        for (o, &id) in out.iter_mut().zip(ids) {
            *o = self.get(id)?;
        }
        Some(())
    }

    /// Decodes a leaf's primitives `ids` into `out` (as long); returns the leaf's box.
    #[inline(always)]
    fn leaf(&self, ids: &[u32], out: &mut [Self::Prim]) -> Option<Lanes> {
        self.decode(ids, out)?;
        Some(Self::Prim::leaf_box(out))
    }
}

/// A triangle geometry's index triples (`primitiveCount` of them).
trait Indices: Sync + Copy {
    /// Triangles in the range.
    fn len(&self) -> usize;
    /// Triangle `p`'s vertex indices, `firstVertex` not added; `None` past the range.
    fn triple(&self, p: usize) -> Option<[usize; 3]>;
    /// Every triangle's vertex indices, in order.
    fn triples(&self) -> impl Iterator<Item = [usize; 3]>;
    /// Asks the caches for triangle `p`'s indices (nothing past the range).
    fn prefetch(&self, p: usize);
}

/// No index buffer: triangle `p` is vertices `3p`, `3p + 1`, `3p + 2`.
#[derive(Clone, Copy)]
struct NoIndices(usize);

impl Indices for NoIndices {
    #[inline(always)]
    fn len(&self) -> usize {
        self.0
    }
    #[inline(always)]
    fn triple(&self, p: usize) -> Option<[usize; 3]> {
        (p < self.0).then_some([3 * p, 3 * p + 1, 3 * p + 2])
    }
    #[inline(always)]
    fn triples(&self) -> impl Iterator<Item = [usize; 3]> {
        (0..self.0).map(|p| [3 * p, 3 * p + 1, 3 * p + 2])
    }
    #[inline(always)]
    fn prefetch(&self, _: usize) {}
}

/// `u16` or `u32` indices: `N`-byte records (6 or 12) of three little-endian values.
#[derive(Clone, Copy)]
struct IndexRecords<'a, const N: usize>(&'a [[u8; N]]);

impl<const N: usize> Indices for IndexRecords<'_, N> {
    #[inline(always)]
    fn len(&self) -> usize {
        self.0.len()
    }
    #[inline(always)]
    fn triple(&self, p: usize) -> Option<[usize; 3]> {
        Some(Self::decode(self.0.get(p)?))
    }
    #[inline(always)]
    fn triples(&self) -> impl Iterator<Item = [usize; 3]> {
        self.0.iter().map(Self::decode)
    }
    #[inline(always)]
    fn prefetch(&self, p: usize) {
        if let Some(r) = self.0.get(p) {
            prefetch(r);
        }
    }
}

impl<const N: usize> IndexRecords<'_, N> {
    #[inline(always)]
    fn decode(b: &[u8; N]) -> [usize; 3] {
        let k = N / 3;
        let at = |i: usize| {
            let mut v = [0u8; 4];
            v[..k].copy_from_slice(&b[i * k..i * k + k]);
            u32::from_le_bytes(v) as usize
        };
        [at(0), at(1), at(2)]
    }
}

/// A triangle geometry's `R32G32B32_SFLOAT` vertices firstVertex to maxVertex, numbered from 0.
trait Vertices: Sync + Copy {
    /// Vertex `v`; `None` past maxVertex.
    fn get(&self, v: usize) -> Option<[f32; 3]>;

    /// Asks the caches for vertex `v` (nothing past maxVertex).
    fn prefetch(&self, v: usize);

    /// Vertex `v`; NaNs past maxVertex.
    #[inline(always)]
    fn vertex(&self, v: usize) -> [f32; 3] {
        self.get(v).unwrap_or([f32::NAN; 3])
    }
}

/// Tightly packed (stride 12): exactly maxVertex + 1 - firstVertex records.
#[derive(Clone, Copy)]
struct Packed<'a>(&'a [[u8; 12]]);

/// `stride` bytes apart; `data` holds every vertex up to `last`.
#[derive(Clone, Copy)]
struct Strided<'a> {
    data: &'a [u8],
    stride: usize,
    last: usize,
}

#[inline(always)]
fn vec3(b: &[u8; 12]) -> [f32; 3] {
    let f = |k: usize| f32::from_le_bytes([b[4 * k], b[4 * k + 1], b[4 * k + 2], b[4 * k + 3]]);
    [f(0), f(1), f(2)]
}

impl Vertices for Packed<'_> {
    #[inline(always)]
    fn get(&self, v: usize) -> Option<[f32; 3]> {
        self.0.get(v).map(vec3)
    }
    #[inline(always)]
    fn prefetch(&self, v: usize) {
        if let Some(x) = self.0.get(v) {
            prefetch(x);
        }
    }
}

impl Vertices for Strided<'_> {
    #[inline(always)]
    fn get(&self, v: usize) -> Option<[f32; 3]> {
        if v > self.last {
            return None;
        }
        let at = v.wrapping_mul(self.stride);
        Some(vec3(
            self.data.get(at..at.wrapping_add(12))?.try_into().ok()?,
        ))
    }
    #[inline(always)]
    fn prefetch(&self, v: usize) {
        if v <= self.last
            && let Some(x) = self.data.get(v.wrapping_mul(self.stride))
        {
            prefetch(x);
        }
    }
}

/// One `R32G32B32_SFLOAT` triangle geometry without a transform; the per-geometry checks are
/// done once, up front. `verts` starts at vertex `firstVertex`, so index values need no
/// addition.
#[derive(Clone, Copy)]
struct TriF32<I, V> {
    index: I,
    verts: V,
    /// The geometry's first primitive sequence number.
    first: u32,
}

impl<I: Indices, V: Vertices> TriF32<I, V> {
    /// The vertex indices (into `verts`) of triangle `id`; out of range (so that
    /// [`Self::triangle`] finds it inactive) past the geometry's range.
    #[inline(always)]
    fn vertex_indices(&self, id: u32) -> [usize; 3] {
        let p = id.wrapping_sub(self.first) as usize;
        self.index.triple(p).unwrap_or([usize::MAX; 3])
    }

    /// The stored form of the triangle with vertices `v`, and whether it is valid and active
    /// (a vertex past maxVertex reads as NaNs).
    #[inline(always)]
    fn triangle(&self, v: &[usize; 3]) -> ([f32; 9], bool) {
        let (a, b, c) = (
            self.verts.vertex(v[0]),
            self.verts.vertex(v[1]),
            self.verts.vertex(v[2]),
        );
        let active = !(a[0].is_nan() | b[0].is_nan() | c[0].is_nan());
        (
            [a[0], a[1], a[2], b[0], b[1], b[2], c[0], c[1], c[2]],
            active,
        )
    }
}

impl<I: Indices, V: Vertices> Source for TriF32<I, V> {
    type Prim = [f32; 9];

    #[inline]
    fn get(&self, id: u32) -> Option<[f32; 9]> {
        let (f, ok) = self.triangle(&self.vertex_indices(id));
        ok.then_some(f)
    }

    /// Decodes and computes the box in one loop; gives up at the first invalid triangle.
    #[inline(always)]
    fn leaf(&self, ids: &[u32], out: &mut [[f32; 9]]) -> Option<Lanes> {
        // (A copy, so that the compiler keeps the fields in registers.)
        let d = *self;
        let mut bounds = Box4::EMPTY;
        for (o, &id) in out.iter_mut().zip(ids) {
            let t = d.index.triple(id.wrapping_sub(d.first) as usize)?;
            let a = d.verts.get(t[0])?;
            let b = d.verts.get(t[1])?;
            let c = d.verts.get(t[2])?;
            if a[0].is_nan() | b[0].is_nan() | c[0].is_nan() {
                return None;
            }
            *o = [a[0], a[1], a[2], b[0], b[1], b[2], c[0], c[1], c[2]];
            grow_triangle(&mut bounds, a, b, c);
        }
        Some(lanes(bounds))
    }
}

/// Any triangle geometry, through the reader (what the general path does).
fn reader_triangle(t: &TriangleReader, p: u32) -> Option<[f32; 9]> {
    if p >= t.primitive_count {
        return None;
    }
    match t.triangle_fast(p) {
        Some(f) if !(f[0].is_nan() || f[3].is_nan() || f[6].is_nan()) => Some(f),
        _ => {
            let v = t.triangle(p).ok()??;
            Some([
                v[0][0], v[0][1], v[0][2], v[1][0], v[1][1], v[1][2], v[2][0], v[2][1], v[2][2],
            ])
        }
    }
}

/// One triangle geometry, decoder chosen at run time.
enum AnyTri<'a> {
    I0(TriF32<NoIndices, Strided<'a>>),
    I2(TriF32<IndexRecords<'a, 6>, Strided<'a>>),
    I4(TriF32<IndexRecords<'a, 12>, Strided<'a>>),
    I0P(TriF32<NoIndices, Packed<'a>>),
    I2P(TriF32<IndexRecords<'a, 6>, Packed<'a>>),
    I4P(TriF32<IndexRecords<'a, 12>, Packed<'a>>),
    Reader(&'a TriangleReader<'a>, u32),
}

impl<'a> AnyTri<'a> {
    fn new(t: &'a TriangleReader<'a>, first: u32) -> Self {
        // The fast decoders need every vertex up to maxVertex and every index in range; a
        // geometry whose buffers are shorter goes through the reader, which says where.
        let Some(l) = t.f32_layout() else {
            return AnyTri::Reader(t, first);
        };
        let n = t.primitive_count as usize;
        let verts_ok = l
            .max_vertex
            .checked_mul(l.vertex_stride)
            .and_then(|e| e.checked_add(12))
            .is_some_and(|e| e <= l.vertex_data.len());
        let index_ok = l.index_data.len() / 3 >= n * l.index_size;
        // (Transformed geometries are rare enough to go through the reader too.)
        if !(verts_ok && index_ok) || l.transform.is_some() {
            return AnyTri::Reader(t, first);
        }
        // The vertices from firstVertex on (vertex `firstVertex + i` is `i` here, so no index
        // needs an addition); none when firstVertex is past maxVertex.
        let fv = l.first_vertex;
        let stride = l.vertex_stride;
        let strided = match l.max_vertex.checked_sub(fv) {
            // (`fv * stride` is within the buffer: `max_vertex * stride + 12` is.)
            Some(last) => Strided {
                data: &l.vertex_data[fv * stride..],
                stride,
                last,
            },
            None => Strided {
                data: &[],
                stride,
                last: 0,
            },
        };
        let packed = || {
            let all: &[[u8; 12]] = bytemuck::cast_slice(&l.vertex_data[..12 * (l.max_vertex + 1)]);
            Packed(&all[fv.min(all.len())..])
        };
        fn tri<I, V>(index: I, verts: V, first: u32) -> TriF32<I, V> {
            TriF32 {
                index,
                verts,
                first,
            }
        }
        let i2 = || IndexRecords::<6>(bytemuck::cast_slice(&l.index_data[..6 * n]));
        let i4 = || IndexRecords::<12>(bytemuck::cast_slice(&l.index_data[..12 * n]));
        match (l.index_size, l.vertex_stride == 12) {
            (0, false) => AnyTri::I0(tri(NoIndices(n), strided, first)),
            (2, false) => AnyTri::I2(tri(i2(), strided, first)),
            (4, false) => AnyTri::I4(tri(i4(), strided, first)),
            (0, true) => AnyTri::I0P(tri(NoIndices(n), packed(), first)),
            (2, true) => AnyTri::I2P(tri(i2(), packed(), first)),
            (4, true) => AnyTri::I4P(tri(i4(), packed(), first)),
            _ => AnyTri::Reader(t, first),
        }
    }
}

impl Source for AnyTri<'_> {
    type Prim = [f32; 9];
    #[inline]
    fn get(&self, id: u32) -> Option<[f32; 9]> {
        match self {
            AnyTri::I0(d) => d.get(id),
            AnyTri::I2(d) => d.get(id),
            AnyTri::I4(d) => d.get(id),
            AnyTri::I0P(d) => d.get(id),
            AnyTri::I2P(d) => d.get(id),
            AnyTri::I4P(d) => d.get(id),
            AnyTri::Reader(t, first) => reader_triangle(t, id.wrapping_sub(*first)),
        }
    }
}

/// Several geometries: the one holding a sequence number is found by binary search.
struct Multi<S> {
    firsts: Vec<u32>,
    geoms: Vec<S>,
}

impl<S: Source> Source for Multi<S> {
    type Prim = S::Prim;
    #[inline]
    fn get(&self, id: u32) -> Option<S::Prim> {
        let g = self.firsts.partition_point(|&f| f <= id).checked_sub(1)?;
        self.geoms.get(g)?.get(id)
    }
}

struct AabbSource<'a> {
    reader: &'a AabbReader<'a>,
    first: u32,
}

impl Source for AabbSource<'_> {
    type Prim = [f32; 6];
    #[inline]
    fn get(&self, id: u32) -> Option<[f32; 6]> {
        let p = id.wrapping_sub(self.first);
        if p >= self.reader.primitive_count {
            return None;
        }
        let b = self.reader.aabb(p).ok()??;
        Some([b.lo[0], b.lo[1], b.lo[2], b.hi[0], b.hi[1], b.hi[2]])
    }
}

/// The stored triangles, already rewritten (by [`in_primitive_order`]): a refit over them only
/// computes the boxes.
struct Written;

impl Source for Written {
    type Prim = [f32; 9];
    const READS_IDS: bool = false;
    /// (Unused: `decode` leaves the stored triangles as they are.)
    fn get(&self, _: u32) -> Option<[f32; 9]> {
        None
    }
    #[inline]
    fn decode(&self, _: &[u32], _: &mut [[f32; 9]]) -> Option<()> {
        Some(())
    }
}

/// The fast path; `None` when it gave up (nothing is reported, the general path takes over).
/// Returns the root bounds. `scratch` is the update's scratch memory
/// ([`crate::layout::plan::update_scratch_size`]).
fn fused(
    bytes: &mut [u8],
    h: &Header,
    prim_kind: PrimKind,
    readers: &[Reader],
    scratch: &mut [u8],
) -> Option<Aabb> {
    let n = h.stored_count as usize;
    let node_count = h.node_count as usize;
    let (head, nodes_part) = bytes.split_at_mut(h.nodes_offset as usize);
    let (head, ids_part) = head.split_at_mut(h.prim_ids_offset as usize);
    let (head, prims_part) = head.split_at_mut(h.prims_offset as usize);
    let geoms = geometry_records(head, h).ok()?;
    let ids: &[u32] = bytemuck::try_cast_slice(ids_part.get(..4 * n)?).ok()?;
    let nodes: &mut [Node] =
        bytemuck::try_cast_slice_mut(nodes_part.get_mut(..NODE_SIZE as usize * node_count)?)
            .ok()?;
    if readers.len() != geoms.len() {
        return None;
    }
    let firsts: Vec<u32> = geoms.iter().map(|g| g.first_primitive).collect();
    match prim_kind {
        PrimKind::Triangles => {
            let prims: &mut [[f32; 9]] =
                bytemuck::try_cast_slice_mut(prims_part.get_mut(..36 * n)?).ok()?;
            let mut geoms = Vec::with_capacity(readers.len());
            for (r, &first) in readers.iter().zip(&firsts) {
                let Reader::Triangles(t) = r else { return None };
                geoms.push(AnyTri::new(t, first));
            }
            if geoms.len() == 1 {
                let tree = Tree { ids, nodes, prims };
                match geoms.pop()? {
                    AnyTri::I0(d) => refit_triangles(tree, d, scratch),
                    AnyTri::I2(d) => refit_triangles(tree, d, scratch),
                    AnyTri::I4(d) => refit_triangles(tree, d, scratch),
                    AnyTri::I0P(d) => refit_triangles(tree, d, scratch),
                    AnyTri::I2P(d) => refit_triangles(tree, d, scratch),
                    AnyTri::I4P(d) => refit_triangles(tree, d, scratch),
                    d @ AnyTri::Reader(..) => tree.refit(&d),
                }
            } else {
                Tree { ids, nodes, prims }.refit(&Multi { firsts, geoms })
            }
        }
        PrimKind::Aabbs => {
            let prims: &mut [[f32; 6]] =
                bytemuck::try_cast_slice_mut(prims_part.get_mut(..24 * n)?).ok()?;
            let mut geoms = Vec::with_capacity(readers.len());
            for (r, &first) in readers.iter().zip(&firsts) {
                let Reader::Aabbs(reader) = r else {
                    return None;
                };
                geoms.push(AabbSource { reader, first });
            }
            Tree { ids, nodes, prims }.refit(&Multi { firsts, geoms })
        }
        _ => None,
    }
}

/// Refits one fast-decoded triangle geometry: on one thread (or on a few, when the leaves'
/// primitives are scattered over the application's buffers, as in a triangle soup) by
/// rewriting the stored triangles first, then computing the boxes from them; on more threads
/// in one pass over the tree, subtrees in parallel. On one thread, a small or a large
/// structure whose stored order follows the application's (a mesh) has its triangles
/// rewritten in stored order (gathered by id); any other in primitive order (scattered to
/// their slots).
fn refit_triangles<I: Indices, V: Vertices>(
    tree: Tree<'_, [f32; 9]>,
    d: TriF32<I, V>,
    scratch: &mut [u8],
) -> Option<Aabb> {
    // The passes before the walk are sequential; the tree walk in leaf order scales with
    // threads (each waits on its own cache misses). On one thread the pass in primitive order
    // reads the application's buffers in sequence and was faster than the walk on every scene
    // measured on the VM (1M soup about 2x, 1M random boxes 1.5x, meshes 1.05-1.15x; on the
    // lent Xeon the soup 1.8x, boxes 1.8x, the conference 1.13x, and the walk the faster on
    // the three small meshes, 1.03-1.12x, where the gather in stored order beats both); on
    // two it is about four times as fast on a 1M soup; from 8 threads on the walk should win
    // (estimated from its speed per thread, not measured).
    let threads = rayon::current_num_threads();
    let scattered = scattered(tree.ids);
    if threads >= 8 || (threads > 1 && !scattered) {
        return tree.refit(&d);
    }
    let Tree { ids, nodes, prims } = tree;
    if prims.len() <= CACHED_MAX_PRIMS && !scattered {
        // The application's buffers of a small mesh stay in the core's caches, where a gather
        // needs no requests ahead, and the stored triangles are written in sequence. On the
        // lent Xeon (five rounds alternated on one lease, against the pass in primitive order):
        // the bunny 1.32x, Sponza 1.22x, Sibenik 1.20x; the conference room (331k) 1.00x.
        // On the VM's Zen 4 (1 MiB of L2, the Xeon's 2 MiB; medians of three): the three
        // 0.94-1.02x, the conference 0.70x.
        in_stored_order::<I, V, false>(&d, ids, prims)?;
    } else if prims.len() >= GATHER_MIN_PRIMS && !scattered {
        // On the VM, against the pass in primitive order: 1M boxes 1.1-1.4x, sphere 1.15-1.2x
        // (no slots to fill and read, the stored triangles written in sequence); a 1M soup,
        // whose gathers each miss the caches, 0.6x; the conference room (331k, most of it
        // in the caches, where the prefetches only add instructions) 0.94x.
        in_stored_order::<I, V, true>(&d, ids, prims)?;
    } else {
        // The stored slot of each primitive, in scratch (4 bytes per primitive, aligned).
        let skip = scratch.as_ptr().align_offset(4).min(scratch.len());
        let slot_bytes = scratch.get_mut(skip..skip + 4 * d.index.len())?;
        let slot: &mut [u32] = bytemuck::try_cast_slice_mut(slot_bytes).ok()?;
        // On the VM: 1M soup +10%, 1M boxes and sphere +25%; the bunny (69k) 10% slower.
        if prims.len() >= PREFETCH_MIN_PRIMS {
            // The slots only where consecutive stored triangles are often far apart in
            // primitive order (a soup); in a mesh the slots written last are still in the
            // caches (the 1M sphere: 6% fewer instructions, no slower).
            let far_slots = 16 * far_pairs(ids, 1 << 14) > SAMPLES;
            in_primitive_order::<I, V, true>(&d, ids, prims, slot, far_slots)?;
        } else {
            in_primitive_order::<I, V, false>(&d, ids, prims, slot, false)?;
        }
    }
    Tree { ids, nodes, prims }.refit(&Written)
}

/// From this many stored triangles (9 MiB of them) the pass in primitive order prefetches.
const PREFETCH_MIN_PRIMS: usize = 1 << 18;

/// Up to this many stored triangles, unless scattered, they are rewritten in stored order
/// with no requests ahead: the application's indices and vertices (about 2.3 MiB with 32-bit
/// indices at two triangles per vertex) stay in a core's caches.
const CACHED_MAX_PRIMS: usize = 1 << 17;

/// From this many stored triangles (18 MiB of them), unless scattered, they are rewritten in
/// stored order, requesting what they read well ahead.
const GATHER_MIN_PRIMS: usize = 1 << 19;

/// Whether consecutive stored primitives are mostly far apart in primitive order (sampled).
fn scattered(ids: &[u32]) -> bool {
    2 * far_pairs(ids, 1 << 16) > SAMPLES
}

/// Pairs of consecutive stored primitives sampled by [`far_pairs`].
const SAMPLES: usize = 1024;

/// How many of [`SAMPLES`] pairs of consecutive stored primitives, evenly spread, are more
/// than `distance` apart in primitive order; none below 2^16 primitives.
fn far_pairs(ids: &[u32], distance: u32) -> usize {
    const MIN: usize = 1 << 16;
    if ids.len() < MIN {
        return 0;
    }
    let step = ids.len() / SAMPLES;
    (0..SAMPLES)
        .filter(|&i| {
            let s = i * step;
            ids[s].abs_diff(ids[s + 1]) > distance
        })
        .count()
}

/// Rewrites the stored triangles (`prims`, ids `ids`) in primitive order: the application's
/// buffers are read in sequence, the stored ones written at random. `None` if any triangle is
/// not valid or the ids are not distinct (the general path then takes over).
// (Not inlined: compiled on its own, its loops keep every pointer and length in a register.)
#[inline(never)]
fn in_primitive_order<I: Indices, V: Vertices, const AHEAD: bool>(
    d: &TriF32<I, V>,
    ids: &[u32],
    prims: &mut [[f32; 9]],
    slot: &mut [u32],
    far_slots: bool,
) -> Option<()> {
    // Both loops write at random (a soup's leaves are scattered over primitive order). With
    // `AHEAD` (structures larger than the caches), the lines they will write (the slots' only
    // with `far_slots`) are requested this many iterations ahead, so that the misses overlap
    // instead of following one another; the last iterations, with nothing left to request,
    // run in a loop of their own.
    const SLOTS_AHEAD: usize = 32;
    const PRIMS_AHEAD: usize = 64;
    let first = d.first;
    slot.fill(NONE);
    let ahead_len = |len: usize, ahead: usize| if AHEAD { len.saturating_sub(ahead) } else { 0 };
    let slots_ahead = if far_slots { SLOTS_AHEAD } else { ids.len() };
    let (head, tail) = ids.split_at(ahead_len(ids.len(), slots_ahead));
    let later = ids.get(SLOTS_AHEAD..).unwrap_or(&[]);
    for (s, (&id, &ahead)) in head.iter().zip(later).enumerate() {
        if let Some(x) = slot.get(ahead.wrapping_sub(first) as usize) {
            prefetch_for_write(x);
        }
        *slot.get_mut(id.wrapping_sub(first) as usize)? = s as u32;
    }
    for (s, &id) in (head.len()..).zip(tail) {
        *slot.get_mut(id.wrapping_sub(first) as usize)? = s as u32;
    }
    // Distinct ids fill as many slots as there are ids.
    let mut empty = 0;
    // (A copy, so that the compiler keeps the fields in registers.)
    let d = *d;
    let (head, tail) = slot.split_at(ahead_len(slot.len(), PRIMS_AHEAD));
    let later = slot.get(PRIMS_AHEAD..).unwrap_or(&[]);
    for ((&s, &ahead), t) in head.iter().zip(later).zip(d.index.triples()) {
        if let Some(x) = prims.get(ahead as usize) {
            // (Both ends: a triangle may straddle two lines.)
            prefetch_for_write(&x[0]);
            prefetch_for_write(&x[8]);
        }
        if s == NONE {
            empty += 1;
        } else {
            d.put(t, s, prims)?;
        }
    }
    for (&s, t) in tail.iter().zip(d.index.triples().skip(head.len())) {
        if s == NONE {
            empty += 1;
        } else {
            d.put(t, s, prims)?;
        }
    }
    (slot.len() - empty == ids.len()).then_some(())
}

/// Rewrites the stored triangles (`prims`, ids `ids`) in stored order, each gathered from the
/// application's buffers by id (with `AHEAD`, what it reads requested well ahead). `None` if
/// any triangle is not valid.
// (Not inlined, as `in_primitive_order`.)
#[inline(never)]
fn in_stored_order<I: Indices, V: Vertices, const AHEAD: bool>(
    d: &TriF32<I, V>,
    ids: &[u32],
    prims: &mut [[f32; 9]],
) -> Option<()> {
    // The reads are scattered and the ids known in advance: the indices of the triangle
    // `INDEX_AHEAD` iterations on are requested, and the vertices of the one `VERTS_AHEAD` on,
    // whose indices were requested long enough before to be in the caches by now. (On the VM,
    // 1M boxes against the pass in primitive order: 32 and 16 ahead 0.93x, 64 and 32 1.17x,
    // 128 and 64 1.13-1.4x, 256 and 128 no better; all three vertices, not only one or two.)
    const INDEX_AHEAD: usize = 128;
    const VERTS_AHEAD: usize = 64;
    // (A copy, so that the compiler keeps the fields in registers.)
    let d = *d;
    let local = |id: u32| id.wrapping_sub(d.first) as usize;
    // (Without `AHEAD`, every triangle is gathered by the second loop, which requests nothing.)
    let head = if AHEAD {
        ids.len().saturating_sub(INDEX_AHEAD)
    } else {
        0
    };
    let (prims_head, prims_tail) = prims.split_at_mut(head.min(prims.len()));
    let index_ahead = ids.get(INDEX_AHEAD..).unwrap_or(&[]);
    let verts_ahead = ids.get(VERTS_AHEAD..).unwrap_or(&[]);
    for (((o, &id), &v), &i) in prims_head
        .iter_mut()
        .zip(ids)
        .zip(verts_ahead)
        .zip(index_ahead)
    {
        d.index.prefetch(local(i));
        if let Some(t) = d.index.triple(local(v)) {
            d.verts.prefetch(t[0]);
            d.verts.prefetch(t[1]);
            d.verts.prefetch(t[2]);
        }
        *o = d.valid(d.index.triple(local(id))?)?;
    }
    for (o, &id) in prims_tail.iter_mut().zip(&ids[head..]) {
        *o = d.valid(d.index.triple(local(id))?)?;
    }
    Some(())
}

/// A slot that holds no stored primitive.
const NONE: u32 = u32::MAX;

impl<I: Indices, V: Vertices> TriF32<I, V> {
    /// Writes the triangle with vertices `t` to stored slot `s`; `None` if it is not valid
    /// (or `s` out of range).
    #[inline(always)]
    fn put(&self, t: [usize; 3], s: u32, prims: &mut [[f32; 9]]) -> Option<()> {
        let f = self.valid(t)?;
        *prims.get_mut(s as usize)? = f;
        Some(())
    }

    /// The stored form of the triangle with vertices `t`; `None` if it is not valid.
    #[inline(always)]
    fn valid(&self, t: [usize; 3]) -> Option<[f32; 9]> {
        let a = self.verts.get(t[0])?;
        let b = self.verts.get(t[1])?;
        let c = self.verts.get(t[2])?;
        if a[0].is_nan() | b[0].is_nan() | c[0].is_nan() {
            return None;
        }
        Some([a[0], a[1], a[2], b[0], b[1], b[2], c[0], c[1], c[2]])
    }
}

/// The parts of a structure a refit touches: all nodes and primitives, or a subtree's.
struct Tree<'t, P> {
    /// Primitive ids of the stored primitives `prims` holds (same length).
    ids: &'t [u32],
    nodes: &'t mut [Node],
    prims: &'t mut [P],
}

/// Subtrees of more nodes than this may be refitted in parallel.
const PARALLEL_NODES: usize = 256;

/// Where a walk over a subtree is: the next node index the depth-first preorder must visit
/// and the next stored primitive, both global.
struct Cursor {
    node: usize,
    prim: usize,
}

impl<P: StoredPrim> Tree<'_, P> {
    /// Refits the whole tree; returns the root bounds (the union of the root's child boxes).
    fn refit<S: Source<Prim = P>>(self, src: &S) -> Option<Aabb> {
        if self.nodes.is_empty() || self.prims.is_empty() {
            // (Both or neither, as View::parse requires.)
            return (self.nodes.is_empty() && self.prims.is_empty()).then_some(Aabb::EMPTY);
        }
        let threads = rayon::current_num_threads();
        // Split subtrees larger than this: some 4 tasks per thread.
        let split = if threads > 1 {
            (self.nodes.len() / (4 * threads)).max(PARALLEL_NODES)
        } else {
            usize::MAX
        };
        self.subtree(src, 0, 0, split, 1)
    }

    /// Refits the subtree rooted at `nodes[0]`, which is global node `node_base` at `depth`
    /// (the root's is 1); its nodes must be exactly `nodes` and its primitives exactly `prims`
    /// (from global `prim_base`). Returns the union of the root's child boxes.
    fn subtree<S: Source<Prim = P>>(
        self,
        src: &S,
        node_base: usize,
        prim_base: usize,
        split: usize,
        depth: u32,
    ) -> Option<Aabb> {
        if self.nodes.len() > split {
            return self.parallel(src, node_base, prim_base, split, depth);
        }
        let Tree { ids, nodes, prims } = self;
        let mut at = Cursor {
            node: node_base + 1,
            prim: prim_base,
        };
        let node_end = node_base + nodes.len();
        let prim_end = prim_base + prims.len();
        let mut w = Walk {
            src,
            ids,
            nodes,
            prims,
            node_base,
            prim_base,
        };
        let b = to_aabb(w.node(node_base, &mut at, 1)?);
        (at.node == node_end && at.prim == prim_end).then_some(b)
    }

    /// Splits the root's used slots into tasks (an inner child's subtree, or a leaf), refits
    /// them in parallel, then sets the root's boxes.
    fn parallel<S: Source<Prim = P>>(
        self,
        src: &S,
        node_base: usize,
        prim_base: usize,
        split: usize,
        depth: u32,
    ) -> Option<Aabb> {
        if depth > MAX_DEPTH {
            return None;
        }
        let Tree { ids, nodes, prims } = self;
        let (root, mut rest) = nodes.split_first_mut()?;
        let node_end = node_base + 1 + rest.len();
        let prim_end = prim_base + prims.len();
        // Per used slot, in slot order: the slot, its first node (inner children) and its
        // first primitive.
        let mut slots: Vec<(usize, Option<usize>, usize)> = Vec::with_capacity(WIDTH);
        for k in 0..WIDTH {
            let c = root.child[k];
            if c == EMPTY_CHILD {
                continue;
            }
            slots.push(if c & LEAF_BIT != 0 {
                (k, None, (c & !LEAF_BIT) as usize)
            } else {
                let c = c as usize;
                (k, Some(c), leftmost_prim(rest, node_base + 1, c)?)
            });
        }
        // Each slot's nodes and primitives run up to the next slot's.
        let mut tasks: Vec<(usize, Tree<P>, usize, usize)> = Vec::with_capacity(slots.len());
        let mut ids_rest = ids;
        let mut prims_rest = prims;
        let mut node_at = node_base + 1;
        let mut prim_at = prim_base;
        for (i, &(k, node_start, prim_start)) in slots.iter().enumerate() {
            let later = &slots[i + 1..];
            let prim_stop = later.first().map_or(prim_end, |s| s.2);
            if prim_start != prim_at
                || prim_stop < prim_at
                || prim_stop - prim_at > prims_rest.len()
            {
                return None;
            }
            let node_len = match node_start {
                None => 0,
                Some(c) => {
                    let stop = later.iter().find_map(|s| s.1).unwrap_or(node_end);
                    if c != node_at || stop <= node_at || stop - node_at > rest.len() {
                        return None;
                    }
                    stop - node_at
                }
            };
            let (mine, tail) = std::mem::take(&mut rest).split_at_mut(node_len);
            rest = tail;
            let (my_ids, ids_tail) = ids_rest.split_at(prim_stop - prim_at);
            ids_rest = ids_tail;
            let (my_prims, prims_tail) =
                std::mem::take(&mut prims_rest).split_at_mut(prim_stop - prim_at);
            prims_rest = prims_tail;
            let t = Tree {
                ids: my_ids,
                nodes: mine,
                prims: my_prims,
            };
            tasks.push((k, t, node_at, prim_at));
            node_at += node_len;
            prim_at = prim_stop;
        }
        if node_at != node_end || prim_at != prim_end {
            return None;
        }
        let count = root.count;
        let boxes: Vec<Option<(usize, Aabb)>> = tasks
            .into_par_iter()
            .map(|(k, t, nb, pb)| {
                let b = if t.nodes.is_empty() {
                    // A leaf: exactly its primitives.
                    let n = count[k] as usize;
                    if t.prims.len() != n || !(1..=MAX_LEAF_SIZE).contains(&n) {
                        return None;
                    }
                    to_aabb(src.leaf(t.ids, t.prims)?)
                } else {
                    t.subtree(src, nb, pb, split, depth + 1)?
                };
                Some((k, b))
            })
            .collect();
        let mut total = Aabb::EMPTY;
        for r in boxes {
            let (k, b) = r?;
            root.set_bounds(k, &b);
            total = total.union(&b);
        }
        Some(total)
    }
}

/// The first stored primitive under node `c` (global; `nodes` starts at global `base`):
/// the leftmost leaf's first primitive.
fn leftmost_prim(nodes: &[Node], base: usize, mut c: usize) -> Option<usize> {
    for _ in 0..=MAX_DEPTH {
        let node = nodes.get(c.checked_sub(base)?)?;
        let k = (0..WIDTH).find(|&k| node.child[k] != EMPTY_CHILD)?;
        let child = node.child[k];
        if child & LEAF_BIT != 0 {
            return Some((child & !LEAF_BIT) as usize);
        }
        c = child as usize;
    }
    None
}

/// A sequential walk over a subtree: `nodes` start at global `node_base`, `prims` (with their
/// `ids`) at global `prim_base`.
struct Walk<'w, 't, S: Source> {
    src: &'w S,
    ids: &'t [u32],
    nodes: &'t mut [Node],
    prims: &'t mut [S::Prim],
    node_base: usize,
    prim_base: usize,
}

impl<S: Source> Walk<'_, '_, S> {
    /// Refits global node `i` and its subtree, depth-first: children must be the next nodes
    /// in preorder (`at.node`) and leaves the next primitives (`at.prim`). Returns the union
    /// of node `i`'s child boxes.
    fn node(&mut self, i: usize, at: &mut Cursor, depth: u32) -> Option<Lanes> {
        if depth > MAX_DEPTH {
            return None;
        }
        let li = i - self.node_base;
        let (child, count) = {
            let n = self.nodes.get(li)?;
            (n.child, n.count)
        };
        let mut total = EMPTY_LANES;
        for k in 0..WIDTH {
            let c = child[k];
            if c == EMPTY_CHILD {
                continue;
            }
            let b = if c & LEAF_BIT != 0 {
                let n = count[k] as usize;
                if (c & !LEAF_BIT) as usize != at.prim || !(1..=MAX_LEAF_SIZE).contains(&n) {
                    return None;
                }
                let leaf = at.prim - self.prim_base..at.prim - self.prim_base + n;
                at.prim += n;
                let ids = if S::READS_IDS {
                    self.ids.get(leaf.clone())?
                } else {
                    &[]
                };
                self.src.leaf(ids, self.prims.get_mut(leaf)?)?
            } else {
                let c = c as usize;
                if c != at.node {
                    return None;
                }
                at.node += 1;
                self.node(c, at, depth + 1)?
            };
            // (Stored as soon as known: one node's boxes are a few cache lines that stay in
            // L1 while its subtrees are walked.)
            self.nodes.get_mut(li)?.set_bounds(k, &to_aabb(b));
            // Aabb::union, in slot order.
            total = (min4(total.0, b.0), max4(total.1, b.1));
        }
        Some(total)
    }
}

// ---------------------------------------------------------------------------------------------
// General path.

/// The update for any layout and any primitive kind: decodes every stored primitive in
/// parallel chunks (reporting the first error in stored order), then refits the nodes in one
/// reverse pass (children always follow their parent).
fn general(
    bytes: &mut [u8],
    h: &Header,
    prim_kind: PrimKind,
    readers: &[Reader],
    instances: &[(InstanceRecord, Aabb)],
    at: Location,
) -> Result<()> {
    let n = h.stored_count as usize;
    let geoms: Vec<GeometryRecord> = geometry_records(bytes, h)?.to_vec();
    let ids: Vec<u32> = prim_ids(bytes, h)?.to_vec();
    let locate = |id: u32| {
        let g = geoms
            .partition_point(|r| r.first_primitive <= id)
            .saturating_sub(1);
        (g, id - geoms[g].first_primitive)
    };
    // New bounds per stored primitive.
    let mut bounds = vec![Aabb::EMPTY; n];
    let size = prim_kind.prim_size() as usize;
    let prims = &mut bytes[h.prims_offset as usize..h.prims_offset as usize + size * n];
    match prim_kind {
        PrimKind::Triangles | PrimKind::Aabbs => {
            // (VUID-03663 was checked by `refit` before the fast path.)
            // One result per chunk (the first error in it), so the error reported is the first
            // in primitive order whatever the thread count.
            const CHUNK: usize = 2048;
            let one = |out: &mut [u8], b: &mut Aabb, id: u32| -> Result<()> {
                let (g, p) = locate(id);
                let at = at.geometry(g).primitive(p);
                let inactive = || {
                    Error::vuid(
                        "VUID-vkBuildAccelerationStructuresKHR-pInfos-03664",
                        at,
                        "an active primitive became inactive in an update",
                    )
                };
                match &readers[g] {
                    Reader::Triangles(t) => {
                        let f = match t.triangle_fast(p) {
                            Some(f) if !(f[0].is_nan() || f[3].is_nan() || f[6].is_nan()) => f,
                            _ => {
                                let v = t.triangle(p)?.ok_or_else(inactive)?;
                                [
                                    v[0][0], v[0][1], v[0][2], v[1][0], v[1][1], v[1][2], v[2][0],
                                    v[2][1], v[2][2],
                                ]
                            }
                        };
                        out.copy_from_slice(bytemuck::cast_slice(&f));
                        *b = triangle_box(&f);
                    }
                    Reader::Aabbs(a) => {
                        let bb = a.aabb(p)?.ok_or_else(inactive)?;
                        out.copy_from_slice(bytemuck::cast_slice(&[
                            bb.lo[0], bb.lo[1], bb.lo[2], bb.hi[0], bb.hi[1], bb.hi[2],
                        ]));
                        *b = bb;
                    }
                    Reader::Instances(_) => {}
                }
                Ok(())
            };
            let results: Vec<Result<()>> = prims
                .par_chunks_mut(size * CHUNK)
                .zip(bounds.par_chunks_mut(CHUNK))
                .zip(ids.par_chunks(CHUNK))
                .map(|((out, b), ids)| {
                    for ((o, bb), &id) in out.chunks_exact_mut(size).zip(b.iter_mut()).zip(ids) {
                        one(o, bb, id)?;
                    }
                    Ok(())
                })
                .collect();
            for r in results {
                r?;
            }
        }
        PrimKind::Instances => {
            // New instances by instance index; every stored one must still be active, and no
            // other may have become active.
            let mut by_id: Vec<Option<usize>> = vec![None; h.primitive_count as usize];
            for (k, (r, _)) in instances.iter().enumerate() {
                if let Some(s) = by_id.get_mut(r.instance_id as usize) {
                    *s = Some(k);
                }
            }
            let mut used = vec![false; instances.len()];
            let recs: &mut [InstanceRecord] =
                bytemuck::try_cast_slice_mut(prims).map_err(misaligned)?;
            for (slot, rec) in recs.iter_mut().enumerate() {
                let id = ids[slot];
                let Some(k) = by_id.get(id as usize).copied().flatten() else {
                    return Err(Error::vuid(
                        "VUID-vkBuildAccelerationStructuresKHR-pInfos-03664",
                        at.geometry(0).primitive(id),
                        "an active instance became inactive in an update",
                    ));
                };
                used[k] = true;
                *rec = instances[k].0;
                bounds[slot] = instances[k].1;
            }
            if let Some(k) = used.iter().position(|u| !u) {
                return Err(Error::vuid(
                    "VUID-vkBuildAccelerationStructuresKHR-pInfos-03663",
                    at.geometry(0).primitive(instances[k].0.instance_id),
                    "an inactive instance became active in an update",
                ));
            }
        }
        PrimKind::None => {}
    }
    // Refit: leaves from primitive bounds, inner children from their node's children.
    let nodes: &mut [Node] = bytemuck::try_cast_slice_mut(
        &mut bytes[h.nodes_offset as usize
            ..h.nodes_offset as usize + NODE_SIZE as usize * h.node_count as usize],
    )
    .map_err(misaligned)?;
    let mut root = Aabb::EMPTY;
    for i in (0..nodes.len()).rev() {
        for k in 0..WIDTH {
            let c = nodes[i].child[k];
            if c == EMPTY_CHILD {
                continue;
            }
            let b = if c & LEAF_BIT != 0 {
                let first = (c & !LEAF_BIT) as usize;
                let count = nodes[i].count[k] as usize;
                bounds[first..first + count]
                    .iter()
                    .fold(Aabb::EMPTY, |a, b| a.union(b))
            } else {
                let child = &nodes[c as usize];
                (0..WIDTH)
                    .filter(|&j| child.child[j] != EMPTY_CHILD)
                    .fold(Aabb::EMPTY, |a, j| a.union(&child.bounds(j)))
            };
            nodes[i].set_bounds(k, &b);
            if i == 0 {
                root = root.union(&b);
            }
        }
    }
    let mut header = *h;
    header.bounds = root;
    bytes[..256].copy_from_slice(bytemuck::bytes_of(&header));
    Ok(())
}

#[cfg(test)]
mod tests {
    //! The fast path against the general path: same bytes and the same result (the same
    //! error, for invalid updates) for every decoder, and whatever the thread count.

    use super::*;
    use crate::device::Device;
    use crate::input::{AabbsData, BuildRangeInfo, Geometry, GeometryData, TrianglesData};
    use crate::layout::plan;
    use crate::layout::view::View;
    use ash::vk;

    struct Rng(u64);
    impl Rng {
        fn f(&mut self) -> f32 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            (self.0 >> 40) as f32 / (1u64 << 24) as f32
        }
        fn below(&mut self, n: usize) -> usize {
            (self.f() * n as f32) as usize % n
        }
    }

    /// A triangle geometry's buffers, vertices `stride` bytes apart.
    #[derive(Clone)]
    struct Tris {
        verts: Vec<u8>,
        stride: usize,
        index: Option<(vk::IndexType, Vec<u8>)>,
        transform: Option<Vec<u8>>,
        max_vertex: u32,
        count: u32,
    }

    impl Tris {
        fn new(r: &mut Rng, count: u32, stride: usize, index: vk::IndexType) -> Tris {
            let n_verts = if index == vk::IndexType::NONE_KHR {
                3 * count as usize
            } else {
                (count as usize + 2).min(60000)
            };
            let mut verts = vec![0u8; n_verts * stride];
            for v in 0..n_verts {
                let c = [r.f() * 50.0, r.f() * 50.0, r.f() * 50.0];
                for k in 0..3 {
                    let at = v * stride + 4 * k;
                    verts[at..at + 4].copy_from_slice(&c[k].to_le_bytes());
                }
            }
            let index = match index {
                vk::IndexType::NONE_KHR => None,
                t => {
                    let size = if t == vk::IndexType::UINT16 { 2 } else { 4 };
                    let mut b = Vec::new();
                    for _ in 0..3 * count {
                        let i = r.below(n_verts) as u32;
                        b.extend_from_slice(&i.to_le_bytes()[..size]);
                    }
                    Some((t, b))
                }
            };
            Tris {
                verts,
                stride,
                index,
                transform: None,
                max_vertex: n_verts as u32 - 1,
                count,
            }
        }
        fn vertex_mut(&mut self, v: usize) -> &mut [u8] {
            &mut self.verts[v * self.stride..v * self.stride + 12]
        }
        /// Moves every vertex a little.
        fn jiggle(&mut self, r: &mut Rng) {
            for v in 0..=self.max_vertex as usize {
                for k in 0..3 {
                    let b = &mut self.vertex_mut(v)[4 * k..4 * k + 4];
                    let x = f32::from_le_bytes([b[0], b[1], b[2], b[3]]) + r.f() - 0.5;
                    b.copy_from_slice(&x.to_le_bytes());
                }
            }
        }
        fn geometry(&self) -> Geometry<'_> {
            Geometry::triangles(
                TrianglesData {
                    vertex_format: vk::Format::R32G32B32_SFLOAT,
                    vertex_data: &self.verts,
                    vertex_stride: self.stride as u64,
                    max_vertex: self.max_vertex,
                    index_type: self.index.as_ref().map_or(vk::IndexType::NONE_KHR, |i| i.0),
                    index_data: self.index.as_ref().map(|i| &i.1[..]),
                    transform_data: self.transform.as_deref(),
                },
                vk::GeometryFlagsKHR::OPAQUE,
            )
        }
    }

    /// A grid of `n` by `n` quads, two triangles each, row by row: the stored order follows
    /// the primitive order (a mesh, not a soup). Without indices each triangle has its own
    /// three vertices.
    fn grid(n: usize, index: vk::IndexType) -> Tris {
        let corner = |i: usize, j: usize| [i as f32, j as f32, ((i * j) % 7) as f32 * 0.1];
        let mut corners = Vec::new();
        let mut triples = Vec::new();
        for j in 0..n {
            for i in 0..n {
                let v = |di: usize, dj: usize| ((j + dj) * (n + 1) + i + di) as u32;
                triples.push([v(0, 0), v(1, 0), v(1, 1)]);
                triples.push([v(0, 0), v(1, 1), v(0, 1)]);
            }
        }
        for j in 0..=n {
            for i in 0..=n {
                corners.push(corner(i, j));
            }
        }
        let (positions, index) = if index == vk::IndexType::NONE_KHR {
            let flat: Vec<[f32; 3]> = triples
                .iter()
                .flatten()
                .map(|&v| corners[v as usize])
                .collect();
            (flat, None)
        } else {
            let bytes = triples
                .iter()
                .flatten()
                .flat_map(|v| v.to_le_bytes())
                .collect();
            (corners, Some((index, bytes)))
        };
        Tris {
            verts: bytemuck::cast_slice(&positions).to_vec(),
            stride: 12,
            index,
            transform: None,
            max_vertex: positions.len() as u32 - 1,
            count: triples.len() as u32,
        }
    }

    fn boxes(r: &mut Rng, count: usize) -> Vec<u8> {
        let mut out = Vec::new();
        for _ in 0..count {
            let lo = [r.f() * 50.0, r.f() * 50.0, r.f() * 50.0];
            let b = [
                lo[0],
                lo[1],
                lo[2],
                lo[0] + r.f(),
                lo[1] + r.f(),
                lo[2] + r.f(),
            ];
            out.extend_from_slice(bytemuck::cast_slice(&b));
        }
        out
    }

    fn ranges(geoms: &[Geometry]) -> Vec<BuildRangeInfo> {
        geoms
            .iter()
            .map(|g| BuildRangeInfo {
                primitive_count: match &g.data {
                    GeometryData::Aabbs(a) => (a.data.len() / a.stride as usize) as u32,
                    _ => 0,
                },
                ..Default::default()
            })
            .collect()
    }

    fn tri_ranges(tris: &[&Tris]) -> Vec<BuildRangeInfo> {
        tris.iter()
            .map(|t| BuildRangeInfo {
                primitive_count: t.count,
                ..Default::default()
            })
            .collect()
    }

    /// The structure's bytes, in 64-byte aligned memory.
    /// Update scratch of the size `build_sizes` reports for the structure `src`.
    fn scratch_for(src: &[u8]) -> Vec<u8> {
        let h: Header = bytemuck::pod_read_unaligned(&src[..256]);
        vec![0; plan::update_scratch_size(h.primitive_count as u64) as usize]
    }

    fn aligned(bytes: &[u8]) -> Vec<Node> {
        let mut buf = vec![Node::EMPTY; bytes.len().div_ceil(256)];
        bytemuck::cast_slice_mut::<Node, u8>(&mut buf)[..bytes.len()].copy_from_slice(bytes);
        buf
    }

    /// The rest of `View::parse`, as `update_one` passes it.
    fn validate(b: &[u8]) -> Result<()> {
        View::parse(b)
            .map(|_| ())
            .map_err(|reason| Error::NotBuilt { handle: 1, reason })
    }

    /// Builds `before`, then updates it to `after` with `refit` on 1, 2 and 4 threads and with
    /// the general path; all must agree (bytes and result). Returns the result.
    fn check(
        before: &[Geometry],
        after: &[Geometry],
        ranges: &[BuildRangeInfo],
        prim_kind: PrimKind,
    ) -> std::result::Result<(), String> {
        let device = Device::new();
        let blas = crate::quick::build(
            &device,
            vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL,
            vk::BuildAccelerationStructureFlagsKHR::ALLOW_UPDATE,
            before,
            ranges,
        )
        .unwrap();
        let src = device.with_bytes(blas, |b| Ok(b.to_vec())).unwrap();
        let at = Location::info(0);
        let readers: Vec<Reader> = after
            .iter()
            .zip(ranges)
            .enumerate()
            .map(|(g, (geom, range))| match &geom.data {
                GeometryData::Triangles(t) => {
                    Reader::Triangles(TriangleReader::new(t, range, at.geometry(g)).unwrap())
                }
                GeometryData::Aabbs(a) => {
                    Reader::Aabbs(AabbReader::new(a, range, at.geometry(g)).unwrap())
                }
                GeometryData::Instances(_) => unreachable!(),
            })
            .collect();
        let run = |f: &dyn Fn(&mut [u8], &Header) -> Result<()>| {
            let mut buf = aligned(&src);
            let bytes = &mut bytemuck::cast_slice_mut::<Node, u8>(&mut buf)[..src.len()];
            let h = *View::parse(bytes).unwrap().header;
            let r = f(bytes, &h).map_err(|e| e.to_string());
            (bytes.to_vec(), r)
        };
        let (want_bytes, general_result) = run(&|b, h| general(b, h, prim_kind, &readers, &[], at));
        // The general path leaves VUID-03663 to `refit`, which checks it first.
        let want = run(&|b, h| check_still_inactive(b, h, &readers, at))
            .1
            .and(general_result.clone());
        // The fast path itself takes every valid update here.
        let fast = run(&|b, h| {
            fused(b, h, prim_kind, &readers, &mut scratch_for(&src))
                .map(|_| ())
                .ok_or(Error::NotSupported(String::new()))
        });
        assert_eq!(fast.1.is_ok(), general_result.is_ok(), "fast path");
        for threads in [1, 2, 4] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            let (bytes, got) = pool.install(|| {
                run(&|b, h| {
                    let mut scratch = scratch_for(&src);
                    refit(b, h, prim_kind, &readers, &[], at, &validate, &mut scratch)
                })
            });
            assert_eq!(got, want, "{threads} threads");
            if got.is_ok() {
                assert!(bytes == want_bytes, "bytes differ on {threads} threads");
            }
        }
        want
    }

    #[test]
    fn every_triangle_decoder_matches_the_general_path() {
        let mut r = Rng(7);
        for (index, stride) in [
            (vk::IndexType::UINT32, 12),
            (vk::IndexType::UINT16, 12),
            (vk::IndexType::NONE_KHR, 12),
            (vk::IndexType::UINT32, 16),
            (vk::IndexType::UINT16, 20),
            (vk::IndexType::NONE_KHR, 24),
        ] {
            // Large enough for the parallel split (some thousand nodes).
            let mut t = Tris::new(&mut r, 30000, stride, index);
            let ranges = tri_ranges(&[&t]);
            let old = t.clone();
            t.jiggle(&mut r);
            // Index values change too (the CTS does that): swap two triangles' indices.
            if let Some((_, idx)) = &mut t.index {
                let s = idx.len() / t.count as usize;
                let (a, b) = idx.split_at_mut(s * 10);
                a[..s].swap_with_slice(&mut b[..s]);
            }
            check(
                &[old.geometry()],
                &[t.geometry()],
                &ranges,
                PrimKind::Triangles,
            )
            .unwrap();
        }
    }

    #[test]
    fn a_first_vertex_offsets_every_index() {
        let mut r = Rng(13);
        for (index, stride) in [
            (vk::IndexType::UINT32, 12),
            (vk::IndexType::UINT16, 16),
            (vk::IndexType::NONE_KHR, 12),
            (vk::IndexType::NONE_KHR, 20),
        ] {
            let fv = 7;
            let mut t = Tris::new(&mut r, 3000, stride, index);
            // firstVertex more vertices at the end, so that every index plus it is in range.
            for _ in 0..fv * stride {
                t.verts.push(0);
            }
            t.max_vertex += fv as u32;
            for v in t.max_vertex as usize + 1 - fv..=t.max_vertex as usize {
                let c = [r.f(), r.f(), r.f()].map(|x| x * 50.0);
                t.vertex_mut(v).copy_from_slice(bytemuck::cast_slice(&c));
            }
            let ranges: Vec<BuildRangeInfo> = tri_ranges(&[&t])
                .into_iter()
                .map(|r| BuildRangeInfo {
                    first_vertex: fv as u32,
                    ..r
                })
                .collect();
            let old = t.clone();
            t.jiggle(&mut r);
            check(
                &[old.geometry()],
                &[t.geometry()],
                &ranges,
                PrimKind::Triangles,
            )
            .unwrap();
            // One index past maxVertex once firstVertex is added (without indices, the range
            // check up front reports it).
            let mut bad = t.clone();
            let Some((ty, idx)) = &mut bad.index else {
                continue;
            };
            let size = if *ty == vk::IndexType::UINT16 { 2 } else { 4 };
            let past = (t.max_vertex + 1 - fv as u32).to_le_bytes();
            idx[3 * size * 100..3 * size * 100 + size].copy_from_slice(&past[..size]);
            let e = check(
                &[old.geometry()],
                &[bad.geometry()],
                &ranges,
                PrimKind::Triangles,
            )
            .unwrap_err();
            assert!(e.contains("maxVertex"), "{e}");
        }
    }

    #[test]
    fn several_geometries_inactive_triangles_and_transforms() {
        let mut r = Rng(11);
        let mut a = Tris::new(&mut r, 5000, 12, vk::IndexType::UINT32);
        let mut b = Tris::new(&mut r, 3000, 16, vk::IndexType::UINT16);
        let mut c = Tris::new(&mut r, 2000, 12, vk::IndexType::NONE_KHR);
        let m: [f32; 12] = [0.5, 0.1, 0.0, 3.0, 0.0, 2.0, 0.3, -1.0, 0.2, 0.0, 1.0, 4.0];
        c.transform = Some(bytemuck::cast_slice(&m).to_vec());
        // Inactive triangles (NaN x) stay inactive.
        let nan = f32::NAN.to_le_bytes();
        a.vertex_mut(3)[..4].copy_from_slice(&nan);
        c.vertex_mut(30)[..4].copy_from_slice(&nan);
        let ranges = tri_ranges(&[&a, &b, &c]);
        let before: Vec<Tris> = [&a, &b, &c].map(|t| t.clone()).to_vec();
        for t in [&mut a, &mut b, &mut c] {
            t.jiggle(&mut r);
        }
        a.vertex_mut(3)[..4].copy_from_slice(&nan);
        c.vertex_mut(30)[..4].copy_from_slice(&nan);
        let geoms_before: Vec<Geometry> = before.iter().map(|t| t.geometry()).collect();
        check(
            &geoms_before,
            &[a.geometry(), b.geometry(), c.geometry()],
            &ranges,
            PrimKind::Triangles,
        )
        .unwrap();
        // A single transformed geometry.
        check(
            &geoms_before[2..],
            &[c.geometry()],
            &ranges[2..],
            PrimKind::Triangles,
        )
        .unwrap();
        // Errors: an inactive triangle made active (03663), active ones made inactive (03664)
        // in two places, an index past maxVertex; each reported as the general path does.
        let mut c2 = c.clone();
        c2.vertex_mut(30)[..4].copy_from_slice(&1.0f32.to_le_bytes());
        let e = check(
            &geoms_before,
            &[a.geometry(), b.geometry(), c2.geometry()],
            &ranges,
            PrimKind::Triangles,
        )
        .unwrap_err();
        assert!(e.contains("03663"), "{e}");
        let mut a2 = a.clone();
        for v in [5usize, 4000] {
            a2.vertex_mut(v)[..4].copy_from_slice(&nan);
        }
        let e = check(
            &geoms_before,
            &[a2.geometry(), b.geometry(), c.geometry()],
            &ranges,
            PrimKind::Triangles,
        )
        .unwrap_err();
        assert!(e.contains("03664"), "{e}");
        let mut b2 = b.clone();
        if let Some((_, idx)) = &mut b2.index {
            idx[600..602].copy_from_slice(&u16::MAX.to_le_bytes());
            idx[60..62].copy_from_slice(&u16::MAX.to_le_bytes());
        }
        let e = check(
            &geoms_before,
            &[a.geometry(), b2.geometry(), c.geometry()],
            &ranges,
            PrimKind::Triangles,
        )
        .unwrap_err();
        assert!(e.contains("maxVertex"), "{e}");
    }

    #[test]
    fn aabbs_match_the_general_path() {
        let mut r = Rng(5);
        let mut data = [boxes(&mut r, 6000), boxes(&mut r, 2500)];
        data[0][..4].copy_from_slice(&f32::NAN.to_le_bytes());
        let geoms = |d: &[Vec<u8>; 2]| -> Vec<Vec<u8>> { d.to_vec() };
        let before = geoms(&data);
        for d in &mut data {
            for (i, b) in d.chunks_exact_mut(24).enumerate().skip(1) {
                let dx = (i % 7) as f32 * 0.01;
                for k in [0, 3] {
                    let x =
                        f32::from_le_bytes([b[4 * k], b[4 * k + 1], b[4 * k + 2], b[4 * k + 3]])
                            + dx;
                    b[4 * k..4 * k + 4].copy_from_slice(&x.to_le_bytes());
                }
            }
        }
        fn g(d: &[Vec<u8>]) -> Vec<Geometry<'_>> {
            d.iter()
                .map(|d| {
                    Geometry::aabbs(
                        AabbsData {
                            data: d,
                            stride: 24,
                        },
                        vk::GeometryFlagsKHR::empty(),
                    )
                })
                .collect()
        }
        let gb = g(&before);
        let ga = g(&data);
        check(&gb, &ga, &ranges(&gb), PrimKind::Aabbs).unwrap();
        // An active box made inactive.
        let mut bad = data.clone();
        bad[1][24 * 2000..24 * 2000 + 4].copy_from_slice(&f32::NAN.to_le_bytes());
        let e = check(&gb, &g(&bad), &ranges(&gb), PrimKind::Aabbs).unwrap_err();
        assert!(e.contains("03664"), "{e}");
    }

    #[test]
    fn a_corrupted_source_is_reported_as_view_parse_reports_it() {
        let mut r = Rng(3);
        let t = Tris::new(&mut r, 20000, 12, vk::IndexType::UINT32);
        let geoms = [t.geometry()];
        let ranges = tri_ranges(&[&t]);
        let device = Device::new();
        let blas = crate::quick::build(
            &device,
            vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL,
            vk::BuildAccelerationStructureFlagsKHR::ALLOW_UPDATE,
            &geoms,
            &ranges,
        )
        .unwrap();
        let src_buf = aligned(&device.with_bytes(blas, |b| Ok(b.to_vec())).unwrap());
        let src: &[u8] = bytemuck::cast_slice(&src_buf);
        let at = Location::info(0);
        let readers = [Reader::Triangles(
            TriangleReader::new(
                match &geoms[0].data {
                    GeometryData::Triangles(d) => d,
                    _ => unreachable!(),
                },
                &ranges[0],
                at.geometry(0),
            )
            .unwrap(),
        )];
        let h = *View::parse(src).unwrap().header;
        let node = |i: usize| h.nodes_offset as usize + 256 * i;
        let child = |i: usize, k: usize| node(i) + 192 + 4 * k;
        let count = |i: usize, k: usize| node(i) + 224 + k;
        // A node whose first slot holds a leaf, and one whose first slot is an inner node.
        let nodes: &[Node] = bytemuck::cast_slice(&src[node(0)..node(h.node_count as usize)]);
        let leaf_node = nodes
            .iter()
            .position(|n| n.child[0] & LEAF_BIT != 0 && n.child[0] != EMPTY_CHILD)
            .unwrap();
        let inner_node = nodes
            .iter()
            .position(|n| n.child[0] & LEAF_BIT == 0)
            .unwrap();
        let patches: Vec<(&str, usize, Vec<u8>)> = vec![
            ("leaf count 0", count(leaf_node, 0), vec![0]),
            ("leaf count 16", count(leaf_node, 0), vec![16]),
            (
                "leaf past the end",
                child(leaf_node, 0),
                (LEAF_BIT | (h.stored_count - 1)).to_le_bytes().to_vec(),
            ),
            (
                "child points back",
                child(inner_node, 0),
                (inner_node as u32).to_le_bytes().to_vec(),
            ),
            (
                "child past the end",
                child(inner_node, 0),
                (h.node_count).to_le_bytes().to_vec(),
            ),
            ("two parents", child(0, 1), 1u32.to_le_bytes().to_vec()),
            (
                "last node unreached",
                child(0, 7),
                EMPTY_CHILD.to_le_bytes().to_vec(),
            ),
            (
                "id out of range",
                h.prim_ids_offset as usize + 4 * 777,
                h.primitive_count.to_le_bytes().to_vec(),
            ),
            (
                "duplicate id",
                h.prim_ids_offset as usize + 4 * 5,
                6u32.to_le_bytes().to_vec(),
            ),
            ("no primitives", 28, 0u32.to_le_bytes().to_vec()),
        ];
        for (what, offset, bytes) in patches {
            let mut bad_buf = src_buf.clone();
            let bad = bytemuck::cast_slice_mut::<Node, u8>(&mut bad_buf);
            bad[offset..offset + bytes.len()].copy_from_slice(&bytes);
            let want = View::parse(bad).err();
            let valid = ["duplicate id", "last node unreached"].contains(&what);
            assert_eq!(want.is_none(), valid, "{what}: {want:?}");
            for threads in [1, 4] {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap();
                let mut buf = aligned(bad);
                let b = &mut bytemuck::cast_slice_mut::<Node, u8>(&mut buf)[..bad.len()];
                let got = match View::parse_sections(b) {
                    Err(e) => Err(e),
                    Ok(v) => {
                        let h = *v.header;
                        let mut scratch =
                            vec![0; plan::update_scratch_size(h.primitive_count as u64) as usize];
                        pool.install(|| {
                            refit(
                                b,
                                &h,
                                PrimKind::Triangles,
                                &readers,
                                &[],
                                at,
                                &validate,
                                &mut scratch,
                            )
                        })
                        .map_err(|e| match e {
                            Error::NotBuilt { reason, .. } => reason,
                            e => format!("not a structure error: {e}"),
                        })
                    }
                };
                match &want {
                    Some(reason) => assert_eq!(got.as_ref().err(), Some(reason), "{what}"),
                    // (Valid for View::parse, but not the encoder's layout: the general path
                    // updates them.)
                    None => assert!(got.is_ok(), "{what}: {got:?}"),
                }
            }
        }
    }

    /// The primitive ids, in stored order, of `t` built with ALLOW_UPDATE (what decides the
    /// one-thread refit path).
    fn stored_ids(t: &Tris, ranges: &[BuildRangeInfo]) -> Vec<u32> {
        let device = Device::new();
        let blas = crate::quick::build(
            &device,
            vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL,
            vk::BuildAccelerationStructureFlagsKHR::ALLOW_UPDATE,
            &[t.geometry()],
            ranges,
        )
        .unwrap();
        let buf = aligned(&device.with_bytes(blas, |b| Ok(b.to_vec())).unwrap());
        View::parse(bytemuck::cast_slice(&buf))
            .unwrap()
            .prim_ids
            .to_vec()
    }

    #[test]
    fn a_soup_is_rewritten_in_primitive_order_with_the_same_result() {
        let mut r = Rng(9);
        for index in [vk::IndexType::UINT32, vk::IndexType::NONE_KHR] {
            // Random triangles: leaf order is unrelated to primitive order.
            let t = Tris::new(&mut r, 300_000, 12, index);
            let ranges = tri_ranges(&[&t]);
            let mut moved = t.clone();
            moved.jiggle(&mut r);
            // (The path is taken: the built tree's ids are scattered.)
            assert!(scattered(&stored_ids(&t, &ranges)));
            check(
                &[t.geometry()],
                &[moved.geometry()],
                &ranges,
                PrimKind::Triangles,
            )
            .unwrap();
            // An active triangle made inactive, an index past maxVertex: reported as the
            // general path does.
            let nan = f32::NAN.to_le_bytes();
            let v0 = match &moved.index {
                Some((_, i)) => u32::from_le_bytes([i[120], i[121], i[122], i[123]]) as usize,
                None => 30,
            };
            moved.vertex_mut(v0)[..4].copy_from_slice(&nan);
            let e = check(
                &[t.geometry()],
                &[moved.geometry()],
                &ranges,
                PrimKind::Triangles,
            )
            .unwrap_err();
            assert!(e.contains("03664"), "{e}");
        }
    }

    #[test]
    fn meshes_of_every_size_are_rewritten_with_the_same_result() {
        let mut r = Rng(21);
        // Three paths by size: 2^17 triangles, as many as the small stored-order one takes
        // (no requests ahead); about 180k, in primitive order (no requests either); 2^19, as
        // many as the large stored-order one needs (requests ahead).
        for (n, index) in [
            (256, vk::IndexType::UINT32),
            (256, vk::IndexType::NONE_KHR),
            (300, vk::IndexType::UINT32),
            (512, vk::IndexType::UINT32),
            (512, vk::IndexType::NONE_KHR),
        ] {
            let t = grid(n, index);
            let ranges = tri_ranges(&[&t]);
            let mut moved = t.clone();
            moved.jiggle(&mut r);
            // (The path is taken: the built tree's ids follow the primitive order.)
            let ids = stored_ids(&t, &ranges);
            let len = ids.len();
            assert!(!scattered(&ids));
            match n {
                256 => assert_eq!(len, CACHED_MAX_PRIMS),
                300 => assert!(CACHED_MAX_PRIMS < len && len < PREFETCH_MIN_PRIMS),
                _ => assert!(len >= GATHER_MIN_PRIMS),
            }
            check(
                &[t.geometry()],
                &[moved.geometry()],
                &ranges,
                PrimKind::Triangles,
            )
            .unwrap();
            // An active triangle made inactive, an index past maxVertex: reported as the
            // general path does.
            let mut bad = moved.clone();
            let last = bad.max_vertex as usize;
            bad.vertex_mut(last)[..4].copy_from_slice(&f32::NAN.to_le_bytes());
            let e = check(
                &[t.geometry()],
                &[bad.geometry()],
                &ranges,
                PrimKind::Triangles,
            )
            .unwrap_err();
            assert!(e.contains("03664"), "{e}");
            let Some((_, idx)) = &mut moved.index else {
                continue;
            };
            idx[4000..4004].copy_from_slice(&(t.max_vertex + 1).to_le_bytes());
            let e = check(
                &[t.geometry()],
                &[moved.geometry()],
                &ranges,
                PrimKind::Triangles,
            )
            .unwrap_err();
            assert!(e.contains("maxVertex"), "{e}");
        }
    }
}
