use crate::layout::SectionKind;
use thiserror::Error;

/// Which node layout an error is about.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LayoutKind {
    ChildPair,
    Escape,
}

impl std::fmt::Display for LayoutKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            LayoutKind::ChildPair => "child-pair",
            LayoutKind::Escape => "escape-pointer",
        })
    }
}

/// Everything that can be wrong with a scene file. Each message is one sentence for the user.
#[derive(Debug, Error, PartialEq)]
pub enum FormatError {
    #[error("the file is truncated: {what} needs {needed} bytes but the file has {len}")]
    Truncated { what: &'static str, needed: u64, len: u64 },
    #[error("this is not a BVH scene file (wrong magic bytes)")]
    BadMagic,
    #[error(
        "the file has format version {found}, which this program no longer reads (it reads version {supported}); recompile it from its source with `bvhc compile`"
    )]
    OldVersion { found: u32, supported: u32 },
    #[error("the file has format version {found}, but this program reads version {supported}")]
    UnsupportedVersion { found: u32, supported: u32 },
    #[error("the header is damaged (its checksum does not match)")]
    HeaderChecksum,
    #[error("the header is damaged: {0}")]
    BadHeader(&'static str),
    #[error("section {0} is unknown to this program")]
    UnknownSection(u32),
    #[error("section {0} appears twice")]
    DuplicateSection(SectionKind),
    #[error("the file has no {0} section")]
    MissingSection(SectionKind),
    #[error("the {section} section (offset {offset}, {size} bytes) reaches past the end of the {file_len}-byte file")]
    SectionOutOfBounds { section: SectionKind, offset: u64, size: u64, file_len: u64 },
    #[error("the {section} section starts at offset {offset}, which is not 16-byte aligned")]
    SectionMisaligned { section: SectionKind, offset: u64 },
    #[error("the {section} section has element size {found}, expected {expected}")]
    ElementSize { section: SectionKind, expected: u32, found: u32 },
    #[error("the {a} and {b} sections overlap")]
    SectionOverlap { a: SectionKind, b: SectionKind },
    #[error("the {section} section is damaged (its checksum does not match)")]
    Checksum { section: SectionKind },
    #[error("the {section} section has {found} entries, but the header says {expected}")]
    CountMismatch { section: SectionKind, expected: u64, found: u64 },
    #[error("the {section} section holds a non-finite number in entry {index}")]
    NonFinite { section: SectionKind, index: u64 },
    #[error("entry {index} of the {section} section refers to {value}, which is out of range (limit {limit})")]
    IndexOutOfRange { section: SectionKind, index: u64, value: u64, limit: u64 },
    #[error("input triangle {0} appears more than once in the triangle permutation")]
    PermutationRepeats(u32),
    #[error("material {index} is invalid: {reason}")]
    BadMaterial { index: u32, reason: &'static str },
    #[error(
        "the names of the materials are not valid UTF-8 text, contain NUL bytes or do not match the material count"
    )]
    BadNames,
    #[error("camera {0} has a name that is not valid UTF-8")]
    BadCameraName(u32),
    #[error("the header's layout flags {0:#x} name no known node layout")]
    NoLayout(u32),
    #[error("node {node} of the escape-pointer layout has escape index {escape}, which does not move forward")]
    EscapeBackwards { node: u32, escape: u32 },
    #[error("node {node} of the {layout} layout is malformed: {reason}")]
    TreeShape { layout: LayoutKind, node: u32, reason: &'static str },
    #[error("node {node} of the {layout} layout has bounds outside its parent's")]
    ChildOutsideParent { layout: LayoutKind, node: u32 },
    #[error("node {node} of the {layout} layout has inverted bounds (min above max)")]
    InvertedBounds { layout: LayoutKind, node: u32 },
    #[error("triangle {triangle} is referenced by {times} leaves of the {layout} layout instead of exactly one")]
    LeafCoverage { layout: LayoutKind, triangle: u32, times: u32 },
    #[error("the header says the tree is {header} deep, but the {layout} layout is {actual} deep")]
    DepthMismatch { layout: LayoutKind, header: u32, actual: u32 },
    #[error("the header says the tree has an SAH cost of {header}, but the {layout} layout has {actual}")]
    SahCostMismatch { layout: LayoutKind, header: f32, actual: f32 },
    #[error("the header says the tree has {header} leaves, but the {layout} layout has {actual}")]
    LeafCountMismatch { layout: LayoutKind, header: u32, actual: u32 },
    #[error("the child-pair and escape-pointer layouts describe different trees (first difference at escape node {0})")]
    LayoutsDiffer(u32),
    #[error("the scene has no triangles")]
    Empty,
    #[error("leaf {node} of the {layout} layout does not contain all of its triangles")]
    TriangleOutsideLeaf { layout: LayoutKind, node: u32 },
    #[error("node {node} of the wide layout is malformed: {reason}")]
    WideShape { node: u32, reason: &'static str },
    #[error("triangle {triangle} is referenced by {times} leaves of the wide layout instead of exactly one")]
    WideCoverage { triangle: u32, times: u32 },
    #[error("slot {slot} of node {node} of the wide layout has a box that does not contain all of its triangles")]
    WideBoxTooSmall { node: u32, slot: u32 },
    #[error(
        "the wide layout is present without a binary one (child-pair or escape-pointer), which the header describes"
    )]
    WideAlone,
    #[error("entry {index} of the {section} section has non-zero padding")]
    NonZeroPadding { section: SectionKind, index: u64 },
}

/// A scene file that could not be read or written.
#[derive(Debug, Error)]
pub enum FileError {
    #[error("cannot read {path}: {source}")]
    Read { path: String, source: std::io::Error },
    #[error("cannot write {path}: {source}")]
    Write { path: String, source: std::io::Error },
    #[error("{path} is not a valid scene file: {source}")]
    Invalid { path: String, source: FormatError },
    #[error("the scene was not written to {path}, because it would not be a valid scene file: {source}")]
    InvalidScene { path: String, source: FormatError },
}
