//! Any bytes as a scene description (its meshes served from memory by
//! `bvh_build_fuzz::stub_meshes`): the importer returns a scene or a one-sentence error, never
//! panics, and a scene it accepts passes `bvh_build_fuzz::check` (finite, unit normals, compiles
//! into a valid file when small).
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    bvh_build_fuzz::check(&bvh_build_fuzz::import_description(data, &bvh_build_fuzz::options(data)));
});
