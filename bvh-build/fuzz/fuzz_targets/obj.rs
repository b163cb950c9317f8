//! Any bytes as an OBJ file (and, after a NUL byte, its material library): the importer returns
//! a scene or a one-sentence error, never panics, and a scene it accepts passes
//! `bvh_build_fuzz::check` (finite, unit normals, compiles).
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    bvh_build_fuzz::check(&bvh_build_fuzz::import_obj(data, &bvh_build_fuzz::options(data)));
});
