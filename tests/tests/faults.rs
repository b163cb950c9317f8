//! Issue 9 item 5: a GPU fault during a frame (a lost device, memory that runs out, work past the
//! time limit) ends in a typed error of one sentence, never a hang or a panic; memory that only
//! the per-pixel buffers lack makes the frame render in smaller tiles, to the same image. The
//! faults are simulated by the device layer (`tracer_vk::Fault`) where lavapipe cannot make them;
//! tools/tests/faults.rs shows that `trace-vk render` then leaves no output file behind.

mod common;

use common::{compile, frame_settings, gpu};
use render_spec::Mode;
use tracer_vk::kernels::Method;
use tracer_vk::render::{Renderer, VkRenderError};
use tracer_vk::{Fault, VkError};

fn one_sentence(e: &VkRenderError) -> String {
    let text = e.to_string();
    assert!(!text.contains('\n') && !text.is_empty(), "{text:?}");
    text
}

#[test]
fn a_device_lost_during_a_frame_is_an_error_and_later_frames_fail_alike() {
    let gpu = gpu();
    let scene = compile("room.toml");
    let s = frame_settings(&scene, "medium", 32, 24, Mode::Whitted);
    let mut r = Renderer::new(&gpu, &scene, Method::Lst, (8, 8)).expect("the scene uploads");
    r.render(&s).expect("a frame before the fault renders");
    gpu.simulate(Some(Fault::DeviceLost));
    let e = r.render(&s).expect_err("the lost device fails the frame");
    assert!(matches!(e, VkRenderError::Vulkan(VkError::DeviceLost)), "{e:?}");
    assert!(one_sentence(&e).contains("device was lost"));
    gpu.simulate(None);
    let again = r.render(&s).expect_err("a lost device stays lost");
    assert!(matches!(again, VkRenderError::Vulkan(VkError::DeviceLost)), "{again:?}");
    let e = Renderer::new(&gpu, &scene, Method::Stackless, (8, 8)).err().expect("nothing uploads to a lost device");
    assert!(matches!(e, VkRenderError::Vulkan(VkError::DeviceLost)), "{e:?}");
}

#[test]
fn a_frame_past_the_time_limit_is_an_error() {
    let gpu = gpu();
    let scene = compile("room.toml");
    let s = frame_settings(&scene, "medium", 32, 24, Mode::Whitted);
    let mut r = Renderer::new(&gpu, &scene, Method::Stackless, (8, 8)).expect("the scene uploads");
    gpu.simulate(Some(Fault::Timeout));
    let e = r.render(&s).expect_err("the frame times out");
    assert!(matches!(e, VkRenderError::Vulkan(VkError::Timeout { .. })), "{e:?}");
    assert!(one_sentence(&e).contains("did not finish"));
    gpu.simulate(None);
    r.render(&s).expect("the device goes on after a timeout");
    assert!(gpu.validation_messages().is_empty(), "{:?}", gpu.validation_messages());
}

/// Out of device memory: where the scene fits but a frame's per-pixel buffers do not, the renderer
/// halves its tiles until they fit and makes the same image; a scene that does not fit is refused
/// with the buffer's name.
#[test]
fn out_of_memory_shrinks_tiles_or_names_the_buffer() {
    let gpu = gpu();
    let scene = compile("room.toml");
    // 256 x 192: the colour buffer alone takes 2.4 MB at 48 bytes a pixel.
    let s = frame_settings(&scene, "medium", 256, 192, Mode::Whitted);
    let mut whole = Renderer::new(&gpu, &scene, Method::Lst, (8, 8)).expect("the scene uploads");
    let expected = whole.render(&s).expect("renders without the fault").image;
    drop(whole);
    // The staging buffer takes 1 MiB; the scene's arrays are smaller.
    gpu.simulate(Some(Fault::OutOfMemory(1 << 20)));
    let mut r = Renderer::new(&gpu, &scene, Method::Lst, (8, 8)).expect("the scene fits");
    let tiled = r.render(&s).expect("the frame renders in smaller tiles").image;
    assert_eq!(tiled.rgb, expected.rgb, "the tiled image differs");
    assert_eq!(tiled.aov.as_ref().map(|a| &a.prim), expected.aov.as_ref().map(|a| &a.prim));
    gpu.simulate(Some(Fault::OutOfMemory(4096)));
    let e = Renderer::new(&gpu, &scene, Method::Lst, (8, 8)).err().expect("the scene does not fit");
    assert!(matches!(e, VkRenderError::Vulkan(VkError::OutOfDeviceMemory { .. })), "{e:?}");
    assert!(one_sentence(&e).contains("ran out of memory"), "{e}");
    gpu.simulate(None);
    assert!(gpu.validation_messages().is_empty(), "{:?}", gpu.validation_messages());
}
