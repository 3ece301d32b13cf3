//! The pinhole camera: eye, attitude and field of view to one world ray per pixel.
//!
//! Conventions (world frame x east, y north, z up):
//! * **yaw**: heading of the view, degrees clockwise from north (0 north, 90 east);
//! * **pitch**: degrees above the horizon, up positive (−90 looks straight down);
//! * **roll**: degrees about the view direction, right wing down positive;
//! * **fov**: horizontal field of view, degrees, in (0, 180); the vertical one follows from the
//!   image's aspect ratio (square pixels).
//!
//! Pixel `(i, j)` (column, row from the top) looks through its centre `(i + 0.5, j + 0.5)`.
//! Invariant: angles that are multiples of 90° give exact axis-aligned directions (sine and
//! cosine of those angles are exact), so an odd-sized image looking due east has a centre ray
//! with no north component at all. [`Basis::through`] is the direction to the image point on a
//! plane at unit distance (not a unit vector): with zero roll and pitch, the points of one image
//! column share their horizontal components bit for bit.

use crate::error::{Error, Result};

/// Orientation of the camera, degrees (see the module docs for the conventions).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Attitude {
    /// Right wing down positive, degrees.
    pub roll: f64,
    /// Up positive, degrees, in [−90, 90].
    pub pitch: f64,
    /// Clockwise from north, degrees.
    pub yaw: f64,
}

/// The preview's pinhole camera: where the eye is, where it looks, and the image it makes
/// (the calibrated cameras of the photos objects are carved from are [`crate::voxel::camera::Camera`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Viewpoint {
    /// Eye position in world coordinates (CRS units; z in metres).
    pub eye: [f64; 3],
    /// Orientation.
    pub attitude: Attitude,
    /// Horizontal field of view, degrees.
    pub hfov: f64,
    /// Image width, pixels.
    pub width: usize,
    /// Image height, pixels.
    pub height: usize,
}

/// The camera's basis: forward, right and up unit vectors in the world frame, and the screen's
/// half extents at unit distance.
#[derive(Debug, Clone, Copy)]
pub struct Basis {
    forward: [f64; 3],
    right: [f64; 3],
    up: [f64; 3],
    half_w: f64,
    half_h: f64,
    width: f64,
    height: f64,
}

/// Sine and cosine of an angle in degrees, exact at multiples of 90°.
fn sin_cos_deg(deg: f64) -> (f64, f64) {
    let q = deg / 90.0;
    if q == q.round() {
        match (q as i64).rem_euclid(4) {
            0 => (0.0, 1.0),
            1 => (1.0, 0.0),
            2 => (0.0, -1.0),
            _ => (-1.0, 0.0),
        }
    } else {
        deg.to_radians().sin_cos()
    }
}

impl Viewpoint {
    /// Check the camera's numbers; errors name the option to fix.
    pub fn validate(&self) -> Result<()> {
        if !self.eye.iter().all(|c| c.is_finite()) {
            return Err(Error::msg("--eye: coordinates must be finite numbers")
                .fix("give X,Y,Z in the database's CRS units and metres"));
        }
        let a = self.attitude;
        if ![a.roll, a.pitch, a.yaw].iter().all(|c| c.is_finite())
            || !(-90.0..=90.0).contains(&a.pitch)
        {
            return Err(Error::msg(format!(
                "--attitude {},{},{}: pitch must be in [-90, 90] and all angles finite",
                a.roll, a.pitch, a.yaw
            ))
            .fix("give ROLL,PITCH,YAW in degrees (yaw clockwise from north, pitch up positive)"));
        }
        if !(self.hfov > 0.0 && self.hfov < 180.0) {
            return Err(Error::msg(format!(
                "--fov {}: must be between 0 and 180 degrees",
                self.hfov
            ))
            .fix("60 is a usual value"));
        }
        check_size(self.width, self.height)
    }

    /// The camera's basis.
    pub fn basis(&self) -> Basis {
        let (sy, cy) = sin_cos_deg(self.attitude.yaw);
        let (sp, cp) = sin_cos_deg(self.attitude.pitch);
        let (sr, cr) = sin_cos_deg(self.attitude.roll);
        let forward = [sy * cp, cy * cp, sp];
        let right0 = [cy, -sy, 0.0];
        let up0 = [-sy * sp, -cy * sp, cp];
        let right = std::array::from_fn(|k| right0[k] * cr - up0[k] * sr);
        let up = std::array::from_fn(|k| up0[k] * cr + right0[k] * sr);
        let half_w = (self.hfov.to_radians() / 2.0).tan();
        Basis {
            forward,
            right,
            up,
            half_w,
            half_h: half_w * self.height as f64 / self.width as f64,
            width: self.width as f64,
            height: self.height as f64,
        }
    }
}

impl Basis {
    /// Unit world direction through the centre of pixel `(i, j)` (column, row from the top):
    /// the tests' reference geometry (the renderer works with [`Basis::through`]).
    #[cfg(test)]
    pub fn direction(&self, i: usize, j: usize) -> [f64; 3] {
        self.direction_at(i as f64 + 0.5, j as f64 + 0.5)
    }

    /// Unit world direction through image point `(x, y)`, in pixels from the image's top-left
    /// corner (pixel `(i, j)` covers `[i, i + 1) × [j, j + 1)`; its centre is `(i + ½, j + ½)`).
    #[cfg(test)]
    pub fn direction_at(&self, x: f64, y: f64) -> [f64; 3] {
        let d = self.through(x, y);
        let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        // An axis-aligned direction stays exact: dividing by a norm of exactly 1 is exact.
        d.map(|c| c / n)
    }

    /// World direction from the eye to image point `(x, y)` (pixels from the image's top-left
    /// corner; pixel `(i, j)` covers `[i, i + 1) × [j, j + 1)`) on the image plane one unit
    /// ahead: `forward + x′·right + y′·up` ([`Basis::through_terms`] of [`Basis::x_term`] and
    /// [`Basis::y_term`]), not normalised. Its horizontal components depend on `x` alone when
    /// `up` is vertical.
    #[inline]
    pub fn through(&self, x: f64, y: f64) -> [f64; 3] {
        self.through_terms(self.x_term(x), self.y_term(y))
    }

    /// `x′`: image point `x` (pixels from the left) on the unit image plane, to the right.
    #[inline]
    pub fn x_term(&self, x: f64) -> f64 {
        (2.0 * x / self.width - 1.0) * self.half_w
    }

    /// `y′`: image point `y` (pixels from the top) on the unit image plane, upward.
    #[inline]
    pub fn y_term(&self, y: f64) -> f64 {
        (1.0 - 2.0 * y / self.height) * self.half_h
    }

    /// Image point `(x, y)` (pixels from the top-left corner, as [`Basis::through`] takes
    /// them) where the world direction `d` from the eye meets the image plane; `None` when `d`
    /// does not point ahead of the camera.
    pub fn project(&self, d: [f64; 3]) -> Option<(f64, f64)> {
        let dot = |a: [f64; 3]| a[0] * d[0] + a[1] * d[1] + a[2] * d[2];
        let f = dot(self.forward);
        if !(f > 0.0) {
            return None;
        }
        let (x, y) = (dot(self.right) / f, dot(self.up) / f);
        Some((
            (x / self.half_w + 1.0) * self.width / 2.0,
            (1.0 - y / self.half_h) * self.height / 2.0,
        ))
    }

    /// `forward + x′·right + y′·up` ([`Basis::through`] with its terms computed once per image
    /// column and row, bit for bit the same).
    #[inline]
    pub fn through_terms(&self, x: f64, y: f64) -> [f64; 3] {
        std::array::from_fn(|k| self.forward[k] + x * self.right[k] + y * self.up[k])
    }
}

/// Check an image size: both sides at least 1 and at most 16384 pixels.
pub fn check_size(width: usize, height: usize) -> Result<()> {
    if width == 0 || height == 0 || width > 16384 || height > 16384 {
        return Err(Error::msg(format!(
            "--size {width}x{height}: each side must be 1 to 16384 pixels"
        ))
        .fix("e.g. --size 640x480"));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cam(roll: f64, pitch: f64, yaw: f64) -> Viewpoint {
        Viewpoint {
            eye: [0.0; 3],
            attitude: Attitude { roll, pitch, yaw },
            hfov: 90.0,
            width: 3,
            height: 3,
        }
    }

    #[test]
    fn yaw_is_clockwise_from_north_and_exact_on_the_axes() {
        assert_eq!(cam(0.0, 0.0, 0.0).basis().direction(1, 1), [0.0, 1.0, 0.0]);
        assert_eq!(cam(0.0, 0.0, 90.0).basis().direction(1, 1), [1.0, 0.0, 0.0]);
        assert_eq!(
            cam(0.0, 0.0, -90.0).basis().direction(1, 1),
            [-1.0, 0.0, 0.0]
        );
        assert_eq!(
            cam(0.0, -90.0, 30.0).basis().direction(1, 1),
            [0.0, 0.0, -1.0]
        );
    }

    #[test]
    fn pitch_up_looks_up_and_the_top_row_is_higher() {
        let b = cam(0.0, 30.0, 0.0).basis();
        assert!((b.direction(1, 1)[2] - 0.5).abs() < 1e-12);
        assert!(b.direction(1, 0)[2] > b.direction(1, 2)[2]);
    }

    #[test]
    fn roll_right_wing_down_lowers_the_right_edge() {
        // Looking north, rolled right wing down: the right-hand pixel column looks lower.
        let b = cam(20.0, 0.0, 0.0).basis();
        assert!(b.direction(2, 1)[2] < 0.0 && b.direction(0, 1)[2] > 0.0);
    }

    #[test]
    fn project_inverts_through_and_refuses_what_is_behind() {
        for (roll, pitch, yaw) in [(0.0, 0.0, 0.0), (10.0, -12.0, 40.0), (-5.0, 30.0, 271.0)] {
            let b = Viewpoint {
                eye: [0.0; 3],
                attitude: Attitude { roll, pitch, yaw },
                hfov: 60.0,
                width: 640,
                height: 400,
            }
            .basis();
            for (x, y) in [(0.0, 0.0), (320.0, 200.0), (639.5, 12.25), (17.0, 399.0)] {
                let d = b.through(x, y).map(|c| c * 37.0);
                let (px, py) = b.project(d).unwrap();
                assert!((px - x).abs() < 1e-9 && (py - y).abs() < 1e-9, "{px} {py}");
                assert_eq!(b.project(d.map(|c| -c)), None);
            }
        }
    }

    #[test]
    fn directions_are_unit_vectors() {
        let b = cam(13.0, -27.0, 211.0).basis();
        for (i, j) in [(0, 0), (2, 1), (1, 2)] {
            let d = b.direction(i, j);
            assert!(((d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt() - 1.0).abs() < 1e-12);
        }
    }

    #[test]
    fn bad_numbers_are_errors() {
        let mut c = cam(0.0, 95.0, 0.0);
        assert!(c.validate().unwrap_err().to_string().contains("pitch"));
        c.attitude.pitch = 0.0;
        c.hfov = 180.0;
        assert!(c.validate().unwrap_err().to_string().contains("--fov"));
        c.hfov = 60.0;
        c.eye[0] = f64::NAN;
        assert!(c.validate().unwrap_err().to_string().contains("--eye"));
    }
}
