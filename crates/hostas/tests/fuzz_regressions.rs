//! Fuzzing, kept green by CI: every file of `fuzz/corpus/<target>/` and
//! `fuzz/regressions/<target>/` goes through the same checks as the cargo-fuzz target of that
//! name (the checks are compiled in from `fuzz/src/checks/`); serialized structures made by
//! this build, and deterministic corruptions of them, go through the `deserialize` checks; and
//! minimized reproductions of the bugs found while fuzzing are pinned below (a new one stays
//! `#[ignore = "BUG: ..."]` while it is open). See `fuzz/README.md`.

#[path = "../../../fuzz/src/checks/mod.rs"]
mod checks;

use hostas::commands::SerializedHeader;
use hostas::{
    AccelerationStructureCreateInfo, BuildGeometryInfo, BuildRangeInfo, Device, Geometry,
    InstancesData, vk,
};
use std::path::{Path, PathBuf};
use std::time::Duration;

fn fuzz_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fuzz")
}

/// Replays `fuzz/<kind>/<target>/*`; returns how many files ran. Missing folders are skipped.
fn replay(kind: &str) -> usize {
    let root = fuzz_dir().join(kind);
    let Ok(dirs) = std::fs::read_dir(&root) else {
        eprintln!("{} does not exist: nothing to replay", root.display());
        return 0;
    };
    let mut dirs: Vec<PathBuf> = dirs
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_dir())
        .collect();
    dirs.sort();
    let mut ran = 0;
    let mut failures = Vec::new();
    for dir in dirs {
        let name = dir
            .file_name()
            .and_then(|n| n.to_str())
            .unwrap_or_default()
            .to_owned();
        let Some(run) = checks::target(&name) else {
            eprintln!("{}: no target named {name}, skipped", dir.display());
            continue;
        };
        let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
            .into_iter()
            .flatten()
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.is_file())
            .collect();
        files.sort();
        for f in files {
            let Ok(bytes) = std::fs::read(&f) else {
                continue;
            };
            ran += 1;
            if std::panic::catch_unwind(|| run(&bytes)).is_err() {
                failures.push(f.display().to_string());
            }
        }
    }
    assert!(
        failures.is_empty(),
        "fuzz inputs that fail their target's checks:\n  {}",
        failures.join("\n  ")
    );
    ran
}

#[test]
fn corpus_passes_the_fuzz_checks() {
    let n = replay("corpus");
    eprintln!("replayed {n} corpus files");
}

#[test]
fn regressions_pass_the_fuzz_checks() {
    let n = replay("regressions");
    eprintln!("replayed {n} regression files");
}

/// Structures serialized by this build (whatever the layout version), and deterministic
/// corruptions of them, pass the `deserialize` checks.
#[test]
fn fresh_serialized_structures_pass_the_deserialize_checks() {
    let mut failures = Vec::new();
    for (i, (name, bytes)) in checks::seeds::deserialize_seeds().into_iter().enumerate() {
        let header = SerializedHeader::parse(&bytes).expect("a seed parses");
        assert_eq!(header.serialized_size, bytes.len() as u64, "{name}");
        assert!(
            Device::new().deserialize(&bytes).is_ok(),
            "{name} deserializes"
        );
        let inputs =
            std::iter::once(bytes.clone()).chain(checks::seeds::mutations(&bytes, 400, i as u64));
        for (k, input) in inputs.enumerate() {
            if std::panic::catch_unwind(|| checks::deserialize::run(&input)).is_err() {
                failures.push(format!("{name} mutation {k}"));
            }
        }
    }
    assert!(
        failures.is_empty(),
        "deserialize checks failed for: {failures:?}"
    );
}

/// The decoder is deterministic and total: any bytes decode, the same bytes the same way.
#[test]
fn build_inputs_decoding_is_deterministic() {
    for seed in 0..64u64 {
        let bytes: Vec<u8> = (0..seed * 7)
            .map(|i| (i.wrapping_mul(2654435761) >> 7) as u8 ^ seed as u8)
            .collect();
        let a = format!("{:?}", checks::build_inputs::Case::decode(&bytes));
        let b = format!("{:?}", checks::build_inputs::Case::decode(&bytes));
        assert_eq!(a, b);
    }
}

/// A serialized header (with this build's UUIDs) followed by nothing.
fn bare_header(deserialized_size: u64) -> Vec<u8> {
    let device = Device::new();
    let blas = hostas::quick::build_triangle_blas(
        &device,
        &[[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        &[[0, 1, 2]],
        Default::default(),
    )
    .unwrap();
    let mut bytes = device.serialize(blas).unwrap();
    bytes.truncate(56);
    bytes[32..40].copy_from_slice(&u64::MAX.to_le_bytes());
    bytes[40..48].copy_from_slice(&deserialized_size.to_le_bytes());
    bytes
}

/// Was a bug (fixed in 74ed721): `Device::deserialize` (crates/hostas/src/commands/copy.rs) created the
/// destination with the header's `deserializedSize` before `copy_memory_to_acceleration_structure`
/// checked that the data holds that many bytes: a 56-byte input could make hostas allocate and
/// zero any amount of memory (8 GiB for `deserializedSize = 2^33`), and past what the allocator
/// grants, the error was `OutOfHostMemory` instead of "the data is too short".
#[test]
fn deserialize_allocates_before_validating() {
    // 2^62 bytes cannot be allocated anywhere, so this shows the order of the checks without
    // allocating: the input is too short, whatever the size it claims.
    let device = Device::new();
    let e = device.deserialize(&bare_header(1 << 62)).unwrap_err();
    assert!(
        matches!(e, hostas::Error::RangeTooShort { .. }),
        "expected RangeTooShort for a 56-byte input, got {e:?}"
    );
}

/// The small-size side of the same path is fine today (kept green).
#[test]
fn deserialize_short_input_is_rejected() {
    let device = Device::new();
    let e = device.deserialize(&bare_header(4096)).unwrap_err();
    assert!(matches!(e, hostas::Error::RangeTooShort { .. }), "{e:?}");
    assert!(SerializedHeader::parse(&bare_header(4096)[..55]).is_err());
}

/// Runs `f` on a thread; fails if it does not finish within `limit`.
fn finishes_within<T: Send + 'static>(
    limit: Duration,
    f: impl FnOnce() -> T + Send + 'static,
) -> T {
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let _ = tx.send(f());
    });
    rx.recv_timeout(limit)
        .unwrap_or_else(|_| panic!("did not finish within {limit:?}"))
}

/// Was a bug (hang, fixed in 74ed721): `build_acceleration_structures`
/// (crates/hostas/src/commands/build.rs, the cross-info scan "Instances may not reference any
/// destination of this call") walked `0..primitiveCount` of every instance geometry, skipping
/// instances that failed to read, before any count was checked against `maxInstanceCount`:
/// primitiveCount = 2^32 - 1 over an empty instance buffer took more than 5 s with the test
/// profile (optimized builds could drop the empty loop) before the call returned an error.
#[test]
fn huge_instance_count_hangs_the_reference_check() {
    let r = finishes_within(Duration::from_secs(5), || {
        let device = Device::new();
        let dst = device
            .create_acceleration_structure(&AccelerationStructureCreateInfo::new(
                vk::AccelerationStructureTypeKHR::TOP_LEVEL,
                4096,
            ))
            .unwrap();
        let geoms = [Geometry::instances(
            InstancesData::Array(&[]),
            vk::GeometryFlagsKHR::empty(),
        )];
        let mut scratch = vec![0u8; 4096];
        let info = BuildGeometryInfo::build(
            vk::AccelerationStructureTypeKHR::TOP_LEVEL,
            Default::default(),
            &geoms,
            dst,
            &mut scratch,
        );
        let range = [BuildRangeInfo {
            primitive_count: u32::MAX,
            ..Default::default()
        }];
        device
            .build_acceleration_structures(&mut [info], &[&range])
            .is_err()
    });
    assert!(r, "the build must fail");
}

/// A BLAS of AABBs (`spread` apart) in `geometries` geometries, built with ALLOW_UPDATE.
fn aabb_blas(
    device: &Device,
    boxes_per_geometry: usize,
    geometries: usize,
    spread: f32,
    flags: vk::BuildAccelerationStructureFlagsKHR,
) -> (hostas::AccelerationStructure, Vec<u8>) {
    let boxes: Vec<u8> = (0..boxes_per_geometry)
        .flat_map(|i| {
            let c = i as f32 * spread;
            [c, 0.0, 0.0, c + 0.5, 0.5, 0.5]
                .into_iter()
                .flat_map(f32::to_le_bytes)
        })
        .collect();
    let geoms: Vec<Geometry> = (0..geometries)
        .map(|_| {
            Geometry::aabbs(
                hostas::AabbsData {
                    data: &boxes,
                    stride: 24,
                },
                vk::GeometryFlagsKHR::empty(),
            )
        })
        .collect();
    let ranges: Vec<BuildRangeInfo> = (0..geometries)
        .map(|_| BuildRangeInfo {
            primitive_count: boxes_per_geometry as u32,
            ..Default::default()
        })
        .collect();
    let a = hostas::quick::build(
        device,
        vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL,
        flags | vk::BuildAccelerationStructureFlagsKHR::ALLOW_UPDATE,
        &geoms,
        &ranges,
    )
    .unwrap();
    (a, boxes)
}

/// Was a bug (overflow panic with overflow checks, fixed in 74ed721): an UPDATE summed its
/// ranges' primitive counts in u32 in `Device::geometry_records`
/// (crates/hostas/src/commands/build.rs, `first += r.primitive_count`) before anything checked
/// them (`update_one` did not call `validate::counts`): two AABB geometries of 2^31 primitives
/// each panicked with "attempt to add with overflow".
#[test]
fn update_with_huge_counts_overflows() {
    let device = Device::new();
    let (a, boxes) = aabb_blas(&device, 4, 2, 1.0, Default::default());
    let geoms: Vec<Geometry> = (0..2)
        .map(|_| {
            Geometry::aabbs(
                hostas::AabbsData {
                    data: &boxes,
                    stride: 24,
                },
                vk::GeometryFlagsKHR::empty(),
            )
        })
        .collect();
    let ranges = [BuildRangeInfo {
        primitive_count: 1 << 31,
        ..Default::default()
    }; 2];
    let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        let mut scratch = vec![0u8; 4096];
        let info = BuildGeometryInfo {
            ty: vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL,
            flags: vk::BuildAccelerationStructureFlagsKHR::ALLOW_UPDATE,
            mode: vk::BuildAccelerationStructureModeKHR::UPDATE,
            src: Some(a),
            dst: Some(a),
            geometries: &geoms,
            scratch: Some(&mut scratch),
        };
        device.build_acceleration_structures(&mut [info], &[&ranges])
    }));
    assert!(
        matches!(r, Ok(Err(_))),
        "the update must fail with an error, not a panic"
    );
}

/// Was a bug (panic, fixed in 74ed721): deserialization (`View::parse`) accepted geometry
/// records whose `geometry_type` disagreed with the structure's primitive kind, and UPDATE takes
/// the primitive kind from the new inputs. A serialized AABB BLAS whose record said TRIANGLES
/// (one u32, plus a supported vertexFormat) deserialized; an update with matching triangle
/// inputs passed `check_update_geometries`, then `refit` sliced the primitive section as 36-byte
/// triangles where 24-byte boxes are stored (crates/hostas/src/commands/build.rs, `refit`:
/// "range end index 2480 out of range for slice of length 2304"), or, when it fit, overwrote
/// the primitive-id and node sections (then "index out of bounds" in the node refit loop).
#[test]
fn update_refits_with_the_new_geometry_type() {
    let device = Device::new();
    // 60 identical boxes, LOW_MEMORY: leaves of 15 under two nodes, so the structure ends
    // before 36 bytes per box past the start of its primitive section.
    let flags = vk::BuildAccelerationStructureFlagsKHR::ALLOW_UPDATE
        | vk::BuildAccelerationStructureFlagsKHR::LOW_MEMORY;
    let (a, _) = aabb_blas(&device, 60, 1, 0.0, flags);
    assert!(device.statistics(a).unwrap().node_count <= 2);
    let mut bytes = device.serialize(a).unwrap();
    // The first geometry record: header 56, structure header 256; type at +12, format at +16.
    let rec = 56 + 256;
    assert_eq!(
        u32::from_le_bytes(bytes[rec + 12..rec + 16].try_into().unwrap()),
        vk::GeometryTypeKHR::AABBS.as_raw() as u32
    );
    bytes[rec + 12..rec + 16]
        .copy_from_slice(&(vk::GeometryTypeKHR::TRIANGLES.as_raw() as u32).to_le_bytes());
    bytes[rec + 16..rec + 20]
        .copy_from_slice(&(vk::Format::R32G32B32_SFLOAT.as_raw() as u32).to_le_bytes());
    let Ok(b) = device.deserialize(&bytes) else {
        return; // Fixed by rejecting the records at deserialization.
    };
    // The record says: UINT16 indices (raw 0), maxVertex 0, no transform, 60 primitives.
    let vertex = [0u8; 12];
    let indices = [0u8; 2 * 3 * 60];
    let geoms = [Geometry::triangles(
        hostas::TrianglesData {
            vertex_format: vk::Format::R32G32B32_SFLOAT,
            vertex_data: &vertex,
            vertex_stride: 12,
            max_vertex: 0,
            index_type: vk::IndexType::UINT16,
            index_data: Some(&indices),
            transform_data: None,
        },
        vk::GeometryFlagsKHR::empty(),
    )];
    let ranges = [BuildRangeInfo {
        primitive_count: 60,
        ..Default::default()
    }];
    let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        let mut scratch = vec![0u8; 4096];
        let info = BuildGeometryInfo {
            ty: vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL,
            flags,
            mode: vk::BuildAccelerationStructureModeKHR::UPDATE,
            src: Some(b),
            dst: Some(b),
            geometries: &geoms,
            scratch: Some(&mut scratch),
        };
        device.build_acceleration_structures(&mut [info], &[&ranges])
    }));
    assert!(
        matches!(r, Ok(Err(_))),
        "the update must be refused (source holds AABBs): {r:?}"
    );
}

/// Was a bug (unbounded allocation, fixed in 74ed721): a top-level structure's handle list is
/// sized from its header's `primitive_count` (crates/hostas/src/commands/copy.rs,
/// `handle_list`), and `View::parse` accepted any count up to 2^32 - 1 as long as the geometry
/// counts added up and nothing was stored. Memory the application wrote through `Buffer::write`
/// (which `View::parse` is documented to withstand) could make a SERIALIZATION_SIZE query or
/// `serialize` allocate up to 32 GiB. `View::parse` now rejects counts past the device limits.
#[test]
fn serialization_size_of_scribbled_tlas() {
    let device = Device::new();
    let blas = hostas::quick::build_triangle_blas(
        &device,
        &[[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        &[[0, 1, 2]],
        Default::default(),
    )
    .unwrap();
    // An empty TLAS (no active instance), then its counts raised to 2^26 (a 512 MiB list).
    let tlas = hostas::quick::build_tlas(
        &device,
        &[hostas::Instance {
            acceleration_structure_reference: 0,
            ..hostas::quick::instance(blas, hostas::Affine::IDENTITY)
        }],
        Default::default(),
    )
    .unwrap();
    let (buffer, offset, _) = device.placement(tlas).unwrap();
    let count: u32 = 1 << 26;
    buffer.write(offset + 24, &count.to_le_bytes()).unwrap(); // Header::primitive_count
    let mut geometries_offset = [0u8; 8];
    buffer.read(offset + 88, &mut geometries_offset).unwrap();
    let geometries_offset = u64::from_le_bytes(geometries_offset);
    buffer
        .write(offset + geometries_offset + 4, &count.to_le_bytes())
        .unwrap(); // GeometryRecord::primitive_count
    let size = device.acceleration_structure_property(
        tlas,
        vk::QueryType::ACCELERATION_STRUCTURE_SERIALIZATION_SIZE_KHR,
    );
    assert!(
        size.is_err(),
        "a TLAS claiming {count} instances (> maxInstanceCount) was accepted: serialization size {size:?}"
    );
    assert!(device.serialize(tlas).is_err());
    assert!(device.statistics(tlas).is_err());
}

/// Was a bug (found by the `ray_query` target, fixed in 74ed721): a ray with a zero direction
/// and tMax = +inf was reported to hit boxes that do not contain its origin, at t = +inf. Every
/// slab the origin lies below of gives an entry and an exit at +inf (`(lo - o) * (1 / 0)`), and
/// `BoxRay::aabb` (crates/hostas/src/traverse/query.rs) accepted `near <= min(far, tMax)`, here
/// `inf <= inf`, when a node whose bounds contain the origin led to the box's leaf:
/// `trace_closest` committed a generated hit at t = +inf and a ray query offered the candidate.
#[test]
fn zero_direction_ray_hits_boxes_at_infinity() {
    let device = Device::new();
    // A box the origin is below of in z, and a second box under the origin, so that the node
    // holding both contains the origin and is entered.
    let boxes = [
        hostas::Aabb {
            lo: [0.25, 0.25, 0.25],
            hi: [0.75, 0.75, 1.0],
        },
        hostas::Aabb {
            lo: [0.4, 0.4, -0.2],
            hi: [0.6, 0.6, -0.1],
        },
    ];
    let blas = hostas::quick::build_aabb_blas(
        &device,
        &boxes,
        vk::GeometryFlagsKHR::OPAQUE,
        Default::default(),
    )
    .unwrap();
    let tlas = hostas::quick::build_single_instance_tlas(&device, blas).unwrap();
    let scene = device.scene(tlas).unwrap();
    let ray = hostas::Ray::new([0.5, 0.5, 0.0], [0.0, 0.0, 0.0]);
    assert!(ray.validate().is_ok());
    let mut q = scene.ray_query(&ray).unwrap();
    let mut candidates = Vec::new();
    while q.proceed() {
        candidates.push(*q.candidate());
    }
    let hit = scene.trace_closest(&ray).unwrap();
    assert!(
        candidates.is_empty() && !hit.is_hit(),
        "the ray's only point is the origin, inside no box; candidates: {candidates:?}, closest hit {hit:?}"
    );
}
