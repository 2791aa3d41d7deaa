//! The device: properties, features, UUIDs, and the acceleration-structure objects.

use crate::error::{Error, Location, Result};
use crate::layout::{LAYOUT_VERSION, view};
use crate::memory::Buffer;
use ash::vk;
use parking_lot::RwLock;
use std::collections::HashMap;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

/// A `VkAccelerationStructureKHR` handle. Its value is also its device address
/// (`vkGetAccelerationStructureDeviceAddressKHR`) and the `accelerationStructureReference`
/// instances use: non-zero, 256-aligned, stable for the object's lifetime.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct AccelerationStructure(pub u64);

impl AccelerationStructure {
    pub const NULL: AccelerationStructure = AccelerationStructure(0);
    pub fn raw(self) -> u64 {
        self.0
    }
    /// `vkGetAccelerationStructureDeviceAddressKHR`.
    pub fn device_address(self) -> u64 {
        self.0
    }
}

/// `VkAccelerationStructureCreateInfoKHR`.
#[derive(Clone, Debug)]
pub struct AccelerationStructureCreateInfo {
    pub create_flags: vk::AccelerationStructureCreateFlagsKHR,
    /// The buffer the structure lives in, or `None` for memory that hostas allocates.
    pub buffer: Option<Buffer>,
    /// Multiple of 256 (VUID-03734).
    pub offset: u64,
    pub size: u64,
    pub ty: vk::AccelerationStructureTypeKHR,
    /// Must be 0: capture/replay addresses are not supported.
    pub device_address: u64,
}

impl AccelerationStructureCreateInfo {
    pub fn new(ty: vk::AccelerationStructureTypeKHR, size: u64) -> Self {
        AccelerationStructureCreateInfo {
            create_flags: Default::default(),
            buffer: None,
            offset: 0,
            size,
            ty,
            device_address: 0,
        }
    }
}

/// A created acceleration structure: its placement.
#[derive(Clone, Debug)]
pub(crate) struct AsObject {
    pub handle: u64,
    pub ty: vk::AccelerationStructureTypeKHR,
    pub buffer: Buffer,
    pub offset: u64,
    pub size: u64,
}

/// `VkPhysicalDeviceAccelerationStructurePropertiesKHR`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct AccelerationStructureProperties {
    pub max_geometry_count: u64,
    pub max_instance_count: u64,
    pub max_primitive_count: u64,
    pub max_per_stage_descriptor_acceleration_structures: u32,
    pub max_per_stage_descriptor_update_after_bind_acceleration_structures: u32,
    pub max_descriptor_set_acceleration_structures: u32,
    pub max_descriptor_set_update_after_bind_acceleration_structures: u32,
    pub min_acceleration_structure_scratch_offset_alignment: u32,
}

/// `VkPhysicalDeviceAccelerationStructureFeaturesKHR`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct AccelerationStructureFeatures {
    pub acceleration_structure: bool,
    pub acceleration_structure_capture_replay: bool,
    pub acceleration_structure_indirect_build: bool,
    pub acceleration_structure_host_commands: bool,
    pub descriptor_binding_acceleration_structure_update_after_bind: bool,
}

pub const PROPERTIES: AccelerationStructureProperties = AccelerationStructureProperties {
    max_geometry_count: (1 << 24) - 1,
    max_instance_count: (1 << 24) - 1,
    max_primitive_count: (1 << 29) - 1,
    max_per_stage_descriptor_acceleration_structures: 1 << 20,
    max_per_stage_descriptor_update_after_bind_acceleration_structures: 1 << 20,
    max_descriptor_set_acceleration_structures: 1 << 20,
    max_descriptor_set_update_after_bind_acceleration_structures: 1 << 20,
    min_acceleration_structure_scratch_offset_alignment: 128,
};

pub const FEATURES: AccelerationStructureFeatures = AccelerationStructureFeatures {
    acceleration_structure: true,
    acceleration_structure_capture_replay: false,
    acceleration_structure_indirect_build: false,
    acceleration_structure_host_commands: true,
    descriptor_binding_acceleration_structure_update_after_bind: true,
};

const fn fnv1a(bytes: &[u8], seed: u64) -> u64 {
    let mut h = 0xcbf2_9ce4_8422_2325u64 ^ seed;
    let mut i = 0;
    while i < bytes.len() {
        h ^= bytes[i] as u64;
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
        i += 1;
    }
    h
}

const fn uuid_from(a: u64, b: u64) -> [u8; 16] {
    let a = a.to_le_bytes();
    let b = b.to_le_bytes();
    let mut out = [0u8; 16];
    let mut i = 0;
    while i < 8 {
        out[i] = a[i];
        out[i + 8] = b[i];
        i += 1;
    }
    out
}

/// `VkPhysicalDeviceIDProperties::driverUUID`: names this implementation and version.
pub const DRIVER_UUID: [u8; 16] = {
    let v = env!("CARGO_PKG_VERSION").as_bytes();
    uuid_from(fnv1a(b"hostas driver", 0), fnv1a(v, 1))
};

/// The compatibility UUID written at offset 16 of serialized structures: derived from the byte
/// layout version, endianness and pointer width, so any change of layout makes old data
/// `INCOMPATIBLE`.
pub const COMPATIBILITY_UUID: [u8; 16] = {
    let v = LAYOUT_VERSION.to_le_bytes();
    let endian: u8 = if cfg!(target_endian = "little") { 1 } else { 2 };
    let ptr = (usize::BITS / 8) as u8;
    let tag = [
        b'h', b'o', b's', b't', b'a', b's', v[0], v[1], v[2], v[3], endian, ptr,
    ];
    uuid_from(fnv1a(&tag, 2), fnv1a(&tag, 3))
};

struct Shared {
    objects: RwLock<HashMap<u64, AsObject>>,
    next_handle: AtomicU64,
}

/// A hostas device: the `VkDevice` the host commands run on.
#[derive(Clone)]
pub struct Device {
    shared: Arc<Shared>,
}

impl Default for Device {
    fn default() -> Self {
        Device::new()
    }
}

static NEXT_DEVICE: AtomicU64 = AtomicU64::new(1);

impl Device {
    pub fn new() -> Device {
        // Handles of different devices never collide: each device takes its own 2^40 range.
        let base = NEXT_DEVICE.fetch_add(1, Ordering::Relaxed) << 40;
        Device {
            shared: Arc::new(Shared {
                objects: RwLock::new(HashMap::new()),
                next_handle: AtomicU64::new(base),
            }),
        }
    }

    pub fn properties(&self) -> AccelerationStructureProperties {
        PROPERTIES
    }
    pub fn features(&self) -> AccelerationStructureFeatures {
        FEATURES
    }
    pub fn driver_uuid(&self) -> [u8; 16] {
        DRIVER_UUID
    }

    /// `vkCreateAccelerationStructureKHR`.
    #[doc(alias = "vkCreateAccelerationStructureKHR")]
    pub fn create_acceleration_structure(
        &self,
        info: &AccelerationStructureCreateInfo,
    ) -> Result<AccelerationStructure> {
        let at = Location::NONE;
        match info.ty {
            vk::AccelerationStructureTypeKHR::TOP_LEVEL
            | vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL
            | vk::AccelerationStructureTypeKHR::GENERIC => {}
            other => {
                return Err(Error::vuid(
                    "VUID-VkAccelerationStructureCreateInfoKHR-type-parameter",
                    at,
                    format!(
                        "type {other:?} cannot be created with vkCreateAccelerationStructureKHR"
                    ),
                ));
            }
        }
        if !info.offset.is_multiple_of(256) {
            return Err(Error::vuid(
                "VUID-VkAccelerationStructureCreateInfoKHR-offset-03734",
                at,
                format!("offset {} is not a multiple of 256", info.offset),
            ));
        }
        if info.device_address != 0 {
            return Err(Error::vuid(
                "VUID-vkCreateAccelerationStructureKHR-deviceAddress-03488",
                at,
                "deviceAddress capture/replay needs accelerationStructureCaptureReplay, which hostas does not support",
            ));
        }
        if info
            .create_flags
            .contains(vk::AccelerationStructureCreateFlagsKHR::DEVICE_ADDRESS_CAPTURE_REPLAY)
        {
            return Err(Error::vuid(
                "VUID-VkAccelerationStructureCreateInfoKHR-createFlags-03613",
                at,
                "DEVICE_ADDRESS_CAPTURE_REPLAY needs accelerationStructureCaptureReplay, which hostas does not support",
            ));
        }
        if info
            .create_flags
            .contains(vk::AccelerationStructureCreateFlagsKHR::from_raw(0x4))
        {
            return Err(Error::NotSupported(
                "VK_NV_ray_tracing_motion_blur structures (MOTION_BIT_NV)".into(),
            ));
        }
        if info.size == 0 {
            return Err(Error::vuid(
                "VUID-VkAccelerationStructureCreateInfoKHR-size-parameter",
                at,
                "size must not be 0",
            ));
        }
        let buffer = match &info.buffer {
            Some(b) => {
                if info
                    .offset
                    .checked_add(info.size)
                    .is_none_or(|end| end > b.size())
                {
                    return Err(Error::vuid(
                        "VUID-VkAccelerationStructureCreateInfoKHR-offset-03616",
                        at,
                        format!(
                            "offset {} + size {} exceeds the buffer's {} bytes",
                            info.offset,
                            info.size,
                            b.size()
                        ),
                    ));
                }
                b.clone()
            }
            None => {
                if info.offset != 0 {
                    return Err(Error::vuid(
                        "VUID-VkAccelerationStructureCreateInfoKHR-offset-03616",
                        at,
                        "offset must be 0 for library-owned memory",
                    ));
                }
                Buffer::new(info.size)?
            }
        };
        let handle = self.shared.next_handle.fetch_add(256, Ordering::Relaxed) + 256;
        let obj = AsObject {
            handle,
            ty: info.ty,
            buffer,
            offset: info.offset,
            size: info.size,
        };
        self.shared.objects.write().insert(handle, obj);
        Ok(AccelerationStructure(handle))
    }

    /// `vkDestroyAccelerationStructureKHR`. Destroying `NULL` does nothing.
    #[doc(alias = "vkDestroyAccelerationStructureKHR")]
    pub fn destroy_acceleration_structure(&self, a: AccelerationStructure) -> Result<()> {
        if a == AccelerationStructure::NULL {
            return Ok(());
        }
        self.shared
            .objects
            .write()
            .remove(&a.0)
            .map(|_| ())
            .ok_or(Error::UnknownHandle {
                kind: "acceleration structure",
                handle: a.0,
            })
    }

    /// `vkGetAccelerationStructureDeviceAddressKHR`.
    #[doc(alias = "vkGetAccelerationStructureDeviceAddressKHR")]
    pub fn device_address(&self, a: AccelerationStructure) -> Result<u64> {
        self.object(a).map(|o| o.handle)
    }

    /// `vkGetDeviceAccelerationStructureCompatibilityKHR`: compares the driver and compatibility
    /// UUIDs at the start of serialized data (`pVersionData`, 32 bytes).
    #[doc(alias = "vkGetDeviceAccelerationStructureCompatibilityKHR")]
    pub fn compatibility(
        &self,
        version_data: &[u8; 32],
    ) -> vk::AccelerationStructureCompatibilityKHR {
        if version_data[..16] == DRIVER_UUID && version_data[16..] == COMPATIBILITY_UUID {
            vk::AccelerationStructureCompatibilityKHR::COMPATIBLE
        } else {
            vk::AccelerationStructureCompatibilityKHR::INCOMPATIBLE
        }
    }

    pub(crate) fn object(&self, a: AccelerationStructure) -> Result<AsObject> {
        self.shared
            .objects
            .read()
            .get(&a.0)
            .cloned()
            .ok_or(Error::UnknownHandle {
                kind: "acceleration structure",
                handle: a.0,
            })
    }

    /// The buffer and offset a structure lives at.
    pub fn placement(&self, a: AccelerationStructure) -> Result<(Buffer, u64, u64)> {
        let o = self.object(a)?;
        Ok((o.buffer, o.offset, o.size))
    }

    /// Runs `f` over the structure's bytes, read-locked.
    pub(crate) fn with_bytes<R>(
        &self,
        a: AccelerationStructure,
        f: impl FnOnce(&[u8]) -> Result<R>,
    ) -> Result<R> {
        let o = self.object(a)?;
        let mem = o.buffer.memory().ok_or_else(|| Error::NotBuilt {
            handle: a.0,
            reason: "its buffer has no memory bound".into(),
        })?;
        let guard = mem.try_read().ok_or(Error::InUse { handle: a.0 })?;
        f(&guard.bytes()[o.offset as usize..(o.offset + o.size) as usize])
    }

    /// The header of a built structure.
    pub(crate) fn header(&self, a: AccelerationStructure) -> Result<crate::layout::Header> {
        self.with_bytes(a, |b| {
            view::read_header(b).map_err(|reason| Error::NotBuilt {
                handle: a.0,
                reason,
            })
        })
    }
}
