//! Property tests of the builders and the file on random and degenerate triangle soups: the tree
//! is walked here independently of the validator, the file must survive a write/read round trip,
//! and two scalar traversals (one per layout) must find the same closest hit as brute force.

use bvh_build::Layouts;
use bvh_build::build::DEPTH_LIMIT;
use bvh_build::scene::Scene;
use bvh_format::Strategy as Builder;
use bvh_format::wide::{Slot, WIDTH};
use bvh_format::{BuildParams, Camera, Light, Material, Node, SceneFile, SceneSettings, Triangle, WideNode};
use glam::Vec3;
use proptest::prelude::*;
use proptest::test_runner::TestCaseError;

type Tri = [[f32; 3]; 3];

/// What a soup was generated as; decides how far the f32 intersection can be trusted.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Kind {
    Random,
    Identical,
    SameCentroid,
    ZeroArea,
    OnOneLine,
    Flat,
    Huge,
    Tiny,
    Large,
    Small,
    Single,
    Slivers,
}

fn point(r: f32) -> impl Strategy<Value = [f32; 3]> {
    [-r..r, -r..r, -r..r]
}

fn scaled(kind: Kind, s: f32) -> impl Strategy<Value = (Kind, Vec<Tri>)> {
    prop::collection::vec([point(1.0), point(1.0), point(1.0)], 1..300)
        .prop_map(move |v| (kind, v.into_iter().map(|t| t.map(|p| p.map(|c| c * s))).collect()))
}

/// Small dyadic numbers, so that sums and halves below are exact in f32.
fn dyadic(r: i32) -> impl Strategy<Value = f32> {
    (-r..=r).prop_map(|i| i as f32 / 16.0)
}

fn dyadic_point(r: i32) -> impl Strategy<Value = [f32; 3]> {
    [dyadic(r), dyadic(r), dyadic(r)]
}

fn add(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

fn mul(a: [f32; 3], s: f32) -> [f32; 3] {
    a.map(|c| c * s)
}

fn soup() -> impl Strategy<Value = (Kind, Vec<Tri>)> {
    let identical =
        ([point(10.0), point(10.0), point(10.0)], 1..300usize).prop_map(|(t, n)| (Kind::Identical, vec![t; n]));
    // Box centre of (c + a, c - a, c + s * a) is exactly c: every centroid the builder sees is equal.
    let same_centroid =
        (dyadic_point(64), prop::collection::vec((dyadic_point(48), [-2..=2i32, -2..=2i32, -2..=2i32]), 1..300))
            .prop_map(|(c, v)| {
                let tris = v
                    .into_iter()
                    .map(|(a, s)| {
                        let b = [a[0] * s[0] as f32 * 0.5, a[1] * s[1] as f32 * 0.5, a[2] * s[2] as f32 * 0.5];
                        [add(c, a), add(c, mul(a, -1.0)), add(c, b)]
                    })
                    .collect();
                (Kind::SameCentroid, tris)
            });
    let zero_area_tri = prop_oneof![
        (dyadic_point(160), dyadic_point(32)).prop_map(|(p, d)| [p, add(p, d), add(add(p, d), d)]),
        (dyadic_point(160), dyadic_point(160)).prop_map(|(p, q)| [p, p, q]),
        dyadic_point(160).prop_map(|p| [p, p, p]),
    ];
    let zero_area = prop::collection::vec(zero_area_tri, 1..300).prop_map(|v| (Kind::ZeroArea, v));
    // Every triangle on the x axis: the node boxes have zero area, so SAH costs divide by zero.
    let on_one_line = prop::collection::vec([dyadic(160), dyadic(160), dyadic(160)], 1..300)
        .prop_map(|v| (Kind::OnOneLine, v.into_iter().map(|x| x.map(|x| [x, 0.0, 0.0])).collect()));
    let flat = prop::collection::vec([point(10.0), point(10.0), point(10.0)], 1..300)
        .prop_map(|v| (Kind::Flat, v.into_iter().map(|t| t.map(|p| [p[0], p[1], 0.0])).collect()));
    let slivers = prop::collection::vec((point(10.0), point(10.0), point(1.0), 0.01f32..0.05), 1..300).prop_map(|v| {
        let tris = v
            .into_iter()
            .map(|(p, long, off, w)| {
                let far = add(p, long);
                let len = (long[0] * long[0] + long[1] * long[1] + long[2] * long[2]).sqrt();
                [p, far, add(add(p, mul(long, 0.5)), mul(off, w * len))]
            })
            .collect();
        (Kind::Slivers, tris)
    });
    let single = [point(10.0), point(10.0), point(10.0)].prop_map(|t| (Kind::Single, vec![t]));
    prop_oneof![
        3 => scaled(Kind::Random, 10.0),
        1 => identical,
        1 => same_centroid,
        1 => zero_area,
        1 => on_one_line,
        1 => flat,
        1 => scaled(Kind::Huge, 1e30),
        1 => scaled(Kind::Tiny, 1e-30),
        1 => scaled(Kind::Large, 1e10),
        1 => scaled(Kind::Small, 1e-10),
        1 => single,
        1 => slivers,
    ]
}

fn params() -> impl Strategy<Value = BuildParams> {
    (any::<bool>(), 2..=64u32, 1..=16u32, 0.0f32..4.0, 0.1f32..4.0).prop_map(|(sweep, bins, leaf, ct, ci)| {
        BuildParams {
            strategy: if sweep { Builder::Sweep } else { Builder::Binned },
            bins,
            traversal_cost: ct,
            intersection_cost: ci,
            max_leaf_size: leaf,
        }
    })
}

fn scene_of(tris: &[Tri], materials: usize) -> Scene {
    let materials: Vec<Material> = (0..materials)
        .map(|i| Material {
            kr: if i % 2 == 1 { 0.5 } else { 0.0 },
            kt: if i % 3 == 2 { 0.9 } else { 0.0 },
            ior: 1.5,
            ..Material::default()
        })
        .collect();
    Scene {
        positions: tris.iter().map(|t| t.map(Vec3::from)).collect(),
        normals: vec![[Vec3::Z; 3]; tris.len()],
        material_ids: (0..tris.len()).map(|i| (i % materials.len()) as u32).collect(),
        material_names: (0..materials.len()).map(|i| format!("material {i}")).collect(),
        materials,
        cameras: vec![Camera::new("main", [0.0, 0.0, 5.0], [0.0; 3], [0.0, 1.0, 0.0], 45.0)],
        lights: vec![Light::new([1.0, 2.0, 3.0], [1.0, 1.0, 1.0])],
        settings: SceneSettings::default(),
        warnings: Vec::new(),
        origin: glam::DVec3::ZERO,
    }
}

/// A position as the compiler stores it: in the file's unit (a power of two, see
/// `bvh_build::unit`), rounded as the compiler rounds it.
fn stored(file: &SceneFile, p: [f32; 3]) -> [f32; 3] {
    p.map(|x| (f64::from(x) / file.unit()) as f32)
}

fn stored_tris(file: &SceneFile, tris: &[Tri]) -> Vec<Tri> {
    tris.iter().map(|t| t.map(|p| stored(file, p))).collect()
}

fn contains(outer: &Node, inner: &Node) -> bool {
    (0..3).all(|k| outer.min[k] <= inner.min[k] && inner.max[k] <= outer.max[k])
}

fn contains_point(n: &Node, p: [f32; 3]) -> bool {
    (0..3).all(|k| n.min[k] <= p[k] && p[k] <= n.max[k])
}

/// Walks the child-pair tree from the root, checking shape, coverage and nesting; returns the
/// depth-first (left-first) order of the nodes with their depths.
fn walk_child_pair(nodes: &[Node], tris: &[Tri], input_index: &[u32]) -> Result<Vec<(usize, u32)>, TestCaseError> {
    let n = tris.len();
    let mut covered = vec![0u32; n];
    let mut visited = vec![false; nodes.len()];
    let mut order = Vec::new();
    let mut stack = vec![(0usize, 0u32)];
    while let Some((i, depth)) = stack.pop() {
        prop_assert!(i < nodes.len(), "node index {} out of range", i);
        prop_assert!(!visited[i], "node {} reached twice", i);
        visited[i] = true;
        order.push((i, depth));
        let node = &nodes[i];
        prop_assert!((0..3).all(|k| node.min[k] <= node.max[k]), "node {} inverted", i);
        if node.is_leaf() {
            let range = node.index as usize..node.index as usize + node.count as usize;
            prop_assert!(range.end <= n, "leaf {} range {:?} past {} triangles", i, range, n);
            for k in range {
                covered[k] += 1;
                for v in tris[input_index[k] as usize] {
                    prop_assert!(contains_point(node, v), "leaf {} does not contain a vertex of triangle {}", i, k);
                }
            }
        } else {
            let l = node.index as usize;
            prop_assert!(l > i && l + 1 < nodes.len(), "node {} has children at {}", i, l);
            for c in [l, l + 1] {
                prop_assert!(contains(node, &nodes[c]), "child {} sticks out of parent {}", c, i);
            }
            stack.push((l + 1, depth + 1));
            stack.push((l, depth + 1));
        }
    }
    prop_assert!(visited.iter().all(|&v| v), "some nodes cannot be reached from the root");
    prop_assert!(covered.iter().all(|&c| c == 1), "coverage is not exactly once: {:?}", covered);
    Ok(order)
}

/// The escape layout must be the child-pair tree in depth-first order, each inner node pointing
/// just past its own subtree.
fn check_escape_is_depth_first(cp: &[Node], esc: &[Node], order: &[(usize, u32)]) -> Result<(), TestCaseError> {
    prop_assert_eq!(esc.len(), cp.len());
    // Subtree sizes in child-pair indices, filled bottom-up by walking the pre-order backwards.
    let mut size = vec![1usize; cp.len()];
    for &(i, _) in order.iter().rev() {
        if !cp[i].is_leaf() {
            let l = cp[i].index as usize;
            size[i] = 1 + size[l] + size[l + 1];
        }
    }
    for (k, &(i, _)) in order.iter().enumerate() {
        let (a, b) = (&cp[i], &esc[k]);
        prop_assert_eq!((a.min, a.max, a.count), (b.min, b.max, b.count), "escape node {}", k);
        if a.is_leaf() {
            prop_assert_eq!(a.index, b.index, "escape leaf {}", k);
        } else {
            prop_assert_eq!(b.index as usize, k + size[i], "escape pointer of node {}", k);
        }
    }
    Ok(())
}

/// Walks the wide tree from the root, independently of the validator: every node reached once
/// and after its parent, at most eight children, every decoded child box holding every vertex
/// of every triangle beneath the child (recomputed here by walking down), every triangle in
/// exactly one leaf. Returns the wide tree's depth.
fn walk_wide(wide: &[WideNode], tris: &[Tri], input_index: &[u32]) -> Result<u32, TestCaseError> {
    let n = input_index.len();
    let mut seen_node = vec![false; wide.len()];
    let mut seen_tri = vec![0u32; n];
    // Triangles beneath each node, gathered bottom-up after the walk.
    let mut stack = vec![(0usize, 0u32)];
    let mut order = Vec::new();
    seen_node[0] = true;
    let mut depth = 0;
    while let Some((i, d)) = stack.pop() {
        order.push(i);
        depth = depth.max(d);
        let w = &wide[i];
        let mut children = 0;
        for s in 0..WIDTH {
            match w.slot(s) {
                Slot::Empty => {}
                Slot::Inner(c) => {
                    children += 1;
                    prop_assert!((c as usize) > i && (c as usize) < wide.len(), "node {} child {}", i, c);
                    prop_assert!(!std::mem::replace(&mut seen_node[c as usize], true), "node {} reached twice", c);
                    stack.push((c as usize, d + 1));
                }
                Slot::Leaf { first, count } => {
                    children += 1;
                    prop_assert!(count as usize <= 8 && first as usize + count as usize <= n);
                    for t in first..first + count {
                        seen_tri[t as usize] += 1;
                    }
                }
            }
        }
        prop_assert!((1..=8).contains(&children), "node {} has {} children", i, children);
    }
    prop_assert!(seen_node.iter().all(|&s| s), "a wide node is unreachable");
    prop_assert!(seen_tri.iter().all(|&c| c == 1), "a triangle is not in exactly one wide leaf");
    // Conservative boxes: each slot's box against the vertices of every triangle beneath it.
    let mut beneath: Vec<Vec<u32>> = vec![Vec::new(); wide.len()];
    for &i in order.iter().rev() {
        let w = &wide[i];
        let mut all = Vec::new();
        for s in 0..WIDTH {
            let ts: Vec<u32> = match w.slot(s) {
                Slot::Empty => continue,
                Slot::Inner(c) => beneath[c as usize].clone(),
                Slot::Leaf { first, count } => (first..first + count).collect(),
            };
            let (lo, hi) = w.child_box(s);
            for &t in &ts {
                for v in tris[input_index[t as usize] as usize] {
                    prop_assert!(
                        (0..3).all(|a| lo[a] <= v[a] && v[a] <= hi[a]),
                        "node {} slot {} misses a vertex",
                        i,
                        s
                    );
                }
            }
            all.extend(ts);
        }
        beneath[i] = all;
    }
    Ok(depth)
}

fn roundtrip(file: &SceneFile) -> Result<(), TestCaseError> {
    prop_assert_eq!(file.validate(), Ok(()));
    let bytes = bvh_format::write(file).map_err(|e| TestCaseError::fail(e.to_string()))?;
    let back = bvh_format::read(&bytes).map_err(|e| TestCaseError::fail(e.to_string()))?;
    prop_assert!(&back == file, "read(write(file)) differs from file");
    Ok(())
}

proptest! {
    // Failing cases are printed with their seed; integration tests have no lib.rs for proptest to
    // persist them beside.
    #![proptest_config(ProptestConfig { cases: 64, failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn trees_are_sound_and_files_round_trip((kind, tris) in soup(), p in params(), materials in 1..4usize) {
        let scene = scene_of(&tris, materials);
        let file = bvh_build::compile(&scene, &p, Layouts::default()).map_err(|e| TestCaseError::fail(e.to_string()))?;
        let tris = stored_tris(&file, &tris);
        let n = tris.len();
        let cp = file.child_pair.as_deref().expect("both layouts requested");
        let esc = file.escape.as_deref().expect("both layouts requested");

        // input_index is a permutation and the stored triangles are the input ones, reordered.
        let mut seen = vec![false; n];
        for (k, &src) in file.input_index.iter().enumerate() {
            prop_assert!(!std::mem::replace(&mut seen[src as usize], true), "input {} stored twice", src);
            let [a, b, c] = tris[src as usize];
            prop_assert_eq!(file.positions(k), [a, b, c]);
            prop_assert_eq!(file.triangles[k].material, (src as usize % materials) as u32);
        }

        let order = walk_child_pair(cp, &tris, &file.input_index)?;
        check_escape_is_depth_first(cp, esc, &order)?;
        for node in cp.iter().filter(|n| n.is_leaf()) {
            prop_assert!(node.count <= p.max_leaf_size, "leaf of {} > max {} ({:?})", node.count, p.max_leaf_size, kind);
        }
        let depth = order.iter().map(|&(_, d)| d).max().unwrap_or(0);
        let bound = DEPTH_LIMIT + (n as f64).log2().ceil() as u32 + 2;
        prop_assert!(depth <= bound, "depth {} > {} for {} triangles ({:?})", depth, bound, n, kind);
        prop_assert_eq!(file.stats().max_depth, depth);

        roundtrip(&file)?;
        let cp_only = SceneFile { escape: None, ..file.clone() };
        let esc_only = SceneFile { child_pair: None, ..file.clone() };
        roundtrip(&cp_only)?;
        roundtrip(&esc_only)?;
        // Compiling with one layout must give the same file as dropping the other.
        let one = Layouts { child_pair: true, escape: false, wide: false };
        prop_assert!(bvh_build::compile(&scene, &p, one).ok().as_ref() == Some(&cp_only));
        let one = Layouts { child_pair: false, escape: true, wide: false };
        prop_assert!(bvh_build::compile(&scene, &p, one).ok().as_ref() == Some(&esc_only));

        // The builder alone gives the same tree as the compiler stored.
        let built = bvh_build::build_tree(&scene.positions, &p).map_err(|e| TestCaseError::fail(e.to_string()))?;
        let nodes: Vec<Node> =
            built.nodes.iter().map(|n| Node { min: stored(&file, n.min), max: stored(&file, n.max), ..*n }).collect();
        prop_assert_eq!(&nodes[..], cp);
        prop_assert_eq!(&built.order, &file.input_index);
    }

    #[test]
    fn wide_layouts_are_sound_and_only_renumber_the_binary_leaves((_kind, tris) in soup(), p in params()) {
        let scene = scene_of(&tris, 2);
        let all = bvh_build::compile(&scene, &p, Layouts::ALL);
        let binary = bvh_build::compile(&scene, &p, Layouts::BINARY).map_err(|e| TestCaseError::fail(e.to_string()))?;
        // A tree with a leaf a wide leaf cannot hold is refused, in a sentence that says what to do.
        let largest = binary.child_pair.as_deref().unwrap().iter().map(|n| n.count).max().unwrap_or(0);
        if largest > bvh_format::wide::MAX_LEAF {
            let e = all.err().map(|e| e.to_string()).unwrap_or_default();
            prop_assert!(e.contains("--max-leaf-size 8 or less"), "{}", e);
            return Ok(());
        }
        let all = all.map_err(|e| TestCaseError::fail(e.to_string()))?;
        let tris = stored_tris(&all, &tris);
        let wide = all.wide.as_deref().expect("the wide layout was asked for");
        let depth = walk_wide(wide, &tris, &all.input_index)?;
        prop_assert_eq!(depth, bvh_format::wide::depth(wide));
        prop_assert!(depth <= all.stats().max_depth, "a wide tree is never deeper than its binary one");
        roundtrip(&all)?;
        roundtrip(&SceneFile { escape: None, ..all.clone() })?;
        // The binary tree is the one compiled without the wide layout, its leaves renumbered: same
        // boxes and counts, and each leaf holds the same input triangles in the same order.
        let (a, b) = (all.child_pair.as_deref().unwrap(), binary.child_pair.as_deref().unwrap());
        prop_assert_eq!(a.len(), b.len());
        for (x, y) in a.iter().zip(b) {
            prop_assert!(x.min == y.min && x.max == y.max && x.count == y.count);
            if x.is_leaf() {
                let r = |n: &Node| n.index as usize..(n.index + n.count) as usize;
                prop_assert_eq!(&all.input_index[r(x)], &binary.input_index[r(y)]);
            } else {
                prop_assert_eq!(x.index, y.index);
            }
        }
        prop_assert_eq!(SceneFile { escape: None, wide: None, ..all.clone() }.validate(), Ok(()));
        prop_assert_eq!(&all.escape, &Some(bvh_format::tree::escape_from_child_pair(a)));
    }

    #[test]
    fn traversals_find_the_brute_force_closest_hit(
        (kind, tris) in soup(),
        p in params(),
        rays in prop::collection::vec(
            (
                [-0.5f32..1.5, -0.5f32..1.5, -0.5f32..1.5],
                [-1.0f32..1.0, -1.0f32..1.0, -1.0f32..1.0],
                0..16u8,
                prop::option::of((any::<prop::sample::Index>(), [0.0f32..1.0, 0.0f32..1.0])),
            ),
            200,
        ),
    ) {
        let file = bvh_build::compile(&scene_of(&tris, 1), &p, Layouts::default())
            .map_err(|e| TestCaseError::fail(e.to_string()))?;
        let tris = stored_tris(&file, &tris);
        let cp = file.child_pair.as_deref().expect("both layouts requested");
        let esc = file.escape.as_deref().expect("both layouts requested");
        let max_depth = file.stats().max_depth as usize;

        // Origins are spread over the scene box padded on every side, so that flat and point-like
        // scenes still get rays from off their plane.
        let (lo, hi) = file.bounds();
        let ext = [hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]];
        let max_abs = lo.iter().chain(&hi).fold(0f32, |m, v| m.max(v.abs()));
        let fallback = if max_abs > 0.0 { max_abs } else { 1.0 };
        let big = ext.iter().fold(0f32, |m, &e| m.max(e));
        let pad = ext.map(|e| e.max(0.1 * big).max(if big > 0.0 { 0.0 } else { fallback }));
        // The f32 intersection's products of coordinates overflow or underflow at these scales, so
        // only its agreement with the traversals is checked there, not its accuracy.
        let f64_comparable = !matches!(kind, Kind::Huge | Kind::Tiny);

        let leaf_tris = file.leaf_triangles();
        for (frac, mut d, zero_mask, aim) in rays {
            let o: [f32; 3] = std::array::from_fn(|k| lo[k] + frac[k] * pad[k]);
            // Random directions rarely meet small triangles; aim some rays at a point of one.
            if let Some((idx, [a, b])) = aim {
                let [v0, v1, v2] = tris[idx.index(tris.len())];
                let (a, b) = if a + b > 1.0 { (1.0 - a, 1.0 - b) } else { (a, b) };
                let target: [f32; 3] = std::array::from_fn(|k| v0[k] + a * (v1[k] - v0[k]) + b * (v2[k] - v0[k]));
                d = sub(target, o);
            }
            // Axis-parallel directions: zero some components (mask values 8..15 keep them all).
            for (k, c) in d.iter_mut().enumerate() {
                if zero_mask < 8 && zero_mask & (1 << k) != 0 {
                    *c = 0.0;
                }
            }
            if d == [0.0; 3] {
                d = [0.0, 0.0, 1.0];
            }
            let ray = Ray::new(o, d, &pad);

            let brute = brute_force_f32(&ray, &leaf_tris);
            let by_cp = traverse_child_pair(&ray, cp, &leaf_tris, max_depth)?;
            let by_esc = traverse_escape(&ray, esc, &leaf_tris);
            for (name, hit) in [("child-pair", by_cp), ("escape", by_esc)] {
                prop_assert_eq!(hit.map(|h| h.0), brute.map(|h| h.0), "{} traversal vs brute force, {:?}, ray {:?}", name, kind, ray);
                if let Some((t, k)) = hit {
                    // Ties may name another triangle, but it must really be hit at that distance.
                    prop_assert_eq!(intersect_f32(&ray, &leaf_tris[k]), Some(t));
                }
            }

            if !f64_comparable {
                continue;
            }
            let exact = brute_force_f64(&ray, &tris);
            if let (Some((t32, k32)), Some((t64, i64))) = (brute, exact) {
                let tol = 1e-3 * (t64 + ray.scale);
                if (t32 as f64 - t64).abs() > tol {
                    // Rounding may decide whether a ray through an edge (or nearly in the plane of a
                    // triangle) hits it; any other disagreement is a wrong answer.
                    let explained = if (t32 as f64) < t64 {
                        let h = intersect_f64_raw(&ray, &tris[file.input_index[k32] as usize]);
                        h.is_some_and(|h| h.margin > -1e-2 && (h.t - t32 as f64).abs() <= tol)
                    } else {
                        let h = intersect_f64_raw(&ray, &tris[i64]).expect("f64 brute force hit it");
                        h.margin < 1e-2 || h.rel_det < 2e-3
                    };
                    prop_assert!(explained, "f32 hit {} at {} but f64 hit {} at {} ({:?}, ray {:?})",
                        file.input_index[k32], t32, i64, t64, kind, ray);
                }
            }
        }
    }
}

#[derive(Debug)]
struct Ray {
    o: [f32; 3],
    d: [f32; 3],
    inv: [f32; 3],
    /// The size of the (padded) scene in units of ray parameter: absolute tolerances scale with it.
    scale: f64,
    /// Widening of box intervals, absolute part.
    slack: f32,
}

impl Ray {
    fn new(o: [f32; 3], d: [f32; 3], extent: &[f32; 3]) -> Self {
        let len = (d.iter().map(|&c| c as f64 * c as f64).sum::<f64>()).sqrt();
        let diag = (extent.iter().map(|&c| c as f64 * c as f64).sum::<f64>()).sqrt();
        let scale = 3.0 * diag / len;
        Ray { o, d, inv: d.map(|c| 1.0 / c), scale, slack: (1e-3 * scale) as f32 }
    }
}

fn sub(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}
fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn norm(a: [f32; 3]) -> f32 {
    dot(a, a).sqrt()
}

/// Möller–Trumbore in f32 (a test of the trees, not of the tracers' triangle test). Near-degenerate
/// determinants (zero-area triangles, rays in a triangle's plane) count as misses, because there
/// the computed hit point can lie far outside the triangle and so outside every box holding it.
fn intersect_f32(ray: &Ray, tri: &Triangle) -> Option<f32> {
    let v0 = tri.p0;
    let (e1, e2) = (sub(tri.p1, v0), sub(tri.p2, v0));
    let p = cross(ray.d, e2);
    let det = dot(e1, p);
    let limit = 1e-3 * norm(e1) * norm(e2) * norm(ray.d);
    // Written so that NaN and infinity (overflowing products) count as misses.
    if !(det.abs() > limit && det.is_finite()) {
        return None;
    }
    let inv = 1.0 / det;
    let s = sub(ray.o, v0);
    let u = dot(s, p) * inv;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = cross(s, e1);
    let v = dot(ray.d, q) * inv;
    if !(v >= 0.0 && u + v <= 1.0) {
        return None;
    }
    let t = dot(e2, q) * inv;
    (t > 0.0 && t.is_finite()).then_some(t)
}

struct Hit64 {
    t: f64,
    /// Smallest barycentric coordinate: negative outside the triangle, near zero at an edge.
    margin: f64,
    /// |det| relative to the product of the edge and direction lengths: the sine-like measure of
    /// how far the ray is from the triangle's plane and the triangle from a line.
    rel_det: f64,
}

/// Möller–Trumbore in f64 without the inside test: the caller decides from `margin`.
fn intersect_f64_raw(ray: &Ray, tri: &Tri) -> Option<Hit64> {
    let f = |v: [f32; 3]| v.map(|c| c as f64);
    let (a, b, c) = (f(tri[0]), f(tri[1]), f(tri[2]));
    let (o, d) = (f(ray.o), f(ray.d));
    let sub = |a: [f64; 3], b: [f64; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    let cross =
        |a: [f64; 3], b: [f64; 3]| [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
    let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let (e1, e2) = (sub(b, a), sub(c, a));
    let p = cross(d, e2);
    let det = dot(e1, p);
    let size = dot(e1, e1).sqrt() * dot(e2, e2).sqrt() * dot(d, d).sqrt();
    if det.is_nan() || det.abs() <= 1e-12 * size {
        return None;
    }
    let s = sub(o, a);
    let u = dot(s, p) / det;
    let q = cross(s, e1);
    let v = dot(d, q) / det;
    let t = dot(e2, q) / det;
    Some(Hit64 { t, margin: u.min(v).min(1.0 - u - v), rel_det: det.abs() / size })
}

fn brute_force_f64(ray: &Ray, tris: &[Tri]) -> Option<(f64, usize)> {
    let mut best: Option<(f64, usize)> = None;
    for (i, tri) in tris.iter().enumerate() {
        if let Some(h) = intersect_f64_raw(ray, tri)
            && h.margin >= 0.0
            && h.t > 0.0
            && best.is_none_or(|(t, _)| h.t < t)
        {
            best = Some((h.t, i));
        }
    }
    best
}

/// Closest hit as (t, index in the file's triangle order).
fn brute_force_f32(ray: &Ray, tris: &[Triangle]) -> Option<(f32, usize)> {
    let mut best: Option<(f32, usize)> = None;
    for (k, tri) in tris.iter().enumerate() {
        if let Some(t) = intersect_f32(ray, tri)
            && best.is_none_or(|(b, _)| t < b)
        {
            best = Some((t, k));
        }
    }
    best
}

/// Entry distance of the ray into the node's box if the box overlaps `[0, t_max]`. Zero direction
/// components are decided by the origin alone, so 0 * inf never turns into a NaN that would make
/// a box be missed. The interval is widened by a small slack: the f32 triangle test accepts hit
/// points up to a rounding error outside the triangle, and so outside its box.
fn slab(ray: &Ray, n: &Node, t_max: f32) -> Option<f32> {
    let (mut near, mut far) = (f32::NEG_INFINITY, f32::INFINITY);
    for k in 0..3 {
        if !ray.inv[k].is_finite() {
            if ray.o[k] < n.min[k] || ray.o[k] > n.max[k] {
                return None;
            }
            continue;
        }
        let t0 = (n.min[k] - ray.o[k]) * ray.inv[k];
        let t1 = (n.max[k] - ray.o[k]) * ray.inv[k];
        near = near.max(t0.min(t1));
        far = far.min(t0.max(t1));
    }
    let widen = |t: f32| 1e-3 * t.abs() + ray.slack;
    let (near, far) = (near - widen(near), far + widen(far));
    (near <= far && far >= 0.0 && near <= t_max).then_some(near)
}

fn test_leaf(ray: &Ray, n: &Node, tris: &[Triangle], best: &mut Option<(f32, usize)>) {
    let first = n.index as usize;
    for (k, tri) in tris[first..first + n.count as usize].iter().enumerate() {
        if let Some(t) = intersect_f32(ray, tri)
            && best.is_none_or(|(b, _)| t < b)
        {
            *best = Some((t, first + k));
        }
    }
}

/// Ordered traversal of the child-pair layout: descend into the nearer child, push the farther one
/// with its entry distance, and skip popped nodes that lie behind the closest hit so far.
fn traverse_child_pair(
    ray: &Ray,
    nodes: &[Node],
    tris: &[Triangle],
    max_depth: usize,
) -> Result<Option<(f32, usize)>, TestCaseError> {
    let mut best: Option<(f32, usize)> = None;
    let t_max = |best: &Option<(f32, usize)>| best.map_or(f32::INFINITY, |b| b.0);
    let mut stack: Vec<(usize, f32)> = Vec::new();
    let mut next = slab(ray, &nodes[0], f32::INFINITY).map(|_| 0usize);
    while let Some(i) = next.take() {
        let n = &nodes[i];
        if n.is_leaf() {
            test_leaf(ray, n, tris, &mut best);
        } else {
            let (l, r) = (n.index as usize, n.index as usize + 1);
            let tm = t_max(&best);
            match (slab(ray, &nodes[l], tm), slab(ray, &nodes[r], tm)) {
                (Some(tl), Some(tr)) => {
                    let (near, far, tfar) = if tl <= tr { (l, r, tr) } else { (r, l, tl) };
                    stack.push((far, tfar));
                    // The header's depth sizes the tracers' stacks; this traversal must fit in it.
                    prop_assert!(stack.len() <= max_depth, "stack of {} for depth {}", stack.len(), max_depth);
                    next = Some(near);
                }
                (Some(_), None) => next = Some(l),
                (None, Some(_)) => next = Some(r),
                (None, None) => {}
            }
        }
        while next.is_none() {
            match stack.pop() {
                Some((j, t)) if t <= t_max(&best) => next = Some(j),
                Some(_) => {}
                None => return Ok(best),
            }
        }
    }
    Ok(best)
}

/// Stackless traversal of the escape layout: on a hit inner node or after a leaf go to the next
/// node, on a missed inner node jump to its escape index.
fn traverse_escape(ray: &Ray, nodes: &[Node], tris: &[Triangle]) -> Option<(f32, usize)> {
    let mut best: Option<(f32, usize)> = None;
    let mut i = 0usize;
    while i < nodes.len() {
        let n = &nodes[i];
        let hit = slab(ray, n, best.map_or(f32::INFINITY, |b| b.0)).is_some();
        if n.is_leaf() {
            if hit {
                test_leaf(ray, n, tris, &mut best);
            }
            i += 1;
        } else {
            i = if hit { i + 1 } else { n.index as usize };
        }
    }
    best
}

/// The collapse on the shipped scenes: every wide tree walked as above (every triangle in one
/// leaf, at most eight children, every decoded box around its triangles), no deeper than the
/// binary tree, and fuller than a binary tree's two children per node.
#[test]
fn shipped_scenes_collapse_into_sound_wide_trees() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes");
    for name in ["room.toml", "bunny.toml", "forest.toml", "car.toml"] {
        let scene = bvh_build::import::load(&dir.join(name), &Default::default()).expect("the scene imports");
        let file = bvh_build::compile(&scene, &BuildParams::default(), Layouts::ALL).expect("the scene compiles");
        let wide = file.wide.as_deref().expect("the wide layout");
        // The stored triangles by input index, as walk_wide looks them up.
        let mut tris = vec![[[0.0f32; 3]; 3]; file.triangles.len()];
        for (k, &src) in file.input_index.iter().enumerate() {
            tris[src as usize] = file.positions(k);
        }
        let depth = walk_wide(wide, &tris, &file.input_index).unwrap_or_else(|e| panic!("{name}: {e}"));
        let children: usize = wide.iter().map(|n| (0..WIDTH).filter(|&s| n.slot(s) != Slot::Empty).count()).sum();
        let per_node = children as f64 / wide.len() as f64;
        println!(
            "{name}: {} wide nodes, depth {depth} (binary {}), {per_node:.2} children per node",
            wide.len(),
            file.stats().max_depth
        );
        assert!(depth < file.stats().max_depth, "{name}: the wide tree is shallower");
        assert!(per_node > 3.0, "{name}: {per_node} children per node");
    }
}
