//! The file `hostas build` writes: several serialized bottom-level structures and the
//! top-level structure over them, in one container.
//!
//! # Format `HOSTASF1` (all integers little-endian)
//!
//! | offset | size | field |
//! |---:|---:|---|
//! | 0 | 8 | magic `HOSTASF1` |
//! | 8 | 4 | `u32` format version, 1 |
//! | 12 | 4 | `u32` N, the number of bottom-level structures |
//! | 16 | 24 | `f32[6]` world bounds of the scene: min x, y, z, max x, y, z (NaN when unknown) |
//! | 40 | 8 | reserved, 0 |
//! | 48 | 24 (N+1) | entries: bottom levels 0..N-1, then the top level |
//! | | | names (UTF-8), then the blobs, each at a multiple of 16 |
//!
//! An entry is `u64 offset, u64 length` of its blob and `u32 offset, u32 length` of its name,
//! all counted from the start of the file. Each blob is exactly what
//! `vkCopyAccelerationStructureToMemoryKHR` wrote (the spec's 56-byte header, the handle list,
//! the structure), except for the top level's handle list: there, handle `i + 1` stands for
//! bottom level `i` of the file and 0 for an inactive instance. A reader deserializes the
//! bottom levels first, rewrites the handle list with their new handles, then deserializes the
//! top level (as the Vulkan CTS does).

use anyhow::{Context, Result, anyhow, bail, ensure};
use hostas::commands::SerializedHeader;
use hostas::{AccelerationStructure, Device};

pub const MAGIC: &[u8; 8] = b"HOSTASF1";
pub const VERSION: u32 = 1;
const HEADER: usize = 48;
const ENTRY: usize = 24;
const HANDLES_AT: usize = 56;

/// One structure of a container.
#[derive(Clone, Debug, PartialEq)]
pub struct Blob {
    pub name: String,
    /// Serialized structure (spec header, handle list, payload).
    pub data: Vec<u8>,
}

/// A parsed container.
#[derive(Clone, Debug, PartialEq)]
pub struct Container {
    pub blases: Vec<Blob>,
    /// The top level, with handles `i + 1` naming `blases[i]`.
    pub tlas: Blob,
    pub bounds: Option<([f32; 3], [f32; 3])>,
}

/// Whether `bytes` start with the container magic.
pub fn is_container(bytes: &[u8]) -> bool {
    bytes.starts_with(MAGIC)
}

fn align16(v: usize) -> usize {
    v.div_ceil(16) * 16
}

fn u32_at(b: &[u8], o: usize) -> u32 {
    u32::from_le_bytes(b[o..o + 4].try_into().unwrap_or_default())
}
fn u64_at(b: &[u8], o: usize) -> u64 {
    u64::from_le_bytes(b[o..o + 8].try_into().unwrap_or_default())
}

/// Rewrites the handle list of serialized data with `map(handle)`.
pub fn rewrite_handles(
    data: &mut [u8],
    mut map: impl FnMut(usize, u64) -> Result<u64>,
) -> Result<()> {
    let header = SerializedHeader::parse(data).map_err(|e| anyhow!("{e}"))?;
    for (i, &h) in header.handles.iter().enumerate() {
        let v = map(i, h)?;
        data[HANDLES_AT + 8 * i..HANDLES_AT + 8 * i + 8].copy_from_slice(&v.to_le_bytes());
    }
    Ok(())
}

impl Container {
    /// Serializes `blases` and `tlas` (whose instances reference only `blases`) from `device`.
    pub fn from_device(
        device: &Device,
        blases: &[(String, AccelerationStructure)],
        tlas: AccelerationStructure,
        bounds: Option<([f32; 3], [f32; 3])>,
    ) -> Result<Container> {
        let mut out = Vec::with_capacity(blases.len());
        for (name, b) in blases {
            out.push(Blob {
                name: name.clone(),
                data: device
                    .serialize(*b)
                    .with_context(|| format!("serializing the bottom level of {name}"))?,
            });
        }
        let mut data = device
            .serialize(tlas)
            .context("serializing the top level")?;
        rewrite_handles(&mut data, |i, h| {
            if h == 0 {
                return Ok(0);
            }
            let k = blases.iter().position(|(_, b)| b.raw() == h).ok_or_else(|| anyhow!("instance {i} references {h:#x}, which is not one of the structures being written"))?;
            Ok(k as u64 + 1)
        })?;
        Ok(Container {
            blases: out,
            tlas: Blob {
                name: String::new(),
                data,
            },
            bounds,
        })
    }

    pub fn to_bytes(&self) -> Vec<u8> {
        let n = self.blases.len();
        let all: Vec<&Blob> = self
            .blases
            .iter()
            .chain(std::iter::once(&self.tlas))
            .collect();
        let names_at = HEADER + ENTRY * all.len();
        let names_len: usize = all.iter().map(|b| b.name.len()).sum();
        let mut blob_at = align16(names_at + names_len);
        let mut out = vec![0u8; names_at];
        out[..8].copy_from_slice(MAGIC);
        out[8..12].copy_from_slice(&VERSION.to_le_bytes());
        out[12..16].copy_from_slice(&(n as u32).to_le_bytes());
        let (lo, hi) = self.bounds.unwrap_or(([f32::NAN; 3], [f32::NAN; 3]));
        for (k, v) in lo.iter().chain(hi.iter()).enumerate() {
            out[16 + 4 * k..20 + 4 * k].copy_from_slice(&v.to_le_bytes());
        }
        let mut name_at = names_at;
        for (i, b) in all.iter().enumerate() {
            let e = HEADER + ENTRY * i;
            out[e..e + 8].copy_from_slice(&(blob_at as u64).to_le_bytes());
            out[e + 8..e + 16].copy_from_slice(&(b.data.len() as u64).to_le_bytes());
            out[e + 16..e + 20].copy_from_slice(&(name_at as u32).to_le_bytes());
            out[e + 20..e + 24].copy_from_slice(&(b.name.len() as u32).to_le_bytes());
            name_at += b.name.len();
            blob_at = align16(blob_at + b.data.len());
        }
        for b in &all {
            out.extend_from_slice(b.name.as_bytes());
        }
        for b in &all {
            out.resize(align16(out.len()), 0);
            out.extend_from_slice(&b.data);
        }
        out
    }

    /// Parses a container, checking every offset and length against the file.
    pub fn parse(bytes: &[u8]) -> Result<Container> {
        ensure!(
            is_container(bytes),
            "not a hostas build file (no HOSTASF1 magic)"
        );
        ensure!(
            bytes.len() >= HEADER,
            "truncated: {} bytes is too short for the 48-byte header",
            bytes.len()
        );
        let version = u32_at(bytes, 8);
        ensure!(
            version == VERSION,
            "format version {version} is not supported (this hostas reads version {VERSION})"
        );
        let n = u32_at(bytes, 12) as usize;
        let entries_end = n
            .checked_add(1)
            .and_then(|k| k.checked_mul(ENTRY))
            .and_then(|s| s.checked_add(HEADER));
        let entries_end = entries_end.filter(|&e| e <= bytes.len()).ok_or_else(|| {
            anyhow!("truncated: the header announces {n} bottom-level structures, but the file ({} bytes) is too short for their entries", bytes.len())
        })?;
        let _ = entries_end;
        let f = |k: usize| {
            f32::from_le_bytes(bytes[16 + 4 * k..20 + 4 * k].try_into().unwrap_or_default())
        };
        let lo = [f(0), f(1), f(2)];
        let hi = [f(3), f(4), f(5)];
        let bounds = (lo.iter().chain(hi.iter()).all(|v| v.is_finite())).then_some((lo, hi));
        let mut blobs = Vec::with_capacity(n + 1);
        for i in 0..=n {
            let what = if i == n {
                "the top level".to_string()
            } else {
                format!("bottom level {i}")
            };
            let e = HEADER + ENTRY * i;
            let (off, len) = (u64_at(bytes, e), u64_at(bytes, e + 8));
            let (name_off, name_len) = (u32_at(bytes, e + 16) as u64, u32_at(bytes, e + 20) as u64);
            let end = off
                .checked_add(len)
                .filter(|&end| end <= bytes.len() as u64);
            let Some(end) = end else {
                bail!(
                    "truncated: {what} is announced at bytes {off}..{}, but the file has {} bytes",
                    off.saturating_add(len),
                    bytes.len()
                );
            };
            let name_end = name_off
                .checked_add(name_len)
                .filter(|&end| end <= bytes.len() as u64);
            let Some(name_end) = name_end else {
                bail!(
                    "truncated: the name of {what} is announced at bytes {name_off}..{}, but the file has {} bytes",
                    name_off + name_len,
                    bytes.len()
                );
            };
            let name =
                String::from_utf8_lossy(&bytes[name_off as usize..name_end as usize]).into_owned();
            blobs.push(Blob {
                name,
                data: bytes[off as usize..end as usize].to_vec(),
            });
        }
        let tlas = blobs.pop().unwrap_or(Blob {
            name: String::new(),
            data: Vec::new(),
        });
        Ok(Container {
            blases: blobs,
            tlas,
            bounds,
        })
    }

    /// Deserializes every structure onto `device`: the bottom levels, then the top level with
    /// its handle list rewritten to them. Returns (bottom levels, top level).
    pub fn load(
        &self,
        device: &Device,
    ) -> Result<(Vec<AccelerationStructure>, AccelerationStructure)> {
        let mut blases = Vec::with_capacity(self.blases.len());
        for (i, b) in self.blases.iter().enumerate() {
            let a = device
                .deserialize(&b.data)
                .map_err(|e| anyhow!("bottom level {i} ({}): {e}", b.name))?;
            blases.push(a);
        }
        let mut data = self.tlas.data.clone();
        rewrite_handles(&mut data, |i, h| match h {
            0 => Ok(0),
            k if k <= blases.len() as u64 => Ok(blases[k as usize - 1].raw()),
            k => bail!(
                "top level: instance {i} refers to bottom level {} but the file holds {}",
                k - 1,
                blases.len()
            ),
        })
        .map_err(|e| anyhow!("top level: {e}"))?;
        let tlas = device
            .deserialize(&data)
            .map_err(|e| anyhow!("top level: {e}"))?;
        Ok((blases, tlas))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Container {
        Container {
            blases: vec![
                Blob {
                    name: "a".into(),
                    data: vec![1; 70],
                },
                Blob {
                    name: "bé".into(),
                    data: vec![2; 33],
                },
            ],
            tlas: Blob {
                name: String::new(),
                data: vec![3; 90],
            },
            bounds: Some(([0.0, 1.0, 2.0], [3.0, 4.0, 5.0])),
        }
    }

    #[test]
    fn round_trip() {
        let c = sample();
        let bytes = c.to_bytes();
        assert_eq!(Container::parse(&bytes).unwrap(), c);
    }

    #[test]
    fn truncations_are_errors() {
        let bytes = sample().to_bytes();
        for len in 0..bytes.len() {
            assert!(Container::parse(&bytes[..len]).is_err(), "{len}");
        }
    }

    #[test]
    fn huge_counts_are_errors() {
        let mut bytes = sample().to_bytes();
        bytes[12..16].copy_from_slice(&u32::MAX.to_le_bytes());
        let e = Container::parse(&bytes).unwrap_err().to_string();
        assert!(e.contains("truncated"), "{e}");
        let mut bytes = sample().to_bytes();
        bytes[HEADER..HEADER + 8].copy_from_slice(&u64::MAX.to_le_bytes());
        assert!(Container::parse(&bytes).is_err());
    }

    #[test]
    fn scene_round_trip_through_a_second_device() {
        let d = Device::new();
        let tri = [[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let flags = hostas::vk::BuildAccelerationStructureFlagsKHR::PREFER_FAST_TRACE;
        let b0 = hostas::quick::build_triangle_blas(&d, &tri, &[[0, 1, 2]], flags).unwrap();
        let b1 = hostas::quick::build_triangle_blas(&d, &tri, &[[0, 2, 1]], flags).unwrap();
        let mut inactive = hostas::quick::instance(b0, hostas::Affine::IDENTITY);
        inactive.acceleration_structure_reference = 0;
        let shifted =
            hostas::Affine::from_rows([1.0, 0.0, 0.0, 5.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0]);
        let instances = [
            hostas::quick::instance(b1, hostas::Affine::IDENTITY),
            inactive,
            hostas::quick::instance(b0, shifted),
        ];
        let tlas = hostas::quick::build_tlas(&d, &instances, flags).unwrap();
        let c = Container::from_device(&d, &[("zero".into(), b0), ("one".into(), b1)], tlas, None)
            .unwrap();
        let c = Container::parse(&c.to_bytes()).unwrap();
        assert_eq!(
            SerializedHeader::parse(&c.tlas.data).unwrap().handles,
            vec![2, 0, 1]
        );
        let d2 = Device::new();
        let (_, t2) = c.load(&d2).unwrap();
        let scene = d2.scene(t2).unwrap();
        let ray = |x: f32| hostas::Ray::new([x, 0.25, 1.0], [0.0, 0.0, -1.0]);
        let a = scene.trace_closest(&ray(0.25)).unwrap();
        let b = scene.trace_closest(&ray(5.25)).unwrap();
        assert_eq!((a.instance_id, b.instance_id), (0, 2));
        // Instance 0 uses the triangle wound the other way.
        assert_ne!(a.front_face, b.front_face);
    }
}
