//! Where the triangle tests find a triangle's corners (`--vertices`): the tracer's own expanded
//! copy (48 bytes per triangle, one contiguous read) or the file's indexed arrays (no copy, a
//! read of the index and then of three vertices). Both give a triangle with the same bits, so the
//! same hits.
//!
//! The traversals are generic over [`TriangleSource`], so that each form is compiled into its own
//! loop (the expanded form's is the loop it always was); [`Triangles`] picks one per ray, and is
//! what shading reads (once per hit, where a branch costs nothing).

use bvh_format::{IndexedTriangle, SceneFile, Triangle};
use render_spec::Vertices;

/// Triangle `i` (in leaf order) as the triangle tests take it.
pub trait TriangleSource: Sync {
    fn triangle(&self, i: u32) -> Triangle;
    fn len(&self) -> usize;
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

impl TriangleSource for [Triangle] {
    #[inline(always)]
    fn triangle(&self, i: u32) -> Triangle {
        self[i as usize]
    }
    fn len(&self) -> usize {
        <[Triangle]>::len(self)
    }
}

/// A `Vec` of expanded triangles as its slice, so that callers may pass `&vec`.
impl TriangleSource for Vec<Triangle> {
    #[inline(always)]
    fn triangle(&self, i: u32) -> Triangle {
        self[i as usize]
    }
    fn len(&self) -> usize {
        Vec::len(self)
    }
}

/// The file's indexed form, read in place.
#[derive(Clone, Copy)]
pub struct Indexed<'a> {
    pub triangles: &'a [IndexedTriangle],
    pub vertices: &'a [[f32; 3]],
}

impl<'a> Indexed<'a> {
    pub fn new(scene: &'a SceneFile) -> Self {
        Self { triangles: &scene.triangles, vertices: &scene.vertices }
    }
}

impl TriangleSource for Indexed<'_> {
    /// [`SceneFile::triangle`], the form the expanded copy is made with.
    #[inline(always)]
    fn triangle(&self, i: u32) -> Triangle {
        let t = &self.triangles[i as usize];
        let [a, b, c] = t.vertices.map(|v| self.vertices[v as usize]);
        Triangle { material: t.material, ..Triangle::from_vertices(a, b, c) }
    }
    fn len(&self) -> usize {
        self.triangles.len()
    }
}

/// The triangles of a [`crate::Tracer`] in the form it was made with.
#[derive(Clone, Copy)]
pub enum Triangles<'a> {
    Expanded(&'a [Triangle]),
    Indexed(Indexed<'a>),
}

impl<'a> Triangles<'a> {
    pub fn form(&self) -> Vertices {
        match self {
            Triangles::Expanded(_) => Vertices::Expanded,
            Triangles::Indexed(_) => Vertices::Indexed,
        }
    }

    /// The expanded copy, where the tracer holds one.
    pub fn expanded(&self) -> Option<&'a [Triangle]> {
        match *self {
            Triangles::Expanded(t) => Some(t),
            Triangles::Indexed(_) => None,
        }
    }

    /// Every triangle in leaf order.
    pub fn iter(&self) -> impl Iterator<Item = Triangle> + '_ {
        (0..self.len() as u32).map(|i| self.triangle(i))
    }
}

impl TriangleSource for Triangles<'_> {
    #[inline]
    fn triangle(&self, i: u32) -> Triangle {
        match self {
            Triangles::Expanded(t) => t.triangle(i),
            Triangles::Indexed(t) => t.triangle(i),
        }
    }
    fn len(&self) -> usize {
        match self {
            Triangles::Expanded(t) => t.len(),
            Triangles::Indexed(t) => t.len(),
        }
    }
}
