//! `deserialize` target: see `src/checks/deserialize.rs`.
#![cfg_attr(not(feature = "replay"), no_main)]

#[cfg(not(feature = "replay"))]
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    hostas_fuzz::checks::deserialize::run(data);
});

#[cfg(feature = "replay")]
fn main() {
    hostas_fuzz::replay::main("deserialize", hostas_fuzz::checks::deserialize::run);
}
