//! Shadow rays on the BVH (listing 8b): attenuation by every shadow-casting triangle on the
//! segment, with a per-light cache of the last opaque blocker.

use super::*;

impl SceneBvh {
    /// Listing 8b: the fraction of light that passes along `origin + t·dir`, `0 < t < t_max`.
    /// Starts at 1; every triangle hit whose material casts shadows multiplies it by that
    /// surface's transparency (1 − opacity, textures included via `surface_at`); stops at 0.
    /// Each triangle counts once; materials that cast no shadows are ignored.
    pub fn any_hit_attenuation(&self, prepared: &PreparedScene, origin: Vec3, dir: Vec3, t_max: f32) -> f32 {
        self.any_hit_attenuation_cached(prepared, origin, dir, t_max, &mut ShadowCache::default())
    }

    /// [`any_hit_attenuation`](Self::any_hit_attenuation) with a shadow cache (Haines &
    /// Greenberg 1986): the leaf of the last opaque blocker found through `cache` is tested
    /// first, and a hit there ends the ray at 0 without a traversal. Neighbouring shadow rays
    /// towards one light are usually blocked by the same triangles, so keep one cache per light
    /// and trace a light's rays in pixel order. The result is the same as without the cache
    /// (an opaque blocker anywhere on the segment gives 0 either way).
    pub fn any_hit_attenuation_cached(
        &self,
        prepared: &PreparedScene,
        origin: Vec3,
        dir: Vec3,
        t_max: f32,
        cache: &mut ShadowCache,
    ) -> f32 {
        if self.nodes.is_empty() {
            return 1.0;
        }
        let r = RayPre::new(Vec3A::from(origin), Vec3A::from(dir));
        if self.cache_blocks(cache, &r, t_max) {
            return 0.0;
        }
        self.attenuation_traversed(prepared, &r, t_max, cache).max(0.0)
    }

    /// The traversal half of [`any_hit_attenuation_cached`](Self::any_hit_attenuation_cached)
    /// (the cache's own leaf already tested): listing 8b's attenuation along `r` (≤ 0 when
    /// blocked), with `cache` moved onto the opaque blocker found, or emptied when none is.
    #[inline(always)]
    pub(super) fn attenuation_traversed(&self, prepared: &PreparedScene, r: &RayPre, t_max: f32, cache: &mut ShadowCache) -> f32 {
        let mut att = 1.0f32;
        self.for_each_pack_hit_with(r, 0.0, t_max, |leaf, slot0, mask, u, v| {
            self.attenuate(prepared, &mut att, cache, leaf, slot0, mask, u, v)
        });
        if att > 0.0 {
            // No opaque blocker: the next ray towards this light most likely passes too, so
            // testing this blocker first would only cost time.
            cache.leaf = EMPTY_SLOT;
        }
        att
    }

    /// Whether an opaque triangle of the cache's leaf blocks the segment `0 < t < t_max`.
    #[inline(always)]
    pub(super) fn cache_blocks(&self, cache: &ShadowCache, r: &RayPre, t_max: f32) -> bool {
        // A cache from another tree only costs time: any pack of this tree hit by an opaque lane
        // is a true blocker.
        if cache.leaf != EMPTY_SLOT && leaf_packs(cache.leaf).end <= self.packs.len() {
            let range = leaf_packs(cache.leaf);
            for (pack, &shadow) in self.packs[range.clone()].iter().zip(&self.pack_shadow[range]) {
                let (_, _, _, hit) = intersect4(pack, r, 0.0, t_max);
                if hit & (shadow as u32 >> 4) != 0 {
                    return true;
                }
            }
        }
        false
    }

    /// Listing 8b's step at a pack hit (as [`SceneBvh::for_each_pack_hit`] reports it):
    /// multiplies `att` by the transparency of each lane hit, or sets it to 0 (and `cache` to
    /// `leaf`) at an opaque blocker; false once `att` is 0 (the ray is done).
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    pub(super) fn attenuate(
        &self,
        prepared: &PreparedScene,
        att: &mut f32,
        cache: &mut ShadowCache,
        leaf: u32,
        slot0: usize,
        mut mask: u32,
        u: [f32; 4],
        v: [f32; 4],
    ) -> bool {
        if mask >> 4 != 0 {
            // An opaque blocker.
            cache.leaf = leaf;
            *att = 0.0;
            return false;
        }
        while mask != 0 {
            let lane = mask.trailing_zeros() as usize & 3;
            mask &= mask - 1;
            let tr = self.slot_shadow[slot0 + lane];
            let tr = if tr == SHADOW_EVALUATE { self.textured_transparency(prepared, slot0 + lane, u[lane], v[lane]) } else { tr };
            *att *= tr;
            if *att <= 0.0 {
                return false;
            }
        }
        true
    }

    /// Shadow transparency (1 − opacity) of the slot's triangle at corner weights (1 − u − v,
    /// u, v), from its textures. Out of line: it is rare, and inlined it would crowd the
    /// traversal loop.
    #[inline(never)]
    pub(super) fn textured_transparency(&self, prepared: &PreparedScene, slot: usize, u: f32, v: f32) -> f32 {
        1.0 - prepared.surface_at(self.slot_ref[slot], Vec3::new(1.0 - u - v, u, v), 0.0).opacity
    }
}
