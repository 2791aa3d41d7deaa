//! The Vulkan host commands, as methods of [`crate::Device`]: each validates its input, locks
//! the memory it touches, and calls the builders, encoder or traversal.

pub mod build;
pub mod copy;
mod refit;
mod validate;

pub use build::BuildSizes;
pub use copy::SerializedHeader;

use crate::device::{AsObject, Device};
use crate::error::{Error, Result};

impl Device {
    /// Runs `f` with the destination bytes (write-locked) and, when given, the source bytes
    /// (read-locked; the same lock when both live in one buffer). `None` is passed as source
    /// when `src` is the destination itself.
    pub(crate) fn with_dst_src<R>(
        &self,
        dst: &AsObject,
        src: Option<&AsObject>,
        at: crate::error::Location,
        f: impl FnOnce(&mut [u8], Option<&[u8]>) -> Result<R>,
    ) -> Result<R> {
        let dmem = dst.buffer.memory().ok_or_else(|| {
            Error::vuid(
                "VUID-vkBuildAccelerationStructuresKHR-pInfos-03722",
                at,
                format!(
                    "the buffer of acceleration structure {:#x} has no memory bound",
                    dst.handle
                ),
            )
        })?;
        let src = src.filter(|s| s.handle != dst.handle);
        match src {
            None => {
                let mut g = dmem
                    .try_write()
                    .ok_or(Error::InUse { handle: dst.handle })?;
                let range = dst.offset as usize..(dst.offset + dst.size) as usize;
                f(&mut g.bytes_mut()[range], None)
            }
            Some(s) => {
                let smem = s.buffer.memory().ok_or_else(|| {
                    Error::vuid(
                        "VUID-vkBuildAccelerationStructuresKHR-pInfos-03723",
                        at,
                        format!(
                            "the buffer of acceleration structure {:#x} has no memory bound",
                            s.handle
                        ),
                    )
                })?;
                if std::sync::Arc::ptr_eq(&dmem, &smem) {
                    let mut g = dmem
                        .try_write()
                        .ok_or(Error::InUse { handle: dst.handle })?;
                    let bytes = g.bytes_mut();
                    let (d0, d1) = (dst.offset as usize, (dst.offset + dst.size) as usize);
                    let (s0, s1) = (s.offset as usize, (s.offset + s.size) as usize);
                    if d0 < s1 && s0 < d1 {
                        return Err(Error::vuid(
                            "VUID-vkBuildAccelerationStructuresKHR-pInfos-03668",
                            at,
                            "source and destination memory overlap but are not the same structure",
                        ));
                    }
                    if d0 < s0 {
                        let (a, b) = bytes.split_at_mut(s0);
                        f(&mut a[d0..d1], Some(&b[..s1 - s0]))
                    } else {
                        let (a, b) = bytes.split_at_mut(d0);
                        f(&mut b[..d1 - d0], Some(&a[s0..s1]))
                    }
                } else {
                    let sg = smem.try_read().ok_or(Error::InUse { handle: s.handle })?;
                    let mut dg = dmem
                        .try_write()
                        .ok_or(Error::InUse { handle: dst.handle })?;
                    f(
                        &mut dg.bytes_mut()[dst.offset as usize..(dst.offset + dst.size) as usize],
                        Some(&sg.bytes()[s.offset as usize..(s.offset + s.size) as usize]),
                    )
                }
            }
        }
    }
}
