//! A least-recently-used cache bounded by bytes: decoded layer films and the
//! PNGs made from them, so a large EXR is decoded once per (file, channel,
//! exposure) and memory stays under the bound however long the page runs.

use std::collections::HashMap;
use std::sync::Arc;

/// Values by key, evicting the least recently used once their sizes add up
/// past `bound` bytes. A value larger than the bound alone is not kept.
#[derive(Debug)]
pub(crate) struct Lru<V> {
    bound: u64,
    used: u64,
    tick: u64,
    map: HashMap<String, (Arc<V>, u64, u64)>,
}

impl<V> Lru<V> {
    /// An empty cache holding at most `bound` bytes.
    pub(crate) fn new(bound: u64) -> Self {
        Lru { bound, used: 0, tick: 0, map: HashMap::new() }
    }

    /// The value under `key`, marked as just used.
    pub(crate) fn get(&mut self, key: &str) -> Option<Arc<V>> {
        self.tick += 1;
        let tick = self.tick;
        self.map.get_mut(key).map(|e| {
            e.2 = tick;
            e.0.clone()
        })
    }

    /// Keeps `value` (of `bytes` bytes) under `key`, evicting the least
    /// recently used values until it fits; gives the value back shared.
    pub(crate) fn insert(&mut self, key: String, value: V, bytes: u64) -> Arc<V> {
        let value = Arc::new(value);
        if let Some(old) = self.map.remove(&key) {
            self.used -= old.1;
        }
        if bytes > self.bound {
            return value;
        }
        while self.used + bytes > self.bound {
            let Some(oldest) = self.map.iter().min_by_key(|(_, e)| e.2).map(|(k, _)| k.clone()) else { break };
            if let Some(e) = self.map.remove(&oldest) {
                self.used -= e.1;
            }
        }
        self.tick += 1;
        self.used += bytes;
        self.map.insert(key, (value.clone(), bytes, self.tick));
        value
    }

    /// Bytes held.
    pub(crate) fn used(&self) -> u64 {
        self.used
    }

    /// The bound, bytes.
    pub(crate) fn bound(&self) -> u64 {
        self.bound
    }

    /// Values held.
    pub(crate) fn len(&self) -> usize {
        self.map.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn evicts_the_least_recently_used_to_stay_under_the_bound() {
        let mut c = Lru::new(100);
        c.insert("a".into(), 1, 40);
        c.insert("b".into(), 2, 40);
        assert_eq!(c.get("a").as_deref(), Some(&1)); // a is now newer than b
        c.insert("c".into(), 3, 40); // 120 > 100: b goes
        assert!(c.get("b").is_none());
        assert_eq!((c.get("a").as_deref(), c.get("c").as_deref()), (Some(&1), Some(&3)));
        assert_eq!((c.used(), c.len()), (80, 2));
        // Too big to keep at all: handed back, nothing evicted.
        assert_eq!(*c.insert("huge".into(), 4, 101), 4);
        assert_eq!((c.used(), c.len()), (80, 2));
        // Replacing a key frees its old size.
        c.insert("a".into(), 5, 10);
        assert_eq!((c.used(), c.get("a").as_deref()), (50, Some(&5)));
    }
}
