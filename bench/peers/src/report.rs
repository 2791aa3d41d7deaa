//! Result rows, the hit cross-check, Markdown tables and JSON lines.

use crate::paired::Ratio;
use crate::rays::{Hit, Kind};
use serde_json::{Value, json};
use std::collections::BTreeMap;

/// Which hostas preset a peer variant is compared with.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Class {
    FastBuild,
    Default,
    FastTrace,
    LowMemory,
}

impl Class {
    pub fn hostas_key(self) -> &'static str {
        match self {
            Class::FastBuild => "fast_build",
            Class::Default => "default",
            Class::FastTrace => "fast_trace",
            Class::LowMemory => "low_memory",
        }
    }
}

#[derive(Default)]
pub struct Row {
    pub library: &'static str,
    /// Short key used on the command line (`--variants lib:key`).
    pub key: String,
    pub variant: String,
    pub class: Option<Class>,
    /// threads -> median build ms, to the traversable structure that is traced.
    pub build_ms: BTreeMap<usize, f64>,
    pub sah: Option<f64>,
    pub sah_note: String,
    /// The SAH is of a wide tree (hostas reports its 8-wide tree's), not a binary one.
    pub sah_wide: bool,
    /// The same SAH over an 8-wide tree, comparable with hostas's: hostas's own, and for
    /// Embree the 8-wide proxy (see `peers/embree.rs`).
    pub sah8: Option<f64>,
    pub bytes: Option<u64>,
    pub bytes_note: String,
    /// median ms for one pass over the rays, per kind (1 thread).
    pub trace_ms: [Option<f64>; 2],
    pub rays: [usize; 2],
    /// threads -> median refit ms.
    pub refit_ms: BTreeMap<usize, f64>,
    pub hits: [Option<Vec<Hit>>; 2],
    pub extra: BTreeMap<String, Value>,
    pub note: String,
    pub error: Option<String>,
}

impl Row {
    pub fn new(library: &'static str, key: &str, variant: &str, class: Option<Class>) -> Row {
        Row {
            library,
            key: key.to_string(),
            variant: variant.to_string(),
            class,
            ..Default::default()
        }
    }
    pub fn name(&self) -> String {
        format!("{}:{}", self.library, self.key)
    }
    pub fn set_trace(&mut self, kind: Kind, ms: f64, hits: Vec<Hit>) {
        let k = kind as usize;
        self.rays[k] = hits.len();
        self.trace_ms[k] = Some(ms);
        self.hits[k] = Some(hits);
    }
    pub fn mrays(&self, kind: Kind) -> Option<f64> {
        let k = kind as usize;
        self.trace_ms[k].map(|ms| self.rays[k] as f64 / (ms * 1e3))
    }
}

#[derive(Clone, Copy, Default, Debug)]
pub struct Check {
    pub rays: usize,
    /// Rays whose result differs from the reference in any way beyond the tolerance.
    pub differ: usize,
    /// Both hit, different primitive, same t within 1e-6 relative (e.g. a shared edge).
    pub ties: usize,
    /// Everything else that differs: hit vs miss, or different t.
    pub true_mismatch: usize,
    /// Subset of true mismatches where one side hit and the other missed.
    pub hit_vs_miss: usize,
    pub ref_hits: usize,
    pub hits: usize,
}

/// Ties: both hit, different primitives, |t1 - t2| <= max(TIE_REL * t, TIE_ABS * diagonal).
/// The absolute floor matters only for t near 0 (origins on a surface), where float t
/// differences are set by the coordinates' precision, not by t.
pub const TIE_REL: f32 = 1e-6;
pub const TIE_ABS: f32 = 1e-7;
/// Same primitive, t computed by two different triangle tests: allowed difference
/// max(SAME_PRIM_REL * t, SAME_PRIM_ABS * diagonal).
pub const SAME_PRIM_REL: f32 = 1e-4;
pub const SAME_PRIM_ABS: f32 = 1e-5;

/// Compares `other` with `reference`, ray by ray; `diagonal` = scene box diagonal.
pub fn compare(reference: &[Hit], other: &[Hit], diagonal: f32) -> Check {
    let mut c = Check {
        rays: reference.len().min(other.len()),
        ..Default::default()
    };
    for (a, b) in reference.iter().zip(other) {
        c.ref_hits += a.is_hit() as usize;
        c.hits += b.is_hit() as usize;
        match (a.is_hit(), b.is_hit()) {
            (false, false) => {}
            (true, false) | (false, true) => {
                c.differ += 1;
                c.true_mismatch += 1;
                c.hit_vs_miss += 1;
            }
            (true, true) => {
                let t = a.t.abs().max(b.t.abs());
                let dt = (a.t - b.t).abs();
                if a.prim == b.prim {
                    if dt > (SAME_PRIM_REL * t).max(SAME_PRIM_ABS * diagonal) {
                        c.differ += 1;
                        c.true_mismatch += 1;
                    }
                } else if dt <= (TIE_REL * t).max(TIE_ABS * diagonal) {
                    c.differ += 1;
                    c.ties += 1;
                } else {
                    c.differ += 1;
                    c.true_mismatch += 1;
                }
            }
        }
    }
    c
}

pub struct SceneReport {
    pub scene: String,
    pub source: String,
    pub tris: usize,
    pub diagonal: f32,
    pub threads: Vec<usize>,
    pub rows: Vec<Row>,
    /// The paired phase's targets (`crate::paired`), the pair counts asked for (builds,
    /// traces), and its wall time.
    pub paired: Vec<Ratio>,
    pub pairs: (usize, usize),
    pub paired_seconds: f64,
    /// Row index used as the cross-check reference, and its name.
    pub reference: Option<usize>,
    pub checks: Vec<[Option<Check>; 2]>,
    pub notes: Vec<String>,
    pub seconds: f64,
}

fn mt(tris: usize, ms: Option<f64>) -> Option<f64> {
    ms.map(|ms| tris as f64 / (ms * 1e3))
}

fn f(v: Option<f64>, prec: usize) -> String {
    match v {
        Some(x) if x.is_finite() => format!("{x:.prec$}"),
        _ => String::new(),
    }
}

impl SceneReport {
    pub fn finish(&mut self) {
        // Reference for the hit cross-check: hostas default preset, else Embree MEDIUM, else
        // the first row with hits.
        // (Hits of either kind: `--kinds` may leave one out.)
        let traced = |r: &Row| r.hits.iter().any(Option::is_some);
        let pick = |lib: &str, key: &str| {
            self.rows
                .iter()
                .position(|r| r.library == lib && r.key == key && traced(r))
        };
        self.reference = pick("hostas", "default")
            .or_else(|| pick("embree", "MEDIUM"))
            .or_else(|| self.rows.iter().position(traced));
        if let (Some(ri), Ok(_)) = (self.reference, std::env::var("PEERS_DEBUG_MISMATCH")) {
            for r in &self.rows {
                for k in 0..2 {
                    if let (Some(a), Some(b)) = (&self.rows[ri].hits[k], &r.hits[k]) {
                        let mut shown = 0;
                        for (i, (x, y)) in a.iter().zip(b).enumerate() {
                            let one = compare(
                                std::slice::from_ref(x),
                                std::slice::from_ref(y),
                                self.diagonal,
                            );
                            if one.true_mismatch > 0 && shown < 5 {
                                shown += 1;
                                eprintln!(
                                    "{} {} kind {k} ray {i}: ref {:?} vs {:?}",
                                    self.scene,
                                    r.name(),
                                    x,
                                    y
                                );
                            }
                        }
                    }
                }
            }
        }
        self.checks = self
            .rows
            .iter()
            .map(|r| {
                let mut out = [None, None];
                if let Some(ri) = self.reference {
                    for (k, o) in out.iter_mut().enumerate() {
                        if let (Some(a), Some(b)) = (&self.rows[ri].hits[k], &r.hits[k]) {
                            *o = Some(compare(a, b, self.diagonal));
                        }
                    }
                }
                out
            })
            .collect();
    }

    fn hostas_row(&self, class: Class) -> Option<&Row> {
        self.rows
            .iter()
            .find(|r| r.library == "hostas" && r.key == class.hostas_key() && r.error.is_none())
    }

    pub fn markdown(&self) -> String {
        let mut s = String::new();
        let tn = *self.threads.last().unwrap_or(&1);
        s += &format!(
            "\n### `{}` ({} triangles; {})\n\n",
            self.scene,
            group(self.tris),
            self.source
        );
        let reference = self
            .reference
            .map(|i| self.rows[i].name())
            .unwrap_or_else(|| "none".into());
        s += &format!(
            "| library | variant | build 1T Mtris/s | build {tn}T Mtris/s | SAH(1,1) | B/tri | primary Mrays/s | incoherent Mrays/s | refit 1T Mtris/s | refit {tn}T Mtris/s | vs {reference}: primary differ (ties/true) | incoherent differ (ties/true) |\n"
        );
        s += "|---|---|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|\n";
        for (i, r) in self.rows.iter().enumerate() {
            if let Some(e) = &r.error {
                s += &format!(
                    "| {} | {} | error: {} |||||||||||\n",
                    r.library,
                    r.variant,
                    e.replace('|', "/")
                );
                continue;
            }
            let b1 = mt(self.tris, r.build_ms.get(&1).copied());
            let bn = if tn > 1 {
                mt(self.tris, r.build_ms.get(&tn).copied())
            } else {
                None
            };
            let r1 = mt(self.tris, r.refit_ms.get(&1).copied());
            let rn = if tn > 1 {
                mt(self.tris, r.refit_ms.get(&tn).copied())
            } else {
                None
            };
            let bpt = r.bytes.map(|b| b as f64 / self.tris as f64);
            let chk = |k: usize| match (self.reference, self.checks[i][k]) {
                (Some(ri), _) if ri == i => "(reference)".to_string(),
                (_, Some(c)) => format!("{} ({}/{})", c.differ, c.ties, c.true_mismatch),
                _ => String::new(),
            };
            s += &format!(
                "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |\n",
                r.library,
                r.variant,
                f(b1, 2),
                f(bn, 2),
                match (r.sah_wide, r.sah8) {
                    (true, _) => format!("{} (8-wide)", f(r.sah, 2)),
                    (false, Some(w)) => format!("{} ({} 8-wide)", f(r.sah, 2), f(Some(w), 2)),
                    (false, None) => f(r.sah, 2),
                },
                f(bpt, 1),
                f(r.mrays(Kind::Primary), 2),
                f(r.mrays(Kind::Incoherent), 2),
                f(r1, 1),
                f(rn, 1),
                chk(0),
                chk(1)
            );
        }
        // Ratios to hostas.
        let mut ratio_rows = String::new();
        for r in &self.rows {
            if r.library == "hostas" || r.error.is_some() {
                continue;
            }
            let Some(class) = r.class else { continue };
            let Some(h) = self.hostas_row(class) else {
                continue;
            };
            let div = |a: Option<f64>, b: Option<f64>| match (a, b) {
                (Some(a), Some(b)) if b > 0.0 => Some(a / b),
                _ => None,
            };
            let bt = |row: &Row, t: usize| mt(self.tris, row.build_ms.get(&t).copied());
            let rt = |row: &Row, t: usize| mt(self.tris, row.refit_ms.get(&t).copied());
            ratio_rows += &format!(
                "| {} {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |\n",
                r.library,
                r.variant,
                h.key,
                f(div(bt(h, 1), bt(r, 1)), 2),
                if tn > 1 {
                    f(div(bt(h, tn), bt(r, tn)), 2)
                } else {
                    String::new()
                },
                match (h.sah, r.sah) {
                    (Some(_), Some(_)) if h.sah_wide != r.sah_wide => match r.sah8 {
                        Some(_) => format!("{} (8-wide)", f(div(h.sah8, r.sah8), 3)),
                        None => "n/c".to_string(),
                    },
                    _ => f(div(h.sah, r.sah), 3),
                },
                f(div(h.bytes.map(|b| b as f64), r.bytes.map(|b| b as f64)), 2),
                f(div(h.mrays(Kind::Primary), r.mrays(Kind::Primary)), 2),
                f(div(h.mrays(Kind::Incoherent), r.mrays(Kind::Incoherent)), 2),
                f(div(rt(h, 1), rt(r, 1)), 2),
                if tn > 1 {
                    f(div(rt(h, tn), rt(r, tn)), 2)
                } else {
                    String::new()
                },
            );
        }
        if !ratio_rows.is_empty() {
            s += &format!(
                "\nhostas ÷ peer (throughputs: > 1 means hostas is faster; SAH and bytes: < 1 means hostas is lower; n/c: hostas reports the SAH of its 8-wide tree, not comparable with a binary tree's; (8-wide): against the peer's 8-wide proxy):\n\n| peer | hostas preset | build 1T | build {tn}T | SAH | B/tri | primary | incoherent | refit 1T | refit {tn}T |\n|---|---|--:|--:|--:|--:|--:|--:|--:|--:|\n"
            );
            s += &ratio_rows;
        }
        s += &self.paired_markdown();
        let mut notes = self.notes.clone();
        for r in &self.rows {
            if !r.note.is_empty() {
                notes.push(format!("{} {}: {}", r.library, r.variant, r.note));
            }
        }
        if !notes.is_empty() {
            s += "\n";
            for n in notes {
                s += &format!("- {n}\n");
            }
        }
        s += &format!("\n(scene wall time {:.1} s)\n", self.seconds);
        s
    }

    fn paired_markdown(&self) -> String {
        if self.paired.is_empty() {
            return String::new();
        }
        let mut s = format!(
            "\nPaired ratios, hostas ÷ Embree throughput (> 1: hostas is faster), 1 thread: {} build pairs / {} trace pairs per target, each pair run back to back with the first side alternating; median of the pair ratios ({:.1} s):\n\n| target | hostas | Embree | median | range | n |\n|---|---|---|--:|--:|--:|\n",
            self.pairs.0, self.pairs.1, self.paired_seconds
        );
        for r in &self.paired {
            let t = r.target;
            s += &match &r.pairs {
                Ok(p) => {
                    let (m, lo, hi) = p.summary();
                    format!(
                        "| {} | {} | {} | {m:.2} | {lo:.2}–{hi:.2} | {} |\n",
                        t.what,
                        t.hostas,
                        t.embree,
                        p.hostas_ms.len()
                    )
                }
                Err(why) => format!(
                    "| {} | {} | {} | skipped: {} | | 0 |\n",
                    t.what,
                    t.hostas,
                    t.embree,
                    why.replace('|', "/")
                ),
            };
        }
        s
    }

    pub fn json_lines(&self) -> Vec<String> {
        let tn = *self.threads.last().unwrap_or(&1);
        let mut out = Vec::new();
        for (i, r) in self.rows.iter().enumerate() {
            let per_t = |m: &BTreeMap<usize, f64>| -> (Value, Value) {
                let ms: serde_json::Map<String, Value> =
                    m.iter().map(|(t, v)| (t.to_string(), json!(v))).collect();
                let tp: serde_json::Map<String, Value> = m
                    .iter()
                    .map(|(t, v)| (t.to_string(), json!(self.tris as f64 / (v * 1e3))))
                    .collect();
                (Value::Object(ms), Value::Object(tp))
            };
            let (build_ms, build_mtris) = per_t(&r.build_ms);
            let (refit_ms, refit_mtris) = per_t(&r.refit_ms);
            let chk = |k: usize| {
                self.checks.get(i).and_then(|c| c[k]).map(|c| {
                    json!({"rays": c.rays, "differ": c.differ, "ties": c.ties, "true_mismatch": c.true_mismatch,
                           "hit_vs_miss": c.hit_vs_miss, "hits": c.hits, "reference_hits": c.ref_hits})
                })
            };
            let mut v = json!({
                "scene": self.scene, "tris": self.tris, "library": r.library, "key": r.key, "variant": r.variant,
                "class": r.class.map(|c| c.hostas_key()), "threads_all": tn,
                "build_ms": build_ms, "build_mtris_s": build_mtris,
                "sah_ct1_ci1": r.sah, "sah8_ct1_ci1": r.sah8, "sah_note": r.sah_note, "sah_tree": if r.sah_wide { "8-wide" } else { "binary" },
                "bytes": r.bytes, "bytes_per_tri": r.bytes.map(|b| b as f64 / self.tris as f64), "bytes_note": r.bytes_note,
                "primary_mrays_s_1t": r.mrays(Kind::Primary), "incoherent_mrays_s_1t": r.mrays(Kind::Incoherent),
                "rays_per_kind": r.rays[0].max(r.rays[1]),
                "refit_ms": refit_ms, "refit_mtris_s": refit_mtris,
                "check_reference": self.reference.map(|ri| self.rows[ri].name()),
                "check_primary": chk(0), "check_incoherent": chk(1),
                "note": r.note, "error": r.error,
            });
            if let Value::Object(m) = &mut v {
                for (k, x) in &r.extra {
                    m.insert(k.clone(), x.clone());
                }
            }
            out.push(v.to_string());
        }
        for r in &self.paired {
            let t = r.target;
            let mut v = json!({
                "paired": t.name, "scene": self.scene, "tris": self.tris,
                "hostas_key": t.hostas, "embree_key": t.embree, "measure": t.what,
            });
            if let Value::Object(m) = &mut v {
                let fields = match &r.pairs {
                    Ok(p) => {
                        let (median, min, max) = p.summary();
                        json!({"median": median, "min": min, "max": max, "n": p.hostas_ms.len(),
                               "ratios": p.ratios(), "hostas_ms": p.hostas_ms, "embree_ms": p.embree_ms,
                               "canary_us": p.canary_us, "canary_l1_us": p.canary_l1_us})
                    }
                    Err(why) => json!({"skipped": why, "n": 0}),
                };
                if let Value::Object(f) = fields {
                    m.extend(f);
                }
            }
            out.push(v.to_string());
        }
        out
    }
}

pub fn group(n: usize) -> String {
    let s = n.to_string();
    let mut out = String::new();
    for (i, c) in s.chars().enumerate() {
        if i > 0 && (s.len() - i).is_multiple_of(3) {
            out.push(',');
        }
        out.push(c);
    }
    out
}
