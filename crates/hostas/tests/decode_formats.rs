//! Decoding of build inputs, checked against values computed in this file.
//!
//! Every supported vertex format × index type × vertex stride × primitiveOffset × firstVertex ×
//! geometry transform is encoded here, by encoders written for this test, into buffers that sit
//! at odd addresses; a BLAS is built through the real commands with `ALLOW_DATA_ACCESS`, one ray
//! per triangle is traced at the triangle's expected centroid, and the committed hit's
//! `triangle_vertex_positions` are compared with the positions the specification's decode rules
//! give (UNORM `c / (2^b - 1)`, SNORM `max(c / (2^(b-1) - 1), -1)`, z = 0 for two components,
//! the fourth component ignored, packed x/y/z in bits 0..9/10..19/20..29, then the transform).
//!
//! AABBs (strides 24/32/40, non-zero offsets) and instances (array and array of pointers, with
//! the 24/8-bit packed fields) are checked the same way, through traced candidates and hits.

use hostas::input::vertex_format::SUPPORTED_VERTEX_FORMATS;
use hostas::{
    AabbsData, AccelerationStructure, AccelerationStructureCreateInfo, BuildGeometryInfo,
    BuildRangeInfo, CandidateType, CommittedType, Device, Geometry, Instance, InstancesData, Ray,
    RayFlags, TrianglesData, vk,
};

// ---------------------------------------------------------------------------------------------
// Helpers: unaligned buffers and the build path.
// ---------------------------------------------------------------------------------------------

/// `len` bytes at an address that is 3 modulo 8 (odd, and not 2-, 4- or 8-aligned), inside a
/// larger allocation, pre-filled with `fill` so that bytes the decoder must not read are garbage.
struct Unaligned {
    storage: Vec<u8>,
    start: usize,
    len: usize,
}

impl Unaligned {
    fn new(len: usize, fill: u8) -> Unaligned {
        let storage = vec![fill; len + 16];
        let addr = storage.as_ptr() as usize;
        let start = (3 + 8 - addr % 8) % 8;
        let u = Unaligned {
            storage,
            start,
            len,
        };
        assert_eq!(u.bytes().as_ptr() as usize % 8, 3);
        u
    }
    fn bytes(&self) -> &[u8] {
        &self.storage[self.start..self.start + self.len]
    }
    fn bytes_mut(&mut self) -> &mut [u8] {
        &mut self.storage[self.start..self.start + self.len]
    }
}

/// Sizes, creates and builds one structure with the Vulkan-shaped commands, scratch at an odd
/// address.
fn build(
    device: &Device,
    ty: vk::AccelerationStructureTypeKHR,
    flags: vk::BuildAccelerationStructureFlagsKHR,
    geometries: &[Geometry],
    ranges: &[BuildRangeInfo],
) -> Result<AccelerationStructure, hostas::Error> {
    let counts: Vec<u32> = ranges.iter().map(|r| r.primitive_count).collect();
    let probe = BuildGeometryInfo::sizes_query(ty, flags, geometries);
    let sizes = device.build_sizes(vk::AccelerationStructureBuildTypeKHR::HOST, &probe, &counts)?;
    let dst = device.create_acceleration_structure(&AccelerationStructureCreateInfo::new(
        ty,
        sizes.acceleration_structure_size,
    ))?;
    let mut scratch = Unaligned::new(sizes.build_scratch_size as usize, 0x5a);
    let info = BuildGeometryInfo::build(ty, flags, geometries, dst, scratch.bytes_mut());
    device.build_acceleration_structures(&mut [info], &[ranges])?;
    Ok(dst)
}

fn blas_flags() -> vk::BuildAccelerationStructureFlagsKHR {
    vk::BuildAccelerationStructureFlagsKHR::ALLOW_DATA_ACCESS
        | vk::BuildAccelerationStructureFlagsKHR::PREFER_FAST_TRACE
}

/// Distance between `x` and the next f32 away from zero.
fn ulp(x: f32) -> f64 {
    let a = x.abs();
    (f32::from_bits(a.to_bits() + 1) as f64) - a as f64
}

// ---------------------------------------------------------------------------------------------
// The test's own description of the vertex formats, and its encoders.
// ---------------------------------------------------------------------------------------------

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    F16,
    F32,
    F64,
    Snorm(u32),
    Unorm(u32),
    /// A2B10G10R10_UNORM_PACK32.
    Packed,
}

#[derive(Clone, Copy, Debug)]
struct Fmt {
    format: vk::Format,
    kind: Kind,
    components: usize,
}

const fn fmt(format: vk::Format, kind: Kind, components: usize) -> Fmt {
    Fmt {
        format,
        kind,
        components,
    }
}

/// Every format the specification lists for acceleration-structure vertex buffers (the mandatory
/// six and the optional ones), plus the 8/16-bit UNORM formats hostas also accepts.
const FORMATS: [Fmt; 22] = [
    fmt(vk::Format::R32G32_SFLOAT, Kind::F32, 2),
    fmt(vk::Format::R32G32B32_SFLOAT, Kind::F32, 3),
    fmt(vk::Format::R32G32B32A32_SFLOAT, Kind::F32, 4),
    fmt(vk::Format::R16G16_SFLOAT, Kind::F16, 2),
    fmt(vk::Format::R16G16B16_SFLOAT, Kind::F16, 3),
    fmt(vk::Format::R16G16B16A16_SFLOAT, Kind::F16, 4),
    fmt(vk::Format::R64G64_SFLOAT, Kind::F64, 2),
    fmt(vk::Format::R64G64B64_SFLOAT, Kind::F64, 3),
    fmt(vk::Format::R64G64B64A64_SFLOAT, Kind::F64, 4),
    fmt(vk::Format::R16G16_SNORM, Kind::Snorm(16), 2),
    fmt(vk::Format::R16G16B16_SNORM, Kind::Snorm(16), 3),
    fmt(vk::Format::R16G16B16A16_SNORM, Kind::Snorm(16), 4),
    fmt(vk::Format::R8G8_SNORM, Kind::Snorm(8), 2),
    fmt(vk::Format::R8G8B8_SNORM, Kind::Snorm(8), 3),
    fmt(vk::Format::R8G8B8A8_SNORM, Kind::Snorm(8), 4),
    fmt(vk::Format::R16G16_UNORM, Kind::Unorm(16), 2),
    fmt(vk::Format::R16G16B16_UNORM, Kind::Unorm(16), 3),
    fmt(vk::Format::R16G16B16A16_UNORM, Kind::Unorm(16), 4),
    fmt(vk::Format::R8G8_UNORM, Kind::Unorm(8), 2),
    fmt(vk::Format::R8G8B8_UNORM, Kind::Unorm(8), 3),
    fmt(vk::Format::R8G8B8A8_UNORM, Kind::Unorm(8), 4),
    fmt(vk::Format::A2B10G10R10_UNORM_PACK32, Kind::Packed, 4),
];

/// Maps a unit value in [0, 1] to a float in [-1, 1] that f16 represents exactly (k/64 - 1).
fn unit_to_float(u: f64) -> f64 {
    (u * 128.0).round() / 64.0 - 1.0
}

impl Fmt {
    fn component_size(&self) -> usize {
        match self.kind {
            Kind::F16 => 2,
            Kind::F32 | Kind::Packed => 4,
            Kind::F64 => 8,
            Kind::Snorm(b) | Kind::Unorm(b) => b as usize / 8,
        }
    }
    fn size(&self) -> usize {
        if self.kind == Kind::Packed {
            4
        } else {
            self.component_size() * self.components
        }
    }
    fn is_float(&self) -> bool {
        matches!(self.kind, Kind::F16 | Kind::F32 | Kind::F64)
    }
    /// How many ulps the decoded value may differ from this file's computation. F16 and F32
    /// values are chosen exactly representable: exact. F64 -> f32 rounding is not pinned by
    /// the spec (Vulkan leaves the rounding direction of float conversions to the
    /// implementation): 1 ulp. Normalized values: `c / m` computed here in f64 then rounded to
    /// f32 can double-round differently from a direct f32 division, and the spec allows
    /// conversions with an error of this order: 1 ulp.
    fn ulp_tolerance(&self) -> f64 {
        match self.kind {
            Kind::F16 | Kind::F32 => 0.0,
            _ => 1.0,
        }
    }

    /// Encodes the unit-space point `u` into `out` (at least `size()` bytes) and returns the
    /// position the specification's decode rules give. The fourth component, when present, gets
    /// a value the decoder must ignore (NaN for float formats; the maximum code otherwise).
    fn encode(&self, u: [f64; 3], out: &mut [u8]) -> [f32; 3] {
        if self.kind == Kind::Packed {
            let c = u.map(|v| (v * 1023.0).round() as u32);
            let word = c[0] | (c[1] << 10) | (c[2] << 20) | (0b10 << 30);
            out[..4].copy_from_slice(&word.to_le_bytes());
            return c.map(|c| (c as f64 / 1023.0) as f32);
        }
        let cs = self.component_size();
        let mut expected = [0f32; 3];
        for k in 0..self.components {
            let value = u.get(k).copied();
            let dst = &mut out[k * cs..(k + 1) * cs];
            let decoded = match self.kind {
                Kind::F16 => {
                    let v = value.map_or(f32::NAN, |u| unit_to_float(u) as f32);
                    dst.copy_from_slice(&half::f16::from_f32(v).to_le_bytes());
                    v
                }
                Kind::F32 => {
                    // Needs more than f16's 11 significant bits: catches a decoder reading
                    // half of the component.
                    let v =
                        value.map_or(f32::NAN, |u| (unit_to_float(u) + (2f64).powi(-20)) as f32);
                    dst.copy_from_slice(&v.to_le_bytes());
                    v
                }
                Kind::F64 => {
                    // Not representable in f32: the decoder must round.
                    let v = value.map_or(f64::NAN, |u| unit_to_float(u) + 1.0e-9);
                    dst.copy_from_slice(&v.to_le_bytes());
                    v as f32
                }
                Kind::Snorm(b) => {
                    let m = (1i64 << (b - 1)) - 1;
                    let c = match value {
                        None => m,
                        // The most negative code decodes to -1, like -m (the max(..., -1) rule).
                        Some(0.0) => -m - 1,
                        Some(u) => ((2.0 * u - 1.0) * m as f64).round() as i64,
                    };
                    dst.copy_from_slice(&c.to_le_bytes()[..cs]);
                    (c as f64 / m as f64).max(-1.0) as f32
                }
                Kind::Unorm(b) => {
                    let m = (1i64 << b) - 1;
                    let c = value.map_or(m, |u| (u * m as f64).round() as i64);
                    dst.copy_from_slice(&c.to_le_bytes()[..cs]);
                    (c as f64 / m as f64) as f32
                }
                Kind::Packed => unreachable!(),
            };
            if k < 3 {
                expected[k] = decoded;
            }
        }
        expected
    }

    /// Overwrites the X component of the vertex at `out` with NaN (float formats only).
    fn poison_x(&self, out: &mut [u8]) {
        match self.kind {
            Kind::F16 => out[..2].copy_from_slice(&half::f16::NAN.to_le_bytes()),
            Kind::F32 => out[..4].copy_from_slice(&f32::NAN.to_le_bytes()),
            Kind::F64 => out[..8].copy_from_slice(&f64::NAN.to_le_bytes()),
            _ => panic!("{:?} has no NaN", self.format),
        }
    }
}

#[test]
fn format_table_matches_the_library() {
    assert_eq!(SUPPORTED_VERTEX_FORMATS.len(), FORMATS.len());
    for f in &FORMATS {
        let lib = SUPPORTED_VERTEX_FORMATS
            .iter()
            .find(|i| i.format == f.format)
            .unwrap_or_else(|| panic!("{:?} not supported", f.format));
        assert_eq!(lib.size as usize, f.size(), "{:?}", f.format);
        assert_eq!(
            lib.component_size as usize,
            f.component_size(),
            "{:?}",
            f.format
        );
        assert_eq!(lib.can_be_nan, f.is_float(), "{:?}", f.format);
    }
}

// ---------------------------------------------------------------------------------------------
// The triangle scene.
// ---------------------------------------------------------------------------------------------

const TRIANGLES: usize = 4;

/// Triangle `t`'s vertices in unit space: one triangle per cell of a 2x2 grid over [0,1]^2,
/// each at its own depth. Vertex 0 of triangle 0 is the origin, so SNORM formats store their
/// most negative code there.
fn unit_triangle(t: usize) -> [[f64; 3]; 3] {
    let (ox, oy) = ((t % 2) as f64 * 0.5, (t / 2) as f64 * 0.5);
    let z = 0.2 + 0.2 * t as f64;
    let a = if t == 0 {
        [0.0, 0.0, z]
    } else {
        [ox + 0.04, oy + 0.04, z]
    };
    [a, [ox + 0.46, oy + 0.1, z], [ox + 0.12, oy + 0.44, z]]
}

/// A non-trivial geometry transform: rotation about z (0.8/0.6), a small shear from z into x and
/// y, a mirroring scale of z, and a translation. Row 2 depends on z only, so every triangle
/// stays in a z = const plane and the rays along -z still reach it.
const TRANSFORM: [f32; 12] = [
    0.8, -0.6, 0.125, 3.0, 0.6, 0.8, -0.0625, -2.0, 0.0, 0.0, -1.5, 0.75,
];
const TRANSFORM_OFFSET: u32 = 32;

/// An expected coordinate: value and allowed absolute error.
#[derive(Clone, Copy, Debug)]
struct Expect {
    value: f64,
    tol: f64,
}

fn expected_position(p: [f32; 3], transform: bool, ulp_tol: f64) -> [Expect; 3] {
    if !transform {
        return p.map(|v| Expect {
            value: v as f64,
            tol: ulp_tol * ulp(v),
        });
    }
    let m = TRANSFORM.map(|v| v as f64);
    let mut out = [Expect {
        value: 0.0,
        tol: 0.0,
    }; 3];
    for (r, o) in out.iter_mut().enumerate() {
        let terms = [
            m[4 * r] * p[0] as f64,
            m[4 * r + 1] * p[1] as f64,
            m[4 * r + 2] * p[2] as f64,
            m[4 * r + 3],
        ];
        let magnitude: f64 = terms.iter().map(|t| t.abs()).sum();
        // The library evaluates three products and three sums in f32: at most six roundings,
        // each of at most eps/2 of a partial result bounded by `magnitude`, so 3 eps; a decode
        // that differs by `ulp_tol` ulps moves the result by at most `ulp_tol` eps more.
        // 4 + 2 * ulp_tol gives a margin without hiding a wrong coefficient or component.
        o.value = terms.iter().sum();
        o.tol = (4.0 + 2.0 * ulp_tol) * f32::EPSILON as f64 * magnitude;
    }
    out
}

#[derive(Clone, Copy, Debug)]
struct Case {
    fmt: Fmt,
    index_type: vk::IndexType,
    padded: bool,
    offset: bool,
    first_vertex: u32,
    transform: bool,
}

/// Vertex permutation for indexed cases: 14 slots, 12 used (5 is coprime to 14).
fn slot_of(i: usize) -> usize {
    (5 * i + 3) % 14
}

struct Built {
    vertices: Unaligned,
    indices: Option<Unaligned>,
    transform: Option<Unaligned>,
    triangles: TrianglesData<'static>,
    range: BuildRangeInfo,
    expected: Vec<[[Expect; 3]; 3]>,
}

/// Encodes the case's buffers; `inactive` makes triangle `inactive` have a NaN X.
fn encode_case(c: &Case, inactive: Option<usize>) -> Built {
    let f = c.fmt;
    let stride = f.size() + if c.padded { 2 * f.component_size() } else { 0 };
    let index_size = match c.index_type {
        vk::IndexType::UINT16 => 2,
        vk::IndexType::UINT32 => 4,
        _ => 0,
    };
    let indexed = index_size != 0;
    let fv = c.first_vertex as usize;
    // A legal, non-zero primitiveOffset that is not a multiple of the stride.
    let primitive_offset = match (c.offset, indexed) {
        (false, _) => 0,
        (true, true) => 3 * index_size,
        (true, false) => 3 * f.component_size(),
    };
    // Where each vertex k of triangle t lives (slot numbers, firstVertex included).
    let slot = |t: usize, k: usize| {
        if indexed {
            fv + slot_of(3 * t + k)
        } else {
            fv + 3 * t + k
        }
    };
    let max_vertex = (0..TRIANGLES)
        .flat_map(|t| (0..3).map(move |k| (t, k)))
        .map(|(t, k)| slot(t, k))
        .max()
        .unwrap_or(0);
    let vertex_base = if indexed { 0 } else { primitive_offset };
    // Exactly as long as the last vertex read: the decoder must not need trailing padding.
    let mut vertices = Unaligned::new(vertex_base + max_vertex * stride + f.size(), 0xab);
    let mut expected = Vec::new();
    for t in 0..TRIANGLES {
        let unit = unit_triangle(t);
        let mut tri = [[Expect {
            value: 0.0,
            tol: 0.0,
        }; 3]; 3];
        for k in 0..3 {
            let at = vertex_base + slot(t, k) * stride;
            let out = &mut vertices.bytes_mut()[at..at + f.size()];
            let decoded = f.encode(unit[k], out);
            if inactive == Some(t) && k == 1 {
                f.poison_x(out);
            }
            tri[k] = expected_position(decoded, c.transform, f.ulp_tolerance());
        }
        expected.push(tri);
    }
    let indices = indexed.then(|| {
        let mut idx = Unaligned::new(primitive_offset + 3 * TRIANGLES * index_size, 0xcd);
        for i in 0..3 * TRIANGLES {
            let raw = slot_of(i) as u32; // firstVertex is added by the decoder
            let at = primitive_offset + i * index_size;
            idx.bytes_mut()[at..at + index_size].copy_from_slice(&raw.to_le_bytes()[..index_size]);
        }
        idx
    });
    let transform = c.transform.then(|| {
        let mut t = Unaligned::new(TRANSFORM_OFFSET as usize + 48, 0xef);
        for (i, v) in TRANSFORM.iter().enumerate() {
            let at = TRANSFORM_OFFSET as usize + 4 * i;
            t.bytes_mut()[at..at + 4].copy_from_slice(&v.to_le_bytes());
        }
        t
    });
    let range = BuildRangeInfo {
        primitive_count: TRIANGLES as u32,
        primitive_offset: primitive_offset as u32,
        first_vertex: c.first_vertex,
        transform_offset: if c.transform { TRANSFORM_OFFSET } else { 0 },
    };
    let triangles = TrianglesData {
        vertex_format: f.format,
        vertex_data: &[],
        vertex_stride: stride as u64,
        max_vertex: max_vertex as u32,
        index_type: c.index_type,
        index_data: None,
        transform_data: None,
    };
    Built {
        vertices,
        indices,
        transform,
        triangles,
        range,
        expected,
    }
}

impl Built {
    fn data(&self) -> TrianglesData<'_> {
        TrianglesData {
            vertex_data: self.vertices.bytes(),
            index_data: self.indices.as_ref().map(|i| i.bytes()),
            transform_data: self.transform.as_ref().map(|t| t.bytes()),
            ..self.triangles
        }
    }
}

fn centroid(tri: &[[Expect; 3]; 3]) -> [f32; 2] {
    let c = |a: usize| ((tri[0][a].value + tri[1][a].value + tri[2][a].value) / 3.0) as f32;
    [c(0), c(1)]
}

fn down_ray(xy: [f32; 2]) -> Ray {
    Ray::new([xy[0], xy[1], 10.0], [0.0, 0.0, -1.0])
}

/// Builds the case, traces every triangle, and returns a description of each mismatch.
fn run_case(device: &Device, c: &Case, inactive: Option<usize>) -> Vec<String> {
    let built = encode_case(c, inactive);
    let geometry = Geometry::triangles(built.data(), vk::GeometryFlagsKHR::OPAQUE);
    let mut errors = Vec::new();
    let blas = match build(
        device,
        vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL,
        blas_flags(),
        &[geometry],
        &[built.range],
    ) {
        Ok(b) => b,
        Err(e) => return vec![format!("{c:?}: build failed: {e}")],
    };
    let tlas = hostas::quick::build_single_instance_tlas(device, blas).expect("tlas");
    {
        let scene = device.scene(tlas).expect("scene");
        for (t, tri) in built.expected.iter().enumerate() {
            let ray = down_ray(centroid(tri));
            let mut q = scene.ray_query(&ray).expect("ray query");
            while q.proceed() {
                let _ = q.confirm_intersection();
            }
            if inactive == Some(t) {
                if q.committed_type() != CommittedType::None {
                    errors.push(format!(
                        "{c:?}: inactive triangle {t}: ray hit primitive {}",
                        q.committed().primitive_index
                    ));
                }
                continue;
            }
            if q.committed_type() != CommittedType::Triangle {
                errors.push(format!("{c:?}: triangle {t}: no hit at its centroid"));
                continue;
            }
            let hit = *q.committed();
            if hit.primitive_index != t as u32 || hit.geometry_index != 0 || hit.instance_id != 0 {
                errors.push(format!(
                    "{c:?}: triangle {t}: hit geometry {} primitive {}",
                    hit.geometry_index, hit.primitive_index
                ));
                continue;
            }
            let got = q.triangle_vertex_positions(true).expect("positions");
            for k in 0..3 {
                for a in 0..3 {
                    let e = tri[k][a];
                    let g = got[k][a] as f64;
                    // NaN-safe: a NaN decode fails too.
                    let ok = (g - e.value).abs() <= e.tol;
                    if !ok {
                        errors.push(format!(
                            "{c:?}: triangle {t} vertex {k} axis {a}: decoded {g} expected {} (tolerance {})",
                            e.value, e.tol
                        ));
                    }
                }
            }
        }
    }
    device
        .destroy_acceleration_structure(tlas)
        .expect("destroy");
    device
        .destroy_acceleration_structure(blas)
        .expect("destroy");
    errors
}

fn all_cases(index_type: vk::IndexType) -> Vec<Case> {
    let mut out = Vec::new();
    for fmt in FORMATS {
        for padded in [false, true] {
            for offset in [false, true] {
                for first_vertex in [0, 5] {
                    for transform in [false, true] {
                        out.push(Case {
                            fmt,
                            index_type,
                            padded,
                            offset,
                            first_vertex,
                            transform,
                        });
                    }
                }
            }
        }
    }
    out
}

fn check_all(index_type: vk::IndexType) {
    let device = Device::new();
    let cases = all_cases(index_type);
    assert_eq!(cases.len(), 22 * 16);
    let errors: Vec<String> = cases
        .iter()
        .flat_map(|c| run_case(&device, c, None))
        .collect();
    assert!(
        errors.is_empty(),
        "{} mismatches, first ones:\n{}",
        errors.len(),
        errors
            .iter()
            .take(20)
            .cloned()
            .collect::<Vec<_>>()
            .join("\n")
    );
}

#[test]
fn every_format_non_indexed() {
    check_all(vk::IndexType::NONE_KHR);
}

#[test]
fn every_format_uint16_indices() {
    check_all(vk::IndexType::UINT16);
}

#[test]
fn every_format_uint32_indices() {
    check_all(vk::IndexType::UINT32);
}

/// The expected values above are not the library's: spot-check a few against hand-computed
/// numbers, so that a shared mistake in this file's encoder would show.
#[test]
fn encoder_spot_checks() {
    let mut b = [0u8; 8];
    let unorm8 = fmt(vk::Format::R8G8B8_UNORM, Kind::Unorm(8), 3);
    assert_eq!(
        unorm8.encode([1.0, 0.0, 0.5], &mut b),
        [1.0, 0.0, 128.0 / 255.0]
    );
    assert_eq!(&b[..3], &[255, 0, 128]);
    let snorm8 = fmt(vk::Format::R8G8_SNORM, Kind::Snorm(8), 2);
    assert_eq!(snorm8.encode([0.0, 1.0, 0.7], &mut b), [-1.0, 1.0, 0.0]);
    assert_eq!(&b[..2], &[0x80, 0x7f]);
    let packed = fmt(vk::Format::A2B10G10R10_UNORM_PACK32, Kind::Packed, 4);
    assert_eq!(packed.encode([1.0, 0.0, 1.0], &mut b), [1.0, 0.0, 1.0]);
    assert_eq!(
        u32::from_le_bytes([b[0], b[1], b[2], b[3]]),
        0x3ff | (0x3ff << 20) | (0b10 << 30)
    );
    let f16 = fmt(vk::Format::R16G16_SFLOAT, Kind::F16, 2);
    assert_eq!(f16.encode([0.75, 0.5, 0.0], &mut b), [0.5, 0.0, 0.0]);
    assert_eq!(&b[..4], &[0x00, 0x38, 0x00, 0x00]);
}

#[test]
fn inactive_triangles_are_skipped_but_counted() {
    let device = Device::new();
    let mut errors = Vec::new();
    for fmt in FORMATS.into_iter().filter(|f| f.is_float()) {
        for index_type in [
            vk::IndexType::NONE_KHR,
            vk::IndexType::UINT16,
            vk::IndexType::UINT32,
        ] {
            for transform in [false, true] {
                let c = Case {
                    fmt,
                    index_type,
                    padded: true,
                    offset: true,
                    first_vertex: 2,
                    transform,
                };
                // Triangle 1 is inactive: the hits on triangles 2 and 3 must still report
                // primitive indices 2 and 3.
                errors.extend(run_case(&device, &c, Some(1)));
            }
        }
    }
    assert!(errors.is_empty(), "{}", errors.join("\n"));
}

fn one_triangle_geometry<'a>(
    format: vk::Format,
    index_type: vk::IndexType,
    data: &'a [u8],
    idx: Option<&'a [u8]>,
) -> [Geometry<'a>; 1] {
    [Geometry::triangles(
        TrianglesData {
            vertex_format: format,
            vertex_data: data,
            vertex_stride: 16,
            max_vertex: 2,
            index_type,
            index_data: idx,
            transform_data: None,
        },
        vk::GeometryFlagsKHR::OPAQUE,
    )]
}

#[test]
fn uint8_indices_are_rejected() {
    let device = Device::new();
    let data = [0u8; 48];
    let idx = [0u8, 1, 2, 0];
    let g = one_triangle_geometry(
        vk::Format::R32G32B32_SFLOAT,
        vk::IndexType::UINT8_KHR,
        &data,
        Some(&idx),
    );
    let range = BuildRangeInfo {
        primitive_count: 1,
        ..Default::default()
    };
    let err = build(
        &device,
        vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL,
        blas_flags(),
        &g,
        &[range],
    )
    .unwrap_err();
    assert!(matches!(err, hostas::Error::Validation { .. }), "{err:?}");
    assert_eq!(
        err.vuid_str(),
        Some("VUID-VkAccelerationStructureGeometryTrianglesDataKHR-indexType-03798")
    );
    // quick::build asks for the sizes first, which already applies this rule (no info index there).
    assert_eq!(err.location().unwrap().geometry, Some(0));
}

#[test]
fn unsupported_vertex_formats_are_rejected() {
    let device = Device::new();
    let data = [0u8; 48];
    for format in [
        vk::Format::R8_UNORM,
        vk::Format::B8G8R8A8_UNORM,
        vk::Format::R32_SFLOAT,
        vk::Format::R16_SFLOAT,
        vk::Format::R32G32B32_UINT,
        vk::Format::R16G16B16A16_SINT,
        vk::Format::R8G8B8A8_SRGB,
        vk::Format::A2R10G10B10_UNORM_PACK32,
        vk::Format::B10G11R11_UFLOAT_PACK32,
        vk::Format::D32_SFLOAT,
        vk::Format::UNDEFINED,
        vk::Format::from_raw(0x7fff_ffff),
    ] {
        let g = one_triangle_geometry(format, vk::IndexType::NONE_KHR, &data, None);
        let range = BuildRangeInfo {
            primitive_count: 1,
            ..Default::default()
        };
        let err = build(
            &device,
            vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL,
            blas_flags(),
            &g,
            &[range],
        )
        .unwrap_err();
        assert!(
            matches!(err, hostas::Error::Validation { .. }),
            "{format:?}: {err:?}"
        );
        assert_eq!(
            err.vuid_str(),
            Some("VUID-VkAccelerationStructureGeometryTrianglesDataKHR-vertexFormat-03797"),
            "{format:?}"
        );
        assert_eq!(err.location().unwrap().geometry, Some(0), "{format:?}");
    }
}

// ---------------------------------------------------------------------------------------------
// AABBs.
// ---------------------------------------------------------------------------------------------

const BOXES: usize = 5;
const INACTIVE_BOX: usize = 2;

/// Box `i`: centred at (3i, 3i, 3i) (so an axis-parallel ray through one centre meets no other
/// box), with its own dyadic half extents.
fn box_of(i: usize) -> ([f32; 3], [f32; 3]) {
    let c = 3.0 * i as f32;
    (
        [c, c, c],
        [0.5 + 0.125 * i as f32, 0.75, 0.25 + 0.0625 * i as f32],
    )
}

#[test]
fn aabbs_with_strides_and_offsets() {
    let device = Device::new();
    for stride in [24usize, 32, 40] {
        for offset in [0usize, 8, 40] {
            let mut data = Unaligned::new(offset + (BOXES - 1) * stride + 24, 0xee);
            for i in 0..BOXES {
                let (c, h) = box_of(i);
                let mut v = [
                    c[0] - h[0],
                    c[1] - h[1],
                    c[2] - h[2],
                    c[0] + h[0],
                    c[1] + h[1],
                    c[2] + h[2],
                ];
                if i == INACTIVE_BOX {
                    // Inactive: minX is NaN; the other bounds are garbage (max < min).
                    v = [f32::NAN, 5.0, 5.0, -5.0, -5.0, -5.0];
                }
                for (k, x) in v.iter().enumerate() {
                    let at = offset + i * stride + 4 * k;
                    data.bytes_mut()[at..at + 4].copy_from_slice(&x.to_le_bytes());
                }
            }
            let g = Geometry::aabbs(
                AabbsData {
                    data: data.bytes(),
                    stride: stride as u64,
                },
                vk::GeometryFlagsKHR::empty(),
            );
            let range = BuildRangeInfo {
                primitive_count: BOXES as u32,
                primitive_offset: offset as u32,
                ..Default::default()
            };
            let blas = build(
                &device,
                vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL,
                blas_flags(),
                &[g],
                &[range],
            )
            .unwrap_or_else(|e| panic!("stride {stride} offset {offset}: {e}"));
            let tlas = hostas::quick::build_single_instance_tlas(&device, blas).expect("tlas");
            let scene = device.scene(tlas).expect("scene");
            for i in 0..BOXES {
                let (c, h) = box_of(i);
                for axis in 0..3 {
                    for sign in [-1.0f32, 1.0] {
                        let mut dir = [0.0f32; 3];
                        dir[axis] = sign;
                        let origin = [
                            c[0] - 100.0 * dir[0],
                            c[1] - 100.0 * dir[1],
                            c[2] - 100.0 * dir[2],
                        ];
                        let mut q = scene.ray_query(&Ray::new(origin, dir)).expect("query");
                        let mut seen = Vec::new();
                        while q.proceed() {
                            assert_eq!(q.candidate_type(), Some(CandidateType::Aabb));
                            seen.push((
                                q.candidate().primitive_index,
                                q.candidate().geometry_index,
                                q.candidate().t,
                            ));
                        }
                        let what = format!(
                            "stride {stride} offset {offset} box {i} axis {axis} sign {sign}"
                        );
                        if i == INACTIVE_BOX {
                            assert!(seen.is_empty(), "{what}: inactive box reported {seen:?}");
                            continue;
                        }
                        assert_eq!(seen.len(), 1, "{what}: {seen:?}");
                        let (prim, geom, t) = seen[0];
                        assert_eq!((prim, geom), (i as u32, 0), "{what}");
                        // The entry distance reveals the bound on this axis and side (the box
                        // may be grown conservatively by a few ulps, hence the tolerance).
                        let expect = 100.0 - h[axis];
                        assert!(
                            (t - expect).abs() <= 1e-3,
                            "{what}: entry t {t}, expected {expect}"
                        );
                    }
                }
            }
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Instances.
// ---------------------------------------------------------------------------------------------

/// This file's own encoder of `VkAccelerationStructureInstanceKHR`.
fn encode_instance(
    rows: [f32; 12],
    custom: u32,
    mask: u8,
    sbt: u32,
    flags: u8,
    reference: u64,
) -> [u8; 64] {
    let mut out = [0u8; 64];
    for (i, v) in rows.iter().enumerate() {
        out[4 * i..4 * i + 4].copy_from_slice(&v.to_le_bytes());
    }
    out[48..52].copy_from_slice(&((custom & 0xff_ffff) | (mask as u32) << 24).to_le_bytes());
    out[52..56].copy_from_slice(&((sbt & 0xff_ffff) | (flags as u32) << 24).to_le_bytes());
    out[56..64].copy_from_slice(&reference.to_le_bytes());
    out
}

#[test]
fn instance_decode_of_hand_written_bytes() {
    let rows = [
        1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0, 10.0, 11.0, 12.0f32,
    ];
    let mut bytes = [0u8; 64];
    for (i, v) in rows.iter().enumerate() {
        bytes[4 * i..4 * i + 4].copy_from_slice(&v.to_le_bytes());
    }
    bytes[48..52].copy_from_slice(&0xab12_3456u32.to_le_bytes());
    bytes[52..56].copy_from_slice(&0xcd65_4321u32.to_le_bytes());
    bytes[56..64].copy_from_slice(&0x0123_4567_89ab_cd00u64.to_le_bytes());
    let inst = Instance::decode(&bytes).expect("64 bytes decode");
    assert_eq!(inst.custom_index, 0x12_3456);
    assert_eq!(inst.mask, 0xab);
    assert_eq!(inst.sbt_record_offset, 0x65_4321);
    assert_eq!(inst.flags, vk::GeometryInstanceFlagsKHR::from_raw(0xcd));
    assert_eq!(inst.acceleration_structure_reference, 0x0123_4567_89ab_cd00);
    assert_eq!(inst.transform.to_rows(), rows);
    // The same bytes from this file's encoder, and back through the library's.
    assert_eq!(
        encode_instance(
            rows,
            0x12_3456,
            0xab,
            0x65_4321,
            0xcd,
            0x0123_4567_89ab_cd00
        ),
        bytes
    );
    assert_eq!(inst.encode(), bytes);
    // Unaligned input, and too-short input.
    let mut shifted = [0u8; 67];
    shifted[3..].copy_from_slice(&bytes);
    assert_eq!(Instance::decode(&shifted[3..]), Some(inst));
    assert_eq!(Instance::decode(&bytes[..63]), None);
}

/// Instance `i` of the TLAS scene: translated to x = 10 i; instance 1 is inactive.
const INSTANCES: usize = 4;
const INACTIVE_INSTANCE: usize = 1;

fn instance_flags(i: usize) -> u8 {
    let f = match i {
        0 => vk::GeometryInstanceFlagsKHR::FORCE_OPAQUE,
        2 => {
            vk::GeometryInstanceFlagsKHR::FORCE_NO_OPAQUE
                | vk::GeometryInstanceFlagsKHR::TRIANGLE_FACING_CULL_DISABLE
        }
        3 => vk::GeometryInstanceFlagsKHR::TRIANGLE_FLIP_FACING,
        _ => vk::GeometryInstanceFlagsKHR::empty(),
    };
    f.as_raw() as u8
}

fn instance_bytes(i: usize, blas: AccelerationStructure) -> [u8; 64] {
    let x = 10.0 * i as f32;
    let rows = [1.0, 0.0, 0.0, x, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0];
    let reference = if i == INACTIVE_INSTANCE {
        0
    } else {
        blas.device_address()
    };
    encode_instance(
        rows,
        0x80_7f00 + i as u32,
        0x80 | (1 << i),
        0xa5_a500 + i as u32,
        instance_flags(i),
        reference,
    )
}

fn check_instance_scene(device: &Device, tlas: AccelerationStructure, what: &str) {
    let scene = device.scene(tlas).expect("scene");
    let mut front = [None; INSTANCES];
    for (i, front) in front.iter_mut().enumerate() {
        let x = 10.0 * i as f32;
        let ray = Ray {
            cull_mask: 0x80,
            ..Ray::new([x, -0.2, 5.0], [0.0, 0.0, -1.0])
        };
        let mut q = scene.ray_query(&ray).expect("query");
        let stopped = q.proceed();
        if i == INACTIVE_INSTANCE {
            assert!(
                !stopped && q.committed_type() == CommittedType::None,
                "{what}: inactive instance hit"
            );
            continue;
        }
        // Instance 0 forces opacity: committed inside proceed. The others are non-opaque (the
        // geometry is, and instance 2 forces it): they stop as candidates.
        let c = if i == 0 {
            assert!(
                !stopped,
                "{what}: FORCE_OPAQUE instance stopped as a candidate"
            );
            assert_eq!(q.committed_type(), CommittedType::Triangle, "{what}");
            *q.committed()
        } else {
            assert!(stopped, "{what}: instance {i} did not stop as a candidate");
            assert!(
                !q.candidate().opaque,
                "{what}: instance {i} candidate is opaque"
            );
            *q.candidate()
        };
        assert_eq!(
            c.instance_id, i as u32,
            "{what}: InstanceId counts inactive instances"
        );
        assert_eq!(c.instance_custom_index, 0x80_7f00 + i as u32, "{what}");
        assert_eq!(c.sbt_record_offset, 0xa5_a500 + i as u32, "{what}");
        assert_eq!((c.geometry_index, c.primitive_index), (0, 0), "{what}");
        *front = Some(c.front_face);
        // Masks: only bit i and bit 7 are set in instance i's mask.
        for j in 0..7 {
            let ray = Ray {
                cull_mask: 1 << j,
                ..ray
            };
            let hit = scene.trace_closest(&ray).expect("trace");
            assert_eq!(
                hit.is_hit(),
                j == i,
                "{what}: instance {i} with cull mask {:#x}",
                1 << j
            );
        }
    }
    // TRIANGLE_FLIP_FACING on instance 3 inverts the facing seen on instance 2.
    assert_eq!(front[0], front[2], "{what}");
    assert_ne!(front[2], front[3], "{what}: TRIANGLE_FLIP_FACING ignored");
    // TRIANGLE_FACING_CULL_DISABLE on instance 2: culling the facing instance 0 shows is ignored
    // there but not on instance 0.
    let cull = if front[0] == Some(true) {
        RayFlags::CULL_FRONT_FACING_TRIANGLES
    } else {
        RayFlags::CULL_BACK_FACING_TRIANGLES
    };
    for (i, expect_hit) in [(0usize, false), (2, true)] {
        let ray = Ray {
            flags: cull,
            ..Ray::new([10.0 * i as f32, -0.2, 5.0], [0.0, 0.0, -1.0])
        };
        assert_eq!(
            scene.trace_closest(&ray).expect("trace").is_hit(),
            expect_hit,
            "{what}: facing cull on instance {i}"
        );
    }
}

fn instance_blas(device: &Device) -> AccelerationStructure {
    let positions: [[f32; 3]; 3] = [[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [0.0, 1.0, 0.0]];
    let g = Geometry::triangles(
        TrianglesData {
            vertex_format: vk::Format::R32G32B32_SFLOAT,
            vertex_data: bytemuck::cast_slice(&positions),
            vertex_stride: 12,
            max_vertex: 2,
            index_type: vk::IndexType::NONE_KHR,
            index_data: None,
            transform_data: None,
        },
        vk::GeometryFlagsKHR::empty(),
    );
    let range = BuildRangeInfo {
        primitive_count: 1,
        ..Default::default()
    };
    build(
        device,
        vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL,
        blas_flags(),
        &[g],
        &[range],
    )
    .expect("blas")
}

#[test]
fn instances_as_array_with_offset() {
    let device = Device::new();
    let blas = instance_blas(&device);
    for offset in [0usize, 16, 80] {
        let mut data = Unaligned::new(offset + 64 * INSTANCES, 0x77);
        for i in 0..INSTANCES {
            data.bytes_mut()[offset + 64 * i..offset + 64 * (i + 1)]
                .copy_from_slice(&instance_bytes(i, blas));
        }
        let g = Geometry::instances(
            InstancesData::Array(data.bytes()),
            vk::GeometryFlagsKHR::empty(),
        );
        let range = BuildRangeInfo {
            primitive_count: INSTANCES as u32,
            primitive_offset: offset as u32,
            ..Default::default()
        };
        let tlas = build(
            &device,
            vk::AccelerationStructureTypeKHR::TOP_LEVEL,
            vk::BuildAccelerationStructureFlagsKHR::PREFER_FAST_TRACE,
            &[g],
            &[range],
        )
        .expect("tlas");
        check_instance_scene(&device, tlas, &format!("array, primitiveOffset {offset}"));
    }
}

#[test]
fn instances_as_pointers_with_offset() {
    let device = Device::new();
    let blas = instance_blas(&device);
    // Each instance in its own odd-addressed allocation.
    let garbage: Vec<Unaligned> = (0..2).map(|_| Unaligned::new(64, 0x99)).collect();
    let records: Vec<Unaligned> = (0..INSTANCES)
        .map(|i| {
            let mut u = Unaligned::new(64, 0);
            u.bytes_mut().copy_from_slice(&instance_bytes(i, blas));
            u
        })
        .collect();
    for skipped in [0usize, 2] {
        // primitiveOffset indexes the pointer array in bytes: 16 skips two pointers.
        let mut ptrs: Vec<&[u8]> = garbage[..skipped].iter().map(|g| g.bytes()).collect();
        ptrs.extend(records.iter().map(|r| r.bytes()));
        let g = Geometry::instances(
            InstancesData::Pointers(&ptrs),
            vk::GeometryFlagsKHR::empty(),
        );
        let range = BuildRangeInfo {
            primitive_count: INSTANCES as u32,
            primitive_offset: 8 * skipped as u32,
            ..Default::default()
        };
        let tlas = build(
            &device,
            vk::AccelerationStructureTypeKHR::TOP_LEVEL,
            vk::BuildAccelerationStructureFlagsKHR::PREFER_FAST_TRACE,
            &[g],
            &[range],
        )
        .expect("tlas");
        check_instance_scene(
            &device,
            tlas,
            &format!("pointers, primitiveOffset {}", 8 * skipped),
        );
    }
}
