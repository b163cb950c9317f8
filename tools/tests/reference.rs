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
    let settings = Settings::of_scene(&room, CameraSpec::from(&room.cameras[0]), Mode::Whitted, (40, 30));
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

/// An EXR colour image of the reference holds its unquantised linear colour (the mean of the f64
/// samples rounded once to f32), not the 8-bit values over 255: an error measured against it must
/// not be the reference's own rounding.
#[test]
fn the_references_exr_holds_its_unquantised_colour() {
    let dir = scratch("reference-exr");
    let o = run(&dir, "bvhc", &["compile", scene("room.toml").to_str().unwrap(), "-o", "room.bvh", "--quiet"]);
    assert_ok(&o, "compiling the room");
    let o =
        run(&dir, "trace-cpu", &["render", "room.bvh", "--reference", "--res", "20x15", "--spp", "4", "-o", "r.exr"]);
    assert_ok(&o, "trace-cpu --reference -o r.exr");

    let room = bvh_format::read_file(&dir.join("room.bvh")).unwrap();
    let settings = Settings {
        accuracy: render_spec::Accuracy { spp: 4, ..Default::default() },
        ..Settings::of_scene(&room, CameraSpec::from(&room.cameras[0]), Mode::Whitted, (20, 15))
    };
    let exact = tracer_cpu::reference::render(&room, &settings).unwrap();
    let exr = exr::prelude::read_all_flat_layers_from_file(dir.join("r.exr")).unwrap();
    let channel = |name: &str| -> Vec<f32> {
        let c = exr.layer_data[0].channel_data.list.iter().find(|c| c.name == *name).expect("an RGB channel");
        c.sample_data.values_as_f32().collect()
    };
    let (r, g, b) = (channel("R"), channel("G"), channel("B"));
    let read: Vec<[f32; 3]> = (0..r.len()).map(|i| [r[i], g[i], b[i]]).collect();
    assert_eq!(read.len(), exact.linear.len());
    assert!(read.iter().zip(&exact.linear).all(|(a, b)| a.map(f32::to_bits) == b.map(f32::to_bits)));
    // Most values lie between 8-bit steps: what the 8-bit image would have written lies on them.
    let off_steps = read.iter().flatten().filter(|&&x| (x * 255.0 - (x * 255.0).round()).abs() > 1e-3).count();
    assert!(off_steps > read.len(), "only {off_steps} of {} values lie off the 8-bit steps", 3 * read.len());
}
