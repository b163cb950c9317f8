//! What a tracer hands back: the 8-bit image, the per-pixel outputs (AOVs) and the rays traced.

/// Per-pixel outputs besides the colour, row-major from the top-left pixel (docs/shading.md,
/// "Output").
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Aovs {
    /// Distance to the primary hit; +inf on a miss.
    pub t: Vec<f32>,
    /// Shading normal at the primary hit, facing the camera; zero on a miss.
    pub normal: Vec<[f32; 3]>,
    /// Index of the primary hit's triangle in the input scene; [`crate::NO_TRIANGLE`] on a miss.
    pub prim: Vec<u32>,
    /// Node boxes tested, over every ray of the pixel.
    pub nodes: Vec<u32>,
    /// Triangles tested, over every ray of the pixel.
    pub tris: Vec<u32>,
}

/// How the primary hits of two renders of one frame differ (see [`Aovs::prim_diff`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PrimDiff {
    /// Pixels whose primary ray hit another triangle at the same distance, within a relative
    /// 1e-4: an exact tie or a shared edge, where two tracers may round differently.
    pub ties: usize,
    /// Pixels whose primary ray hit another triangle at another distance, or hit in one render
    /// and missed in the other.
    pub differs: usize,
}

impl Aovs {
    /// Compares the primary hits pixel by pixel with another render of the same frame.
    pub fn prim_diff(&self, other: &Aovs) -> PrimDiff {
        let mut d = PrimDiff::default();
        for ((&p, &q), (&a, &b)) in self.prim.iter().zip(&other.prim).zip(self.t.iter().zip(&other.t)) {
            if p == q {
                continue;
            }
            let both_hit = p != crate::NO_TRIANGLE && q != crate::NO_TRIANGLE;
            if both_hit && (a - b).abs() <= 1e-4 * a.abs().max(b.abs()) {
                d.ties += 1;
            } else {
                d.differs += 1;
            }
        }
        d
    }
}

/// Rays traced, by kind.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RayCounts {
    pub primary: u64,
    pub shadow: u64,
    pub secondary: u64,
    /// Ambient-occlusion rays ([`crate::Mode::Ao`]).
    pub ao: u64,
    /// Diffuse bounces ([`crate::Mode::Diffuse`]).
    pub diffuse: u64,
    /// Of these, the rays stopped by their own surface; counted only when asked (`--self-hits`),
    /// else zero.
    pub self_hits: SelfHits,
}

impl RayCounts {
    /// Rays traced (self-hits are some of them, not more).
    pub fn total(&self) -> u64 {
        self.primary + self.shadow + self.secondary + self.ao + self.diffuse
    }
}

/// Exact acne: rays leaving a surface that the triangle they leave from meets in `(0, t_max]`
/// with the frame's triangle test, by kind. Such a ray is stopped by its own surface (a shadow or
/// AO ray is blocked, a secondary or diffuse ray finds its own triangle at a distance of about
/// the origin offset; docs/accuracy.md). Deciding it by that one triangle, not by the hit a
/// traversal reports, makes the count the same for every traversal, any-hit ones included.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SelfHits {
    pub shadow: u64,
    pub secondary: u64,
    pub ao: u64,
    pub diffuse: u64,
}

impl SelfHits {
    pub fn total(&self) -> u64 {
        self.shadow + self.secondary + self.ao + self.diffuse
    }
}

impl std::ops::Add for SelfHits {
    type Output = SelfHits;
    fn add(self, o: SelfHits) -> SelfHits {
        SelfHits {
            shadow: self.shadow + o.shadow,
            secondary: self.secondary + o.secondary,
            ao: self.ao + o.ao,
            diffuse: self.diffuse + o.diffuse,
        }
    }
}

impl std::ops::Add for RayCounts {
    type Output = RayCounts;
    fn add(self, o: RayCounts) -> RayCounts {
        RayCounts {
            primary: self.primary + o.primary,
            shadow: self.shadow + o.shadow,
            secondary: self.secondary + o.secondary,
            ao: self.ao + o.ao,
            diffuse: self.diffuse + o.diffuse,
            self_hits: self.self_hits + o.self_hits,
        }
    }
}

/// A rendered image.
#[derive(Clone, Debug)]
pub struct Image {
    pub width: u32,
    pub height: u32,
    /// 8-bit RGB, row-major from the top-left pixel.
    pub rgb: Vec<[u8; 3]>,
    /// Present when [`crate::Settings::aovs`] asked for it.
    pub aov: Option<Aovs>,
    pub rays: RayCounts,
}
