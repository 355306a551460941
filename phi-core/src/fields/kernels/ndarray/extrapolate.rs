//! The valid-region growth kernel: box sums over the frontier, in the composite's order.

/// The extrapolation of [`LatticeKernels::float_extrapolate_valid`] for one mask per site, layer by
/// layer over the frontier only: the invalid sites next to the valid region. Each frontier site
/// takes its box sums in the order [`box_sum_in_place`] adds them over the whole grid (axis 0
/// first, `(below + centre) + above`, zeros beyond the edges), so the values are bit for bit the
/// composite's, at a cost that follows the frontier instead of the grid. Takes the values and
/// the mask (any nonzero entry is valid) and returns both grown.
pub(super) fn extrapolate_frontier(
    v: &[f32],
    mask: &[f32],
    grid: &[usize],
    channels: usize,
    cells: usize,
) -> (Vec<f32>, Vec<f32>) {
    match grid.len() {
        1 => frontier_kernel::<1>(v, mask, grid, channels, cells),
        2 => frontier_kernel::<2>(v, mask, grid, channels, cells),
        3 => frontier_kernel::<3>(v, mask, grid, channels, cells),
        _ => unreachable!("grids have one to three dimensions"),
    }
}

/// [`extrapolate_frontier`] on a `D`-dimensional grid. It works on a copy padded by one site
/// beyond every side (mask and values 0, never queued), so that every site's `3^D` box lies in
/// the array and the loops need no bounds tests: a padding site adds the zero the composite
/// adds beyond the edge.
#[allow(clippy::needless_range_loop)] // box positions index several arrays
fn frontier_kernel<const D: usize>(
    v: &[f32],
    mask: &[f32],
    grid: &[usize],
    channels: usize,
    cells: usize,
) -> (Vec<f32>, Vec<f32>) {
    let sites: usize = grid.iter().product();
    if sites == 0 || cells == 0 {
        return (v.to_vec(), mask.iter().map(|&m| unit_mask(m)).collect());
    }
    let padded: [usize; D] = std::array::from_fn(|axis| grid[axis] + 2);
    let mut strides = [1usize; D];
    for axis in (0..D.saturating_sub(1)).rev() {
        strides[axis] = strides[axis + 1] * padded[axis + 1];
    }
    let padded_sites: usize = padded.iter().product();
    // The interior: padded index of each grid site, row by row along the last axis.
    let row = grid[D - 1];
    let row_starts = || {
        (0..sites / row).map(move |r| {
            let (mut rest, mut at) = (r, 0);
            for axis in (0..D - 1).rev() {
                at += (rest % grid[axis] + 1) * strides[axis];
                rest /= grid[axis];
            }
            (r * row, at + 1)
        })
    };
    let mut pv = vec![0.0f32; padded_sites * channels];
    let mut pm = vec![0.0f32; padded_sites];
    let mut queued = vec![true; padded_sites];
    for (site, at) in row_starts() {
        pv[at * channels..(at + row) * channels]
            .copy_from_slice(&v[site * channels..(site + row) * channels]);
        for (m, &valid) in pm[at..at + row].iter_mut().zip(&mask[site..site + row]) {
            *m = unit_mask(valid);
        }
        queued[at..at + row].fill(false);
    }
    // The 3^D box around a site, itself included: per box position `k` (row-major over the
    // per-axis steps −1, 0, +1, axis 0 slowest), its flat offset.
    let positions = 3usize.pow(D as u32);
    let mut box_offset = [0isize; 27];
    for (k, offset) in box_offset[..positions].iter_mut().enumerate() {
        let mut rest = k;
        for axis in (0..D).rev() {
            let step = (rest % 3) as isize - 1;
            rest /= 3;
            *offset += step * strides[axis] as isize;
        }
    }
    let box_offset = &box_offset[..positions];
    // The box sum of the gathered `values` (one per box position) in box_sum_in_place's order:
    // axis 0 first, each as `(below + centre) + above`. Sums in place; the result is `values[0]`.
    let reduce_box = |values: &mut [f32]| {
        let mut len = values.len();
        for _ in 0..D {
            len /= 3;
            for j in 0..len {
                values[j] = (values[j] + values[len + j]) + values[2 * len + j];
            }
        }
        values[0]
    };
    // The first frontier: the invalid sites that see a valid one. Whether a site sees one is the
    // count of valid sites in its box, summed axis by axis over the whole padded array (long
    // vectorised runs; each pass covers every site whose neighbours along its axis lie in the
    // array, which includes all that a later pass reads for an interior site).
    let mut seen = pm.clone();
    let mut pass = vec![0.0f32; padded_sites];
    for &stride in &strides {
        let n = padded_sites;
        for ((out, below), (centre, above)) in pass[stride..n - stride]
            .iter_mut()
            .zip(&seen[..n - 2 * stride])
            .zip(seen[stride..n - stride].iter().zip(&seen[2 * stride..]))
        {
            *out = (below + centre) + above;
        }
        std::mem::swap(&mut seen, &mut pass);
    }
    // Most runs of sites hold no frontier site: each run of 16 is tested at once (vectorised),
    // and only runs with one are walked site by site.
    let mut frontier = Vec::new();
    for (_, at) in row_starts() {
        for start in (at..at + row).step_by(16) {
            let end = (start + 16).min(at + row);
            let hit = pm[start..end]
                .iter()
                .zip(&seen[start..end])
                .fold(false, |hit, (&m, &count)| {
                    hit | ((m == 0.0) & (count != 0.0))
                });
            if !hit {
                continue;
            }
            for site in start..end {
                if pm[site] == 0.0 && seen[site] != 0.0 {
                    queued[site] = true;
                    frontier.push(site);
                }
            }
        }
    }
    let mut updates = Vec::new();
    let mut count_box = [0.0f32; 27];
    let mut sum_box = vec![0.0f32; positions * channels];
    let mut next = Vec::new();
    for _ in 0..cells {
        if frontier.is_empty() {
            break;
        }
        updates.clear();
        for &site in &frontier {
            // Gather the mask and the masked values over the box.
            for (k, &offset) in box_offset.iter().enumerate() {
                let nb = site.wrapping_add_signed(offset);
                let m = pm[nb];
                count_box[k] = m;
                for ch in 0..channels {
                    sum_box[ch * positions + k] = pv[nb * channels + ch] * m;
                }
            }
            let count = reduce_box(&mut count_box[..positions]);
            // A frontier site has a valid neighbour: count > 0, and the composite divides by
            // `count + 0`.
            for sums in sum_box.chunks_exact_mut(positions) {
                updates.push(reduce_box(sums) / (count + 0.0));
            }
        }
        for (&site, new) in frontier.iter().zip(updates.chunks_exact(channels)) {
            for (ch, &x) in new.iter().enumerate() {
                pv[site * channels + ch] = x;
            }
            pm[site] = 1.0;
        }
        next.clear();
        for &site in &frontier {
            for &offset in box_offset {
                let nb = site.wrapping_add_signed(offset);
                if pm[nb] == 0.0 && !queued[nb] {
                    queued[nb] = true;
                    next.push(nb);
                }
            }
        }
        std::mem::swap(&mut frontier, &mut next);
    }
    let mut values = Vec::with_capacity(sites * channels);
    let mut valid = Vec::with_capacity(sites);
    for (_, at) in row_starts() {
        values.extend_from_slice(&pv[at * channels..(at + row) * channels]);
        valid.extend_from_slice(&pm[at..at + row]);
    }
    (values, valid)
}

/// A mask entry as `0` or `1` (any nonzero entry is valid).
#[inline(always)]
pub(super) fn unit_mask(m: f32) -> f32 {
    if m != 0.0 { 1.0 } else { 0.0 }
}

/// Replaces `data` (`[grid..., channels]`, row-major) by its sum over the `3^d` box around each
/// site (zero beyond the edges), one axis after the other, each as `(x[i−1] + x[i]) + x[i+1]`:
/// the order of the composite `box_sum`, so the results agree bit for bit.
pub(super) fn box_sum_in_place(
    data: &mut [f32],
    grid: &[usize],
    channels: usize,
    scratch: &mut Vec<f32>,
) {
    for (axis, &n) in grid.iter().enumerate() {
        let inner = grid[axis + 1..].iter().product::<usize>() * channels;
        let block = n * inner;
        if block == 0 {
            return;
        }
        scratch.clear();
        scratch.extend_from_slice(data);
        for (src, dst) in scratch
            .chunks_exact(block)
            .zip(data.chunks_exact_mut(block))
        {
            // Rows of `inner` values along the axis; missing neighbours are zeros. The rows with
            // both neighbours form one contiguous run, summed as one flat loop (vectorised, and
            // cheap when `inner` is small, as along the last axis).
            if n == 1 {
                for (o, &c) in dst.iter_mut().zip(src) {
                    *o = (0.0 + c) + 0.0;
                }
                continue;
            }
            let interior = (n - 2) * inner;
            let (first, rest) = dst.split_at_mut(inner);
            let (middle, last) = rest.split_at_mut(interior);
            for ((o, &c), &a) in first
                .iter_mut()
                .zip(&src[..inner])
                .zip(&src[inner..2 * inner])
            {
                *o = (0.0 + c) + a;
            }
            let below = &src[..interior];
            let centre = &src[inner..inner + interior];
            let above = &src[2 * inner..2 * inner + interior];
            for (((o, &b), &c), &a) in middle.iter_mut().zip(below).zip(centre).zip(above) {
                *o = (b + c) + a;
            }
            let end = n * inner;
            for ((o, &b), &c) in last
                .iter_mut()
                .zip(&src[end - 2 * inner..end - inner])
                .zip(&src[end - inner..end])
            {
                *o = (b + c) + 0.0;
            }
        }
    }
}
