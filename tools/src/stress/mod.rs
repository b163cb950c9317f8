//! The stability sweep (issue 9): generated stress scenes ([`scenes`]) along each axis of
//! trouble ([`cases`]), rendered by every method, every pixel's primary hit checked against the
//! exact f64 reference ([`check`]), each point counted as correct, a silent failure (wrong
//! closest hit, leak, NaN or infinite value, wrong image, crash, hang) or a clear refusal.
//! `stress` (tools/src/bin/stress.rs) runs it and writes docs/stability.md ([`report`]).

pub mod cases;
pub mod check;
pub mod edge_grid;
pub mod report;
pub mod scenes;

use bvh_format::SceneFile;
use render_spec::{Image, Intersect, Settings};
use std::sync::Arc;
use std::sync::mpsc;
use std::time::Duration;

/// A traversal method of either tracer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Method {
    Cpu(tracer_cpu::Method),
    Gpu(tracer_vk::kernels::Method),
}

impl Method {
    pub fn name(self) -> String {
        match self {
            Method::Cpu(m) => format!("CPU {}", m.name()),
            Method::Gpu(m) => format!("GPU {}", m.name()),
        }
    }
}

/// Every method the sweep runs: CPU ordered, stackless, packet, and the wide BVH one ray at a
/// time and as packets (bvh8, bvh8-packet: the two ways `--method auto`, the default, picks
/// from); GPU LST, stackless, SST, SST-subgroup and rt-pipeline (refused, with the reason, on a
/// device without it: see [`unsupported`]).
pub const METHODS: [Method; 10] = [
    Method::Cpu(tracer_cpu::Method::Ordered),
    Method::Cpu(tracer_cpu::Method::Stackless),
    Method::Cpu(tracer_cpu::Method::Packet),
    Method::Cpu(tracer_cpu::Method::Bvh8),
    Method::Cpu(tracer_cpu::Method::Bvh8Packet),
    Method::Gpu(tracer_vk::kernels::Method::Lst),
    Method::Gpu(tracer_vk::kernels::Method::Stackless),
    Method::Gpu(tracer_vk::kernels::Method::Sst),
    Method::Gpu(tracer_vk::kernels::Method::SstSubgroup),
    Method::Gpu(tracer_vk::kernels::Method::RtPipeline),
];

/// Why `method` does not run on `gpu` at all (a GPU method the device lacks, such as rt-pipeline
/// on lavapipe), as the refusal every point then records; `None` where it runs.
pub fn unsupported(method: Method, gpu: Option<&tracer_vk::Gpu>) -> Option<String> {
    match (method, gpu) {
        (Method::Gpu(m), Some(g)) => crate::auto::support(g, m).err().map(|why| format!("not supported: {why}")),
        _ => None,
    }
}

/// The triangle tests a point runs with: the default edge-consistent test, and Möller-Trumbore
/// (`--intersect mt`) on the axes where the two can differ (rays through edges and vertices, far
/// from the origin, at extreme scales).
pub const INTERSECTS: [Intersect; 2] = [Intersect::Watertight, Intersect::MollerTrumbore];

/// The name of a sweep line: the method, with " mt" for Möller-Trumbore.
pub fn line_name(method: Method, intersect: Intersect) -> String {
    match intersect {
        Intersect::Watertight => method.name(),
        Intersect::MollerTrumbore => format!("{} mt", method.name()),
    }
}

/// What a point's images are compared with, besides every primary hit against the reference.
#[derive(Clone, Debug)]
pub enum Expect {
    /// Only the primary hits are checked.
    Hits,
    /// Each shot's colours must match these images (the same scene at the origin, at scale 1):
    /// a pixel off by more than [`check::COLOUR_TOLERANCE`] counts as a wrong image (acne).
    Images(Vec<Image>),
    /// As `Images`, with the CPU ordered walk's images of the shots themselves, rendered when the
    /// point runs (so that a large frame's image is made only if its axis is swept, and held only
    /// while its point runs).
    CpuOrdered,
}

/// One point of one axis: a scene and the frames rendered of it.
#[derive(Clone, Debug)]
pub struct Case {
    pub axis: &'static str,
    /// The size of the condition, the chart's x.
    pub x: f64,
    pub label: String,
    pub scene: SceneFile,
    pub shots: Vec<Settings>,
    pub expect: Expect,
    /// Hits closer than this to the ray origin are ambiguous (a ray leaving a surface).
    pub near: f64,
    /// Also run every method with Möller-Trumbore ([`INTERSECTS`]).
    pub both_tests: bool,
}

impl Case {
    /// Pixels of all its shots.
    pub fn pixels(&self) -> u64 {
        self.shots.iter().map(|s| s.width as u64 * s.height as u64).sum()
    }

    /// How long one method may take on this point: `limit` for up to 4 Mi pixels (every point
    /// but the large frames), proportionally more above.
    pub fn time_limit(&self, limit: Duration) -> Duration {
        limit * self.pixels().div_ceil(1 << 22).max(1) as u32
    }
}

/// What one method did on one point.
#[derive(Clone, Debug, Default)]
pub struct Tally {
    pub pixels: u64,
    /// Pixels with any silent failure below (each pixel counted once).
    pub failed: u64,
    pub wrong: u64,
    pub leaks: u64,
    pub non_finite: u64,
    /// Pixels whose colour differs from the expected image (acne, a wrong reflection).
    pub image: u64,
    pub crash: Option<String>,
    pub hang: bool,
    /// The device failed (lost, or its kernels dropped work) with this typed error: not silent,
    /// but a failure, not a limit.
    pub fault: Option<String>,
    /// The fault was the device's loss: the GPU is not used again.
    pub device_lost: bool,
    /// The method refused the point with this sentence (a limit, not a silent failure).
    pub refusal: Option<String>,
}

impl Tally {
    /// Share of pixels that failed silently: 1 for a crash or hang, `None` for a refusal.
    pub fn failure_rate(&self) -> Option<f64> {
        if self.crash.is_some() || self.hang || self.fault.is_some() {
            return Some(1.0);
        }
        if self.refusal.is_some() {
            return None;
        }
        Some(self.failed as f64 / self.pixels.max(1) as f64)
    }

    /// Whether anything failed in silence.
    pub fn silent_failure(&self) -> bool {
        self.failure_rate().is_some_and(|r| r > 0.0)
    }

    /// Whether a line with this triangle test failed: Möller-Trumbore's wrong hits, leaks and
    /// wrong pixels at edges are the trade `--intersect mt` makes (docs/shading.md), so only a
    /// crash, hang, device fault or NaN counts against it.
    pub fn failed_with(&self, intersect: Intersect) -> bool {
        match intersect {
            Intersect::Watertight => self.silent_failure(),
            Intersect::MollerTrumbore => {
                self.crash.is_some() || self.hang || self.fault.is_some() || self.non_finite > 0
            }
        }
    }
}

/// Why a method gave no images.
#[derive(Debug)]
enum Stop {
    /// A typed error naming a limit, before the first frame.
    Refused(String),
    /// The device was lost (`true`) or dropped work.
    Fault(String, bool),
    /// The GPU did not finish within its own timeout.
    Hang,
}

impl From<tracer_vk::render::VkRenderError> for Stop {
    fn from(e: tracer_vk::render::VkRenderError) -> Stop {
        use tracer_vk::VkError;
        use tracer_vk::render::VkRenderError as E;
        match e {
            E::Vulkan(VkError::Timeout { .. }) => Stop::Hang,
            E::Vulkan(VkError::DeviceLost) => Stop::Fault(e.to_string(), true),
            E::LostWork { .. } | E::Fault { .. } => Stop::Fault(e.to_string(), false),
            e => Stop::Refused(e.to_string()),
        }
    }
}

/// The shots of `case` with triangle test `intersect`.
fn shots(case: &Case, intersect: Intersect) -> Vec<Settings> {
    let mut shots = case.shots.clone();
    for s in &mut shots {
        s.accuracy.intersect = intersect;
    }
    shots
}

/// Renders every shot of `case` with `method` and `intersect`.
fn render_all(
    case: &Case,
    method: Method,
    intersect: Intersect,
    gpu: Option<&tracer_vk::Gpu>,
) -> Result<Vec<Image>, Stop> {
    let shots = shots(case, intersect);
    match method {
        Method::Cpu(m) => {
            let tracer = tracer_cpu::Tracer::new(&case.scene);
            shots.iter().map(|s| tracer_cpu::render(&tracer, s, m).map_err(|e| Stop::Refused(e.to_string()))).collect()
        }
        Method::Gpu(m) => {
            let gpu = gpu.ok_or_else(|| Stop::Refused("no Vulkan device".to_owned()))?;
            let mut r = tracer_vk::render::Renderer::new(gpu, &case.scene, m, (8, 8))?;
            shots
                .iter()
                .map(|s| {
                    // A frame too large for its hits is judged by its colours against the CPU's:
                    // exact kernels (`--exact`), so that a GPU fusing multiply-adds makes no
                    // difference there (it moves rays by an ulp, which flips a few grazing shadow
                    // rays: differences the hits would show to be rounding, the colours cannot).
                    r.set_exact(!s.aovs);
                    r.render(s).map(|o| o.image).map_err(Stop::from)
                })
                .collect()
        }
    }
}

/// How a run of one method on one point ended.
enum Ended {
    Images(Vec<Image>),
    Stopped(Stop),
    Crashed(String),
}

/// Runs `case` with `method` and `intersect` on a worker thread: a panic is a crash, no answer
/// within the case's share of `limit` a hang (the thread is left behind; the caller stops using
/// the device). `expected` are the images a [`Expect::CpuOrdered`] point compares with.
pub fn run(
    case: &Arc<Case>,
    reference: &Arc<Vec<Vec<check::RefPixel>>>,
    expected: Option<&[Image]>,
    method: Method,
    intersect: Intersect,
    gpu: Option<&Arc<tracer_vk::Gpu>>,
    limit: Duration,
) -> Tally {
    let (tx, rx) = mpsc::channel();
    let (c, g) = (Arc::clone(case), gpu.cloned());
    let worker = std::thread::spawn(move || {
        let r =
            std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| render_all(&c, method, intersect, g.as_deref())));
        // Let go of the device before answering: were this thread's reference the last one, the
        // device would be destroyed here while the caller (or the process's exit) goes on, and
        // lavapipe crashes when its teardown races the exit.
        drop((c, g));
        let _ = tx.send(match r {
            Ok(Ok(images)) => Ended::Images(images),
            Ok(Err(e)) => Ended::Stopped(e),
            Err(p) => Ended::Crashed(
                p.downcast_ref::<String>()
                    .cloned()
                    .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
                    .unwrap_or_else(|| "a panic".to_owned()),
            ),
        });
    });
    let mut tally = Tally::default();
    let answer = rx.recv_timeout(case.time_limit(limit));
    if answer.is_ok() {
        // It has answered, so it only has to end: no thread of a finished run outlives it.
        let _ = worker.join();
    }
    match answer {
        Ok(Ended::Images(images)) => {
            for (k, image) in images.iter().enumerate() {
                let expected = match &case.expect {
                    Expect::Images(v) => v.get(k),
                    Expect::CpuOrdered => expected.and_then(|v| v.get(k)),
                    Expect::Hits => None,
                };
                check::tally_image(case, &reference[k], &case.shots[k], image, expected, &mut tally);
            }
        }
        Ok(Ended::Stopped(Stop::Refused(e))) => tally.refusal = Some(e),
        Ok(Ended::Stopped(Stop::Fault(e, lost))) => (tally.fault, tally.device_lost) = (Some(e), lost),
        Ok(Ended::Stopped(Stop::Hang)) | Err(_) => tally.hang = true,
        Ok(Ended::Crashed(e)) => tally.crash = Some(e),
    }
    tally
}

/// One row of the results: a point, a method, what happened.
#[derive(Clone, Debug)]
pub struct Row {
    pub axis: &'static str,
    pub x: f64,
    pub label: String,
    pub method: Method,
    pub intersect: Intersect,
    pub tally: Tally,
}

impl Row {
    pub fn line(&self) -> String {
        line_name(self.method, self.intersect)
    }

    /// Whether this row failed (see [`Tally::failed_with`]).
    pub fn failed(&self) -> bool {
        self.tally.failed_with(self.intersect)
    }
}

/// Runs every case with every method in `methods` (and, where the case asks, with both triangle
/// tests), calling `progress` after each point.
pub fn sweep(
    cases: Vec<Case>,
    methods: &[Method],
    gpu: Option<Arc<tracer_vk::Gpu>>,
    limit: Duration,
    progress: &dyn Fn(&Row),
) -> Vec<Row> {
    let mut rows = Vec::new();
    let mut gpu_lost = false;
    for case in cases {
        let case = Arc::new(case);
        let reference = Arc::new(case.shots.iter().map(|s| check::reference(&case.scene, s, case.near)).collect());
        let expected = matches!(case.expect, Expect::CpuOrdered).then(|| {
            let tracer = tracer_cpu::Tracer::new(&case.scene);
            let render = |s| tracer_cpu::render(&tracer, s, tracer_cpu::Method::Ordered);
            case.shots.iter().map(render).collect::<Result<Vec<_>, _>>().map_err(|e| e.to_string())
        });
        let intersects = if case.both_tests { &INTERSECTS[..] } else { &INTERSECTS[..1] };
        for &intersect in intersects {
            for &method in methods {
                let tally = if matches!(method, Method::Gpu(_)) && gpu_lost {
                    let why = "not run: the device hung or was lost on an earlier point";
                    Tally { refusal: Some(why.to_owned()), ..Tally::default() }
                } else if let Some(why) = unsupported(method, gpu.as_deref()) {
                    Tally { refusal: Some(why), ..Tally::default() }
                } else if let Some(Err(e)) = &expected {
                    Tally { refusal: Some(format!("no CPU image to compare with: {e}")), ..Tally::default() }
                } else {
                    let expected = expected.as_ref().and_then(|e| e.as_deref().ok());
                    run(&case, &reference, expected, method, intersect, gpu.as_ref(), limit)
                };
                if (tally.hang || tally.device_lost) && matches!(method, Method::Gpu(_)) {
                    gpu_lost = true;
                }
                let row = Row { axis: case.axis, x: case.x, label: case.label.clone(), method, intersect, tally };
                progress(&row);
                rows.push(row);
            }
        }
    }
    rows
}

#[cfg(test)]
mod tests {
    use super::*;
    use tracer_vk::VkError;
    use tracer_vk::render::VkRenderError;

    #[test]
    fn device_errors_are_faults_hangs_or_limits() {
        let lost = Stop::from(VkRenderError::Vulkan(VkError::DeviceLost));
        assert!(matches!(lost, Stop::Fault(ref m, true) if m.contains("lost")), "{lost:?}");
        let dropped = VkRenderError::LostWork { method: "LST", what: "primary rays", done: 1, expected: 2 };
        assert!(matches!(Stop::from(dropped), Stop::Fault(_, false)));
        assert!(matches!(Stop::from(VkRenderError::Vulkan(VkError::Timeout { seconds: 1 })), Stop::Hang));
        let memory = VkRenderError::Vulkan(VkError::OutOfDeviceMemory { label: "nodes".into(), bytes: 1 << 30 });
        assert!(matches!(Stop::from(memory), Stop::Refused(ref m) if m.contains("nodes")));
    }

    #[test]
    fn moller_trumbore_lines_fail_only_on_crashes_hangs_faults_and_nans() {
        let leaks = Tally { pixels: 10, failed: 3, leaks: 2, wrong: 1, ..Tally::default() };
        assert!(leaks.failed_with(Intersect::Watertight));
        assert!(!leaks.failed_with(Intersect::MollerTrumbore));
        let nan = Tally { pixels: 10, failed: 1, non_finite: 1, ..Tally::default() };
        assert!(nan.failed_with(Intersect::MollerTrumbore));
        let fault = Tally { fault: Some("the Vulkan device was lost".into()), ..Tally::default() };
        assert!(fault.failed_with(Intersect::MollerTrumbore) && fault.failure_rate() == Some(1.0));
        assert!(report::cell(&fault).starts_with("**FAULT**"));
    }

    #[test]
    fn triangle_counts_grow_by_ten_up_to_the_cap() {
        assert_eq!(cases::triangle_counts(100_000), [1000, 10_000, 100_000]);
        assert_eq!(cases::triangle_counts(3_000_000), [1000, 10_000, 100_000, 1_000_000, 3_000_000]);
        assert_eq!(cases::triangle_counts(1000), [1000]);
        for n in [1000u64, 100_000, 3_000_000] {
            let side = scenes::terrain_side(n) as u64;
            assert!((2 * side * side).abs_diff(n) <= 4 * side, "{n}: side {side}");
        }
    }

    #[test]
    fn large_frames_get_more_time_than_small_ones() {
        let scene = scenes::chain(2);
        let shot = cases::shot(&scene, render_spec::CameraSpec::from(&scene.cameras[0]), 16384, 16384);
        let mut c = Case {
            axis: cases::AXES[13],
            x: 0.0,
            label: String::new(),
            scene,
            shots: vec![shot],
            expect: Expect::CpuOrdered,
            near: 0.0,
            both_tests: false,
        };
        assert_eq!(c.time_limit(Duration::from_secs(60)), Duration::from_secs(60 * 64));
        c.shots[0].width = 64;
        c.shots[0].height = 48;
        assert_eq!(c.time_limit(Duration::from_secs(60)), Duration::from_secs(60));
    }
}
