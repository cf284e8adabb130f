//! The simulation's keyed random numbers: its purposes, numbered, over the
//! shared keyed draws of [`crate::seed`] (a pure function of (seed, agent
//! id, purpose, counter)).

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

/// 64 random bits for (seed, id, purpose, counter).
pub(crate) fn bits(seed: u64, id: u32, purpose: Purpose, counter: i64) -> u64 {
    crate::seed::keyed_bits(seed, id, purpose as u64, counter)
}

/// Uniform in [0, 1).
pub(crate) fn unit(seed: u64, id: u32, purpose: Purpose, counter: i64) -> f64 {
    crate::seed::unit_of(bits(seed, id, purpose, counter))
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
