//! Any bytes: `read` must return, never panic, and whatever it accepts must survive a write and a
//! second read unchanged.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(scene) = bvh_format::read(data) {
        let bytes = bvh_format::write(&scene).expect("a scene the reader accepted must be writable");
        let again = bvh_format::read(&bytes).expect("a written scene must read back");
        assert!(again == scene, "the scene changed in a write/read round trip");
    }
});
