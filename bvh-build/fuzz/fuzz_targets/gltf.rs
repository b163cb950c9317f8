//! Any bytes as a glTF or GLB file (external buffers refused, `data:` URIs and the GLB binary
//! chunk read): the importer returns a scene or a one-sentence error, never panics, and a scene
//! it accepts passes `bvh_build_fuzz::check` (finite, unit normals, compiles).
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    bvh_build_fuzz::check(&bvh_build_fuzz::import_gltf(data, &bvh_build_fuzz::options(data)));
});
