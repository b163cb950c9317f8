//! The reader and validator. Order of checks: header and section table (sizes, alignment,
//! overlaps, checksums), then the contents of every section, then the trees. Nothing is returned
//! until all of them pass.

use crate::SceneFile;
use crate::error::{FileError, FormatError, LayoutKind};
use crate::layout::{
    ALIGN, FLAG_CHILD_PAIR, FLAG_ESCAPE, FLAG_WIDE, HEADER_SIZE, Header, MAGIC, SECTION_ENTRY_SIZE, SectionEntry,
    SectionKind, VERSION,
};
use crate::tree::{self, Tree};
use crate::types::{BuildParams, FLAT, IndexedTriangle, SceneSettings, Strategy};
use bytemuck::Pod;

/// Size of one section, as `bvhc info` reports it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SectionInfo {
    pub kind: SectionKind,
    pub count: u64,
    pub bytes: u64,
    pub offset: u64,
}

/// [`read`], also returning the section table in file order (for `bvhc info`).
pub fn read_with_sections(bytes: &[u8]) -> Result<(SceneFile, Vec<SectionInfo>), FormatError> {
    let scene = read(bytes)?;
    let header: Header = bytemuck::pod_read_unaligned(&bytes[..HEADER_SIZE]);
    let table = &bytes[HEADER_SIZE..HEADER_SIZE + header.section_count as usize * SECTION_ENTRY_SIZE];
    let sections = table
        .chunks_exact(SECTION_ENTRY_SIZE)
        .filter_map(|c| {
            let e: SectionEntry = bytemuck::pod_read_unaligned(c);
            let kind = SectionKind::from_u32(e.kind)?;
            Some(SectionInfo { kind, count: e.count, bytes: e.count * e.element_size as u64, offset: e.offset })
        })
        .collect();
    Ok((scene, sections))
}

/// Reads and validates a scene file held in memory.
pub fn read(bytes: &[u8]) -> Result<SceneFile, FormatError> {
    read_from(&Memory(bytes)).map_err(|e| match e {
        Failure::Format(e) => e,
        Failure::Source(never) => match never {},
    })
}

/// Where the reader takes a file's bytes from: memory ([`Memory`]), or an open file read piece by
/// piece straight into each section's array ([`OpenFile`]). The checks, their order and their
/// errors are the same for both: they are written once, in [`read_from`].
trait Source {
    /// What reading can fail with besides the file's contents (nothing, for memory).
    type Error;
    /// The file's length in bytes.
    fn len(&self) -> u64;
    /// `n` bytes from `offset` (a range the caller has checked lies within [`Source::len`]).
    fn bytes(&self, offset: u64, n: usize) -> Result<std::borrow::Cow<'_, [u8]>, Self::Error>;
    /// The `T`s of `n` bytes from `offset` (within the file, a multiple of `T`'s size), in a new
    /// array.
    fn items<T: Pod + Send>(&self, offset: u64, n: usize) -> Result<Vec<T>, Self::Error>;
}

/// Why [`read_from`] returned no scene.
enum Failure<E> {
    Format(FormatError),
    Source(E),
}

impl<E> From<FormatError> for Failure<E> {
    fn from(e: FormatError) -> Self {
        Failure::Format(e)
    }
}

/// Pieces of a section copied or read by one task: large enough that a task's overhead does not
/// count, small enough that a large section spreads over every thread.
const PIECE: usize = 1 << 20;

/// A file held in memory.
struct Memory<'a>(&'a [u8]);

impl Source for Memory<'_> {
    type Error = std::convert::Infallible;

    fn len(&self) -> u64 {
        self.0.len() as u64
    }

    fn bytes(&self, offset: u64, n: usize) -> Result<std::borrow::Cow<'_, [u8]>, Self::Error> {
        Ok(std::borrow::Cow::Borrowed(&self.0[offset as usize..offset as usize + n]))
    }

    /// Copied out of the buffer (whose alignment is the buffer's) by rayon's pool in pieces, into
    /// memory the allocator hands out zeroed (fresh pages for large sections), so that the copy's
    /// page faults spread over the threads as the copy does.
    fn items<T: Pod + Send>(&self, offset: u64, n: usize) -> Result<Vec<T>, Self::Error> {
        use rayon::prelude::*;
        let data = &self.0[offset as usize..offset as usize + n];
        let mut items: Vec<T> = bytemuck::zeroed_vec(n / size_of::<T>());
        let out: &mut [u8] = bytemuck::cast_slice_mut(&mut items);
        let data = &data[..out.len()];
        out.par_chunks_mut(PIECE).zip(data.par_chunks(PIECE)).for_each(|(to, from)| to.copy_from_slice(from));
        Ok(items)
    }
}

/// A regular file, open, and its length when it was opened.
#[cfg(unix)]
struct OpenFile {
    file: std::fs::File,
    len: u64,
}

#[cfg(unix)]
impl OpenFile {
    /// Fills `buf` from `offset`; a file that ends before (it got shorter since it was opened) is
    /// an error, not a section cut short.
    fn read_at(&self, buf: &mut [u8], offset: u64) -> std::io::Result<()> {
        use std::os::unix::fs::FileExt;
        self.file.read_exact_at(buf, offset).map_err(|e| match e.kind() {
            std::io::ErrorKind::UnexpectedEof => {
                std::io::Error::new(e.kind(), "the file got shorter while it was being read")
            }
            _ => e,
        })
    }
}

#[cfg(unix)]
impl Source for OpenFile {
    type Error = std::io::Error;

    fn len(&self) -> u64 {
        self.len
    }

    fn bytes(&self, offset: u64, n: usize) -> Result<std::borrow::Cow<'_, [u8]>, Self::Error> {
        let mut buf = vec![0; n];
        self.read_at(&mut buf, offset)?;
        Ok(std::borrow::Cow::Owned(buf))
    }

    /// Read by rayon's pool in pieces (`pread`, which takes no shared file position) straight into
    /// memory the allocator hands out zeroed, as [`Memory`] copies: reading the whole file into one
    /// buffer first took the dragon's 84 MB 23-35 ms more on the 2-core VM (`read bytes` against
    /// `read_file` of tracer-cpu's `examples/load_profile.rs`). Advising these arrays onto huge
    /// pages, as that buffer was, changed nothing measurable there.
    fn items<T: Pod + Send>(&self, offset: u64, n: usize) -> Result<Vec<T>, Self::Error> {
        use rayon::prelude::*;
        let mut items: Vec<T> = bytemuck::zeroed_vec(n / size_of::<T>());
        let out: &mut [u8] = bytemuck::cast_slice_mut(&mut items);
        out.par_chunks_mut(PIECE)
            .enumerate()
            .try_for_each(|(i, piece)| self.read_at(piece, offset + (i * PIECE) as u64))?;
        Ok(items)
    }
}

/// Reads and validates a scene file from `src`.
fn read_from<S: Source>(src: &S) -> Result<SceneFile, Failure<S::Error>> {
    let len = src.len();
    let head = src.bytes(0, len.min(HEADER_SIZE as u64) as usize).map_err(Failure::Source)?;
    // The magic first, so that a short file of another kind (a text file) is named as such
    // rather than as a truncated scene file.
    let magic = bytemuck::bytes_of(&MAGIC);
    if head[..head.len().min(magic.len())] != magic[..head.len().min(magic.len())] {
        return Err(FormatError::BadMagic.into());
    }
    if head.len() < HEADER_SIZE {
        return Err(FormatError::Truncated { what: "the header", needed: HEADER_SIZE as u64, len }.into());
    }
    let header: Header = bytemuck::pod_read_unaligned(&head[..HEADER_SIZE]);
    if header.magic != MAGIC {
        return Err(FormatError::BadMagic.into());
    }
    if header.version < VERSION {
        return Err(FormatError::OldVersion { found: header.version, supported: VERSION }.into());
    }
    if header.version != VERSION {
        return Err(FormatError::UnsupportedVersion { found: header.version, supported: VERSION }.into());
    }
    if header.header_size as usize != HEADER_SIZE {
        return Err(FormatError::BadHeader("its size field is wrong").into());
    }
    let table_len = header.section_count as u64 * SECTION_ENTRY_SIZE as u64;
    let table_end = HEADER_SIZE as u64 + table_len;
    if table_end > len {
        return Err(FormatError::Truncated { what: "the section table", needed: table_end, len }.into());
    }
    let table_bytes = src.bytes(HEADER_SIZE as u64, table_len as usize).map_err(Failure::Source)?;
    if crate::write::header_crc(&header, &table_bytes) != header.header_crc {
        return Err(FormatError::HeaderChecksum.into());
    }

    let mut found: Vec<(SectionKind, SectionEntry)> = Vec::new();
    for chunk in table_bytes.chunks_exact(SECTION_ENTRY_SIZE) {
        let e: SectionEntry = bytemuck::pod_read_unaligned(chunk);
        let kind = SectionKind::from_u32(e.kind).ok_or(FormatError::UnknownSection(e.kind))?;
        if found.iter().any(|(k, _)| *k == kind) {
            return Err(FormatError::DuplicateSection(kind).into());
        }
        if e.element_size != kind.element_size() {
            return Err(FormatError::ElementSize {
                section: kind,
                expected: kind.element_size(),
                found: e.element_size,
            }
            .into());
        }
        if !e.offset.is_multiple_of(ALIGN) {
            return Err(FormatError::SectionMisaligned { section: kind, offset: e.offset }.into());
        }
        let size = e.count.checked_mul(e.element_size as u64);
        let end = size.and_then(|s| e.offset.checked_add(s));
        match (size, end) {
            (Some(_), Some(end)) if end <= len && e.offset >= table_end => {}
            (Some(s), Some(end)) if end > len => {
                return Err(FormatError::SectionOutOfBounds {
                    section: kind,
                    offset: e.offset,
                    size: s,
                    file_len: len,
                }
                .into());
            }
            (Some(_), Some(_)) => {
                return Err(FormatError::BadHeader("a section overlaps the section table").into());
            }
            _ => {
                return Err(FormatError::SectionOutOfBounds {
                    section: kind,
                    offset: e.offset,
                    size: u64::MAX,
                    file_len: len,
                }
                .into());
            }
        }
        found.push((kind, e));
    }
    let range = |e: &SectionEntry| e.offset..e.offset + e.count * e.element_size as u64;
    for (i, (ka, a)) in found.iter().enumerate() {
        for (kb, b) in &found[i + 1..] {
            let (ra, rb) = (range(a), range(b));
            if !ra.is_empty() && !rb.is_empty() && ra.start < rb.end && rb.start < ra.end {
                return Err(FormatError::SectionOverlap { a: *ka, b: *kb }.into());
            }
        }
    }

    let sections = Sections { src, found: &found };

    if header.flags & !(FLAG_CHILD_PAIR | FLAG_ESCAPE | FLAG_WIDE) != 0 || header.flags == 0 {
        return Err(FormatError::NoLayout(header.flags).into());
    }
    if header.flags & (FLAG_CHILD_PAIR | FLAG_ESCAPE) == 0 {
        return Err(FormatError::WideAlone.into());
    }
    let names: Vec<u8> = sections.required(SectionKind::MaterialNames)?;
    let names = std::str::from_utf8(&names).map_err(|_| FormatError::BadNames)?;
    let strategy =
        Strategy::from_u32(header.strategy).ok_or(FormatError::BadHeader("its builder strategy is unknown"))?;

    let scene = SceneFile {
        build: BuildParams {
            strategy,
            bins: header.bins,
            traversal_cost: header.traversal_cost,
            intersection_cost: header.intersection_cost,
            max_leaf_size: header.max_leaf_size,
        },
        settings: SceneSettings {
            ambient: header.ambient,
            background: header.background,
            max_indirections: header.max_indirections,
        },
        origin: header.origin,
        scale_log2: header.scale_log2,
        vertices: sections.required(SectionKind::Vertices)?,
        triangles: sections.required(SectionKind::Triangles)?,
        normals: sections.required(SectionKind::Normals)?,
        normal_indices: sections.required(SectionKind::NormalIndices)?,
        materials: sections.required(SectionKind::Materials)?,
        material_names: names.split('\0').map(str::to_owned).collect(),
        input_index: sections.required(SectionKind::InputIndex)?,
        child_pair: sections.layout(&header, FLAG_CHILD_PAIR, SectionKind::NodesChildPair)?,
        escape: sections.layout(&header, FLAG_ESCAPE, SectionKind::NodesEscape)?,
        wide: sections.layout(&header, FLAG_WIDE, SectionKind::NodesWide)?,
        cameras: sections.required(SectionKind::Cameras)?,
        lights: sections.required(SectionKind::Lights)?,
    };
    validate_scene(&scene, Some(&header))?;
    Ok(scene)
}

/// The sections a file's table lists, read from its source.
struct Sections<'a, S> {
    src: &'a S,
    found: &'a [(SectionKind, SectionEntry)],
}

impl<S: Source> Sections<'_, S> {
    /// A section's items, once their bytes match the section's checksum.
    fn get<T: Pod + Send>(&self, kind: SectionKind) -> Result<Option<Vec<T>>, Failure<S::Error>> {
        let Some((_, e)) = self.found.iter().find(|(k, _)| *k == kind) else {
            return Ok(None);
        };
        // The element sizes the table was checked against are the sizes of the types read here.
        debug_assert_eq!(e.element_size as usize, size_of::<T>(), "{kind:?}");
        let n = (e.count * e.element_size as u64) as usize;
        let items: Vec<T> = self.src.items(e.offset, n).map_err(Failure::Source)?;
        if crate::write::section_crc(bytemuck::cast_slice(&items)) != e.crc {
            return Err(FormatError::Checksum { section: kind }.into());
        }
        Ok(Some(items))
    }

    fn required<T: Pod + Send>(&self, kind: SectionKind) -> Result<Vec<T>, Failure<S::Error>> {
        self.get(kind)?.ok_or(Failure::Format(FormatError::MissingSection(kind)))
    }

    /// A layout's nodes where the header's flags announce them, which must then be present, and
    /// nothing where they do not.
    fn layout<T: Pod + Send>(
        &self,
        header: &Header,
        flag: u32,
        kind: SectionKind,
    ) -> Result<Option<Vec<T>>, Failure<S::Error>> {
        match (header.flags & flag != 0, self.get(kind)?) {
            (true, Some(n)) => Ok(Some(n)),
            (true, None) => Err(FormatError::MissingSection(kind).into()),
            (false, Some(_)) => {
                Err(FormatError::BadHeader("a node section is present that the flags do not announce").into())
            }
            (false, None) => Ok(None),
        }
    }
}

/// Reads and validates a scene file from disk. A regular file is read section by section into the
/// scene's arrays; anything else that is not a device (a pipe) is read whole first.
pub fn read_file(path: &std::path::Path) -> Result<SceneFile, FileError> {
    let p = || path.display().to_string();
    let unreadable = |source| FileError::Read { path: p(), source };
    #[cfg(unix)]
    if std::fs::metadata(path).is_ok_and(|m| m.is_file()) {
        let file = std::fs::File::open(path).map_err(unreadable)?;
        let len = file.metadata().map_err(unreadable)?.len();
        return read_from(&OpenFile { file, len }).map_err(|e| match e {
            Failure::Format(source) => FileError::Invalid { path: p(), source },
            Failure::Source(source) => unreadable(source),
        });
    }
    let bytes = read_input(path).map_err(unreadable)?;
    read(&bytes).map_err(|source| FileError::Invalid { path: p(), source })
}

/// The bytes of an input file (a scene file, a mesh, a description, a file a scene refers to), as
/// `std::fs::read`, but a character or block device is refused: `/dev/zero` or a disk is no
/// scene and need not end, so reading it whole would take memory until the program is killed
/// instead of ending in an error. A pipe is read to its end, as a file is.
pub fn read_input(path: &std::path::Path) -> std::io::Result<Vec<u8>> {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        let kind = std::fs::metadata(path)?.file_type();
        if kind.is_char_device() || kind.is_block_device() {
            return Err(std::io::Error::new(std::io::ErrorKind::InvalidInput, "it is a device, not a file"));
        }
    }
    // As `std::fs::read`, with a large file's buffer on transparent huge pages: the dragon's
    // 84 MB took 45-60 ms to read into fresh 4 KiB pages on the 2-core VM, 26-30 ms into huge
    // ones (tracer-cpu's `examples/load_profile.rs`).
    use std::io::Read;
    let mut file = std::fs::File::open(path)?;
    let len = file.metadata().map_or(0, |m| m.len() as usize);
    let mut bytes = Vec::new();
    // One byte more, so that reading to the end finds it without growing the buffer; a pipe
    // or a file that grows meanwhile just grows it.
    bytes
        .try_reserve_exact(len.saturating_add(1))
        .map_err(|_| std::io::Error::from(std::io::ErrorKind::OutOfMemory))?;
    crate::memory::advise_huge_pages(bytes.spare_capacity_mut(), 32 << 20);
    file.read_to_end(&mut bytes)?;
    Ok(bytes)
}

/// The index of the first value that is not finite, if any.
fn first_non_finite(values: &[f32]) -> Option<usize> {
    crate::par::position_first(values, |v| !v.is_finite())
}

fn check_finite<T: Pod>(section: SectionKind, items: &[T]) -> Result<(), FormatError> {
    let floats: &[f32] = bytemuck::cast_slice(items);
    let per = std::mem::size_of::<T>() / 4;
    match first_non_finite(floats) {
        Some(i) => Err(FormatError::NonFinite { section, index: (i / per) as u64 }),
        None => Ok(()),
    }
}

/// Checks the contents of a scene; with a header, also that the header agrees with them.
pub(crate) fn validate_scene(s: &SceneFile, header: Option<&Header>) -> Result<(), FormatError> {
    let n = s.triangles.len() as u64;
    if n == 0 {
        return Err(FormatError::Empty);
    }
    if n > u32::MAX as u64 - 1 {
        return Err(FormatError::BadHeader("it counts more triangles than the format allows"));
    }
    let count = |section, expected: u64, found: usize| {
        if found as u64 != expected {
            Err(FormatError::CountMismatch { section, expected, found: found as u64 })
        } else {
            Ok(())
        }
    };
    if let Some(h) = header {
        count(SectionKind::Triangles, h.triangle_count as u64, s.triangles.len())?;
        count(SectionKind::Vertices, h.vertex_count as u64, s.vertices.len())?;
        count(SectionKind::Normals, h.normal_count as u64, s.normals.len())?;
        count(SectionKind::Materials, h.material_count as u64, s.materials.len())?;
        count(SectionKind::Cameras, h.camera_count as u64, s.cameras.len())?;
        count(SectionKind::Lights, h.light_count as u64, s.lights.len())?;
    }
    if !s.normal_indices.is_empty() || !s.normals.is_empty() {
        count(SectionKind::NormalIndices, n, s.normal_indices.len())?;
    }
    count(SectionKind::InputIndex, n, s.input_index.len())?;
    if s.material_names.len() != s.materials.len() || s.material_names.iter().any(|n| n.contains('\0')) {
        return Err(FormatError::BadNames);
    }

    if s.vertices.len() as u64 > u32::MAX as u64 || s.normals.len() as u64 > u32::MAX as u64 {
        return Err(FormatError::BadHeader("it counts more vertices or normals than the format allows"));
    }
    if !s.origin.iter().all(|v| v.is_finite()) {
        return Err(FormatError::BadHeader("its origin offset is not finite"));
    }
    if s.scale_log2.unsigned_abs() > crate::MAX_SCALE_LOG2.unsigned_abs() {
        return Err(FormatError::BadHeader("its scale exponent is out of range"));
    }
    check_finite(SectionKind::Vertices, &s.vertices)?;
    check_finite(SectionKind::Normals, &s.normals)?;
    check_finite(SectionKind::Lights, &s.lights)?;
    check_finite(SectionKind::Materials, &s.materials)?;
    for (i, c) in s.cameras.iter().enumerate() {
        // The padding too: FORMAT.md allows no non-finite float anywhere, and a NaN would make the
        // scene unequal to itself after a round trip.
        let f = [c.eye, c.at, c.up, [c.fov_deg, c._pad0, c._pad1]].concat();
        if first_non_finite(&f).is_some() {
            return Err(FormatError::NonFinite { section: SectionKind::Cameras, index: i as u64 });
        }
        if c.name().is_none() {
            return Err(FormatError::BadCameraName(i as u32));
        }
    }
    let settings = [s.settings.ambient, s.settings.background].concat();
    if first_non_finite(&settings).is_some()
        || !s.build.traversal_cost.is_finite()
        || !s.build.intersection_cost.is_finite()
    {
        return Err(FormatError::BadHeader("it holds a non-finite setting"));
    }

    let out_of_range = |section, index: usize, value: u32, limit: usize| {
        Err(FormatError::IndexOutOfRange { section, index: index as u64, value: value as u64, limit: limit as u64 })
    };
    // The first bad entry, found on every thread, gets the error the serial loop gave.
    let (nv, nm, nn) = (s.vertices.len(), s.materials.len(), s.normals.len());
    let bad = |t: &IndexedTriangle| t.vertices.iter().any(|&v| v as usize >= nv) || t.material as usize >= nm;
    if let Some(i) = crate::par::position_first(&s.triangles, bad) {
        let t = &s.triangles[i];
        if let Some(&v) = t.vertices.iter().find(|&&v| v as usize >= nv) {
            return out_of_range(SectionKind::Triangles, i, v, nv);
        }
        return out_of_range(SectionKind::Triangles, i, t.material, nm);
    }
    let bad = |idx: &[u32; 3]| *idx != FLAT && idx.iter().any(|&v| v as usize >= nn);
    if let Some(i) = crate::par::position_first(&s.normal_indices, bad) {
        let v = s.normal_indices[i].into_iter().find(|&v| v as usize >= nn).unwrap_or_default();
        return out_of_range(SectionKind::NormalIndices, i, v, nn);
    }
    for (i, mat) in s.materials.iter().enumerate() {
        let bad = |reason| Err(FormatError::BadMaterial { index: i as u32, reason });
        let colours = [mat.kd, mat.ks].concat();
        if colours.iter().any(|&v| v < 0.0) || mat.shininess < 0.0 {
            return bad("a colour or the shininess is negative");
        }
        if !(0.0..=1.0).contains(&mat.kr) || !(0.0..=1.0).contains(&mat.kt) {
            return bad("its reflection or transmission weight is outside 0 to 1");
        }
        if mat.kr > 0.0 && mat.kt > 0.0 {
            return bad("it is both reflective and refractive");
        }
        if mat.kt > 0.0 && mat.ior <= 0.0 {
            return bad("it is refractive with a non-positive index of refraction");
        }
    }
    if !is_permutation(&s.input_index) {
        let mut seen = vec![false; n as usize];
        for (i, &src) in s.input_index.iter().enumerate() {
            if src as u64 >= n {
                return Err(FormatError::IndexOutOfRange {
                    section: SectionKind::InputIndex,
                    index: i as u64,
                    value: src as u64,
                    limit: n,
                });
            }
            if std::mem::replace(&mut seen[src as usize], true) {
                return Err(FormatError::PermutationRepeats(src));
            }
        }
    }

    if s.child_pair.is_none() && s.escape.is_none() {
        return Err(if s.wide.is_some() { FormatError::WideAlone } else { FormatError::NoLayout(0) });
    }
    let trees = [s.child_pair.as_deref().map(Tree::child_pair), s.escape.as_deref().map(Tree::escape)];
    for t in trees.into_iter().flatten() {
        tree::check_shape(t, n as u32)?;
        if let Some(h) = header {
            if t.nodes.len() as u64 != h.node_count as u64 {
                let section = match t.layout {
                    LayoutKind::ChildPair => SectionKind::NodesChildPair,
                    LayoutKind::Escape => SectionKind::NodesEscape,
                };
                return Err(FormatError::CountMismatch {
                    section,
                    expected: h.node_count as u64,
                    found: t.nodes.len() as u64,
                });
            }
            // The tracers size their stacks from the header's depth: it must be the truth.
            let st = tree::stats(t, s.build.traversal_cost, s.build.intersection_cost);
            if st.max_depth != h.max_depth {
                return Err(FormatError::DepthMismatch { layout: t.layout, header: h.max_depth, actual: st.max_depth });
            }
            // Written from the same tree as an f32; the tolerance only allows for another
            // summation order, while a cost from a different tree is off by far more.
            let sah = st.sah_cost as f32;
            if (sah - h.sah_cost).abs() > 1e-5 * sah.abs().max(1.0) || !h.sah_cost.is_finite() {
                return Err(FormatError::SahCostMismatch { layout: t.layout, header: h.sah_cost, actual: sah });
            }
            if st.leaf_count != h.leaf_count {
                return Err(FormatError::LeafCountMismatch {
                    layout: t.layout,
                    header: h.leaf_count,
                    actual: st.leaf_count,
                });
            }
        }
    }
    if let (Some(cp), Some(esc)) = (&s.child_pair, &s.escape) {
        tree::check_same_tree(cp, esc)?;
    }
    let t = s.tree();
    check_leaf_boxes(t, s)?;
    if let Some(w) = &s.wide {
        crate::wide::validate(w, &s.triangles, &s.vertices)?;
    }
    if let Some(h) = header
        && (h.bounds_min != t.nodes[0].min || h.bounds_max != t.nodes[0].max)
    {
        return Err(FormatError::BadHeader("its scene bounds differ from the root node's box"));
    }
    Ok(())
}

/// Every leaf's box must hold its triangles' vertices, or a tracer would skip triangles it should
/// hit. The vertices are stored exactly, so no slack is allowed.
fn check_leaf_boxes(t: Tree<'_>, s: &SceneFile) -> Result<(), FormatError> {
    let outside = |n: &crate::Node| {
        n.is_leaf()
            && (n.index as usize..(n.index + n.count) as usize)
                .any(|tri| s.positions(tri).iter().any(|v| (0..3).any(|a| v[a] < n.min[a] || v[a] > n.max[a])))
    };
    match crate::par::position_first(t.nodes, outside) {
        Some(i) => Err(FormatError::TriangleOutsideLeaf { layout: t.layout, node: i as u32 }),
        None => Ok(()),
    }
}

/// Whether `index` holds every number below its length once, decided on every thread; where it
/// does not, the serial loop of [`validate_scene`] finds the first offending entry.
fn is_permutation(index: &[u32]) -> bool {
    use std::sync::atomic::{AtomicBool, Ordering::Relaxed};
    let seen: Vec<AtomicBool> = (0..index.len()).map(|_| AtomicBool::new(false)).collect();
    crate::par::all(index, |_, &i| seen.get(i as usize).is_some_and(|f| !f.swap(true, Relaxed)))
}

#[cfg(all(test, unix))]
mod tests {
    #[test]
    fn a_device_is_refused_before_it_is_read() {
        let e = super::read_input(std::path::Path::new("/dev/zero")).unwrap_err();
        assert_eq!(e.kind(), std::io::ErrorKind::InvalidInput);
        let e = super::read_file(std::path::Path::new("/dev/zero")).unwrap_err();
        assert_eq!(e.to_string(), "cannot read /dev/zero: it is a device, not a file");
    }

    /// A file that ends before the length it had when it was opened (another program cut it
    /// meanwhile) is an error of reading, not a damaged scene and not a panic.
    #[test]
    fn a_file_that_got_shorter_is_an_error_of_reading() {
        let path = std::env::temp_dir().join(format!("bvh-format-shorter-{}", std::process::id()));
        std::fs::write(&path, crate::layout::MAGIC).unwrap();
        let file = std::fs::File::open(&path).unwrap();
        let e = super::read_from(&super::OpenFile { file, len: 4096 }).err().unwrap();
        let _ = std::fs::remove_file(&path);
        match e {
            super::Failure::Source(e) => {
                assert_eq!(e.to_string(), "the file got shorter while it was being read");
            }
            super::Failure::Format(e) => panic!("reported as a damaged file: {e}"),
        }
    }
}
