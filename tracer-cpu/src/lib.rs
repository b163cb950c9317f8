//! The CPU tracer: the baseline every GPU figure is compared against, and the trusted side of the
//! cross-backend image diffs. The shading definition it implements is `docs/shading.md`.
//!
//! - [`geometry`]: rays, the slab test, Möller-Trumbore, self-intersection offsets.
//! - [`traverse`]: scalar ordered child-pair traversal and stackless escape-pointer traversal.
//! - [`bvh8`]: the wide BVHs (8 or 4 children per node, collapsed at load from the child-pair
//!   tree) and their single-ray traversal, 8 boxes or 8 triangles per AVX2 sequence, 4 per 128-bit
//!   sequence.
//! - [`packet`]: 8-wide AVX2 packets for coherent primary and shadow rays over the child-pair tree;
//!   [`packet8`]: the same packets over the wide BVH.
//! - [`reference`]: the exact f64 reference: brute-force and traversed closest hits, and images.
//! - [`vertices`]: where the triangle tests read a triangle's corners, the expanded copy or the
//!   file's indexed arrays (`--vertices`).
//! - [`lanes`]: the rays of one stage of a 4 x 2 pixel block, traced as a packet or one by one.
//! - [`shade`]: the shading formulas; [`whitted`]: the stages of ray casting and Whitted ray
//!   tracing for a block of pixels.
//! - [`render`]: whole images in parallel bands, written straight into the 8-bit image and AOVs.

pub mod bvh8;
#[cfg(feature = "embree")]
pub mod embree;
pub mod geometry;
pub mod lanes;
pub mod packet;
pub mod packet8;
pub mod reference;
pub mod render;
pub mod shade;
pub mod traverse;
pub mod vertices;
pub mod whitted;
pub mod wide;

pub use geometry::{Cost, Hit, Ray};
pub use render::{Tracer, Walk, render, render_with_progress};
pub use render_spec::Vertices;

/// How rays find their closest hit.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Method {
    /// Ordered traversal of the child-pair layout with a stack, one ray at a time.
    Ordered,
    /// Stackless walk of the escape-pointer layout, one ray at a time.
    Stackless,
    /// The wide BVH ([`bvh8`]), derived at load from the child-pair layout, one ray at a time:
    /// all 8 children's boxes, or all of a leaf's triangles, tested in one AVX2 sequence (one
    /// lane at a time without AVX2).
    Bvh8,
    /// The 4-wide BVH ([`bvh8::Bvh4`]), collapsed at load the same way, one ray at a time: all 4
    /// children's boxes, or all of a leaf's up to 4 triangles, tested in one 128-bit sequence.
    Bvh4,
    /// 8-wide SIMD packets (AVX2) for primary and shadow rays, ordered traversal for the rest.
    Packet,
    /// 8-wide SIMD packets (AVX2) over the wide BVH ([`packet8`]) for every stage of a block,
    /// lanes left alone finishing on the wide BVH one at a time ([`Method::Bvh8`], which it is
    /// without AVX2).
    Bvh8Packet,
    /// Picked per kind of ray (`lanes::Mixed`): the rays of each stage (primary, shadow,
    /// secondary, AO, diffuse) one at a time on the wide BVH ([`Method::Bvh8`]) or as packets on
    /// it ([`Method::Bvh8Packet`]), whichever a short measurement of the frame's own rays at its
    /// start ([`render::plan`]) finds faster. [`Method::Stackless`] for a file that holds only the
    /// escape-pointer layout.
    Auto,
}

impl Method {
    /// Every method, in the order `trace-cpu --help` lists them: the one list of CPU method names
    /// (the CLI, `trace-cpu bench`, the examples and the tests take it from here).
    pub const ALL: [Method; 7] = [
        Method::Auto,
        Method::Packet,
        Method::Ordered,
        Method::Stackless,
        Method::Bvh8,
        Method::Bvh4,
        Method::Bvh8Packet,
    ];

    /// The method `trace-cpu --method` calls `name`.
    pub fn named(name: &str) -> Option<Method> {
        Method::ALL.into_iter().find(|m| m.name() == name)
    }

    /// The names of [`Method::ALL`], comma-separated, for messages.
    pub fn names() -> String {
        Method::ALL.map(Method::name).join(", ")
    }

    /// The method actually used on `scene`: packets fall back to ordered traversal without AVX2,
    /// and `Auto` takes the stackless walk when the file has no child-pair layout.
    pub fn resolve(self, scene: &bvh_format::SceneFile) -> Method {
        match self {
            Method::Auto if scene.child_pair.is_none() && scene.escape.is_some() => Method::Stackless,
            Method::Packet if packet::available() => Method::Packet,
            Method::Packet => Method::Ordered,
            Method::Bvh8Packet if packet8::available() => Method::Bvh8Packet,
            Method::Bvh8Packet => Method::Bvh8,
            m => m,
        }
    }

    /// The name `trace-cpu --method` takes.
    pub fn name(self) -> &'static str {
        match self {
            Method::Ordered => "ordered",
            Method::Stackless => "stackless",
            Method::Bvh8 => "bvh8",
            Method::Bvh4 => "bvh4",
            Method::Packet => "packet",
            Method::Bvh8Packet => "bvh8-packet",
            Method::Auto => "auto",
        }
    }
}

/// Bytes of the file as trace-cpu reads it into memory: the indexed geometry, normals, materials,
/// input indices and every layout stored (the wide layout included, which trace-cpu does not
/// walk).
pub fn file_bytes(scene: &bvh_format::SceneFile) -> u64 {
    let nodes = |n: &Option<Vec<bvh_format::Node>>| n.as_ref().map_or(0, |n| std::mem::size_of_val(&n[..]));
    let s = scene;
    (std::mem::size_of_val(&s.vertices[..])
        + std::mem::size_of_val(&s.triangles[..])
        + std::mem::size_of_val(&s.normals[..])
        + std::mem::size_of_val(&s.normal_indices[..])
        + std::mem::size_of_val(&s.materials[..])
        + std::mem::size_of_val(&s.input_index[..])
        + nodes(&s.child_pair)
        + nodes(&s.escape)
        + s.wide.as_ref().map_or(0, |w| std::mem::size_of_val(&w[..]))) as u64
}

/// Bytes of scene data trace-cpu holds while rendering `scene` with the vertex form `vertices`
/// and a method that does not collapse the wide BVH (for `bvhc info`; [`Tracer::held_bytes`]
/// counts a render's own): the file as read ([`file_bytes`]), and in the expanded form the
/// triangles expanded to three vertices each for intersection (48 bytes per triangle).
pub fn held_bytes(scene: &bvh_format::SceneFile, vertices: Vertices) -> u64 {
    let expanded = match vertices {
        Vertices::Expanded => scene.triangles.len() * std::mem::size_of::<bvh_format::Triangle>(),
        Vertices::Indexed => 0,
    };
    file_bytes(scene) + expanded as u64
}

#[cfg(test)]
mod tests {
    use super::Method;

    #[test]
    fn every_method_is_found_by_its_name() {
        for m in Method::ALL {
            assert_eq!(Method::named(m.name()), Some(m));
            assert!(Method::names().contains(m.name()));
        }
        assert_eq!(Method::named("Packet"), None);
        assert_eq!(Method::names().split(", ").count(), Method::ALL.len());
    }
}
