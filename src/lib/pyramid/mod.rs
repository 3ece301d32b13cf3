//! The max-Z / average-colour hierarchy with shadows and shading (`dbms pyramid`).
//!
//! Invariant: every cell of every coarse level holds the exact max of the heights of its level-0
//! block (a conservative bound for ray marching), the rounded average colour of the block's valid
//! level-0 cells, and an occupancy state; nodata never becomes data. See `docs/pyramid.md`.

pub mod cascade;
pub mod reduce;
pub mod raised;
pub mod shade;
