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
use render_spec::{Image, Settings};
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

/// Every method the sweep runs: CPU ordered, stackless, packet; GPU LST, stackless, SST,
/// SST-subgroup and rt-pipeline (refused, with the reason, on a device without it: see
/// [`unsupported`]).
pub const METHODS: [Method; 8] = [
    Method::Cpu(tracer_cpu::Method::Ordered),
    Method::Cpu(tracer_cpu::Method::Stackless),
    Method::Cpu(tracer_cpu::Method::Packet),
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

/// What a point's images are compared with, besides every primary hit against the reference.
#[derive(Clone, Debug)]
pub enum Expect {
    /// Only the primary hits are checked.
    Hits,
    /// Each shot's colours must match these images (the same scene at the origin, at scale 1):
    /// a pixel off by more than [`check::COLOUR_TOLERANCE`] counts as a wrong image (acne).
    Images(Vec<Image>),
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
    /// The method refused the point with this sentence (a limit, not a silent failure).
    pub refusal: Option<String>,
}

impl Tally {
    /// Share of pixels that failed silently: 1 for a crash or hang, `None` for a refusal.
    pub fn failure_rate(&self) -> Option<f64> {
        if self.crash.is_some() || self.hang {
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
}

/// Renders every shot of `case` with `method`. A refusal (a typed error) is returned as `Err`.
fn render_all(case: &Case, method: Method, gpu: Option<&tracer_vk::Gpu>) -> Result<Vec<Image>, String> {
    match method {
        Method::Cpu(m) => {
            let tracer = tracer_cpu::Tracer::new(&case.scene);
            case.shots.iter().map(|s| tracer_cpu::render(&tracer, s, m).map_err(|e| e.to_string())).collect()
        }
        Method::Gpu(m) => {
            let gpu = gpu.ok_or("no Vulkan device")?;
            let mut r = tracer_vk::render::Renderer::new(gpu, &case.scene, m, (8, 8)).map_err(|e| e.to_string())?;
            case.shots.iter().map(|s| r.render(s).map(|o| o.image).map_err(|e| e.to_string())).collect()
        }
    }
}

/// How a run of one method on one point ended.
enum Ended {
    Images(Vec<Image>),
    Refused(String),
    Crashed(String),
}

/// Runs `case` with `method` on a worker thread: a panic is a crash, no answer within `limit` a
/// hang (the thread is left behind; the caller stops using the device).
pub fn run(
    case: &Arc<Case>,
    reference: &Arc<Vec<Vec<check::RefPixel>>>,
    method: Method,
    gpu: Option<&Arc<tracer_vk::Gpu>>,
    limit: Duration,
) -> Tally {
    let (tx, rx) = mpsc::channel();
    let (c, g) = (Arc::clone(case), gpu.cloned());
    std::thread::spawn(move || {
        let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| render_all(&c, method, g.as_deref())));
        let _ = tx.send(match r {
            Ok(Ok(images)) => Ended::Images(images),
            Ok(Err(e)) => Ended::Refused(e),
            Err(p) => Ended::Crashed(
                p.downcast_ref::<String>()
                    .cloned()
                    .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
                    .unwrap_or_else(|| "a panic".to_owned()),
            ),
        });
    });
    let mut tally = Tally::default();
    match rx.recv_timeout(limit) {
        Ok(Ended::Images(images)) => {
            for (k, image) in images.iter().enumerate() {
                let expected = match &case.expect {
                    Expect::Images(v) => v.get(k),
                    Expect::Hits => None,
                };
                check::tally_image(case, &reference[k], &case.shots[k], image, expected, &mut tally);
            }
        }
        Ok(Ended::Refused(e)) => tally.refusal = Some(e),
        Ok(Ended::Crashed(e)) => tally.crash = Some(e),
        Err(_) => tally.hang = true,
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
    pub tally: Tally,
}

/// Runs every case with every method in `methods`, calling `progress` after each point.
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
        for &method in methods {
            let tally = if matches!(method, Method::Gpu(_)) && gpu_lost {
                Tally { refusal: Some("not run: the device hung on an earlier point".to_owned()), ..Tally::default() }
            } else if let Some(why) = unsupported(method, gpu.as_deref()) {
                Tally { refusal: Some(why), ..Tally::default() }
            } else {
                run(&case, &reference, method, gpu.as_ref(), limit)
            };
            if tally.hang && matches!(method, Method::Gpu(_)) {
                gpu_lost = true;
            }
            let row = Row { axis: case.axis, x: case.x, label: case.label.clone(), method, tally };
            progress(&row);
            rows.push(row);
        }
    }
    rows
}
