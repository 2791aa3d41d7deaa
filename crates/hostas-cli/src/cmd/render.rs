//! `hostas render (MESH|FILE) -o IMAGE.png`: renders a mesh or a built scene.

use crate::cli::parse_vec3;
use crate::geom::{add, cross, length, normalize, scale, sub};
use crate::render::{Camera, Look, render};
use crate::shade::NoPrograms;
use crate::{input, note, progress};
use anyhow::{Result, anyhow, ensure};
use clap::Args;
use hostas::vk;
use std::path::PathBuf;

const AFTER_HELP: &str = "\
Shading shows the surface normal (as RGB) mixed with a per-instance tint, lit by a sun with
shadow rays and a sky. The default view looks at the whole scene from the front (+z when y
is up), a little from the right and above.

Examples:
  hostas render bunny.obj -o bunny.png
  hostas render scene.hostas -o view.png --width 1280 --height 720 --spp 4
  hostas render sponza.obj -o inside.png --eye 8,2,0 --target -8,3,0 --fov 60";

/// Render a mesh or a `hostas build` file to a PNG image
#[derive(Args, Debug)]
#[command(after_help = AFTER_HELP)]
pub struct RenderArgs {
    /// A mesh, a `hostas build` file or a serialized bottom-level structure
    #[arg(value_name = "MESH|FILE")]
    pub input: PathBuf,
    /// The PNG file to write
    #[arg(short, long, value_name = "IMAGE.png")]
    pub output: PathBuf,
    /// Image width in pixels
    #[arg(long, default_value_t = 800, value_parser = clap::value_parser!(u32).range(1..=16384))]
    pub width: u32,
    /// Image height in pixels
    #[arg(long, default_value_t = 600, value_parser = clap::value_parser!(u32).range(1..=16384))]
    pub height: u32,
    /// Camera position (default: framing the whole scene)
    #[arg(long, value_parser = parse_vec3, value_name = "X,Y,Z", allow_hyphen_values = true)]
    pub eye: Option<[f32; 3]>,
    /// Point the camera looks at (default: the scene's centre)
    #[arg(long, value_parser = parse_vec3, value_name = "X,Y,Z", allow_hyphen_values = true)]
    pub target: Option<[f32; 3]>,
    /// Up direction
    #[arg(long, value_parser = parse_vec3, value_name = "X,Y,Z", default_value = "0,1,0", allow_hyphen_values = true)]
    pub up: [f32; 3],
    /// Vertical field of view, degrees
    #[arg(long, default_value_t = 40.0)]
    pub fov: f32,
    /// Samples (primary rays) per pixel
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=256))]
    pub spp: u32,
    /// Direction towards the sun (default: above, behind the camera's left shoulder)
    #[arg(long, value_parser = parse_vec3, value_name = "X,Y,Z", allow_hyphen_values = true)]
    pub sun: Option<[f32; 3]>,
    /// No shadow rays
    #[arg(long)]
    pub no_shadows: bool,
    /// Tint back faces red
    #[arg(long)]
    pub mark_back_faces: bool,
}

pub fn run(a: RenderArgs) -> Result<()> {
    ensure!(
        a.fov > 0.0 && a.fov < 180.0,
        "--fov must be between 0 and 180 degrees, got {}",
        a.fov
    );
    ensure!(length(a.up) > 0.0, "--up must not be the zero vector");
    let loaded = input::load(
        &a.input,
        vk::BuildAccelerationStructureFlagsKHR::PREFER_FAST_TRACE,
    )?;
    let aspect = a.width as f32 / a.height as f32;
    let (lo, hi) = loaded.bounds.unwrap_or(([-1.0; 3], [1.0; 3]));
    if loaded.bounds.is_none() && a.eye.is_none() {
        note!("the scene's bounds are unknown: looking at the unit cube; use --eye and --target");
    }
    let mut camera = Camera::framing(lo, hi, a.up, a.fov, aspect);
    if let Some(t) = a.target {
        let offset = sub(camera.eye, camera.target);
        camera.target = t;
        camera.eye = add(t, offset);
    }
    if let Some(e) = a.eye {
        camera.eye = e;
    }
    let view = normalize(sub(camera.target, camera.eye));
    let right = normalize(cross(view, a.up));
    let sun = match a.sun {
        Some(s) => normalize(s),
        None => normalize(add(
            add(normalize(a.up), scale(view, -0.5)),
            scale(right, -0.6),
        )),
    };
    ensure!(length(sun) > 0.0, "--sun must not be the zero vector");
    let look = Look {
        sun,
        shadows: !a.no_shadows,
        tint_instances: loaded.blases.len() > 1,
        mark_back_faces: a.mark_back_faces,
        spp: a.spp,
        scene_radius: 0.5 * length(sub(hi, lo)),
        up: normalize(a.up),
    };
    let scene = loaded
        .device
        .scene(loaded.tlas)
        .map_err(|e| anyhow!("{}: {e}", a.input.display()))?;
    let pb = progress::bar(a.height as u64, "rendering");
    let (image, stats) = render(
        &scene,
        &camera,
        a.width,
        a.height,
        &NoPrograms,
        &look,
        &|| pb.inc(1),
    )?;
    pb.finish_and_clear();
    image.save_png(&a.output)?;
    note!(
        "wrote {} ({}x{}): {} rays in {:.1} ms, {:.2} Mrays/s on {} threads; eye {:?}, target {:?}",
        a.output.display(),
        a.width,
        a.height,
        stats.rays(),
        stats.time.as_secs_f64() * 1e3,
        stats.mrays_per_s(),
        rayon::current_num_threads(),
        camera.eye,
        camera.target
    );
    Ok(())
}
