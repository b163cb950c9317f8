//! The byte layout: the fixed header, the section table and the section kinds.
//! `FORMAT.md` beside this crate documents the same layout for readers in other languages.

use crate::types::{Camera, IndexedTriangle, Light, Material, Node};
use crate::wide::WideNode;
use bytemuck::{Pod, Zeroable};

pub const MAGIC: [u8; 8] = *b"BVHSCENE";
pub const VERSION: u32 = 4;
/// Every section starts at a multiple of this.
pub const ALIGN: u64 = 16;

/// Header flag: the child-pair layout is present.
pub const FLAG_CHILD_PAIR: u32 = 1;
/// Header flag: the escape-pointer layout is present.
pub const FLAG_ESCAPE: u32 = 2;
/// Header flag: the wide (8-wide, compressed) layout is present.
pub const FLAG_WIDE: u32 = 4;

/// The fixed header at offset 0, 184 bytes, little-endian.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct Header {
    pub magic: [u8; 8],
    pub version: u32,
    pub header_size: u32,
    pub flags: u32,
    pub section_count: u32,
    pub triangle_count: u32,
    pub vertex_count: u32,
    pub normal_count: u32,
    pub node_count: u32,
    pub leaf_count: u32,
    pub max_depth: u32,
    pub material_count: u32,
    pub camera_count: u32,
    pub light_count: u32,
    pub max_indirections: u32,
    pub strategy: u32,
    pub bins: u32,
    pub max_leaf_size: u32,
    pub traversal_cost: f32,
    pub intersection_cost: f32,
    pub sah_cost: f32,
    pub bounds_min: [f32; 3],
    pub _pad0: u32,
    pub bounds_max: [f32; 3],
    pub _pad1: u32,
    pub ambient: [f32; 3],
    pub _pad2: u32,
    pub background: [f32; 3],
    pub _pad3: u32,
    /// World position of the scene's local origin; every stored position is relative to it
    /// (finite; see [`crate::SceneFile::origin`]).
    pub origin: [f64; 3],
    /// Power of two of the stored unit in world units (see [`crate::SceneFile::scale_log2`]);
    /// within [`crate::MAX_SCALE_LOG2`] of zero.
    pub scale_log2: i32,
    /// CRC-32 of the header (with this field zero) followed by the section table.
    pub header_crc: u32,
}

pub const HEADER_SIZE: usize = std::mem::size_of::<Header>();

/// One entry of the section table that follows the header, 32 bytes.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct SectionEntry {
    pub kind: u32,
    pub element_size: u32,
    pub count: u64,
    pub offset: u64,
    /// CRC-32 of the section's bytes.
    pub crc: u32,
    pub _reserved: u32,
}

pub const SECTION_ENTRY_SIZE: usize = std::mem::size_of::<SectionEntry>();

/// The kinds of section, with their numeric tags in the section table.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum SectionKind {
    Vertices = 1,
    Triangles = 2,
    Normals = 3,
    NormalIndices = 4,
    Materials = 5,
    MaterialNames = 6,
    InputIndex = 7,
    NodesChildPair = 8,
    NodesEscape = 9,
    Cameras = 10,
    Lights = 11,
    NodesWide = 12,
}

impl SectionKind {
    pub const ALL: [SectionKind; 12] = [
        SectionKind::Vertices,
        SectionKind::Triangles,
        SectionKind::Normals,
        SectionKind::NormalIndices,
        SectionKind::Materials,
        SectionKind::MaterialNames,
        SectionKind::InputIndex,
        SectionKind::NodesChildPair,
        SectionKind::NodesEscape,
        SectionKind::Cameras,
        SectionKind::Lights,
        SectionKind::NodesWide,
    ];

    pub fn from_u32(v: u32) -> Option<Self> {
        Self::ALL.into_iter().find(|k| *k as u32 == v)
    }

    /// Bytes per element.
    pub fn element_size(self) -> u32 {
        (match self {
            SectionKind::Vertices | SectionKind::Normals | SectionKind::NormalIndices => 12,
            SectionKind::Triangles => std::mem::size_of::<IndexedTriangle>(),
            SectionKind::InputIndex => 4,
            SectionKind::Materials => std::mem::size_of::<Material>(),
            SectionKind::MaterialNames => 1,
            SectionKind::NodesChildPair | SectionKind::NodesEscape => std::mem::size_of::<Node>(),
            SectionKind::Cameras => std::mem::size_of::<Camera>(),
            SectionKind::Lights => std::mem::size_of::<Light>(),
            SectionKind::NodesWide => std::mem::size_of::<WideNode>(),
        }) as u32
    }

    pub fn name(self) -> &'static str {
        match self {
            SectionKind::Vertices => "vertices",
            SectionKind::Triangles => "triangles",
            SectionKind::Normals => "normals",
            SectionKind::NormalIndices => "normal indices",
            SectionKind::Materials => "materials",
            SectionKind::MaterialNames => "material names",
            SectionKind::InputIndex => "input index",
            SectionKind::NodesChildPair => "child-pair nodes",
            SectionKind::NodesEscape => "escape-pointer nodes",
            SectionKind::Cameras => "cameras",
            SectionKind::Lights => "lights",
            SectionKind::NodesWide => "wide nodes",
        }
    }
}

impl std::fmt::Display for SectionKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

const _: () = assert!(HEADER_SIZE == 184);
const _: () = assert!(SECTION_ENTRY_SIZE == 32);
