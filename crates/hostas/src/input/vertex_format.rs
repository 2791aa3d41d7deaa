//! The vertex formats a hostas device supports for acceleration-structure vertex buffers
//! (`VK_FORMAT_FEATURE_ACCELERATION_STRUCTURE_VERTEX_BUFFER_BIT_KHR`), and their decoding.
//!
//! Only X, Y and Z are positions: two-component formats give z = 0 and a fourth component is
//! ignored. Normalized formats follow the spec's fixed-point conversion rules: UNORM is
//! `c / (2^b - 1)`, SNORM is `max(c / (2^(b-1) - 1), -1)`.

use ash::vk;

/// How one component is stored.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Component {
    F16,
    F32,
    F64,
    Snorm8,
    Snorm16,
    Unorm8,
    Unorm16,
    /// `A2B10G10R10_UNORM_PACK32`: x in bits 0..9, y in 10..19, z in 20..29.
    Unorm10Packed,
}

/// Size and shape of a supported vertex format.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct VertexFormatInfo {
    pub format: vk::Format,
    pub component: Component,
    /// Components stored per vertex (2, 3 or 4).
    pub components: u32,
    /// Bytes per component; for the packed format, the whole 4-byte word.
    pub component_size: u32,
    /// Bytes per vertex.
    pub size: u32,
    /// Whether a NaN can be represented (inactive triangles exist only for float formats).
    pub can_be_nan: bool,
}

const fn info(format: vk::Format, component: Component, components: u32) -> VertexFormatInfo {
    let component_size = match component {
        Component::F16 | Component::Snorm16 | Component::Unorm16 => 2,
        Component::F32 | Component::Unorm10Packed => 4,
        Component::F64 => 8,
        Component::Snorm8 | Component::Unorm8 => 1,
    };
    let size = if matches!(component, Component::Unorm10Packed) {
        4
    } else {
        component_size * components
    };
    let can_be_nan = matches!(component, Component::F16 | Component::F32 | Component::F64);
    VertexFormatInfo {
        format,
        component,
        components,
        component_size,
        size,
        can_be_nan,
    }
}

/// Every vertex format hostas accepts: the six the spec makes mandatory, the ten optional ones
/// the CTS probes, and the 8/16-bit UNORM formats.
pub const SUPPORTED_VERTEX_FORMATS: &[VertexFormatInfo] = &[
    info(vk::Format::R32G32_SFLOAT, Component::F32, 2),
    info(vk::Format::R32G32B32_SFLOAT, Component::F32, 3),
    info(vk::Format::R32G32B32A32_SFLOAT, Component::F32, 4),
    info(vk::Format::R16G16_SFLOAT, Component::F16, 2),
    info(vk::Format::R16G16B16_SFLOAT, Component::F16, 3),
    info(vk::Format::R16G16B16A16_SFLOAT, Component::F16, 4),
    info(vk::Format::R64G64_SFLOAT, Component::F64, 2),
    info(vk::Format::R64G64B64_SFLOAT, Component::F64, 3),
    info(vk::Format::R64G64B64A64_SFLOAT, Component::F64, 4),
    info(vk::Format::R16G16_SNORM, Component::Snorm16, 2),
    info(vk::Format::R16G16B16_SNORM, Component::Snorm16, 3),
    info(vk::Format::R16G16B16A16_SNORM, Component::Snorm16, 4),
    info(vk::Format::R8G8_SNORM, Component::Snorm8, 2),
    info(vk::Format::R8G8B8_SNORM, Component::Snorm8, 3),
    info(vk::Format::R8G8B8A8_SNORM, Component::Snorm8, 4),
    info(vk::Format::R16G16_UNORM, Component::Unorm16, 2),
    info(vk::Format::R16G16B16_UNORM, Component::Unorm16, 3),
    info(vk::Format::R16G16B16A16_UNORM, Component::Unorm16, 4),
    info(vk::Format::R8G8_UNORM, Component::Unorm8, 2),
    info(vk::Format::R8G8B8_UNORM, Component::Unorm8, 3),
    info(vk::Format::R8G8B8A8_UNORM, Component::Unorm8, 4),
    info(
        vk::Format::A2B10G10R10_UNORM_PACK32,
        Component::Unorm10Packed,
        3,
    ),
];

/// The format's description, or `None` when it cannot be used as an acceleration-structure
/// vertex format.
pub fn vertex_format_info(format: vk::Format) -> Option<VertexFormatInfo> {
    SUPPORTED_VERTEX_FORMATS
        .iter()
        .copied()
        .find(|i| i.format == format)
}

impl VertexFormatInfo {
    /// Decodes the position stored in `bytes` (at least `self.size` long).
    #[inline]
    pub fn decode(&self, bytes: &[u8]) -> Option<[f32; 3]> {
        let bytes = bytes.get(..self.size as usize)?;
        let mut out = [0f32; 3];
        if self.component == Component::Unorm10Packed {
            let w = u32::from_le_bytes(bytes.try_into().ok()?);
            for (k, o) in out.iter_mut().enumerate() {
                *o = ((w >> (10 * k)) & 0x3ff) as f32 / 1023.0;
            }
            return Some(out);
        }
        let n = self.components.min(3) as usize;
        let cs = self.component_size as usize;
        for (k, o) in out.iter_mut().enumerate().take(n) {
            let c = &bytes[k * cs..(k + 1) * cs];
            *o = match self.component {
                Component::F32 => f32::from_le_bytes([c[0], c[1], c[2], c[3]]),
                Component::F16 => half::f16::from_le_bytes([c[0], c[1]]).to_f32(),
                Component::F64 => {
                    f64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]) as f32
                }
                Component::Snorm8 => (c[0] as i8 as f32 / 127.0).max(-1.0),
                Component::Snorm16 => (i16::from_le_bytes([c[0], c[1]]) as f32 / 32767.0).max(-1.0),
                Component::Unorm8 => c[0] as f32 / 255.0,
                Component::Unorm16 => u16::from_le_bytes([c[0], c[1]]) as f32 / 65535.0,
                Component::Unorm10Packed => unreachable!("handled above"),
            };
        }
        Some(out)
    }

    /// The alignment `primitiveOffset` needs for non-indexed triangles (VUID-03657): the
    /// component size, or the whole format for packed formats.
    pub fn offset_alignment(&self) -> u32 {
        self.component_size
    }
}
