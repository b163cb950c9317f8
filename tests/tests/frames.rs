//! How the Vulkan tracer splits its work (issue 15, item 4): a frame rendered in many tiles is the
//! frame rendered in one, and bounce passes stop once every path has ended, so a huge
//! `--indirections` costs nothing beyond what the scene needs.

mod common;

use common::{compile, gpu};
use render_spec::{CameraSpec, MAX_INDIRECTIONS, Mode, Settings};
use tracer_vk::kernels::Method;
use tracer_vk::render::{Output, Renderer};

fn room_settings(scene: &bvh_format::SceneFile, width: u32, height: u32, max_indirections: u32) -> Settings {
    Settings {
        width,
        height,
        camera: CameraSpec::from(scene.camera("medium").expect("room has a medium camera")),
        mode: Mode::Whitted,
        lights: scene.lights.clone(),
        max_indirections,
        aovs: true,
        accuracy: render_spec::Accuracy::default(),
    }
}

fn assert_same_frame(what: &str, a: &Output, b: &Output) {
    let (a, b) = (&a.image, &b.image);
    assert_eq!(a.rays, b.rays, "{what}: ray counts");
    assert!(a.rgb == b.rgb, "{what}: colours differ");
    let (a, b) = (a.aov.as_ref().expect("AOVs were asked for"), b.aov.as_ref().expect("AOVs were asked for"));
    assert!(a.prim == b.prim && a.normal == b.normal, "{what}: triangles or normals differ");
    assert!(a.t.iter().zip(&b.t).all(|(x, y)| x.to_bits() == y.to_bits()), "{what}: distances differ");
    assert!(a.nodes == b.nodes && a.tris == b.tris, "{what}: traversal costs differ");
}

#[test]
fn a_frame_in_many_tiles_is_the_frame_in_one() {
    let gpu = gpu();
    let scene = compile("room.toml");
    // 100 x 75 with tiles of at most 3 workgroups: bands cut into columns, partial workgroups
    // at the right and bottom edges of the image, and a last tile narrower than the others.
    let s = room_settings(&scene, 100, 75, scene.settings.max_indirections);
    for method in [Method::Lst, Method::Stackless, Method::Sst, Method::SstSubgroup] {
        let mut r = Renderer::new(&gpu, &scene, method, (8, 8)).expect("the scene uploads");
        let whole = r.render(&s).expect("the GPU renders one tile");
        r.limit_tile_pixels(3 * 64);
        let mut steps = Vec::new();
        let tiled = r
            .render_with_progress(&s, true, &mut |p| steps.push((p.pixels_done, p.pixels)))
            .expect("the GPU renders in tiles");
        assert_same_frame(&format!("{} in tiles", method.name()), &whole, &tiled);
        assert!(steps.len() > 10, "{}: {} tiles, expected many", method.name(), steps.len());
        assert!(steps.windows(2).all(|w| w[0].0 < w[1].0), "progress must grow with every tile");
        assert_eq!(steps.last(), Some(&(100 * 75, 100 * 75)), "the last tile completes the frame");
    }
    let messages = gpu.validation_messages();
    assert!(messages.is_empty(), "the validation layer reported: {messages:#?}");
}

/// The largest secondary pass a frame ran, from the labels of its timed passes.
fn last_bounce(out: &Output) -> u32 {
    out.passes.iter().filter_map(|(label, _)| label.strip_prefix("trace secondary ")?.parse().ok()).max().unwrap_or(0)
}

#[test]
fn bounce_passes_stop_once_no_path_is_alive() {
    let gpu = gpu();
    let scene = compile("room.toml");
    assert!(scene.settings.max_indirections < 8, "room is meant to need few bounces");
    for method in [Method::Lst, Method::Sst] {
        let mut r = Renderer::new(&gpu, &scene, method, (8, 8)).expect("the scene uploads");
        let own = r.render(&room_settings(&scene, 64, 48, scene.settings.max_indirections)).unwrap();
        let most = r.render(&room_settings(&scene, 64, 48, MAX_INDIRECTIONS)).unwrap();
        // Room's glass and mirror lose light at every bounce: every path ends within a few
        // bounces, so allowing 1024 changes neither the image nor the work.
        assert_same_frame(&format!("{} at {MAX_INDIRECTIONS} indirections", method.name()), &own, &most);
        let passes = last_bounce(&most);
        assert!(passes <= 16, "{}: {passes} secondary passes ran after every path had ended", method.name());
        let err = r.render(&room_settings(&scene, 64, 48, MAX_INDIRECTIONS + 1)).unwrap_err().to_string();
        assert!(err.contains(&MAX_INDIRECTIONS.to_string()) && !err.contains('\n'), "{err}");
    }
}

/// Frames recorded back to back into one submission (`trace-vk bench --in-flight`, issue 10 item
/// 3) give the single frame's image, AOVs and ray counts, in every mode, tiled or not; with more
/// than one sample per pixel they are refused, since a copy would add its sample again.
#[test]
fn frames_recorded_into_one_submission_give_the_single_frames_image() {
    let gpu = gpu();
    let scene = compile("room.toml");
    let base = room_settings(&scene, 40, 30, scene.settings.max_indirections);
    let modes = [Mode::Cast, Mode::Whitted, Mode::Ao(render_spec::Ao { samples: 3, length: 0.1 }), Mode::Diffuse];
    for method in [Method::Lst, Method::Stackless] {
        for mode in modes {
            let s = Settings { mode, ..base.clone() };
            let mut r = Renderer::new(&gpu, &scene, method, (8, 8)).expect("the scene uploads");
            let one = r.render(&s).expect("one frame per submission");
            r.set_frames_per_submission(3);
            let three = r.render(&s).expect("three frames per submission");
            let what = format!("{} {} x3", method.name(), mode.name());
            assert_same_frame(&what, &one, &three);
            r.limit_tile_pixels(2 * 64);
            assert_same_frame(&format!("{what} in tiles"), &one, &r.render(&s).expect("tiled, three per submission"));
        }
    }
    let mut r = Renderer::new(&gpu, &scene, Method::Lst, (8, 8)).expect("the scene uploads");
    r.set_frames_per_submission(2);
    let spp4 = Settings { accuracy: render_spec::Accuracy { spp: 4, ..Default::default() }, ..base };
    let e = r.render(&spp4).expect_err("copies of a four-sample frame are refused").to_string();
    assert!(e.contains("one sample per pixel") && !e.contains('\n'), "{e}");
    let messages = gpu.validation_messages();
    assert!(messages.is_empty(), "the validation layer reported: {messages:#?}");
}
