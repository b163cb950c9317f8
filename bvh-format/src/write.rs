//! The writer: header, section table, then each section at a 16-byte aligned offset.

use crate::SceneFile;
use crate::error::{FileError, FormatError};
use crate::layout::{
    ALIGN, FLAG_CHILD_PAIR, FLAG_ESCAPE, FLAG_WIDE, HEADER_SIZE, Header, MAGIC, SECTION_ENTRY_SIZE, SectionEntry,
    SectionKind, VERSION,
};

fn align_up(v: u64) -> u64 {
    v.div_ceil(ALIGN) * ALIGN
}

/// Material names joined by NUL bytes (validation rejects names that contain one).
pub(crate) fn encode_names(names: &[String]) -> Vec<u8> {
    names.join("\0").into_bytes()
}

/// A validated scene laid out as a file: the header and section table, then each section's bytes
/// at its offset (zeros between them), `len` bytes in all.
struct Plan<'a> {
    head: Vec<u8>,
    sections: Vec<(u64, std::borrow::Cow<'a, [u8]>)>,
    len: u64,
}

/// Validates `scene` and lays it out; the writer never produces a file that the reader would reject.
fn plan(scene: &SceneFile) -> Result<Plan<'_>, FormatError> {
    scene.validate()?;
    let stats = scene.stats();
    let names = encode_names(&scene.material_names);
    let names_len = names.len() as u64;

    let mut sections: Vec<(SectionKind, u64, std::borrow::Cow<'_, [u8]>)> = vec![
        (SectionKind::Vertices, scene.vertices.len() as u64, bytemuck::cast_slice(&scene.vertices).into()),
        (SectionKind::Triangles, scene.triangles.len() as u64, bytemuck::cast_slice(&scene.triangles).into()),
        (SectionKind::Normals, scene.normals.len() as u64, bytemuck::cast_slice(&scene.normals).into()),
        (
            SectionKind::NormalIndices,
            scene.normal_indices.len() as u64,
            bytemuck::cast_slice(&scene.normal_indices).into(),
        ),
        (SectionKind::Materials, scene.materials.len() as u64, bytemuck::cast_slice(&scene.materials).into()),
        (SectionKind::MaterialNames, names_len, names.into()),
        (SectionKind::InputIndex, scene.input_index.len() as u64, bytemuck::cast_slice(&scene.input_index).into()),
    ];
    let mut flags = 0;
    if let Some(n) = &scene.child_pair {
        flags |= FLAG_CHILD_PAIR;
        sections.push((SectionKind::NodesChildPair, n.len() as u64, bytemuck::cast_slice(n).into()));
    }
    if let Some(n) = &scene.escape {
        flags |= FLAG_ESCAPE;
        sections.push((SectionKind::NodesEscape, n.len() as u64, bytemuck::cast_slice(n).into()));
    }
    if let Some(n) = &scene.wide {
        flags |= FLAG_WIDE;
        sections.push((SectionKind::NodesWide, n.len() as u64, bytemuck::cast_slice(n).into()));
    }
    sections.push((SectionKind::Cameras, scene.cameras.len() as u64, bytemuck::cast_slice(&scene.cameras).into()));
    sections.push((SectionKind::Lights, scene.lights.len() as u64, bytemuck::cast_slice(&scene.lights).into()));

    let table_end = (HEADER_SIZE + SECTION_ENTRY_SIZE * sections.len()) as u64;
    let mut offset = align_up(table_end);
    let mut table = Vec::with_capacity(sections.len());
    for (kind, count, bytes) in &sections {
        table.push(SectionEntry {
            kind: *kind as u32,
            element_size: kind.element_size(),
            count: *count,
            offset,
            crc: section_crc(bytes),
            _reserved: 0,
        });
        offset = align_up(offset + bytes.len() as u64);
    }

    let (bounds_min, bounds_max) = scene.bounds();
    let mut header = Header {
        magic: MAGIC,
        version: VERSION,
        header_size: HEADER_SIZE as u32,
        flags,
        section_count: sections.len() as u32,
        triangle_count: scene.triangles.len() as u32,
        vertex_count: scene.vertices.len() as u32,
        normal_count: scene.normals.len() as u32,
        node_count: stats.node_count,
        leaf_count: stats.leaf_count,
        max_depth: stats.max_depth,
        material_count: scene.materials.len() as u32,
        camera_count: scene.cameras.len() as u32,
        light_count: scene.lights.len() as u32,
        max_indirections: scene.settings.max_indirections,
        strategy: scene.build.strategy.to_u32(),
        bins: scene.build.bins,
        max_leaf_size: scene.build.max_leaf_size,
        traversal_cost: scene.build.traversal_cost,
        intersection_cost: scene.build.intersection_cost,
        sah_cost: stats.sah_cost as f32,
        bounds_min,
        bounds_max,
        ambient: scene.settings.ambient,
        background: scene.settings.background,
        origin: scene.origin,
        scale_log2: scene.scale_log2,
        ..Header::default()
    };
    header.header_crc = header_crc(&header, bytemuck::cast_slice(&table));

    let mut head = Vec::with_capacity(table_end as usize);
    head.extend_from_slice(bytemuck::bytes_of(&header));
    head.extend_from_slice(bytemuck::cast_slice(&table));
    let sections = sections.into_iter().zip(&table).map(|((_, _, bytes), entry)| (entry.offset, bytes)).collect();
    Ok(Plan { head, sections, len: offset })
}

/// Serialises a scene. The scene is validated first, so the writer never produces a file that the
/// reader would reject.
pub fn write(scene: &SceneFile) -> Result<Vec<u8>, FormatError> {
    let plan = plan(scene)?;
    let mut out = Vec::with_capacity(plan.len as usize);
    out.extend_from_slice(&plan.head);
    for (offset, bytes) in &plan.sections {
        out.resize(*offset as usize, 0);
        out.extend_from_slice(bytes);
    }
    out.resize(plan.len as usize, 0);
    Ok(out)
}

/// Why [`write_to`] wrote no complete file.
#[derive(Debug, thiserror::Error)]
pub enum WriteError {
    #[error("it would not be a valid scene file: {0}")]
    Invalid(#[from] FormatError),
    #[error("{0}")]
    Io(#[from] std::io::Error),
}

/// [`write`] straight into `out`, section by section, without assembling the file in memory
/// first (a copy of the whole file, 110 MB for a million triangles). Validates first, and writes
/// nothing if the scene is invalid. Returns the number of bytes written.
pub fn write_to(scene: &SceneFile, out: &mut impl std::io::Write) -> Result<u64, WriteError> {
    let plan = plan(scene)?;
    emit(&plan, out)?;
    Ok(plan.len)
}

/// Writes a laid-out file: the head, then each section after zeros up to its offset.
fn emit(plan: &Plan<'_>, out: &mut impl std::io::Write) -> std::io::Result<()> {
    const ZEROS: [u8; ALIGN as usize] = [0; ALIGN as usize];
    out.write_all(&plan.head)?;
    let mut at = plan.head.len() as u64;
    for (offset, bytes) in &plan.sections {
        out.write_all(&ZEROS[..(offset - at) as usize])?;
        out.write_all(bytes)?;
        at = offset + bytes.len() as u64;
    }
    out.write_all(&ZEROS[..(plan.len - at) as usize])
}

/// CRC-32 of a section, the same number as `crc32fast::hash`: pieces of 4 MiB are hashed on every
/// thread and their CRCs combined in order.
pub(crate) fn section_crc(bytes: &[u8]) -> u32 {
    use rayon::prelude::*;
    bytes
        .par_chunks(1 << 22)
        .map(|piece| {
            let mut h = crc32fast::Hasher::new();
            h.update(piece);
            h
        })
        .reduce_with(|mut a, b| {
            a.combine(&b);
            a
        })
        .map_or_else(|| crc32fast::hash(&[]), crc32fast::Hasher::finalize)
}

/// CRC-32 over the header with its checksum field zeroed, then the section table.
pub(crate) fn header_crc(header: &Header, table: &[u8]) -> u32 {
    let mut h = *header;
    h.header_crc = 0;
    let mut hasher = crc32fast::Hasher::new();
    hasher.update(bytemuck::bytes_of(&h));
    hasher.update(table);
    hasher.finalize()
}

/// Writes a scene to `path` through a temporary file in the same folder, renamed into place only
/// when complete, so an interrupted write never leaves a damaged file under the final name (a
/// link is followed to its file, a device such as `/dev/null` written in place:
/// [`crate::destination`]).
pub fn write_file(scene: &SceneFile, path: &std::path::Path) -> Result<(), FileError> {
    // Validated before the temporary file exists, so an invalid scene leaves nothing behind.
    let plan = plan(scene).map_err(|source| FileError::InvalidScene { path: path.display().to_string(), source })?;
    let werr = |source| FileError::Write { path: path.display().to_string(), source };
    crate::destination::write_replacing(path, |w| emit(&plan, w)).map_err(werr)
}
