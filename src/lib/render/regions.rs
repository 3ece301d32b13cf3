//! Descending into a tile set's regions (a database's insets, docs/tile-format.md "Regions")
//! while marching a ray through their parent.
//!
//! A parent's level-0 cells over a region hold the region's cover (exact max Z), so the
//! parent's hierarchy brings a ray down to level 0 wherever it may hit the region. There, when
//! the region's finer cells are wanted — always without range thresholds; with them, when a
//! parent cell is still wider than a pixel where the ray enters the region — the ray is marched
//! through the region's own hierarchy (the same [`march`], on the region's tile file, plan and
//! sampler; nested regions in turn) over the whole time it is inside the region's box, and
//! either hits there or goes on in the parent from where it leaves the box, never testing the
//! covers.
//!
//! Invariant: what a region gives a ray is a pure function of the ray, its span and the region
//! — the region march starts where the ray enters the region's box (or the span starts), not
//! where the parent's walk happened to come down — so a parent's hierarchical and level-0
//! traversals agree on it bit for bit, and the region march itself keeps [`march`]'s invariants
//! over the region's cells. Region cells are `factor` times smaller: a ray's region axes are
//! its parent axes moved to the window's corner and scaled by the factor; heights and `τ` are
//! the parent's, so ranges compare across regions.

use super::march::{march, Hit, Plan, Span};
use super::ray::{Axis, Ray};
use super::sampler::{ColumnCache, Sampler};
use crate::error::Result;
use crate::inset::CellWindow;
use crate::tiles::region::Region;
use crate::tiles::TileReader;

/// One region as a frame reads it: its tile file, its plan, its decoded voxel columns.
pub struct RegionFrame<'a> {
    /// The region.
    pub region: Region,
    /// Its tile file (the base reader's, kept across frames: [`TileReader::regions`]).
    pub reader: &'a TileReader,
    /// How rays step its levels (the frame's traversal, blend and pixel size; its own cells).
    pub plan: Plan,
    /// Its decoded voxel columns, shared by the frame's samplers.
    pub columns: ColumnCache,
    /// The frame (index) of its parent region; `None`: the base.
    pub parent: Option<usize>,
}

/// Every region of a tile set, set up for one frame.
#[derive(Default)]
pub struct RegionFrames<'a> {
    frames: Vec<RegionFrame<'a>>,
}

impl<'a> RegionFrames<'a> {
    /// The regions of the tile file behind `base` (its [`TileReader::regions`]: checked, opened
    /// once and kept), each with a plan like the base's `plan` for its own cells; `per_pixel`:
    /// radians a pixel spans (for the range thresholds). None with `repeat` (regions do not
    /// repeat with the database), and none for a reader whose pages a filter recolours (a
    /// sensor view: regions carry no sensor layers, so the base stands for them).
    pub fn open(
        base: &'a TileReader,
        plan: &Plan,
        per_pixel: f64,
        repeat: bool,
    ) -> Result<RegionFrames<'a>> {
        let info = base.info();
        if repeat || info.regions.is_empty() || base.is_filtered() {
            return Ok(RegionFrames::default());
        }
        let readers = base.regions()?;
        let mut frames = Vec::with_capacity(info.regions.len());
        for (r, reader) in info.regions.iter().zip(readers) {
            let ri = reader.info();
            let (lod, top) = (plan.thresholds.is_some(), ri.levels.len() - 1);
            let region_plan = Plan::of_levels(ri, top, plan.traversal, lod, plan.blend, per_pixel);
            let parent = r.parent.as_ref().map(|p| {
                info.regions
                    .iter()
                    .position(|o| &o.name == p)
                    .expect("checked")
            });
            frames.push(RegionFrame {
                region: r.clone(),
                reader,
                plan: region_plan,
                columns: ColumnCache::default(),
                parent,
            });
        }
        Ok(RegionFrames { frames })
    }

    /// Whether the tile set has regions to descend into.
    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }

    /// `base` (a sampler of the base tile file) with a sampler of each of its regions, each
    /// with its own regions in turn.
    pub fn attach<'s>(&'s self, base: Sampler<'s>) -> Sampler<'s> {
        self.attach_below(base, None)
    }

    fn attach_below<'s>(&'s self, mut sampler: Sampler<'s>, parent: Option<usize>) -> Sampler<'s> {
        for (k, f) in self.frames.iter().enumerate() {
            if f.parent != parent {
                continue;
            }
            let own = Sampler::new(f.reader, false, &f.columns).region_edges();
            sampler.children.push(Child {
                window: f.region.window,
                factor: f.region.factor,
                sampler: self.attach_below(own, Some(k)),
                plan: &f.plan,
            });
        }
        sampler
    }
}

/// A region below a sampler's tile set: where it lies, and how to march it.
pub struct Child<'a> {
    /// The parent's level-0 cells it covers.
    pub window: CellWindow,
    /// Parent cells per region cell on each axis.
    pub factor: usize,
    /// Its cells (and its own regions).
    pub sampler: Sampler<'a>,
    /// How rays step it.
    pub plan: &'a Plan,
}

impl Child<'_> {
    /// Whether the window holds parent level-0 cell `(c, r)`.
    #[inline]
    pub fn holds(&self, c: i64, r: i64) -> bool {
        let w = &self.window;
        c >= w.col0 as i64 && c < w.col1 as i64 && r >= w.row0 as i64 && r < w.row1 as i64
    }

    /// `ray` (in the parent's cell space) in the region's cell space.
    pub fn ray(&self, ray: &Ray) -> Ray {
        let f = self.factor as f64;
        let (c0, r0) = (self.window.col0 as f64, self.window.row0 as f64);
        Ray {
            u: Axis::new((ray.u.o - c0) * f, ray.u.d * f),
            v: Axis::new((ray.v.o - r0) * f, ray.v.d * f),
            ..*ray
        }
    }
}

/// What a region gives a ray that came down to one of its parent's cells.
pub enum Entered {
    /// The ray hits the region.
    Hit(Hit),
    /// The ray crosses the region without a hit and leaves its box at this `τ`: the parent
    /// goes on from there.
    Passed(f64),
    /// The ray is no longer inside the region's box (it left it at or before now): the parent
    /// goes on, without testing the cover.
    Left,
    /// The region's cells are not wanted (range thresholds): the parent's cover stands for it.
    Coarse,
}

/// The region `child` of the tile set being marched with `plan` (whose range thresholds decide
/// whether its cells are wanted), for `ray` over `span` at parent time `now`, counting the
/// cells its march visits into `steps`.
pub fn enter(
    ray: &Ray,
    span: Span,
    now: f64,
    child: &mut Child,
    plan: &Plan,
    steps: &mut u64,
) -> Result<Entered> {
    let inner = child.ray(ray);
    let (w, h) = (child.sampler.size(0).0, child.sampler.size(0).1);
    let (a, b) = inner.u.slab(w);
    let (c, d) = inner.v.slab(h);
    let (t0, t1) = (a.max(c).max(span.t0), b.min(d).min(span.t1));
    if t1 <= t0 || t1 <= now {
        return Ok(Entered::Left);
    }
    if let Some(th) = &plan.thresholds {
        // Ranges only grow along a ray: past the threshold at the region's entry, the parent's
        // cells are under a pixel all through it.
        if ray.range(t0) > th[0] {
            return Ok(Entered::Coarse);
        }
    }
    let (hit, n) = march(&inner, Span { t0, t1 }, &mut child.sampler, child.plan)?;
    *steps += n;
    Ok(match hit {
        Some(hit) => Entered::Hit(hit),
        None => Entered::Passed(t1),
    })
}
