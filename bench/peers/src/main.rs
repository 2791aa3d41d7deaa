//! Side-by-side benchmark: hostas against Embree 3, tinybvh and obvhs on the same triangles
//! and the same rays. See README.md for what each figure means and how to run it.

mod mesh;
#[cfg(not(feature = "cli-mesh"))]
mod meshload_standin;
mod paired;
mod peers;
mod rays;
mod report;
mod sah;
mod scene;
mod util;

use clap::{Parser, ValueEnum};
use report::SceneReport;
use std::io::Write;
use std::path::PathBuf;
use std::time::Instant;

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum SahProxy {
    /// No Embree SAH proxy.
    Off,
    /// Proxy for LOW and MEDIUM only (HIGH's rtcBuildBVH with spatial splits is slow).
    Fast,
    /// Proxy for LOW, MEDIUM and HIGH.
    All,
}

const LIBS: [&str; 4] = ["hostas", "embree", "tinybvh", "obvhs"];

/// Variants run on the crown (3.5M triangles) unless --full-crown or --variants is given.
const CROWN_DEFAULT: &str = "hostas:default,embree:MEDIUM";

#[derive(Parser, Debug)]
#[command(
    name = "hostas-peers",
    about = "hostas vs Embree 3, tinybvh and obvhs: build, SAH, bytes, trace, refit"
)]
struct Args {
    /// Scenes, comma separated: sphere, soup, boxes, bunny, sponza, sibenik, conference, crown.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "sphere,soup,boxes,bunny,sponza,sibenik,conference,crown"
    )]
    scenes: Vec<String>,
    /// Libraries, comma separated: hostas, embree, tinybvh, obvhs.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "hostas,embree,tinybvh,obvhs"
    )]
    libs: Vec<String>,
    /// Restrict to variants, comma separated `lib` or `lib:key` (keys: embree LOW MEDIUM
    /// MEDIUM_ROBUST HIGH refit; tinybvh Build BuildAVX BuildHQ refit; obvhs very_fast medium;
    /// hostas fast_build default fast_trace low_memory refit).
    #[arg(long, value_delimiter = ',')]
    variants: Option<Vec<String>>,
    /// Timed build repetitions (median), after --warmup untimed ones.
    #[arg(long, default_value_t = 5)]
    reps: usize,
    #[arg(long, default_value_t = 1)]
    warmup: usize,
    /// Timed repetitions on scenes of --big-tris triangles or more.
    #[arg(long, default_value_t = 3)]
    big_reps: usize,
    /// Warm-up repetitions on big scenes (the median of 3 already drops one cold outlier).
    #[arg(long, default_value_t = 0)]
    big_warmup: usize,
    /// Timed refit repetitions (median), after --refit-warmup untimed ones, on every scene:
    /// a refit takes milliseconds, and the lent machine's refit times spread widely.
    #[arg(long, default_value_t = 11)]
    refit_reps: usize,
    #[arg(long, default_value_t = 1)]
    refit_warmup: usize,
    /// Repetitions for the spatial-split builders (Embree HIGH, tinybvh BuildHQ).
    #[arg(long, default_value_t = 3)]
    slow_reps: usize,
    /// Repetitions for the spatial-split builders on big scenes.
    #[arg(long, default_value_t = 1)]
    big_slow_reps: usize,
    /// What counts as a big scene.
    #[arg(long, default_value_t = 500_000)]
    big_tris: usize,
    #[arg(long, default_value_t = 0)]
    slow_warmup: usize,
    /// Image width of the primary rays: W x W primary rays and as many incoherent rays.
    #[arg(long, default_value_t = 256)]
    rays: usize,
    /// Ray kinds to trace, comma separated (the others are left out of every phase: a
    /// profile of one kind, e.g. under callgrind).
    #[arg(long, value_enum, value_delimiter = ',', default_values_t = rays::Kind::ALL)]
    kinds: Vec<rays::Kind>,
    /// Timed trace passes per ray kind (median), after one untimed pass that records hits.
    #[arg(long, default_value_t = 3)]
    passes: usize,
    /// "All threads" count (default: available parallelism). 1-thread figures are always run.
    #[arg(long)]
    threads: Option<usize>,
    /// Folder of the real meshes (default: <repo>/../shared/meshes).
    #[arg(long)]
    meshes: Option<PathBuf>,
    /// Write one JSON object per row (and one per scene) to this file.
    #[arg(long)]
    json: Option<PathBuf>,
    #[arg(long)]
    no_refit: bool,
    #[arg(long)]
    no_trace: bool,
    #[arg(long, value_enum, default_value_t = SahProxy::Fast)]
    embree_sah_proxy: SahProxy,
    /// Run every variant on the crown too (default there: hostas and Embree MEDIUM only).
    #[arg(long)]
    full_crown: bool,
    /// Pairs per target in the paired phase (hostas and Embree alternated, ratio per pair;
    /// see README); 0 turns the phase off.
    #[arg(long, default_value_t = 7)]
    pairs: usize,
    /// Build pairs per target on scenes of --big-tris triangles or more (trace pairs stay
    /// --pairs).
    #[arg(long, default_value_t = 5)]
    big_pairs: usize,
    /// Leave the 1-thread phases unpinned (by default they run on the CPU the program starts
    /// on, as `taskset -c N` would pin them; all-thread phases use every CPU either way).
    #[arg(long)]
    no_pin: bool,
}

#[derive(Clone)]
pub struct Cfg {
    pub threads: Vec<usize>,
    pub warmup: usize,
    pub reps: usize,
    pub slow_warmup: usize,
    pub slow_reps: usize,
    pub refit_warmup: usize,
    pub refit_reps: usize,
    pub passes: usize,
    pub refit: bool,
    pub trace: bool,
    pub sah_proxy: SahProxy,
    /// Pairs per target in the paired phase (0: off), and build pairs (fewer on big scenes).
    pub pairs: usize,
    pub build_pairs: usize,
    libs: Vec<String>,
    variants: Option<Vec<String>>,
}

impl Cfg {
    /// Whether variant `key` of library `lib` is selected.
    pub fn wants(&self, lib: &str, key: &str) -> bool {
        if !self.libs.iter().any(|l| l.eq_ignore_ascii_case(lib)) {
            return false;
        }
        match &self.variants {
            None => true,
            Some(v) => v.iter().any(|s| {
                let (l, k) = s.split_once(':').unwrap_or((s.as_str(), "*"));
                l.eq_ignore_ascii_case(lib) && (k == "*" || k.eq_ignore_ascii_case(key))
            }),
        }
    }
}

fn main() {
    util::set_ftz_daz();
    let args = Args::parse();
    let started = Instant::now();
    let pin_cpu = util::init_pinning(!args.no_pin);
    let all_threads = args.threads.unwrap_or_else(util::available_threads).max(1);
    let threads = if all_threads > 1 {
        vec![1, all_threads]
    } else {
        vec![1]
    };
    for l in &args.libs {
        if !LIBS.contains(&l.as_str()) {
            eprintln!("unknown library '{l}' (known: {})", LIBS.join(", "));
            std::process::exit(2);
        }
    }
    let base = Cfg {
        threads: threads.clone(),
        warmup: args.warmup,
        reps: args.reps.max(1),
        slow_warmup: args.slow_warmup,
        slow_reps: args.slow_reps.max(1),
        refit_warmup: args.refit_warmup,
        refit_reps: args.refit_reps.max(1),
        passes: args.passes.max(1),
        refit: !args.no_refit,
        trace: !args.no_trace,
        sah_proxy: args.embree_sah_proxy,
        pairs: args.pairs,
        build_pairs: args.pairs,
        libs: args.libs.clone(),
        variants: args.variants.clone(),
    };
    let mesh_dir = args.meshes.clone().unwrap_or_else(scene::default_mesh_dir);
    let mut json = args.json.as_ref().map(|p| {
        if let Some(dir) = p.parent() {
            let _ = std::fs::create_dir_all(dir);
        }
        std::io::BufWriter::new(
            std::fs::File::create(p).unwrap_or_else(|e| panic!("{}: {e}", p.display())),
        )
    });

    println!("# hostas vs peers\n");
    println!(
        "Threads: 1 and {all_threads} (machine: {} logical CPUs). Builds: median of {} after {} warm-up ({} after {} for Embree HIGH and tinybvh BuildHQ; fewer on scenes of {}+ triangles, see the notes). Refits: median of {} after {} warm-up, every scene. Trace: {} primary + {} incoherent rays, closest hit, t in [0, inf), 1 thread, median of {} passes. {} {} FTZ/DAZ on for every thread we own.",
        util::available_threads(),
        base.reps,
        base.warmup,
        base.slow_reps,
        base.slow_warmup,
        args.big_tris,
        base.refit_reps,
        base.refit_warmup,
        args.rays * args.rays,
        args.rays * args.rays,
        base.passes,
        if args.pairs > 0 {
            format!(
                "Paired phase: hostas and Embree alternated, {} pairs per target ({} build pairs on big scenes), median of the pair ratios.",
                args.pairs,
                args.big_pairs.max(1)
            )
        } else {
            "Paired phase off (--pairs 0).".to_string()
        },
        match pin_cpu {
            Some(_) => format!("{} (--no-pin: not pinned).", util::pinning_note(pin_cpu)),
            None => format!("{}.", util::pinning_note(pin_cpu)),
        }
    );
    let machine = util::machine();
    let compiled_for = util::compiled_for();
    println!("Machine: {machine}. Rust code compiled for {compiled_for}.");
    println!(
        "Versions: Embree {}, tinybvh 1.6.8 (tinybvh-rs 0.1.0-beta.3 header, C++ shim), obvhs 0.4.0, hostas {}.",
        peers::embree::version(),
        option_env!("PEERS_GIT_REV").unwrap_or("(git revision unknown)")
    );
    println!(
        "SAH(1,1) = sum over interior nodes of A/A(root) x C_trav + sum over leaves of A/A(root) x N x C_isect, with C_trav = C_isect = 1, on each library's binary tree (Embree: rtcBuildBVH proxy; hostas: the value hostas reports). B/tri = bytes of the traced structure / triangles. Mesh loader: {}. Mesh folder: {}{}",
        mesh::LOADER,
        mesh_dir.display(),
        if mesh_dir.exists() {
            ""
        } else {
            " (ABSENT: real-mesh scenes are skipped)"
        }
    );

    for name in &args.scenes {
        let t_scene = Instant::now();
        let loaded = match scene::load(name, &mesh_dir) {
            Ok(l) => l,
            Err(e) => {
                eprintln!("{e}");
                std::process::exit(2);
            }
        };
        let sc = match loaded {
            scene::Loaded::Scene(s) => s,
            scene::Loaded::Missing(why) => {
                println!("\n### `{name}`: skipped: {why}\n");
                continue;
            }
        };
        let mut cfg = base.clone();
        let mut notes = Vec::new();
        if sc.tri_count() >= args.big_tris {
            cfg.reps = args.big_reps.max(1);
            cfg.warmup = args.big_warmup;
            cfg.slow_reps = args.big_slow_reps.max(1);
            if cfg.pairs > 0 {
                cfg.build_pairs = args.big_pairs.max(1);
            }
            notes.push(format!(
                "big scene: builds median of {} after {} warm-up ({} for Embree HIGH / tinybvh BuildHQ); {} build pairs",
                cfg.reps, cfg.warmup, cfg.slow_reps, cfg.build_pairs
            ));
        }
        if name == "crown" && !args.full_crown && args.variants.is_none() {
            cfg.variants = Some(CROWN_DEFAULT.split(',').map(String::from).collect());
            notes.push(format!("crown: only {CROWN_DEFAULT} by default, to fit the time budget (--full-crown runs all)"));
        }
        let load_start = util::loadavg();
        let load_s = t_scene.elapsed().as_secs_f64();
        let mut rays = rays::generate(&sc, args.rays);
        rays.keep(&args.kinds);
        eprintln!(
            "[{:6.1}s] scene {} ({} tris, loaded in {:.1}s)",
            started.elapsed().as_secs_f64(),
            sc.name,
            sc.tri_count(),
            load_s
        );
        // The 1-thread phases on one CPU; each library's all-thread phase unpins itself.
        let pinned = util::cpus_for(1);
        notes.push(util::pinning_note(pin_cpu));
        let mut rows = Vec::new();
        type RunFn = fn(&scene::Scene, &rays::RaySet, &Cfg) -> Vec<report::Row>;
        let libs: [(&str, RunFn); 4] = [
            ("hostas", peers::hostas::run),
            ("embree", peers::embree::run),
            ("tinybvh", peers::tinybvh::run),
            ("obvhs", peers::obvhs::run),
        ];
        for (lib, run) in libs {
            if !cfg.libs.iter().any(|l| l == lib) {
                continue;
            }
            let t0 = Instant::now();
            let r = run(&sc, &rays, &cfg);
            eprintln!(
                "[{:6.1}s]   {lib}: {} rows in {:.1}s",
                started.elapsed().as_secs_f64(),
                r.len(),
                t0.elapsed().as_secs_f64()
            );
            rows.extend(r);
        }
        let t0 = Instant::now();
        let paired = paired::run(&sc, &rays, &cfg);
        let paired_seconds = t0.elapsed().as_secs_f64();
        drop(pinned);
        if !paired.is_empty() {
            eprintln!(
                "[{:6.1}s]   paired: {} targets in {paired_seconds:.1}s",
                started.elapsed().as_secs_f64(),
                paired.len(),
            );
        }
        let mut rep = SceneReport {
            scene: sc.name.clone(),
            source: sc.source.clone(),
            tris: sc.tri_count(),
            diagonal: sc.diagonal(),
            threads: threads.clone(),
            rows,
            paired,
            pairs: (cfg.build_pairs, cfg.pairs),
            paired_seconds,
            reference: None,
            checks: Vec::new(),
            notes,
            seconds: 0.0,
        };
        if let (Some(a), Some(b)) = (load_start, util::loadavg()) {
            let busy = if a.max(b) > all_threads as f64 + 0.5 {
                " (the machine was busy with other work: expect depressed, noisy figures, the all-thread ones first)"
            } else {
                ""
            };
            rep.notes.push(format!(
                "1-minute load average at scene start / end: {a:.2} / {b:.2}{busy}"
            ));
        }
        rep.finish();
        rep.seconds = t_scene.elapsed().as_secs_f64();
        print!("{}", rep.markdown());
        std::io::stdout().flush().ok();
        if let Some(j) = json.as_mut() {
            let summary = serde_json::json!({
                "scene_summary": sc.name, "tris": sc.tri_count(), "source": sc.source, "seconds": rep.seconds,
                "threads": threads, "rays_per_kind": args.rays * args.rays,
                "check_reference": rep.reference.map(|i| rep.rows[i].name()), "notes": rep.notes,
                "hostas": option_env!("PEERS_GIT_REV"), "machine": machine,
                "compiled_for": compiled_for,
            });
            writeln!(j, "{summary}").unwrap();
            for l in rep.json_lines() {
                writeln!(j, "{l}").unwrap();
            }
        }
    }
    println!(
        "\nTotal wall time: {:.1} s",
        started.elapsed().as_secs_f64()
    );
}
