//! `ray_query` target: see `src/checks/ray_query.rs`.
#![cfg_attr(not(feature = "replay"), no_main)]

#[cfg(not(feature = "replay"))]
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    hostas_fuzz::checks::ray_query::run(data);
});

#[cfg(feature = "replay")]
fn main() {
    hostas_fuzz::replay::main("ray_query", hostas_fuzz::checks::ray_query::run);
}
