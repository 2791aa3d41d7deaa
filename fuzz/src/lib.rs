//! hostas fuzz targets. The checks live in [`checks`] (shared with the regression test); this
//! crate adds the `arbitrary` glue for `cargo fuzz fmt` and the replay `main` of the
//! `replay` feature.

pub mod checks;
pub mod replay;

use arbitrary::{Arbitrary, Unstructured};

/// A `build_inputs` case decoded from bytes with the same decoder the target and the
/// regression test use, for `cargo fuzz fmt build_inputs <file>`.
#[derive(Debug)]
pub struct BuildCase(pub checks::build_inputs::Case);

impl<'a> Arbitrary<'a> for BuildCase {
    fn arbitrary(u: &mut Unstructured<'a>) -> arbitrary::Result<Self> {
        let bytes = u.bytes(u.len())?;
        Ok(BuildCase(checks::build_inputs::Case::decode(bytes)))
    }
    fn arbitrary_take_rest(u: Unstructured<'a>) -> arbitrary::Result<Self> {
        Ok(BuildCase(checks::build_inputs::Case::decode(u.take_rest())))
    }
}
