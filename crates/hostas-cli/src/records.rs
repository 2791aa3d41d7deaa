//! The binary ray and hit records of `hostas trace` (little-endian, tightly packed).
//!
//! Ray (40 bytes): `f32 origin[3], f32 tmin, f32 direction[3], f32 tmax, u32 ray_flags,
//! u32 cull_mask`.
//!
//! Hit (32 bytes): `f32 t, u32 instance_id, u32 geometry_index, u32 primitive_id,
//! f32 barycentric_u, f32 barycentric_v, u32 kind (0 miss, 1 triangle, 2 generated),
//! u32 front_face`. A miss is all zeros.

use anyhow::{Result, ensure};
use hostas::{Hit, HitKind, Ray, RayFlags};

pub const RAY_SIZE: usize = 40;
pub const HIT_SIZE: usize = 32;

fn f32_at(b: &[u8], o: usize) -> f32 {
    f32::from_le_bytes(b[o..o + 4].try_into().unwrap_or_default())
}
fn u32_at(b: &[u8], o: usize) -> u32 {
    u32::from_le_bytes(b[o..o + 4].try_into().unwrap_or_default())
}

pub fn encode_ray(r: &Ray) -> [u8; RAY_SIZE] {
    let mut out = [0u8; RAY_SIZE];
    let words: [u32; 10] = [
        r.origin[0].to_bits(),
        r.origin[1].to_bits(),
        r.origin[2].to_bits(),
        r.t_min.to_bits(),
        r.direction[0].to_bits(),
        r.direction[1].to_bits(),
        r.direction[2].to_bits(),
        r.t_max.to_bits(),
        r.flags.0,
        r.cull_mask,
    ];
    for (i, w) in words.iter().enumerate() {
        out[4 * i..4 * i + 4].copy_from_slice(&w.to_le_bytes());
    }
    out
}

pub fn decode_ray(b: &[u8]) -> Ray {
    Ray {
        origin: [f32_at(b, 0), f32_at(b, 4), f32_at(b, 8)],
        t_min: f32_at(b, 12),
        direction: [f32_at(b, 16), f32_at(b, 20), f32_at(b, 24)],
        t_max: f32_at(b, 28),
        flags: RayFlags(u32_at(b, 32)),
        cull_mask: u32_at(b, 36),
    }
}

/// Decodes a whole rays file.
pub fn decode_rays(bytes: &[u8]) -> Result<Vec<Ray>> {
    ensure!(
        bytes.len().is_multiple_of(RAY_SIZE),
        "truncated: {} bytes is not a whole number of {RAY_SIZE}-byte ray records ({} complete, {} bytes left over)",
        bytes.len(),
        bytes.len() / RAY_SIZE,
        bytes.len() % RAY_SIZE
    );
    Ok(bytes.chunks_exact(RAY_SIZE).map(decode_ray).collect())
}

pub fn encode_hit(h: &Hit) -> [u8; HIT_SIZE] {
    let mut out = [0u8; HIT_SIZE];
    if !h.is_hit() {
        return out;
    }
    let words: [u32; 8] = [
        h.t.to_bits(),
        h.instance_id,
        h.geometry_index,
        h.primitive_index,
        h.barycentrics[0].to_bits(),
        h.barycentrics[1].to_bits(),
        h.kind as u32,
        h.front_face as u32,
    ];
    for (i, w) in words.iter().enumerate() {
        out[4 * i..4 * i + 4].copy_from_slice(&w.to_le_bytes());
    }
    out
}

/// A decoded hit record (what another tool reading the file sees).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HitRecord {
    pub t: f32,
    pub instance_id: u32,
    pub geometry_index: u32,
    pub primitive_id: u32,
    pub barycentrics: [f32; 2],
    pub kind: u32,
    pub front_face: bool,
}

pub fn decode_hit(b: &[u8]) -> HitRecord {
    HitRecord {
        t: f32_at(b, 0),
        instance_id: u32_at(b, 4),
        geometry_index: u32_at(b, 8),
        primitive_id: u32_at(b, 12),
        barycentrics: [f32_at(b, 16), f32_at(b, 20)],
        kind: u32_at(b, 24),
        front_face: u32_at(b, 28) != 0,
    }
}

pub fn decode_hits(bytes: &[u8]) -> Result<Vec<HitRecord>> {
    ensure!(
        bytes.len().is_multiple_of(HIT_SIZE),
        "truncated: {} bytes is not a whole number of {HIT_SIZE}-byte hit records",
        bytes.len()
    );
    Ok(bytes.chunks_exact(HIT_SIZE).map(decode_hit).collect())
}

impl HitRecord {
    pub fn is_hit(&self) -> bool {
        self.kind != HitKind::Miss as u32
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ray_round_trip() {
        let r = Ray {
            origin: [1.0, -2.0, 3.5],
            t_min: 0.25,
            direction: [0.0, -0.0, 1.0],
            t_max: f32::INFINITY,
            flags: RayFlags(0x123),
            cull_mask: 0x7f,
        };
        let b = encode_ray(&r);
        assert_eq!(decode_ray(&b), r);
        assert_eq!(decode_rays(&b).unwrap(), vec![r]);
        assert!(decode_rays(&b[..39]).is_err());
    }

    #[test]
    fn hit_round_trip() {
        let h = Hit {
            kind: HitKind::Generated,
            t: 2.5,
            instance_id: 7,
            instance_custom_index: 9,
            geometry_index: 1,
            primitive_index: 42,
            barycentrics: [0.25, 0.5],
            front_face: true,
        };
        let d = decode_hit(&encode_hit(&h));
        assert_eq!(
            d,
            HitRecord {
                t: 2.5,
                instance_id: 7,
                geometry_index: 1,
                primitive_id: 42,
                barycentrics: [0.25, 0.5],
                kind: 2,
                front_face: true
            }
        );
        assert_eq!(encode_hit(&Hit::MISS), [0; HIT_SIZE]);
    }
}
