//! The `main` of the targets without libFuzzer (feature `replay`): replays files and
//! directories, or runs the target on random inputs for a while.
//!
//! ```text
//! <target> [PATH...]                 replay each file (directories: every file inside)
//! <target> --random SECONDS [SEED]   random inputs (mutated corpus files when a PATH is given)
//! ```
//! A panic prints the input's path (or, in random mode, saves it to
//! `fuzz/artifacts/<target>/crash-<hash>`) and exits with status 101.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

fn files(paths: &[PathBuf]) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for p in paths {
        if p.is_dir() {
            let mut v: Vec<PathBuf> = std::fs::read_dir(p)
                .map(|d| {
                    d.filter_map(|e| e.ok().map(|e| e.path()))
                        .filter(|p| p.is_file())
                        .collect()
                })
                .unwrap_or_default();
            v.sort();
            out.extend(v);
        } else if p.is_file() {
            out.push(p.clone());
        }
    }
    out
}

fn hash(b: &[u8]) -> u64 {
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    for &x in b {
        h ^= x as u64;
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        // splitmix64
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

/// A random input: fresh bytes, or a corpus file with a few byte-level mutations.
fn mutate(r: &mut Rng, seeds: &[Vec<u8>]) -> Vec<u8> {
    if seeds.is_empty() || r.below(4) == 0 {
        let len = r.below(512);
        return (0..len).map(|_| r.next() as u8).collect();
    }
    let mut b = seeds[r.below(seeds.len())].clone();
    for _ in 0..1 + r.below(8) {
        match r.below(7) {
            0 if !b.is_empty() => {
                let i = r.below(b.len());
                b[i] = r.next() as u8;
            }
            1 if !b.is_empty() => {
                let i = r.below(b.len());
                b[i] ^= 1 << r.below(8);
            }
            2 if b.len() >= 4 => {
                let i = r.below(b.len() - 3);
                let v: u32 = [
                    0,
                    1,
                    u32::MAX,
                    0x8000_0000,
                    0x7fff_ffff,
                    64,
                    256,
                    r.next() as u32,
                ][r.below(8)];
                b[i..i + 4].copy_from_slice(&v.to_le_bytes());
            }
            3 if b.len() >= 8 => {
                let i = r.below(b.len() - 7);
                b[i..i + 8].copy_from_slice(&r.next().to_le_bytes());
            }
            4 => {
                let n = r.below(b.len() + 1);
                b.truncate(n);
            }
            5 => {
                let i = r.below(b.len() + 1);
                let n = r.below(16);
                let ins: Vec<u8> = (0..n).map(|_| r.next() as u8).collect();
                b.splice(i..i, ins);
            }
            _ if b.len() >= 2 => {
                // Copy a chunk from elsewhere (repeats structure).
                let n = 1 + r.below(32.min(b.len() / 2));
                let from = r.below(b.len() - n + 1);
                let to = r.below(b.len() - n + 1);
                let chunk = b[from..from + n].to_vec();
                b[to..to + n].copy_from_slice(&chunk);
            }
            _ => {}
        }
    }
    b
}

pub fn main(target: &str, f: fn(&[u8])) {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if let Some(pos) = args.iter().position(|a| a == "--random") {
        let secs: f64 = args
            .get(pos + 1)
            .and_then(|s| s.parse().ok())
            .unwrap_or(60.0);
        let seed: u64 = args.get(pos + 2).and_then(|s| s.parse().ok()).unwrap_or(1);
        let paths: Vec<PathBuf> = args
            .iter()
            .enumerate()
            .filter(|(i, _)| *i < pos || *i > pos + 2)
            .map(|(_, a)| PathBuf::from(a))
            .collect();
        let seeds: Vec<Vec<u8>> = files(&paths)
            .iter()
            .filter_map(|p| std::fs::read(p).ok())
            .collect();
        let mut r = Rng(seed);
        let start = Instant::now();
        let mut n = 0u64;
        let mut last_report = Instant::now();
        while start.elapsed() < Duration::from_secs_f64(secs) {
            let input = mutate(&mut r, &seeds);
            let res = std::panic::catch_unwind(|| f(&input));
            n += 1;
            if res.is_err() {
                let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
                    .join("artifacts")
                    .join(target);
                let _ = std::fs::create_dir_all(&dir);
                let path = dir.join(format!("crash-{:016x}", hash(&input)));
                let _ = std::fs::write(&path, &input);
                eprintln!(
                    "{target}: crash after {n} inputs; input saved to {}",
                    path.display()
                );
                std::process::exit(101);
            }
            if last_report.elapsed() > Duration::from_secs(30) {
                eprintln!(
                    "{target}: {n} inputs, {:.0} s",
                    start.elapsed().as_secs_f64()
                );
                last_report = Instant::now();
            }
        }
        eprintln!(
            "{target}: {n} random inputs in {:.1} s, no crash",
            start.elapsed().as_secs_f64()
        );
        return;
    }
    let list = files(&args.iter().map(PathBuf::from).collect::<Vec<_>>());
    for p in &list {
        let data = std::fs::read(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
        eprintln!("{target}: {}", p.display());
        f(&data);
    }
    eprintln!("{target}: replayed {} file(s)", list.len());
}
