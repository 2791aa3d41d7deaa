//! The C ABI of hostas, with the Vulkan command signatures (`hostas_BuildAccelerationStructuresKHR`
//! and so on). Not implemented yet: this crate reserves the place where, as the design brief
//! says, the only `extern "C"` and `unsafe` code will live (raw Vulkan structs and host addresses
//! decoded once into the core's slices, panics caught at the boundary). Until then, use the
//! safe Rust API of the `hostas` crate.
#![deny(unsafe_op_in_unsafe_fn)]

/// Whether this build exports the C entry points (it does not yet).
pub const C_ABI_AVAILABLE: bool = false;
