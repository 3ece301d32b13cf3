//! Camera models that map world points (metres) to image pixels and pixels back to rays.
//!
//! # Conventions (the invariant carving, colouring and the test renderer share)
//! * Pixel space: `(u, v)` with `(0, 0)` the top-left **corner** of the image, `u` to the right,
//!   `v` down; pixel `(col, row)` covers `[col, col+1) × [row, row+1)` and its centre is at
//!   `(col + 0.5, row + 0.5)` (the same corner convention as [`crate::grid`]). A point lands in
//!   pixel `(⌊u⌋, ⌊v⌋)`.
//! * Camera frame (OpenCV): x right, y down, z forward along the viewing direction.
//! * Pinhole: `q = R · (X − C)` with `C = −Rᵀ t` the camera centre, `u = fx · qx/qz + cx`,
//!   `v = fy · qy/qz + cy`. A point with depth `qz ≤` [`NEAR`] is **behind** the camera and has no
//!   projection. Orthographic: `u = cx + scale · (X − centre)·right`, `v = cy + scale · (X − centre)·down`;
//!   nothing is behind an orthographic camera.
//! * Every constructor rejects a camera that is not invertible (zero focal length or scale, a
//!   singular or non-rotation `R`, an up vector parallel to the viewing direction) with an error.

use super::vec3::{add_scaled, cross, dot, norm, sub, unit};
use crate::error::{Error, Result};

/// Depth (metres along the viewing direction) at or below which a point is behind a pinhole camera.
pub const NEAR: f64 = 1e-6;

/// A calibrated camera: where every world point lands in its image.
#[derive(Debug, Clone, PartialEq)]
pub enum Camera {
    /// Perspective projection through a centre.
    Pinhole(Pinhole),
    /// Parallel projection along one direction.
    Orthographic(Orthographic),
}

/// A pinhole camera (see module conventions).
#[derive(Debug, Clone, PartialEq)]
pub struct Pinhole {
    /// Focal lengths in pixels, > 0.
    pub fx: f64,
    /// Focal length along v, pixels, > 0.
    pub fy: f64,
    /// Principal point u, pixels.
    pub cx: f64,
    /// Principal point v, pixels.
    pub cy: f64,
    /// World → camera rotation; its rows are the camera's right, down and forward axes.
    pub r: [[f64; 3]; 3],
    /// Camera centre in world coordinates, metres.
    pub centre: [f64; 3],
}

/// An orthographic camera (see module conventions).
#[derive(Debug, Clone, PartialEq)]
pub struct Orthographic {
    /// Unit viewing direction (world).
    pub forward: [f64; 3],
    /// Unit world direction of increasing `u`.
    pub right: [f64; 3],
    /// Unit world direction of increasing `v`.
    pub down: [f64; 3],
    /// World point (metres) that projects to `(cx, cy)`.
    pub centre: [f64; 3],
    /// Pixels per metre, > 0.
    pub scale: f64,
    /// Pixel u of `centre`.
    pub cx: f64,
    /// Pixel v of `centre`.
    pub cy: f64,
}

/// A ray `origin + t · dir` for `t` in `t_min..t_max` (metres when `dir` is a unit vector).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ray {
    /// Start point, world metres.
    pub origin: [f64; 3],
    /// Direction (not necessarily unit).
    pub dir: [f64; 3],
    /// Smallest parameter on the ray.
    pub t_min: f64,
    /// Largest parameter on the ray.
    pub t_max: f64,
}

const DEFAULT_UP: [f64; 3] = [0.0, 0.0, 1.0];

impl Camera {
    /// A pinhole camera from intrinsics (pixels) and the world → camera rotation `r` and
    /// translation `t` (OpenCV: `q = R·X + t`).
    pub fn pinhole(
        fx: f64,
        fy: f64,
        cx: f64,
        cy: f64,
        r: [[f64; 3]; 3],
        t: [f64; 3],
    ) -> Result<Camera> {
        check_intrinsics(fx, fy, cx, cy)?;
        check_rotation(&r)?;
        if t.iter().any(|v| !v.is_finite()) {
            return Err(Error::msg("camera translation t is not finite"));
        }
        // C = −Rᵀ t
        let centre = [0, 1, 2].map(|j| -(r[0][j] * t[0] + r[1][j] * t[1] + r[2][j] * t[2]));
        Ok(Camera::Pinhole(Pinhole {
            fx,
            fy,
            cx,
            cy,
            r,
            centre,
        }))
    }

    /// A pinhole camera at `position` looking at `target` (world metres). `up` (default +z) sets
    /// the image's up direction; see [`orientation`] for a view straight down or up.
    pub fn look_at(
        fx: f64,
        fy: f64,
        cx: f64,
        cy: f64,
        position: [f64; 3],
        target: [f64; 3],
        up: Option<[f64; 3]>,
    ) -> Result<Camera> {
        check_intrinsics(fx, fy, cx, cy)?;
        if position.iter().chain(&target).any(|v| !v.is_finite()) {
            return Err(Error::msg("camera position or look_at is not finite"));
        }
        let forward = unit(sub(target, position)).ok_or_else(|| {
            Error::msg("camera position equals look_at: no viewing direction")
                .fix("give a look_at point away from the position")
        })?;
        let r = orientation(forward, up)?;
        Ok(Camera::Pinhole(Pinhole {
            fx,
            fy,
            cx,
            cy,
            r,
            centre: position,
        }))
    }

    /// An orthographic camera looking along `direction`, `scale` pixels per metre, with world
    /// point `centre` at pixel `(cx, cy)`.
    pub fn orthographic(
        direction: [f64; 3],
        up: Option<[f64; 3]>,
        scale: f64,
        centre: [f64; 3],
        cx: f64,
        cy: f64,
    ) -> Result<Camera> {
        if !(scale.is_finite() && scale > 0.0) {
            return Err(Error::msg(format!(
                "orthographic scale {scale} is not a positive number of pixels per metre"
            ))
            .fix("give \"scale\" > 0"));
        }
        if centre.iter().chain(&[cx, cy]).any(|v| !v.is_finite()) {
            return Err(Error::msg("orthographic centre, cx or cy is not finite"));
        }
        let forward = unit(direction).ok_or_else(|| {
            Error::msg("orthographic direction is zero").fix("give a non-zero \"direction\"")
        })?;
        let [right, down, forward] = orientation(forward, up)?;
        Ok(Camera::Orthographic(Orthographic {
            forward,
            right,
            down,
            centre,
            scale,
            cx,
            cy,
        }))
    }

    /// Depth of world point `p` along the viewing direction, metres (negative behind a pinhole
    /// camera; for an orthographic camera, relative to its centre).
    #[inline]
    pub fn depth(&self, p: [f64; 3]) -> f64 {
        match self {
            Camera::Pinhole(c) => dot(c.r[2], sub(p, c.centre)),
            Camera::Orthographic(c) => dot(c.forward, sub(p, c.centre)),
        }
    }

    /// Pixel position `(u, v)` of world point `p`, or `None` when `p` is behind a pinhole camera.
    #[inline]
    pub fn project(&self, p: [f64; 3]) -> Option<[f64; 2]> {
        match self {
            Camera::Pinhole(c) => {
                let d = sub(p, c.centre);
                let z = dot(c.r[2], d);
                (z > NEAR).then(|| {
                    [
                        c.fx * dot(c.r[0], d) / z + c.cx,
                        c.fy * dot(c.r[1], d) / z + c.cy,
                    ]
                })
            }
            Camera::Orthographic(c) => {
                let d = sub(p, c.centre);
                Some([
                    c.cx + c.scale * dot(c.right, d),
                    c.cy + c.scale * dot(c.down, d),
                ])
            }
        }
    }

    /// The ray of world points that project to pixel position `(u, v)`: from the camera centre
    /// forward for a pinhole camera, the whole line for an orthographic one.
    pub fn ray(&self, u: f64, v: f64) -> Ray {
        match self {
            Camera::Pinhole(c) => {
                let q = [(u - c.cx) / c.fx, (v - c.cy) / c.fy, 1.0];
                let dir = [0, 1, 2].map(|j| c.r[0][j] * q[0] + c.r[1][j] * q[1] + c.r[2][j] * q[2]);
                Ray {
                    origin: c.centre,
                    dir,
                    t_min: 0.0,
                    t_max: f64::INFINITY,
                }
            }
            Camera::Orthographic(c) => {
                let o = add_scaled(c.centre, (u - c.cx) / c.scale, c.right);
                Ray {
                    origin: add_scaled(o, (v - c.cy) / c.scale, c.down),
                    dir: c.forward,
                    t_min: f64::NEG_INFINITY,
                    t_max: f64::INFINITY,
                }
            }
        }
    }

    /// Unit direction from world point `p` towards the camera and the distance (metres) to it
    /// (infinite for an orthographic camera): the path light takes from `p` to the image.
    pub fn towards(&self, p: [f64; 3]) -> ([f64; 3], f64) {
        match self {
            Camera::Pinhole(c) => {
                let d = sub(c.centre, p);
                let n = norm(d);
                if n > 0.0 {
                    ([d[0] / n, d[1] / n, d[2] / n], n)
                } else {
                    ([0.0, 0.0, 1.0], 0.0)
                }
            }
            Camera::Orthographic(c) => (c.forward.map(|v| -v), f64::INFINITY),
        }
    }
}

/// The rows (right, down, forward) of the rotation of a camera looking along unit `forward`
/// with image-up `up`. Default up is +z; a view within 1e-6 rad of straight down or up with the
/// default gets +y (north) as up, so a top view is a map with north at the top. An explicit up
/// parallel to the viewing direction is an error.
pub fn orientation(forward: [f64; 3], up: Option<[f64; 3]>) -> Result<[[f64; 3]; 3]> {
    let up_vec = match up {
        Some(u) => unit(u)
            .ok_or_else(|| Error::msg("camera up vector is zero").fix("give a non-zero \"up\""))?,
        None if norm(cross(forward, DEFAULT_UP)) < 1e-6 => [0.0, 1.0, 0.0],
        None => DEFAULT_UP,
    };
    let right = unit(cross(forward, up_vec)).filter(|_| norm(cross(forward, up_vec)) >= 1e-6).ok_or_else(|| {
        Error::msg("camera up vector is parallel to the viewing direction: the image orientation is undefined")
            .fix("give an \"up\" across the view, e.g. [0,1,0] for a view straight down")
    })?;
    Ok([right, cross(forward, right), forward])
}

fn check_intrinsics(fx: f64, fy: f64, cx: f64, cy: f64) -> Result<()> {
    if !(fx.is_finite() && fy.is_finite() && fx > 0.0 && fy > 0.0) {
        return Err(Error::msg(format!(
            "focal lengths fx={fx}, fy={fy} must be positive pixels: the camera is not invertible"
        ))
        .fix("give fx and fy > 0 (pixels)"));
    }
    if !(cx.is_finite() && cy.is_finite()) {
        return Err(Error::msg("principal point cx, cy is not finite"));
    }
    Ok(())
}

fn check_rotation(r: &[[f64; 3]; 3]) -> Result<()> {
    if r.iter().flatten().any(|v| !v.is_finite()) {
        return Err(Error::msg("rotation R is not finite"));
    }
    let det = dot(r[0], cross(r[1], r[2]));
    if det.abs() < 1e-9 {
        return Err(Error::msg(
            "rotation R is singular (determinant 0): the camera is not invertible",
        )
        .fix("give R as a 3×3 rotation matrix, rows orthonormal"));
    }
    let orthonormal = (0..3)
        .all(|i| (0..3).all(|j| (dot(r[i], r[j]) - if i == j { 1.0 } else { 0.0 }).abs() < 1e-6));
    if !orthonormal || det < 0.0 {
        return Err(Error::msg(format!("R is not a rotation (rows must be orthonormal with determinant +1; determinant is {det:.6})"))
            .fix("give R as a proper 3×3 rotation matrix, world → camera"));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: [f64; 2], b: [f64; 2]) -> bool {
        (a[0] - b[0]).abs() < 1e-9 && (a[1] - b[1]).abs() < 1e-9
    }

    #[test]
    fn look_at_projects_target_to_principal_point_and_up_to_top() {
        let c = Camera::look_at(
            500.0,
            500.0,
            320.0,
            240.0,
            [0.0, -10.0, 0.0],
            [0.0, 0.0, 0.0],
            None,
        )
        .unwrap();
        assert!(close(c.project([0.0, 0.0, 0.0]).unwrap(), [320.0, 240.0]));
        let up = c.project([0.0, 0.0, 1.0]).unwrap();
        assert!(
            up[1] < 240.0 && (up[0] - 320.0).abs() < 1e-9,
            "up should be up in the image: {up:?}"
        );
        let east = c.project([1.0, 0.0, 0.0]).unwrap();
        assert!(east[0] > 320.0, "looking north, east is to the right");
        assert_eq!(c.project([0.0, -11.0, 0.0]), None, "behind the camera");
    }

    #[test]
    fn ray_through_projection_contains_the_point() {
        let cams = [
            Camera::look_at(
                400.0,
                380.0,
                100.5,
                90.25,
                [3.0, -7.0, 4.0],
                [0.2, 0.1, 0.3],
                Some([0.1, 0.0, 1.0]),
            )
            .unwrap(),
            Camera::orthographic([1.0, 2.0, -3.0], None, 37.0, [0.5, 0.5, 0.5], 64.0, 60.0)
                .unwrap(),
        ];
        for c in &cams {
            for p in [[0.3, -0.2, 0.9], [1.0, 1.0, -1.0], [-0.5, 0.25, 0.0]] {
                let [u, v] = c.project(p).unwrap();
                let r = c.ray(u, v);
                // The distance from p to the ray's line is zero.
                let d = sub(p, r.origin);
                let dist = norm(cross(d, r.dir)) / norm(r.dir);
                assert!(dist < 1e-9, "{dist}");
                let t = dot(d, r.dir) / dot(r.dir, r.dir);
                assert!(t >= r.t_min && t <= r.t_max);
            }
        }
    }

    #[test]
    fn r_t_form_matches_look_at_form() {
        let a = Camera::look_at(
            300.0,
            300.0,
            50.0,
            50.0,
            [500_010.0, 5_000_000.0, 120.0],
            [500_000.0, 5_000_000.0, 100.0],
            None,
        )
        .unwrap();
        let Camera::Pinhole(p) = &a else {
            unreachable!()
        };
        let t = [0, 1, 2].map(|i| -dot(p.r[i], p.centre));
        let b = Camera::pinhole(300.0, 300.0, 50.0, 50.0, p.r, t).unwrap();
        let x = [500_001.0, 5_000_000.5, 101.0];
        let (pa, pb) = (a.project(x).unwrap(), b.project(x).unwrap());
        // UTM-sized coordinates: agreement to a thousandth of a pixel.
        assert!(
            (pa[0] - pb[0]).abs() < 1e-3 && (pa[1] - pb[1]).abs() < 1e-3,
            "{pa:?} {pb:?}"
        );
    }

    #[test]
    fn straight_down_view_defaults_to_north_up() {
        let c = Camera::look_at(
            100.0,
            100.0,
            50.0,
            50.0,
            [0.0, 0.0, 10.0],
            [0.0, 0.0, 0.0],
            None,
        )
        .unwrap();
        let n = c.project([0.0, 1.0, 0.0]).unwrap();
        let e = c.project([1.0, 0.0, 0.0]).unwrap();
        assert!(
            n[1] < 50.0 && e[0] > 50.0,
            "north up, east right: {n:?} {e:?}"
        );
        let err = Camera::look_at(
            100.0,
            100.0,
            50.0,
            50.0,
            [0.0, 0.0, 10.0],
            [0.0, 0.0, 0.0],
            Some([0.0, 0.0, 1.0]),
        )
        .unwrap_err();
        assert!(err.to_string().contains("parallel"), "{err}");
    }

    #[test]
    fn non_invertible_cameras_are_errors() {
        let id = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        assert!(Camera::pinhole(0.0, 100.0, 0.0, 0.0, id, [0.0; 3])
            .unwrap_err()
            .to_string()
            .contains("not invertible"));
        let singular = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 1.0, 0.0]];
        assert!(Camera::pinhole(100.0, 100.0, 0.0, 0.0, singular, [0.0; 3])
            .unwrap_err()
            .to_string()
            .contains("singular"));
        let scaled = [[2.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        assert!(Camera::pinhole(100.0, 100.0, 0.0, 0.0, scaled, [0.0; 3]).is_err());
        let mirror = [[-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        assert!(Camera::pinhole(100.0, 100.0, 0.0, 0.0, mirror, [0.0; 3]).is_err());
        assert!(Camera::look_at(100.0, 100.0, 0.0, 0.0, [1.0; 3], [1.0; 3], None).is_err());
        assert!(Camera::orthographic([0.0; 3], None, 1.0, [0.0; 3], 0.0, 0.0).is_err());
        assert!(Camera::orthographic([1.0, 0.0, 0.0], None, 0.0, [0.0; 3], 0.0, 0.0).is_err());
    }
}
