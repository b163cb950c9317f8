//! The same input gives the same file, byte for byte, on any number of threads: the parallel
//! parts of import, build, welding and writing must not let scheduling into the result.

use bvh_build::import::{ImportOptions, load};
use bvh_format::{BuildParams, Strategy};
use std::path::Path;

/// Imports, compiles and serialises `scene` on a rayon pool of `threads`.
fn file_bytes(scene: &Path, params: &BuildParams, threads: usize) -> Vec<u8> {
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().expect("a thread pool");
    pool.install(|| {
        let s = load(scene, &ImportOptions { smooth_normals: true }).expect("the scene imports");
        let file = bvh_build::compile_for_writing(&s, params, Default::default(), None).expect("the scene compiles");
        let mut bytes = Vec::new();
        bvh_format::write_to(&file, &mut bytes).expect("the file writes");
        assert_eq!(bytes, bvh_format::write(&file).expect("the file writes"), "write_to and write agree");
        bytes
    })
}

#[test]
fn the_compiled_file_does_not_depend_on_the_number_of_threads() {
    // The bunny on its floor: 69,453 triangles, more than one parallel split's worth (the root
    // and its children are binned and partitioned by every thread), smooth normals to weld, and
    // two large floor triangles for the large-triangle candidate.
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/bunny.toml");
    for params in [BuildParams::default(), BuildParams { strategy: Strategy::Binned, bins: 4, ..Default::default() }] {
        let one = file_bytes(&scene, &params, 1);
        let read = bvh_format::read(&one).expect("the file reads back");
        assert!(read.triangles.len() > 1 << 16, "large enough for the parallel splits");
        assert!(!read.normals.is_empty(), "smooth normals were welded");
        for threads in [2, 3, 8] {
            let many = file_bytes(&scene, &params, threads);
            assert!(one == many, "{} bins: {threads} threads wrote a different file", params.bins);
        }
    }
}
