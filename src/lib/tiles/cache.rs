//! A bounded least-recently-used cache of decoded pages, shareable between threads.
//!
//! Invariant: never holds more than `capacity` pages; a hit makes the page the most recent;
//! an insert beyond capacity evicts the least recent. Capacity 0 caches nothing.

use super::page::Page;
use std::collections::{BTreeMap, HashMap};
use std::sync::{Arc, Mutex};

/// LRU of pages keyed by index position.
pub(crate) struct PageCache {
    capacity: usize,
    inner: Mutex<Lru>,
}

#[derive(Default)]
struct Lru {
    /// Position → (page, last-use tick).
    pages: HashMap<usize, (Arc<Page>, u64)>,
    /// Last-use tick → position: the smallest tick is the eviction victim.
    by_use: BTreeMap<u64, usize>,
    tick: u64,
}

impl PageCache {
    pub fn new(capacity: usize) -> PageCache {
        PageCache { capacity, inner: Mutex::new(Lru::default()) }
    }

    /// The cached page at `pos`, marking it most recently used.
    pub fn get(&self, pos: usize) -> Option<Arc<Page>> {
        let mut lru = self.inner.lock().unwrap_or_else(|p| p.into_inner());
        let lru = &mut *lru;
        lru.tick += 1;
        let (page, used) = lru.pages.get_mut(&pos)?;
        lru.by_use.remove(used);
        *used = lru.tick;
        lru.by_use.insert(lru.tick, pos);
        Some(page.clone())
    }

    /// Cache `page` at `pos` (replacing what another thread may have inserted meanwhile).
    pub fn insert(&self, pos: usize, page: Arc<Page>) {
        if self.capacity == 0 {
            return;
        }
        let mut lru = self.inner.lock().unwrap_or_else(|p| p.into_inner());
        let lru = &mut *lru;
        lru.tick += 1;
        if let Some((_, used)) = lru.pages.insert(pos, (page, lru.tick)) {
            lru.by_use.remove(&used);
        }
        lru.by_use.insert(lru.tick, pos);
        while lru.pages.len() > self.capacity {
            let (_, victim) = lru.by_use.pop_first().expect("by_use mirrors pages");
            lru.pages.remove(&victim);
        }
    }

    /// Number of pages held.
    #[cfg(test)]
    pub fn len(&self) -> usize {
        self.inner.lock().unwrap().pages.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn page(v: f32) -> Arc<Page> {
        let mut p = Page::nodata(1);
        p.max_z[0] = v;
        Arc::new(p)
    }

    #[test]
    fn evicts_the_least_recently_used() {
        let c = PageCache::new(2);
        c.insert(1, page(1.0));
        c.insert(2, page(2.0));
        assert!(c.get(1).is_some()); // 2 is now the oldest
        c.insert(3, page(3.0));
        assert_eq!(c.len(), 2);
        assert!(c.get(2).is_none());
        assert_eq!(c.get(1).unwrap().max_z[0], 1.0);
        assert_eq!(c.get(3).unwrap().max_z[0], 3.0);
        c.insert(3, page(4.0)); // replacing keeps the count
        assert_eq!(c.len(), 2);
        assert_eq!(c.get(3).unwrap().max_z[0], 4.0);
    }

    #[test]
    fn capacity_zero_holds_nothing() {
        let c = PageCache::new(0);
        c.insert(1, page(1.0));
        assert!(c.get(1).is_none());
        assert_eq!(c.len(), 0);
    }
}
