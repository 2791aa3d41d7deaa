//! The paired phase: hostas and Embree measured back to back, one ratio per pair.
//!
//! Per-library medians taken a minute apart move by up to ±30% on a shared 2-vCPU machine, so
//! their ratio does too. perf-anchors.md 4.3 asks for every goal to be a ratio measured in the
//! same process, on the same rays, with the same thread count, interleaved. So, for each
//! issue-5 target that compares hostas with Embree, this phase runs N pairs of one hostas and
//! one Embree measurement, alternating which side runs first (hostas, Embree; Embree, hostas;
//! ...: ABBA), takes the ratio within each pair (hostas throughput ÷ Embree throughput, that is
//! Embree time ÷ hostas time, since both sides do the same work), and reports the median of the
//! pair ratios with their range.

use crate::Cfg;
use crate::peers;
use crate::rays::{Hit, Kind, Ray, RaySet};
use crate::scene::Scene;
use crate::util::{Rng, median};
use std::hint::black_box;
use std::sync::OnceLock;
use std::time::{Duration, Instant};

/// One library's side of a pair.
pub trait Side {
    /// One whole 1-thread build of the side's variant, timed as in the library's own run; the
    /// structure is destroyed untimed, unless `keep`: then it replaces the kept one, for `trace`.
    fn build(&mut self, keep: bool) -> Result<Duration, String>;
    /// One pass over `rays` with the kept structure (1 thread), timed as in the library's own
    /// run.
    fn trace(&mut self, rays: &[Ray], hits: &mut [Hit]) -> Result<Duration, String>;
}

/// An issue-5 target measured in pairs.
pub struct Target {
    /// Name in the JSON (`"paired"`) and in `targets.py`.
    pub name: &'static str,
    /// What is timed, for the Markdown table.
    pub what: &'static str,
    pub hostas: &'static str,
    pub embree: &'static str,
}

pub const FAST_BUILD_BUILD: Target = Target {
    name: "fast_build_build_1t_vs_low",
    what: "build 1T",
    hostas: "fast_build",
    embree: "LOW",
};
pub const FAST_TRACE_BUILD: Target = Target {
    name: "fast_trace_build_1t_vs_medium",
    what: "build 1T",
    hostas: "fast_trace",
    embree: "MEDIUM",
};
pub const FAST_TRACE_PRIMARY: Target = Target {
    name: "fast_trace_primary_vs_medium",
    what: "primary rays 1T",
    hostas: "fast_trace",
    embree: "MEDIUM",
};
pub const FAST_TRACE_INCOHERENT: Target = Target {
    name: "fast_trace_incoherent_vs_medium",
    what: "incoherent rays 1T",
    hostas: "fast_trace",
    embree: "MEDIUM",
};
/// Context, not targets: the same traces against Embree's robust mode, whose node and triangle
/// tests are the nearest Embree has to the exact, watertight ones hostas must use (MEDIUM's
/// default kernel is Moller-Trumbore with fast box tests).
pub const FAST_TRACE_PRIMARY_ROBUST: Target = Target {
    name: "fast_trace_primary_vs_medium_robust",
    what: "primary rays 1T",
    hostas: "fast_trace",
    embree: "MEDIUM_ROBUST",
};
pub const FAST_TRACE_INCOHERENT_ROBUST: Target = Target {
    name: "fast_trace_incoherent_vs_medium_robust",
    what: "incoherent rays 1T",
    hostas: "fast_trace",
    embree: "MEDIUM_ROBUST",
};

/// The timed parts of each pair, in ms, and the canaries timed just before each pair, in µs:
/// [`L2_CANARY`] and [`L1_CANARY`].
#[derive(Default)]
pub struct Pairs {
    pub hostas_ms: Vec<f64>,
    pub embree_ms: Vec<f64>,
    pub canary_us: Vec<f64>,
    pub canary_l1_us: Vec<f64>,
}

impl Pairs {
    /// hostas throughput ÷ Embree throughput, per pair.
    pub fn ratios(&self) -> Vec<f64> {
        self.hostas_ms
            .iter()
            .zip(&self.embree_ms)
            .map(|(h, e)| e / h)
            .collect()
    }
    /// (median, min, max) of the pair ratios.
    pub fn summary(&self) -> (f64, f64, f64) {
        let mut r = self.ratios();
        let m = median(&mut r);
        let min = r.iter().copied().fold(f64::INFINITY, f64::min);
        let max = r.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        (m, min, max)
    }
}

/// A target's outcome: its pairs, or why it was skipped.
pub struct Ratio {
    pub target: &'static Target,
    pub pairs: Result<Pairs, String>,
}

/// Runs `pairs` pairs after `warmup` untimed rounds, the first side alternating: hostas then
/// Embree in even pairs, Embree then hostas in odd ones. The closures get `true` on their last
/// call.
fn alternate(
    pairs: usize,
    warmup: usize,
    mut hostas: impl FnMut(bool) -> Result<Duration, String>,
    mut embree: impl FnMut(bool) -> Result<Duration, String>,
) -> Result<Pairs, String> {
    let mut hostas = |last| hostas(last).map_err(|e| format!("hostas: {e}"));
    let mut embree = |last| embree(last).map_err(|e| format!("embree: {e}"));
    for _ in 0..warmup {
        hostas(false)?;
        embree(false)?;
    }
    let ms = |d: Duration| d.as_secs_f64() * 1e3;
    let mut out = Pairs::default();
    for i in 0..pairs {
        let last = i + 1 == pairs;
        out.canary_us.push(L2_CANARY.time());
        out.canary_l1_us.push(L1_CANARY.time());
        let (h, e) = if i % 2 == 0 {
            let h = hostas(last)?;
            (h, embree(last)?)
        } else {
            let e = embree(last)?;
            (hostas(last)?, e)
        };
        out.hostas_ms.push(ms(h));
        out.embree_ms.push(ms(e));
    }
    Ok(out)
}

/// A fixed walk through a buffer that fits one of the core's caches, timed in µs: one pass
/// over the buffer brings it in, then [`CANARY_STEPS`] dependent loads follow a random cycle
/// through it (each waits for the one before: the time is that cache's latency, or the next
/// level's where the buffer no longer fits). The lent Xeon has stretches of seconds to
/// minutes in which hostas's one-thread trace of a mesh slows by 50-85% and Embree's by
/// 15-35%. The thirty-ninth session's probes found that busy loops on the machine's other
/// CPUs do not decide them and that a timed loop of arithmetic does not see them; the L2 walk
/// does (its time correlates with both sides'). Timed before each pair, the walks say how busy
/// the core's caches were when the pair ran.
struct Canary {
    bytes: usize,
    cycle: OnceLock<Vec<u32>>,
}

/// Three quarters of the lent Xeon's L2 (2 MiB a core).
static L2_CANARY: Canary = Canary::new(3 << 19);
/// Three quarters of the VM's L1 data cache (32 KiB; the Xeon's is 48 KiB), which a core's
/// two hardware threads share: whether the slow stretches are the L1's (the forty-first
/// session: it barely moves in them, while the L2 walk doubles).
static L1_CANARY: Canary = Canary::new(3 << 13);
/// Dependent loads a [`Canary`] times.
const CANARY_STEPS: usize = 20_000;

impl Canary {
    const fn new(bytes: usize) -> Canary {
        Canary {
            bytes,
            cycle: OnceLock::new(),
        }
    }

    fn time(&self) -> f64 {
        let next = self.cycle.get_or_init(|| {
            // Sattolo's shuffle (a fixed seed): one cycle through every entry.
            let n = self.bytes / 4;
            let mut next: Vec<u32> = (0..n as u32).collect();
            let mut rng = Rng::new(0xca4a);
            for i in (1..n).rev() {
                next.swap(i, (rng.next_u64() % i as u64) as usize);
            }
            next
        });
        black_box(next.iter().fold(0u32, |a, &x| a ^ x));
        let t = Instant::now();
        let mut i = 0u32;
        for _ in 0..CANARY_STEPS {
            i = next[i as usize];
        }
        black_box(i);
        t.elapsed().as_secs_f64() * 1e6
    }
}

type Sides<'a> = (Box<dyn Side + 'a>, Box<dyn Side + 'a>);

/// Both sides of `target`, or why they cannot run.
fn sides<'a>(scene: &'a Scene, cfg: &Cfg, target: &Target) -> Result<Sides<'a>, String> {
    for (lib, key) in [("hostas", target.hostas), ("embree", target.embree)] {
        if !cfg.wants(lib, key) {
            return Err(format!("{lib}:{key} not selected"));
        }
    }
    Ok((
        peers::hostas::pair_side(scene, target.hostas)?,
        peers::embree::pair_side(scene, target.embree)?,
    ))
}

/// Build pairs after at least one untimed build of each side: a side's first build pays for
/// fresh pages (hostas's scratch, Embree's allocator blocks), 2-4x its later ones on 1M
/// triangles, even on big scenes where the per-library runs skip the warm-up.
fn builds(cfg: &Cfg, (h, e): &mut Sides, keep: bool) -> Result<Pairs, String> {
    alternate(
        cfg.build_pairs,
        cfg.warmup.max(1),
        |last| h.build(keep && last),
        |last| e.build(keep && last),
    )
}

/// Trace pairs over the structures the sides keep, after one untimed pass each.
fn traces(cfg: &Cfg, h: &mut dyn Side, e: &mut dyn Side, rays: &[Ray]) -> Result<Pairs, String> {
    let mut hostas_hits = vec![Hit::MISS; rays.len()];
    let mut embree_hits = hostas_hits.clone();
    alternate(
        cfg.pairs,
        1,
        |_| h.trace(rays, &mut hostas_hits),
        |_| e.trace(rays, &mut embree_hits),
    )
}

/// The primary-ray and incoherent-ray pairs of `targets` between `sides` (hostas, Embree), or
/// the reason there are none.
fn trace_targets<'a>(
    cfg: &Cfg,
    rays: &RaySet,
    mut sides: Result<(&mut (dyn Side + 'a), &mut (dyn Side + 'a)), String>,
    [primary, incoherent]: [&'static Target; 2],
) -> [Ratio; 2] {
    [(primary, Kind::Primary), (incoherent, Kind::Incoherent)].map(|(target, kind)| {
        let pairs = match &mut sides {
            _ if rays.get(kind).is_empty() => Err("left out by --kinds".to_string()),
            Ok((h, e)) => traces(cfg, &mut **h, &mut **e, rays.get(kind)),
            Err(why) => Err(why.clone()),
        };
        Ratio { target, pairs }
    })
}

/// The paired phase of one scene (see the module comment). Empty when it is off (`--pairs 0`).
pub fn run(scene: &Scene, rays: &RaySet, cfg: &Cfg) -> Vec<Ratio> {
    if cfg.pairs == 0 {
        return Vec::new();
    }
    let mut out = Vec::new();
    let t = &FAST_BUILD_BUILD;
    let pairs = sides(scene, cfg, t).and_then(|mut s| builds(cfg, &mut s, false));
    out.push(Ratio { target: t, pairs });
    // Fast trace: the last build pair keeps its structures, which the trace pairs then use.
    let (pairs, mut kept) = match sides(scene, cfg, &FAST_TRACE_BUILD) {
        Ok(mut s) => match builds(cfg, &mut s, cfg.trace) {
            Ok(p) => (Ok(p), Ok(s)),
            Err(e) => (
                Err(e.clone()),
                Err(format!("no structures, the build pairs failed: {e}")),
            ),
        },
        Err(why) => (Err(why.clone()), Err(why)),
    };
    const NO_TRACE: &str = "--no-trace";
    let medium = match &mut kept {
        _ if !cfg.trace => Err(NO_TRACE.to_string()),
        Ok((h, e)) => Ok((h.as_mut(), e.as_mut())),
        Err(why) => Err(why.clone()),
    };
    let traced = trace_targets(
        cfg,
        rays,
        medium,
        [&FAST_TRACE_PRIMARY, &FAST_TRACE_INCOHERENT],
    );
    out.push(Ratio {
        target: &FAST_TRACE_BUILD,
        pairs,
    });
    out.extend(traced);
    // The same hostas structure against Embree's robust mode (one untimed build kept).
    let robust = FAST_TRACE_PRIMARY_ROBUST.embree;
    let mut robust_side = match &kept {
        _ if !cfg.trace => Err(NO_TRACE.to_string()),
        Err(why) => Err(why.clone()),
        Ok(_) if !cfg.wants("embree", robust) => Err(format!("embree:{robust} not selected")),
        Ok(_) => peers::embree::pair_side(scene, robust).and_then(|mut r| r.build(true).map(|_| r)),
    };
    let sides = match (&mut kept, &mut robust_side) {
        (Ok((h, _)), Ok(r)) => Ok((h.as_mut(), r.as_mut())),
        (_, Err(why)) => Err(why.clone()),
        (Err(why), _) => Err(why.clone()),
    };
    out.extend(trace_targets(
        cfg,
        rays,
        sides,
        [&FAST_TRACE_PRIMARY_ROBUST, &FAST_TRACE_INCOHERENT_ROBUST],
    ));
    out
}
