//! `dbms render --path`: every frame of a flight rendered in one process, the page cache warm
//! from frame to frame, written as numbered PNG files and, for quick looks, one animated PNG.
//!
//! Invariant: the frames are written and synced under temporary names as they are rendered, and
//! renamed into place only when the last one is: a run killed while rendering leaves the
//! directory's earlier flight whole. The renames run between the removal of the directory's
//! record ([`RECORD_FILE`]: the frames and their SHA-256) and the writing of the new one, so a
//! record always describes the frames beside it; the animation comes last (its rename is the
//! run's end: `make` may take it as the target). Frames are the same bytes on every run, and
//! frame files left from a longer earlier flight in the directory are removed.

use super::{render_view, Frame, ViewOptions, Viewpoint};
use crate::db::fault_point;
use crate::error::{Error, Result};
use crate::io::atomic::{commit_all, write_bytes_atomic, AtomicFile};
use crate::progress::Progress;
use crate::tiles::TileReader;
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// What a flight took (for the summary and `--json`).
#[derive(Debug, Clone, Serialize)]
pub struct FlightStats {
    /// Frames rendered.
    pub frames: usize,
    /// Seconds spent rendering (ray casting, page reads), all frames.
    pub render_seconds: f64,
    /// Frames per second of rendering alone.
    pub frames_per_second: f64,
    /// Seconds of the whole run, encoding and writing included.
    pub total_seconds: f64,
    /// Pages read from the tile file per frame: mean, and the most in one frame (the first
    /// frame fills the cache).
    pub pages_read_per_frame: f64,
    /// The most pages one frame read.
    pub pages_read_max: u64,
    /// Level cells stepped per ray, mean over the flight.
    pub cells_stepped_per_ray: f64,
}

/// The record a flight leaves in its frame directory once every frame is in place
/// (schemas/flight-frames.schema.json): the frame count and size, and each frame file with its
/// SHA-256, so a reader can tell a complete set from a mixed or partial one.
pub const RECORD_FILE: &str = "frames.json";

/// The record of a complete flight ([`RECORD_FILE`]).
#[derive(Debug, Clone, Serialize)]
struct Record {
    /// `dbms-flight-frames`.
    format: &'static str,
    /// 1.
    version: u32,
    /// Frames in the flight.
    frames: usize,
    /// Frame width and height, pixels.
    width: usize,
    height: usize,
    /// Each frame file (its name in the directory) and the hex SHA-256 of its bytes.
    files: Vec<RecordedFrame>,
}

#[derive(Debug, Clone, Serialize)]
struct RecordedFrame {
    file: String,
    sha256: String,
}

/// The file of frame `k` in `dir`.
pub fn frame_file(dir: &Path, k: usize) -> PathBuf {
    dir.join(format!("frame-{k:05}.png"))
}

/// Render `viewpoints` over `reader` with `opts`, each frame finished by `overlay` (e.g. the
/// night-vision view's light points, [`super::sensor::Overlay::draw`]): frame `k`
/// into [`frame_file`]`(dir, k)` (the directory is created), and, given `animation`, every
/// frame into one animated PNG there, shown `1 / fps` seconds each, looping.
pub fn fly(
    reader: &TileReader,
    viewpoints: &[Viewpoint],
    opts: &ViewOptions,
    overlay: &dyn Fn(&mut Frame, &Viewpoint) -> Result<()>,
    dir: &Path,
    animation: Option<(&Path, f64)>,
    progress: &Progress,
) -> Result<FlightStats> {
    let start = Instant::now();
    let (Some(first), false) = (viewpoints.first(), dir.as_os_str().is_empty()) else {
        return Err(Error::msg(
            "a flight needs at least one frame and an output directory",
        ));
    };
    if dir.exists() && !dir.is_dir() {
        return Err(Error::file(dir, "exists and is not a directory")
            .fix("give -o a directory for the frames (created if missing)"));
    }
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let mut animated = match animation {
        Some((path, fps)) => Some(Animation::create(path, first, viewpoints.len(), fps)?),
        None => None,
    };
    let (mut render_seconds, mut pages, mut pages_max, mut steps, mut rays) = (0.0, 0, 0, 0, 0);
    let (mut staged, mut recorded) = (Vec::new(), Vec::new());
    for (k, camera) in viewpoints.iter().enumerate() {
        let mut frame = render_view(reader, camera, opts)
            .map_err(|e| Error::msg(format!("frame {k} (eye {:?}): {e}", camera.eye)))?;
        overlay(&mut frame, camera)
            .map_err(|e| Error::msg(format!("frame {k} (eye {:?}): {e}", camera.eye)))?;
        let s = &frame.stats;
        render_seconds += s.seconds;
        pages += s.reader.pages_read;
        pages_max = pages_max.max(s.reader.pages_read);
        steps += s.cells_stepped;
        rays += s.rays;
        let (file, sha256) = stage_frame(&frame, &frame_file(dir, k), &mut staged)?;
        recorded.push(RecordedFrame { file, sha256 });
        fault_point("flight-frame-staged");
        if let Some(a) = animated.as_mut() {
            a.push(&frame)?;
        }
        progress.inc(1);
    }
    let record = Record {
        format: "dbms-flight-frames",
        version: 1,
        frames: viewpoints.len(),
        width: first.width,
        height: first.height,
        files: recorded,
    };
    let record_file = dir.join(RECORD_FILE);
    match std::fs::remove_file(&record_file) {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
            return Err(Error::io(&record_file, e))
        }
        _ => {}
    }
    commit_all(staged)?;
    remove_stale_frames(dir, viewpoints.len())?;
    fault_point("flight-frames-renamed");
    let json = serde_json::to_vec_pretty(&record).expect("a record serialises");
    write_bytes_atomic(&record_file, &json)?;
    if let Some(a) = animated {
        a.finish()?;
    }
    let frames = viewpoints.len();
    Ok(FlightStats {
        frames,
        render_seconds,
        frames_per_second: frames as f64 / render_seconds.max(1e-9),
        total_seconds: start.elapsed().as_secs_f64(),
        pages_read_per_frame: pages as f64 / frames as f64,
        pages_read_max: pages_max,
        cells_stepped_per_ray: steps as f64 / rays.max(1) as f64,
    })
}

/// Write `frame` as a PNG under a temporary name beside `file`, staged in `staged` for the
/// rename that puts the whole flight in place; returns the file's name and its hex SHA-256.
fn stage_frame(
    frame: &Frame,
    file: &Path,
    staged: &mut Vec<crate::io::atomic::Staged>,
) -> Result<(String, String)> {
    use sha2::Digest;
    let bytes = frame.png()?;
    let mut out = AtomicFile::create(file)?;
    std::io::Write::write_all(out.writer(), &bytes).map_err(|e| Error::io(file, e))?;
    staged.push(out.stage()?);
    let sha = crate::manifest::hex(&sha2::Sha256::digest(&bytes));
    let name = file.file_name().map(|n| n.to_string_lossy().into_owned());
    Ok((name.unwrap_or_default(), sha))
}

/// Remove `frame-NNNNN.png` files numbered `count` or more (left by a longer earlier flight).
fn remove_stale_frames(dir: &Path, count: usize) -> Result<()> {
    for entry in std::fs::read_dir(dir).map_err(|e| Error::io(dir, e))? {
        let path = entry.map_err(|e| Error::io(dir, e))?.path();
        let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
        let index = name
            .strip_prefix("frame-")
            .and_then(|n| n.strip_suffix(".png"))
            .filter(|n| n.len() == 5)
            .and_then(|n| n.parse::<usize>().ok());
        if index.is_some_and(|k| k >= count) {
            std::fs::remove_file(&path).map_err(|e| Error::io(&path, e))?;
        }
    }
    Ok(())
}

/// An animated PNG written frame by frame into a temporary file, renamed into place at the end.
struct Animation {
    writer: png::Writer<std::io::BufWriter<std::fs::File>>,
    staged: AtomicFile,
}

/// The error of encoding the animated PNG at `path`.
fn apng_error(path: &Path, e: png::EncodingError) -> Error {
    Error::file(path, format!("encoding the APNG failed: {e}"))
}

impl Animation {
    fn create(path: &Path, first: &Viewpoint, frames: usize, fps: f64) -> Result<Animation> {
        let mut staged = AtomicFile::create(path)?;
        // The encoder writes through its own handle on the temporary file (the staged one's
        // buffer stays empty); `finish` flushes it, then the commit syncs and renames the file.
        let sink = staged
            .writer()
            .get_ref()
            .try_clone()
            .map_err(|e| Error::io(path, e))?;
        let fail = |e| apng_error(path, e);
        let mut encoder = png::Encoder::new(
            std::io::BufWriter::new(sink),
            first.width as u32,
            first.height as u32,
        );
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        encoder.set_animated(frames as u32, 0).map_err(fail)?;
        let delay_ms = (1000.0 / fps).round().clamp(1.0, u16::MAX as f64) as u16;
        encoder.set_frame_delay(delay_ms, 1000).map_err(fail)?;
        Ok(Animation {
            writer: encoder.write_header().map_err(fail)?,
            staged,
        })
    }

    fn push(&mut self, frame: &Frame) -> Result<()> {
        self.writer
            .write_image_data(frame.rgb_bytes())
            .map_err(|e| apng_error(self.staged.path(), e))
    }

    fn finish(self) -> Result<()> {
        let Animation { writer, staged } = self;
        writer.finish().map_err(|e| apng_error(staged.path(), e))?;
        staged.commit()
    }
}
