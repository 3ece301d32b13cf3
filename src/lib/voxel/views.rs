//! `VIEWS.json`: the calibrated views `dbms sculpt` carves from (spec: `docs/sculpt.md`, schema:
//! `schemas/views.schema.json`).
//!
//! # Rules
//! * Paths are relative to the directory of the `VIEWS.json` file.
//! * A silhouette comes from a `mask` image (a pixel is object when its alpha ≥ 128 and its mean
//!   of R, G, B ≥ 128) or from a background `key` (object when alpha ≥ 128 and some channel
//!   differs from the key colour by more than `tolerance`); exactly one of the two.
//! * Pinhole cameras give `fx`, `fy` (pixels), optional `cx`, `cy` (default: the image centre,
//!   `width/2`, `height/2`) and either `R` (3×3, world → camera, rows) with `t`, or `position`
//!   and `look_at` with optional `up`. Orthographic cameras give `direction`, optional `up`,
//!   `scale` (pixels per metre) and optional `centre` (world point at `(cx, cy)`, default origin).

use super::camera::Camera;
use super::carve::View;
use super::picture::Picture;
use super::silhouette::Silhouette;
use crate::error::{Error, Result};
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// The whole file: the views and, optionally, the box to carve.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ViewsFile {
    /// The views, at least one.
    pub views: Vec<ViewSpec>,
    /// `[minx, miny, minz, maxx, maxy, maxz]`, world metres; `--bounds` overrides it.
    #[serde(default)]
    pub bounds: Option<[f64; 6]>,
    /// The schema the file declares (for editors); not used.
    #[serde(default, rename = "$schema")]
    pub schema: Option<String>,
}

/// One view as written in the file.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ViewSpec {
    /// The photograph (PNG, JPEG or TIFF): colour source, and silhouette source with `key`.
    pub image: PathBuf,
    /// A mask image of the same size (white = object).
    #[serde(default)]
    pub mask: Option<PathBuf>,
    /// Background colour key (silhouette = pixels that differ from it).
    #[serde(default)]
    pub key: Option<Key>,
    /// The camera that took `image`.
    pub camera: CameraSpec,
}

/// A background colour key.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Key {
    /// Background colour `[r, g, b]`.
    pub colour: [u8; 3],
    /// Largest per-channel difference still counted as background (default 0).
    #[serde(default)]
    pub tolerance: u8,
}

/// A camera as written in the file (see the module rules).
#[derive(Debug, Clone, Deserialize)]
#[serde(tag = "type", rename_all = "lowercase", deny_unknown_fields)]
pub enum CameraSpec {
    /// Perspective camera.
    Pinhole {
        /// Focal length along u, pixels.
        fx: f64,
        /// Focal length along v, pixels.
        fy: f64,
        /// Principal point u, pixels (default width/2).
        #[serde(default)]
        cx: Option<f64>,
        /// Principal point v, pixels (default height/2).
        #[serde(default)]
        cy: Option<f64>,
        /// World → camera rotation, rows.
        #[serde(default, rename = "R")]
        r: Option<[[f64; 3]; 3]>,
        /// World → camera translation, metres.
        #[serde(default)]
        t: Option<[f64; 3]>,
        /// Camera centre, world metres.
        #[serde(default)]
        position: Option<[f64; 3]>,
        /// A world point on the optical axis, metres.
        #[serde(default)]
        look_at: Option<[f64; 3]>,
        /// Image up direction (default +z, +y when looking straight down or up).
        #[serde(default)]
        up: Option<[f64; 3]>,
    },
    /// Parallel-projection camera.
    Orthographic {
        /// Viewing direction (world).
        direction: [f64; 3],
        /// Image up direction (default +z, +y when looking straight down or up).
        #[serde(default)]
        up: Option<[f64; 3]>,
        /// Pixels per metre.
        scale: f64,
        /// World point at pixel `(cx, cy)`, metres (default `[0, 0, 0]`).
        #[serde(default)]
        centre: Option<[f64; 3]>,
        /// Pixel u of `centre` (default width/2).
        #[serde(default)]
        cx: Option<f64>,
        /// Pixel v of `centre` (default height/2).
        #[serde(default)]
        cy: Option<f64>,
    },
}

impl CameraSpec {
    /// The camera for an image of `width × height` pixels.
    pub fn build(&self, width: u32, height: u32) -> Result<Camera> {
        let (w2, h2) = (width as f64 / 2.0, height as f64 / 2.0);
        match *self {
            CameraSpec::Pinhole {
                fx,
                fy,
                cx,
                cy,
                r,
                t,
                position,
                look_at,
                up,
            } => {
                let (cx, cy) = (cx.unwrap_or(w2), cy.unwrap_or(h2));
                match (r, t, position, look_at) {
                    (Some(r), Some(t), None, None) if up.is_none() => Camera::pinhole(fx, fy, cx, cy, r, t),
                    (None, None, Some(p), Some(l)) => Camera::look_at(fx, fy, cx, cy, p, l, up),
                    _ => Err(Error::msg(
                        "a pinhole camera needs either \"R\" and \"t\", or \"position\" and \"look_at\" (with optional \"up\")",
                    )
                    .fix("give one of the two forms")),
                }
            }
            CameraSpec::Orthographic {
                direction,
                up,
                scale,
                centre,
                cx,
                cy,
            } => Camera::orthographic(
                direction,
                up,
                scale,
                centre.unwrap_or([0.0; 3]),
                cx.unwrap_or(w2),
                cy.unwrap_or(h2),
            ),
        }
    }
}

impl ViewsFile {
    /// Parse a `VIEWS.json` file: an object `{"views": [...], "bounds": [...]}` or just the list
    /// (a leading UTF-8 byte order mark is skipped).
    pub fn read(path: &Path) -> Result<ViewsFile> {
        let text = crate::io::read_settings(path)?;
        let parsed = if text.trim_start().starts_with('[') {
            serde_json::from_str::<Vec<ViewSpec>>(&text).map(|views| ViewsFile {
                views,
                bounds: None,
                schema: None,
            })
        } else {
            serde_json::from_str::<ViewsFile>(&text)
        };
        let file = parsed.map_err(|e| {
            Error::file(path, format!("not a valid views file: {e}"))
                .fix("see docs/sculpt.md and schemas/views.schema.json")
        })?;
        if file.views.is_empty() {
            return Err(Error::file(path, "the file lists no views").fix("give at least one view"));
        }
        Ok(file)
    }

    /// Every file a run reads through this views file (read from `path`): `path` itself and
    /// each view's image and mask, as [`load`] resolves them — what its outputs must not be.
    pub fn files(&self, path: &Path) -> Vec<PathBuf> {
        let dir = path.parent().unwrap_or(Path::new("."));
        std::iter::once(path.to_path_buf())
            .chain(self.views.iter().flat_map(|v| {
                std::iter::once(dir.join(&v.image)).chain(v.mask.as_ref().map(|m| dir.join(m)))
            }))
            .collect()
    }
}

/// A loaded view: camera, silhouette and the colour image.
pub struct LoadedView {
    /// Camera and silhouette.
    pub view: View,
    /// The photograph, for colour.
    pub image: Picture,
    /// The file the silhouette came from (mask or image), for messages.
    pub silhouette_path: PathBuf,
}

/// Load every view of `file` (read from `path`), checking sizes, cameras and silhouettes.
pub fn load(path: &Path, file: &ViewsFile) -> Result<Vec<LoadedView>> {
    let dir = path.parent().unwrap_or(Path::new("."));
    file.views
        .iter()
        .enumerate()
        .map(|(i, spec)| {
            let in_view = |e: Error, p: &Path| Error {
                problem: format!("view {i}: {}", e.problem),
                ..e.in_file(p)
            };
            let image_path = dir.join(&spec.image);
            let image = Picture::read(&image_path).map_err(|e| in_view(e, &image_path))?;
            let camera = spec
                .camera
                .build(image.width, image.height)
                .map_err(|e| in_view(e, path))?;
            let (inside, silhouette_path): (Vec<bool>, PathBuf) = match (&spec.mask, &spec.key) {
                (Some(m), None) => {
                    let mask_path = dir.join(m);
                    let mask = Picture::read(&mask_path).map_err(|e| in_view(e, &mask_path))?;
                    if (mask.width, mask.height) != (image.width, image.height) {
                        return Err(Error::file(
                            &mask_path,
                            format!(
                                "view {i}: mask is {}×{} pixels but the image is {}×{}",
                                mask.width, mask.height, image.width, image.height
                            ),
                        )
                        .fix("give a mask of the image's size"));
                    }
                    let on = |p: &[u8; 4]| {
                        p[3] >= 128 && (p[0] as u32 + p[1] as u32 + p[2] as u32) >= 3 * 128
                    };
                    (mask.pixels.iter().map(on).collect(), mask_path)
                }
                (None, Some(k)) => {
                    let on = |p: &[u8; 4]| {
                        p[3] >= 128 && (0..3).any(|c| p[c].abs_diff(k.colour[c]) > k.tolerance)
                    };
                    (image.pixels.iter().map(on).collect(), image_path.clone())
                }
                _ => {
                    return Err(Error::file(
                        path,
                        format!("view {i}: give exactly one of \"mask\" and \"key\""),
                    )
                    .fix("see docs/sculpt.md"))
                }
            };
            let silhouette = Silhouette::new(image.width, image.height, inside);
            if silhouette.area() == 0 {
                return Err(Error::file(
                    &silhouette_path,
                    format!("view {i}: the silhouette is empty, so it would carve away everything"),
                )
                .fix(if spec.key.is_some() {
                    "check the key colour and lower the tolerance (pixels within it of the key are background)"
                } else {
                    "check the mask (white = object)"
                }));
            }
            Ok(LoadedView {
                view: View { camera, silhouette },
                image,
                silhouette_path,
            })
        })
        .collect()
}
