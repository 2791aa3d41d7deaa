//! # hostas
//!
//! Vulkan's host acceleration-structure commands (`VK_KHR_acceleration_structure` with
//! `accelerationStructureHostCommands`) implemented on the CPU, with CPU ray traversal that
//! follows the ray-query semantics of the specification to the letter.
//!
//! ```
//! use hostas::{vk, Device, Ray};
//! let device = Device::new();
//! // One triangle in the z = 0 plane.
//! let positions = [[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
//! let blas = hostas::quick::build_triangle_blas(&device, &positions, &[[0, 1, 2]],
//!     vk::BuildAccelerationStructureFlagsKHR::PREFER_FAST_TRACE).unwrap();
//! let tlas = hostas::quick::build_single_instance_tlas(&device, blas).unwrap();
//! let scene = device.scene(tlas).unwrap();
//! let hit = scene.trace_closest(&Ray::new([0.25, 0.25, 1.0], [0.0, 0.0, -1.0])).unwrap();
//! assert_eq!(hit.t, 1.0);
//! ```
#![forbid(unsafe_code)]
// Negated float comparisons are deliberate (they treat NaN as failing the test), and indexed
// loops over lanes are the form that autovectorizes.
#![allow(clippy::neg_cmp_op_on_partial_ord, clippy::needless_range_loop)]

pub mod build;
pub mod commands;
pub mod device;
pub mod error;
pub mod input;
pub mod layout;
pub mod math;
pub mod memory;
pub mod quick;
pub mod stats;
pub mod traverse;

pub use ash::vk;
pub use commands::BuildSizes;
pub use device::{AccelerationStructure, AccelerationStructureCreateInfo, Device};
pub use error::{Error, Location, Result};
pub use input::instances::Instance;
pub use input::{
    AabbsData, BuildGeometryInfo, BuildRangeInfo, Geometry, GeometryData, InstancesData,
    TrianglesData,
};
pub use math::{Aabb, Affine};
pub use memory::{Buffer, HostMemory};
pub use traverse::{
    CandidateType, CommittedType, Hit, HitKind, Interleave, Intersection, Ray, RayFlags, RayQuery,
    Scene, Tracer,
};
