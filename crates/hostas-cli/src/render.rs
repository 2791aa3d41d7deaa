//! Rendering a scene to an image: a pinhole camera, one or more jittered primary rays per
//! pixel, normal-and-instance shading, a sun with shadow rays and a sky, traced on all
//! threads of the current rayon pool.

use crate::geom::{Rng, V3, add, cross, dot, length, lerp, mul, normalize, scale, sub};
use crate::image::Image;
use crate::shade::{self, Programs, Surface};
use anyhow::{Result, anyhow, ensure};
use hostas::{Ray, RayFlags, Scene};
use rayon::prelude::*;
use std::time::{Duration, Instant};

/// A pinhole camera.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    pub eye: V3,
    pub target: V3,
    pub up: V3,
    /// Vertical field of view, degrees.
    pub fov_y: f32,
}

impl Camera {
    /// A view of the box `lo..hi` from the front, a little from the right and above (front is
    /// +z and up is +y unless `up` says otherwise), far enough that the whole box fits.
    pub fn framing(lo: V3, hi: V3, up: V3, fov_y: f32, aspect: f32) -> Camera {
        let center = scale(add(lo, hi), 0.5);
        let radius = (0.5 * length(sub(hi, lo))).max(1e-3);
        let up = normalize(up);
        // Front: +z when y is up; otherwise the axis after `up`'s largest component.
        let major = (0..3)
            .max_by(|&a, &b| up[a].abs().total_cmp(&up[b].abs()))
            .unwrap_or(1);
        let mut front = [0.0; 3];
        front[(major + 1) % 3] = 1.0;
        let right = normalize(cross(up, front));
        let dir = normalize(add(
            add(scale(front, 1.0), scale(right, 0.45)),
            scale(up, 0.4),
        ));
        let half = (fov_y.to_radians() * 0.5)
            .tan()
            .min((fov_y.to_radians() * 0.5).tan() * aspect);
        let distance = radius / half.atan().sin() * 1.02;
        Camera {
            eye: add(center, scale(dir, distance)),
            target: center,
            up,
            fov_y,
        }
    }
}

/// How to shade.
#[derive(Clone, Copy, Debug)]
pub struct Look {
    /// Unit vector towards the sun.
    pub sun: V3,
    pub shadows: bool,
    /// Colour each instance differently (otherwise one clay colour).
    pub tint_instances: bool,
    /// Show back faces with a red tint.
    pub mark_back_faces: bool,
    /// Primary rays per pixel (jittered on a grid when > 1).
    pub spp: u32,
    /// Scene size, for ray offsets.
    pub scene_radius: f32,
    pub up: V3,
}

/// What a render did.
#[derive(Clone, Copy, Debug, Default)]
pub struct RenderStats {
    pub primary_rays: u64,
    pub shadow_rays: u64,
    pub hits: u64,
    pub time: Duration,
}

impl RenderStats {
    pub fn rays(&self) -> u64 {
        self.primary_rays + self.shadow_rays
    }
    pub fn mrays_per_s(&self) -> f64 {
        self.rays() as f64 / self.time.as_secs_f64().max(1e-9) / 1e6
    }
}

/// A pleasant colour for instance `i`.
pub fn instance_tint(i: u32) -> V3 {
    let h = (i.wrapping_mul(0x9e37_79b9) >> 8) as f32 / (1u32 << 24) as f32;
    hsv(h, 0.55, 0.95)
}

pub fn hsv(h: f32, s: f32, v: f32) -> V3 {
    let f = |n: f32| {
        let k = (n + h * 6.0) % 6.0;
        v - v * s * (k.min(4.0 - k).clamp(0.0, 1.0))
    };
    [f(5.0), f(3.0), f(1.0)]
}

/// The sky seen along `dir`.
pub fn sky(dir: V3, look: &Look) -> V3 {
    let d = normalize(dir);
    let h = dot(d, look.up).clamp(-1.0, 1.0);
    let horizon = [0.74, 0.82, 0.94];
    let zenith = [0.2, 0.4, 0.8];
    let ground = [0.42, 0.4, 0.38];
    let base = if h >= 0.0 {
        lerp(horizon, zenith, h.powf(0.6))
    } else {
        lerp(horizon, ground, (-h).powf(0.5))
    };
    let sun =
        dot(d, look.sun).max(0.0).powf(600.0) * 6.0 + dot(d, look.sun).max(0.0).powf(12.0) * 0.25;
    add(base, [sun, sun * 0.9, sun * 0.7])
}

/// Default surface colour: the normal (as RGB) mixed with the instance's tint.
pub fn default_albedo(s: &Surface, n: V3, look: &Look) -> V3 {
    let tint = if look.tint_instances {
        instance_tint(s.hit.instance_id)
    } else {
        [0.78, 0.58, 0.42]
    };
    let normal_rgb = [0.5 + 0.5 * n[0], 0.5 + 0.5 * n[1], 0.5 + 0.5 * n[2]];
    let mut c = lerp(tint, normal_rgb, 0.45);
    if look.mark_back_faces && !s.hit.front_face {
        c = mul(c, [1.0, 0.3, 0.3]);
    }
    c
}

/// Linear colour seen along `ray`, with the rays it took.
pub fn shade_ray(
    scene: &Scene,
    ray: &Ray,
    programs: &impl Programs,
    look: &Look,
    stats: &mut RenderStats,
) -> hostas::Result<V3> {
    stats.primary_rays += 1;
    let Some(s) = shade::trace(scene, ray, programs)? else {
        return Ok(sky(ray.direction, look));
    };
    stats.hits += 1;
    let d = normalize(ray.direction);
    let mut n = s.normal.unwrap_or(scale(d, -1.0));
    if dot(n, d) > 0.0 {
        n = scale(n, -1.0);
    }
    let albedo = programs
        .albedo(&s)
        .unwrap_or_else(|| default_albedo(&s, n, look));
    let lambert = dot(n, look.sun).max(0.0);
    let mut visible = 1.0;
    if lambert > 0.0 && look.shadows {
        let eps = look.scene_radius * 2e-5 + 1e-5 * length(s.position);
        let shadow = Ray {
            origin: add(s.position, scale(n, eps)),
            t_min: 0.0,
            direction: look.sun,
            t_max: f32::INFINITY,
            flags: RayFlags::TERMINATE_ON_FIRST_HIT | RayFlags::SKIP_CLOSEST_HIT_SHADER,
            cull_mask: 0xff,
        };
        stats.shadow_rays += 1;
        if shade::occluded(scene, &shadow, programs)? {
            visible = 0.0;
        }
    }
    let hemisphere = 0.5 + 0.5 * dot(n, look.up);
    let ambient = lerp([0.12, 0.11, 0.1], [0.24, 0.28, 0.36], hemisphere);
    let light = add(ambient, scale([1.0, 0.95, 0.85], 0.8 * lambert * visible));
    Ok(mul(albedo, light))
}

fn to_srgb8(v: f32) -> u8 {
    let v = v.max(0.0);
    // A soft shoulder keeps highlights from clipping hard.
    let v = v / (1.0 + 0.15 * v);
    let s = if v <= 0.003_130_8 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    };
    (s.clamp(0.0, 1.0) * 255.0 + 0.5) as u8
}

/// Renders `width` x `height` pixels; `row_done` is called after each row.
pub fn render(
    scene: &Scene,
    camera: &Camera,
    width: u32,
    height: u32,
    programs: &impl Programs,
    look: &Look,
    row_done: &(dyn Fn() + Sync),
) -> Result<(Image, RenderStats)> {
    ensure!(
        width > 0 && height > 0,
        "the image must be at least 1x1 pixels"
    );
    let forward = normalize(sub(camera.target, camera.eye));
    let right = normalize(cross(forward, camera.up));
    ensure!(
        forward != [0.0; 3] && right != [0.0; 3],
        "the camera's eye, target and up vector do not define a view (eye = target, or up parallel to the view direction)"
    );
    let up = cross(right, forward);
    let half_h = (camera.fov_y.clamp(1.0, 179.0).to_radians() * 0.5).tan();
    let half_w = half_h * width as f32 / height as f32;
    let spp = look.spp.max(1);
    let grid = (spp as f32).sqrt().ceil() as u32;
    let start = Instant::now();
    let mut image = Image::new(width, height);
    let rows: Vec<Result<RenderStats>> = image
        .rgba
        .par_chunks_mut(width as usize * 4)
        .enumerate()
        .map(|(y, row)| {
            let mut stats = RenderStats::default();
            let mut rng = Rng::new(y as u64 + 1);
            for x in 0..width as usize {
                let mut sum = [0.0f32; 3];
                for k in 0..spp {
                    let (jx, jy) = if spp == 1 {
                        (0.5, 0.5)
                    } else {
                        (
                            ((k % grid) as f32 + rng.f32()) / grid as f32,
                            ((k / grid) as f32 + rng.f32()) / grid as f32,
                        )
                    };
                    let u = (2.0 * (x as f32 + jx) / width as f32 - 1.0) * half_w;
                    let v = (1.0 - 2.0 * (y as f32 + jy) / height as f32) * half_h;
                    let dir = add(forward, add(scale(right, u), scale(up, v)));
                    let ray = Ray::new(camera.eye, dir);
                    let c = shade_ray(scene, &ray, programs, look, &mut stats)
                        .map_err(|e| anyhow!("tracing pixel ({x}, {y}): {e}"))?;
                    sum = add(sum, c);
                }
                let c = scale(sum, 1.0 / spp as f32);
                row[4 * x..4 * x + 4].copy_from_slice(&[
                    to_srgb8(c[0]),
                    to_srgb8(c[1]),
                    to_srgb8(c[2]),
                    255,
                ]);
            }
            row_done();
            Ok(stats)
        })
        .collect();
    let mut total = RenderStats::default();
    for r in rows {
        let r = r?;
        total.primary_rays += r.primary_rays;
        total.shadow_rays += r.shadow_rays;
        total.hits += r.hits;
    }
    total.time = start.elapsed();
    Ok((image, total))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn framing_sees_the_box() {
        let c = Camera::framing([-1.0; 3], [1.0; 3], [0.0, 1.0, 0.0], 40.0, 4.0 / 3.0);
        assert!(c.eye[2] > 2.0 && c.eye[1] > 0.0 && c.eye[0] > 0.0, "{c:?}");
        assert_eq!(c.target, [0.0; 3]);
        let z = Camera::framing([-1.0; 3], [1.0; 3], [0.0, 0.0, 1.0], 40.0, 1.0);
        assert!(z.eye[2] > 0.0, "{z:?}");
    }

    #[test]
    fn srgb_ends() {
        assert_eq!(to_srgb8(0.0), 0);
        assert_eq!(to_srgb8(100.0), 255);
        assert!(to_srgb8(0.18) > 100);
    }
}
