//! `dbms render`: a ray-cast preview of a tile set, perspective or top-down.

use super::Ctx;
use dbms::grid::Bounds;
use dbms::render::flight::FlightStats;
use dbms::render::sensor::{IrScale, Overlay, Sensor, SensorOptions};
use dbms::render::sky::Backdrop;
use dbms::render::{self, Attitude, RenderStats, Traversal, ViewOptions, Viewpoint};
use dbms::tiles::TileReader;
use dbms::Error;
use std::path::PathBuf;

/// Ray-cast a view of a tile set (or, with --top, an orthographic map of all of it) to PNG.
#[derive(clap::Args)]
pub struct Args {
    /// The tile file (written by `dbms pyramid`).
    #[arg(long)]
    tiles: PathBuf,
    /// Eye position X,Y,Z: CRS units and metres.
    #[arg(
        long,
        value_name = "X,Y,Z",
        required_unless_present_any = ["top", "path"],
        allow_hyphen_values = true
    )]
    eye: Option<String>,
    /// ROLL,PITCH,YAW in degrees: roll right wing down positive, pitch up positive, yaw clockwise from north.
    #[arg(
        long,
        value_name = "ROLL,PITCH,YAW",
        default_value = "0,0,0",
        allow_hyphen_values = true
    )]
    attitude: String,
    /// Horizontal field of view, degrees.
    #[arg(long, default_value_t = 60.0, allow_negative_numbers = true)]
    fov: f64,
    /// Image size WxH in pixels (for --top: default the grid's size, at most 1024 on the long side).
    #[arg(long, value_name = "WxH")]
    size: Option<String>,
    /// Also write the range of each pixel, metres, as a one-channel f32 OpenEXR (inf = sky).
    #[arg(long, value_name = "RANGE.exr")]
    range_out: Option<PathBuf>,
    /// hierarchical (max-Z hierarchy) or level0 (cell-by-cell reference stepping).
    #[arg(long, value_enum, default_value = "hierarchical")]
    traversal: TraversalArg,
    /// Turn range thresholds off: always colour from level 0.
    #[arg(long)]
    no_lod: bool,
    /// Repeat the database over the plane (modulo arithmetic) instead of showing sky past its edges.
    #[arg(long)]
    repeat: bool,
    /// Range haze: visibility in metres (a hit this far is 63% haze).
    #[arg(long, value_name = "METRES", allow_negative_numbers = true)]
    haze: Option<f64>,
    /// Stop looking beyond this range, metres.
    #[arg(long, value_name = "METRES", allow_negative_numbers = true)]
    max_range: Option<f64>,
    /// Rays per pixel, a square (1, 4, 9, 16, …): stratified supersampling, the pixel's colour
    /// their mean; the range image stays the centre ray's.
    #[arg(long, value_name = "N", default_value_t = 1)]
    samples: usize,
    /// Blend two levels' colours across a band around each range threshold (no seam where a
    /// moving view switches level).
    #[arg(long, conflicts_with = "no_lod")]
    blend: bool,
    /// March every ray on its own, without the column coherence used at zero roll and pitch
    /// (one walk per image column; same image, slower; for benchmarks and checks).
    #[arg(long)]
    no_coherence: bool,
    /// Orthographic top-down map of the whole database instead of a perspective view.
    #[arg(long, conflicts_with_all = ["eye", "repeat", "haze", "max_range", "traversal", "samples", "blend", "no_coherence", "path"])]
    top: bool,
    /// With --top: map only this window, MINX,MINY,MAXX,MAXY in the tile set's CRS units (the
    /// patent's god's-eye view of an area); default size its cells, at most 1024 on the long side.
    #[arg(
        long,
        value_name = "MINX,MINY,MAXX,MAXY",
        requires = "top",
        allow_hyphen_values = true
    )]
    window: Option<String>,
    /// Fly: render a frame every 1/--fps s along this path (.csv with a header x,y,z[,t], or a
    /// .geojson LineString of [x, y, z], optional properties.times), PNG frames into the -o
    /// directory. The view looks along the path (--fixed-heading: --attitude's yaw).
    #[arg(long, value_name = "PATH", conflicts_with_all = ["eye", "range_out"])]
    path: Option<PathBuf>,
    /// With --path: speed along the path, metres per second (for paths without times).
    #[arg(
        long,
        value_name = "M/S",
        requires = "path",
        allow_negative_numbers = true
    )]
    speed: Option<f64>,
    /// With --path: frames per second of flight time.
    #[arg(
        long,
        default_value_t = 25.0,
        requires = "path",
        allow_negative_numbers = true
    )]
    fps: f64,
    /// With --path: keep --attitude's yaw instead of looking along the path.
    #[arg(long, requires = "path")]
    fixed_heading: bool,
    /// With --path: also write every frame into this animated PNG (APNG), 1/--fps s each.
    #[arg(long, value_name = "FLIGHT.png", requires = "path")]
    animation: Option<PathBuf>,
    /// What the view is drawn for: the daylight colours, or a sensor's layer of the tile set
    /// (the geometry, and so the range image, is the same).
    #[arg(long, value_parser = super::choice::<Sensor>(), default_value = "visual")]
    sensor: Sensor,
    /// With --sensor ir: the temperatures drawn black and white, MIN,MAX in kelvin (default:
    /// the coldest and hottest cell of the coarsest level). Fix it to compare views.
    #[arg(long, value_name = "MIN,MAX")]
    ir_range: Option<String>,
    /// With --sensor nvg: the instant (RFC 3339 UTC), for the moon's position, phase and light.
    #[arg(long, value_name = "RFC3339")]
    time: Option<String>,
    /// With --sensor nvg: atmospheric extinction for the moonlight, magnitudes per air mass
    /// (default 0.172: a high site; 0.25-0.3 at sea level).
    #[arg(long, value_name = "MAG")]
    extinction: Option<f64>,
    /// With --sensor radar: put the radar at the eye in this band (L, S, C, X, Ku, Ka, W) and
    /// draw each pixel's σ⁰ at its own incidence, from the tile set's normal and material
    /// layers (dbms pyramid --normals --materials); without it, the backscatter layer's look.
    #[arg(long, value_name = "BAND")]
    band: Option<String>,
    /// Pages kept in the reader's cache (each 9·P² bytes, 590 kB at P = 256, plus P² or 4·P²
    /// per sensor layer).
    #[arg(long, default_value_t = 512)]
    cache_pages: usize,
    /// Output PNG (with --path: the directory of frame-NNNNN.png files, created if missing, and
    /// their record frames.json, written once every frame is in place).
    #[arg(short, long)]
    output: PathBuf,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum TraversalArg {
    Hierarchical,
    Level0,
}

/// Parse `WxH`.
fn size(s: &str) -> dbms::Result<(usize, usize)> {
    s.split_once(['x', 'X'])
        .and_then(|(w, h)| Some((w.trim().parse().ok()?, h.trim().parse().ok()?)))
        .ok_or_else(|| {
            Error::msg(format!("--size {s}: expected WIDTHxHEIGHT in pixels"))
                .fix("e.g. --size 640x480")
        })
}

pub fn run(args: Args, ctx: &Ctx) -> dbms::Result<()> {
    if args.path.is_some() {
        return fly(args, ctx);
    }
    let outputs: Vec<&std::path::Path> = std::iter::once(args.output.as_path())
        .chain(args.range_out.as_deref())
        .collect();
    dbms::io::atomic::check_outputs(&outputs, &[&args.tiles])?;
    let (reader, backdrop, overlay) = open(&args)?;
    let mut lights_drawn = None;
    if args.top && matches!(overlay, Overlay::Radar(_)) {
        return Err(
            Error::msg("--band puts the radar at the eye, and --top has none")
                .fix("drop --top for a view from --eye, or --band to draw the backscatter layer"),
        );
    }
    let frame = if args.top {
        let g = &reader.info().grid;
        let window = args
            .window
            .as_deref()
            .map(|s| Bounds::parse_option("--window", s))
            .transpose()?;
        // The map's cells across and down: the grid's, or the window's.
        let (cw, ch) = match window {
            Some(b) => (
                b.width() / g.transform.cell_x.abs(),
                b.height() / g.transform.cell_y.abs(),
            ),
            None => (g.width as f64, g.height as f64),
        };
        let (w, h) = match &args.size {
            Some(s) => size(s)?,
            None => {
                let k = (cw.max(ch) / 1024.0).max(1.0);
                (
                    ((cw / k).round() as usize).clamp(1, 16384),
                    ((ch / k).round() as usize).clamp(1, 16384),
                )
            }
        };
        render::render_top(&reader, w, h, !args.no_lod, window)?
    } else {
        let eye = super::triple(
            "--eye",
            args.eye.as_deref().unwrap_or_default(),
            "X,Y,Z in the database's CRS units and metres",
        )?;
        let (width, height) = size(args.size.as_deref().unwrap_or("640x480"))?;
        let camera = Viewpoint {
            eye,
            attitude: attitude(&args)?,
            hfov: args.fov,
            width,
            height,
        };
        let mut frame = render::render_view(&reader, &camera, &view_options(&args, backdrop))?;
        lights_drawn = overlay.draw(&mut frame, &camera, &reader, args.haze)?;
        frame
    };
    frame.write(&args.output, args.range_out.as_deref())?;
    ctx.report(&Rendered {
        output: args.output,
        range_out: args.range_out,
        width: frame.width,
        height: frame.height,
        lights_drawn,
        stats: frame.stats,
    });
    Ok(())
}

fn attitude(args: &Args) -> dbms::Result<Attitude> {
    let [roll, pitch, yaw] =
        super::triple("--attitude", &args.attitude, "ROLL,PITCH,YAW in degrees")?;
    Ok(Attitude { roll, pitch, yaw })
}

/// The tile file, read for `--sensor` (its pages recoloured), the view's backdrop and what is
/// drawn over each frame (night vision's lights, the radar at the eye).
fn open(args: &Args) -> dbms::Result<(TileReader, Backdrop, Overlay)> {
    if args.ir_range.is_some() && args.sensor != Sensor::Ir {
        return Err(Error::msg("--ir-range is for --sensor ir").fix("add --sensor ir"));
    }
    if (args.time.is_some() || args.extinction.is_some()) && args.sensor != Sensor::Nvg {
        return Err(
            Error::msg("--time and --extinction are for --sensor nvg").fix("add --sensor nvg")
        );
    }
    if args.band.is_some() && args.sensor != Sensor::Radar {
        return Err(Error::msg("--band is for --sensor radar").fix("add --sensor radar"));
    }
    let band = args
        .band
        .as_deref()
        .map(dbms::radar_map::parse_band)
        .transpose()?;
    let reader = TileReader::open(&args.tiles, args.cache_pages)?;
    let ir_range = match &args.ir_range {
        Some(s) => {
            let [lo, hi] = super::numbers("--ir-range", s, "MIN,MAX in kelvin")?;
            Some(IrScale::new(lo, hi)?)
        }
        None => None,
    };
    let opts = SensorOptions {
        ir_range,
        time: args.time.clone(),
        extinction_mag_per_airmass: args
            .extinction
            .unwrap_or(dbms::moon::DEFAULT_EXTINCTION_MAG_PER_AIRMASS),
        band,
    };
    Ok(match render::sensor::view(args.sensor, &reader, &opts)? {
        Some(v) => (reader.with_filter(v.filter), v.backdrop, v.overlay),
        None => (reader, Backdrop::Daylight, Overlay::None),
    })
}

fn view_options(args: &Args, backdrop: Backdrop) -> ViewOptions {
    ViewOptions {
        backdrop,
        traversal: match args.traversal {
            TraversalArg::Hierarchical => Traversal::Hierarchical,
            TraversalArg::Level0 => Traversal::Level0,
        },
        lod: !args.no_lod,
        repeat: args.repeat,
        visibility: args.haze,
        max_range: args.max_range,
        samples: args.samples,
        blend: args.blend,
        coherence: !args.no_coherence,
    }
}

/// `--path`: every frame of the flight, then the summary.
fn fly(args: Args, ctx: &Ctx) -> dbms::Result<()> {
    let path = args.path.as_deref().expect("--path given");
    if let Some(a) = &args.animation {
        dbms::io::atomic::check_outputs(&[a], &[&args.tiles, path])?;
    }
    let waypoints = render::path::read(path)?;
    let (width, height) = size(args.size.as_deref().unwrap_or("640x480"))?;
    let flight = render::path::Flight {
        fps: args.fps,
        speed: args.speed,
        attitude: attitude(&args)?,
        fixed_heading: args.fixed_heading,
    };
    let viewpoints = render::path::viewpoints(&waypoints, &flight, args.fov, width, height)?;
    let (reader, backdrop, overlay) = open(&args)?;
    let progress = ctx.progress(viewpoints.len() as u64, "frames");
    let stats = render::flight::fly(
        &reader,
        &viewpoints,
        &view_options(&args, backdrop),
        &|frame: &mut render::Frame, camera: &Viewpoint| {
            overlay.draw(frame, camera, &reader, args.haze).map(|_| ())
        },
        &args.output,
        args.animation.as_deref().map(|a| (a, args.fps)),
        &progress,
    )?;
    progress.finish();
    ctx.report(&Flown {
        output: args.output,
        animation: args.animation,
        width,
        height,
        stats,
    });
    Ok(())
}

/// `dbms render`'s summary for one view.
#[derive(serde::Serialize)]
struct Rendered {
    output: PathBuf,
    range_out: Option<PathBuf>,
    width: usize,
    height: usize,
    /// With --sensor nvg: the light points drawn (the others are hidden or out of view).
    #[serde(skip_serializing_if = "Option::is_none")]
    lights_drawn: Option<usize>,
    stats: RenderStats,
}

impl std::fmt::Display for Rendered {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let s = &self.stats;
        write!(
            f,
            "{}: {}×{}, {} of {} rays hit, {:.2} Mrays/s ({:.3} s); {} pages touched, {} read ({} bytes), {} cache hits",
            self.output.display(),
            self.width,
            self.height,
            s.hits,
            s.rays,
            s.rays_per_second / 1e6,
            s.seconds,
            s.pages_touched,
            s.reader.pages_read,
            s.reader.bytes_read,
            s.reader.cache_hits
        )?;
        match self.lights_drawn {
            Some(n) => write!(f, "; {n} light points drawn"),
            None => Ok(()),
        }
    }
}

/// `dbms render --path`'s summary.
#[derive(serde::Serialize)]
struct Flown {
    output: PathBuf,
    animation: Option<PathBuf>,
    width: usize,
    height: usize,
    stats: FlightStats,
}

impl std::fmt::Display for Flown {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let s = &self.stats;
        write!(
            f,
            "{}: {} frames {}×{}, {:.1} frames/s rendering ({:.2} s; {:.2} s with writing), {:.1} pages read per frame (most {}), {:.1} cells stepped per ray",
            self.output.display(),
            s.frames,
            self.width,
            self.height,
            s.frames_per_second,
            s.render_seconds,
            s.total_seconds,
            s.pages_read_per_frame,
            s.pages_read_max,
            s.cells_stepped_per_ray,
        )?;
        if let Some(a) = &self.animation {
            write!(f, "; animation {}", a.display())?;
        }
        Ok(())
    }
}
