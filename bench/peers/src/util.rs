//! Small shared helpers: deterministic RNG, timing, medians, FTZ/DAZ, pinning.

use std::time::{Duration, Instant};

/// SplitMix64: tiny, deterministic, good enough for scene and ray generation.
#[derive(Clone)]
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Rng(seed ^ 0x9E37_79B9_7F4A_7C15)
    }
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    pub fn f32(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 * (1.0 / (1u64 << 24) as f32)
    }
    pub fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.f32()
    }
    /// Uniform direction on the unit sphere.
    pub fn unit_vector(&mut self) -> [f32; 3] {
        let z = self.range(-1.0, 1.0);
        let phi = self.range(0.0, std::f32::consts::TAU);
        let r = (1.0 - z * z).max(0.0).sqrt();
        [r * phi.cos(), r * phi.sin(), z]
    }
}

/// Enables flush-to-zero and denormals-are-zero on the calling thread (Embree's
/// recommendation; applied to every library's threads that we own, alike).
pub fn set_ftz_daz() {
    #[cfg(target_arch = "x86_64")]
    unsafe {
        let mut csr: u32 = 0;
        std::arch::asm!("stmxcsr [{}]", in(reg) &mut csr, options(nostack));
        csr |= 0x8040; // FTZ (bit 15) | DAZ (bit 6)
        std::arch::asm!("ldmxcsr [{}]", in(reg) &csr, options(nostack));
    }
}

pub fn median(v: &mut [f64]) -> f64 {
    assert!(!v.is_empty());
    v.sort_by(|a, b| a.partial_cmp(b).unwrap());
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Runs `f` `warmup + reps` times; `f` returns the duration of its timed part (so that setup
/// and teardown inside it stay untimed). Returns the median of the last `reps`, in ms.
pub fn median_ms(warmup: usize, reps: usize, mut f: impl FnMut() -> Duration) -> f64 {
    for _ in 0..warmup {
        f();
    }
    let mut v: Vec<f64> = (0..reps.max(1)).map(|_| f().as_secs_f64() * 1e3).collect();
    median(&mut v)
}

pub fn time<R>(f: impl FnOnce() -> R) -> (R, Duration) {
    let t = Instant::now();
    let r = f();
    (r, t.elapsed())
}

/// A rayon pool of `n` threads with FTZ/DAZ set on each worker.
pub fn pool(n: usize) -> rayon::ThreadPool {
    rayon::ThreadPoolBuilder::new()
        .num_threads(n)
        .start_handler(|_| set_ftz_daz())
        .build()
        .expect("rayon pool")
}

pub fn available_threads() -> usize {
    std::thread::available_parallelism()
        .map(|n| n.get())
        .unwrap_or(1)
}

/// The processor and memory settings the run is on (Linux; "unknown" parts elsewhere): the model
/// name, its family, model and stepping (the name alone does not tell a lent Xeon's generation),
/// and the transparent huge page mode, which decides whether the applications' buffers are in
/// huge pages.
pub fn machine() -> String {
    let cpuinfo = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
    let field = |key: &str| {
        cpuinfo
            .lines()
            .take_while(|l| !l.trim().is_empty())
            .find_map(|l| {
                let (k, v) = l.split_once(':')?;
                (k.trim() == key).then(|| v.trim().to_string())
            })
    };
    let name = field("model name").unwrap_or_else(|| "unknown processor".into());
    let ids = match (field("cpu family"), field("model"), field("stepping")) {
        (Some(f), Some(m), Some(s)) => format!(" (family {f}, model {m}, stepping {s})"),
        _ => String::new(),
    };
    let thp = std::fs::read_to_string("/sys/kernel/mm/transparent_hugepage/enabled")
        .ok()
        .and_then(|t| {
            let start = t.find('[')?;
            let end = t[start..].find(']')? + start;
            Some(t[start + 1..end].to_string())
        })
        .unwrap_or_else(|| "unknown".into());
    format!("{name}{ids}, transparent huge pages {thp}")
}

/// What the Rust code (hostas, obvhs, this program) was compiled for: the `-C target-cpu` and
/// which of the x86 vector extensions that matter here it may use.
pub fn compiled_for() -> String {
    let features = [
        ("avx512vl", cfg!(target_feature = "avx512vl")),
        ("avx512f", cfg!(target_feature = "avx512f")),
        ("fma", cfg!(target_feature = "fma")),
        ("avx2", cfg!(target_feature = "avx2")),
        ("avx", cfg!(target_feature = "avx")),
        ("sse4.1", cfg!(target_feature = "sse4.1")),
    ];
    let on: Vec<&str> = features.iter().filter(|f| f.1).map(|f| f.0).collect();
    let listed = if on.is_empty() {
        let all: Vec<&str> = features.iter().map(|f| f.0).collect();
        format!("none of {}", all.join(", "))
    } else {
        on.join(", ")
    };
    format!("target-cpu {} ({listed})", env!("PEERS_TARGET_CPU"))
}

/// The 1-minute load average (Linux), to flag runs on a busy machine.
pub fn loadavg() -> Option<f64> {
    std::fs::read_to_string("/proc/loadavg")
        .ok()?
        .split_whitespace()
        .next()?
        .parse()
        .ok()
}

/// Where the 1-thread phases run: every library's 1-thread builds, refits and traces, and the
/// paired phase, on one CPU (as `taskset -c N` would pin a whole 1-thread run; see
/// `../shared/notes/perf-anchors.md`), so that the scheduler cannot move them between cores
/// in the middle of a timing. All-thread phases run with the process's original CPU set.
/// Threads inherit the mask of the thread that creates them, so pools and Embree devices
/// made inside either scope get its CPUs.
#[cfg(target_os = "linux")]
mod affinity {
    use std::sync::OnceLock;

    /// The process's CPU set at start and the CPU the 1-thread phases are pinned to.
    static SETS: OnceLock<(libc::cpu_set_t, Option<usize>)> = OnceLock::new();

    fn get() -> Option<libc::cpu_set_t> {
        // SAFETY: a zeroed cpu_set_t is a valid empty set; the size passed is its own.
        unsafe {
            let mut set: libc::cpu_set_t = std::mem::zeroed();
            (libc::sched_getaffinity(0, std::mem::size_of_val(&set), &mut set) == 0).then_some(set)
        }
    }

    fn set(set: &libc::cpu_set_t) {
        // SAFETY: `set` is a valid cpu_set_t of the size passed. A failure leaves the mask as
        // it was (the timing is then only less steady), so the result is not needed.
        unsafe {
            libc::sched_setaffinity(0, std::mem::size_of_val(set), set);
        }
    }

    /// Records the original set and picks the CPU (the one the calling thread is on, when
    /// it is in the set; `None` when pinning is off or unavailable).
    pub fn init(pin: bool) -> Option<usize> {
        let original = get()?;
        // SAFETY: sched_getcpu has no preconditions.
        let cpu = usize::try_from(unsafe { libc::sched_getcpu() }).ok();
        // SAFETY: CPU_ISSET reads a bit of a valid set (the index is checked against its size).
        let cpu = cpu.filter(|&c| {
            c < libc::CPU_SETSIZE as usize && unsafe { libc::CPU_ISSET(c, &original) }
        });
        SETS.get_or_init(|| (original, cpu.filter(|_| pin))).1
    }

    pub fn one_cpu() -> Option<libc::cpu_set_t> {
        let cpu = SETS.get()?.1?;
        // SAFETY: as in `get`; CPU_SET writes a bit below CPU_SETSIZE (checked in `init`).
        unsafe {
            let mut s: libc::cpu_set_t = std::mem::zeroed();
            libc::CPU_SET(cpu, &mut s);
            Some(s)
        }
    }

    pub fn original() -> Option<libc::cpu_set_t> {
        SETS.get().filter(|s| s.1.is_some()).map(|s| s.0)
    }

    /// Sets `to` (when there is one) until the guard drops, then restores the mask before.
    pub struct Guard(Option<libc::cpu_set_t>);

    pub fn scope(to: Option<libc::cpu_set_t>) -> Guard {
        let before = to.and_then(|to| {
            let before = get();
            set(&to);
            before
        });
        Guard(before)
    }

    impl Drop for Guard {
        fn drop(&mut self) {
            if let Some(before) = &self.0 {
                set(before);
            }
        }
    }
}

#[cfg(not(target_os = "linux"))]
mod affinity {
    pub fn init(_pin: bool) -> Option<usize> {
        None
    }
    pub struct Guard;
    impl Drop for Guard {
        fn drop(&mut self) {}
    }
    pub fn one_cpu() -> Option<()> {
        None
    }
    pub fn original() -> Option<()> {
        None
    }
    pub fn scope(_to: Option<()>) -> Guard {
        Guard
    }
}

/// Picks the CPU of the 1-thread phases (see `affinity`): the one the program starts on, or
/// none with `pin` false. Returns it, for the report.
pub fn init_pinning(pin: bool) -> Option<usize> {
    affinity::init(pin)
}

/// What the report says of the pinning [`init_pinning`] chose.
pub fn pinning_note(pin_cpu: Option<usize>) -> String {
    match pin_cpu {
        Some(c) => format!("1-thread phases pinned to CPU {c}"),
        None => "1-thread phases not pinned".to_string(),
    }
}

/// Runs the enclosing scope, until the guard drops, with `threads` threads' worth of CPUs:
/// the 1-thread phases' CPU for 1, the original set otherwise.
#[must_use]
pub fn cpus_for(threads: usize) -> impl Drop {
    if threads == 1 {
        affinity::scope(affinity::one_cpu())
    } else {
        affinity::scope(affinity::original())
    }
}
