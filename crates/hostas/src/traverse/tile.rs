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
//! pixel below it). The order is only the walk's: each ray's hit is the one it finds alone.

use super::Ray;

/// A block's width and height in pixels (a packet's eight rays).
const WIDE: usize = 2;
const HIGH: usize = 4;

/// The shortest row taken for a camera's (shorter ones are more likely rays that share an
/// origin by chance: a point's, in random directions).
const MIN_ROW: usize = 8;

/// The longest row looked for (the look costs a few instructions per ray of the row).
const MAX_ROW: usize = 4096;

/// `items` (a camera's rows, `width` long, a multiple of [`WIDE`]) block by block, into `out`:
/// each band of [`HIGH`] rows a block at a time, each block's row by row; the items past the
/// last whole band in their order. [`from_blocks`] undoes it.
pub(super) fn to_blocks<T: Copy>(items: &[T], width: usize, out: &mut Vec<T>) {
    let Some(band) = copy_and_band(items, width, out) else {
        return;
    };
    for (from, to) in items.chunks_exact(band).zip(out.chunks_exact_mut(band)) {
        let (Some([r0, r1, r2, r3]), (blocks, _)) = (rows(from, width), to.as_chunks_mut()) else {
            continue;
        };
        let rows = r0.iter().zip(r1).zip(r2).zip(r3);
        for (block, (((&[a, b], &[c, d]), &[e, f]), &[g, h])) in blocks.iter_mut().zip(rows) {
            *block = [a, b, c, d, e, f, g, h];
        }
    }
}

/// `blocks` (in [`to_blocks`]'s order of a camera's rows `width` long) back in row order,
/// into `out`.
pub(super) fn from_blocks<T: Copy>(blocks: &[T], width: usize, out: &mut Vec<T>) {
    let Some(band) = copy_and_band(blocks, width, out) else {
        return;
    };
    for (from, to) in blocks.chunks_exact(band).zip(out.chunks_exact_mut(band)) {
        let ((each, _), Some([r0, r1, r2, r3])) = (from.as_chunks(), rows_mut(to, width)) else {
            continue;
        };
        let rows = r0.iter_mut().zip(r1).zip(r2).zip(r3);
        for (&[a, b, c, d, e, f, g, h], (((p0, p1), p2), p3)) in each.iter().zip(rows) {
            (*p0, *p1, *p2, *p3) = ([a, b], [c, d], [e, f], [g, h]);
        }
    }
}

/// `items` copied to `out` (to be rearranged there band by band: the items past the last
/// whole band stay as they are), and the length of a band of [`HIGH`] rows `width` long;
/// `None` for a width that makes no blocks (zero or not a multiple of [`WIDE`]), the copy
/// then kept in the items' order.
fn copy_and_band<T: Copy>(items: &[T], width: usize, out: &mut Vec<T>) -> Option<usize> {
    out.clear();
    out.extend_from_slice(items);
    (width > 0 && width.is_multiple_of(WIDE)).then(|| width * HIGH)
}

/// A band's [`HIGH`] rows, `width` long, in pairs of pixels.
fn rows<T>(band: &[T], width: usize) -> Option<[&[[T; WIDE]]; HIGH]> {
    let (pairs, _) = band.as_chunks::<WIDE>();
    let (r0, rest) = pairs.split_at_checked(width / WIDE)?;
    let (r1, rest) = rest.split_at_checked(width / WIDE)?;
    let (r2, r3) = rest.split_at_checked(width / WIDE)?;
    Some([r0, r1, r2, r3])
}

/// [`rows`], to write.
fn rows_mut<T>(band: &mut [T], width: usize) -> Option<[&mut [[T; WIDE]]; HIGH]> {
    let (pairs, _) = band.as_chunks_mut::<WIDE>();
    let (r0, rest) = pairs.split_at_mut_checked(width / WIDE)?;
    let (r1, rest) = rest.split_at_mut_checked(width / WIDE)?;
    let (r2, r3) = rest.split_at_mut_checked(width / WIDE)?;
    Some([r0, r1, r2, r3])
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

    #[test]
    fn blocks_of_two_by_four_then_the_rest_in_order() {
        let rays = camera(16, 9, 0);
        assert_eq!(row_length(&rays), Some(16));
        let indices: Vec<u32> = (0..144).collect();
        let mut order = Vec::new();
        to_blocks(&indices, 16, &mut order);
        assert_eq!(order[..8], [0, 1, 16, 17, 32, 33, 48, 49]);
        assert_eq!(order[8..16], [2, 3, 18, 19, 34, 35, 50, 51]);
        // The second band of four rows, then the ninth row as it came.
        assert_eq!(order[64..72], [64, 65, 80, 81, 96, 97, 112, 113]);
        assert_eq!(order[128..], indices[128..]);
        let mut back = Vec::new();
        from_blocks(&order, 16, &mut back);
        assert_eq!(back, indices);
        // No blocks of a width they cannot be made of.
        for width in [0, 15] {
            to_blocks(&indices, width, &mut order);
            assert_eq!(order, indices);
            from_blocks(&indices, width, &mut back);
            assert_eq!(back, indices);
        }
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
