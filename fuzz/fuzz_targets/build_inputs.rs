//! `build_inputs` target: see `src/checks/build_inputs.rs`. The input is decoded by
//! `Case::decode` (through `BuildCase`'s `Arbitrary` impl, so that `cargo fuzz fmt` prints it).
#![cfg_attr(not(feature = "replay"), no_main)]

#[cfg(not(feature = "replay"))]
libfuzzer_sys::fuzz_target!(|case: hostas_fuzz::BuildCase| {
    hostas_fuzz::checks::build_inputs::run_case(&case.0);
});

#[cfg(feature = "replay")]
fn main() {
    hostas_fuzz::replay::main("build_inputs", hostas_fuzz::checks::build_inputs::run);
}
