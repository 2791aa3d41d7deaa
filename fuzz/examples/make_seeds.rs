//! Writes the seed corpora into `fuzz/corpus/<target>/`:
//!
//! * `deserialize`: real structures serialized by hostas (triangle BLASes indexed and not,
//!   with a transform, several geometries, each build preset; an AABB BLAS with ALLOW_UPDATE; an
//!   empty BLAS; a TLAS with active and inactive instances).
//! * `build_inputs`: random byte strings whose decoded case builds something (a triangle BLAS,
//!   an AABB BLAS, a TLAS, an update), so that fuzzing starts past the validation layer.
//! * `ray_query`: a few scene seeds and decision streams.
//!
//! `cargo run --release --no-default-features --features replay --example make_seeds`

use hostas_fuzz::checks::build_inputs::{Case, run_case};
use std::path::Path;

fn write(dir: &Path, name: &str, bytes: &[u8]) {
    std::fs::create_dir_all(dir).unwrap();
    std::fs::write(dir.join(name), bytes).unwrap();
    println!("{}/{name}: {} bytes", dir.display(), bytes.len());
}

fn main() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("corpus");

    for (name, bytes) in hostas_fuzz::checks::seeds::deserialize_seeds() {
        write(&root.join("deserialize"), &name, &bytes);
    }

    // build_inputs: random inputs whose cases build something of each kind.
    let dir = root.join("build_inputs");
    let mut lcg = 0x2545_f491_4f6c_dd1du64;
    let mut want = [("blas", 3usize), ("tlas", 2), ("update", 2)];
    let mut tries = 0;
    while want.iter().any(|(_, n)| *n > 0) && tries < 200_000 {
        tries += 1;
        let len = 16 + (lcg % 400) as usize;
        let bytes: Vec<u8> = (0..len)
            .map(|_| {
                lcg ^= lcg << 13;
                lcg ^= lcg >> 7;
                lcg ^= lcg << 17;
                (lcg >> 24) as u8
            })
            .collect();
        let case = Case::decode(&bytes);
        let out = run_case(&case);
        let kind = if out.updated > 0 {
            2
        } else if out.built_tlas > 0 {
            1
        } else if out.built_blas > 0 {
            0
        } else {
            continue;
        };
        if want[kind].1 > 0 {
            want[kind].1 -= 1;
            write(&dir, &format!("{}-{}", want[kind].0, want[kind].1), &bytes);
        }
    }
    println!("build_inputs: {tries} random inputs tried");

    for (name, bytes) in hostas_fuzz::checks::seeds::ray_query_seeds() {
        write(&root.join("ray_query"), &name, &bytes);
    }
}
