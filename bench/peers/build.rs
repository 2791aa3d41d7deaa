//! Compiles `shim/tb_shim.cpp`: a small C++ shim over the `tiny_bvh.h` header that tinybvh-rs
//! bundles (same version, 1.6.8), with the namespace renamed so it links beside tinybvh-rs.
//! tinybvh-rs exposes neither BuildAVX nor thread control; the shim does.

use std::path::{Path, PathBuf};

const TINYBVH_RS_DIR: &str = "tinybvh-rs-0.1.0-beta.3";

fn find_header() -> PathBuf {
    if let Ok(p) = std::env::var("TINYBVH_HEADER") {
        return PathBuf::from(p);
    }
    let mut homes = Vec::new();
    if let Ok(h) = std::env::var("CARGO_HOME") {
        homes.push(PathBuf::from(h));
    }
    if let Ok(h) = std::env::var("HOME") {
        homes.push(Path::new(&h).join(".cargo"));
    }
    for home in homes {
        let src = home.join("registry").join("src");
        let Ok(entries) = std::fs::read_dir(&src) else {
            continue;
        };
        for e in entries.flatten() {
            let cand = e.path().join(TINYBVH_RS_DIR).join("ffi/tinybvh/tiny_bvh.h");
            if cand.exists() {
                return cand;
            }
        }
    }
    panic!(
        "could not find {TINYBVH_RS_DIR}/ffi/tinybvh/tiny_bvh.h in the cargo registry; \
         run `cargo fetch` or set TINYBVH_HEADER=/path/to/tiny_bvh.h"
    );
}

/// The `-C target-cpu` the Rust code is built for (the last one in the flags; "generic" when
/// none), so that the report says what code it measured.
fn target_cpu() -> String {
    // Each flag is one element: `-Ctarget-cpu=X`, or `-C` then `target-cpu=X`; the last wins.
    let flags = std::env::var("CARGO_ENCODED_RUSTFLAGS").unwrap_or_default();
    flags
        .split('\x1f')
        .filter_map(|f| f.trim_start_matches("-C").strip_prefix("target-cpu="))
        .next_back()
        .unwrap_or("generic")
        .to_string()
}

fn main() {
    println!("cargo:rerun-if-env-changed=CARGO_ENCODED_RUSTFLAGS");
    println!("cargo:rustc-env=PEERS_TARGET_CPU={}", target_cpu());
    let header = find_header();
    let include_dir = header.parent().unwrap().to_path_buf();
    println!("cargo:rerun-if-changed=shim/tb_shim.cpp");
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-env-changed=TINYBVH_HEADER");
    println!("cargo:rerun-if-changed={}", header.display());
    cc::Build::new()
        .cpp(true)
        .file("shim/tb_shim.cpp")
        .include(&include_dir)
        .std("c++20")
        .flag("-march=native") // same as tinybvh-rs's own build and `-C target-cpu=native`
        .flag("-O3")
        .flag_if_supported("-Wno-unused-parameter")
        .flag_if_supported("-Wno-unused-variable")
        .flag_if_supported("-Wno-class-memaccess")
        .flag_if_supported("-Wno-missing-field-initializers")
        .flag_if_supported("-Wno-sign-compare")
        .flag_if_supported("-Wno-unused-but-set-variable")
        .flag_if_supported("-Wno-maybe-uninitialized")
        .warnings(false)
        .compile("tb_shim");
}
