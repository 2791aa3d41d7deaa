//! A small, dependency-free byte decoder: the structure-aware targets read their inputs through
//! it, so that the fuzz crate (libFuzzer, `arbitrary`) and the regression test in
//! `crates/hostas/tests/fuzz_regressions.rs` (no extra dependencies) decode a corpus file into
//! exactly the same case. Reads past the end return zeros, so every byte string is a valid
//! input and short inputs decode to small, simple cases.

pub struct Source<'a> {
    data: &'a [u8],
    pos: usize,
}

impl<'a> Source<'a> {
    pub fn new(data: &'a [u8]) -> Self {
        Source { data, pos: 0 }
    }

    pub fn is_empty(&self) -> bool {
        self.pos >= self.data.len()
    }

    pub fn u8(&mut self) -> u8 {
        let v = self.data.get(self.pos).copied().unwrap_or(0);
        self.pos = self.pos.saturating_add(1);
        v
    }

    pub fn u16(&mut self) -> u16 {
        u16::from_le_bytes([self.u8(), self.u8()])
    }

    pub fn u32(&mut self) -> u32 {
        u32::from_le_bytes([self.u8(), self.u8(), self.u8(), self.u8()])
    }

    pub fn u64(&mut self) -> u64 {
        (self.u32() as u64) | (self.u32() as u64) << 32
    }

    pub fn bool(&mut self) -> bool {
        self.u8() & 1 == 1
    }

    /// A value in `0..n` (`n > 0`), from one byte when `n <= 256`.
    pub fn below(&mut self, n: u32) -> u32 {
        debug_assert!(n > 0);
        if n <= 256 {
            self.u8() as u32 % n
        } else {
            self.u32() % n
        }
    }

    /// `true` with probability about `num / 256`.
    pub fn chance(&mut self, num: u8) -> bool {
        self.u8() < num
    }

    pub fn choose<T: Copy>(&mut self, items: &[T]) -> T {
        items[self.below(items.len() as u32) as usize]
    }

    /// Up to `len` raw bytes (fewer when the input runs out).
    pub fn bytes(&mut self, len: usize) -> &'a [u8] {
        let start = self.pos.min(self.data.len());
        let end = start.saturating_add(len).min(self.data.len());
        self.pos = self.pos.saturating_add(len);
        &self.data[start..end]
    }

    /// A float that is often a boundary value (0, ±1, NaN, ±inf, huge, tiny, subnormal).
    pub fn f32(&mut self) -> f32 {
        match self.u8() % 16 {
            0 => 0.0,
            1 => 1.0,
            2 => -1.0,
            3 => f32::NAN,
            4 => f32::INFINITY,
            5 => f32::NEG_INFINITY,
            6 => f32::MAX,
            7 => f32::MIN_POSITIVE,
            8 => f32::from_bits(1),
            9 => -0.0,
            10 => 1e30,
            11 => f32::from_bits(self.u32()),
            _ => (self.u16() as i16) as f32 / 256.0,
        }
    }

    /// A float in a moderate range, mostly finite: coordinates of "reasonable" geometry.
    pub fn coord(&mut self) -> f32 {
        match self.u8() % 32 {
            0 => self.f32(),
            _ => (self.u16() as i16) as f32 / 1024.0,
        }
    }

    /// A 32-bit count or size that is often small, sometimes a boundary value.
    pub fn count(&mut self, small: u32) -> u32 {
        match self.u8() % 16 {
            0 => u32::MAX,
            1 => 1 << 24,
            2 => (1 << 24) + 1,
            3 => (1 << 29) - 1,
            4 => 1 << 29,
            5 => 1 << 31,
            6 => self.u32(),
            _ => self.below(small.max(1) + 1),
        }
    }
}
