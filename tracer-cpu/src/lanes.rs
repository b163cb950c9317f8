//! How the rays of one stage of a pixel block are traced: the renderer hands up to 8 rays (the
//! lanes of a 4 x 2 block: primary rays, the shadow rays towards one light, or the secondary rays
//! of one indirection) to a [`TraceLanes`], which traces them as an AVX2 packet or one by one.
//! Every way finds the same hits (bit for bit), so the choice changes speed and the cost AOV only.

use crate::geometry::{MollerTrumbore, Ray, TriangleTest, Watertight};
use crate::packet::{self, Entry, LANES, Rays, Results};
use crate::packet8;
use crate::render::Walk;
use crate::traverse::Stack;
use crate::vertices::Triangles;
use render_spec::Intersect;

/// Traces the valid lanes of `rays` with the triangle test `test` (the frame's); a lane's hit is
/// its closest hit in `(0, t_max]`, or for [`TraceLanes::occluded`] any hit (Some means blocked).
/// Lanes that are not valid get no hit and no cost.
pub trait TraceLanes {
    fn closest(&mut self, rays: &Rays, test: Intersect) -> Results;
    fn occluded(&mut self, rays: &Rays, test: Intersect) -> Results;

    /// [`Self::closest`] for rays of the stage `stage` (the Whitted driver says which), for a
    /// tracer that picks its way by the kind of ray.
    fn closest_in(&mut self, stage: Stage, rays: &Rays, test: Intersect) -> Results {
        let _ = stage;
        self.closest(rays, test)
    }

    /// [`Self::occluded`] for rays of the stage `stage`.
    fn occluded_in(&mut self, stage: Stage, rays: &Rays, test: Intersect) -> Results {
        let _ = stage;
        self.occluded(rays, test)
    }
}

/// The kinds of ray the Whitted driver traces: the coherent primary rays and shadow rays of a
/// block towards one light, and the incoherent mirror and glass bounces, AO and diffuse rays.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stage {
    Primary,
    Shadow,
    Secondary,
    Ao,
    Diffuse,
}

impl Stage {
    /// Every stage, in the order of [`Stage::index`].
    pub const ALL: [Stage; 5] = [Stage::Primary, Stage::Shadow, Stage::Secondary, Stage::Ao, Stage::Diffuse];

    /// This stage's place in [`Stage::ALL`] (for tables indexed by stage).
    pub fn index(self) -> usize {
        self as usize
    }

    /// The stage's name in messages (`trace-cpu render`'s timing line).
    pub fn name(self) -> &'static str {
        match self {
            Stage::Primary => "primary",
            Stage::Shadow => "shadow",
            Stage::Secondary => "secondary",
            Stage::Ao => "AO",
            Stage::Diffuse => "diffuse",
        }
    }
}

/// One ray at a time with a scalar traversal (ordered or stackless, as
/// [`Tracer::walk`](crate::Tracer::walk) chose it).
pub struct OneByOne<'a> {
    walk: Walk<'a>,
    stack: Stack,
}

impl<'a> OneByOne<'a> {
    pub fn new(walk: Walk<'a>) -> Self {
        Self { walk, stack: Stack::default() }
    }

    #[inline(always)]
    fn trace<const ANY: bool, T: TriangleTest>(&mut self, rays: &Rays) -> Results {
        let mut out = Results::default();
        // Every lane's ray with its reciprocals made before the first is traced, so that no
        // ray's first box test waits for its divisions.
        let prepared: [Ray; LANES] = std::array::from_fn(|i| rays.ray(i));
        for (i, ray) in prepared.iter().enumerate() {
            if !rays.valid[i] {
                continue;
            }
            let hit = self.walk.trace::<ANY, T>(ray, 0.0, rays.t_max[i], &mut self.stack, &mut out.cost[i]);
            out.set(i, hit);
        }
        out
    }

    fn trace_with<const ANY: bool>(&mut self, rays: &Rays, test: Intersect) -> Results {
        match test {
            Intersect::Watertight => self.trace::<ANY, Watertight>(rays),
            Intersect::MollerTrumbore => self.trace::<ANY, MollerTrumbore>(rays),
        }
    }
}

impl TraceLanes for OneByOne<'_> {
    fn closest(&mut self, rays: &Rays, test: Intersect) -> Results {
        self.trace_with::<false>(rays, test)
    }
    fn occluded(&mut self, rays: &Rays, test: Intersect) -> Results {
        self.trace_with::<true>(rays, test)
    }
}

/// 8-wide AVX2 packets over the child-pair layout; a stage with few live lanes (the rays that
/// are left after some bounces) goes one ray at a time with ordered traversal, which then costs
/// less than walking the tree for a mostly empty packet.
pub struct Packets<'a> {
    stack: Vec<Entry>,
    single: OneByOne<'a>,
}

/// Lanes at or below which a stage is traced one ray at a time.
const SPARSE: usize = 2;

impl<'a> Packets<'a> {
    /// Packets over the child-pair layout of `walk` (from `Tracer::walk(Method::Packet)`), only
    /// where [`packet::available`]. Given a stackless walk, every ray goes one by one on it: packets
    /// exist for the child-pair layout only, and the caller chose that walk.
    pub fn new(walk: Walk<'a>) -> Self {
        Self { stack: Vec::with_capacity(128), single: OneByOne::new(walk) }
    }

    fn trace<const ANY: bool, T: TriangleTest>(&mut self, rays: &Rays) -> Results {
        let walk = self.single.walk;
        match walk.child_pair() {
            Some(nodes) if rays.count() > SPARSE => match walk.tracer().triangles() {
                Triangles::Expanded(tris) => packet::trace::<ANY, T>(nodes, tris, rays, &mut self.stack),
                Triangles::Indexed(tris) => packet::trace::<ANY, T>(nodes, &tris, rays, &mut self.stack),
            },
            _ => self.single.trace::<ANY, T>(rays),
        }
    }

    fn trace_with<const ANY: bool>(&mut self, rays: &Rays, test: Intersect) -> Results {
        match test {
            Intersect::Watertight => self.trace::<ANY, Watertight>(rays),
            Intersect::MollerTrumbore => self.trace::<ANY, MollerTrumbore>(rays),
        }
    }
}

impl TraceLanes for Packets<'_> {
    fn closest(&mut self, rays: &Rays, test: Intersect) -> Results {
        self.trace_with::<false>(rays, test)
    }
    fn occluded(&mut self, rays: &Rays, test: Intersect) -> Results {
        self.trace_with::<true>(rays, test)
    }
}

/// `--method auto`: every ray on the wide BVH one at a time ([`crate::bvh8`]), except in the
/// stages where auto's measurement ([`crate::render::plan`]) found packets on the same wide BVH
/// ([`crate::packet8`], `--method bvh8-packet`) faster. A packet stage's calls with few live lanes
/// still go one by one, which then costs less than a mostly empty packet.
pub struct Mixed<'a> {
    single: OneByOne<'a>,
    packets: Option<packet8::Lanes<'a>>,
    /// Per stage ([`Stage::index`]): whether its rays go as packets.
    packet_stages: [bool; Stage::ALL.len()],
}

impl<'a> Mixed<'a> {
    /// Singles on `wide` (a bvh8 walk); wide packets on its BVH for the stages marked in
    /// `packet_stages`, none where `wide` walks no wide BVH or this CPU runs no wide packets
    /// ([`Walk::packet_bvh8`]).
    pub fn new(wide: Walk<'a>, packet_stages: [bool; Stage::ALL.len()]) -> Self {
        let packets = wide.packet_bvh8().map(packet8::Lanes::new);
        Self { single: OneByOne::new(wide), packets, packet_stages }
    }

    /// The packets for `stage`'s `rays`, where this stage takes them and enough lanes are live.
    #[inline]
    fn packets_for(&mut self, stage: Stage, rays: &Rays) -> Option<&mut packet8::Lanes<'a>> {
        match &mut self.packets {
            Some(p) if self.packet_stages[stage.index()] && rays.count() > SPARSE => Some(p),
            _ => None,
        }
    }
}

impl TraceLanes for Mixed<'_> {
    fn closest(&mut self, rays: &Rays, test: Intersect) -> Results {
        self.single.closest(rays, test)
    }
    fn occluded(&mut self, rays: &Rays, test: Intersect) -> Results {
        self.single.occluded(rays, test)
    }
    fn closest_in(&mut self, stage: Stage, rays: &Rays, test: Intersect) -> Results {
        match self.packets_for(stage, rays) {
            Some(p) => p.closest(rays, test),
            None => self.single.closest(rays, test),
        }
    }
    fn occluded_in(&mut self, stage: Stage, rays: &Rays, test: Intersect) -> Results {
        match self.packets_for(stage, rays) {
            Some(p) => p.occluded(rays, test),
            None => self.single.occluded(rays, test),
        }
    }
}
