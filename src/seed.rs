//! Keyed random draws: every draw is a pure function of (seed, agent id,
//! purpose[, counter]), never a step of a shared sequence, so results do not
//! depend on iteration order, thread count, or which other agents exist.
//!
//! Two keyings share these primitives and must keep their values (caches,
//! casts and renders are reproduced from them): casting names its purposes
//! by strings, hashed with FNV-1a ([`uniform`]); the reference simulation
//! numbers them ([`keyed_bits`] with the number of its purpose).

use crate::fingerprint::fnv1a_continued;

/// splitmix64's finaliser: a bijection of 64 bits with good avalanche.
pub(crate) fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// splitmix64's golden-ratio increment (2^64 / phi).
const GOLDEN_GAMMA: u64 = 0x9e37_79b9_7f4a_7c15;

/// One splitmix64 output: the state advanced by the golden gamma, mixed.
fn splitmix(z: u64) -> u64 {
    mix64(z.wrapping_add(GOLDEN_GAMMA))
}

/// The top 53 bits of `bits` as a uniform number in [0, 1).
pub(crate) fn unit_of(bits: u64) -> f64 {
    (bits >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
}

/// FNV-1a of a purpose string, so purposes are named, not numbered.
pub(crate) fn purpose_hash(purpose: &str) -> u64 {
    purpose_hash_from(crate::fingerprint::FNV_OFFSET_BASIS, purpose)
}

/// FNV-1a continued over `more` from the hash `h` of a prefix:
/// `purpose_hash_from(purpose_hash("part/"), slot)` is
/// `purpose_hash("part/" + slot)` without building the string.
pub(crate) fn purpose_hash_from(h: u64, more: &str) -> u64 {
    fnv1a_continued(h, more.as_bytes())
}

/// A uniform number in [0, 1) keyed by (seed, agent id, purpose).
pub fn uniform(seed: u64, agent: u32, purpose: &str) -> f64 {
    uniform_hashed(seed, agent, purpose_hash(purpose))
}

/// [`uniform`] with the purpose already hashed by [`purpose_hash`].
pub(crate) fn uniform_hashed(seed: u64, agent: u32, purpose: u64) -> f64 {
    let h = mix64(mix64(mix64(seed) ^ u64::from(agent).wrapping_mul(GOLDEN_GAMMA)) ^ purpose);
    unit_of(h)
}

/// 64 random bits for (seed, id, numbered purpose, counter): each key
/// folded in by one splitmix64 step.
pub(crate) fn keyed_bits(seed: u64, id: u32, purpose: u64, counter: i64) -> u64 {
    let mut h = splitmix(seed);
    h = splitmix(h ^ u64::from(id));
    h = splitmix(h ^ purpose);
    splitmix(h ^ counter as u64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uniform_is_keyed_and_in_range() {
        let a = uniform(1, 7, "height");
        assert_eq!(a, uniform(1, 7, "height"));
        assert_ne!(a, uniform(2, 7, "height"));
        assert_ne!(a, uniform(1, 8, "height"));
        assert_ne!(a, uniform(1, 7, "scheme"));
        for id in 0..1000 {
            let u = uniform(3, id, "x");
            assert!((0.0..1.0).contains(&u));
        }
    }

    #[test]
    fn continued_purpose_hash_is_the_whole_string() {
        assert_eq!(purpose_hash_from(purpose_hash("part/"), "head"), purpose_hash("part/head"));
        let torso = purpose_hash_from(purpose_hash("material/"), "torso");
        assert_eq!(uniform_hashed(5, 9, torso), uniform(5, 9, "material/torso"));
    }

    #[test]
    fn splitmix_is_the_reference_generator() {
        // splitmix64 seeded with 0: its first output (Vigna's reference code).
        assert_eq!(splitmix(0), 0xe220_a839_7b1d_cdaf);
    }
}
