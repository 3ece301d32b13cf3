//! A bounded least-recently-used cache of decoded pages, shareable between threads.
//!
//! Invariant: never holds more than `capacity` pages; a hit makes the page the most recent;
//! an insert beyond capacity evicts the least recent. Capacity 0 caches nothing.
//!
//! Hits are the hot path of every ray step, so they take only a shared read lock and stamp
//! the page's atomic last-use tick; the O(capacity) search for the victim happens on inserts,
//! which follow a page read from the file and are far costlier anyway.

use super::page::Page;
use std::collections::HashMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, RwLock};

/// LRU of pages keyed by index position.
pub(crate) struct PageCache {
    capacity: usize,
    tick: AtomicU64,
    pages: RwLock<HashMap<usize, Slot>>,
}

struct Slot {
    page: Arc<Page>,
    /// Tick of the last use; ticks are unique, so the least recent page is unambiguous.
    used: AtomicU64,
}

impl PageCache {
    pub fn new(capacity: usize) -> PageCache {
        PageCache {
            capacity,
            tick: AtomicU64::new(0),
            pages: RwLock::new(HashMap::new()),
        }
    }

    fn next_tick(&self) -> u64 {
        self.tick.fetch_add(1, Ordering::Relaxed) + 1
    }

    /// Most pages it holds.
    pub fn capacity(&self) -> usize {
        self.capacity
    }

    /// The cached page at `pos`, marking it most recently used.
    pub fn get(&self, pos: usize) -> Option<Arc<Page>> {
        let pages = self.pages.read().unwrap_or_else(|p| p.into_inner());
        let slot = pages.get(&pos)?;
        slot.used.store(self.next_tick(), Ordering::Relaxed);
        Some(slot.page.clone())
    }

    /// Cache `page` at `pos` (replacing what another thread may have inserted meanwhile).
    pub fn insert(&self, pos: usize, page: Arc<Page>) {
        if self.capacity == 0 {
            return;
        }
        let mut pages = self.pages.write().unwrap_or_else(|p| p.into_inner());
        pages.insert(
            pos,
            Slot {
                page,
                used: AtomicU64::new(self.next_tick()),
            },
        );
        while pages.len() > self.capacity {
            let victim = *pages
                .iter()
                .min_by_key(|(_, s)| s.used.load(Ordering::Relaxed))
                .map(|(k, _)| k)
                .expect("over capacity, so not empty");
            pages.remove(&victim);
        }
    }

    /// Number of pages held.
    #[cfg(test)]
    pub fn len(&self) -> usize {
        self.pages.read().unwrap().len()
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
