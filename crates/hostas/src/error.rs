//! The error type of every hostas command.
//!
//! A failed valid-usage rule is reported as [`Error::Validation`] with the rule's VUID and the
//! index of the offending build info, geometry and primitive, so the message points at the
//! application's mistake. Each error maps onto the `VkResult` a Vulkan command would return.

use ash::vk;
use std::fmt;

/// Where in a command's input an error was found.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Location {
    /// Index into `pInfos` (build) or the structure list (queries).
    pub info: Option<u32>,
    /// Index into `pGeometries` / `ppGeometries`.
    pub geometry: Option<u32>,
    /// Primitive (triangle, AABB or instance) index within the geometry's range.
    pub primitive: Option<u32>,
    /// Index of the ray in a batch ([`Tracer::closest_batch`](crate::Tracer::closest_batch),
    /// [`Scene::trace_batch`](crate::Scene::trace_batch)).
    pub ray: Option<u64>,
}

impl Location {
    pub const NONE: Location = Location {
        info: None,
        geometry: None,
        primitive: None,
        ray: None,
    };
    pub fn info(i: usize) -> Self {
        Location {
            info: Some(i as u32),
            ..Self::NONE
        }
    }
    pub fn geometry(self, g: usize) -> Self {
        Location {
            geometry: Some(g as u32),
            ..self
        }
    }
    pub fn primitive(self, p: u32) -> Self {
        Location {
            primitive: Some(p),
            ..self
        }
    }
    pub fn ray(self, r: u64) -> Self {
        Location {
            ray: Some(r),
            ..self
        }
    }
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let mut sep = "";
        for (name, v) in [
            ("info", self.info.map(u64::from)),
            ("geometry", self.geometry.map(u64::from)),
            ("primitive", self.primitive.map(u64::from)),
            ("ray", self.ray),
        ] {
            if let Some(v) = v {
                write!(f, "{sep}{name} {v}")?;
                sep = ", ";
            }
        }
        Ok(())
    }
}

/// Everything that can go wrong in a hostas command.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum Error {
    /// The input breaks a valid-usage rule of the Vulkan specification.
    #[error("{vuid}: {message} ({location})")]
    Validation {
        vuid: &'static str,
        message: String,
        location: Location,
    },
    /// A host-memory range handed in (vertex, index, AABB, instance, scratch or destination
    /// bytes) is shorter than the command needs to read or write.
    #[error("input range too short: {what} needs {needed} bytes, {available} given ({location})")]
    RangeTooShort {
        what: &'static str,
        needed: u64,
        available: u64,
        location: Location,
    },
    /// A handle does not name a live object of this device.
    #[error("unknown {kind} handle {handle:#x}")]
    UnknownHandle { kind: &'static str, handle: u64 },
    /// The structure's memory is locked by a live `Scene` or another command.
    #[error(
        "acceleration structure {handle:#x} is in use (a Scene still reads it, or another command writes it)"
    )]
    InUse { handle: u64 },
    /// A structure's bytes are not a hostas acceleration structure this version can read.
    #[error("acceleration structure {handle:#x} holds no valid structure: {reason}")]
    NotBuilt { handle: u64, reason: String },
    /// A feature the specification names that this version does not implement.
    #[error("not supported: {0}")]
    NotSupported(String),
    /// Allocation failed or a size overflowed the host's address space.
    #[error("out of host memory: {0}")]
    OutOfHostMemory(String),
}

impl Error {
    pub(crate) fn vuid(vuid: &'static str, location: Location, message: impl Into<String>) -> Self {
        Error::Validation {
            vuid,
            message: message.into(),
            location,
        }
    }

    /// The VUID of a validation error.
    pub fn vuid_str(&self) -> Option<&'static str> {
        match self {
            Error::Validation { vuid, .. } => Some(vuid),
            _ => None,
        }
    }

    /// Where the error was found, for validation and range errors.
    pub fn location(&self) -> Option<Location> {
        match self {
            Error::Validation { location, .. } | Error::RangeTooShort { location, .. } => {
                Some(*location)
            }
            _ => None,
        }
    }

    /// [`Error::location`], to amend.
    fn location_mut(&mut self) -> Option<&mut Location> {
        match self {
            Error::Validation { location, .. } | Error::RangeTooShort { location, .. } => {
                Some(location)
            }
            _ => None,
        }
    }

    /// The error with ray `index` of a batch as its location's ray (validation and range
    /// errors; others are returned as they are).
    pub(crate) fn in_ray(mut self, index: usize) -> Self {
        if let Some(location) = self.location_mut() {
            location.ray = Some(index as u64);
        }
        self
    }

    /// The error of ray `index` of a batch moved by `offset` (the batch was part of a larger
    /// one starting there).
    pub(crate) fn shift_ray(mut self, offset: usize) -> Self {
        if let Some(location) = self.location_mut() {
            location.ray = location.ray.map(|r| r + offset as u64);
        }
        self
    }

    /// The `VkResult` a Vulkan command returns for this error.
    pub fn vk_result(&self) -> vk::Result {
        match self {
            Error::Validation { .. }
            | Error::RangeTooShort { .. }
            | Error::UnknownHandle { .. } => vk::Result::ERROR_VALIDATION_FAILED_EXT,
            Error::OutOfHostMemory(_) => vk::Result::ERROR_OUT_OF_HOST_MEMORY,
            Error::NotSupported(_) => vk::Result::ERROR_FEATURE_NOT_PRESENT,
            Error::InUse { .. } | Error::NotBuilt { .. } => vk::Result::ERROR_UNKNOWN,
        }
    }
}

pub type Result<T, E = Error> = std::result::Result<T, E>;
