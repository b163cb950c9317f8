//! Damaged and forged scene files: the reader must reject every one with the error that names the
//! damage, and never panic. Forged files have their checksums recomputed, so that the semantic
//! checks behind the checksums are reached.

use bvh_build::Layouts;
use bvh_build::scene::Scene;
use bvh_format::layout::{HEADER_SIZE, Header, SECTION_ENTRY_SIZE, SectionEntry};
use bvh_format::wide::{Slot, WIDTH};
use bvh_format::{
    BuildParams, Camera, FormatError, LayoutKind, Light, Material, Node, SceneFile, SceneSettings, SectionKind,
    WideNode,
};
use glam::Vec3;

// A fixed seed makes every damaged file reproducible.
use tests::Rng;

fn scene(triangles: usize, layouts: Layouts) -> SceneFile {
    let mut rng = Rng(0x5eed_1234_abcd_0001);
    let mut p = || Vec3::new(rng.unit(), rng.unit(), rng.unit()) * 20.0 - 10.0;
    let positions: Vec<[Vec3; 3]> = (0..triangles)
        .map(|_| {
            let a = p();
            [a, a + p() * 0.1, a + p() * 0.1]
        })
        .collect();
    let materials = vec![
        Material::default(),
        Material { kr: 0.6, ks: [0.5; 3], ..Material::default() },
        Material { kt: 0.9, ior: 1.5, ..Material::default() },
    ];
    let scene = Scene {
        normals: vec![[Vec3::Y; 3]; positions.len()],
        material_ids: (0..positions.len() as u32).map(|i| i % 3).collect(),
        material_names: vec!["white".into(), "mirror".into(), "glass".into()],
        materials,
        cameras: vec![
            Camera::new("front", [0.0, 0.0, 30.0], [0.0; 3], [0.0, 1.0, 0.0], 45.0),
            Camera::new("top", [0.0, 30.0, 0.0], [0.0; 3], [0.0, 0.0, -1.0], 60.0),
        ],
        lights: vec![Light::new([5.0, 5.0, 5.0], [1.0, 1.0, 1.0]), Light::new([-5.0, 8.0, 0.0], [0.3, 0.3, 0.5])],
        settings: SceneSettings { max_indirections: 3, ..SceneSettings::default() },
        positions,
        warnings: Vec::new(),
        origin: glam::DVec3::ZERO,
    };
    bvh_build::compile(&scene, &BuildParams { max_leaf_size: 4, ..BuildParams::default() }, layouts).unwrap()
}

fn bytes_of(file: &SceneFile) -> Vec<u8> {
    let bytes = bvh_format::write(file).unwrap();
    assert_eq!(bvh_format::read(&bytes).as_ref(), Ok(file), "the undamaged file must read back");
    bytes
}

/// Every layout, so that each damage below reaches the wide one too.
fn big_file() -> Vec<u8> {
    bytes_of(&scene(300, Layouts::ALL))
}

fn header(bytes: &[u8]) -> Header {
    bytemuck::pod_read_unaligned(&bytes[..HEADER_SIZE])
}

fn table(bytes: &[u8]) -> Vec<SectionEntry> {
    let count = header(bytes).section_count as usize;
    (0..count)
        .map(|i| {
            let at = HEADER_SIZE + i * SECTION_ENTRY_SIZE;
            bytemuck::pod_read_unaligned(&bytes[at..at + SECTION_ENTRY_SIZE])
        })
        .collect()
}

fn set_table(bytes: &mut [u8], table: &[SectionEntry]) {
    let start = HEADER_SIZE;
    bytes[start..start + table.len() * SECTION_ENTRY_SIZE].copy_from_slice(bytemuck::cast_slice(table));
}

fn set_header(bytes: &mut [u8], h: &Header) {
    bytes[..HEADER_SIZE].copy_from_slice(bytemuck::bytes_of(h));
}

fn edit_header(bytes: &mut [u8], f: impl FnOnce(Header) -> Header) {
    let h = f(header(bytes));
    set_header(bytes, &h);
}

fn range(e: &SectionEntry) -> std::ops::Range<usize> {
    e.offset as usize..(e.offset + e.count * e.element_size as u64) as usize
}

fn entry(bytes: &[u8], kind: SectionKind) -> SectionEntry {
    *table(bytes).iter().find(|e| e.kind == kind as u32).unwrap_or_else(|| panic!("no {kind} section"))
}

fn section_mut(bytes: &mut [u8], kind: SectionKind) -> &mut [u8] {
    let r = range(&entry(bytes, kind));
    &mut bytes[r]
}

/// Recomputes every section checksum, then the header checksum, as a writer would: after this
/// only the semantic checks can find what was changed.
fn reseal(bytes: &mut [u8]) {
    let mut t = table(bytes);
    for e in &mut t {
        // Entries that reach outside the file keep their checksum: the reader stops at them first.
        let end = e.count.checked_mul(e.element_size as u64).and_then(|s| s.checked_add(e.offset));
        if let Some(end) = end.filter(|&end| end <= bytes.len() as u64) {
            e.crc = crc32fast::hash(&bytes[e.offset as usize..end as usize]);
        }
    }
    set_table(bytes, &t);
    reseal_header(bytes);
}

/// Recomputes the header checksum only (over the header with the field zero, then the table).
fn reseal_header(bytes: &mut [u8]) {
    let mut h = header(bytes);
    h.header_crc = 0;
    let table_end = HEADER_SIZE + h.section_count as usize * SECTION_ENTRY_SIZE;
    let mut hasher = crc32fast::Hasher::new();
    hasher.update(bytemuck::bytes_of(&h));
    hasher.update(&bytes[HEADER_SIZE..table_end]);
    h.header_crc = hasher.finalize();
    set_header(bytes, &h);
}

/// Reads a file that must be rejected, and checks the message is one sentence.
fn rejected(bytes: &[u8]) -> FormatError {
    let read = bvh_format::read(bytes);
    // Compared as printed: an error may hold a NaN (a forged header's statistics).
    let (disk, memory) = (format!("{:?}", from_disk(bytes).err()), format!("{:?}", read.as_ref().err()));
    assert_eq!(disk, memory, "read from disk and from memory, the same file gives another result");
    match read {
        Ok(_) => panic!("a damaged file of {} bytes was accepted", bytes.len()),
        Err(e) => {
            let msg = e.to_string();
            assert!(!msg.is_empty() && !msg.contains('\n'), "message {msg:?} of {e:?} is not one line");
            e
        }
    }
}

/// What [`bvh_format::read_file`] makes of `bytes` written to a file: it reads a regular file
/// section by section, not through [`bvh_format::read`], and must agree with it on every file.
fn from_disk(bytes: &[u8]) -> Result<SceneFile, FormatError> {
    let dir = tests::Scratch::new("damaged");
    let path = dir.join("scene.bvh");
    std::fs::write(&path, bytes).unwrap();
    match bvh_format::read_file(&path) {
        Ok(scene) => Ok(scene),
        Err(bvh_format::FileError::Invalid { source, .. }) => Err(source),
        Err(e) => panic!("a file on disk could not be read: {e}"),
    }
}

fn nodes(bytes: &[u8], kind: SectionKind) -> Vec<Node> {
    bytemuck::pod_collect_to_vec(&bytes[range(&entry(bytes, kind))])
}

fn set_node(bytes: &mut [u8], kind: SectionKind, i: usize, n: Node) {
    section_mut(bytes, kind)[i * 32..i * 32 + 32].copy_from_slice(bytemuck::bytes_of(&n));
}

/// Bytes that some checksum covers: the header, the table and every section's data (the padding
/// between sections is not covered).
fn covered_bytes(bytes: &[u8]) -> Vec<std::ops::Range<usize>> {
    let head = 0..HEADER_SIZE + table(bytes).len() * SECTION_ENTRY_SIZE;
    std::iter::once(head).chain(table(bytes).iter().map(range).filter(|r| !r.is_empty())).collect()
}

fn data_end(bytes: &[u8]) -> usize {
    table(bytes).iter().map(|e| range(e).end).max().unwrap()
}

/// Every cut that loses a byte of the header, table or a section is reported as a truncation;
/// only the zero padding after the last section may go.
fn check_cut(bytes: &[u8], len: usize) {
    let cut = &bytes[..len];
    if len >= data_end(bytes) {
        assert!(bvh_format::read(cut).is_ok(), "cutting only padding at {len} must be harmless");
        assert!(from_disk(cut).is_ok(), "cutting only padding at {len} must be harmless on disk too");
        return;
    }
    let e = rejected(cut);
    assert!(matches!(e, FormatError::Truncated { .. } | FormatError::SectionOutOfBounds { .. }), "cut at {len}: {e:?}");
}

/// A file whose sections span many of the pieces `read_file` reads on separate threads reads
/// from disk as the scene that was written, as it does from memory.
#[test]
fn a_large_file_reads_the_same_from_disk() {
    let file = scene(150_000, Layouts::ALL);
    let bytes = bytes_of(&file);
    let largest = table(&bytes).iter().map(|e| range(e).len()).max().unwrap();
    assert!(largest > 2 << 20, "the largest section ({largest} bytes) should span several 1 MiB pieces");
    assert_eq!(from_disk(&bytes).as_ref(), Ok(&file));
}

#[test]
fn truncation_at_every_section_boundary() {
    let bytes = big_file();
    let table_end = HEADER_SIZE + table(&bytes).len() * SECTION_ENTRY_SIZE;
    let mut cuts = vec![0, 1, 8, HEADER_SIZE - 1, HEADER_SIZE, HEADER_SIZE + 1, table_end - 1, table_end];
    for e in table(&bytes) {
        let r = range(&e);
        cuts.extend([r.start, r.start + 1, r.end.saturating_sub(1), r.end, r.end + 1]);
    }
    cuts.retain(|&c| c < bytes.len());
    for len in cuts {
        check_cut(&bytes, len);
    }
    assert!(matches!(rejected(&bytes[..HEADER_SIZE - 1]), FormatError::Truncated { needed: 184, len: 183, .. }));
    assert!(matches!(rejected(&bytes[..table_end - 1]), FormatError::Truncated { .. }));
    let last = table(&bytes).into_iter().max_by_key(|e| e.offset).unwrap();
    let section = SectionKind::from_u32(last.kind).unwrap();
    let e = rejected(&bytes[..range(&last).end - 1]);
    assert!(matches!(e, FormatError::SectionOutOfBounds { section: s, .. } if s == section), "{e:?}");
}

#[test]
fn truncation_at_every_byte_of_small_files() {
    for layouts in [
        Layouts::default(),
        Layouts { child_pair: true, escape: false, wide: false },
        Layouts { child_pair: false, escape: true, wide: false },
        Layouts { child_pair: false, escape: true, wide: true },
        Layouts::ALL,
    ] {
        let bytes = bytes_of(&scene(3, layouts));
        for len in 0..bytes.len() {
            check_cut(&bytes, len);
        }
    }
}

#[test]
fn wrong_magic_and_version() {
    let bytes = big_file();
    for i in 0..8 {
        let mut b = bytes.clone();
        b[i] ^= 0x20;
        assert_eq!(rejected(&b), FormatError::BadMagic);
    }
    for version in [5u32, 7, u32::MAX] {
        let mut b = bytes.clone();
        b[8..12].copy_from_slice(&version.to_le_bytes());
        assert_eq!(rejected(&b), FormatError::UnsupportedVersion { found: version, supported: 4 });
        // A correct checksum does not make an unknown version readable.
        reseal_header(&mut b);
        assert_eq!(rejected(&b), FormatError::UnsupportedVersion { found: version, supported: 4 });
    }
    // A file of an older version (version 1 stored one vertex and two edges per triangle;
    // version 2 had no scale exponent, so a tiny or huge scene in it renders with offsets that
    // do not fit it; version 3 had no wide layout, so `--method cwbvh` could not trace it) is
    // named as such, with what to do about it.
    for version in [0u32, 1, 2, 3] {
        let mut b = bytes.clone();
        b[8..12].copy_from_slice(&version.to_le_bytes());
        let e = rejected(&b);
        assert_eq!(e, FormatError::OldVersion { found: version, supported: 4 });
        assert!(e.to_string().contains("recompile it from its source with `bvhc compile`"), "{e}");
    }
}

#[test]
fn every_bit_flip_of_header_and_table() {
    let bytes = big_file();
    let table_end = HEADER_SIZE + table(&bytes).len() * SECTION_ENTRY_SIZE;
    for byte in 0..table_end {
        for bit in 0..8 {
            let mut b = bytes.clone();
            b[byte] ^= 1 << bit;
            let e = rejected(&b);
            let ok = match byte {
                0..8 => e == FormatError::BadMagic,
                8..12 => matches!(e, FormatError::UnsupportedVersion { .. } | FormatError::OldVersion { .. }),
                12..16 => e == FormatError::BadHeader("its size field is wrong"),
                // A larger section count reaches past the file or reads section data as table.
                20..24 => matches!(e, FormatError::Truncated { .. } | FormatError::HeaderChecksum),
                _ => e == FormatError::HeaderChecksum,
            };
            assert!(ok, "bit {bit} of byte {byte}: {e:?}");
        }
    }
}

#[test]
fn flipped_bit_in_each_section_names_it() {
    let bytes = big_file();
    for e in table(&bytes) {
        let kind = SectionKind::from_u32(e.kind).unwrap();
        let r = range(&e);
        if r.is_empty() {
            continue;
        }
        for at in [r.start, r.start + r.len() / 2, r.end - 1] {
            let mut b = bytes.clone();
            b[at] ^= 0x10;
            assert_eq!(rejected(&b), FormatError::Checksum { section: kind }, "byte {at} of {kind}");
        }
    }
}

#[test]
fn random_bit_flips_in_checksummed_bytes() {
    let bytes = big_file();
    let covered: Vec<usize> = covered_bytes(&bytes).into_iter().flatten().collect();
    let mut rng = Rng(0xf11b_5eed);
    for _ in 0..3000 {
        let mut b = bytes.clone();
        // Distinct bytes, so that two flips never cancel.
        let mut at: Vec<usize> = (0..1 + rng.below(8)).map(|_| covered[rng.below(covered.len())]).collect();
        at.sort_unstable();
        at.dedup();
        for &i in &at {
            b[i] ^= 1 << rng.below(8);
        }
        rejected(&b);
    }
}

#[test]
fn random_garbage() {
    let mut rng = Rng(0x6a5b_a6e0);
    let good = big_file();
    for len in (0..600).chain((600..40_000).step_by(997)) {
        let mut garbage: Vec<u8> = (0..len).map(|_| rng.next_u64() as u8).collect();
        rejected(&garbage);
        // The same garbage behind a plausible start, so that the checks past the magic run too.
        if len >= 16 {
            garbage[..16].copy_from_slice(&good[..16]);
            rejected(&garbage);
        }
    }
}

#[test]
fn random_section_tables_with_valid_header_checksum() {
    // Plausible tables (known kinds, right element sizes, aligned offsets, small counts) behind a
    // correct header checksum reach the bounds, overlap and content checks. None may panic.
    let mut rng = Rng(0x7ab1_e5ee);
    let good = big_file();
    for _ in 0..2000 {
        let mut b = good.clone();
        let mut t = table(&b);
        for _ in 0..1 + rng.below(4) {
            let i = rng.below(t.len());
            match rng.below(5) {
                0 => t[i].count = rng.below(64) as u64,
                1 => t[i].offset = (rng.below(b.len() / 16 + 2) * 16) as u64,
                2 => t[i].kind = 1 + rng.below(11) as u32,
                3 => t[i].count = rng.next_u64() >> rng.below(64),
                _ => {
                    let j = rng.below(t.len());
                    t.swap(i, j);
                }
            }
            t[i].element_size = SectionKind::from_u32(t[i].kind).map_or(8, |k| k.element_size());
        }
        set_table(&mut b, &t);
        if rng.below(2) == 0 {
            reseal(&mut b);
        } else {
            reseal_header(&mut b);
        }
        // Some edits (swapping entries) leave a readable file; only panics are failures here.
        if let Err(e) = bvh_format::read(&b) {
            let msg = e.to_string();
            assert!(!msg.is_empty() && !msg.contains('\n'));
        }
    }
}

#[test]
fn inflated_section_counts() {
    let bytes = big_file();
    for i in 0..table(&bytes).len() {
        let kind = SectionKind::from_u32(table(&bytes)[i].kind).unwrap();
        for extra in [1u64, 16, 1000, 1 << 40, u64::MAX / 2] {
            let mut b = bytes.clone();
            let mut t = table(&b);
            t[i].count = t[i].count.saturating_add(extra);
            set_table(&mut b, &t);
            assert_eq!(rejected(&b), FormatError::HeaderChecksum);
            reseal_header(&mut b);
            let e = rejected(&b);
            let ok = match e {
                FormatError::SectionOutOfBounds { section, .. } => section == kind,
                FormatError::SectionOverlap { a, b } => a == kind || b == kind,
                // A section that grows only into the zero padding behind it keeps its bounds.
                FormatError::Checksum { section } => section == kind,
                _ => false,
            };
            assert!(ok, "{kind} count + {extra}: {e:?}");
            // With every checksum recomputed the contents themselves must give it away.
            reseal(&mut b);
            rejected(&b);
        }
    }
}

/// Edits a fresh copy of the big file, reseals it, and returns the error.
fn forge(edit: impl FnOnce(&mut Vec<u8>)) -> FormatError {
    let mut b = big_file();
    edit(&mut b);
    reseal(&mut b);
    rejected(&b)
}

fn first_inner(nodes: &[Node], from: usize) -> usize {
    (from..nodes.len()).find(|&i| !nodes[i].is_leaf()).unwrap()
}

#[test]
fn forged_escape_pointer_moving_backwards() {
    let e = forge(|b| {
        let esc = nodes(b, SectionKind::NodesEscape);
        let i = first_inner(&esc, 1);
        set_node(b, SectionKind::NodesEscape, i, Node { index: i as u32 - 1, ..esc[i] });
    });
    assert!(matches!(e, FormatError::EscapeBackwards { .. }), "{e:?}");
    let e = forge(|b| {
        let esc = nodes(b, SectionKind::NodesEscape);
        set_node(b, SectionKind::NodesEscape, 0, Node { index: 0, ..esc[0] });
    });
    assert_eq!(e, FormatError::EscapeBackwards { node: 0, escape: 0 });
}

#[test]
fn forged_leaf_range_out_of_range() {
    for kind in [SectionKind::NodesChildPair, SectionKind::NodesEscape] {
        let layout = if kind == SectionKind::NodesEscape { LayoutKind::Escape } else { LayoutKind::ChildPair };
        for past in [1u32, 1000, u32::MAX - 300] {
            let e = forge(|b| {
                let ns = nodes(b, kind);
                let i = ns.iter().position(|n| n.is_leaf()).unwrap();
                set_node(b, kind, i, Node { index: 300 - ns[i].count + past, ..ns[i] });
            });
            assert!(matches!(e, FormatError::TreeShape { layout: l, .. } if l == layout), "{e:?}");
        }
        // A count that overflows u32 when added to the index.
        let e = forge(|b| {
            let ns = nodes(b, kind);
            let i = ns.iter().position(|n| n.is_leaf()).unwrap();
            set_node(b, kind, i, Node { count: u32::MAX, ..ns[i] });
        });
        assert!(matches!(e, FormatError::TreeShape { .. }), "{e:?}");
    }
}

#[test]
fn forged_leaf_coverage() {
    for kind in [SectionKind::NodesChildPair, SectionKind::NodesEscape] {
        // A triangle dropped from a leaf.
        let mut dropped = 0;
        let e = forge(|b| {
            let ns = nodes(b, kind);
            let i = ns.iter().position(|n| n.count >= 2).unwrap();
            dropped = ns[i].index + ns[i].count - 1;
            set_node(b, kind, i, Node { count: ns[i].count - 1, ..ns[i] });
        });
        assert!(matches!(e, FormatError::LeafCoverage { triangle, times: 0, .. } if triangle == dropped), "{e:?}");
        // A triangle in two leaves (and another leaf's triangles in none).
        let mut twice = 0;
        let e = forge(|b| {
            let ns = nodes(b, kind);
            let leaves: Vec<usize> = (0..ns.len()).filter(|&i| ns[i].is_leaf()).collect();
            let (a, c) = (leaves[0], leaves[1]);
            twice = ns[a].index;
            set_node(b, kind, c, Node { index: ns[a].index, count: 1, ..ns[c] });
        });
        assert!(matches!(e, FormatError::LeafCoverage { triangle, times: 2, .. } if triangle == twice), "{e:?}");
    }
}

#[test]
fn forged_non_finite_numbers() {
    for (kind, index) in [(SectionKind::NodesChildPair, 0usize), (SectionKind::NodesEscape, 5)] {
        for v in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            let e = forge(|b| {
                let ns = nodes(b, kind);
                let mut n = ns[index];
                n.max[1] = v;
                set_node(b, kind, index, n);
            });
            assert_eq!(e, FormatError::NonFinite { section: kind, index: index as u64 });
        }
    }
    let e = forge(|b| {
        section_mut(b, SectionKind::Vertices)[12 * 7 + 4..12 * 7 + 8].copy_from_slice(&f32::NAN.to_le_bytes())
    });
    assert_eq!(e, FormatError::NonFinite { section: SectionKind::Vertices, index: 7 });
    // Every triangle has the normal +y: one normal, welded.
    let e = forge(|b| section_mut(b, SectionKind::Normals)[4..8].copy_from_slice(&f32::INFINITY.to_le_bytes()));
    assert_eq!(e, FormatError::NonFinite { section: SectionKind::Normals, index: 0 });
    let e = forge(|b| section_mut(b, SectionKind::Lights)[32 + 16..32 + 20].copy_from_slice(&f32::NAN.to_le_bytes()));
    assert_eq!(e, FormatError::NonFinite { section: SectionKind::Lights, index: 1 });
    let e = forge(|b| section_mut(b, SectionKind::Cameras)[64..68].copy_from_slice(&f32::NAN.to_le_bytes()));
    assert_eq!(e, FormatError::NonFinite { section: SectionKind::Cameras, index: 1 });
}

#[test]
fn forged_material_errors() {
    let e =
        forge(|b| section_mut(b, SectionKind::Triangles)[16 * 11 + 12..16 * 12].copy_from_slice(&3u32.to_le_bytes()));
    assert_eq!(e, FormatError::IndexOutOfRange { section: SectionKind::Triangles, index: 11, value: 3, limit: 3 });
    // Material 1 is the mirror (kr = 0.6); give it transmission as well.
    let e = forge(|b| section_mut(b, SectionKind::Materials)[48 + 32..48 + 36].copy_from_slice(&0.5f32.to_le_bytes()));
    assert_eq!(e, FormatError::BadMaterial { index: 1, reason: "it is both reflective and refractive" });
    let e = forge(|b| section_mut(b, SectionKind::Materials)[0..4].copy_from_slice(&(-1.0f32).to_le_bytes()));
    assert!(matches!(e, FormatError::BadMaterial { index: 0, .. }), "{e:?}");
    let e = forge(|b| section_mut(b, SectionKind::MaterialNames)[1] = 0xff);
    assert_eq!(e, FormatError::BadNames);
}

#[test]
fn forged_input_index_that_is_not_a_permutation() {
    let mut repeated = 0;
    let e = forge(|b| {
        let s = section_mut(b, SectionKind::InputIndex);
        let first: [u8; 4] = s[0..4].try_into().unwrap();
        repeated = u32::from_le_bytes(first);
        s[40..44].copy_from_slice(&first);
    });
    assert_eq!(e, FormatError::PermutationRepeats(repeated));
    let e = forge(|b| section_mut(b, SectionKind::InputIndex)[8..12].copy_from_slice(&300u32.to_le_bytes()));
    assert_eq!(e, FormatError::IndexOutOfRange { section: SectionKind::InputIndex, index: 2, value: 300, limit: 300 });
}

#[test]
fn forged_header_statistics() {
    let truth = header(&big_file());
    for depth in [0, truth.max_depth - 1, truth.max_depth + 1, u32::MAX] {
        let e = forge(|b| edit_header(b, |h| Header { max_depth: depth, ..h }));
        let expected =
            FormatError::DepthMismatch { layout: LayoutKind::ChildPair, header: depth, actual: truth.max_depth };
        assert_eq!(e, expected);
    }
    for sah in [truth.sah_cost * 1.01, truth.sah_cost * 0.99, 0.0, f32::NAN, f32::INFINITY] {
        let e = forge(|b| edit_header(b, |h| Header { sah_cost: sah, ..h }));
        assert!(matches!(e, FormatError::SahCostMismatch { layout: LayoutKind::ChildPair, .. }), "{sah}: {e:?}");
    }
    let e = forge(|b| edit_header(b, |h| Header { leaf_count: truth.leaf_count + 1, ..h }));
    assert!(matches!(e, FormatError::LeafCountMismatch { .. }), "{e:?}");
    let e = forge(|b| edit_header(b, |h| Header { triangle_count: 299, ..h }));
    assert!(matches!(e, FormatError::CountMismatch { section: SectionKind::Triangles, .. }), "{e:?}");
    let e = forge(|b| edit_header(b, |h| Header { node_count: truth.node_count + 2, ..h }));
    assert!(matches!(e, FormatError::CountMismatch { section: SectionKind::NodesChildPair, .. }), "{e:?}");
    let e = forge(|b| edit_header(b, |h| Header { flags: 8, ..h }));
    assert_eq!(e, FormatError::NoLayout(8));
    let e = forge(|b| edit_header(b, |h| Header { flags: 4, ..h }));
    assert_eq!(e, FormatError::WideAlone, "the wide layout without a binary one");
    let e = forge(|b| edit_header(b, |h| Header { flags: 5, ..h }));
    assert!(matches!(e, FormatError::BadHeader(_)), "an unannounced escape section: {e:?}");
    let e = forge(|b| edit_header(b, |h| Header { flags: 3, ..h }));
    assert!(matches!(e, FormatError::BadHeader(_)), "an unannounced wide section: {e:?}");
    let e = forge(|b| {
        let mut t = table(b);
        t.retain(|e| e.kind != SectionKind::NodesWide as u32);
        let count = t.len() as u32;
        set_table(b, &t);
        edit_header(b, |h| Header { section_count: count, ..h });
    });
    assert_eq!(e, FormatError::MissingSection(SectionKind::NodesWide), "an announced wide section that is missing");
    let e = forge(|b| edit_header(b, |h| Header { traversal_cost: f32::NAN, ..h }));
    assert!(matches!(e, FormatError::BadHeader(_)), "{e:?}");
}

#[test]
fn forged_layouts_that_describe_different_trees() {
    // Swapping the root's two children keeps a valid child-pair tree (every index is absolute),
    // but its depth-first order is no longer the escape layout's.
    let e = forge(|b| {
        let cp = nodes(b, SectionKind::NodesChildPair);
        let l = cp[0].index as usize;
        set_node(b, SectionKind::NodesChildPair, l, cp[l + 1]);
        set_node(b, SectionKind::NodesChildPair, l + 1, cp[l]);
    });
    assert_eq!(e, FormatError::LayoutsDiffer(1));
    // A leaf that names other triangles in one layout only.
    let e = forge(|b| {
        let cp = nodes(b, SectionKind::NodesChildPair);
        let leaves: Vec<usize> = (0..cp.len()).filter(|&i| cp[i].is_leaf() && cp[i].count == 1).collect();
        let (x, y) = (leaves[0], leaves[1]);
        set_node(b, SectionKind::NodesChildPair, x, Node { index: cp[y].index, ..cp[x] });
        set_node(b, SectionKind::NodesChildPair, y, Node { index: cp[x].index, ..cp[y] });
    });
    assert!(matches!(e, FormatError::LayoutsDiffer(_)), "{e:?}");
}

#[test]
fn forged_section_table_errors() {
    let e = forge(|b| {
        let mut t = table(b);
        t[1].kind = t[0].kind;
        set_table(b, &t);
    });
    assert!(
        matches!(e, FormatError::DuplicateSection(SectionKind::Vertices) | FormatError::ElementSize { .. }),
        "{e:?}"
    );
    let e = forge(|b| {
        let mut t = table(b);
        t[2].kind = 99;
        set_table(b, &t);
    });
    assert_eq!(e, FormatError::UnknownSection(99));
    let e = forge(|b| {
        let mut t = table(b);
        t[0].offset += 8;
        set_table(b, &t);
    });
    assert!(matches!(e, FormatError::SectionMisaligned { section: SectionKind::Vertices, .. }), "{e:?}");
    let e = forge(|b| {
        let mut t = table(b);
        t[0].element_size = 32;
        set_table(b, &t);
    });
    assert_eq!(e, FormatError::ElementSize { section: SectionKind::Vertices, expected: 12, found: 32 });
    let e = forge(|b| {
        let mut t = table(b);
        t[1].offset = t[0].offset;
        set_table(b, &t);
    });
    assert!(matches!(e, FormatError::SectionOverlap { .. }), "{e:?}");
    // Dropping the lights entry from the table.
    let e = forge(|b| {
        let h = header(b);
        set_header(b, &Header { section_count: h.section_count - 1, ..h });
    });
    assert_eq!(e, FormatError::MissingSection(SectionKind::Lights));
}

#[test]
fn forged_nan_in_camera_padding() {
    // FORMAT.md: every floating-point value in every section is finite, padding included; a NaN
    // accepted here would also make the scene unequal to itself after a round trip.
    for at in [12usize, 28, 44] {
        let e = forge(|b| {
            section_mut(b, SectionKind::Cameras)[64 + at..64 + at + 4].copy_from_slice(&f32::NAN.to_le_bytes())
        });
        assert_eq!(e, FormatError::NonFinite { section: SectionKind::Cameras, index: 1 }, "byte {at}");
    }
}

#[test]
fn forged_triangle_outside_its_leaf() {
    // Move the first vertex far away: its triangles' leaf boxes no longer hold them, and a tracer
    // would skip them.
    let e = forge(|b| {
        let t = &mut section_mut(b, SectionKind::Vertices)[0..4];
        let x = f32::from_le_bytes(t.try_into().unwrap()) + 1000.0;
        t.copy_from_slice(&x.to_le_bytes());
    });
    assert!(matches!(e, FormatError::TriangleOutsideLeaf { .. }), "{e:?}");
}

#[test]
fn forged_vertex_and_normal_indices() {
    let vertices = header(&big_file()).vertex_count;
    let e = forge(|b| {
        section_mut(b, SectionKind::Triangles)[16 * 5 + 4..16 * 5 + 8].copy_from_slice(&vertices.to_le_bytes())
    });
    let expected = FormatError::IndexOutOfRange {
        section: SectionKind::Triangles,
        index: 5,
        value: vertices as u64,
        limit: vertices as u64,
    };
    assert_eq!(e, expected);
    let e =
        forge(|b| section_mut(b, SectionKind::NormalIndices)[12 * 4 + 8..12 * 5].copy_from_slice(&1u32.to_le_bytes()));
    assert_eq!(e, FormatError::IndexOutOfRange { section: SectionKind::NormalIndices, index: 4, value: 1, limit: 1 });
    // A triangle half flat: the flat marker is all three indices or none.
    let e = forge(|b| section_mut(b, SectionKind::NormalIndices)[0..4].copy_from_slice(&u32::MAX.to_le_bytes()));
    assert!(matches!(e, FormatError::IndexOutOfRange { section: SectionKind::NormalIndices, index: 0, .. }), "{e:?}");
    // Normal indices for only some triangles.
    let e = forge(|b| {
        edit_header(b, |mut h| {
            h.normal_count = 0;
            h
        })
    });
    assert!(matches!(e, FormatError::CountMismatch { section: SectionKind::Normals, .. }), "{e:?}");
}

#[test]
fn forged_origin_and_header_bounds() {
    let e = forge(|b| {
        edit_header(b, |mut h| {
            h.origin[2] = f64::NAN;
            h
        })
    });
    assert!(matches!(e, FormatError::BadHeader(m) if m.contains("origin")), "{e:?}");
    let e = forge(|b| {
        edit_header(b, |mut h| {
            h.origin[0] = f64::INFINITY;
            h
        })
    });
    assert!(matches!(e, FormatError::BadHeader(m) if m.contains("origin")), "{e:?}");
    for scale_log2 in [bvh_format::MAX_SCALE_LOG2 + 1, -bvh_format::MAX_SCALE_LOG2 - 1, i32::MIN, i32::MAX] {
        let e = forge(|b| {
            edit_header(b, |mut h| {
                h.scale_log2 = scale_log2;
                h
            })
        });
        assert!(matches!(e, FormatError::BadHeader(m) if m.contains("scale exponent")), "{scale_log2}: {e:?}");
    }
    let e = forge(|b| {
        edit_header(b, |mut h| {
            h.bounds_max[1] += 1.0;
            h
        })
    });
    assert!(matches!(e, FormatError::BadHeader(_)), "{e:?}");
}

#[test]
fn names_with_nul_bytes_are_rejected_not_rewritten() {
    let mut s = scene(10, Layouts::default());
    s.material_names[0] = "a\0b".to_owned();
    assert_eq!(s.validate(), Err(FormatError::BadNames));
    assert!(bvh_format::write(&s).is_err());
}

#[test]
fn an_invalid_scene_is_not_written_and_the_message_blames_the_scene_not_a_file() {
    let dir = std::env::temp_dir().join(format!("bvh-invalid-write-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("out.bvh");
    let mut s = scene(40, Layouts::default());
    s.vertices[0][0] = f32::NAN;
    let e = bvh_format::write_file(&s, &path).unwrap_err();
    assert!(matches!(e, bvh_format::FileError::InvalidScene { .. }), "{e:?}");
    let msg = e.to_string();
    assert!(msg.starts_with("the scene was not written to") && !msg.contains("is not a valid scene file"), "{msg}");
    assert!(!path.exists(), "nothing was written");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `bvhc compile -o /dev/null` as root renamed its file over the device; through a link the
/// rename replaced the link. A link is followed to its file and a device is written in place (a
/// link to `/dev/null`, so that a regression replaces the test's link, not the device).
#[cfg(unix)]
#[test]
fn a_scene_written_through_a_link_replaces_the_file_it_names_and_a_device_is_written_in_place() {
    use std::os::unix::fs::FileTypeExt;
    let dir = std::env::temp_dir().join(format!("bvh-write-links-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let s = scene(40, Layouts::default());
    let (target, link, null) = (dir.join("target.bvh"), dir.join("link.bvh"), dir.join("null.bvh"));
    std::fs::write(&target, b"old").unwrap();
    std::os::unix::fs::symlink(&target, &link).unwrap();
    bvh_format::write_file(&s, &link).unwrap();
    assert!(std::fs::symlink_metadata(&link).unwrap().file_type().is_symlink(), "the link stays a link");
    assert_eq!(bvh_format::read_file(&target).unwrap(), s, "the file it names holds the scene");
    std::os::unix::fs::symlink("/dev/null", &null).unwrap();
    bvh_format::write_file(&s, &null).unwrap();
    assert!(std::fs::symlink_metadata(&null).unwrap().file_type().is_symlink());
    assert!(std::fs::metadata("/dev/null").unwrap().file_type().is_char_device(), "/dev/null is still the device");
    assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 3, "no temporary file left");
    std::fs::remove_dir_all(&dir).unwrap();
}

fn wide_nodes(bytes: &[u8]) -> Vec<WideNode> {
    bytemuck::pod_collect_to_vec(&bytes[range(&entry(bytes, SectionKind::NodesWide))])
}

fn set_wide(bytes: &mut [u8], i: usize, n: WideNode) {
    section_mut(bytes, SectionKind::NodesWide)[i * 80..i * 80 + 80].copy_from_slice(bytemuck::bytes_of(&n));
}

/// Forges wide node `i` (of the big file) with `f`, and returns the error.
fn forge_wide(pick: impl Fn(&[WideNode]) -> usize, f: impl FnOnce(&mut WideNode, &[WideNode])) -> FormatError {
    forge(|b| {
        let ws = wide_nodes(b);
        let i = pick(&ws);
        let mut n = ws[i];
        f(&mut n, &ws);
        set_wide(b, i, n);
    })
}

fn slot_where(n: &WideNode, f: impl Fn(Slot) -> bool) -> Option<usize> {
    (0..WIDTH).find(|&s| f(n.slot(s)))
}

fn with_leaf(ws: &[WideNode]) -> usize {
    ws.iter().position(|n| slot_where(n, |s| matches!(s, Slot::Leaf { .. })).is_some()).unwrap()
}

fn with_inner(ws: &[WideNode]) -> usize {
    ws.iter().position(|n| n.inner_mask != 0).unwrap()
}

fn is_leaf(s: Slot) -> bool {
    matches!(s, Slot::Leaf { .. })
}

#[test]
fn the_wide_layout_round_trips_and_is_checked_like_the_others() {
    let bytes = big_file();
    let file = bvh_format::read(&bytes).unwrap();
    let wide = file.wide.as_deref().expect("the big file has the wide layout");
    assert!(wide.len() > 3, "the big file's wide tree has several levels ({} nodes)", wide.len());
    let inner = |n: &WideNode| n.inner_mask.count_ones() as usize;
    assert_eq!(wide.iter().map(inner).sum::<usize>(), wide.len() - 1, "every node but the root is one slot's child");
    // Damage caught by the section checksum names the wide section.
    let r = range(&entry(&bytes, SectionKind::NodesWide));
    let mut b = bytes.clone();
    b[r.start + 40] ^= 1;
    assert_eq!(rejected(&b), FormatError::Checksum { section: SectionKind::NodesWide });
    let e = forge(|b| {
        let mut t = table(b);
        let w = t.iter_mut().find(|e| e.kind == SectionKind::NodesWide as u32).unwrap();
        w.element_size = 64;
        set_table(b, &t);
    });
    assert_eq!(e, FormatError::ElementSize { section: SectionKind::NodesWide, expected: 80, found: 64 });
}

#[test]
fn forged_wide_boxes_that_do_not_contain_their_triangles() {
    for axis in 0..3 {
        // A leaf's box pulled in by one step at its high corner (a leaf's vertex lies on it).
        let e = forge_wide(with_leaf, |n, _| {
            let s = slot_where(n, is_leaf).unwrap();
            let lo = n.lo[axis][s];
            n.hi[axis][s] = n.hi[axis][s].saturating_sub(1).max(lo);
            n.lo[axis][s] = n.lo[axis][s].min(n.hi[axis][s]);
        });
        // Either the box is now too small, or (where the grid step is below the vertex's spacing)
        // the same box: the forge must not pass silently either way.
        assert!(matches!(e, FormatError::WideBoxTooSmall { .. }), "axis {axis}: {e:?}");
        // An inner child's box collapsed to its low corner.
        let e = forge_wide(with_inner, |n, _| {
            let s = slot_where(n, |s| matches!(s, Slot::Inner(_))).unwrap();
            n.hi[axis][s] = n.lo[axis][s];
        });
        assert!(matches!(e, FormatError::WideBoxTooSmall { .. }), "axis {axis}: {e:?}");
        // A grid step halved: every box shrinks towards the origin.
        let e = forge_wide(|_| 0, |n, _| n.exponents[axis] -= 1);
        assert!(matches!(e, FormatError::WideBoxTooSmall { node: 0, .. }), "axis {axis}: {e:?}");
        // The grid moved up by a tenth of the scene.
        let e = forge_wide(|_| 0, |n, _| n.origin[axis] += 2.0);
        assert!(matches!(e, FormatError::WideBoxTooSmall { node: 0, .. }), "axis {axis}: {e:?}");
    }
}

#[test]
fn forged_wide_fields_out_of_range() {
    let shape = |e: FormatError, what: &str| {
        assert!(matches!(e, FormatError::WideShape { .. }), "{what}: {e:?}");
    };
    for v in [f32::NAN, f32::INFINITY] {
        shape(forge_wide(|_| 0, |n, _| n.origin[1] = v), "non-finite origin");
    }
    for e in [0u8, 255] {
        shape(forge_wide(|_| 0, |n, _| n.exponents[2] = e), "exponent out of range");
    }
    // A huge step decodes to infinity.
    shape(forge_wide(|_| 0, |n, _| n.exponents[0] = 254), "a box beyond f32");
    shape(
        forge_wide(with_leaf, |n, _| {
            let s = slot_where(n, is_leaf).unwrap();
            n.hi[0][s] = 0;
            n.lo[0][s] = 1;
        }),
        "inverted quantised box",
    );
    shape(
        forge_wide(
            |ws| ws.iter().position(|n| (0..WIDTH).any(|s| n.slot(s) == Slot::Empty)).unwrap(),
            |n, _| {
                let s = slot_where(n, |s| s == Slot::Empty).unwrap();
                n.hi[1][s] = 3;
            },
        ),
        "an empty slot with a box",
    );
    shape(
        forge_wide(with_inner, |n, _| {
            let s = slot_where(n, |s| matches!(s, Slot::Inner(_))).unwrap();
            n.meta[s] = 5;
        }),
        "an inner child with a meta byte",
    );
    // A leaf past the 32-triangle window: offset 31, 8 triangles (0xFF is the empty slot).
    shape(
        forge_wide(with_leaf, |n, _| {
            let s = slot_where(n, is_leaf).unwrap();
            n.meta[s] = (7 << 5) | 30;
        }),
        "a leaf past its window",
    );
    for base in [300, 1000, u32::MAX - 3] {
        shape(forge_wide(with_leaf, |n, _| n.triangle_base = base), "a leaf past the last triangle");
    }
}

#[test]
fn forged_wide_trees_that_are_not_trees() {
    let shape = |e: FormatError, what: &str| {
        assert!(matches!(e, FormatError::WideShape { .. }), "{what}: {e:?}");
    };
    // A cycle: a node's children start at itself, or at the root.
    shape(forge_wide(|ws| with_inner(&ws[1..]) + 1, |n, _| n.child_base = 0), "children before the parent");
    shape(forge_wide(with_inner, |n, ws| n.child_base = ws.len() as u32), "children past the last node");
    // Two nodes sharing a child: the root's first child's children moved onto the root's.
    shape(
        forge_wide(
            |ws| ws.iter().position(|n| n.inner_mask != 0 && n.child_base > 1).unwrap(),
            |n, ws| {
                let first = ws.iter().position(|m| m.inner_mask != 0).unwrap();
                n.child_base = ws[first].child_base;
            },
        ),
        "a shared child",
    );
    // An inner child turned into an empty slot: its subtree is unreachable.
    shape(
        forge_wide(with_inner, |n, _| {
            let s = (0..WIDTH).rev().find(|&s| n.inner_mask & (1 << s) != 0).unwrap();
            n.inner_mask &= !(1 << s);
            n.meta[s] = bvh_format::wide::EMPTY;
            (n.lo[0][s], n.lo[1][s], n.lo[2][s], n.hi[0][s], n.hi[1][s], n.hi[2][s]) = (0, 0, 0, 0, 0, 0);
        }),
        "an orphaned subtree",
    );
}

#[test]
fn forged_wide_leaf_coverage() {
    // A leaf shortened by one triangle: that triangle is in no leaf.
    let e = forge_wide(
        |ws| ws.iter().position(|n| (0..WIDTH).any(|s| matches!(n.slot(s), Slot::Leaf { count: 2.., .. }))).unwrap(),
        |n, _| {
            let s = slot_where(n, |s| matches!(s, Slot::Leaf { count: 2.., .. })).unwrap();
            n.meta[s] -= 1 << 5;
        },
    );
    assert!(matches!(e, FormatError::WideCoverage { times: 0, .. }), "{e:?}");
    // A leaf moved onto another's triangles.
    let e = forge_wide(
        |ws| {
            ws.iter()
                .position(|n| (0..WIDTH).filter(|&s| is_leaf(n.slot(s))).count() >= 2)
                .expect("a node with two leaves")
        },
        |n, _| {
            let leaves: Vec<usize> = (0..WIDTH).filter(|&s| is_leaf(n.slot(s))).collect();
            n.meta[leaves[1]] = n.meta[leaves[0]];
        },
    );
    assert!(matches!(e, FormatError::WideCoverage { times: 2, .. } | FormatError::WideBoxTooSmall { .. }), "{e:?}");
}
