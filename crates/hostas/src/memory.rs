//! Host memory and buffers: where acceleration structures live.
//!
//! A [`Buffer`] is the `VkBuffer` an acceleration structure is created in; its memory may be
//! bound after the structure is created (as in Vulkan). Memory is 64-byte aligned so that the
//! layout's sections can be viewed as typed slices. The application reads and writes buffer
//! memory with [`Buffer::read`] and [`Buffer::write`], as it would through a mapping.

use crate::error::{Error, Result};
use bytemuck::{Pod, Zeroable};
use parking_lot::{Mutex, RwLock};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

#[derive(Clone, Copy, Pod, Zeroable)]
#[repr(C, align(64))]
pub(crate) struct Block([u8; 64]);

/// Regions at least this large are mapped from the OS and advised to use huge pages.
const MAPPED_MIN: usize = 2 << 20;
/// The transparent huge page size of x86-64 and most aarch64 kernels.
const HUGE_PAGE: usize = 2 << 20;

/// Where the bytes of a [`HostMemory`] live.
enum Pages {
    /// Small regions: the allocator's (64-byte aligned) memory.
    Heap(Box<[Block]>),
    /// Large regions: an anonymous mapping (zero filled by the OS), with a
    /// transparent-huge-page hint on Linux. A structure over a million triangles spans about
    /// 50 MB; with 4 KiB pages, incoherent rays, refits and builds miss the TLB on nearly
    /// every node (measured on the 1M sphere: +30% build, +45% trace with huge pages).
    /// Embree advises its large allocations the same way. The bytes start at a 2 MiB boundary
    /// of the mapping (`start`) and the mapping extends to one, so that every part of them
    /// can be a huge page, wherever the OS placed the mapping.
    Mapped { map: memmap2::MmapMut, start: usize },
}

/// Host memory: what a buffer is bound to ([`HostMemory::allocate`]: contents undefined, as
/// after `vkAllocateMemory`), and what the convenience calls and benchmarks use for scratch
/// ([`HostMemory::zeroed`]).
pub struct HostMemory {
    pages: Pages,
    len: usize,
}

/// A 64-byte aligned copy of `bytes` (for validating untrusted data as typed sections).
pub(crate) fn aligned_copy(bytes: &[u8]) -> Result<HostMemory> {
    let mut m = HostMemory::zeroed(bytes.len())?;
    m.bytes_mut().copy_from_slice(bytes);
    Ok(m)
}

impl HostMemory {
    /// `len` zero bytes, at least 64-byte aligned.
    pub fn zeroed(len: usize) -> Result<HostMemory> {
        HostMemory::new(len, true)
    }

    /// `len` bytes, at least 64-byte aligned, whose contents are undefined as after
    /// `vkAllocateMemory`: zeros, or (a mapping kept from memory dropped in the last seconds)
    /// what this process last wrote there. Builds do not depend on what their memory held
    /// (the encoder writes every byte of the structure, its gaps included), so a buffer's
    /// memory is not zeroed again: a 70k-triangle fast build would write its structure's
    /// megabytes twice.
    pub fn allocate(len: usize) -> Result<HostMemory> {
        HostMemory::new(len, false)
    }

    fn new(len: usize, zero: bool) -> Result<HostMemory> {
        let oom = || Error::OutOfHostMemory(format!("{len} bytes could not be allocated"));
        let pages = if len >= MAPPED_MIN {
            // Room to start at a huge-page boundary and to end at one (only touched pages
            // take memory; the tail of the last huge page is at most 2 MiB).
            let span = len.div_ceil(HUGE_PAGE) * HUGE_PAGE + HUGE_PAGE;
            let (mut map, reused) = match spare::take(span) {
                Some(map) => (map, true),
                None => {
                    let map = memmap2::MmapMut::map_anon(span).map_err(|_| oom())?;
                    #[cfg(target_os = "linux")]
                    {
                        // Only a hint: where the kernel has no huge pages it keeps small ones.
                        let _ = map.advise(memmap2::Advice::HugePage);
                    }
                    (map, false)
                }
            };
            let start = map.as_ptr().align_offset(HUGE_PAGE);
            if reused && zero {
                // Fresh pages are zero already; kept ones are zeroed where handed out.
                map[start..start + len].fill(0);
            }
            Pages::Mapped { map, start }
        } else {
            // Zeroed by the allocator (fresh pages from the OS are zero already), not by a
            // memset.
            Pages::Heap(
                bytemuck::allocation::try_zeroed_slice_box::<Block>(len.div_ceil(64))
                    .map_err(|()| oom())?,
            )
        };
        Ok(HostMemory { pages, len })
    }
    pub fn len(&self) -> usize {
        self.len
    }
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }
    pub fn bytes(&self) -> &[u8] {
        match &self.pages {
            Pages::Heap(b) => &bytemuck::cast_slice(b)[..self.len],
            Pages::Mapped { map, start } => &map[*start..*start + self.len],
        }
    }
    pub fn bytes_mut(&mut self) -> &mut [u8] {
        match &mut self.pages {
            Pages::Heap(b) => &mut bytemuck::cast_slice_mut(b)[..self.len],
            Pages::Mapped { map, start } => &mut map[*start..*start + self.len],
        }
    }
}

impl Drop for HostMemory {
    fn drop(&mut self) {
        // An empty heap slice allocates nothing.
        let empty = Pages::Heap(Box::default());
        if let Pages::Mapped { map, .. } = std::mem::replace(&mut self.pages, empty) {
            spare::keep(map);
        }
    }
}

/// The most freed memory kept for later allocations: by [`spare`] in all, and by
/// `quick::build` for its scratch (a 9M-triangle build's).
pub(crate) const KEPT_MAX: usize = 1 << 30;

/// Mappings of dropped memory, kept for the next allocations of about their size (as
/// allocators such as jemalloc keep freed pages for a while): an application that destroys a
/// structure and builds the next one would otherwise have the OS fault in and zero fresh pages
/// for every build (and, with huge pages, sometimes compact memory to find them), where
/// zeroing pages it has is one `memset`. On a 2-core VM, fresh pages made a 70k-triangle
/// fast build 2.6 to 30 ms, depending on what else the process had freed.
mod spare {
    use parking_lot::Mutex;
    use std::time::{Duration, Instant};

    /// At most this many bytes are kept, in at most [`COUNT`] mappings, each for at most
    /// [`AGE`] (returned to the OS at the next allocation or drop after that). A structure of
    /// 3.5M triangles spans about 260 MiB before compaction; with a limit of 256 MiB here
    /// (and for `quick`'s scratch) its builds faulted in fresh pages every time, and the
    /// crown's builds ran at 0.94x (fast trace) and 0.83x (fast build) of their speed now on
    /// the Xeon.
    const BYTES: usize = super::KEPT_MAX;
    const COUNT: usize = 8;
    const AGE: Duration = Duration::from_secs(2);

    static KEPT: Mutex<Vec<(Instant, memmap2::MmapMut)>> = Mutex::new(Vec::new());

    /// Unmaps what has been kept longer than [`AGE`], and the oldest beyond the limits.
    fn trim(kept: &mut Vec<(Instant, memmap2::MmapMut)>, now: Instant) {
        kept.retain(|(at, _)| now.duration_since(*at) < AGE);
        while kept.len() > COUNT || kept.iter().map(|(_, m)| m.len()).sum::<usize>() > BYTES {
            kept.remove(0);
        }
    }

    /// The smallest kept mapping of at least `span` bytes and at most twice that.
    pub(super) fn take(span: usize) -> Option<memmap2::MmapMut> {
        let mut kept = KEPT.lock();
        trim(&mut kept, Instant::now());
        let best = (0..kept.len())
            .filter(|&i| (span..=2 * span).contains(&kept[i].1.len()))
            .min_by_key(|&i| kept[i].1.len())?;
        Some(kept.remove(best).1)
    }

    /// Keeps `map` for [`take`] (the oldest mappings make way).
    pub(super) fn keep(map: memmap2::MmapMut) {
        if map.len() > BYTES {
            return;
        }
        let now = Instant::now();
        let mut kept = KEPT.lock();
        kept.push((now, map));
        trim(&mut kept, now);
    }
}

pub(crate) type MemoryRef = Arc<RwLock<HostMemory>>;

static NEXT_BUFFER_ID: AtomicU64 = AtomicU64::new(1);

struct BufferInner {
    id: u64,
    size: u64,
    memory: Mutex<Option<MemoryRef>>,
}

/// A buffer that acceleration structures are placed in (`VkBuffer` with
/// `ACCELERATION_STRUCTURE_STORAGE` usage, bound to host-visible memory).
#[derive(Clone)]
pub struct Buffer {
    inner: Arc<BufferInner>,
}

impl std::fmt::Debug for Buffer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Buffer")
            .field("id", &self.inner.id)
            .field("size", &self.inner.size)
            .finish()
    }
}

impl Buffer {
    /// A buffer of `size` bytes with no memory bound yet.
    pub fn new_unbound(size: u64) -> Buffer {
        Buffer {
            inner: Arc::new(BufferInner {
                id: NEXT_BUFFER_ID.fetch_add(1, Ordering::Relaxed),
                size,
                memory: Mutex::new(None),
            }),
        }
    }
    /// A buffer of `size` bytes with host memory bound (see [`Buffer::bind_memory`]).
    pub fn new(size: u64) -> Result<Buffer> {
        let b = Buffer::new_unbound(size);
        b.bind_memory()?;
        Ok(b)
    }
    /// Binds host memory (`vkBindBufferMemory`), whose contents are undefined
    /// ([`HostMemory::allocate`]). Binding twice is an error.
    pub fn bind_memory(&self) -> Result<()> {
        let mut m = self.inner.memory.lock();
        if m.is_some() {
            return Err(Error::vuid(
                "VUID-vkBindBufferMemory-buffer-07459",
                Default::default(),
                "buffer already has memory bound",
            ));
        }
        let len = usize::try_from(self.inner.size)
            .map_err(|_| Error::OutOfHostMemory(format!("{} bytes", self.inner.size)))?;
        *m = Some(Arc::new(RwLock::new(HostMemory::allocate(len)?)));
        Ok(())
    }
    pub fn size(&self) -> u64 {
        self.inner.size
    }
    pub fn id(&self) -> u64 {
        self.inner.id
    }
    pub(crate) fn memory(&self) -> Option<MemoryRef> {
        self.inner.memory.lock().clone()
    }
    fn range(&self, offset: u64, len: usize) -> Result<std::ops::Range<usize>> {
        let end = offset
            .checked_add(len as u64)
            .filter(|&e| e <= self.inner.size);
        match end {
            Some(e) => Ok(offset as usize..e as usize),
            None => Err(Error::RangeTooShort {
                what: "buffer",
                needed: offset.saturating_add(len as u64),
                available: self.inner.size,
                location: Default::default(),
            }),
        }
    }
    /// Copies bytes out of the buffer's memory.
    pub fn read(&self, offset: u64, out: &mut [u8]) -> Result<()> {
        let mem = self
            .memory()
            .ok_or_else(|| Error::NotSupported("buffer has no memory bound".into()))?;
        let r = self.range(offset, out.len())?;
        let guard = mem.try_read().ok_or(Error::InUse {
            handle: self.inner.id,
        })?;
        out.copy_from_slice(&guard.bytes()[r]);
        Ok(())
    }
    /// Copies bytes into the buffer's memory.
    pub fn write(&self, offset: u64, data: &[u8]) -> Result<()> {
        let mem = self
            .memory()
            .ok_or_else(|| Error::NotSupported("buffer has no memory bound".into()))?;
        let r = self.range(offset, data.len())?;
        let mut guard = mem.try_write().ok_or(Error::InUse {
            handle: self.inner.id,
        })?;
        guard.bytes_mut()[r].copy_from_slice(data);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn small_and_mapped_memory_are_zeroed_aligned_and_writable() {
        for len in [
            0,
            1,
            4096 + 3,
            MAPPED_MIN - 1,
            MAPPED_MIN,
            3 * MAPPED_MIN + 5,
        ] {
            let mut m = HostMemory::zeroed(len).unwrap();
            assert_eq!(m.len(), len);
            assert_eq!(m.bytes().len(), len);
            assert!(m.bytes().iter().all(|&b| b == 0), "len {len}");
            assert_eq!(m.bytes().as_ptr() as usize % 64, 0, "len {len}");
            if len >= MAPPED_MIN {
                assert_eq!(m.bytes().as_ptr() as usize % HUGE_PAGE, 0, "len {len}");
            }
            if len > 0 {
                m.bytes_mut()[len - 1] = 7;
                assert_eq!(m.bytes()[len - 1], 7);
            }
            let copy = aligned_copy(m.bytes()).unwrap();
            assert_eq!(copy.bytes(), m.bytes());
        }
    }

    #[test]
    fn reused_mappings_are_zeroed_again() {
        let len = 3 * MAPPED_MIN + 5;
        for _ in 0..4 {
            let mut m = HostMemory::zeroed(len).unwrap();
            assert!(m.bytes().iter().all(|&b| b == 0));
            assert_eq!(m.bytes().as_ptr() as usize % HUGE_PAGE, 0);
            m.bytes_mut().fill(0xa5);
            let mut smaller = HostMemory::zeroed(len - MAPPED_MIN).unwrap();
            assert!(smaller.bytes().iter().all(|&b| b == 0));
            smaller.bytes_mut().fill(0x5a);
        }
    }

    #[test]
    fn a_large_structures_memory_is_kept_for_the_next_allocation() {
        // A 3.5M-triangle structure's size before compaction: over the 256 MiB once kept,
        // so that every build of the crown faulted in fresh pages. Only the marked page takes
        // memory. A fresh mapping (the OS may place it at the same address) would read zero
        // where this one was marked. (Only eight other drops between these lines could evict
        // it from the spares.)
        let len = 258 << 20;
        let mut m = HostMemory::allocate(len).unwrap();
        m.bytes_mut()[len - 1] = 0x5a;
        drop(m);
        let again = HostMemory::allocate(len).unwrap();
        assert_eq!(
            again.bytes()[len - 1],
            0x5a,
            "the dropped mapping was not kept"
        );
    }

    #[test]
    fn allocated_memory_is_aligned_and_writable_and_may_be_reused_as_it_is() {
        let len = 3 * MAPPED_MIN + 5;
        let mut m = HostMemory::allocate(len).unwrap();
        assert_eq!(m.bytes().len(), len);
        assert_eq!(m.bytes().as_ptr() as usize % HUGE_PAGE, 0);
        m.bytes_mut().fill(0xa5);
        drop(m);
        // A zeroed allocation never sees what an allocated one held.
        let z = HostMemory::zeroed(len).unwrap();
        assert!(z.bytes().iter().all(|&b| b == 0));
        drop(z);
        let mut a = HostMemory::allocate(len - 7).unwrap();
        assert_eq!(a.bytes().len(), len - 7);
        a.bytes_mut()[len - 8] = 1;
        assert_eq!(a.bytes()[len - 8], 1);
    }
}
