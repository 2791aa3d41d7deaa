//! The order in which a camera's rays are walked in packets: blocks of [`WIDE`] x [`HIGH`]
//! pixels, not the rows in which the camera writes them. Eight neighbours along a row fan out
//! over eight pixels' width and one's height; a block of 2 x 4 over two by four, so its rays
//! reach more of the same nodes and leaves. On the lent Xeon, the 1M-triangle soup's primary
//! rays fed in such blocks read 1.03-1.04x Embree MEDIUM against 0.84-0.94x fed row by row
//! (the thirty-fifth session's experiment, `docs/results/s35/`).
//!
//! Where packets seldom split in rows (the meshes' large triangles), blocks measured slower:
//! the tracer walks a camera's rows in blocks only where its packets split often
//! ([`super::packet::split_often`]).
//!
//! A batch is taken for a camera's rows where its rays share the first ray's origin and,
//! within a quarter of the batch, a ray's direction comes back next to the first ray's (the
//! pixel below it). The order is only the walk's: each ray's hit is the one it finds alone,
//! written at the ray's index.

use super::Ray;
use super::screen::{LANES, RootBox, Screened};

/// A block's width and height in pixels (a packet's eight rays).
const WIDE: usize = 2;
const HIGH: usize = 4;

/// The shortest row taken for a camera's (shorter ones are more likely rays that share an
/// origin by chance: a point's, in random directions).
const MIN_ROW: usize = 8;

/// The longest row looked for (the look costs a few instructions per ray of the row).
const MAX_ROW: usize = 4096;

/// A camera's rows, `width` long, in the order in which packets walk them: each band of
/// [`HIGH`] rows a block of [`WIDE`] x [`HIGH`] pixels at a time (each block's pixels row by
/// row), then the rays past the last whole band in their order. The rays are read where they
/// lie: copying them into this order and the hits back cost about 40 instructions a ray.
#[derive(Clone, Copy, Debug)]
pub(super) struct Blocks {
    /// Where each of a block's pixels lies from its top left one.
    offsets: [usize; LANES],
    width: usize,
    /// The end of the rays walked in blocks.
    banded: usize,
    /// The block walked, by its top left pixel, and the end of that pixel's row.
    block: usize,
    row_end: usize,
}

// (A block is what the screen takes at once.)
const _: () = assert!(WIDE * HIGH == LANES);

impl Blocks {
    /// The rays of a batch `len` long, a camera's rows `width` long; in the batch's order for
    /// a width that makes no blocks (zero or not a multiple of [`WIDE`]).
    pub(super) fn new(len: usize, width: usize) -> Blocks {
        let blocks = width > 0 && width.is_multiple_of(WIDE);
        let band = width.saturating_mul(HIGH);
        Blocks {
            offsets: std::array::from_fn(|k| k / WIDE * width + k % WIDE),
            width,
            banded: if blocks { len / band * band } else { 0 },
            block: 0,
            row_end: width,
        }
    }

    /// The batch's index of the ray at position `p` of the walk's order, asked for every
    /// position in turn (`p` = 0, 1, 2...).
    #[inline(always)]
    pub(super) fn index(&mut self, p: usize) -> usize {
        if p >= self.banded {
            return p;
        }
        let k = p % LANES;
        if k == 0 && p > 0 {
            self.block += WIDE;
            if self.block == self.row_end {
                // The band's end: the next band's first row.
                self.block += (HIGH - 1) * self.width;
                self.row_end = self.block + self.width;
            }
        }
        self.block + self.offsets[k]
    }

    /// Screens against `root` the [`LANES`] rays of `rays` (as many as there are) from
    /// position `p` of the walk's order, the last one asked for ([`Blocks::index`]), a
    /// multiple of [`LANES`].
    #[inline(always)]
    pub(super) fn screen(&self, root: &RootBox, rays: &[Ray], p: usize) -> Screened {
        if p >= self.banded {
            return root.screen(rays.get(p..).unwrap_or_default());
        }
        let Some(first) = rays.get(self.block) else {
            return Screened::default();
        };
        let ray = |k: usize| {
            rays.get(self.block + self.offsets[k % LANES])
                .unwrap_or(first)
        };
        root.screen_each(LANES, ray)
    }
}

/// The length of a camera's rows in `rays` (from its first ray, which may lie anywhere in
/// its row): where every ray up to there shares the first ray's origin and the direction
/// nearest the first ray's, past the directions of the rest of its row, lies about a pixel
/// away (at most twice as far as the first ray's neighbour's, squared four times: no more
/// oblong pixels). `None` where no such row of [`MIN_ROW`] to [`MAX_ROW`] rays, a multiple of
/// [`WIDE`], fits [`HIGH`] times in the batch.
pub(super) fn row_length(rays: &[Ray]) -> Option<usize> {
    let first = rays.first()?;
    let apart = |r: &Ray| {
        let (d, e) = (r.direction, first.direction);
        (0..3).map(|k| (d[k] - e[k]) * (d[k] - e[k])).sum::<f32>()
    };
    let step = apart(rays.get(1)?);
    // (Not a positive number: directions that do not fan out.)
    if !(step > 0.0) {
        return None;
    }
    let longest = (rays.len() / HIGH).min(MAX_ROW);
    let (mut last, mut back) = (step, false);
    for (k, r) in rays.iter().enumerate().take(longest + 2).skip(2) {
        if r.origin != first.origin {
            return None;
        }
        let now = apart(r);
        if now < last {
            // Past the row's end: coming back towards the first ray.
            back = true;
        } else if back {
            // Ray `k - 1` was the nearest: the pixel below the first.
            let width = k - 1;
            let square = last <= 4.0 * step;
            let fits = (MIN_ROW..=longest).contains(&width) && width.is_multiple_of(WIDE);
            return (square && fits).then_some(width);
        }
        last = now;
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A pinhole camera's `width` x `height` rays, row by row, from pixel `skip` on.
    fn camera(width: usize, height: usize, skip: usize) -> Vec<Ray> {
        (0..width * height)
            .skip(skip)
            .map(|p| {
                let (x, y) = ((p % width) as f32, (p / width) as f32);
                let d = [x - width as f32 / 2.0, height as f32 / 2.0 - y, -100.0];
                Ray::new([1.0, 2.0, 3.0], d)
            })
            .collect()
    }

    #[test]
    fn a_cameras_rows_are_found_from_any_pixel_of_a_row() {
        for skip in [0, 1, 7, 32, 63] {
            assert_eq!(
                row_length(&camera(64, 8, skip)),
                Some(64),
                "from pixel {skip}"
            );
        }
    }

    /// The indices `order` walks for a batch `len` long, position by position.
    fn walked(mut order: Blocks, len: usize) -> Vec<usize> {
        (0..len).map(|p| order.index(p)).collect()
    }

    #[test]
    fn blocks_of_two_by_four_then_the_rest_in_order() {
        let rays = camera(16, 9, 0);
        assert_eq!(row_length(&rays), Some(16));
        let order = walked(Blocks::new(144, 16), 144);
        assert_eq!(order[..8], [0, 1, 16, 17, 32, 33, 48, 49]);
        assert_eq!(order[8..16], [2, 3, 18, 19, 34, 35, 50, 51]);
        assert_eq!(order[56..64], [14, 15, 30, 31, 46, 47, 62, 63]);
        // The second band of four rows, then the ninth row as it came.
        assert_eq!(order[64..72], [64, 65, 80, 81, 96, 97, 112, 113]);
        assert_eq!(order[128..], (128..144).collect::<Vec<_>>());
    }

    #[test]
    fn every_ray_is_walked_once() {
        for (len, width) in [
            (0, 16),
            (5, 16),
            (63, 16),
            (64, 16),
            (1000, 8),
            (1024, 256),
            (1027, 2),
        ] {
            let mut each = walked(Blocks::new(len, width), len);
            each.sort_unstable();
            assert_eq!(each, (0..len).collect::<Vec<_>>(), "{len} x {width}");
        }
        // No blocks of a width they cannot be made of: the batch's order.
        for width in [0, 15] {
            let order = walked(Blocks::new(64, width), 64);
            assert_eq!(order, (0..64).collect::<Vec<_>>(), "width {width}");
        }
    }

    #[test]
    fn the_screen_takes_each_block() {
        // Boxes around points of some rays: the screen finds the others outside, lane by
        // lane in the walk's order (the first block's, then the ninth row's first eight).
        let rays = camera(16, 9, 0);
        let around = |some: &[usize]| {
            let mut lo = [f32::INFINITY; 3];
            let mut hi = [f32::NEG_INFINITY; 3];
            for &i in some {
                let r = &rays[i];
                for k in 0..3 {
                    let p = r.origin[k] + r.direction[k];
                    (lo[k], hi[k]) = (lo[k].min(p), hi[k].max(p));
                }
            }
            RootBox::around(lo, hi)
        };
        let mut order = Blocks::new(rays.len(), 16);
        order.index(0);
        assert_eq!(
            order.screen(&around(&[16, 17]), &rays, 0).outside,
            0b1111_0011
        );
        assert_eq!(order.screen(&around(&[49]), &rays, 0).outside, 0b0111_1111);
        for p in 1..=8 {
            order.index(p);
        }
        assert_eq!(order.screen(&around(&[2]), &rays, 8).outside, 0b1111_1110);
        for p in 9..=128 {
            order.index(p);
        }
        let row = around(&[130, 131, 132, 133, 134, 135]);
        assert_eq!(order.screen(&row, &rays, 128).outside, 0b0000_0011);
    }

    #[test]
    fn other_batches_are_no_cameras_rows() {
        // Too few rows for a band.
        assert_eq!(row_length(&camera(64, 3, 0)), None);
        // Rows too short, or odd.
        assert_eq!(row_length(&camera(4, 64, 0)), None);
        assert_eq!(row_length(&camera(63, 8, 0)), None);
        // Origins that differ.
        let mut rays = camera(64, 8, 0);
        rays[40].origin[0] += 1.0;
        assert_eq!(row_length(&rays), None);
        // One direction repeated.
        let same = vec![Ray::new([0.0; 3], [0.0, 0.0, -1.0]); 256];
        assert_eq!(row_length(&same), None);
        // Oblong pixels: rows more than twice as far apart as the pixels of a row.
        let oblong: Vec<Ray> = camera(64, 8, 0)
            .into_iter()
            .map(|mut r| {
                r.direction[1] *= 2.5;
                r
            })
            .collect();
        assert_eq!(row_length(&oblong), None);
    }
}
