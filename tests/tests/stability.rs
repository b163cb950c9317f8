//! The CI slice of the stability sweep (issue 9, `stress --quick`): a cheap point or two of every
//! axis, every method (CPU ordered, stackless, packet, bvh8, bvh8-packet; Vulkan LST, stackless,
//! SST, SST-subgroup on lavapipe, and rt-pipeline, which lavapipe lacks: refused at every point
//! with the reason), asserting that no pixel fails in silence: no wrong closest hit against the f64
//! reference, no leak, no NaN or infinite value, no wrong pixel where an image is compared, no
//! crash and no hang. A refusal (a typed error naming the limit) is allowed and printed. The scale
//! axis's end points (10^-8 and 10^8, which failed before the compiler stored scenes in a unit of
//! their own, `bvh_build::unit`) are among the asserted points. The slice includes the size axis
//! (10^3 and 10^5 triangles; frames of 500x375, 16384x2 and 2x16384) and, where the triangle
//! test can matter, every method again with Möller-Trumbore, whose edge disagreements are its
//! documented trade and are printed, not asserted (`Row::failed`).
//! The sweep's full range and its charts are in docs/stability.md.

mod common;

use std::sync::Arc;
use std::time::Duration;
use tools::stress::cases::{self, AXES, Extent};
use tools::stress::{METHODS, report};

#[test]
fn no_method_fails_in_silence_on_any_axis() {
    let gpu = Arc::new(common::gpu());
    let all = cases::all(Extent::Quick, cases::DEFAULT_MAX_TRIANGLES, &|_| true);
    // The sweep's demonstration of what the compiler's rebasing prevents is not a method.
    let checked: Vec<_> = all.into_iter().filter(|c| c.axis != AXES[1]).collect();
    let rows = tools::stress::sweep(checked, &METHODS, Some(gpu.clone()), Duration::from_secs(300), &|row| {
        println!("{} {} {}: {}", row.axis, row.label, row.line(), report::cell(&row.tally));
        if let Some(r) = &row.tally.refusal {
            println!("    refused: {r}");
        }
    });
    let silent: Vec<String> = rows
        .iter()
        .filter(|r| r.failed())
        .map(|r| format!("{} {} {}: {}", r.axis, r.label, r.line(), report::cell(&r.tally)))
        .collect();
    assert!(silent.is_empty(), "failed in silence:\n{}", silent.join("\n"));
    // The scale axis's end points ran on every method the device supports and were rendered,
    // not refused; a method it lacks is refused with the reason, never left out.
    for label in ["10^-8", "10^8"] {
        for m in METHODS {
            let r = rows.iter().find(|r| r.axis == AXES[2] && r.label == label && r.method == m);
            match tools::stress::unsupported(m, Some(&gpu)) {
                None => assert!(
                    r.is_some_and(|r| r.tally.refusal.is_none() && r.tally.pixels > 0),
                    "scale {label} did not render on {}",
                    m.name()
                ),
                Some(why) => assert_eq!(r.and_then(|r| r.tally.refusal.clone()), Some(why), "{}", m.name()),
            }
        }
    }
    // Every axis ran on every method.
    for axis in AXES.iter().filter(|a| **a != AXES[1]) {
        for m in METHODS {
            assert!(rows.iter().any(|r| r.axis == *axis && r.method == m), "{axis} did not run on {}", m.name());
        }
    }
    assert!(gpu.validation_messages().is_empty());
}

/// A 1000-deep chain gave no LST frame on lavapipe (docs/stability.md, finding 5): lavapipe
/// compiled the kernel's zero-initialised private stack for minutes inside the first submission.
/// Without the initialisers the 1000-deep chain compiles in seconds; LST refuses a stack deeper
/// than `CPU_DEVICE_STACK_LIMIT` on CPU devices before the first frame, naming the depth, and
/// stackless renders that chain.
#[test]
fn lst_refuses_a_stack_lavapipe_cannot_compile_before_the_first_frame() {
    use tracer_vk::kernels::Method;
    use tracer_vk::render::{CPU_DEVICE_STACK_LIMIT, Renderer, VkRenderError};
    let gpu = common::gpu();
    let deep = tools::stress::scenes::chain(CPU_DEVICE_STACK_LIMIT + 2);
    let depth = deep.stats().max_depth;
    assert!(depth > CPU_DEVICE_STACK_LIMIT);
    let lst = Renderer::new(&gpu, &deep, Method::Lst, (8, 8));
    if gpu.info().kind == tracer_vk::DeviceKind::Cpu {
        let e = lst.err().expect("a stack past the limit is refused on a CPU device");
        assert!(matches!(&e, VkRenderError::PrivateStack { depth: d, .. } if *d == depth), "{e:?}");
        let text = e.to_string();
        assert!(text.contains(&depth.to_string()) && text.contains("stackless") && !text.contains('\n'), "{text}");
        let allowed = tools::stress::scenes::chain(CPU_DEVICE_STACK_LIMIT);
        assert!(allowed.stats().max_depth <= CPU_DEVICE_STACK_LIMIT);
        assert!(Renderer::new(&gpu, &allowed, Method::Lst, (8, 8)).is_ok());
        // The sweep's deepest chain is within it.
        assert!(tools::stress::scenes::chain(1001).stats().max_depth <= CPU_DEVICE_STACK_LIMIT);
    } else {
        assert!(lst.is_ok(), "only CPU devices limit LST's stack");
    }
    assert!(Renderer::new(&gpu, &deep, Method::Stackless, (8, 8)).is_ok());
}

/// SST keeps a stack of whole nodes in workgroup memory and shrinks its leaf cache to what is
/// left: it refuses, naming the bytes, only a tree whose stack does not fit beside a cache of one
/// triangle, and takes the deepest tree whose stack does.
#[test]
fn sst_refuses_only_a_stack_its_workgroup_memory_cannot_hold() {
    use tracer_vk::kernels::{Method, sst_shared_bytes};
    use tracer_vk::render::{Renderer, VkRenderError};
    let gpu = common::gpu();
    let limit = gpu.info().max_shared_memory as u64;
    let fits = |depth: u32| {
        let spec = tracer_vk::kernels::Specialisation {
            stack_size: depth,
            leaf_size: 1,
            ..tracer_vk::kernels::Specialisation::every_feature(Method::Sst)
        };
        sst_shared_bytes(&spec) <= limit
    };
    let deepest = (1..100_000).take_while(|&d| fits(d)).last().expect("a stack of one fits");
    for method in [Method::Sst, Method::SstSubgroup] {
        let too_deep = tools::stress::scenes::chain(deepest + 2);
        assert_eq!(too_deep.stats().max_depth, deepest + 1);
        let e = Renderer::new(&gpu, &too_deep, method, (8, 8)).err().expect("refused");
        let VkRenderError::SharedMemory { depth, needed, limit: l } = e else { panic!("{e:?}") };
        assert_eq!((depth, l), (deepest + 1, limit));
        assert!(needed > limit);
        let text = e.to_string();
        assert!(text.contains(&needed.to_string()) && text.contains("stackless") && !text.contains('\n'), "{text}");
        let deepest_chain = tools::stress::scenes::chain(deepest + 1);
        let r = Renderer::new(&gpu, &deepest_chain, method, (8, 8)).expect("fits");
        assert_eq!(r.specialisation().stack_size, deepest);
    }
}

/// The subnormal-direction axis tests what it says: the tilted mirror's normal has a subnormal x
/// component, every primary ray of the one-pixel-wide frame has x = 0, most hit the
/// mirror, and their reflection (the CPU's own `reflect`) has a subnormal, non-zero x component, and
/// the f64 reference sees the lit wall in that reflection (not the black background).
#[test]
fn subnormal_mirror_reflects_rays_with_subnormal_components_onto_the_wall() {
    use render_spec::CameraSpec;
    for eps in [1e-39f32, 1e-44] {
        let scene =
            bvh_build::compile(&tools::stress::scenes::subnormal_mirror(eps), &Default::default(), Default::default())
                .expect("compiles");
        let shot = cases::shot(&scene, CameraSpec::from(&scene.cameras[0]), 1, 16);
        let frame = shot.frame().expect("a valid camera");
        // The mirror is flat: the tracers shade it with its geometric normal.
        let mirror = (0..scene.triangles.len()).find(|&i| scene.triangles[i].material == 0).expect("a mirror");
        let [a, b, c] = scene.positions(mirror).map(glam::Vec3::from);
        let normal = (b - a).cross(c - a);
        let normal = normal * (1.0 / normal.length());
        assert!(normal.x.is_subnormal(), "{eps:e}: normal {normal:?}");
        let reference = tracer_cpu::reference::render(&scene, &shot).expect("the reference renders").image;
        let aov = tracer_cpu::render(&tracer_cpu::Tracer::new(&scene), &shot, tracer_cpu::Method::Ordered)
            .expect("renders")
            .aov
            .expect("AOVs");
        let mut reflected = 0;
        for y in 0..16 {
            let d = frame.direction(0, y);
            assert_eq!(d.x, 0.0, "{eps:e}: row {y}: {d:?}");
            // The upper rows see the wall itself.
            if aov.prim[y as usize] >= 2 {
                continue;
            }
            reflected += 1;
            let r = tracer_cpu::shade::reflect(d, normal);
            assert!(r.x.is_subnormal(), "{eps:e}: row {y}: reflection {r:?}");
            let rgb = reference.rgb[y as usize];
            assert!(rgb.iter().any(|c| *c > 40), "{eps:e}: row {y}: the reflection shows {rgb:?}, not the wall");
        }
        assert!(reflected >= 8, "{eps:e}: only {reflected} of 16 rows see the mirror");
    }
}
