//! The evaluation matrix of the thesis (6.2.1) for any tracer: scenes x cameras x sizes x modes x
//! methods, the median of repeated frames per setting, written as CSV and Markdown. `trace-cpu
//! bench` and `trace-vk bench` both run it, so their rows have the same columns and one table or
//! chart can hold CPU and GPU rows of a scene side by side (`bench-chart`).

use crate::output::{self, Kind, Output};
use crate::render_args::{IntersectArg, MAX_LIGHTS, VerticesArg, lights_n, parse_count, parse_res, stored_camera};
use bvh_format::SceneFile;
use clap::ValueEnum;
use render_spec::{Ao, CameraSpec, Image, Mode, Settings, Vertices};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// The options of the matrix, shared by both tracers' `bench` commands.
#[derive(clap::Args, Debug, Clone)]
pub struct MatrixArgs {
    /// Scenes: compiled .bvh files, meshes or scene descriptions [default: the built-in bunny].
    pub scenes: Vec<PathBuf>,
    /// Stored cameras to render from.
    #[arg(long, value_delimiter = ',', default_value = "close-up,medium,wide", allow_hyphen_values = true)]
    pub cameras: Vec<String>,
    /// Image sizes.
    #[arg(long, value_delimiter = ',', value_parser = parse_res, default_value = "640x480,1280x960,1920x1440", allow_hyphen_values = true)]
    pub res: Vec<(u32, u32)>,
    /// Modes: cast; whitted with a light count (whitted1, whitted2, whitted4); ao with the rays
    /// per hit, of 10% of the scene's diagonal (ao8) or of another fraction (ao8:0.25); diffuse.
    #[arg(long, value_delimiter = ',', value_parser = parse_mode, default_value = "cast,whitted1,whitted2", allow_hyphen_values = true)]
    pub modes: Vec<BenchMode>,
    /// Timed frames per setting, 1 to 100000; the median is reported [default: 50 on the GPU, 10
    /// on the CPU, whose frames are a hundred times longer].
    #[arg(long, value_parser = parse_frames, allow_hyphen_values = true)]
    pub frames: Option<usize>,
    /// Untimed frames before the timed ones, 0 to 100000 [default: 3 on the GPU, 1 on the CPU].
    #[arg(long, value_parser = parse_warmup, allow_hyphen_values = true)]
    pub warmup: Option<usize>,
    /// Write the table as CSV here (and as Markdown next to it, .md).
    #[arg(long, default_value = "bench.csv", allow_hyphen_values = true)]
    pub csv: PathBuf,
    /// Triangle test of every setting (`render --intersect`): two runs that differ only here
    /// measure what the edge-consistent test costs against Möller-Trumbore.
    #[arg(long, value_enum, default_value = "watertight")]
    pub intersect: IntersectArg,
    /// Vertex forms to time each method with (`render --vertices`), side by side: a form other
    /// than expanded names its rows METHOD+FORM (lst+indexed), and each prints its bytes held
    /// (trace-cpu) or uploaded (trace-vk).
    #[arg(long, value_delimiter = ',', value_enum, default_value = "expanded")]
    pub vertices: Vec<VerticesArg>,
}

/// What a bench row's method name adds for the indexed vertex form (`lst+indexed`).
pub const INDEXED_SUFFIX: &str = "+indexed";

/// The bench's name of the method `name` reading triangles in `form`: the method's own for the
/// default expanded form, with [`INDEXED_SUFFIX`] for the indexed one.
pub fn with_form(name: &str, form: Vertices) -> String {
    match form {
        Vertices::Expanded => name.to_owned(),
        Vertices::Indexed => format!("{name}{INDEXED_SUFFIX}"),
    }
}

/// A bench method name split into the method and its vertex form ([`with_form`] undone).
pub fn split_form(name: &str) -> (&str, Vertices) {
    match name.strip_suffix(INDEXED_SUFFIX) {
        Some(name) => (name, Vertices::Indexed),
        None => (name, Vertices::Expanded),
    }
}

pub fn parse_frames(s: &str) -> Result<usize, String> {
    parse_count(s, 1, 100_000, "the number of frames").map(|n| n as usize)
}

pub fn parse_warmup(s: &str) -> Result<usize, String> {
    parse_count(s, 0, 100_000, "the number of warm-up frames").map(|n| n as usize)
}

/// A mode of the matrix: ray casting, Whitted ray tracing with this many lights (the scene's
/// first ones, completed by [`lights_n`]), ambient occlusion or the diffuse bounce.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BenchMode {
    pub mode: Mode,
    pub lights: usize,
}

impl BenchMode {
    /// `cast`, `whitted1`, `whitted2`, `ao8`, `ao8:0.25`, `diffuse`: the name the options and
    /// the tables use.
    pub fn name(&self) -> String {
        match self.mode {
            Mode::Cast | Mode::Diffuse => self.mode.name().to_owned(),
            Mode::Whitted => format!("whitted{}", self.lights),
            Mode::Ao(ao) if ao.length == Ao::default().length => format!("ao{}", ao.samples),
            Mode::Ao(ao) => format!("ao{}:{}", ao.samples, ao.length),
        }
    }
}

pub fn parse_mode(s: &str) -> Result<BenchMode, String> {
    let plain = |mode| Ok(BenchMode { mode, lights: 0 });
    match s.trim() {
        "cast" => plain(Mode::Cast),
        "diffuse" => plain(Mode::Diffuse),
        t => {
            if let Some(n) = t.strip_prefix("whitted") {
                return parse_count(n, 1, MAX_LIGHTS as u64, "the light count after \"whitted\"")
                    .map(|n| BenchMode { mode: Mode::Whitted, lights: n as usize });
            }
            let Some(rest) = t.strip_prefix("ao") else {
                return Err(format!("{s:?} is not a mode (cast, whitted1, whitted2, ..., ao8, ao8:0.25, diffuse)"));
            };
            let (n, length) = match rest.split_once(':') {
                Some((n, length)) => (n, Some(length)),
                None => (rest, None),
            };
            let samples = crate::render_args::parse_ao_samples(n)?;
            let length = length.map_or(Ok(Ao::default().length), crate::render_args::parse_ao_length)?;
            plain(Mode::Ao(Ao { samples, length }))
        }
    }
}

/// Rays of a frame by kind, in the order of the tables' columns: primary, shadow, secondary, AO
/// and diffuse.
pub type Rays = [u64; 5];

/// [`Rays`] of a frame's counts.
pub fn rays_of(r: &render_spec::RayCounts) -> Rays {
    [r.primary, r.shadow, r.secondary, r.ao, r.diffuse]
}

/// What one frame cost: milliseconds (whatever the tracer's [`Bench::timing`] says they cover) and
/// its rays.
#[derive(Clone, Copy, Debug)]
pub struct Timed {
    pub ms: f64,
    pub rays: Rays,
}

/// A tracer the matrix can time.
pub trait Bench {
    /// What one (scene, method) pair keeps from frame to frame (a renderer with its buffers).
    type Renderer<'a>
    where
        Self: 'a;
    /// `cpu` or `vk`: the `tracer` column.
    fn tracer(&self) -> &'static str;
    /// The machine, in a few words: the `device` column.
    fn device(&self) -> String;
    /// What the time of a frame covers, for the Markdown preface.
    fn timing(&self) -> String;
    fn prepare<'a>(&'a self, scene: &'a SceneFile, method: &str) -> Result<Self::Renderer<'a>, String>;
    /// [`Bench::prepare`] for a scene read from `path` (`None`: the built-in scene), for tracers
    /// that keep something beside the scene file (`trace-vk`'s `auto` caches its picks there).
    fn prepare_file<'a>(
        &'a self,
        scene: &'a SceneFile,
        _path: Option<&'a Path>,
        method: &str,
    ) -> Result<Self::Renderer<'a>, String> {
        self.prepare(scene, method)
    }
    /// Why this tracer cannot run `method` on its device at all (rt-pipeline on a GPU without
    /// ray tracing), or `None`: the evaluation lists such methods as not supported.
    fn unsupported(&self, _method: &str) -> Option<String> {
        None
    }
    /// The `method` column of a row measured with `r` (`trace-vk`'s `auto` adds its pick).
    fn method_label(&self, _r: &Self::Renderer<'_>, method: &str) -> String {
        method.to_owned()
    }
    /// Whether the tracer implements these accuracy settings (the evaluation leaves out those it
    /// does not, rather than report an image rendered without them).
    fn honours(&self, _accuracy: &render_spec::Accuracy) -> bool {
        true
    }
    /// One timed frame; the tracer may leave out reading back the pixels and AOVs.
    fn frame(&self, r: &mut Self::Renderer<'_>, s: &Settings) -> Result<Timed, String>;
    /// One untimed frame with its pixels, and its AOVs when the settings ask for them.
    fn image(&self, r: &mut Self::Renderer<'_>, s: &Settings) -> Result<Image, String>;
    /// [`Bench::image`] with the rays stopped by their own triangle counted
    /// (render_spec::SelfHits, `--self-hits`); the evaluation's exact acne.
    fn image_with_self_hits(&self, r: &mut Self::Renderer<'_>, s: &Settings) -> Result<Image, String>;
    /// Checked once after the last frame (the Vulkan tracer's validation messages).
    fn finish(&self) -> Result<(), String> {
        Ok(())
    }
}

/// One measured setting: a line of the CSV.
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    pub scene: String,
    pub triangles: u64,
    pub camera: String,
    pub width: u32,
    pub height: u32,
    pub mode: String,
    pub lights: usize,
    pub method: String,
    pub median_ms: f64,
    pub min_ms: f64,
    /// Every ray counts towards the rate, AO and diffuse rays included.
    pub rays: Rays,
    pub tracer: String,
    pub device: String,
    /// The triangle test (`watertight`, `mt`); empty where the source does not say (CSV files
    /// from before the column, the ray report, whose method names carry it).
    pub intersect: String,
}

/// The CSV columns, in order.
pub const CSV_HEADER: &str = "scene,triangles,camera,width,height,mode,lights,method,median_ms,min_ms,primary,shadow,\
                              secondary,ao,diffuse,mrays_per_s,tracer,device,intersect";

impl Row {
    pub fn total_rays(&self) -> u64 {
        self.rays.iter().sum()
    }

    /// Million rays per second over the median frame.
    pub fn mrays(&self) -> f64 {
        self.total_rays() as f64 / self.median_ms / 1e3
    }

    pub fn csv(&self) -> String {
        let [p, s, r, a, d] = self.rays;
        format!(
            "{},{},{},{},{},{},{},{},{:.4},{:.4},{p},{s},{r},{a},{d},{:.2},{},{},{}",
            field(&self.scene),
            self.triangles,
            field(&self.camera),
            self.width,
            self.height,
            self.mode,
            self.lights,
            self.method,
            self.median_ms,
            self.min_ms,
            self.mrays(),
            self.tracer,
            field(&self.device),
            self.intersect
        )
    }

    fn markdown(&self) -> String {
        let [p, s, r, a, d] = self.rays;
        format!(
            "| {} | {} | {}x{} | {} | {} {} | {} | {} | {p} | {s} | {r} | {a} | {d} |",
            self.scene,
            self.camera,
            self.width,
            self.height,
            self.mode,
            self.tracer,
            self.method,
            significant(self.median_ms),
            significant(self.mrays()),
        )
    }
}

/// Commas would split a field: names keep their words, joined by semicolons instead.
pub fn field(s: &str) -> String {
    s.replace(',', ";")
}

/// A figure with three significant digits and no exponent (0.0123, 4.56, 789, 12345), so that a
/// small rate never reads as 0.0 and a large one keeps its integer digits.
pub fn significant(x: f64) -> String {
    if !x.is_finite() || x == 0.0 {
        return format!("{x}");
    }
    let digits = (2 - x.abs().log10().floor() as i32).max(0) as usize;
    format!("{x:.digits$}")
}

/// The throughput table of a ray report (`tracer-cpu/examples/ray_report.rs`) as rows, for charts:
/// the kind of ray as the mode, the column's first word ("ours", "Embree") as the tracer and the
/// rest as the method, the thread count as the device; only the rows of `threads` (by default the
/// largest thread count in the file).
pub fn read_ray_report(path: &Path, threads: Option<u32>) -> Result<Vec<Row>, String> {
    let text = read_text(path)?;
    ray_report_rows(&text, threads).map_err(|e| format!("{}: {e}", path.display()))
}

/// A text file the charts read (a CSV, a ray report), refused if it is a device as every input is
/// ([`bvh_format::read_input`]).
fn read_text(path: &Path) -> Result<String, String> {
    let bytes = bvh_format::read_input(path).map_err(|e| format!("cannot read {}: {e}", path.display()))?;
    String::from_utf8(bytes).map_err(|_| format!("{} is not UTF-8 text", path.display()))
}

/// [`read_ray_report`] on the report's text.
fn ray_report_rows(text: &str, threads: Option<u32>) -> Result<Vec<Row>, String> {
    const KINDS: [&str; 5] = ["primary", "shadow", "secondary", "ao", "diffuse"];
    let cells = |l: &str| l.trim().trim_matches('|').split('|').map(|c| c.trim().to_owned()).collect::<Vec<_>>();
    let table: Vec<&str> = text
        .lines()
        .skip_while(|l| !l.starts_with("### Throughput"))
        .skip(2)
        .take_while(|l| l.starts_with('|'))
        .collect();
    let Some((header, body)) = table.split_first() else {
        return Err("it holds no ray report throughput table".to_owned());
    };
    let header = cells(header);
    let column = |name: &str| header.iter().position(|h| h == name);
    let (Some(scene), Some(size), Some(rays), Some(kind), Some(thr)) =
        (column("scene"), column("size"), column("rays"), column("kind"), column("threads"))
    else {
        return Err("its throughput table lacks a scene, size, rays, kind or threads column".to_owned());
    };
    // The scene's triangle count from the Scenes line: "NAME (N triangles, ...".
    let triangles = |name: &str| -> u64 {
        let line = text.lines().find(|l| l.starts_with("- Scenes:")).unwrap_or("");
        line.split(&format!("{name} ("))
            .nth(1)
            .and_then(|r| r.split(' ').next())
            .and_then(|n| n.parse().ok())
            .unwrap_or(0)
    };
    let body: Vec<Vec<String>> = body.iter().skip(1).map(|l| cells(l)).filter(|c| c.len() == header.len()).collect();
    let most = body.iter().filter_map(|c| c[thr].parse::<u32>().ok()).max();
    let want = threads.or(most).ok_or_else(|| "its throughput table has no rows".to_owned())?;
    let mut rows = Vec::new();
    for c in body.iter().filter(|c| c[thr].parse::<u32>().ok() == Some(want)) {
        let (Some((w, h)), Ok(n), Some(k)) =
            (c[size].split_once('x'), c[rays].parse::<u64>(), KINDS.iter().position(|k| *k == c[kind]))
        else {
            return Err(format!("cannot read the row {:?}", c.join(" | ")));
        };
        let mut counts = [0; 5];
        counts[k] = n;
        // The tracers' columns: a rate, or "-" where one was left out; the ratios ("a / b") are not.
        for (i, name) in header.iter().enumerate().skip(thr + 1).filter(|(_, h)| !h.contains(" / ")) {
            let Ok(mrays) = c[i].parse::<f64>() else { continue };
            let (tracer, method) = name.split_once(' ').unwrap_or((name, ""));
            rows.push(Row {
                scene: c[scene].clone(),
                triangles: triangles(&c[scene]),
                camera: "medium".into(),
                width: w.parse().unwrap_or(0),
                height: h.parse().unwrap_or(0),
                mode: c[kind].clone(),
                lights: 1,
                method: method.to_owned(),
                median_ms: n as f64 / mrays / 1e3,
                min_ms: n as f64 / mrays / 1e3,
                rays: counts,
                tracer: tracer.to_owned(),
                device: format!("{want} threads"),
                intersect: String::new(),
            });
        }
    }
    if rows.is_empty() {
        return Err(format!("it has no rates on {want} threads"));
    }
    Ok(rows)
}

/// One measurement repeated: the rows of several runs (the rounds of an A/B run, say) that agree
/// in every field but their times.
#[derive(Clone, Debug, PartialEq)]
pub struct Repeated {
    /// The first run's row with the median of the runs' median times and the least of their
    /// minima, so that its rate is the median run's (the mean of the middle two for an even count).
    pub row: Row,
    pub runs: usize,
    /// The slowest and the fastest run's rate, Mrays/s.
    pub slowest: f64,
    pub fastest: f64,
}

/// Merges rows that repeat one measurement, keeping the order in which each first appears. A
/// chart or table of several runs then shows one median per setting, and the runs' spread beside
/// it, instead of one bar per run.
pub fn merge_repeats(rows: &[Row]) -> Vec<Repeated> {
    let same = |a: &Row, b: &Row| {
        Row { median_ms: 0.0, min_ms: 0.0, ..a.clone() } == Row { median_ms: 0.0, min_ms: 0.0, ..b.clone() }
    };
    let mut groups: Vec<Vec<&Row>> = Vec::new();
    for r in rows {
        match groups.iter_mut().find(|g| same(g[0], r)) {
            Some(g) => g.push(r),
            None => groups.push(vec![r]),
        }
    }
    groups
        .into_iter()
        .map(|g| {
            let mut ms: Vec<f64> = g.iter().map(|r| r.median_ms).collect();
            ms.sort_by(f64::total_cmp);
            let n = ms.len();
            let median_ms = if n % 2 == 1 { ms[n / 2] } else { (ms[n / 2 - 1] + ms[n / 2]) / 2.0 };
            let min_ms = g.iter().map(|r| r.min_ms).fold(f64::INFINITY, f64::min);
            let rates: Vec<f64> = g.iter().map(|r| r.mrays()).collect();
            Repeated {
                row: Row { median_ms, min_ms, ..g[0].clone() },
                runs: n,
                slowest: rates.iter().copied().fold(f64::INFINITY, f64::min),
                fastest: rates.iter().copied().fold(0.0, f64::max),
            }
        })
        .collect()
}

/// Reads rows written by [`Row::csv`] (or by earlier versions of `trace-vk bench`, whose files have
/// no `tracer` and `device` columns: those rows are `vk` on an unnamed device; nor `ao` and
/// `diffuse`: those rows traced none; nor `intersect`: left empty).
pub fn read_csv(path: &Path) -> Result<Vec<Row>, String> {
    let text = read_text(path)?;
    let mut lines = text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty());
    let (_, header) = lines.next().ok_or_else(|| format!("{} is empty", path.display()))?;
    let names: Vec<&str> = header.split(',').map(str::trim).collect();
    let col = |name: &str| names.iter().position(|n| *n == name);
    let need = |name: &str| col(name).ok_or_else(|| format!("{} has no column {name:?}", path.display()));
    let idx = [
        need("scene")?,
        need("triangles")?,
        need("camera")?,
        need("width")?,
        need("height")?,
        need("mode")?,
        need("lights")?,
        need("method")?,
        need("median_ms")?,
        need("min_ms")?,
        need("primary")?,
        need("shadow")?,
        need("secondary")?,
    ];
    let (tracer, device, ao, diffuse, intersect) =
        (col("tracer"), col("device"), col("ao"), col("diffuse"), col("intersect"));
    let mut rows = Vec::new();
    for (n, line) in lines {
        let f: Vec<&str> = line.split(',').map(str::trim).collect();
        let bad = |what: &str| format!("{} line {}: {what}", path.display(), n + 1);
        if f.len() != names.len() {
            return Err(bad(&format!("{} fields where the header has {}", f.len(), names.len())));
        }
        let num = |i: usize| f[idx[i]].parse::<f64>().map_err(|_| bad(&format!("{:?} is not a number", f[idx[i]])));
        let count = |s: &str| s.parse::<u64>().map_err(|_| bad(&format!("{s:?} is not a count")));
        let int = |i: usize| count(f[idx[i]]);
        let optional = |c: Option<usize>| c.map_or(Ok(0), |i| count(f[i]));
        rows.push(Row {
            scene: f[idx[0]].to_owned(),
            triangles: int(1)?,
            camera: f[idx[2]].to_owned(),
            width: int(3)? as u32,
            height: int(4)? as u32,
            mode: f[idx[5]].to_owned(),
            lights: int(6)? as usize,
            method: f[idx[7]].to_owned(),
            median_ms: num(8)?,
            min_ms: num(9)?,
            rays: [int(10)?, int(11)?, int(12)?, optional(ao)?, optional(diffuse)?],
            tracer: tracer.map_or("vk", |i| f[i]).to_owned(),
            device: device.map_or("", |i| f[i]).to_owned(),
            intersect: intersect.map_or("", |i| f[i]).to_owned(),
        });
    }
    Ok(rows)
}

/// The Markdown table of `rows`, after a preface naming each device with what its times cover.
pub fn markdown(prefaces: &[String], rows: &[Row]) -> String {
    let mut s = String::new();
    for p in prefaces {
        let _ = writeln!(s, "{p}\n");
    }
    s.push_str(
        "| scene | camera | size | mode | tracer, method | median ms | Mrays/s | primary | shadow | secondary | AO | diffuse |\n",
    );
    s.push_str("|---|---|---|---|---|---:|---:|---:|---:|---:|---:|---:|\n");
    for r in rows {
        let _ = writeln!(s, "{}", r.markdown());
    }
    s
}

/// Checks the CSV path and its Markdown copy (`.md` beside it) before any work.
pub fn check_tables(csv: &Path) -> Result<[Output; 2], String> {
    let md = csv.with_extension("md");
    let checked =
        output::check(&[("--csv", csv, Kind::Table), ("--csv (its Markdown copy)", &md, Kind::Markdown)], &[])
            .map_err(|e| e.to_string())?;
    let [csv, md]: [Output; 2] = checked.try_into().map_err(|_| "two outputs were checked".to_owned())?;
    Ok([csv, md])
}

/// Writes the CSV and the Markdown next to it (`.md`), each complete or not at all.
pub fn write_tables(csv: &Path, preface: &str, rows: &[Row]) -> Result<PathBuf, String> {
    let [csv, md] = check_tables(csv)?;
    let mut text = String::from(CSV_HEADER);
    text.push('\n');
    for r in rows {
        text.push_str(&r.csv());
        text.push('\n');
    }
    output::write_text(&csv, &text).map_err(|e| e.to_string())?;
    output::write_text(&md, &markdown(&[preface.to_owned()], rows)).map_err(|e| e.to_string())?;
    Ok(md.path)
}

/// The times of one setting: the median and the fastest of the timed frames, and the rays of the
/// last one.
#[derive(Clone, Copy, Debug)]
pub struct Measured {
    pub median_ms: f64,
    pub min_ms: f64,
    pub rays: Rays,
}

/// The least wall time of untimed frames before a setting is timed (see [`measure`]).
const WARM_UP_S: f64 = 1.0;
/// A window of the settling test (see [`measure`]) holds at least this many untimed frames and
/// lasts at least SETTLE_WINDOW_S.
const SETTLE_WINDOW: usize = 3;
const SETTLE_WINDOW_S: f64 = 0.2;
/// A window whose median is faster than the one before by more than this share is still
/// warming up.
const SETTLE_SHARE: f64 = 0.02;
/// The most wall time of untimed frames where the times do not settle.
const MAX_WARM_UP_S: f64 = 10.0;

/// Renders at least `warmup` untimed frames and at least 1 s of them, and goes on until the
/// frame times have settled, then `frames` timed frames of `settings` (`frames` at least 1).
pub fn measure<B: Bench>(
    bench: &B,
    renderer: &mut B::Renderer<'_>,
    settings: &Settings,
    warmup: usize,
    frames: usize,
) -> Result<Measured, String> {
    // A GPU raises its clocks only after some busy time, and lowers them in idle gaps. On the
    // H100, sub-millisecond frames after three warm-up frames came out up to 4.7x slow for the
    // first setting of a scene, and after a fixed 1 s of warm-up still up to 3.7x slow in
    // trace-eval, whose settings follow idle gaps (the CPU's evaluation before the GPU's, FLIP
    // and the hit comparison between settings), where `trace-vk bench` runs its settings back to
    // back. So the warm-up ends only once the times stop falling: a window (SETTLE_WINDOW frames
    // and SETTLE_WINDOW_S) whose median is within SETTLE_SHARE of the window before, or after
    // MAX_WARM_UP_S; whatever came before, the timed frames then start from the same state.
    let start = std::time::Instant::now();
    let (mut warmed, mut settled) = (0, false);
    let (mut window, mut previous) = (Vec::new(), None::<f64>);
    let mut window_start = start;
    loop {
        let elapsed = start.elapsed().as_secs_f64();
        if warmed >= warmup && elapsed >= WARM_UP_S && (settled || elapsed >= MAX_WARM_UP_S) {
            break;
        }
        window.push(bench.frame(renderer, settings)?.ms);
        warmed += 1;
        if window.len() >= SETTLE_WINDOW && window_start.elapsed().as_secs_f64() >= SETTLE_WINDOW_S {
            window_start = std::time::Instant::now();
            let m = median(&mut window);
            // Without timestamps there is nothing to settle.
            settled = !m.is_finite() || previous.is_some_and(|p| m >= p * (1.0 - SETTLE_SHARE));
            previous = Some(m);
            window.clear();
        }
    }
    let mut times = Vec::with_capacity(frames);
    let mut rays = Rays::default();
    for _ in 0..frames.max(1) {
        let t = bench.frame(renderer, settings)?;
        times.push(t.ms);
        rays = t.rays;
    }
    let min_ms = times.iter().copied().fold(f64::INFINITY, f64::min);
    Ok(Measured { median_ms: median(&mut times), min_ms, rays })
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 { v[n / 2] } else { 0.5 * (v[n / 2 - 1] + v[n / 2]) }
}

/// Frames and warm-up frames per setting when the options leave them out.
pub struct Defaults {
    pub frames: usize,
    pub warmup: usize,
}

/// Runs the matrix with `methods` on `bench`, shows progress, prints the Markdown table and
/// writes the CSV and Markdown files. Returns the rows.
pub fn run<B: Bench>(bench: &B, m: &MatrixArgs, methods: &[&str], defaults: Defaults) -> Result<Vec<Row>, String> {
    let frames = m.frames.unwrap_or(defaults.frames);
    let warmup = m.warmup.unwrap_or(defaults.warmup);
    if methods.is_empty() || m.cameras.is_empty() || m.res.is_empty() || m.modes.is_empty() {
        return Err("the matrix is empty: give at least one method, camera, size and mode".to_owned());
    }
    check_tables(&m.csv)?;
    let scenes: Vec<Option<PathBuf>> =
        if m.scenes.is_empty() { vec![None] } else { m.scenes.iter().cloned().map(Some).collect() };
    let total = scenes.len() * m.cameras.len() * m.res.len() * m.modes.len() * methods.len();
    let bar =
        crate::cli::Progress::new(total as u64, "{bar:40} {pos}/{len} settings ({elapsed}, {eta} left) {msg}", false);
    let device = bench.device();
    let accuracy = render_spec::Accuracy { intersect: m.intersect.intersect(), ..Default::default() };
    if !bench.honours(&accuracy) {
        return Err(format!("this tracer has no {:?} triangle test", m.intersect));
    }
    let intersect_name = m.intersect.to_possible_value().map(|v| v.get_name().to_owned()).unwrap_or_default();
    let mut rows = Vec::with_capacity(total);
    for path in &scenes {
        let name = path
            .as_ref()
            .and_then(|p| p.file_stem())
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "bunny (built-in)".to_owned());
        bar.set_message(format!("loading {name}"));
        let scene = crate::load_scene_with(path.as_deref(), crate::layouts_for(methods))?.file;
        // Every camera is looked up before the first frame, so a misspelt one fails at once.
        let cameras: Vec<(&String, CameraSpec)> =
            m.cameras.iter().map(|c| Ok((c, stored_camera(&scene, c)?))).collect::<Result<_, String>>()?;
        for &method in methods {
            let mut renderer = bench.prepare_file(&scene, path.as_deref(), method)?;
            for &(cam, camera) in &cameras {
                for &(width, height) in &m.res {
                    for mode in &m.modes {
                        bar.set_message(format!("{name} {cam} {width}x{height} {} {method}", mode.name()));
                        let settings = Settings {
                            width,
                            height,
                            camera,
                            mode: mode.mode,
                            lights: lights_n(&scene, mode.lights, &camera),
                            max_indirections: scene.settings.max_indirections,
                            aovs: false,
                            accuracy,
                        };
                        let m = measure(bench, &mut renderer, &settings, warmup, frames)?;
                        rows.push(Row {
                            scene: name.clone(),
                            triangles: scene.triangles.len() as u64,
                            camera: cam.clone(),
                            width,
                            height,
                            mode: mode.name(),
                            lights: mode.lights,
                            method: bench.method_label(&renderer, method),
                            median_ms: m.median_ms,
                            min_ms: m.min_ms,
                            rays: m.rays,
                            tracer: bench.tracer().to_owned(),
                            device: device.clone(),
                            intersect: intersect_name.clone(),
                        });
                        bar.inc(1);
                    }
                }
            }
        }
    }
    bar.finish();
    bench.finish()?;
    let preface = format!(
        "Device: {device} (`{}`); {frames} frames per setting after at least {warmup} warm-up frames, 1 s of them and more until their times settled; {}; triangle test {intersect_name}.",
        bench.tracer(),
        bench.timing(),
    );
    let md_path = write_tables(&m.csv, &preface, &rows)?;
    crate::say!("{}", markdown(&[preface], &rows));
    crate::say!("-> {} and {}", m.csv.display(), md_path.display());
    Ok(rows)
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_ray_report_table_becomes_one_row_per_tracer_and_kind_at_one_thread_count() {
        let text = "# CPU ray throughput\n\n- Scenes: bunny (69453 triangles, scenes/bunny.toml)\n\n\
### Throughput, million rays per second\n\n\
| scene | size | rays | kind | threads | ours bvh8 | ours bvh8 packet | Embree 1 | bvh8 / Embree 1 |\n\
|---|---|---:|---|---:|---:|---:|---:|---:|\n\
| bunny | 64x48 | 3072 | primary | 1 | 15.00 | - | 12.00 | 125% |\n\
| bunny | 64x48 | 3072 | primary | 16 | 200.00 | 480.00 | 160.00 | 125% |\n\
| bunny | 64x48 | 2000 | shadow | 16 | 100.00 | 250.00 | 125.00 | 80% |\n\n### Hit agreement\n";
        let rows = super::ray_report_rows(text, None).unwrap();
        // 16 threads by default: 2 kinds x 3 tracers, the ratio column left out.
        assert_eq!(rows.len(), 6);
        let r = rows.iter().find(|r| r.mode == "shadow" && r.tracer == "Embree" && r.method == "1").unwrap();
        assert_eq!((r.scene.as_str(), r.triangles, r.width, r.height), ("bunny", 69453, 64, 48));
        assert_eq!(r.rays, [0, 2000, 0, 0, 0]);
        assert_eq!(r.device, "16 threads");
        assert!((r.mrays() - 125.0).abs() < 1e-9);
        assert!(rows.iter().any(|r| r.tracer == "ours" && r.method == "bvh8 packet" && r.mode == "primary"));
        let one = super::ray_report_rows(text, Some(1)).unwrap();
        assert_eq!(one.len(), 2);
        assert!((one[0].mrays() - 15.0).abs() < 1e-9 && one[0].rays == [3072, 0, 0, 0, 0]);
        assert!(super::ray_report_rows(text, Some(8)).unwrap_err().contains("no rates on 8 threads"));
        assert!(super::ray_report_rows("# nothing", None).unwrap_err().contains("no ray report"));
    }

    use super::*;

    #[test]
    fn repeated_runs_merge_into_their_median_and_spread() {
        let row = |scene: &str, ms: f64| Row {
            scene: scene.into(),
            triangles: 3,
            camera: "medium".into(),
            width: 10,
            height: 10,
            mode: "primary".into(),
            lights: 1,
            method: "bvh8".into(),
            median_ms: ms,
            min_ms: ms * 0.9,
            rays: [1000, 0, 0, 0, 0],
            tracer: "ours".into(),
            device: "16 threads".into(),
            intersect: "watertight".into(),
        };
        let rows = [row("a", 2.0), row("b", 1.0), row("a", 4.0), row("a", 1.0), row("b", 3.0)];
        let merged = merge_repeats(&rows);
        assert_eq!(merged.len(), 2);
        let (a, b) = (&merged[0], &merged[1]);
        assert_eq!((a.row.scene.as_str(), a.runs, a.row.median_ms, a.row.min_ms), ("a", 3, 2.0, 0.9));
        assert_eq!((a.slowest, a.fastest), (0.25, 1.0));
        // An even count: the mean of the middle two times.
        assert_eq!((b.row.scene.as_str(), b.runs, b.row.median_ms), ("b", 2, 2.0));
        // A row that differs in anything but its times is a measurement of its own.
        let other = Row { rays: [999, 0, 0, 0, 0], ..row("a", 2.0) };
        assert_eq!(merge_repeats(&[row("a", 2.0), other]).len(), 2);
    }

    #[test]
    fn modes_parse_and_name_themselves() {
        assert_eq!(parse_mode("cast").unwrap(), BenchMode { mode: Mode::Cast, lights: 0 });
        assert_eq!(parse_mode("whitted2").unwrap().name(), "whitted2");
        assert!(parse_mode("whitted0").is_err() && parse_mode("whitted").is_err() && parse_mode("trace").is_err());
    }

    #[test]
    fn figures_keep_three_significant_digits() {
        assert_eq!(significant(0.012345), "0.0123");
        assert_eq!(significant(4.567), "4.57");
        assert_eq!(significant(789.4), "789");
        assert_eq!(significant(12345.6), "12346");
    }

    #[test]
    fn modes_parse_and_name_themselves_back() {
        for name in ["cast", "whitted1", "whitted4", "ao8", "ao1", "ao16:0.25", "diffuse"] {
            assert_eq!(parse_mode(name).unwrap().name(), name);
        }
        assert_eq!(parse_mode("ao8").unwrap().mode, Mode::Ao(Ao { samples: 8, length: 0.1 }));
        assert_eq!(parse_mode("ao2:0.5").unwrap().mode, Mode::Ao(Ao { samples: 2, length: 0.5 }));
        for bad in ["ao", "ao0", "ao8:", "ao8:0", "ao8:-1", "aox", "diffuse2", "whitted"] {
            assert!(parse_mode(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn rows_survive_a_round_trip_through_csv_and_old_files_read_as_vk() {
        let row = Row {
            scene: "dragon".into(),
            triangles: 871416,
            camera: "medium".into(),
            width: 640,
            height: 480,
            mode: "whitted2".into(),
            lights: 2,
            method: "packet".into(),
            median_ms: 12.5,
            min_ms: 11.25,
            rays: [307200, 400000, 100, 0, 0],
            tracer: "cpu".into(),
            device: "Some CPU, 16 threads".into(),
            intersect: "mt".into(),
        };
        let dir = std::env::temp_dir().join(format!("bench-csv-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let csv = dir.join("b.csv");
        let md = write_tables(&csv, "Device: test.", std::slice::from_ref(&row)).unwrap();
        let back = read_csv(&csv).unwrap();
        assert_eq!(back, vec![Row { device: "Some CPU; 16 threads".into(), ..row.clone() }]);
        assert!(
            std::fs::read_to_string(&md).unwrap().contains("| dragon | medium | 640x480 | whitted2 | cpu packet |")
        );
        let old = dir.join("old.csv");
        std::fs::write(
            &old,
            "scene,triangles,camera,width,height,mode,lights,method,median_ms,min_ms,primary,shadow,secondary,mrays_per_s\n\
             bunny,69453,medium,1920,1440,cast,0,lst,0.4416,0.4279,2764800,0,0,6260.9\n",
        )
        .unwrap();
        let old = read_csv(&old).unwrap();
        assert_eq!((old[0].tracer.as_str(), old[0].method.as_str(), old[0].rays), ("vk", "lst", [2764800, 0, 0, 0, 0]));
        assert_eq!(old[0].intersect, "", "a file from before the intersect column does not say");
        assert!((old[0].mrays() - 6260.9).abs() < 0.1);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
