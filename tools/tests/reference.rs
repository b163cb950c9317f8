//! `trace-cpu render --reference`: the exact reference from the command line, the image
//! `tracer_cpu::reference::render` makes for the same settings, with the AOVs and the heatmap.

mod common;

use common::{assert_ok, assert_one_sentence_error, run, scene, scratch};
use render_spec::{CameraSpec, Mode, Settings};

#[test]
fn the_reference_writes_the_librarys_image() {
    let dir = scratch("reference");
    let o = run(&dir, "bvhc", &["compile", scene("room.toml").to_str().unwrap(), "-o", "room.bvh", "--quiet"]);
    assert_ok(&o, "compiling the room");
    let args =
        ["render", "room.bvh", "--reference", "--res", "40x30", "-o", "r.png", "--aov", "a.exr", "--heatmap", "h.png"];
    let out = assert_ok(&run(&dir, "trace-cpu", &args), "trace-cpu --reference");
    assert!(out.contains("with the f64 reference"), "{out}");
    assert!(dir.join("a.exr").exists() && dir.join("h.png").exists(), "{out}");
    let png = image::open(dir.join("r.png")).unwrap().to_rgb8();

    let room = bvh_format::read_file(&dir.join("room.bvh")).unwrap();
    let settings = Settings {
        width: 40,
        height: 30,
        camera: CameraSpec::from(&room.cameras[0]),
        mode: Mode::Whitted,
        lights: room.lights.clone(),
        max_indirections: room.settings.max_indirections,
        aovs: false,
        accuracy: render_spec::Accuracy::default(),
    };
    let exact = tracer_cpu::reference::render(&room, &settings).unwrap();
    assert_eq!(png.pixels().map(|p| p.0).collect::<Vec<_>>(), exact.image.rgb);
    // Not a blank image: the room's walls, floor and objects differ.
    let distinct: std::collections::HashSet<[u8; 3]> = exact.image.rgb.iter().copied().collect();
    assert!(distinct.len() > 50, "{} colours", distinct.len());

    let o = run(&dir, "trace-cpu", &["render", "room.bvh", "--reference", "--method", "packet", "-o", "x.png"]);
    assert_one_sentence_error(&o, "--method");
    for (option, value) in [("--intersect", "mt"), ("--offset", "1e-3"), ("--cutoff", "0.1")] {
        let o = run(&dir, "trace-cpu", &["render", "room.bvh", "--reference", option, value, "-o", "x.png"]);
        assert_one_sentence_error(&o, option);
    }
    // Samples per pixel count: four primary rays per pixel.
    let o = run(&dir, "trace-cpu", &["render", "room.bvh", "--reference", "--spp", "4", "--res", "8x6", "-o", "s.png"]);
    let out = assert_ok(&o, "--reference --spp 4");
    assert!(out.contains("192 primary"), "{out}");
}
