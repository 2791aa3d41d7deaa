//! End-to-end tests of the `hostas` binary: every subcommand, on small generated meshes in a
//! temporary directory, and corrupt or truncated inputs.

use hostas::{Ray, RayFlags};
use hostas_cli::records::{self, HitRecord};
use hostas_cli::shapes;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn hostas(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_hostas"))
        .args(args)
        .current_dir(dir)
        .output()
        .expect("run hostas")
}

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}
fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[track_caller]
fn ok(o: &Output) -> String {
    assert!(
        o.status.success(),
        "exit {:?}\nstdout:\n{}\nstderr:\n{}",
        o.status.code(),
        stdout(o),
        stderr(o)
    );
    stdout(o)
}

/// A clean failure: exit 1, one `hostas: error:` message on stderr, no panic.
#[track_caller]
fn fails(o: &Output, expect: &str) -> String {
    let e = stderr(o);
    assert_eq!(
        o.status.code(),
        Some(1),
        "expected exit 1\nstdout:\n{}\nstderr:\n{e}",
        stdout(o)
    );
    let last = e.lines().last().unwrap_or_default();
    assert!(
        last.starts_with("hostas: error: ") && e.matches("hostas: error: ").count() == 1,
        "stderr: {e}"
    );
    assert!(
        !e.contains("panicked") && !e.contains("RUST_BACKTRACE"),
        "stderr: {e}"
    );
    assert!(e.contains(expect), "expected {expect:?} in stderr: {e}");
    e
}

fn write_obj(path: &Path, positions: &[[f32; 3]], indices: &[[u32; 3]]) {
    let mut s = String::new();
    for p in positions {
        s += &format!("v {} {} {}\n", p[0], p[1], p[2]);
    }
    for t in indices {
        s += &format!("f {} {} {}\n", t[0] + 1, t[1] + 1, t[2] + 1);
    }
    std::fs::write(path, s).unwrap();
}

struct Fixture {
    dir: tempfile::TempDir,
}

impl Fixture {
    /// A temporary directory with `ball.obj` (a unit icosphere) and `ring.obj` (a torus
    /// centred at x = 4).
    fn new() -> Fixture {
        let dir = tempfile::tempdir().unwrap();
        let ball = shapes::icosphere(2);
        write_obj(&dir.path().join("ball.obj"), &ball.positions, &ball.indices);
        let ring = shapes::torus(1.0, 0.3, 24, 12);
        let moved: Vec<[f32; 3]> = ring
            .positions
            .iter()
            .map(|p| [p[0] + 4.0, p[1], p[2]])
            .collect();
        write_obj(&dir.path().join("ring.obj"), &moved, &ring.indices);
        Fixture { dir }
    }
    fn path(&self, name: &str) -> PathBuf {
        self.dir.path().join(name)
    }
    fn run(&self, args: &[&str]) -> Output {
        hostas(args, self.dir.path())
    }
    fn write(&self, name: &str, bytes: &[u8]) {
        std::fs::write(self.path(name), bytes).unwrap();
    }
}

fn png_size(path: &Path) -> (u32, u32) {
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    // Not a blank image: some pixels differ from the first one.
    let px = &buf[..info.buffer_size()];
    assert!(px.chunks(4).any(|p| p != &px[..4]), "blank image");
    (info.width, info.height)
}

fn rays_file(rays: &[Ray]) -> Vec<u8> {
    rays.iter().flat_map(records::encode_ray).collect()
}

/// Rays at the ball (some hitting, some missing), at the ring, and some with flags and masks.
fn test_rays() -> Vec<Ray> {
    let mut rays = Vec::new();
    for i in 0..40 {
        let y = -1.5 + 3.0 * i as f32 / 39.0;
        rays.push(Ray::new([0.0, y, 5.0], [0.0, 0.0, -1.0]));
        rays.push(Ray::new([4.0 + y, 0.0, 5.0], [0.0, 0.0, -1.0]));
    }
    // From inside the ball: hits the back face.
    rays.push(Ray::new([0.0, 0.0, 0.0], [0.0, 0.0, 1.0]));
    let mut culled = Ray::new([0.0, 0.0, 0.0], [0.0, 0.0, 1.0]);
    culled.flags = RayFlags::CULL_BACK_FACING_TRIANGLES;
    rays.push(culled);
    let mut masked = Ray::new([0.0, 0.0, 5.0], [0.0, 0.0, -1.0]);
    masked.cull_mask = 0;
    rays.push(masked);
    let mut short = Ray::new([0.0, 0.0, 5.0], [0.0, 0.0, -1.0]);
    short.t_max = 3.0;
    rays.push(short);
    let mut skip = Ray::new([0.0, 0.0, 5.0], [0.0, 0.0, -1.0]);
    skip.flags = RayFlags::SKIP_TRIANGLES;
    rays.push(skip);
    rays
}

fn read_hits(path: &Path) -> Vec<HitRecord> {
    records::decode_hits(&std::fs::read(path).unwrap()).unwrap()
}

#[test]
fn help_version_and_usage_errors() {
    let f = Fixture::new();
    let help = ok(&f.run(&["--help"]));
    for word in [
        "demo",
        "build",
        "info",
        "render",
        "trace",
        "bench",
        "Examples",
        "Exit status",
        "--threads",
        "--quiet",
    ] {
        assert!(help.contains(word), "--help lacks {word}:\n{help}");
    }
    for sub in ["demo", "build", "info", "render", "trace", "bench"] {
        let h = ok(&f.run(&[sub, "--help"]));
        assert!(h.contains("Examples"), "{sub} --help lacks examples:\n{h}");
    }
    let v = ok(&f.run(&["--version"]));
    assert!(v.contains(env!("CARGO_PKG_VERSION")), "{v}");
    let o = f.run(&["frobnicate"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("frobnicate"));
    let o = f.run(&["build", "ball.obj"]);
    assert_eq!(o.status.code(), Some(2), "missing -o is a usage error");
    let o = f.run(&[
        "build",
        "ball.obj",
        "-o",
        "x",
        "--fast-trace",
        "--fast-build",
    ]);
    assert_eq!(o.status.code(), Some(2), "conflicting presets");
    let o = f.run(&["render", "ball.obj", "-o", "x.png", "--eye", "1,2"]);
    assert_eq!(o.status.code(), Some(2));
}

#[test]
fn demo_renders_and_reports() {
    let f = Fixture::new();
    let out = ok(&f.run(&[
        "demo",
        "--width",
        "160",
        "--height",
        "120",
        "--spp",
        "1",
        "-o",
        "d.png",
        "--threads",
        "2",
    ]));
    assert_eq!(png_size(&f.path("d.png")), (160, 120));
    for word in [
        "BLAS lattice globe",
        "not opaque",
        "AABBs (procedural)",
        "TLAS",
        "compacted",
        "1 inactive",
        "2 mirrored",
        "Mrays/s",
        "19,200/19,200 probe rays hit identically",
        "deferred operations",
        "not implemented",
    ] {
        assert!(out.contains(word), "report lacks {word:?}:\n{out}");
    }
    // The default output name.
    ok(&f.run(&[
        "demo", "--width", "32", "--height", "24", "--spp", "1", "-q",
    ]));
    assert_eq!(png_size(&f.path("hostas-demo.png")), (32, 24));
}

#[test]
fn build_info_trace_round_trip() {
    let f = Fixture::new();
    let out = ok(&f.run(&[
        "build",
        "ball.obj",
        "ring.obj",
        "--compact",
        "--fast-trace",
        "-o",
        "scene.hostas",
    ]));
    assert!(
        out.contains("BLAS 0 (ball)") && out.contains("BLAS 1 (ring)"),
        "{out}"
    );
    let info = ok(&f.run(&["info", "scene.hostas"]));
    for word in [
        "hostas build file, 2 bottom level(s)",
        "driverUUID",
        "compatibility UUID",
        "bottom-level, triangles",
        "PREFER_FAST_TRACE",
        "ALLOW_COMPACTION",
        "SAH cost",
        "depth",
        "triangles            indexed, ",
        "top-level, instances",
        "0x1, 0x2",
    ] {
        assert!(info.contains(word), "info lacks {word:?}:\n{info}");
    }
    let json = ok(&f.run(&["info", "--json", "scene.hostas"]));
    let v: serde_json::Value = serde_json::from_str(json.trim()).unwrap();
    assert_eq!(v["format"], "hostas-build");
    let s = &v["structures"];
    assert_eq!(s.as_array().unwrap().len(), 3);
    assert_eq!(s[0]["statistics"]["primitives"], 320);
    assert_eq!(s[0]["statistics"]["preset"], "fast-trace");
    assert_eq!(s[1]["name"], "ring");
    assert_eq!(s[2]["header"]["handles"], serde_json::json!([1, 2]));
    assert_eq!(s[2]["statistics"]["type"], "top-level");
    assert!(s[0]["statistics"]["sah_cost"].as_f64().unwrap() > 0.0);
    // A closed mesh built for fast trace shares its vertices: well under three per triangle.
    assert_eq!(s[0]["statistics"]["triangles"], "indexed");
    let shared = s[0]["statistics"]["shared_vertices"].as_u64().unwrap();
    assert!(shared > 0 && shared < 320, "{shared} shared vertices");

    // Trace the same rays through the build file and through the meshes.
    let rays = test_rays();
    f.write("rays.bin", &rays_file(&rays));
    ok(&f.run(&[
        "trace",
        "scene.hostas",
        "--rays",
        "rays.bin",
        "--hits",
        "file.bin",
    ]));
    ok(&f.run(&[
        "trace", "ball.obj", "--rays", "rays.bin", "--hits", "ball.bin",
    ]));
    ok(&f.run(&[
        "trace",
        "scene.hostas",
        "--rays",
        "rays.bin",
        "--hits",
        "any.bin",
        "--any-hit",
        "--threads",
        "1",
    ]));
    let (file, ball, any) = (
        read_hits(&f.path("file.bin")),
        read_hits(&f.path("ball.bin")),
        read_hits(&f.path("any.bin")),
    );
    assert_eq!(file.len(), rays.len());
    let n = rays.len();
    for i in 0..n {
        let (fh, bh, ah) = (file[i], ball[i], any[i]);
        if bh.is_hit() {
            // The ball is instance 0 of the file; the same triangle is hit at the same t.
            assert_eq!(
                (fh.kind, fh.instance_id, fh.primitive_id, fh.t.to_bits()),
                (1, 0, bh.primitive_id, bh.t.to_bits()),
                "ray {i}"
            );
            assert_eq!(bh.instance_id, 0);
        }
        assert_eq!(
            fh.is_hit(),
            ah.is_hit(),
            "ray {i}: any-hit and closest-hit disagree on hit/miss"
        );
        if fh.is_hit() {
            assert!(
                ah.t >= fh.t,
                "ray {i}: any-hit t {} < closest t {}",
                ah.t,
                fh.t
            );
            assert_eq!(fh.geometry_index, 0);
            let [u, v] = fh.barycentrics;
            assert!(u >= 0.0 && v >= 0.0 && u + v <= 1.0 + 1e-6);
        } else {
            assert_eq!(records::decode_hit(&[0; 32]), fh, "a miss is all zeros");
        }
    }
    // Ray 40 of the first 80 passes through the ball's centre line: t = 4 (sphere of radius
    // about 1, outside front face). Odd rays go at the ring (instance 1).
    let centre = file[40];
    assert!(
        centre.is_hit() && (centre.t - 4.0).abs() < 0.05 && centre.front_face,
        "{centre:?}"
    );
    assert!(
        file.iter()
            .skip(1)
            .step_by(2)
            .take(40)
            .any(|h| h.is_hit() && h.instance_id == 1)
    );
    let k = 80;
    assert!(
        file[k].is_hit() && !file[k].front_face,
        "from inside: back face {:?}",
        file[k]
    );
    assert!(!file[k + 1].is_hit(), "back faces culled");
    assert!(!file[k + 2].is_hit(), "cull mask 0 misses");
    assert!(
        !file[k + 3].is_hit(),
        "tmax 3 stops short of the ball at t = 4"
    );
    assert!(!file[k + 4].is_hit(), "SkipTriangles");
}

#[test]
fn render_writes_png_of_the_right_size() {
    let f = Fixture::new();
    ok(&f.run(&[
        "render", "ball.obj", "-o", "ball.png", "--width", "96", "--height", "64", "-q",
    ]));
    assert_eq!(png_size(&f.path("ball.png")), (96, 64));
    ok(&f.run(&["build", "ball.obj", "ring.obj", "-o", "scene.hostas", "-q"]));
    ok(&f.run(&[
        "render",
        "scene.hostas",
        "-o",
        "scene.png",
        "--width",
        "50",
        "--height",
        "70",
        "--spp",
        "2",
        "--eye",
        "2,3,8",
        "--target",
        "2,0,0",
        "--fov",
        "50",
    ]));
    assert_eq!(png_size(&f.path("scene.png")), (50, 70));
    let e = fails(
        &f.run(&[
            "render", "ball.obj", "-o", "x.png", "--eye", "0,0,0", "--target", "0,0,0",
        ]),
        "camera",
    );
    assert!(!f.path("x.png").exists(), "{e}");
    fails(
        &f.run(&[
            "render",
            "ball.obj",
            "-o",
            "no/such/dir/x.png",
            "--width",
            "8",
            "--height",
            "8",
        ]),
        "cannot write",
    );
}

#[test]
fn bench_json_lines() {
    let f = Fixture::new();
    let out = ok(&f.run(&[
        "bench",
        "ball.obj",
        "--json",
        "--reps",
        "1",
        "--rays",
        "500",
        "--presets",
        "fast-trace,low-memory",
        "--threads",
        "2",
    ]));
    let lines: Vec<serde_json::Value> = out
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(lines.len(), 2);
    for (l, preset) in lines.iter().zip(["fast-trace", "low-memory"]) {
        assert_eq!(l["mesh"], "ball");
        assert_eq!(l["triangles"], 320);
        assert_eq!(l["preset"], preset);
        assert_eq!(l["threads"], 2);
        for key in [
            "build_ms",
            "build_mtris_per_s",
            "sah_cost",
            "bytes_per_triangle",
            "compacted_bytes_per_triangle",
            "trace_primary_mrays_per_s",
            "trace_incoherent_mrays_per_s",
            "refit_mtris_per_s",
        ] {
            assert!(l[key].as_f64().is_some_and(|v| v > 0.0), "{key} in {l}");
        }
        assert!(l["compacted_bytes_per_triangle"].as_f64() <= l["bytes_per_triangle"].as_f64());
    }
    let table = ok(&f.run(&[
        "bench",
        "ring.obj",
        "--reps",
        "1",
        "--rays",
        "100",
        "--presets",
        "fast-build",
        "-q",
    ]));
    assert!(
        table.contains("ring") && table.contains("fast-build") && table.contains("primary Mrays/s"),
        "{table}"
    );
    // Built-in scenes only, saying that ../shared/meshes is absent. Run from a nested folder
    // so that `..` is inside the fixture, whatever the system's temporary directory holds.
    let nested = f.path("work/here");
    std::fs::create_dir_all(&nested).unwrap();
    let o = hostas(
        &[
            "bench",
            "--reps",
            "1",
            "--rays",
            "64",
            "--presets",
            "fast-build",
            "--json",
        ],
        &nested,
    );
    let out = ok(&o);
    assert_eq!(out.lines().count(), 2, "{out}");
    assert!(stderr(&o).contains("absent"), "{}", stderr(&o));
    // The note on the build's vector code: exactly when this build (the test's flags are the
    // binary's) has no AVX2 and the processor has it.
    #[cfg(target_arch = "x86_64")]
    {
        let narrower = !cfg!(target_feature = "avx2") && std::is_x86_feature_detected!("avx2");
        assert_eq!(
            stderr(&o).contains("target-cpu=native"),
            narrower,
            "{}",
            stderr(&o)
        );
    }
    std::fs::create_dir(f.path("empty")).unwrap();
    fails(
        &f.run(&["bench", "--no-builtin", "--meshes", "empty"]),
        "nothing to measure: empty holds no meshes",
    );
}

#[test]
fn corrupt_and_truncated_inputs_fail_cleanly() {
    let f = Fixture::new();
    ok(&f.run(&["build", "ball.obj", "ring.obj", "-o", "scene.hostas", "-q"]));
    let good = std::fs::read(f.path("scene.hostas")).unwrap();

    fails(
        &f.run(&["info", "missing.hostas"]),
        "missing.hostas: cannot read",
    );
    fails(
        &f.run(&["render", "missing.obj", "-o", "x.png"]),
        "missing.obj",
    );

    // Truncated anywhere: a clean error from every reader.
    for cut in [
        0,
        5,
        8,
        30,
        47,
        60,
        100,
        200,
        good.len() / 3,
        good.len() / 2,
        good.len() - 1,
    ] {
        f.write("cut.hostas", &good[..cut]);
        for args in [
            &["info", "cut.hostas"][..],
            &["trace", "cut.hostas", "--rays", "r.bin", "--hits", "h.bin"],
            &[
                "render",
                "cut.hostas",
                "-o",
                "c.png",
                "--width",
                "4",
                "--height",
                "4",
            ],
        ] {
            f.write("r.bin", &rays_file(&test_rays()[..2]));
            let o = f.run(args);
            assert_eq!(
                o.status.code(),
                Some(1),
                "cut at {cut}: {args:?}: {}",
                stderr(&o)
            );
            assert!(!stderr(&o).contains("panicked"), "{}", stderr(&o));
        }
    }
    f.write("cut.hostas", &good[..good.len() - 1]);
    fails(&f.run(&["info", "cut.hostas"]), "truncated");

    // A structure payload that is not a hostas structure any more.
    let mut bad = good.clone();
    let c = hostas_cli::container::Container::parse(&good).unwrap();
    let first_blob = u64::from_le_bytes(good[48..56].try_into().unwrap()) as usize;
    bad[first_blob + 56..first_blob + 60].copy_from_slice(b"junk");
    f.write("bad.hostas", &bad);
    fails(
        &f.run(&["trace", "bad.hostas", "--rays", "r.bin", "--hits", "h.bin"]),
        "bottom level 0 (ball)",
    );
    let info = ok(&f.run(&["info", "bad.hostas"]));
    assert!(
        info.contains("another implementation") || info.contains("does not deserialize"),
        "{info}"
    );
    assert_eq!(c.blases.len(), 2);

    // A top level whose handle names a bottom level the file does not hold.
    let mut c2 = c.clone();
    hostas_cli::container::rewrite_handles(&mut c2.tlas.data, |_, _| Ok(7)).unwrap();
    f.write("dangling.hostas", &c2.to_bytes());
    fails(
        &f.run(&["render", "dangling.hostas", "-o", "x.png"]),
        "refers to bottom level 6 but the file holds 2",
    );

    // Bytes in every byte of the payload flipped in turn: never a panic.
    let tlas_at =
        u64::from_le_bytes(good[48 + 2 * 24..48 + 2 * 24 + 8].try_into().unwrap()) as usize;
    for k in (0..good.len() - tlas_at).step_by(37) {
        let mut b = good.clone();
        b[tlas_at + k] ^= 0xa5;
        f.write("flip.hostas", &b);
        for args in [
            &["info", "flip.hostas"][..],
            &["trace", "flip.hostas", "--rays", "r.bin", "--hits", "h.bin"],
        ] {
            let o = f.run(args);
            assert!(
                matches!(o.status.code(), Some(0 | 1)),
                "flip at {k}: {}",
                stderr(&o)
            );
            assert!(
                !stderr(&o).contains("panicked"),
                "flip at {k}: {}",
                stderr(&o)
            );
        }
    }

    // Not a structure at all.
    f.write(
        "noise.bin",
        b"this is not an acceleration structure, just some text",
    );
    fails(
        &f.run(&["info", "noise.bin"]),
        "not a hostas build file or serialized acceleration structure",
    );
    fails(
        &f.run(&["trace", "noise.bin", "--rays", "r.bin", "--hits", "h.bin"]),
        "not a mesh",
    );
    fails(&f.run(&["info", "ball.obj"]), "it looks like a mesh");
    let mut noise = vec![0xffu8; 300];
    noise[32..40].copy_from_slice(&1000u64.to_le_bytes());
    noise[48..56].copy_from_slice(&0u64.to_le_bytes());
    f.write("noise.bin", &noise);
    fails(
        &f.run(&["info", "noise.bin"]),
        "serializedSize 1000 for a file of 300 bytes: truncated?",
    );

    // Broken meshes: the mesh loader's message with the place.
    f.write("broken.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n");
    fails(
        &f.run(&["build", "broken.obj", "-o", "x.hostas"]),
        "broken.obj:4",
    );
    fails(
        &f.run(&["render", "broken.obj", "-o", "x.png"]),
        "refers to vertex 9",
    );
    f.write("empty.ply", b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n\0\0");
    fails(
        &f.run(&["trace", "empty.ply", "--rays", "r.bin", "--hits", "h.bin"]),
        "truncated",
    );

    // Ray files: truncated records and rays that break the runtime rules.
    f.write("short.bin", &rays_file(&test_rays()[..2])[..79]);
    fails(
        &f.run(&[
            "trace",
            "ball.obj",
            "--rays",
            "short.bin",
            "--hits",
            "h.bin",
        ]),
        "not a whole number of 40-byte ray records",
    );
    let mut rays = test_rays()[..3].to_vec();
    rays[2].t_min = f32::NAN;
    f.write("nan.bin", &rays_file(&rays));
    fails(
        &f.run(&["trace", "ball.obj", "--rays", "nan.bin", "--hits", "h.bin"]),
        "ray 2: VUID-RuntimeSpirv-OpRayQueryInitializeKHR-06351",
    );
    rays[2] = Ray::new([0.0; 3], [0.0, 0.0, 1.0]);
    rays[2].flags = RayFlags::OPAQUE | RayFlags::NO_OPAQUE;
    f.write("flags.bin", &rays_file(&rays));
    fails(
        &f.run(&[
            "trace",
            "ball.obj",
            "--rays",
            "flags.bin",
            "--hits",
            "h.bin",
        ]),
        "ray 2",
    );
    // Past the first chunk of rays the command traces at once, the index is still the file's.
    let mut rays = test_rays().repeat(5000_usize.div_ceil(test_rays().len()));
    rays[4500].t_max = -1.0;
    f.write("late.bin", &rays_file(&rays));
    let e = fails(
        &f.run(&["trace", "ball.obj", "--rays", "late.bin", "--hits", "h.bin"]),
        "ray 4500: VUID-RuntimeSpirv-OpRayQueryInitializeKHR-06349",
    );
    assert!(e.trim_end().ends_with("must be non-negative"), "{e}");
}

#[test]
fn info_decodes_other_implementations_and_bare_structures() {
    let f = Fixture::new();
    // A header as another driver would write it: 56 bytes, two handles, an opaque payload.
    let mut foreign = Vec::new();
    foreign.extend_from_slice(&[0x11; 16]);
    foreign.extend_from_slice(&[0x22; 16]);
    foreign.extend_from_slice(&(56u64 + 16 + 8).to_le_bytes());
    foreign.extend_from_slice(&4096u64.to_le_bytes());
    foreign.extend_from_slice(&2u64.to_le_bytes());
    foreign.extend_from_slice(&0xdead_0000u64.to_le_bytes());
    foreign.extend_from_slice(&0xbeef_0000u64.to_le_bytes());
    foreign.extend_from_slice(&[0u8; 8]);
    f.write("foreign.bin", &foreign);
    let info = ok(&f.run(&["info", "foreign.bin"]));
    for word in [
        "serialized acceleration structure",
        "11111111-1111-1111-1111-111111111111",
        "22222222-2222",
        "4,096 bytes",
        "2: 0xdead0000, 0xbeef0000",
        "another implementation",
    ] {
        assert!(info.contains(word), "info lacks {word:?}:\n{info}");
    }
    let json: serde_json::Value =
        serde_json::from_str(ok(&f.run(&["info", "foreign.bin", "--json"])).trim()).unwrap();
    assert_eq!(json["structures"][0]["implementation"], "unknown");
    assert_eq!(
        json["structures"][0]["header"]["handles"],
        serde_json::json!([0xdead_0000u64, 0xbeef_0000u64])
    );
    fails(
        &f.run(&["trace", "foreign.bin", "--rays", "r.bin", "--hits", "h.bin"]),
        "r.bin: cannot read",
    );
    f.write("r.bin", &[]);
    fails(
        &f.run(&["trace", "foreign.bin", "--rays", "r.bin", "--hits", "h.bin"]),
        "another implementation",
    );
    let mut short = foreign.clone();
    short.truncate(60);
    f.write("short.bin", &short);
    fails(
        &f.run(&["info", "short.bin"]),
        "not a hostas build file or serialized acceleration structure",
    );

    // A bare hostas BLAS (cut out of a build file): described, traced and rendered.
    ok(&f.run(&["build", "ball.obj", "-o", "ball.hostas", "-q"]));
    let c = hostas_cli::container::Container::parse(&std::fs::read(f.path("ball.hostas")).unwrap())
        .unwrap();
    f.write("ball.blas", &c.blases[0].data);
    let info = ok(&f.run(&["info", "ball.blas"]));
    assert!(
        info.contains("this version") && info.contains("320 (320 active)"),
        "{info}"
    );
    let rays = test_rays();
    f.write("rays.bin", &rays_file(&rays));
    ok(&f.run(&[
        "trace",
        "ball.blas",
        "--rays",
        "rays.bin",
        "--hits",
        "hits.bin",
    ]));
    assert!(read_hits(&f.path("hits.bin"))[40].is_hit());
    ok(&f.run(&[
        "render",
        "ball.blas",
        "-o",
        "b.png",
        "--width",
        "20",
        "--height",
        "20",
    ]));
    assert_eq!(png_size(&f.path("b.png")), (20, 20));
    // A bare top level has no bottom levels to trace.
    f.write("ball.tlas", &c.tlas.data);
    fails(
        &f.run(&[
            "trace",
            "ball.tlas",
            "--rays",
            "rays.bin",
            "--hits",
            "h.bin",
        ]),
        "bare serialized top-level",
    );
    ok(&f.run(&["info", "ball.tlas"]));
}
