//! Keyed random numbers: every draw is a pure function of
//! (seed, agent id, purpose, counter), so results never depend on iteration
//! order, thread count, or which other agents exist.

/// What a draw is for; each purpose gets its own stream.
#[derive(Clone, Copy, Debug)]
#[repr(u64)]
pub(crate) enum Purpose {
    /// Spawn position jitter, x then z (counter 0 and 1).
    SpawnJitter = 1,
    /// Spawn heading jitter.
    SpawnHeading = 2,
    /// Rig choice in a spawn region.
    Rig = 3,
    /// Cycle choice in a spawn region.
    Cycle = 4,
    /// Starting phase in the cycle.
    Phase = 5,
    /// Next cycle at a cycle boundary (counter = frame).
    NextCycle = 6,
}

fn splitmix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// 64 random bits for (seed, id, purpose, counter).
pub(crate) fn bits(seed: u64, id: u32, purpose: Purpose, counter: i64) -> u64 {
    let mut h = splitmix(seed);
    h = splitmix(h ^ u64::from(id));
    h = splitmix(h ^ purpose as u64);
    splitmix(h ^ counter as u64)
}

/// Uniform in [0, 1).
pub(crate) fn unit(seed: u64, id: u32, purpose: Purpose, counter: i64) -> f64 {
    (bits(seed, id, purpose, counter) >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
}

/// Picks an entry of `items` (value, weight) with probability proportional
/// to its weight, using `u` in [0, 1). Weights are non-negative and sum > 0.
pub(crate) fn choose<T: Copy>(items: &[(T, f32)], u: f64) -> Option<T> {
    let total: f64 = items.iter().map(|&(_, w)| f64::from(w)).sum();
    if total <= 0.0 || items.is_empty() {
        return None;
    }
    let mut x = u * total;
    for &(v, w) in items {
        let w = f64::from(w);
        if x < w {
            return Some(v);
        }
        x -= w;
    }
    // Rounding left a sliver: the last entry with weight takes it.
    items.iter().rev().find(|&&(_, w)| w > 0.0).map(|&(v, _)| v)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keyed_and_spread() {
        assert_eq!(bits(1, 2, Purpose::Rig, 0), bits(1, 2, Purpose::Rig, 0));
        assert_ne!(bits(1, 2, Purpose::Rig, 0), bits(1, 3, Purpose::Rig, 0));
        assert_ne!(bits(1, 2, Purpose::Rig, 0), bits(2, 2, Purpose::Rig, 0));
        assert_ne!(bits(1, 2, Purpose::Rig, 0), bits(1, 2, Purpose::Cycle, 0));
        let mean: f64 = (0..10_000).map(|i| unit(7, i, Purpose::Phase, 0)).sum::<f64>() / 10_000.0;
        assert!((mean - 0.5).abs() < 0.02, "{mean}");
    }

    #[test]
    fn choose_by_weight() {
        let items = [('a', 1.0), ('b', 0.0), ('c', 3.0)];
        assert_eq!(choose(&items, 0.0), Some('a'));
        assert_eq!(choose(&items, 0.2), Some('a'));
        assert_eq!(choose(&items, 0.3), Some('c'));
        assert_eq!(choose(&items, 0.999_999_9), Some('c'));
        assert_eq!(choose::<char>(&[], 0.5), None);
    }
}
