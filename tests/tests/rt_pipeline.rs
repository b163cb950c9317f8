//! `--method rt-pipeline`, the vendor's traversal, against LST.
//!
//! Where the device has the ray-tracing extensions (the H100: run with `--ignored`, see
//! tools/scripts/h100-rtpipe.sh), its images equal LST's to the cross-backend tests' tolerance:
//! the same primary-hit triangles but for ties, 99.9% of pixels within 1/255, FLIP below 0.01, and
//! the same rays of every kind. Where it has not (lavapipe here and in CI), the method is refused
//! before anything is uploaded, in one sentence naming what is missing; the split stages are tested
//! there with LST's traversal standing in for the driver's.

mod common;

use common::{compile, gpu};
use render_spec::Mode;
use tracer_vk::VkError;
use tracer_vk::kernels::Method;
use tracer_vk::render::{Renderer, VkRenderError};
use tracer_vk::rt::Support;

/// The device's own answer (`trace-vk devices`) and the renderer's agree: refused with the missing
/// extensions named where the device lacks them, built where it has them.
#[test]
fn the_renderer_refuses_rt_pipeline_exactly_where_the_device_lacks_it() {
    let gpu = gpu();
    let scene = compile("room.toml");
    let info = gpu.info();
    // Mesa's lavapipe has no ray tracing (22.3 here): the refusal path must be the one taken.
    if info.driver.contains("llvmpipe") {
        assert!(matches!(&info.rt_pipeline, Support::Missing(m) if m.contains("VK_KHR_acceleration_structure")));
    }
    let made = Renderer::new(&gpu, &scene, Method::RtPipeline, (8, 8));
    match &info.rt_pipeline {
        Support::Missing(missing) => {
            let e = made.err().expect("a device without ray tracing refuses rt-pipeline");
            assert!(matches!(e, VkRenderError::Vulkan(VkError::Unsupported(_))), "{e:?}");
            let s = e.to_string();
            assert!(s.starts_with("--method rt-pipeline needs ") && s.contains(missing.as_str()), "{s}");
            assert!(s.contains(&info.name) && !s.contains('\n') && !s.ends_with('.'), "{s}");
            println!("refused on {}: {s}", info.name);
        }
        Support::Supported(_) => {
            let r = made.unwrap_or_else(|e| panic!("{} supports rt-pipeline but: {e}", info.name));
            let b = r.structure_build().expect("rt-pipeline built structures");
            assert!(b.bottom_bytes > 0 && b.top_bytes > 0, "{b:?}");
            println!("built on {}: {b:?}", info.name);
        }
    }
    let messages = gpu.validation_messages();
    assert!(messages.is_empty(), "the validation layer reported: {messages:#?}");
}

/// rt-pipeline's stages split around the trace, with LST in place of the driver's traversal, give
/// LST's images bit for bit: every colour, primary triangle, distance and normal and the same rays
/// of every kind, over whole frames and small tiles, cast, Whitted, AO and diffuse. This runs the ray and hit
/// records, the halves and their slots on any device (lavapipe here); only the driver's traversal
/// itself needs the H100.
#[test]
fn the_split_stages_with_lst_in_place_of_the_driver_give_lsts_images() {
    let gpu = gpu();
    for (scene_name, camera, w, h) in [("room.toml", "close-up", 96, 72), ("bunny.toml", "medium", 96, 72)] {
        let scene = compile(scene_name);
        for mode in [Mode::Cast, Mode::Whitted, Mode::Ao(render_spec::Ao::default()), Mode::Diffuse] {
            let settings = common::frame_settings(&scene, camera, w, h, mode);
            // Exact kernels (no contraction): two kernels holding the same LST code then round
            // alike on any device, also where the compiler would fuse differently in each.
            let mut lst = Renderer::new(&gpu, &scene, Method::Lst, (8, 8)).unwrap();
            lst.set_exact(true);
            let lst = lst.render(&settings).unwrap().image;
            let mut r = Renderer::rt_stand_in(&gpu, &scene, (8, 8)).unwrap();
            r.set_exact(true);
            assert!(r.structure_build().is_none(), "the stand-in builds no driver structures");
            for tile in [u64::MAX, 1000] {
                r.limit_tile_pixels(tile);
                let out = r.render(&settings).expect("the split stages render");
                let split = out.image;
                let what = format!("{scene_name} {camera} {mode:?} tiles of {tile} pixels");
                let (a, b) = (lst.aov.as_ref().unwrap(), split.aov.as_ref().unwrap());
                let differ = lst.rgb.iter().zip(&split.rgb).filter(|(p, q)| p != q).count();
                assert_eq!(differ, 0, "{what}: {differ} pixels differ from LST's");
                assert_eq!(a.prim, b.prim, "{what}: primary triangles");
                assert_eq!(a.t, b.t, "{what}: distances");
                assert_eq!(a.normal, b.normal, "{what}: normals");
                assert_eq!(split.rays, lst.rays, "{what}: rays of every kind");
                let traced = match mode {
                    Mode::Cast => true,
                    Mode::Whitted => lst.rays.shadow > 0,
                    Mode::Ao(_) => lst.rays.ao > 0,
                    Mode::Diffuse => lst.rays.diffuse > 0,
                };
                assert!(lst.rays.primary > 0 && traced, "{what}: {:?}", lst.rays);
                // The passes are timed in parts: the ray halves, the traversal, the hit halves.
                for part in [tracer_vk::render::RT_RAY_HALVES, tracer_vk::render::RT_TRAVERSAL] {
                    assert!(out.passes.iter().any(|(l, _)| l == part), "{what}: no {part} in {:?}", out.passes);
                }
            }
        }
    }
    let messages = gpu.validation_messages();
    assert!(messages.is_empty(), "the validation layer reported: {messages:#?}");
}

fn compare_with_lst(scene_name: &str, camera: &str, w: u32, h: u32) {
    let gpu = gpu();
    let scene = compile(scene_name);
    for mode in [Mode::Cast, Mode::Whitted] {
        let settings = common::frame_settings(&scene, camera, w, h, mode);
        let lst = Renderer::new(&gpu, &scene, Method::Lst, (8, 8)).unwrap().render(&settings).unwrap().image;
        let mut r = Renderer::new(&gpu, &scene, Method::RtPipeline, (8, 8))
            .unwrap_or_else(|e| panic!("this test needs a device with rt-pipeline (run it on the H100): {e}"));
        // Small tiles too, so that the records are reused from tile to tile.
        for tile in [u64::MAX, 777] {
            r.limit_tile_pixels(tile);
            let rt = r.render(&settings).expect("rt-pipeline renders").image;
            let what = format!("{scene_name} {camera} {mode:?} tiles of {tile} pixels");
            let d = common::diff(&lst, &rt);
            println!(
                "{what}: {:.4}% of pixels within 1/255 of LST, FLIP mean {:.5}, triangle ids: {} ties, {} other differences; rays rt {:?} lst {:?}",
                d.within_one * 100.0,
                d.flip_mean,
                d.prim_ties,
                d.prim_differs,
                rt.rays,
                lst.rays
            );
            common::assert_matches_cpu(&format!("rt-pipeline against LST, {what}"), &lst, &rt);
        }
    }
    let messages = gpu.validation_messages();
    assert!(messages.is_empty(), "the validation layer reported: {messages:#?}");
}

#[test]
#[ignore = "needs a device with VK_KHR_ray_tracing_pipeline (the H100: tools/scripts/h100-rtpipe.sh runs it)"]
fn rt_pipeline_images_equal_lsts_on_the_room() {
    compare_with_lst("room.toml", "medium", 160, 120);
    compare_with_lst("room.toml", "close-up", 120, 90);
}

#[test]
#[ignore = "needs a device with VK_KHR_ray_tracing_pipeline (the H100: tools/scripts/h100-rtpipe.sh runs it)"]
fn rt_pipeline_images_equal_lsts_on_the_bunny() {
    compare_with_lst("bunny.toml", "medium", 160, 120);
}
