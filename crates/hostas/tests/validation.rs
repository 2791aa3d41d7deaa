//! One test per valid-usage rule hostas checks: each builds an input that breaks exactly that
//! rule and asserts the error kind, the VUID and where the error points (info, geometry and
//! primitive index). Per-info rules are broken in the middle info of a three-info call, and
//! per-geometry / per-primitive rules in geometry 1 / primitive 1 or 2, so that the reported
//! indices are meaningful. Every case also runs under `catch_unwind` in
//! `no_invalid_input_panics`.
//!
//! Tests named `unchecked_*` cover rules that an early version did not check (found by these
//! tests, then implemented).

use hostas::{
    AabbsData, AccelerationStructure, AccelerationStructureCreateInfo, Affine, Buffer,
    BuildGeometryInfo, BuildRangeInfo, CandidateType, Device, Error, Geometry, Instance,
    InstancesData, Location, Ray, RayFlags, TrianglesData, vk,
};

// ---------------------------------------------------------------------------------------------
// What a case must produce.
// ---------------------------------------------------------------------------------------------

#[derive(Clone, Copy, Debug)]
enum Want {
    Vuid(&'static str),
    RangeTooShort,
    NotSupported,
}
use Want::{NotSupported, RangeTooShort};

fn vuid(v: &'static str) -> Want {
    Want::Vuid(v)
}

/// The expected `Error::location()`.
#[derive(Clone, Copy, Debug)]
enum At {
    Loc(Location),
    /// `location()` is `None` (errors without a location).
    NoLocation,
    /// Not asserted (a separate test asserts it).
    Unchecked,
}

/// The error names no info (command-level rules, create, rays, build sizes).
const NOWHERE: At = At::Loc(Location::NONE);

fn info(i: usize) -> At {
    At::Loc(Location::info(i))
}
fn geom(i: usize, g: usize) -> At {
    At::Loc(Location::info(i).geometry(g))
}
fn prim(i: usize, g: usize, p: u32) -> At {
    At::Loc(Location::info(i).geometry(g).primitive(p))
}
fn sizes_geom(g: usize) -> At {
    At::Loc(Location {
        geometry: Some(g as u32),
        ..Location::NONE
    })
}

fn expect(name: &str, result: Result<(), Error>, want: Want, at: At) {
    let err = match result {
        Ok(()) => panic!("{name}: the invalid input was accepted"),
        Err(e) => e,
    };
    match want {
        Want::Vuid(v) => {
            assert!(
                matches!(err, Error::Validation { .. }),
                "{name}: not a validation error: {err:?}"
            );
            assert_eq!(err.vuid_str(), Some(v), "{name}: {err}");
            assert_eq!(
                err.vk_result(),
                vk::Result::ERROR_VALIDATION_FAILED_EXT,
                "{name}"
            );
        }
        Want::RangeTooShort => assert!(
            matches!(err, Error::RangeTooShort { .. }),
            "{name}: {err:?}"
        ),
        Want::NotSupported => assert!(matches!(err, Error::NotSupported(_)), "{name}: {err:?}"),
    }
    match at {
        At::Loc(l) => assert_eq!(err.location(), Some(l), "{name}: {err}"),
        At::NoLocation => assert_eq!(err.location(), None, "{name}: {err}"),
        At::Unchecked => {}
    }
}

/// For cases with several variants: all must fail the same way; returns the first result (or
/// the first that differs, so that `expect` reports it).
fn same(results: Vec<Result<(), Error>>) -> Result<(), Error> {
    let mut it = results.into_iter();
    let first = it.next().unwrap_or(Ok(()));
    let Err(e0) = &first else { return first };
    for r in it {
        match &r {
            Ok(()) => return r,
            Err(e)
                if e.vuid_str() != e0.vuid_str()
                    || e.location() != e0.location()
                    || std::mem::discriminant(e) != std::mem::discriminant(e0) =>
            {
                return r;
            }
            Err(_) => {}
        }
    }
    first
}

// ---------------------------------------------------------------------------------------------
// Fixtures.
// ---------------------------------------------------------------------------------------------

const BLAS: vk::AccelerationStructureTypeKHR = vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL;
const TLAS: vk::AccelerationStructureTypeKHR = vk::AccelerationStructureTypeKHR::TOP_LEVEL;
const GENERIC: vk::AccelerationStructureTypeKHR = vk::AccelerationStructureTypeKHR::GENERIC;
const BIG: u64 = 1 << 20;

fn fast() -> vk::BuildAccelerationStructureFlagsKHR {
    vk::BuildAccelerationStructureFlagsKHR::PREFER_FAST_TRACE
}
fn updatable() -> vk::BuildAccelerationStructureFlagsKHR {
    vk::BuildAccelerationStructureFlagsKHR::ALLOW_UPDATE
        | vk::BuildAccelerationStructureFlagsKHR::PREFER_FAST_TRACE
}

/// Two triangles, non-indexed.
static TRI_POS: [[f32; 3]; 6] = [
    [0.0, 0.0, 0.0],
    [1.0, 0.0, 0.0],
    [0.0, 1.0, 0.0],
    [2.0, 0.0, 0.0],
    [3.0, 0.0, 0.0],
    [2.0, 1.0, 0.0],
];
/// The same with triangle 1 inactive (NaN X in its first vertex).
static TRI_POS_INACTIVE_1: [[f32; 3]; 6] = [
    [0.0, 0.0, 0.0],
    [1.0, 0.0, 0.0],
    [0.0, 1.0, 0.0],
    [f32::NAN, 0.0, 0.0],
    [3.0, 0.0, 0.0],
    [2.0, 1.0, 0.0],
];
static IDX32: [u32; 6] = [0, 1, 2, 3, 4, 5];
static IDENTITY_ROWS: [f32; 12] = [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0];
static BOXES: [[f32; 6]; 2] = [
    [0.0, 0.0, 0.0, 1.0, 1.0, 1.0],
    [2.0, 2.0, 2.0, 3.0, 3.0, 3.0],
];
static BOXES_INACTIVE_1: [[f32; 6]; 2] = [
    [0.0, 0.0, 0.0, 1.0, 1.0, 1.0],
    [f32::NAN, 2.0, 2.0, 3.0, 3.0, 3.0],
];

fn bytes_of<T: bytemuck::Pod>(v: &'static [T]) -> &'static [u8] {
    bytemuck::cast_slice(v)
}

fn tri_data() -> TrianglesData<'static> {
    TrianglesData {
        vertex_format: vk::Format::R32G32B32_SFLOAT,
        vertex_data: bytes_of(&TRI_POS),
        vertex_stride: 12,
        max_vertex: 5,
        index_type: vk::IndexType::NONE_KHR,
        index_data: None,
        transform_data: None,
    }
}
fn indexed_data() -> TrianglesData<'static> {
    TrianglesData {
        index_type: vk::IndexType::UINT32,
        index_data: Some(bytes_of(&IDX32)),
        ..tri_data()
    }
}
fn tris(d: TrianglesData<'_>) -> Geometry<'_> {
    Geometry::triangles(d, vk::GeometryFlagsKHR::OPAQUE)
}
fn tri_geom() -> Geometry<'static> {
    tris(tri_data())
}
fn aabb_data() -> AabbsData<'static> {
    AabbsData {
        data: bytes_of(&BOXES),
        stride: 24,
    }
}
fn aabb_geom() -> Geometry<'static> {
    Geometry::aabbs(aabb_data(), vk::GeometryFlagsKHR::empty())
}
fn r(n: u32) -> BuildRangeInfo {
    BuildRangeInfo {
        primitive_count: n,
        ..Default::default()
    }
}

fn create(
    device: &Device,
    ty: vk::AccelerationStructureTypeKHR,
    size: u64,
) -> AccelerationStructure {
    device
        .create_acceleration_structure(&AccelerationStructureCreateInfo::new(ty, size))
        .expect("create")
}

/// Runs `bad` as info 1 between two valid bottom-level builds.
fn with_neighbours(
    device: &Device,
    bad: BuildGeometryInfo,
    bad_ranges: &[BuildRangeInfo],
) -> Result<(), Error> {
    let g = [tri_geom()];
    let ranges = [r(2)];
    let (d0, d2) = (create(device, BLAS, BIG), create(device, BLAS, BIG));
    let (mut s0, mut s2) = (vec![0u8; BIG as usize], vec![0u8; BIG as usize]);
    let mut infos = [
        BuildGeometryInfo::build(BLAS, fast(), &g, d0, &mut s0),
        bad,
        BuildGeometryInfo::build(BLAS, fast(), &g, d2, &mut s2),
    ];
    device.build_acceleration_structures(&mut infos, &[&ranges, bad_ranges, &ranges])
}

/// A build of `geometries` as info 1 of three, into a large GENERIC destination.
fn build_bad_on(
    device: &Device,
    ty: vk::AccelerationStructureTypeKHR,
    flags: vk::BuildAccelerationStructureFlagsKHR,
    geometries: &[Geometry],
    ranges: &[BuildRangeInfo],
) -> Result<(), Error> {
    let dst = create(device, GENERIC, BIG);
    let mut scratch = vec![0u8; BIG as usize];
    with_neighbours(
        device,
        BuildGeometryInfo::build(ty, flags, geometries, dst, &mut scratch),
        ranges,
    )
}

fn build_bad(
    ty: vk::AccelerationStructureTypeKHR,
    flags: vk::BuildAccelerationStructureFlagsKHR,
    geometries: &[Geometry],
    ranges: &[BuildRangeInfo],
) -> Result<(), Error> {
    build_bad_on(&Device::new(), ty, flags, geometries, ranges)
}

/// A bad BLAS whose geometry 1 is `g1` (geometry 0 is valid).
fn blas_geometry_1(g1: Geometry, r1: BuildRangeInfo) -> Result<(), Error> {
    build_bad(BLAS, fast(), &[tri_geom(), g1], &[r(2), r1])
}

fn sizes(
    ty: vk::AccelerationStructureTypeKHR,
    flags: vk::BuildAccelerationStructureFlagsKHR,
    geometries: &[Geometry],
    counts: &[u32],
) -> Result<(), Error> {
    let probe = BuildGeometryInfo::sizes_query(ty, flags, geometries);
    Device::new()
        .build_sizes(vk::AccelerationStructureBuildTypeKHR::HOST, &probe, counts)
        .map(|_| ())
}

fn build_into(
    device: &Device,
    dst: AccelerationStructure,
    ty: vk::AccelerationStructureTypeKHR,
    flags: vk::BuildAccelerationStructureFlagsKHR,
    geometries: &[Geometry],
    ranges: &[BuildRangeInfo],
) -> Result<(), Error> {
    let mut s = vec![0u8; BIG as usize];
    device.build_acceleration_structures(
        &mut [BuildGeometryInfo::build(ty, flags, geometries, dst, &mut s)],
        &[ranges],
    )
}

/// A structure built from `geometries` into a fresh GENERIC destination.
fn built(
    device: &Device,
    ty: vk::AccelerationStructureTypeKHR,
    flags: vk::BuildAccelerationStructureFlagsKHR,
    geometries: &[Geometry],
    ranges: &[BuildRangeInfo],
) -> AccelerationStructure {
    let d = create(device, GENERIC, BIG);
    build_into(device, d, ty, flags, geometries, ranges).expect("valid build");
    d
}

fn simple_blas(device: &Device) -> AccelerationStructure {
    built(device, BLAS, fast(), &[tri_geom()], &[r(2)])
}

/// Four instances of `blas` (instance 1 inactive), with `edit` applied to instance 2.
fn instances(blas: AccelerationStructure, edit: impl Fn(&mut Instance)) -> Vec<u8> {
    (0..4)
        .flat_map(|i| {
            let mut inst = hostas::quick::instance(
                blas,
                Affine::from_rows([
                    1.0,
                    0.0,
                    0.0,
                    5.0 * i as f32,
                    0.0,
                    1.0,
                    0.0,
                    0.0,
                    0.0,
                    0.0,
                    1.0,
                    0.0,
                ]),
            );
            if i == 1 {
                inst.acceleration_structure_reference = 0;
            }
            if i == 2 {
                edit(&mut inst);
            }
            inst.encode()
        })
        .collect()
}

fn inst_geom(bytes: &[u8]) -> Geometry<'_> {
    Geometry::instances(InstancesData::Array(bytes), vk::GeometryFlagsKHR::empty())
}

/// A TLAS build as info 1 over `bytes` (4 instances).
fn tlas_bad(device: &Device, bytes: &[u8]) -> Result<(), Error> {
    build_bad_on(device, TLAS, fast(), &[inst_geom(bytes)], &[r(4)])
}

/// An update (info 1 of three) with the given pieces.
#[allow(clippy::too_many_arguments)]
fn update_bad(
    device: &Device,
    src: Option<AccelerationStructure>,
    dst: AccelerationStructure,
    ty: vk::AccelerationStructureTypeKHR,
    flags: vk::BuildAccelerationStructureFlagsKHR,
    geometries: &[Geometry],
    ranges: &[BuildRangeInfo],
    scratch: Option<&mut [u8]>,
) -> Result<(), Error> {
    let info = BuildGeometryInfo {
        ty,
        flags,
        mode: vk::BuildAccelerationStructureModeKHR::UPDATE,
        src,
        dst: Some(dst),
        geometries,
        scratch,
    };
    with_neighbours(device, info, ranges)
}

/// Builds an updatable two-geometry BLAS from (`g0`, `g1`) and updates it in place with
/// (`n0`, `n1`).
fn update_two(
    g: [Geometry; 2],
    gr: [BuildRangeInfo; 2],
    n: [Geometry; 2],
    nr: [BuildRangeInfo; 2],
) -> Result<(), Error> {
    let device = Device::new();
    let src = built(&device, BLAS, updatable(), &g, &gr);
    let mut s = vec![0u8; BIG as usize];
    update_bad(
        &device,
        Some(src),
        src,
        BLAS,
        updatable(),
        &n,
        &nr,
        Some(&mut s),
    )
}

/// Whether the structure's memory is still all zero (never written).
fn untouched(device: &Device, a: AccelerationStructure) -> bool {
    let (buffer, offset, size) = device.placement(a).expect("placement");
    let mut bytes = vec![0u8; size as usize];
    buffer.read(offset, &mut bytes).expect("read");
    bytes.iter().all(|&b| b == 0)
}

fn bytes_of_structure(device: &Device, a: AccelerationStructure) -> Vec<u8> {
    let (buffer, offset, size) = device.placement(a).expect("placement");
    let mut bytes = vec![0u8; size as usize];
    buffer.read(offset, &mut bytes).expect("read");
    bytes
}

/// A single-instance scene over a triangle BLAS built with `flags` (one triangle at z = 0
/// around (0.5, 0.5)).
fn triangle_scene(device: &Device, flags: vk::BuildAccelerationStructureFlagsKHR) -> hostas::Scene {
    let blas = built(device, BLAS, flags, &[tri_geom()], &[r(2)]);
    let tlas = hostas::quick::build_single_instance_tlas(device, blas).expect("tlas");
    device.scene(tlas).expect("scene")
}

fn aabb_scene(device: &Device) -> hostas::Scene {
    let blas = built(device, BLAS, fast(), &[aabb_geom()], &[r(2)]);
    let tlas = hostas::quick::build_single_instance_tlas(device, blas).expect("tlas");
    device.scene(tlas).expect("scene")
}

fn down(x: f32, y: f32) -> Ray {
    Ray::new([x, y, 10.0], [0.0, 0.0, -1.0])
}

/// Validates `ray` directly and through a scene's ray query and closest-hit trace: all three
/// must fail the same way.
fn ray_invalid(ray: Ray) -> Result<(), Error> {
    let device = Device::new();
    let scene = triangle_scene(&device, fast());
    same(vec![
        ray.validate(),
        scene.ray_query(&ray).map(|_| ()),
        scene.trace_closest(&ray).map(|_| ()),
    ])
}

// ---------------------------------------------------------------------------------------------
// The rules.
// ---------------------------------------------------------------------------------------------

macro_rules! rules {
    ($( $(#[$attr:meta])* $name:ident: $want:expr, $at:expr => $body:block )*) => {
        $(
            mod $name {
                #[allow(unused_imports)]
                use super::*;
                pub(super) fn case() -> Result<(), Error> $body
                #[test]
                $(#[$attr])*
                fn rule() {
                    super::expect(stringify!($name), case(), $want, $at);
                }
            }
        )*
        /// Every case, for the no-panic sweep.
        const ALL_CASES: &[(&str, fn() -> Result<(), Error>)] = &[$((stringify!($name), $name::case)),*];
    };
}

rules! {
    // ---- VkAccelerationStructureBuildGeometryInfoKHR ----------------------------------------

    type_generic: vuid("VUID-VkAccelerationStructureBuildGeometryInfoKHR-type-03654"), info(1) => {
        build_bad(GENERIC, fast(), &[tri_geom()], &[r(2)])
    }

    type_unknown: vuid("VUID-VkAccelerationStructureBuildGeometryInfoKHR-type-parameter"), info(1) => {
        same(vec![
            build_bad(vk::AccelerationStructureTypeKHR::from_raw(3), fast(), &[tri_geom()], &[r(2)]),
            build_bad(vk::AccelerationStructureTypeKHR::from_raw(-1), fast(), &[tri_geom()], &[r(2)]),
        ])
    }

    flags_fast_trace_and_fast_build: vuid("VUID-VkAccelerationStructureBuildGeometryInfoKHR-flags-03796"), info(1) => {
        let f = vk::BuildAccelerationStructureFlagsKHR::PREFER_FAST_TRACE | vk::BuildAccelerationStructureFlagsKHR::PREFER_FAST_BUILD;
        build_bad(BLAS, f, &[tri_geom()], &[r(2)])
    }

    flags_unsupported: vuid("VUID-VkAccelerationStructureBuildGeometryInfoKHR-flags-parameter"), info(1) => {
        // Motion blur (0x20), micromap and other extension bits, and bits no extension defines.
        same([0x20u32, 0x40, 0x80, 0x100, 0x200, 0x400, 0x1000, 0x4000, 0x8000_0000]
            .into_iter()
            .map(|b| build_bad(BLAS, fast() | vk::BuildAccelerationStructureFlagsKHR::from_raw(b), &[tri_geom()], &[r(2)]))
            .collect())
    }

    geometry_flags_unknown: vuid("VUID-VkAccelerationStructureGeometryKHR-flags-parameter"), geom(1, 1) => {
        same([0x4u32, 0x8000_0000]
            .into_iter()
            .map(|b| {
                let g1 = Geometry { flags: vk::GeometryFlagsKHR::from_raw(b) | vk::GeometryFlagsKHR::OPAQUE, ..tri_geom() };
                blas_geometry_1(g1, r(2))
            })
            .collect())
    }

    tlas_with_triangles: vuid("VUID-VkAccelerationStructureBuildGeometryInfoKHR-type-03789"), geom(1, 0) => {
        build_bad(TLAS, fast(), &[tri_geom()], &[r(2)])
    }

    tlas_geometry_count_not_one: vuid("VUID-VkAccelerationStructureBuildGeometryInfoKHR-type-03790"), info(1) => {
        let device = Device::new();
        let blas = simple_blas(&device);
        let bytes = instances(blas, |_| {});
        same(vec![
            build_bad_on(&device, TLAS, fast(), &[inst_geom(&bytes), inst_geom(&bytes)], &[r(4), r(4)]),
            build_bad_on(&device, TLAS, fast(), &[], &[]),
        ])
    }

    blas_with_instances: vuid("VUID-VkAccelerationStructureBuildGeometryInfoKHR-type-03791"), geom(1, 1) => {
        let device = Device::new();
        let blas = simple_blas(&device);
        let bytes = instances(blas, |_| {});
        build_bad_on(&device, BLAS, fast(), &[tri_geom(), inst_geom(&bytes)], &[r(2), r(4)])
    }

    mixed_geometry_types: vuid("VUID-VkAccelerationStructureBuildGeometryInfoKHR-type-03792"), geom(1, 1) => {
        same(vec![
            build_bad(BLAS, fast(), &[tri_geom(), aabb_geom()], &[r(2), r(2)]),
            build_bad(BLAS, fast(), &[aabb_geom(), tri_geom()], &[r(2), r(2)]),
        ])
    }

    geometry_count_exceeds_limit: vuid("VUID-VkAccelerationStructureBuildGeometryInfoKHR-type-03793"), NOWHERE => {
        // maxGeometryCount is 2^24 - 1. Only the sizes query: it reads no geometry data.
        let n = Device::new().properties().max_geometry_count as usize + 1;
        let geometries = vec![tri_geom(); n];
        sizes(BLAS, fast(), &geometries, &[])
    }

    too_many_triangles: vuid("VUID-VkAccelerationStructureBuildGeometryInfoKHR-type-03795"), info(1) => {
        // The total over geometries counts: 2 * 2^28 = maxPrimitiveCount + 1. Indexed, so no
        // maxVertex rule fires first; nothing is read before the count check.
        let half = 1u32 << 28;
        build_bad(BLAS, fast(), &[tris(indexed_data()), tris(indexed_data())], &[r(half), r(half)])
    }

    too_many_triangles_sizes: vuid("VUID-VkAccelerationStructureBuildGeometryInfoKHR-type-03795"), NOWHERE => {
        let half = 1u32 << 28;
        sizes(BLAS, fast(), &[tris(indexed_data()), tri_geom()], &[half, half])
    }

    too_many_aabbs: vuid("VUID-VkAccelerationStructureBuildGeometryInfoKHR-type-03794"), info(1) => {
        let half = 1u32 << 28;
        build_bad(BLAS, fast(), &[aabb_geom(), aabb_geom()], &[r(half), r(half)])
    }

    too_many_aabbs_sizes: vuid("VUID-VkAccelerationStructureBuildGeometryInfoKHR-type-03794"), NOWHERE => {
        let half = 1u32 << 28;
        sizes(BLAS, fast(), &[aabb_geom(), aabb_geom()], &[half, half])
    }

    too_many_instances: vuid("VUID-vkBuildAccelerationStructuresKHR-pInfos-03801"), info(1) => {
        let n = Device::new().properties().max_instance_count as u32 + 1;
        build_bad(TLAS, fast(), &[inst_geom(&[])], &[r(n)])
    }

    too_many_instances_sizes: vuid("VUID-vkGetAccelerationStructureBuildSizesKHR-pBuildInfo-03785"), NOWHERE => {
        let n = Device::new().properties().max_instance_count as u32 + 1;
        sizes(TLAS, fast(), &[inst_geom(&[])], &[n])
    }

    // ---- vkGetAccelerationStructureBuildSizesKHR --------------------------------------------

    sizes_count_length_mismatch: vuid("VUID-vkGetAccelerationStructureBuildSizesKHR-pBuildInfo-03619"), NOWHERE => {
        same(vec![
            sizes(BLAS, fast(), &[tri_geom(), tri_geom()], &[2]),
            sizes(BLAS, fast(), &[tri_geom()], &[2, 2]),
            sizes(BLAS, fast(), &[tri_geom()], &[]),
        ])
    }

    sizes_device_build_type: NotSupported, At::NoLocation => {
        let probe = BuildGeometryInfo::sizes_query(BLAS, fast(), &[]);
        Device::new().build_sizes(vk::AccelerationStructureBuildTypeKHR::DEVICE, &probe, &[]).map(|_| ())
    }

    sizes_checks_info_rules: vuid("VUID-VkAccelerationStructureBuildGeometryInfoKHR-type-03654"), NOWHERE => {
        sizes(GENERIC, fast(), &[tri_geom()], &[2])
    }

    sizes_geometry_rule_location: vuid("VUID-VkAccelerationStructureBuildGeometryInfoKHR-type-03792"), sizes_geom(1) => {
        sizes(BLAS, fast(), &[tri_geom(), aabb_geom()], &[2, 2])
    }

    // ---- vkBuildAccelerationStructuresKHR: the call and its destinations ---------------------

    info_count_zero: vuid("VUID-vkBuildAccelerationStructuresKHR-infoCount-arraylength"), NOWHERE => {
        Device::new().build_acceleration_structures(&mut [], &[])
    }

    range_arrays_count_mismatch: vuid("VUID-vkBuildAccelerationStructuresKHR-ppBuildRangeInfos-parameter"), NOWHERE => {
        let device = Device::new();
        let dst = create(&device, BLAS, BIG);
        let mut s = vec![0u8; BIG as usize];
        let g = [tri_geom()];
        let ranges = [r(2)];
        device.build_acceleration_structures(&mut [BuildGeometryInfo::build(BLAS, fast(), &g, dst, &mut s)], &[&ranges, &ranges])
    }

    range_count_mismatch: vuid("VUID-vkBuildAccelerationStructuresKHR-ppBuildRangeInfos-03676"), info(1) => {
        same(vec![
            build_bad(BLAS, fast(), &[tri_geom(), tri_geom()], &[r(2)]),
            build_bad(BLAS, fast(), &[tri_geom()], &[r(2), r(2)]),
        ])
    }

    dst_null: vuid("VUID-vkBuildAccelerationStructuresKHR-dstAccelerationStructure-03800"), info(1) => {
        let device = Device::new();
        let g = [tri_geom()];
        let mut s = vec![0u8; BIG as usize];
        let info = BuildGeometryInfo { dst: None, ..BuildGeometryInfo::build(BLAS, fast(), &g, AccelerationStructure::NULL, &mut s) };
        with_neighbours(&device, info, &[r(2)])
    }

    dst_invalid_handle: vuid("VUID-vkBuildAccelerationStructuresKHR-dstAccelerationStructure-03800"), info(1) => {
        let device = Device::new();
        let other_device = Device::new();
        let destroyed = create(&device, BLAS, BIG);
        device.destroy_acceleration_structure(destroyed).expect("destroy");
        let foreign = create(&other_device, BLAS, BIG);
        let g = [tri_geom()];
        same([AccelerationStructure(0xdead_0000), AccelerationStructure::NULL, destroyed, foreign]
            .into_iter()
            .map(|dst| {
                let mut s = vec![0u8; BIG as usize];
                with_neighbours(&device, BuildGeometryInfo::build(BLAS, fast(), &g, dst, &mut s), &[r(2)])
            })
            .collect())
    }

    dst_twice: vuid("VUID-vkBuildAccelerationStructuresKHR-dstAccelerationStructure-03698"), info(2) => {
        let device = Device::new();
        let a = create(&device, BLAS, BIG);
        let b = create(&device, BLAS, BIG);
        let g = [tri_geom()];
        let ranges = [r(2)];
        let (mut s0, mut s1, mut s2) = (vec![0u8; BIG as usize], vec![0u8; BIG as usize], vec![0u8; BIG as usize]);
        device.build_acceleration_structures(
            &mut [
                BuildGeometryInfo::build(BLAS, fast(), &g, a, &mut s0),
                BuildGeometryInfo::build(BLAS, fast(), &g, b, &mut s1),
                BuildGeometryInfo::build(BLAS, fast(), &g, a, &mut s2),
            ],
            &[&ranges, &ranges, &ranges],
        )
    }

    dst_memory_overlap: vuid("VUID-vkBuildAccelerationStructuresKHR-dstAccelerationStructure-03702"), info(2) => {
        // Two structures in one buffer whose ranges overlap by 256 bytes.
        let device = Device::new();
        let buffer = Buffer::new(2 * BIG).expect("buffer");
        let place = |offset: u64| {
            let ci = AccelerationStructureCreateInfo { buffer: Some(buffer.clone()), offset, ..AccelerationStructureCreateInfo::new(BLAS, BIG) };
            device.create_acceleration_structure(&ci).expect("create")
        };
        let (a, b) = (place(0), place(BIG - 256));
        let c = create(&device, BLAS, BIG);
        let g = [tri_geom()];
        let ranges = [r(2)];
        let (mut s0, mut s1, mut s2) = (vec![0u8; BIG as usize], vec![0u8; BIG as usize], vec![0u8; BIG as usize]);
        device.build_acceleration_structures(
            &mut [
                BuildGeometryInfo::build(BLAS, fast(), &g, a, &mut s0),
                BuildGeometryInfo::build(BLAS, fast(), &g, c, &mut s1),
                BuildGeometryInfo::build(BLAS, fast(), &g, b, &mut s2),
            ],
            &[&ranges, &ranges, &ranges],
        )
    }

    src_is_dst_of_other_info: vuid("VUID-vkBuildAccelerationStructuresKHR-pInfos-03403"), info(1) => {
        // Info 1 updates x into y while info 2 rebuilds x.
        let device = Device::new();
        let g = [tri_geom()];
        let ranges = [r(2)];
        let x = built(&device, BLAS, updatable(), &g, &ranges);
        let (a, y) = (create(&device, BLAS, BIG), create(&device, BLAS, BIG));
        let (mut s0, mut s1, mut s2) = (vec![0u8; BIG as usize], vec![0u8; BIG as usize], vec![0u8; BIG as usize]);
        let update = BuildGeometryInfo { mode: vk::BuildAccelerationStructureModeKHR::UPDATE, src: Some(x), ..BuildGeometryInfo::build(BLAS, updatable(), &g, y, &mut s1) };
        device.build_acceleration_structures(
            &mut [BuildGeometryInfo::build(BLAS, fast(), &g, a, &mut s0), update, BuildGeometryInfo::build(BLAS, updatable(), &g, x, &mut s2)],
            &[&ranges, &ranges, &ranges],
        )
    }

    mode_unknown: vuid("VUID-vkBuildAccelerationStructuresKHR-mode-04628"), info(1) => {
        let device = Device::new();
        let g = [tri_geom()];
        let dst = create(&device, BLAS, BIG);
        let mut s = vec![0u8; BIG as usize];
        let info = BuildGeometryInfo { mode: vk::BuildAccelerationStructureModeKHR::from_raw(2), ..BuildGeometryInfo::build(BLAS, fast(), &g, dst, &mut s) };
        with_neighbours(&device, info, &[r(2)])
    }

    dst_type_blas_for_tlas_build: vuid("VUID-vkBuildAccelerationStructuresKHR-pInfos-03699"), info(1) => {
        let device = Device::new();
        let blas = simple_blas(&device);
        let bytes = instances(blas, |_| {});
        let g = [inst_geom(&bytes)];
        let dst = create(&device, BLAS, BIG);
        let mut s = vec![0u8; BIG as usize];
        with_neighbours(&device, BuildGeometryInfo::build(TLAS, fast(), &g, dst, &mut s), &[r(4)])
    }

    dst_type_tlas_for_blas_build: vuid("VUID-vkBuildAccelerationStructuresKHR-pInfos-03700"), info(1) => {
        let device = Device::new();
        let g = [tri_geom()];
        let dst = create(&device, TLAS, BIG);
        let mut s = vec![0u8; BIG as usize];
        with_neighbours(&device, BuildGeometryInfo::build(BLAS, fast(), &g, dst, &mut s), &[r(2)])
    }

    dst_too_small: vuid("VUID-vkBuildAccelerationStructuresKHR-pInfos-03675"), info(1) => {
        let device = Device::new();
        let g = [tri_geom()];
        let probe = BuildGeometryInfo::sizes_query(BLAS, fast(), &g);
        let need = device.build_sizes(vk::AccelerationStructureBuildTypeKHR::HOST, &probe, &[2]).expect("sizes").acceleration_structure_size;
        let dst = create(&device, BLAS, need - 1);
        let mut s = vec![0u8; BIG as usize];
        with_neighbours(&device, BuildGeometryInfo::build(BLAS, fast(), &g, dst, &mut s), &[r(2)])
    }

    scratch_too_small: vuid("VUID-vkBuildAccelerationStructuresKHR-pInfos-03725"), info(1) => {
        let device = Device::new();
        let g = [tri_geom()];
        let probe = BuildGeometryInfo::sizes_query(BLAS, fast(), &g);
        let need = device.build_sizes(vk::AccelerationStructureBuildTypeKHR::HOST, &probe, &[2]).expect("sizes").build_scratch_size;
        let dst = create(&device, BLAS, BIG);
        let mut s = vec![0u8; need as usize - 1];
        let short = with_neighbours(&device, BuildGeometryInfo::build(BLAS, fast(), &g, dst, &mut s), &[r(2)]);
        let none = with_neighbours(&device, BuildGeometryInfo { scratch: None, ..BuildGeometryInfo::build(BLAS, fast(), &g, dst, &mut []) }, &[r(2)]);
        same(vec![short, none])
    }

    dst_buffer_unbound: vuid("VUID-vkBuildAccelerationStructuresKHR-pInfos-03722"), At::Unchecked => {
        let device = Device::new();
        let ci = AccelerationStructureCreateInfo { buffer: Some(Buffer::new_unbound(BIG)), ..AccelerationStructureCreateInfo::new(BLAS, BIG) };
        let dst = device.create_acceleration_structure(&ci).expect("create");
        let g = [tri_geom()];
        let mut s = vec![0u8; BIG as usize];
        with_neighbours(&device, BuildGeometryInfo::build(BLAS, fast(), &g, dst, &mut s), &[r(2)])
    }

    dst_buffer_unbound_location: vuid("VUID-vkBuildAccelerationStructuresKHR-pInfos-03722"), info(1) => {
        dst_buffer_unbound::case()
    }

    // ---- Triangle geometry ------------------------------------------------------------------

    vertex_format_unsupported: vuid("VUID-VkAccelerationStructureGeometryTrianglesDataKHR-vertexFormat-03797"), geom(1, 1) => {
        same([vk::Format::R8_UNORM, vk::Format::B8G8R8A8_UNORM, vk::Format::R32_SFLOAT, vk::Format::R32G32B32_UINT, vk::Format::UNDEFINED]
            .into_iter()
            .map(|f| blas_geometry_1(tris(TrianglesData { vertex_format: f, ..tri_data() }), r(2)))
            .collect())
    }

    index_type_uint8: vuid("VUID-VkAccelerationStructureGeometryTrianglesDataKHR-indexType-03798"), geom(1, 1) => {
        same([vk::IndexType::UINT8_KHR, vk::IndexType::from_raw(2), vk::IndexType::from_raw(-1)]
            .into_iter()
            .map(|t| blas_geometry_1(tris(TrianglesData { index_type: t, ..indexed_data() }), r(2)))
            .collect())
    }

    vertex_stride_not_multiple: vuid("VUID-VkAccelerationStructureGeometryTrianglesDataKHR-vertexStride-03735"), geom(1, 1) => {
        same(vec![
            blas_geometry_1(tris(TrianglesData { vertex_stride: 14, ..tri_data() }), r(2)),
            blas_geometry_1(tris(TrianglesData { vertex_format: vk::Format::R16G16B16_SFLOAT, vertex_stride: 7, ..tri_data() }), r(2)),
            blas_geometry_1(tris(TrianglesData { vertex_format: vk::Format::R64G64B64_SFLOAT, vertex_stride: 28, ..tri_data() }), r(2)),
        ])
    }

    vertex_stride_too_large: vuid("VUID-VkAccelerationStructureGeometryTrianglesDataKHR-vertexStride-03819"), geom(1, 1) => {
        same(vec![
            blas_geometry_1(tris(TrianglesData { vertex_stride: 1 << 32, ..tri_data() }), r(2)),
            blas_geometry_1(tris(TrianglesData { vertex_stride: u64::MAX - 3, ..tri_data() }), r(2)),
        ])
    }

    index_data_with_index_type_none: vuid("VUID-VkAccelerationStructureGeometryTrianglesDataKHR-indexData-parameter"), geom(1, 1) => {
        blas_geometry_1(tris(TrianglesData { index_type: vk::IndexType::NONE_KHR, ..indexed_data() }), r(2))
    }

    index_data_null: vuid("VUID-vkBuildAccelerationStructuresKHR-pInfos-03772"), geom(1, 1) => {
        blas_geometry_1(tris(TrianglesData { index_data: None, ..indexed_data() }), r(2))
    }

    indexed_primitive_offset_misaligned: vuid("VUID-VkAccelerationStructureBuildRangeInfoKHR-primitiveOffset-03656"), geom(1, 1) => {
        let idx16: &'static [u8] = bytes_of(&IDX32);
        same(vec![
            blas_geometry_1(tris(indexed_data()), BuildRangeInfo { primitive_offset: 2, ..r(1) }),
            blas_geometry_1(tris(TrianglesData { index_type: vk::IndexType::UINT16, index_data: Some(idx16), ..indexed_data() }), BuildRangeInfo { primitive_offset: 1, ..r(1) }),
        ])
    }

    non_indexed_primitive_offset_misaligned: vuid("VUID-VkAccelerationStructureBuildRangeInfoKHR-primitiveOffset-03657"), geom(1, 1) => {
        same(vec![
            blas_geometry_1(tri_geom(), BuildRangeInfo { primitive_offset: 2, ..r(1) }),
            blas_geometry_1(tris(TrianglesData { vertex_format: vk::Format::R16G16B16A16_SFLOAT, vertex_stride: 8, ..tri_data() }), BuildRangeInfo { primitive_offset: 1, ..r(1) }),
            // Packed: the whole 4-byte format is the unit.
            blas_geometry_1(tris(TrianglesData { vertex_format: vk::Format::A2B10G10R10_UNORM_PACK32, vertex_stride: 4, ..tri_data() }), BuildRangeInfo { primitive_offset: 2, ..r(1) }),
        ])
    }

    transform_offset_misaligned: vuid("VUID-VkAccelerationStructureBuildRangeInfoKHR-transformOffset-03658"), geom(1, 1) => {
        let t: &'static [u8] = bytes_of(&IDENTITY_ROWS);
        same([4u32, 8, 12]
            .into_iter()
            .map(|o| blas_geometry_1(tris(TrianglesData { transform_data: Some(t), ..tri_data() }), BuildRangeInfo { transform_offset: o, ..r(2) }))
            .collect())
    }

    max_vertex_non_indexed: vuid("VUID-VkAccelerationStructureBuildRangeInfoKHR-None-10775"), geom(1, 1) => {
        same(vec![
            // firstVertex + 3 * primitiveCount - 1 = 5 > maxVertex 4.
            blas_geometry_1(tris(TrianglesData { max_vertex: 4, ..tri_data() }), r(2)),
            // = 3 > maxVertex 2.
            blas_geometry_1(tris(TrianglesData { max_vertex: 2, ..tri_data() }), BuildRangeInfo { first_vertex: 1, ..r(1) }),
        ])
    }

    max_vertex_indexed: vuid("VUID-VkAccelerationStructureBuildRangeInfoKHR-maxVertex-10774"), prim(1, 1, 1) => {
        same(vec![
            // Triangle 1 uses index 5 > maxVertex 4 (triangle 0 is fine).
            blas_geometry_1(tris(TrianglesData { max_vertex: 4, ..indexed_data() }), r(2)),
            // Index 4 + firstVertex 1 = 5 > maxVertex 4; triangle 0's 0..2 + 1 are fine.
            blas_geometry_1(tris(TrianglesData { max_vertex: 4, ..indexed_data() }), BuildRangeInfo { first_vertex: 1, ..r(2) }),
        ])
    }

    // ---- AABB geometry ----------------------------------------------------------------------

    aabb_stride_not_multiple_of_8: vuid("VUID-VkAccelerationStructureGeometryAabbsDataKHR-stride-03545"), geom(1, 1) => {
        same([4u64, 20, 28, 36]
            .into_iter()
            .map(|s| build_bad(BLAS, fast(), &[aabb_geom(), Geometry::aabbs(AabbsData { stride: s, ..aabb_data() }, vk::GeometryFlagsKHR::empty())], &[r(2), r(1)]))
            .collect())
    }

    aabb_stride_too_large: vuid("VUID-VkAccelerationStructureGeometryAabbsDataKHR-stride-03820"), geom(1, 1) => {
        build_bad(BLAS, fast(), &[aabb_geom(), Geometry::aabbs(AabbsData { stride: 1 << 32, ..aabb_data() }, vk::GeometryFlagsKHR::empty())], &[r(2), r(1)])
    }

    aabb_primitive_offset_misaligned: vuid("VUID-VkAccelerationStructureBuildRangeInfoKHR-primitiveOffset-03659"), geom(1, 1) => {
        same([4u32, 12, 20]
            .into_iter()
            .map(|o| build_bad(BLAS, fast(), &[aabb_geom(), aabb_geom()], &[r(2), BuildRangeInfo { primitive_offset: o, ..r(1) }]))
            .collect())
    }

    aabb_min_x_greater_than_max_x: vuid("VUID-VkAabbPositionsKHR-minX-03546"), prim(1, 1, 1) => {
        static B: [[f32; 6]; 2] = [[0.0, 0.0, 0.0, 1.0, 1.0, 1.0], [3.0, 2.0, 2.0, 2.5, 3.0, 3.0]];
        build_bad(BLAS, fast(), &[aabb_geom(), Geometry::aabbs(AabbsData { data: bytes_of(&B), stride: 24 }, vk::GeometryFlagsKHR::empty())], &[r(2), r(2)])
    }

    aabb_min_y_greater_than_max_y: vuid("VUID-VkAabbPositionsKHR-minY-03547"), prim(1, 1, 1) => {
        static B: [[f32; 6]; 2] = [[0.0, 0.0, 0.0, 1.0, 1.0, 1.0], [2.0, 3.5, 2.0, 3.0, 3.0, 3.0]];
        // NaN in maxY: the comparison fails too (only a NaN minX marks a box inactive).
        static N: [[f32; 6]; 2] = [[0.0, 0.0, 0.0, 1.0, 1.0, 1.0], [2.0, 2.0, 2.0, 3.0, f32::NAN, 3.0]];
        same([&B, &N]
            .into_iter()
            .map(|b| build_bad(BLAS, fast(), &[aabb_geom(), Geometry::aabbs(AabbsData { data: bytes_of(b), stride: 24 }, vk::GeometryFlagsKHR::empty())], &[r(2), r(2)]))
            .collect())
    }

    aabb_min_z_greater_than_max_z: vuid("VUID-VkAabbPositionsKHR-minZ-03548"), prim(1, 1, 1) => {
        static B: [[f32; 6]; 2] = [[0.0, 0.0, 0.0, 1.0, 1.0, 1.0], [2.0, 2.0, 4.0, 3.0, 3.0, 3.0]];
        build_bad(BLAS, fast(), &[aabb_geom(), Geometry::aabbs(AabbsData { data: bytes_of(&B), stride: 24 }, vk::GeometryFlagsKHR::empty())], &[r(2), r(2)])
    }

    // ---- Instance geometry ------------------------------------------------------------------

    instance_primitive_offset_misaligned: vuid("VUID-VkAccelerationStructureBuildRangeInfoKHR-primitiveOffset-03660"), geom(1, 0) => {
        let device = Device::new();
        let blas = simple_blas(&device);
        let mut bytes = vec![0u8; 64];
        bytes.extend(instances(blas, |_| {}));
        same([8u32, 4, 24, 40]
            .into_iter()
            .map(|o| build_bad_on(&device, TLAS, fast(), &[inst_geom(&bytes)], &[BuildRangeInfo { primitive_offset: o, ..r(3) }]))
            .collect())
    }

    instance_force_opaque_and_no_opaque: vuid("VUID-VkAccelerationStructureInstanceKHR-flags-parameter"), prim(1, 0, 2) => {
        let device = Device::new();
        let blas = simple_blas(&device);
        let bytes = instances(blas, |i| i.flags = vk::GeometryInstanceFlagsKHR::FORCE_OPAQUE | vk::GeometryInstanceFlagsKHR::FORCE_NO_OPAQUE);
        tlas_bad(&device, &bytes)
    }

    instance_transform_singular: vuid("VUID-VkTransformMatrixKHR-matrix-03799"), prim(1, 0, 2) => {
        let device = Device::new();
        let blas = simple_blas(&device);
        same([
            [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0f32], // a zero row
            [1.0, 2.0, 0.0, 0.0, 2.0, 4.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0],   // dependent rows
            [0.0; 12],
            [f32::NAN, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0],
        ]
        .into_iter()
        .map(|rows| tlas_bad(&device, &instances(blas, |i| i.transform = Affine::from_rows(rows))))
        .collect())
    }

    instance_reference_unknown_handle: vuid("VUID-vkBuildAccelerationStructuresKHR-pInfos-03779"), prim(1, 0, 2) => {
        let device = Device::new();
        let blas = simple_blas(&device);
        let destroyed = simple_blas(&device);
        device.destroy_acceleration_structure(destroyed).expect("destroy");
        let foreign = simple_blas(&Device::new());
        same([0xdead_0000u64, 1, blas.0 + 256 * 1000, destroyed.0, foreign.0]
            .into_iter()
            .map(|r| tlas_bad(&device, &instances(blas, |i| i.acceleration_structure_reference = r)))
            .collect())
    }

    instance_reference_is_tlas: vuid("VUID-vkBuildAccelerationStructuresKHR-pInfos-03779"), prim(1, 0, 2) => {
        let device = Device::new();
        let blas = simple_blas(&device);
        let tlas = hostas::quick::build_single_instance_tlas(&device, blas).expect("tlas");
        tlas_bad(&device, &instances(blas, |i| i.acceleration_structure_reference = tlas.0))
    }

    instance_reference_unbuilt: vuid("VUID-vkBuildAccelerationStructuresKHR-pInfos-03779"), prim(1, 0, 2) => {
        let device = Device::new();
        let blas = simple_blas(&device);
        let unbuilt = create(&device, BLAS, BIG);
        tlas_bad(&device, &instances(blas, |i| i.acceleration_structure_reference = unbuilt.0))
    }

    instance_reference_buffer_unbound: vuid("VUID-vkBuildAccelerationStructuresKHR-pInfos-03724"), prim(1, 0, 2) => {
        let device = Device::new();
        let blas = simple_blas(&device);
        let ci = AccelerationStructureCreateInfo { buffer: Some(Buffer::new_unbound(BIG)), ..AccelerationStructureCreateInfo::new(BLAS, BIG) };
        let unbound = device.create_acceleration_structure(&ci).expect("create");
        tlas_bad(&device, &instances(blas, |i| i.acceleration_structure_reference = unbound.0))
    }

    instance_reference_is_dst_of_call: vuid("VUID-vkBuildAccelerationStructuresKHR-None-03407"), prim(1, 0, 2) => {
        // Info 1 (the TLAS) references the destination of info 2 (a BLAS being built).
        let device = Device::new();
        let blas = simple_blas(&device);
        let being_built = create(&device, BLAS, BIG);
        let bytes = instances(blas, |i| i.acceleration_structure_reference = being_built.0);
        let (g, gi) = ([tri_geom()], [inst_geom(&bytes)]);
        let (a, t) = (create(&device, BLAS, BIG), create(&device, TLAS, BIG));
        let (mut s0, mut s1, mut s2) = (vec![0u8; BIG as usize], vec![0u8; BIG as usize], vec![0u8; BIG as usize]);
        device.build_acceleration_structures(
            &mut [
                BuildGeometryInfo::build(BLAS, fast(), &g, a, &mut s0),
                BuildGeometryInfo::build(TLAS, fast(), &gi, t, &mut s1),
                BuildGeometryInfo::build(BLAS, fast(), &g, being_built, &mut s2),
            ],
            &[&[r(2)], &[r(4)], &[r(2)]],
        )
    }

    // ---- Input ranges too short -------------------------------------------------------------

    short_vertex_data: RangeTooShort, prim(1, 1, 1) => {
        // Triangle 1's last vertex is cut short by one byte.
        let v = &bytes_of(&TRI_POS)[..71];
        same(vec![
            blas_geometry_1(tris(TrianglesData { vertex_data: v, ..tri_data() }), r(2)),
            blas_geometry_1(tris(TrianglesData { vertex_data: v, ..indexed_data() }), r(2)),
            // The offsets move the reads past the end.
            blas_geometry_1(tri_geom(), BuildRangeInfo { primitive_offset: 4, ..r(2) }),
        ])
    }

    short_index_data: RangeTooShort, prim(1, 1, 1) => {
        let idx = &bytes_of(&IDX32)[..23];
        same(vec![
            blas_geometry_1(tris(TrianglesData { index_data: Some(idx), ..indexed_data() }), r(2)),
            blas_geometry_1(tris(indexed_data()), BuildRangeInfo { primitive_offset: 4, ..r(2) }),
        ])
    }

    short_transform_data: RangeTooShort, geom(1, 1) => {
        let t = bytes_of(&IDENTITY_ROWS);
        same(vec![
            blas_geometry_1(tris(TrianglesData { transform_data: Some(&t[..47]), ..tri_data() }), r(2)),
            blas_geometry_1(tris(TrianglesData { transform_data: Some(t), ..tri_data() }), BuildRangeInfo { transform_offset: 16, ..r(2) }),
        ])
    }

    short_aabb_data: RangeTooShort, prim(1, 1, 1) => {
        let b = &bytes_of(&BOXES)[..47];
        same(vec![
            build_bad(BLAS, fast(), &[aabb_geom(), Geometry::aabbs(AabbsData { data: b, stride: 24 }, vk::GeometryFlagsKHR::empty())], &[r(2), r(2)]),
            build_bad(BLAS, fast(), &[aabb_geom(), Geometry::aabbs(AabbsData { stride: 32, ..aabb_data() }, vk::GeometryFlagsKHR::empty())], &[r(2), r(2)]),
            build_bad(BLAS, fast(), &[aabb_geom(), aabb_geom()], &[r(2), BuildRangeInfo { primitive_offset: 8, ..r(2) }]),
        ])
    }

    short_instance_array: RangeTooShort, prim(1, 0, 2) => {
        let device = Device::new();
        let blas = simple_blas(&device);
        let bytes = instances(blas, |_| {});
        same(vec![
            build_bad_on(&device, TLAS, fast(), &[inst_geom(&bytes[..3 * 64 - 1])], &[r(4)]),
            build_bad_on(&device, TLAS, fast(), &[inst_geom(&bytes[..3 * 64 + 63])], &[BuildRangeInfo { primitive_offset: 64, ..r(3) }]),
        ])
    }

    short_instance_pointers: RangeTooShort, prim(1, 0, 2) => {
        let device = Device::new();
        let blas = simple_blas(&device);
        let bytes = instances(blas, |_| {});
        let records: Vec<&[u8]> = bytes.chunks(64).collect();
        let mut truncated = records.clone();
        truncated[2] = &records[2][..63];
        let run = |ptrs: &[&[u8]], range: BuildRangeInfo| {
            build_bad_on(&device, TLAS, fast(), &[Geometry::instances(InstancesData::Pointers(ptrs), vk::GeometryFlagsKHR::empty())], &[range])
        };
        same(vec![
            // The array of pointers ends after two entries.
            run(&records[..2], r(4)),
            // Skipping two pointers (primitiveOffset 16): entry 2 of the range is past the end.
            run(&records, BuildRangeInfo { primitive_offset: 16, ..r(3) }),
            // Instance 2 points at 63 bytes.
            run(&truncated, r(4)),
        ])
    }

    // ---- Updates ----------------------------------------------------------------------------

    update_src_null: vuid("VUID-vkBuildAccelerationStructuresKHR-pInfos-04630"), info(1) => {
        let device = Device::new();
        let dst = built(&device, BLAS, updatable(), &[tri_geom()], &[r(2)]);
        let mut s = vec![0u8; BIG as usize];
        update_bad(&device, None, dst, BLAS, updatable(), &[tri_geom()], &[r(2)], Some(&mut s))
    }

    update_src_invalid_handle: vuid("VUID-vkBuildAccelerationStructuresKHR-srcAccelerationStructure-04629"), info(1) => {
        let device = Device::new();
        let dst = built(&device, BLAS, updatable(), &[tri_geom()], &[r(2)]);
        let destroyed = create(&device, BLAS, BIG);
        device.destroy_acceleration_structure(destroyed).expect("destroy");
        same([AccelerationStructure(0xdead_0000), destroyed]
            .into_iter()
            .map(|src| {
                let mut s = vec![0u8; BIG as usize];
                update_bad(&device, Some(src), dst, BLAS, updatable(), &[tri_geom()], &[r(2)], Some(&mut s))
            })
            .collect())
    }

    update_src_not_built: vuid("VUID-vkBuildAccelerationStructuresKHR-pInfos-03667"), info(1) => {
        let device = Device::new();
        let src = create(&device, BLAS, BIG);
        let dst = create(&device, BLAS, BIG);
        let mut s = vec![0u8; BIG as usize];
        update_bad(&device, Some(src), dst, BLAS, updatable(), &[tri_geom()], &[r(2)], Some(&mut s))
    }

    update_src_without_allow_update: vuid("VUID-vkBuildAccelerationStructuresKHR-pInfos-03667"), info(1) => {
        let device = Device::new();
        let src = built(&device, BLAS, fast(), &[tri_geom()], &[r(2)]);
        let mut s = vec![0u8; BIG as usize];
        same(vec![
            update_bad(&device, Some(src), src, BLAS, fast(), &[tri_geom()], &[r(2)], Some(&mut s)),
            update_bad(&device, Some(src), src, BLAS, updatable(), &[tri_geom()], &[r(2)], Some(&mut s)),
        ])
    }

    update_flags_changed: vuid("VUID-vkBuildAccelerationStructuresKHR-pInfos-03759"), info(1) => {
        let device = Device::new();
        let src = built(&device, BLAS, updatable(), &[tri_geom()], &[r(2)]);
        let mut s = vec![0u8; BIG as usize];
        let changed = vk::BuildAccelerationStructureFlagsKHR::ALLOW_UPDATE | vk::BuildAccelerationStructureFlagsKHR::PREFER_FAST_BUILD;
        let added = updatable() | vk::BuildAccelerationStructureFlagsKHR::ALLOW_COMPACTION;
        same(vec![
            update_bad(&device, Some(src), src, BLAS, changed, &[tri_geom()], &[r(2)], Some(&mut s)),
            update_bad(&device, Some(src), src, BLAS, added, &[tri_geom()], &[r(2)], Some(&mut s)),
        ])
    }

    update_type_changed: vuid("VUID-vkBuildAccelerationStructuresKHR-pInfos-03760"), info(1) => {
        // A GENERIC structure built as a BLAS, updated as a TLAS.
        let device = Device::new();
        let blas = simple_blas(&device);
        let src = built(&device, BLAS, updatable(), &[tri_geom()], &[r(2)]);
        let bytes = instances(blas, |_| {});
        let mut s = vec![0u8; BIG as usize];
        update_bad(&device, Some(src), src, TLAS, updatable(), &[inst_geom(&bytes)], &[r(4)], Some(&mut s))
    }

    update_geometry_count_changed: vuid("VUID-vkBuildAccelerationStructuresKHR-pInfos-03758"), info(1) => {
        let device = Device::new();
        let src = built(&device, BLAS, updatable(), &[tri_geom(), tri_geom()], &[r(2), r(2)]);
        let mut s = vec![0u8; BIG as usize];
        same(vec![
            update_bad(&device, Some(src), src, BLAS, updatable(), &[tri_geom()], &[r(2)], Some(&mut s)),
            update_bad(&device, Some(src), src, BLAS, updatable(), &[tri_geom(), tri_geom(), tri_geom()], &[r(2), r(2), r(2)], Some(&mut s)),
        ])
    }

    update_dst_too_small: vuid("VUID-vkBuildAccelerationStructuresKHR-pInfos-03675"), info(1) => {
        let device = Device::new();
        let src = built(&device, BLAS, updatable(), &[tri_geom()], &[r(2)]);
        let dst = create(&device, BLAS, 256);
        let mut s = vec![0u8; BIG as usize];
        update_bad(&device, Some(src), dst, BLAS, updatable(), &[tri_geom()], &[r(2)], Some(&mut s))
    }

    update_scratch_too_small: vuid("VUID-vkBuildAccelerationStructuresKHR-pInfos-03726"), info(1) => {
        let device = Device::new();
        let g = [tri_geom()];
        let src = built(&device, BLAS, updatable(), &g, &[r(2)]);
        let probe = BuildGeometryInfo { ty: BLAS, flags: updatable(), mode: vk::BuildAccelerationStructureModeKHR::UPDATE, src: None, dst: None, geometries: &g, scratch: None };
        let need = device.build_sizes(vk::AccelerationStructureBuildTypeKHR::HOST, &probe, &[2]).expect("sizes").update_scratch_size;
        let mut s = vec![0u8; need as usize - 1];
        same(vec![
            update_bad(&device, Some(src), src, BLAS, updatable(), &g, &[r(2)], Some(&mut s)),
            update_bad(&device, Some(src), src, BLAS, updatable(), &g, &[r(2)], None),
        ])
    }

    update_geometry_type_changed: vuid("VUID-vkBuildAccelerationStructuresKHR-pInfos-03761"), geom(1, 0) => {
        // All geometries must change together (a BLAS has one geometry type), so the first
        // differing one is geometry 0.
        update_two([tri_geom(), tri_geom()], [r(2), r(2)], [aabb_geom(), aabb_geom()], [r(2), r(2)])
    }

    update_geometry_flags_changed: vuid("VUID-vkBuildAccelerationStructuresKHR-pInfos-03762"), geom(1, 1) => {
        let g1 = Geometry { flags: vk::GeometryFlagsKHR::OPAQUE | vk::GeometryFlagsKHR::NO_DUPLICATE_ANY_HIT_INVOCATION, ..tri_geom() };
        let a1 = Geometry::aabbs(aabb_data(), vk::GeometryFlagsKHR::OPAQUE);
        same(vec![
            update_two([tri_geom(), tri_geom()], [r(2), r(2)], [tri_geom(), g1], [r(2), r(2)]),
            update_two([aabb_geom(), aabb_geom()], [r(2), r(2)], [aabb_geom(), a1], [r(2), r(2)]),
        ])
    }

    update_vertex_format_changed: vuid("VUID-vkBuildAccelerationStructuresKHR-pInfos-03763"), geom(1, 1) => {
        let g1 = tris(TrianglesData { vertex_format: vk::Format::R32G32_SFLOAT, ..tri_data() });
        update_two([tri_geom(), tri_geom()], [r(2), r(2)], [tri_geom(), g1], [r(2), r(2)])
    }

    update_max_vertex_changed: vuid("VUID-vkBuildAccelerationStructuresKHR-pInfos-03764"), geom(1, 1) => {
        let g1 = tris(TrianglesData { max_vertex: 6, ..tri_data() });
        update_two([tri_geom(), tri_geom()], [r(2), r(2)], [tri_geom(), g1], [r(2), r(2)])
    }

    update_index_type_changed: vuid("VUID-vkBuildAccelerationStructuresKHR-pInfos-03765"), geom(1, 1) => {
        let idx16: &'static [u8] = bytes_of(&IDX32);
        let g16 = tris(TrianglesData { index_type: vk::IndexType::UINT16, index_data: Some(idx16), ..indexed_data() });
        same(vec![
            update_two([tri_geom(), tri_geom()], [r(2), r(2)], [tri_geom(), tris(indexed_data())], [r(2), r(2)]),
            update_two([tri_geom(), tris(indexed_data())], [r(2), r(2)], [tri_geom(), tri_geom()], [r(2), r(2)]),
            update_two([tri_geom(), tris(indexed_data())], [r(2), r(2)], [tri_geom(), g16], [r(2), r(2)]),
        ])
    }

    update_transform_added: vuid("VUID-vkBuildAccelerationStructuresKHR-pInfos-03766"), geom(1, 1) => {
        let g1 = tris(TrianglesData { transform_data: Some(bytes_of(&IDENTITY_ROWS)), ..tri_data() });
        update_two([tri_geom(), tri_geom()], [r(2), r(2)], [tri_geom(), g1], [r(2), r(2)])
    }

    update_transform_removed: vuid("VUID-vkBuildAccelerationStructuresKHR-pInfos-03767"), geom(1, 1) => {
        let g1 = tris(TrianglesData { transform_data: Some(bytes_of(&IDENTITY_ROWS)), ..tri_data() });
        update_two([tri_geom(), g1], [r(2), r(2)], [tri_geom(), tri_geom()], [r(2), r(2)])
    }

    update_primitive_count_changed: vuid("VUID-vkBuildAccelerationStructuresKHR-primitiveCount-03769"), geom(1, 1) => {
        same(vec![
            update_two([tri_geom(), tri_geom()], [r(2), r(2)], [tri_geom(), tri_geom()], [r(2), r(1)]),
            update_two([aabb_geom(), aabb_geom()], [r(2), r(1)], [aabb_geom(), aabb_geom()], [r(2), r(2)]),
        ])
    }

    update_triangle_made_inactive: vuid("VUID-vkBuildAccelerationStructuresKHR-pInfos-03664"), prim(1, 1, 1) => {
        let g1 = tris(TrianglesData { vertex_data: bytes_of(&TRI_POS_INACTIVE_1), ..tri_data() });
        update_two([tri_geom(), tri_geom()], [r(2), r(2)], [tri_geom(), g1], [r(2), r(2)])
    }

    update_triangle_made_active: vuid("VUID-vkBuildAccelerationStructuresKHR-pInfos-03663"), prim(1, 1, 1) => {
        let g1 = tris(TrianglesData { vertex_data: bytes_of(&TRI_POS_INACTIVE_1), ..tri_data() });
        update_two([tri_geom(), g1], [r(2), r(2)], [tri_geom(), tri_geom()], [r(2), r(2)])
    }

    update_aabb_made_inactive: vuid("VUID-vkBuildAccelerationStructuresKHR-pInfos-03664"), prim(1, 1, 1) => {
        let g1 = Geometry::aabbs(AabbsData { data: bytes_of(&BOXES_INACTIVE_1), stride: 24 }, vk::GeometryFlagsKHR::empty());
        update_two([aabb_geom(), aabb_geom()], [r(2), r(2)], [aabb_geom(), g1], [r(2), r(2)])
    }

    update_aabb_made_active: vuid("VUID-vkBuildAccelerationStructuresKHR-pInfos-03663"), prim(1, 1, 1) => {
        let g1 = Geometry::aabbs(AabbsData { data: bytes_of(&BOXES_INACTIVE_1), stride: 24 }, vk::GeometryFlagsKHR::empty());
        update_two([aabb_geom(), g1], [r(2), r(2)], [aabb_geom(), aabb_geom()], [r(2), r(2)])
    }

    update_instance_made_active: vuid("VUID-vkBuildAccelerationStructuresKHR-pInfos-03663"), prim(1, 0, 1) => {
        // Instance 1 is inactive in the source; the update gives it a reference.
        let device = Device::new();
        let blas = simple_blas(&device);
        let before = instances(blas, |_| {});
        let mut after = before.clone();
        after[64 + 56..128].copy_from_slice(&blas.0.to_le_bytes());
        let src = built(&device, TLAS, updatable(), &[inst_geom(&before)], &[r(4)]);
        let mut s = vec![0u8; BIG as usize];
        update_bad(&device, Some(src), src, TLAS, updatable(), &[inst_geom(&after)], &[r(4)], Some(&mut s))
    }

    update_instance_made_inactive: vuid("VUID-vkBuildAccelerationStructuresKHR-pInfos-03664"), prim(1, 0, 2) => {
        let device = Device::new();
        let blas = simple_blas(&device);
        let before = instances(blas, |_| {});
        let after = instances(blas, |i| i.acceleration_structure_reference = 0);
        let src = built(&device, TLAS, updatable(), &[inst_geom(&before)], &[r(4)]);
        let mut s = vec![0u8; BIG as usize];
        update_bad(&device, Some(src), src, TLAS, updatable(), &[inst_geom(&after)], &[r(4)], Some(&mut s))
    }

    update_instance_activity_swapped: vuid("VUID-vkBuildAccelerationStructuresKHR-pInfos-03664"), prim(1, 0, 2) => {
        // Instance 1 becomes active and instance 2 inactive: same count, 2 is reported.
        let device = Device::new();
        let blas = simple_blas(&device);
        let before = instances(blas, |_| {});
        let mut after = instances(blas, |i| i.acceleration_structure_reference = 0);
        after[64 + 56..128].copy_from_slice(&blas.0.to_le_bytes());
        let src = built(&device, TLAS, updatable(), &[inst_geom(&before)], &[r(4)]);
        let mut s = vec![0u8; BIG as usize];
        update_bad(&device, Some(src), src, TLAS, updatable(), &[inst_geom(&after)], &[r(4)], Some(&mut s))
    }

    update_src_dst_overlap: vuid("VUID-vkBuildAccelerationStructuresKHR-pInfos-03668"), At::Unchecked => {
        overlapping_update()
    }

    update_src_dst_overlap_location: vuid("VUID-vkBuildAccelerationStructuresKHR-pInfos-03668"), info(1) => {
        overlapping_update()
    }

    update_src_buffer_unbound: vuid("VUID-vkBuildAccelerationStructuresKHR-pInfos-03723"), info(1) => {
        let device = Device::new();
        let ci = AccelerationStructureCreateInfo { buffer: Some(Buffer::new_unbound(BIG)), ..AccelerationStructureCreateInfo::new(BLAS, BIG) };
        let src = device.create_acceleration_structure(&ci).expect("create");
        let dst = create(&device, BLAS, BIG);
        let mut s = vec![0u8; BIG as usize];
        update_bad(&device, Some(src), dst, BLAS, updatable(), &[tri_geom()], &[r(2)], Some(&mut s))
    }

    // ---- Rules the specification states and hostas does not check ---------------------------

    unchecked_update_first_vertex_changed: vuid("VUID-vkBuildAccelerationStructuresKHR-firstVertex-03770"), geom(1, 1) => {
        // Seven vertices, so that indices 0..5 fit with firstVertex 0 and with firstVertex 1.
        static POS7: [[f32; 3]; 7] = [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [2.0, 0.0, 0.0], [3.0, 0.0, 0.0], [2.0, 1.0, 0.0]];
        let g = tris(TrianglesData { vertex_data: bytes_of(&POS7), max_vertex: 6, ..indexed_data() });
        update_two([tri_geom(), g], [r(2), r(2)], [tri_geom(), g], [r(2), BuildRangeInfo { first_vertex: 1, ..r(2) }])
    }

    unchecked_src_invalid_in_build_mode: vuid("VUID-vkBuildAccelerationStructuresKHR-srcAccelerationStructure-04629"), info(1) => {
        let device = Device::new();
        let g = [tri_geom()];
        let dst = create(&device, BLAS, BIG);
        let mut s = vec![0u8; BIG as usize];
        let info = BuildGeometryInfo { src: Some(AccelerationStructure(0xdead_0000)), ..BuildGeometryInfo::build(BLAS, fast(), &g, dst, &mut s) };
        with_neighbours(&device, info, &[r(2)])
    }

    unchecked_dst_overlaps_other_update_src: vuid("VUID-vkBuildAccelerationStructuresKHR-dstAccelerationStructure-03701"), info(0) => {
        let device = Device::new();
        let buffer = Buffer::new(2 * BIG).expect("buffer");
        let place = |offset: u64| {
            let ci = AccelerationStructureCreateInfo { buffer: Some(buffer.clone()), offset, ..AccelerationStructureCreateInfo::new(BLAS, BIG) };
            device.create_acceleration_structure(&ci).expect("create")
        };
        let (x, d) = (place(0), place(BIG - 256));
        let g = [tri_geom()];
        let ranges = [r(2)];
        build_into(&device, x, BLAS, updatable(), &g, &ranges).expect("source");
        let y = create(&device, BLAS, BIG);
        let (mut s0, mut s1) = (vec![0u8; BIG as usize], vec![0u8; BIG as usize]);
        let update = BuildGeometryInfo { mode: vk::BuildAccelerationStructureModeKHR::UPDATE, src: Some(x), ..BuildGeometryInfo::build(BLAS, updatable(), &g, y, &mut s1) };
        device.build_acceleration_structures(&mut [BuildGeometryInfo::build(BLAS, fast(), &g, d, &mut s0), update], &[&ranges, &ranges])
    }

    unchecked_dst_overlaps_referenced_blas: vuid("VUID-vkBuildAccelerationStructuresKHR-dstAccelerationStructure-03706"), prim(1, 0, 0) => {
        let device = Device::new();
        let buffer = Buffer::new(2 * BIG).expect("buffer");
        let place = |offset: u64| {
            let ci = AccelerationStructureCreateInfo { buffer: Some(buffer.clone()), offset, ..AccelerationStructureCreateInfo::new(BLAS, BIG) };
            device.create_acceleration_structure(&ci).expect("create")
        };
        let (b, d) = (place(0), place(BIG - 256));
        let g = [tri_geom()];
        let ranges = [r(2)];
        build_into(&device, b, BLAS, fast(), &g, &ranges).expect("blas");
        let bytes = instances(b, |_| {});
        let gi = [inst_geom(&bytes)];
        let t = create(&device, TLAS, BIG);
        let (mut s0, mut s1) = (vec![0u8; BIG as usize], vec![0u8; BIG as usize]);
        device.build_acceleration_structures(
            &mut [BuildGeometryInfo::build(BLAS, fast(), &g, d, &mut s0), BuildGeometryInfo::build(TLAS, fast(), &gi, t, &mut s1)],
            &[&ranges, &[r(4)]],
        )
    }

    unchecked_update_instance_references_dst_of_call: vuid("VUID-vkBuildAccelerationStructuresKHR-None-03407"), prim(1, 0, 2) => {
        let device = Device::new();
        let blas = simple_blas(&device);
        let other = simple_blas(&device);
        let before = instances(blas, |_| {});
        let after = instances(blas, |i| i.acceleration_structure_reference = other.0);
        let t = built(&device, TLAS, updatable(), &[inst_geom(&before)], &[r(4)]);
        let g = [tri_geom()];
        let gi = [inst_geom(&after)];
        let (mut s0, mut s1) = (vec![0u8; BIG as usize], vec![0u8; BIG as usize]);
        let update = BuildGeometryInfo { mode: vk::BuildAccelerationStructureModeKHR::UPDATE, src: Some(t), ..BuildGeometryInfo::build(TLAS, updatable(), &gi, t, &mut s1) };
        device.build_acceleration_structures(&mut [BuildGeometryInfo::build(BLAS, fast(), &g, other, &mut s0), update], &[&[r(2)], &[r(4)]])
    }

    unchecked_instance_flags_unknown_bits: vuid("VUID-VkAccelerationStructureInstanceKHR-flags-parameter"), prim(1, 0, 2) => {
        let device = Device::new();
        let blas = simple_blas(&device);
        tlas_bad(&device, &instances(blas, |i| i.flags = vk::GeometryInstanceFlagsKHR::from_raw(0x80)))
    }

    unchecked_sizes_vertex_format: vuid("VUID-VkAccelerationStructureGeometryTrianglesDataKHR-vertexFormat-03797"), sizes_geom(1) => {
        sizes(BLAS, fast(), &[tri_geom(), tris(TrianglesData { vertex_format: vk::Format::R8_UNORM, ..tri_data() })], &[2, 2])
    }

    // ---- vkCreateAccelerationStructureKHR / buffers -----------------------------------------

    create_offset_not_multiple_of_256: vuid("VUID-VkAccelerationStructureCreateInfoKHR-offset-03734"), NOWHERE => {
        let device = Device::new();
        let buffer = Buffer::new(BIG).expect("buffer");
        same([1u64, 128, 255, 257]
            .into_iter()
            .map(|offset| {
                let ci = AccelerationStructureCreateInfo { buffer: Some(buffer.clone()), offset, ..AccelerationStructureCreateInfo::new(BLAS, 1024) };
                device.create_acceleration_structure(&ci).map(|_| ())
            })
            .collect())
    }

    create_range_exceeds_buffer: vuid("VUID-VkAccelerationStructureCreateInfoKHR-offset-03616"), NOWHERE => {
        let device = Device::new();
        let buffer = Buffer::new(4096).expect("buffer");
        let with = |offset: u64, size: u64| {
            let ci = AccelerationStructureCreateInfo { buffer: Some(buffer.clone()), offset, ..AccelerationStructureCreateInfo::new(BLAS, size) };
            device.create_acceleration_structure(&ci).map(|_| ())
        };
        same(vec![
            with(0, 4097),
            with(3840, 512),
            with(4096, 1),
            with(!255u64, 512), // 256-aligned, but offset + size overflows
            // No buffer: hostas allocates exactly `size`, so a non-zero offset cannot fit.
            device.create_acceleration_structure(&AccelerationStructureCreateInfo { offset: 256, ..AccelerationStructureCreateInfo::new(BLAS, 1024) }).map(|_| ()),
        ])
    }

    create_device_address_nonzero: vuid("VUID-vkCreateAccelerationStructureKHR-deviceAddress-03488"), NOWHERE => {
        let ci = AccelerationStructureCreateInfo {
            device_address: 0x10000,
            create_flags: vk::AccelerationStructureCreateFlagsKHR::DEVICE_ADDRESS_CAPTURE_REPLAY,
            ..AccelerationStructureCreateInfo::new(BLAS, 1024)
        };
        Device::new().create_acceleration_structure(&ci).map(|_| ())
    }


    create_capture_replay_flag: vuid("VUID-VkAccelerationStructureCreateInfoKHR-createFlags-03613"), NOWHERE => {
        let ci = AccelerationStructureCreateInfo {
            create_flags: vk::AccelerationStructureCreateFlagsKHR::DEVICE_ADDRESS_CAPTURE_REPLAY,
            ..AccelerationStructureCreateInfo::new(BLAS, 1024)
        };
        Device::new().create_acceleration_structure(&ci).map(|_| ())
    }

    create_size_zero: vuid("VUID-VkAccelerationStructureCreateInfoKHR-size-parameter"), NOWHERE => {
        let device = Device::new();
        let buffer = Buffer::new(4096).expect("buffer");
        same(vec![
            device.create_acceleration_structure(&AccelerationStructureCreateInfo::new(BLAS, 0)).map(|_| ()),
            device.create_acceleration_structure(&AccelerationStructureCreateInfo { buffer: Some(buffer), ..AccelerationStructureCreateInfo::new(TLAS, 0) }).map(|_| ()),
        ])
    }

    create_type_unknown: vuid("VUID-VkAccelerationStructureCreateInfoKHR-type-parameter"), NOWHERE => {
        same([3i32, -1, 1_000_165_000]
            .into_iter()
            .map(|t| Device::new().create_acceleration_structure(&AccelerationStructureCreateInfo::new(vk::AccelerationStructureTypeKHR::from_raw(t), 1024)).map(|_| ()))
            .collect())
    }

    create_motion_flag: NotSupported, At::NoLocation => {
        let ci = AccelerationStructureCreateInfo { create_flags: vk::AccelerationStructureCreateFlagsKHR::from_raw(0x4), ..AccelerationStructureCreateInfo::new(BLAS, 1024) };
        Device::new().create_acceleration_structure(&ci).map(|_| ())
    }

    bind_memory_twice: vuid("VUID-vkBindBufferMemory-buffer-07459"), NOWHERE => {
        let b = Buffer::new_unbound(1024);
        b.bind_memory().expect("first bind");
        same(vec![b.bind_memory(), Buffer::new(64).expect("buffer").bind_memory()])
    }

    // ---- Rays (OpRayQueryInitializeKHR) -----------------------------------------------------

    ray_origin_or_direction_not_finite: vuid("VUID-RuntimeSpirv-OpRayQueryInitializeKHR-06348"), NOWHERE => {
        same(vec![
            ray_invalid(Ray::new([f32::INFINITY, 0.0, 0.0], [0.0, 0.0, -1.0])),
            ray_invalid(Ray::new([0.0, f32::NEG_INFINITY, 0.0], [0.0, 0.0, -1.0])),
            ray_invalid(Ray::new([0.0, 0.0, 0.0], [0.0, 0.0, f32::INFINITY])),
            ray_invalid(Ray::new([0.0, 0.0, f32::NAN], [0.0, 0.0, -1.0])),
            ray_invalid(Ray::new([0.0, 0.0, 0.0], [f32::NAN, 0.0, -1.0])),
            // Every lane of the vector check: the direction's y too (huge finite values stay
            // valid: `huge_finite_rays_are_valid`).
            ray_invalid(Ray::new([0.0, 0.0, 0.0], [0.0, f32::NEG_INFINITY, -1.0])),
        ])
    }

    ray_t_nan: vuid("VUID-RuntimeSpirv-OpRayQueryInitializeKHR-06351"), NOWHERE => {
        same(vec![
            ray_invalid(Ray { t_min: f32::NAN, ..down(0.25, 0.25) }),
            ray_invalid(Ray { t_max: f32::NAN, ..down(0.25, 0.25) }),
        ])
    }

    ray_t_negative: vuid("VUID-RuntimeSpirv-OpRayQueryInitializeKHR-06349"), NOWHERE => {
        same(vec![
            ray_invalid(Ray { t_min: -1.0, ..down(0.25, 0.25) }),
            ray_invalid(Ray { t_min: f32::NEG_INFINITY, ..down(0.25, 0.25) }),
            ray_invalid(Ray { t_max: -0.5, ..down(0.25, 0.25) }),
        ])
    }

    ray_t_min_greater_than_t_max: vuid("VUID-RuntimeSpirv-OpRayQueryInitializeKHR-06350"), NOWHERE => {
        same(vec![
            ray_invalid(Ray { t_min: 2.0, t_max: 1.0, ..down(0.25, 0.25) }),
            ray_invalid(Ray { t_min: f32::INFINITY, t_max: 1.0, ..down(0.25, 0.25) }),
        ])
    }

    ray_skip_triangles_and_aabbs: vuid("VUID-RuntimeSpirv-OpRayQueryInitializeKHR-06889"), NOWHERE => {
        ray_invalid(Ray { flags: RayFlags::SKIP_TRIANGLES | RayFlags::SKIP_AABBS, ..down(0.25, 0.25) })
    }

    ray_two_triangle_culls: vuid("VUID-RuntimeSpirv-OpRayQueryInitializeKHR-06890"), NOWHERE => {
        same([
            RayFlags::SKIP_TRIANGLES | RayFlags::CULL_BACK_FACING_TRIANGLES,
            RayFlags::SKIP_TRIANGLES | RayFlags::CULL_FRONT_FACING_TRIANGLES,
            RayFlags::CULL_BACK_FACING_TRIANGLES | RayFlags::CULL_FRONT_FACING_TRIANGLES,
        ]
        .into_iter()
        .map(|flags| ray_invalid(Ray { flags, ..down(0.25, 0.25) }))
        .collect())
    }

    ray_two_opacity_flags: vuid("VUID-RuntimeSpirv-OpRayQueryInitializeKHR-06891"), NOWHERE => {
        let all = [RayFlags::OPAQUE, RayFlags::NO_OPAQUE, RayFlags::CULL_OPAQUE, RayFlags::CULL_NO_OPAQUE];
        let mut cases = Vec::new();
        for (i, a) in all.iter().enumerate() {
            for b in &all[i + 1..] {
                cases.push(ray_invalid(Ray { flags: *a | *b, ..down(0.25, 0.25) }));
            }
        }
        same(cases)
    }

    // ---- Ray-query operations ---------------------------------------------------------------

    confirm_without_triangle_candidate: vuid("VUID-RuntimeSpirv-OpRayQueryConfirmIntersectionKHR"), NOWHERE => {
        let device = Device::new();
        let tri = triangle_scene(&device, fast());
        let boxes = aabb_scene(&device);
        // Before proceed; and on an AABB candidate.
        let mut q = tri.ray_query(&down(0.25, 0.25))?;
        let fresh = q.confirm_intersection();
        let mut q = boxes.ray_query(&down(0.5, 0.5))?;
        assert!(q.proceed() && q.candidate_type() == Some(CandidateType::Aabb));
        same(vec![fresh, q.confirm_intersection()])
    }

    generate_without_aabb_candidate: vuid("VUID-RuntimeSpirv-OpRayQueryGenerateIntersectionKHR"), NOWHERE => {
        let device = Device::new();
        let tri = triangle_scene(&device, fast());
        let mut q = tri.ray_query(&down(0.25, 0.25))?;
        let fresh = q.generate_intersection(1.0);
        // NoOpaque turns the triangle into a candidate.
        let mut q = tri.ray_query(&Ray { flags: RayFlags::NO_OPAQUE, ..down(0.25, 0.25) })?;
        assert!(q.proceed() && q.candidate_type() == Some(CandidateType::Triangle));
        same(vec![fresh, q.generate_intersection(10.0)])
    }

    generate_outside_t_range: vuid("VUID-RuntimeSpirv-OpRayQueryGenerateIntersectionKHR-06353"), NOWHERE => {
        let device = Device::new();
        let boxes = aabb_scene(&device);
        let ray = Ray { t_min: 1.0, t_max: 50.0, ..down(0.5, 0.5) };
        let mut results = Vec::new();
        for t in [0.5, 50.5, f32::INFINITY, f32::NAN] {
            let mut q = boxes.ray_query(&ray)?;
            assert!(q.proceed() && q.candidate_type() == Some(CandidateType::Aabb));
            results.push(q.generate_intersection(t));
        }
        // After a committed hit at 9.5, the range ends there.
        let mut q = boxes.ray_query(&ray)?;
        assert!(q.proceed());
        q.generate_intersection(9.5)?;
        if q.proceed() {
            results.push(q.generate_intersection(9.75));
        }
        same(results)
    }

    vertex_positions_without_triangle: vuid("VUID-RuntimeSpirv-OpRayQueryGetIntersectionTriangleVertexPositionsKHR"), NOWHERE => {
        let device = Device::new();
        let data = vk::BuildAccelerationStructureFlagsKHR::ALLOW_DATA_ACCESS;
        let tri = triangle_scene(&device, data);
        let boxes = aabb_scene(&device);
        let q = tri.ray_query(&down(0.25, 0.25))?;
        let fresh = q.triangle_vertex_positions(true).map(|_| ());
        let mut miss = tri.ray_query(&down(-5.0, -5.0))?;
        assert!(!miss.proceed());
        let mut q = boxes.ray_query(&down(0.5, 0.5))?;
        assert!(q.proceed());
        let candidate = q.triangle_vertex_positions(false).map(|_| ());
        q.generate_intersection(9.5)?;
        same(vec![fresh, miss.triangle_vertex_positions(true).map(|_| ()), candidate, q.triangle_vertex_positions(true).map(|_| ())])
    }

    vertex_positions_without_data_access: vuid("VUID-RuntimeSpirv-OpRayQueryGetIntersectionTriangleVertexPositionsKHR-08761"), NOWHERE => {
        let device = Device::new();
        let tri = triangle_scene(&device, fast());
        let mut q = tri.ray_query(&down(0.25, 0.25))?;
        assert!(!q.proceed());
        assert_eq!(q.committed_type(), hostas::CommittedType::Triangle);
        q.triangle_vertex_positions(true).map(|_| ())
    }
}

/// x (updatable) and y in one buffer, overlapping; info 1 updates x into y.
fn overlapping_update() -> Result<(), Error> {
    let device = Device::new();
    let buffer = Buffer::new(2 * BIG).expect("buffer");
    let place = |offset: u64| {
        let ci = AccelerationStructureCreateInfo {
            buffer: Some(buffer.clone()),
            offset,
            ..AccelerationStructureCreateInfo::new(BLAS, BIG)
        };
        device.create_acceleration_structure(&ci).expect("create")
    };
    let (x, y) = (place(0), place(BIG / 2));
    build_into(&device, x, BLAS, updatable(), &[tri_geom()], &[r(2)]).expect("source");
    let mut s = vec![0u8; BIG as usize];
    update_bad(
        &device,
        Some(x),
        y,
        BLAS,
        updatable(),
        &[tri_geom()],
        &[r(2)],
        Some(&mut s),
    )
}

// ---------------------------------------------------------------------------------------------
// Sweeps.
// ---------------------------------------------------------------------------------------------

/// The finiteness rule rejects only infinities and NaNs: the largest and smallest finite
/// components (whose products with zero, which the check sums, stay zero) are valid, through
/// every entry point.
#[test]
fn huge_finite_rays_are_valid() {
    let device = Device::new();
    let scene = triangle_scene(&device, fast());
    for ray in [
        Ray::new([f32::MAX, -f32::MAX, 1e-45], [0.0, 0.0, -1.0]),
        Ray::new([0.0, 0.0, 1.0], [-f32::MAX, f32::MIN_POSITIVE, -f32::MAX]),
    ] {
        assert!(ray.validate().is_ok(), "{ray:?}");
        assert!(scene.ray_query(&ray).is_ok(), "{ray:?}");
        assert!(scene.trace_closest(&ray).is_ok(), "{ray:?}");
    }
}

#[test]
fn no_invalid_input_panics() {
    let mut panicked = Vec::new();
    for (name, case) in ALL_CASES {
        if std::panic::catch_unwind(case).is_err() {
            panicked.push(*name);
        }
    }
    assert!(panicked.is_empty(), "panicked: {panicked:?}");
}

#[test]
fn every_library_vuid_has_a_case() {
    // Every VUID string in the sources of the build, build-sizes, create, buffer and ray-query
    // paths must appear in a case of this file, so that a rule added there gets a test. (The
    // copy, serialization and query commands have their own tests.) Read at run time.
    const FILES: [&str; 10] = [
        "device.rs",
        "memory.rs",
        "commands/build.rs",
        "commands/mod.rs",
        "commands/validate.rs",
        "input/triangles.rs",
        "input/aabbs.rs",
        "input/instances.rs",
        "traverse/mod.rs",
        "traverse/query.rs",
    ];
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let src: String = FILES
        .iter()
        .map(|f| std::fs::read_to_string(root.join(f)).unwrap_or_else(|e| panic!("{f}: {e}")))
        .collect();
    assert!(
        src.matches("\"VUID-").count() > 80,
        "the VUIDs of the build path were not found"
    );
    let this = include_str!("validation.rs");
    let mut missing = Vec::new();
    for (i, _) in src.match_indices("\"VUID-") {
        let v = &src[i + 1..];
        let v = &v[..v.find('"').unwrap_or(0)];
        if !this.contains(&format!("vuid(\"{v}\")")) {
            missing.push(v.to_string());
        }
    }
    missing.sort();
    missing.dedup();
    assert!(
        missing.is_empty(),
        "library VUIDs without a case: {missing:?}"
    );
}

// ---------------------------------------------------------------------------------------------
// Cross-info rules run before anything is written.
// ---------------------------------------------------------------------------------------------

#[test]
fn cross_info_failures_write_nothing() {
    let device = Device::new();
    let g = [tri_geom()];
    let ranges = [r(2)];
    let buf = || vec![0u8; BIG as usize];

    // 03698: info 2 repeats info 0's destination.
    let (a, b) = (create(&device, BLAS, BIG), create(&device, BLAS, BIG));
    let (mut s0, mut s1, mut s2) = (buf(), buf(), buf());
    let e = device
        .build_acceleration_structures(
            &mut [
                BuildGeometryInfo::build(BLAS, fast(), &g, a, &mut s0),
                BuildGeometryInfo::build(BLAS, fast(), &g, b, &mut s1),
                BuildGeometryInfo::build(BLAS, fast(), &g, a, &mut s2),
            ],
            &[&ranges, &ranges, &ranges],
        )
        .unwrap_err();
    assert_eq!(
        e.vuid_str(),
        Some("VUID-vkBuildAccelerationStructuresKHR-dstAccelerationStructure-03698")
    );
    assert!(
        untouched(&device, a) && untouched(&device, b),
        "03698: an earlier info was built"
    );

    // 03800: the last info's destination is invalid.
    let (a, b) = (create(&device, BLAS, BIG), create(&device, BLAS, BIG));
    let (mut s0, mut s1, mut s2) = (buf(), buf(), buf());
    let e = device
        .build_acceleration_structures(
            &mut [
                BuildGeometryInfo::build(BLAS, fast(), &g, a, &mut s0),
                BuildGeometryInfo::build(BLAS, fast(), &g, b, &mut s1),
                BuildGeometryInfo::build(
                    BLAS,
                    fast(),
                    &g,
                    AccelerationStructure(0xdead_0000),
                    &mut s2,
                ),
            ],
            &[&ranges, &ranges, &ranges],
        )
        .unwrap_err();
    assert_eq!(
        e.vuid_str(),
        Some("VUID-vkBuildAccelerationStructuresKHR-dstAccelerationStructure-03800")
    );
    assert!(
        untouched(&device, a) && untouched(&device, b),
        "03800: an earlier info was built"
    );

    // 03702: the last info's destination overlaps the first's memory.
    let buffer = Buffer::new(2 * BIG).expect("buffer");
    let place = |offset: u64| {
        let ci = AccelerationStructureCreateInfo {
            buffer: Some(buffer.clone()),
            offset,
            ..AccelerationStructureCreateInfo::new(BLAS, BIG)
        };
        device.create_acceleration_structure(&ci).expect("create")
    };
    let (a, c) = (place(0), place(BIG - 256));
    let b = create(&device, BLAS, BIG);
    let (mut s0, mut s1, mut s2) = (buf(), buf(), buf());
    let e = device
        .build_acceleration_structures(
            &mut [
                BuildGeometryInfo::build(BLAS, fast(), &g, a, &mut s0),
                BuildGeometryInfo::build(BLAS, fast(), &g, b, &mut s1),
                BuildGeometryInfo::build(BLAS, fast(), &g, c, &mut s2),
            ],
            &[&ranges, &ranges, &ranges],
        )
        .unwrap_err();
    assert_eq!(
        e.vuid_str(),
        Some("VUID-vkBuildAccelerationStructuresKHR-dstAccelerationStructure-03702")
    );
    assert!(
        untouched(&device, a) && untouched(&device, b) && untouched(&device, c),
        "03702: an info was built"
    );

    // 03403: info 1 updates x, info 2 rebuilds x; info 0 and x stay as they were.
    let x = built(&device, BLAS, updatable(), &g, &ranges);
    let x_before = bytes_of_structure(&device, x);
    let (a, y) = (create(&device, BLAS, BIG), create(&device, BLAS, BIG));
    let (mut s0, mut s1, mut s2) = (buf(), buf(), buf());
    let update = BuildGeometryInfo {
        mode: vk::BuildAccelerationStructureModeKHR::UPDATE,
        src: Some(x),
        ..BuildGeometryInfo::build(BLAS, updatable(), &g, y, &mut s1)
    };
    let e = device
        .build_acceleration_structures(
            &mut [
                BuildGeometryInfo::build(BLAS, fast(), &g, a, &mut s0),
                update,
                BuildGeometryInfo::build(BLAS, updatable(), &g, x, &mut s2),
            ],
            &[&ranges, &ranges, &ranges],
        )
        .unwrap_err();
    assert_eq!(
        e.vuid_str(),
        Some("VUID-vkBuildAccelerationStructuresKHR-pInfos-03403")
    );
    assert!(
        untouched(&device, a) && untouched(&device, y),
        "03403: an info was built"
    );
    assert_eq!(
        bytes_of_structure(&device, x),
        x_before,
        "03403: the source changed"
    );

    // And after each failure the same destinations build fine.
    build_into(&device, a, BLAS, fast(), &g, &ranges).expect("rebuild after failure");
}

#[test]
fn cross_info_03407_writes_nothing() {
    let device = Device::new();
    let g = [tri_geom()];
    let being_built = create(&device, BLAS, BIG);
    let blas = simple_blas(&device);
    let bytes = instances(blas, |i| i.acceleration_structure_reference = being_built.0);
    let gi = [inst_geom(&bytes)];
    let t = create(&device, TLAS, BIG);
    let (mut s0, mut s1) = (vec![0u8; BIG as usize], vec![0u8; BIG as usize]);
    let e = device
        .build_acceleration_structures(
            &mut [
                BuildGeometryInfo::build(BLAS, fast(), &g, being_built, &mut s0),
                BuildGeometryInfo::build(TLAS, fast(), &gi, t, &mut s1),
            ],
            &[&[r(2)], &[r(4)]],
        )
        .unwrap_err();
    assert_eq!(
        e.vuid_str(),
        Some("VUID-vkBuildAccelerationStructuresKHR-None-03407")
    );
    assert_eq!(
        e.location(),
        Some(Location::info(1).geometry(0).primitive(2))
    );
    assert!(
        untouched(&device, being_built),
        "info 0 was built before the cross-info rule failed"
    );
    assert!(untouched(&device, t));
}
