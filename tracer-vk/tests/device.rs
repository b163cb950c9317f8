//! The device layer on a real Vulkan device (lavapipe here and in CI), always with the validation
//! layer on. Without a Vulkan loader or device these tests fail with the install hint: they must
//! not pass on a machine where nothing was tested.

use std::time::Duration;

use tracer_vk::{DeviceKind, FAULT_VARIABLE, Fault, Gpu, ValidationLog, VkError, list_devices, translate};

fn gpu() -> Gpu {
    Gpu::new(None, true).unwrap_or_else(|e| panic!("{e}"))
}

fn assert_clean(log: &ValidationLog, when: &str) {
    let m = log.messages();
    assert!(m.is_empty(), "{} validation messages {when}:\n{}", m.len(), m.join("\n"));
}

/// Checks the log while the device is open and again after everything is destroyed, when the
/// layer reports leaks and misuse at teardown.
fn finish(gpu: Gpu) {
    let log = gpu.validation_log();
    assert_clean(&log, "while running");
    drop(gpu);
    assert_clean(&log, "at teardown");
}

/// A few MB of bytes that are not all alike.
fn random_bytes(n: usize, seed: u64) -> Vec<u8> {
    tests::Rng(seed).bytes(n)
}

const DOUBLE: &str = r#"
    override WG: u32 = 64u;
    struct Params { count: u32, factor: u32 }
    @group(0) @binding(0) var<storage, read_write> data: array<u32>;
    var<immediate> params: Params;
    @compute @workgroup_size(WG)
    fn main(@builtin(global_invocation_id) id: vec3<u32>) {
        if id.x < params.count { data[id.x] = data[id.x] * params.factor; }
    }
"#;

/// Seconds of work on lavapipe: each invocation spins on a data-dependent loop.
const SLOW: &str = r#"
    @group(0) @binding(0) var<storage, read_write> data: array<u32>;
    @compute @workgroup_size(64)
    fn main(@builtin(global_invocation_id) id: vec3<u32>) {
        var x = data[id.x];
        for (var i = 0u; i < 4000u; i++) { x = x * 1664525u + 1013904223u; }
        data[id.x] = x;
    }
"#;

fn push(values: &[u32]) -> Vec<u8> {
    bytemuck::cast_slice(values).to_vec()
}

#[test]
fn handles_cross_threads() {
    fn send_sync<T: Send + Sync>() {}
    send_sync::<Gpu>();
    send_sync::<tracer_vk::Buffer>();
    send_sync::<tracer_vk::Pipeline>();
    send_sync::<tracer_vk::DeviceInfo>();
}

#[test]
fn lists_devices() {
    let devices = list_devices().unwrap_or_else(|e| panic!("{e}"));
    assert!(!devices.is_empty());
    for (i, d) in devices.iter().enumerate() {
        eprintln!("{d:?}");
        assert_eq!(d.index, i);
        assert!(!d.name.is_empty() && !d.driver.is_empty(), "{d:?}");
        assert!(d.api_version >= (1, 1, 0), "{d:?}");
        assert!(d.subgroup_size > 0 && d.subgroup_size.is_power_of_two(), "{d:?}");
        assert!(d.max_shared_memory >= 16384, "{d:?}");
        assert!(d.max_storage_buffer_range >= 1 << 27, "{d:?}");
        assert!(d.max_workgroup_invocations >= 128 && d.max_workgroup_size.iter().all(|&s| s > 0), "{d:?}");
        assert!(d.max_workgroup_count.iter().all(|&c| c >= 65535), "{d:?}");
        assert!(d.max_push_constants_size >= 128 && d.max_memory_allocation > 0, "{d:?}");
        assert!(d.device_local_bytes > 0 && d.timestamp_period_ns > 0.0, "{d:?}");
    }
    // Where lavapipe is not installed on purpose (the GPU machine), say so with this variable.
    if std::env::var("TRACER_VK_EXPECT_LAVAPIPE").as_deref() != Ok("0") {
        let lvp = devices.iter().find(|d| d.name.contains("llvmpipe")).expect("lavapipe (llvmpipe) is listed");
        assert_eq!(lvp.kind, DeviceKind::Cpu);
        assert!(lvp.supports_subgroup_ops && lvp.timestamps, "{lvp:?}");
    }
    let gpu = gpu();
    assert_eq!(gpu.info().name, devices[gpu.info().index].name);
    let e = Gpu::new(Some(devices.len()), true).err().expect("an index past the end fails");
    assert!(matches!(e, VkError::DeviceIndex { .. }), "{e:?}");
    finish(gpu);
}

#[test]
fn upload_download_round_trip() {
    let gpu = gpu();
    // Not a multiple of 16: the buffer is rounded up, the tail is whatever was there.
    let data = random_bytes(3 << 20 | 5, 1);
    let buf = gpu.create_buffer(data.len() as u64, "round trip").unwrap();
    assert_eq!(buf.size(), (3 << 20) + 16);
    assert_eq!(buf.label(), "round trip");
    gpu.upload(&buf, &data).unwrap();
    let back = gpu.download(&buf).unwrap();
    assert_eq!(back.len() as u64, buf.size());
    assert!(back[..data.len()] == data[..], "downloaded bytes differ");

    // Larger than one staging chunk (64 MiB), so the copy is split. Each MiB is rotated
    // differently, so a chunk copied to the wrong offset shows.
    let mib = random_bytes(1 << 20, 2);
    let mut big = Vec::with_capacity(66 << 20);
    for i in 0..66 {
        let mut m = mib.clone();
        m.rotate_left(i * 7919);
        big.extend_from_slice(&m);
    }
    let big_buf = gpu.create_buffer_with(&big, "big").unwrap();
    assert!(gpu.download(&big_buf).unwrap() == big, "66 MiB round trip differs");

    let e = gpu.upload(&buf, &big).unwrap_err();
    assert!(matches!(e, VkError::Usage(_)), "{e:?}");
    drop((buf, big_buf));
    finish(gpu);
}

#[test]
fn doubles_a_million_u32_with_an_override_workgroup_size() {
    let gpu = gpu();
    let n = 1u32 << 20;
    let input: Vec<u32> = (0..n).map(|i| i.wrapping_mul(2_654_435_761)).collect();
    let buf = gpu.create_buffer_with(&input, "numbers").unwrap();
    let wg = 128u32;
    let spirv = translate(DOUBLE, "double", &[("WG", wg as f64)]).unwrap();
    let pipeline = gpu.pipeline(&spirv, 1, 8, "double").unwrap();
    let timings = gpu
        .run(|r| {
            r.mark("start");
            r.dispatch(&pipeline, &[&buf], &push(&[n, 2]), [n / wg, 1, 1])?;
            r.mark("double");
            // The barrier after a dispatch makes its writes visible to the next one.
            r.dispatch(&pipeline, &[&buf], &push(&[n, 3]), [n / wg, 1, 1])?;
            r.mark("triple");
            Ok(())
        })
        .unwrap();
    let out: Vec<u32> = gpu.download_as(&buf).unwrap();
    assert_eq!(out.len(), n as usize);
    for (i, (&a, &b)) in input.iter().zip(&out).enumerate() {
        assert_eq!(b, a.wrapping_mul(6), "element {i}");
    }
    assert_eq!(timings.intervals.iter().map(|(l, _)| l.as_str()).collect::<Vec<_>>(), ["double", "triple"]);

    // Misuse is an error, not a validation message or a crash.
    let e = gpu.run(|r| r.dispatch(&pipeline, &[], &push(&[n, 2]), [1, 1, 1])).unwrap_err();
    assert!(matches!(e, VkError::Usage(_)), "{e:?}");
    let e = gpu.run(|r| r.dispatch(&pipeline, &[&buf], &[0; 4], [1, 1, 1])).unwrap_err();
    assert!(matches!(e, VkError::Usage(_)), "{e:?}");
    let e = gpu.run(|r| r.dispatch(&pipeline, &[&buf], &push(&[n, 2]), [u32::MAX, 1, 1])).unwrap_err();
    assert!(matches!(e, VkError::Usage(_)), "{e:?}");
    let e = gpu.pipeline(&spirv, 1, 6, "odd push").unwrap_err();
    assert!(matches!(e, VkError::Usage(_)), "{e:?}");
    // A run after failed ones works, and zero() clears.
    gpu.run(|r| {
        r.zero(&buf);
        r.dispatch(&pipeline, &[&buf], &push(&[n, 2]), [n / wg, 1, 1])
    })
    .unwrap();
    assert!(gpu.download_as::<u32>(&buf).unwrap().iter().all(|&x| x == 0));
    drop((pipeline, buf));
    finish(gpu);
}

#[test]
fn timestamps_measure_work() {
    let gpu = gpu();
    let n = 1u32 << 16;
    let buf = gpu.create_buffer(n as u64 * 4, "numbers").unwrap();
    let pipeline = gpu.pipeline(&translate(DOUBLE, "double", &[]).unwrap(), 1, 8, "double").unwrap();
    // Many sets in one run: the descriptor pools must grow (256 sets per pool).
    let many = 600;
    let t = gpu
        .run(|r| {
            r.zero(&buf);
            r.mark("begin");
            for i in 0..many {
                r.dispatch(&pipeline, &[&buf], &push(&[n, 1]), [n / 64, 1, 1])?;
                // More marks than one query pool holds (64).
                if i % 5 == 0 {
                    r.mark(&format!("d{i}"));
                }
            }
            r.mark("end");
            Ok(())
        })
        .unwrap();
    eprintln!("{} dispatches over 64Ki elements: {:.3} ms", many, t.total_ms);
    assert!(t.total_ms > 0.0 && t.total_ms.is_finite(), "{t:?}");
    assert_eq!(t.intervals.len(), many / 5 + 1);
    assert!(t.intervals.iter().all(|&(_, ms)| ms >= 0.0 && ms.is_finite()), "{t:?}");
    let sum: f64 = t.intervals.iter().map(|(_, ms)| ms).sum();
    assert!((sum - t.total_ms).abs() < 1e-6 * t.total_ms.max(1.0), "{sum} vs {}", t.total_ms);
    assert!(t.get("end").is_some());
    // One mark or none: no intervals, nothing measured.
    let t = gpu.run(|r| {
        r.mark("alone");
        Ok(())
    });
    assert_eq!(t.unwrap().total_ms, 0.0);
    drop((pipeline, buf));
    finish(gpu);
}

#[test]
fn too_large_buffer_is_refused() {
    let gpu = gpu();
    let limit = gpu.info().max_storage_buffer_range;
    let e = gpu.create_buffer(limit + 1, "nodes").unwrap_err();
    match &e {
        VkError::BufferTooLarge { label, bytes, limit: l } => {
            assert_eq!((label.as_str(), *bytes, *l), ("nodes", limit + 1, limit));
        }
        other => panic!("{other:?}"),
    }
    let text = e.to_string();
    assert!(text.contains("nodes") && text.contains("maxStorageBufferRange") && !text.contains('\n'), "{text}");
    finish(gpu);
}

#[test]
fn wgsl_syntax_error_is_one_line() {
    let e = translate("@compute @workgroup_size(1) fn main( { }", "broken", &[]).unwrap_err();
    let VkError::Shader { label, message } = &e else { panic!("{e:?}") };
    assert_eq!(label, "broken");
    assert!(message.contains("wgsl:1:"), "the full message has naga's diagnostic: {message}");
    let text = e.to_string();
    assert!(!text.contains('\n') && text.starts_with("shader `broken` did not compile: "), "{text}");
    // And a device that never saw it stays clean.
    finish(gpu());
}

#[test]
fn timeout_is_an_error_not_a_hang() {
    let mut gpu = gpu();
    let buf = gpu.create_buffer_with(&vec![1u32; 1 << 16], "slow").unwrap();
    let pipeline = gpu.pipeline(&translate(SLOW, "slow", &[]).unwrap(), 1, 0, "slow").unwrap();
    gpu.set_timeout(Duration::from_nanos(1));
    let e = gpu.run(|r| r.dispatch(&pipeline, &[&buf], &[], [1 << 10, 1, 1])).unwrap_err();
    assert!(matches!(e, VkError::Timeout { .. }), "{e:?}");
    assert!(!e.to_string().contains('\n'));
    // The abandoned work is waited for before the next use of the queue.
    gpu.timeout = Duration::from_secs(120);
    let out: Vec<u32> = gpu.download_as(&buf).unwrap();
    assert!(out.iter().all(|&x| x == out[0]) && out[0] != 1);
    drop((pipeline, buf));
    finish(gpu);
}

/// `trace-vk render --method sst --workgroup 1x1` once aborted with "double free or corruption":
/// after a timeout the renderer's buffers were freed while lavapipe's threads still ran the
/// kernel that used them. Objects dropped while abandoned work is in flight must outlive it.
#[test]
fn buffers_dropped_after_a_timeout_outlive_the_abandoned_work() {
    let mut gpu = gpu();
    let buf = gpu.create_buffer_with(&vec![1u32; 1 << 16], "slow").unwrap();
    let pipeline = gpu.pipeline(&translate(SLOW, "slow", &[]).unwrap(), 1, 0, "slow").unwrap();
    gpu.set_timeout(Duration::from_nanos(1));
    let e = gpu.run(|r| r.dispatch(&pipeline, &[&buf], &[], [1 << 10, 1, 1])).unwrap_err();
    assert!(matches!(e, VkError::Timeout { .. }), "{e:?}");
    // Dropped while the GPU still runs the dispatch that binds them.
    drop((pipeline, buf));
    gpu.timeout = Duration::from_secs(120);
    // The device stays usable, and nothing was destroyed in use.
    let other = gpu.create_buffer_with(&[5u32; 4], "after").unwrap();
    assert_eq!(gpu.download_as::<u32>(&other).unwrap(), [5; 4]);
    drop(other);
    finish(gpu);
}

#[test]
fn validation_messages_are_recorded() {
    // The other tests assert an empty log; this shows that the log would not be empty if the
    // layer complained. An unaligned fill offset breaks a valid-usage rule of vkCmdFillBuffer.
    let gpu = gpu();
    let buf = gpu.create_buffer(64, "misused").unwrap();
    gpu.run(|r| {
        // SAFETY: invalid on purpose, but within the buffer; the driver only sees a small fill.
        unsafe { gpu.ash_device().cmd_fill_buffer(r.raw(), buf.raw(), 2, 4, 0) };
        Ok(())
    })
    .unwrap();
    let m = gpu.validation_messages();
    assert!(m.iter().any(|m| m.contains("dstOffset")), "{m:?}");
}

#[test]
fn upload_inside_run_is_an_error() {
    let gpu = gpu();
    let buf = gpu.create_buffer(16, "x").unwrap();
    let e = gpu.run(|_| gpu.upload(&buf, &[0; 16])).unwrap_err();
    assert!(matches!(e, VkError::Usage(_)), "{e:?}");
    gpu.upload(&buf, &[7; 16]).unwrap();
    assert_eq!(gpu.download(&buf).unwrap(), [7; 16]);
    drop(buf);
    finish(gpu);
}

/// A lost device (simulated: lavapipe never loses its own) ends the run that saw it with
/// `DeviceLost` in one sentence, and stays lost: later uploads and runs fail the same way, not
/// with a hang or a crash, even after the simulation is switched off.
#[test]
fn a_lost_device_is_an_error_and_stays_lost() {
    let gpu = gpu();
    let buf = gpu.create_buffer_with(&[1u32; 64], "numbers").unwrap();
    let pipeline = gpu.pipeline(&translate(DOUBLE, "double", &[]).unwrap(), 1, 8, "double").unwrap();
    gpu.run(|r| r.dispatch(&pipeline, &[&buf], &push(&[64, 2]), [1, 1, 1])).unwrap();
    gpu.simulate(Some(Fault::DeviceLost));
    let e = gpu.run(|r| r.dispatch(&pipeline, &[&buf], &push(&[64, 2]), [1, 1, 1])).unwrap_err();
    assert!(matches!(e, VkError::DeviceLost), "{e:?}");
    let text = e.to_string();
    assert!(text.contains("lost") && !text.contains('\n'), "{text}");
    gpu.simulate(None);
    assert!(matches!(gpu.upload(&buf, &[0; 16]).unwrap_err(), VkError::DeviceLost));
    assert!(matches!(gpu.download(&buf).unwrap_err(), VkError::DeviceLost));
    assert!(matches!(gpu.run(|_| Ok(())).unwrap_err(), VkError::DeviceLost));
    drop((pipeline, buf));
    finish(gpu);
}

/// Allocations past what the (simulated) device has left fail with `OutOfDeviceMemory`, naming
/// the buffer and its size; smaller ones still succeed, and the device is usable afterwards.
#[test]
fn out_of_device_memory_names_the_buffer() {
    let gpu = gpu();
    gpu.simulate(Some(Fault::OutOfMemory(1 << 20)));
    let e = gpu.create_buffer(4 << 20, "nodes").unwrap_err();
    match &e {
        VkError::OutOfDeviceMemory { label, bytes } => assert_eq!((label.as_str(), *bytes), ("nodes", 4 << 20)),
        other => panic!("{other:?}"),
    }
    let text = e.to_string();
    assert!(text.contains("nodes") && text.contains("4194304") && !text.contains('\n'), "{text}");
    let small = gpu.create_buffer_with(&[3u32; 16], "small").unwrap();
    assert_eq!(gpu.download_as::<u32>(&small).unwrap(), [3; 16]);
    gpu.simulate(None);
    let big = gpu.create_buffer(4 << 20, "nodes").unwrap();
    drop((small, big));
    finish(gpu);
}

/// A run that does not finish in time ends in `Timeout`, one sentence; the simulation of it
/// (for frames, whose work lavapipe finishes too fast to time out for real) says the same.
#[test]
fn a_simulated_timeout_reads_like_a_real_one() {
    let gpu = gpu();
    let buf = gpu.create_buffer_with(&[1u32; 64], "numbers").unwrap();
    let pipeline = gpu.pipeline(&translate(DOUBLE, "double", &[]).unwrap(), 1, 8, "double").unwrap();
    gpu.simulate(Some(Fault::Timeout));
    let e = gpu.run(|r| r.dispatch(&pipeline, &[&buf], &push(&[64, 2]), [1, 1, 1])).unwrap_err();
    assert!(matches!(e, VkError::Timeout { seconds: 120 }), "{e:?}");
    gpu.simulate(None);
    // The work had finished: the device goes on.
    gpu.run(|r| r.dispatch(&pipeline, &[&buf], &push(&[64, 3]), [1, 1, 1])).unwrap();
    assert_eq!(gpu.download_as::<u32>(&buf).unwrap()[..64], [6; 64]);
    drop((pipeline, buf));
    finish(gpu);
}

#[test]
fn fault_names_parse_and_a_wrong_one_is_one_sentence() {
    assert_eq!(Fault::parse("device-lost").unwrap(), Fault::DeviceLost);
    assert_eq!(Fault::parse("timeout").unwrap(), Fault::Timeout);
    assert_eq!(Fault::parse("out-of-memory:65536").unwrap(), Fault::OutOfMemory(65536));
    for bad in ["lost", "out-of-memory:", "out-of-memory:-1", "timeout "] {
        let e = Fault::parse(bad).unwrap_err();
        let text = e.to_string();
        assert!(matches!(e, VkError::Usage(_)) && text.contains(FAULT_VARIABLE) && !text.contains('\n'), "{text}");
    }
}
