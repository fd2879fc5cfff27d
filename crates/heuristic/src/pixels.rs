//! Per-pixel passes over the G-buffer's object-id target: counting A for every object, and
//! writing the heuristic mask from the selection.

/// Object id of a pixel that no object covers (sky).
pub const SKY_ID: u32 = u32::MAX;
/// Object id of a pixel covered by the ray-traced RT-scene (point cloud, design §5), not by a
/// selectable object.
pub const RT_SCENE_ID: u32 = u32::MAX - 1;

/// A (paper Table 3) for every object in one pass: `counts[i]` = number of pixels whose id is `i`.
///
/// Ids `>= object_count` are ignored; that includes [`SKY_ID`] and [`RT_SCENE_ID`]. The result
/// has exactly `object_count` entries.
///
/// The pass counts *runs* of equal ids and adds each run once: rasterised images are made of long
/// horizontal runs, and adding one pixel at a time to the same counter would serialise every
/// increment on the previous store (≈ 5 cycles per pixel). Chunks of 16 pixels that all continue
/// the current run are recognised with one vectorised test.
pub fn count_visible_pixels(object_id: &[u32], object_count: usize) -> Vec<u64> {
    let mut counts = vec![0u64; object_count];
    let Some(&first) = object_id.first() else {
        return counts;
    };
    let mut run = Run { id: first, length: 0 };
    let mut chunks = object_id.chunks_exact(CHUNK);
    for chunk in &mut chunks {
        // Fast path (vectorised): the whole chunk continues the current run.
        if all_equal(chunk, run.id) {
            run.length += CHUNK as u64;
        } else {
            for &id in chunk {
                run.push(id, &mut counts);
            }
        }
    }
    for &id in chunks.remainder() {
        run.push(id, &mut counts);
    }
    run.flush(&mut counts);
    counts
}

/// Pixels tested at once for "same id as before" (one or two SIMD registers).
const CHUNK: usize = 16;

/// `true` when every id in `chunk` equals `id`; branch-free so that it vectorises.
fn all_equal(chunk: &[u32], id: u32) -> bool {
    chunk.iter().fold(0, |acc, &other| acc | (other ^ id)) == 0
}

/// A run of equal ids not yet added to the counts.
struct Run {
    id: u32,
    length: u64,
}

impl Run {
    fn push(&mut self, id: u32, counts: &mut [u64]) {
        if id == self.id {
            self.length += 1;
        } else {
            self.flush(counts);
            *self = Run { id, length: 1 };
        }
    }

    fn flush(&self, counts: &mut [u64]) {
        if let Some(count) = counts.get_mut(self.id as usize) {
            *count += self.length;
        }
    }
}

/// The heuristic mask (design §2): `mask[p] = 1.0` where pixel `p`'s object is selected, else
/// `0.0` (sky, RT-scene and ids `>= selected.len()` give 0).
///
/// `object_id` and `mask` are the same image and should have the same length; if they do not,
/// only the common prefix is written.
pub fn write_mask(object_id: &[u32], selected: &[bool], mask: &mut [f32]) {
    debug_assert_eq!(object_id.len(), mask.len(), "id buffer and mask differ in size");
    let n = object_id.len().min(mask.len());
    // Mask value per object, plus one trailing 0.0 that every out-of-range id maps to: the
    // per-pixel lookup is then branch-free.
    let values: Vec<f32> = selected.iter().map(|&on| if on { 1.0 } else { 0.0 }).chain([0.0]).collect();
    let last = selected.len();
    let value = |id: u32| values[(id as usize).min(last)];
    let mut id_chunks = object_id[..n].chunks_exact(CHUNK);
    let mut mask_chunks = mask[..n].chunks_exact_mut(CHUNK);
    for (ids, out) in (&mut id_chunks).zip(&mut mask_chunks) {
        // Fast path: one object covers the whole chunk, so one lookup fills it (fixed-size
        // copy: a few vector stores, no call to memset).
        if all_equal(ids, ids[0]) {
            out.copy_from_slice(&[value(ids[0]); CHUNK]);
        } else {
            for (m, &id) in out.iter_mut().zip(ids) {
                *m = value(id);
            }
        }
    }
    for (m, &id) in mask_chunks.into_remainder().iter_mut().zip(id_chunks.remainder()) {
        *m = value(id);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_runs_and_ignores_out_of_range_ids() {
        let ids = [0, 0, 2, SKY_ID, 2, 2, RT_SCENE_ID, 1, 7, 0];
        assert_eq!(count_visible_pixels(&ids, 3), vec![3, 1, 3]);
        // The same buffer against fewer objects drops the higher ids.
        assert_eq!(count_visible_pixels(&ids, 1), vec![3]);
        assert_eq!(count_visible_pixels(&[], 2), vec![0, 0]);
        assert_eq!(count_visible_pixels(&[SKY_ID; 4], 0), Vec::<u64>::new());
        // Trailing run is flushed.
        assert_eq!(count_visible_pixels(&[1, 1, 1], 2), vec![0, 3]);
    }

    /// Deterministic pseudo-random ids (objects 0..23, sky, RT-scene) in runs of 0 to 60 pixels,
    /// so that both the per-pixel and the 16-pixel fast paths are taken.
    fn runs_of_ids() -> Vec<u32> {
        let mut state = 12345u32;
        let mut ids = Vec::new();
        for _ in 0..3000 {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            let id = match state >> 29 {
                0 => SKY_ID,
                1 => RT_SCENE_ID,
                _ => (state >> 8) % 23,
            };
            let run = (state >> 4) % 61;
            ids.extend(std::iter::repeat_n(id, run as usize));
        }
        ids
    }

    #[test]
    fn counts_match_naive_histogram() {
        let ids = runs_of_ids();
        let mut naive = vec![0u64; 20];
        for &id in &ids {
            if (id as usize) < naive.len() {
                naive[id as usize] += 1;
            }
        }
        assert_eq!(count_visible_pixels(&ids, 20), naive);
        // Every offset of the chunk grid.
        for skip in 1..16 {
            let mut naive = vec![0u64; 20];
            for &id in &ids[skip..] {
                if (id as usize) < naive.len() {
                    naive[id as usize] += 1;
                }
            }
            assert_eq!(count_visible_pixels(&ids[skip..], 20), naive);
        }
    }

    #[test]
    fn mask_matches_naive_on_long_runs() {
        let ids = runs_of_ids();
        let selected: Vec<bool> = (0..20).map(|i| i % 3 != 0).collect();
        let mut mask = vec![0.5f32; ids.len()];
        write_mask(&ids, &selected, &mut mask);
        for (&id, &m) in ids.iter().zip(&mask) {
            let on = (id as usize) < selected.len() && selected[id as usize];
            assert_eq!(m, if on { 1.0 } else { 0.0 }, "id {id}");
        }
    }

    #[test]
    fn mask_marks_exactly_selected_pixels() {
        let ids = [0, 1, 2, SKY_ID, RT_SCENE_ID, 1, 5, 0];
        let selected = [false, true, true];
        let mut mask = [0.5f32; 8];
        write_mask(&ids, &selected, &mut mask);
        assert_eq!(mask, [0.0, 1.0, 1.0, 0.0, 0.0, 1.0, 0.0, 0.0]);
    }
}
