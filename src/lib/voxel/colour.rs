//! Colouring a carved volume from its views, with visibility.
//!
//! # Rule
//! A surface voxel takes the rounded mean RGB of the pixels it lands in (pixel `(⌊u⌋, ⌊v⌋)` of
//! its centre) over the views that **see** it: its centre is in front of the camera, inside the
//! image and the silhouette, and from the centre of one of its exposed faces that faces the
//! camera the ray to the camera (3-D DDA through the voxel grid) meets no solid voxel before the
//! camera or the grid's edge. A voxel seen by no view, and every interior voxel, gets the `fill`
//! colour, so a hidden voxel never takes the colour of the voxel that hides it.

use super::camera::Camera;
use super::carve::View;
use super::grid::VoxelGrid;
use super::object::VoxelObject;
use super::occupancy::Occupancy;
use super::picture::Picture;
use rayon::prelude::*;

/// Counts from a colouring pass.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct ColourStats {
    /// Surface voxels (solid, an empty 6-neighbour).
    pub surface: usize,
    /// Surface voxels seen by at least one view.
    pub seen: usize,
    /// Surface voxels seen by no view (given the fill colour).
    pub unseen: usize,
}

/// Colour `occupancy` from `views` and their `images` (same order; a pixel counts only where both
/// the image and the silhouette have it); `fill` is the
/// colour of interior and unseen voxels. Parallel over y-slabs, deterministic.
pub fn colour(
    grid: VoxelGrid,
    occupancy: Occupancy,
    views: &[View],
    images: &[Picture],
    fill: [u8; 3],
) -> (VoxelObject, ColourStats) {
    assert_eq!(views.len(), images.len(), "one image per view");
    let slabs: Vec<(Vec<[u8; 3]>, usize, usize)> = (0..grid.dims[1])
        .into_par_iter()
        .map(|y| {
            let (mut out, mut surface, mut seen) = (Vec::new(), 0, 0);
            for x in 0..grid.dims[0] {
                for z in 0..grid.dims[2] {
                    if !occupancy.get_index(grid.index(x, y, z)) {
                        continue;
                    }
                    if !occupancy.is_surface(x, y, z) {
                        out.push(fill);
                        continue;
                    }
                    surface += 1;
                    let mut sum = [0u32; 3];
                    let mut n = 0u32;
                    for (view, img) in views.iter().zip(images) {
                        if let Some(px) = seen_pixel(&grid, &occupancy, view, img, [x, y, z]) {
                            (0..3).for_each(|k| sum[k] += px[k] as u32);
                            n += 1;
                        }
                    }
                    if n == 0 {
                        out.push(fill);
                    } else {
                        seen += 1;
                        out.push(sum.map(|s| ((s + n / 2) / n) as u8));
                    }
                }
            }
            (out, surface, seen)
        })
        .collect();
    let surface = slabs.iter().map(|s| s.1).sum();
    let seen = slabs.iter().map(|s| s.2).sum();
    let colours = slabs.into_iter().flat_map(|s| s.0).collect();
    (
        VoxelObject::new(grid, occupancy, colours),
        ColourStats {
            surface,
            seen,
            unseen: surface - seen,
        },
    )
}

/// The image pixel `view` sees voxel `v` through, or `None` when it does not see it.
fn seen_pixel(
    grid: &VoxelGrid,
    occ: &Occupancy,
    view: &View,
    img: &Picture,
    v: [u32; 3],
) -> Option<[u8; 4]> {
    let c = grid.centre(v[0], v[1], v[2]);
    let [u, w] = view.camera.project(c)?;
    let s = &view.silhouette;
    let (width, height) = (
        img.width.min(s.width()) as f64,
        img.height.min(s.height()) as f64,
    );
    if !(u >= 0.0 && w >= 0.0 && u < width && w < height) {
        return None;
    }
    let (col, row) = (u as u32, w as u32);
    if !s.contains(col, row) || !visible(grid, occ, &view.camera, c, v) {
        return None;
    }
    Some(img.get(col, row))
}

/// Can `camera` see voxel `v` (centre `c`)? Light leaves a voxel through an exposed face (one
/// whose neighbour is empty or outside the grid) that faces the camera; the voxel is seen when
/// the ray from the centre of such a face towards the camera crosses no solid voxel before it
/// reaches the camera or leaves the grid. Starting on the face, not at the centre, keeps the
/// staircase neighbours of a slanted surface from hiding it at grazing angles.
fn visible(grid: &VoxelGrid, occ: &Occupancy, camera: &Camera, c: [f64; 3], v: [u32; 3]) -> bool {
    let (dir, _) = camera.towards(c);
    let s = grid.voxel_size;
    (0..6).any(|f| {
        let (a, sign) = (f / 2, if f % 2 == 0 { -1i64 } else { 1 });
        if dir[a] * sign as f64 <= 0.0 {
            return false; // this face looks away from the camera
        }
        let mut nb = v.map(|i| i as i64);
        nb[a] += sign;
        if occ.get(nb[0], nb[1], nb[2]) {
            return false; // not exposed
        }
        if nb[a] < 0 || nb[a] >= grid.dims[a] as i64 {
            return true; // the face is on the grid's edge: nothing beyond can hide it
        }
        let mut face = c;
        face[a] += sign as f64 * s / 2.0;
        let (d, dist) = camera.towards(face);
        // Start position in voxel units: on the face, inside the empty neighbour.
        let mut start = v.map(|i| i as f64 + 0.5);
        start[a] += sign as f64 * 0.5;
        !occluded(grid, occ, nb, start, d, dist / s)
    })
}

/// Does the ray `start + t·dir` (voxel units, `dir` unit), starting in empty voxel `cell`, meet a
/// solid voxel for `t < t_end`? Amanatides–Woo traversal; ties step the lowest axis first.
fn occluded(
    grid: &VoxelGrid,
    occ: &Occupancy,
    mut cell: [i64; 3],
    start: [f64; 3],
    dir: [f64; 3],
    t_end: f64,
) -> bool {
    let dims = grid.dims.map(|d| d as i64);
    let mut t_next = [f64::INFINITY; 3];
    let mut t_step = [0.0f64; 3];
    let mut step = [0i64; 3];
    for a in 0..3 {
        if dir[a] != 0.0 {
            step[a] = if dir[a] > 0.0 { 1 } else { -1 };
            t_step[a] = 1.0 / dir[a].abs();
            let boundary = if dir[a] > 0.0 {
                (cell[a] + 1) as f64
            } else {
                cell[a] as f64
            };
            t_next[a] = ((boundary - start[a]) / dir[a]).max(0.0);
        }
    }
    loop {
        let a = if t_next[0] <= t_next[1] && t_next[0] <= t_next[2] {
            0
        } else if t_next[1] <= t_next[2] {
            1
        } else {
            2
        };
        if t_next[a] >= t_end {
            return false; // reached the camera
        }
        cell[a] += step[a];
        if cell[a] < 0 || cell[a] >= dims[a] {
            return false; // left the grid: nothing more can occlude
        }
        if occ.get(cell[0], cell[1], cell[2]) {
            return true;
        }
        t_next[a] += t_step[a];
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::voxel::silhouette::Silhouette;

    fn flat(colour: [u8; 4], w: u32, h: u32) -> Picture {
        Picture {
            width: w,
            height: h,
            pixels: vec![colour; (w * h) as usize],
        }
    }

    #[test]
    fn hidden_voxels_do_not_take_the_occluders_colour() {
        // Two walls across x (x = 2..=3 and x = 6..=7); a red view from −x, a blue view from +x.
        let g = VoxelGrid::new([0.0; 3], 1.0, [10, 4, 4]).unwrap();
        let occ = Occupancy::from_fn(&g, |p| {
            (2.0..4.0).contains(&p[0]) || (6.0..8.0).contains(&p[0])
        });
        let sil = || Silhouette::new(16, 16, vec![true; 256]);
        let from_west =
            Camera::orthographic([1.0, 0.0, 0.0], None, 4.0, [5.0, 2.0, 2.0], 8.0, 8.0).unwrap();
        let from_east = Camera::look_at(
            40.0,
            40.0,
            8.0,
            8.0,
            [30.0, 2.0, 2.0],
            [5.0, 2.0, 2.0],
            None,
        )
        .unwrap();
        let views = vec![
            View {
                camera: from_west,
                silhouette: sil(),
            },
            View {
                camera: from_east,
                silhouette: sil(),
            },
        ];
        let images = vec![
            flat([255, 0, 0, 255], 16, 16),
            flat([0, 0, 255, 255], 16, 16),
        ];
        let fill = [9, 9, 9];
        let (obj, stats) = colour(g, occ, &views, &images, fill);
        let rank = crate::voxel::occupancy::Rank::new(&obj.occupancy);
        let at = |x| obj.colour_at(&rank, x, 1, 1).unwrap();
        assert_eq!(at(2), [255, 0, 0], "west face seen by the red view");
        assert_eq!(
            at(3),
            fill,
            "east face of the first wall is hidden from both views"
        );
        assert_eq!(
            at(6),
            fill,
            "west face of the second wall is behind the first wall"
        );
        assert_eq!(at(7), [0, 0, 255], "east face seen by the blue view");
        assert_eq!(
            stats.surface,
            obj.len(),
            "4 voxels thick: every voxel touches the grid edge or air"
        );
        assert_eq!(stats.seen + stats.unseen, stats.surface);
    }

    #[test]
    fn a_top_view_sees_exactly_the_top_of_every_column_of_a_ball() {
        // Face-based visibility: the staircase of a curved surface does not hide its own voxels.
        let g = VoxelGrid::covering([-1.0; 3], [1.0; 3], 2.0 / 32.0).unwrap();
        let occ = Occupancy::from_fn(&g, |p| p[0] * p[0] + p[1] * p[1] + p[2] * p[2] <= 0.81);
        let top = Camera::orthographic([0.0, 0.0, -1.0], None, 20.0, [0.0; 3], 25.0, 25.0).unwrap();
        let views = vec![View {
            camera: top,
            silhouette: Silhouette::new(50, 50, vec![true; 2500]),
        }];
        let columns = (0..32u32)
            .flat_map(|y| (0..32u32).map(move |x| (x, y)))
            .filter(|&(x, y)| (0..32).any(|z| occ.get(x as i64, y as i64, z)))
            .count();
        let (_, stats) = colour(g, occ, &views, &[flat([1, 2, 3, 255], 50, 50)], [0; 3]);
        assert_eq!(stats.seen, columns);
    }

    #[test]
    fn colour_is_the_mean_of_the_seeing_views() {
        let g = VoxelGrid::new([0.0; 3], 1.0, [1, 1, 1]).unwrap();
        let occ = Occupancy::from_fn(&g, |_| true);
        let sil = || Silhouette::new(4, 4, vec![true; 16]);
        let cams = [[0.0, 0.0, -1.0], [1.0, 0.0, 0.0]]
            .map(|d| Camera::orthographic(d, None, 2.0, [0.5; 3], 2.0, 2.0).unwrap());
        let views: Vec<View> = cams
            .into_iter()
            .map(|camera| View {
                camera,
                silhouette: sil(),
            })
            .collect();
        let images = vec![
            flat([100, 0, 51, 255], 4, 4),
            flat([201, 10, 50, 255], 4, 4),
        ];
        let (obj, stats) = colour(g, occ, &views, &images, [0; 3]);
        assert_eq!(obj.colours, vec![[151, 5, 51]]);
        assert_eq!(
            stats,
            ColourStats {
                surface: 1,
                seen: 1,
                unseen: 0
            }
        );
    }
}
