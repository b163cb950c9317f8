//! The shared formulas, one function at a time, in the manner of tinybvh's reference tests: a
//! WGSL harness calls the kernels' own slab test, triangle test, origin offset, surface normal,
//! reflection, refraction, Phong term, adaptive bounce test, primary ray direction, sample sequence and
//! cosine-distributed direction on edge-case inputs on the Vulkan
//! device at hand (lavapipe in CI), and every result must equal the Rust function of the CPU
//! tracer bit for bit. Whole images agree only where a pixel happens to exercise a difference;
//! these cases aim at the corners: axis-parallel rays with +0 and -0, origins in a box's face,
//! rays through edges and vertices, degenerate triangles, grazing and total internal reflection,
//! huge and tiny coordinates.

mod common;

use bvh_format::{Material, Node, Triangle};
use glam::Vec3;
use render_spec::constants::STOP_CONTRIBUTION;
use render_spec::{BounceStop, CameraSpec, Frame, Intersect};
use tests::Rng;
use tracer_cpu::geometry::{self, Ray};
use tracer_cpu::shade::{self, Surface};
use tracer_vk::kernels::{self, Method, Specialisation};
use tracer_vk::{Buffer, DeviceKind, Gpu};

/// Marks a difference on a case with subnormal inputs on a device that may flush them.
const FLUSHED: &str = "(flushed)";

/// vec4s of input per case, and of output.
const IN: usize = 6;
const OUT: usize = 2;

/// The harness entry point: `pass_info.light` picks the function, `cases` holds IN vec4s per
/// case, `results` receives the result's bits. The kernels' own bindings 0..13 stay as they are;
/// the harness adds 14 and 15.
const HARNESS: &str = r#"
@group(0) @binding(14) var<storage, read> cases: array<vec4<f32>>;
@group(0) @binding(15) var<storage, read_write> results: array<vec4<u32>>;

fn arg(i: u32, k: u32) -> vec4<f32> {
    return cases[i * 6u + k];
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.x;
    if i >= arrayLength(&results) / 2u {
        return;
    }
    var a = vec4<f32>(0.0);
    var b = vec4<f32>(0.0);
    switch pass_info.light {
        case 0u: {
            let n = Node(arg(i, 0u).xyz, 1u, arg(i, 1u).xyz, 0u);
            a.x = slab(n, make_ray(arg(i, 2u).xyz, arg(i, 3u).xyz), arg(i, 0u).w);
        }
        case 1u: {
            let tri = Tri(arg(i, 0u).xyz, 0u, arg(i, 1u).xyz, 0u, arg(i, 2u).xyz, 0u);
            a = vec4<f32>(intersect(tri, make_ray(arg(i, 3u).xyz, arg(i, 4u).xyz), arg(i, 5u).x, arg(i, 5u).y), 0.0);
        }
        case 2u: {
            a = vec4<f32>(offset_origin(arg(i, 0u).xyz, arg(i, 1u).xyz), 0.0);
        }
        case 3u: {
            a = vec4<f32>(reflect_dir(arg(i, 0u).xyz, arg(i, 1u).xyz), 0.0);
        }
        case 4u: {
            a = refract_dir(arg(i, 0u).xyz, arg(i, 1u).xyz, arg(i, 0u).w);
        }
        case 5u: {
            let m = Material(arg(i, 0u), arg(i, 1u), vec4<f32>(0.0));
            let s = Surface(vec3<f32>(0.0), arg(i, 2u).xyz, arg(i, 2u).xyz, true);
            a = vec4<f32>(phong(m, s, arg(i, 3u).xyz, arg(i, 4u).xyz), 0.0);
        }
        case 6u: {
            a.x = select(0.0, 1.0, worth_tracing(arg(i, 0u).x, u32(arg(i, 0u).y)));
        }
        case 7u: {
            // Triangle i of the tris binding, hit at t with barycentrics (u, v).
            let s = surface_at(make_ray(arg(i, 0u).xyz, arg(i, 1u).xyz), HitRec(arg(i, 2u).x, i, arg(i, 2u).y, arg(i, 2u).z));
            a = vec4<f32>(s.geometric, select(0.0, 1.0, s.front));
            b = vec4<f32>(s.shading, 0.0);
        }
        case 8u: {
            a = vec4<f32>(primary_dir(u32(arg(i, 0u).x), u32(arg(i, 0u).y)), 0.0);
        }
        case 9u: {
            // Words as 16-bit halves (exact in f32): pixel, sample; then rays, ray.
            let w = vec4<u32>(arg(i, 0u));
            let n = incoherent_sample((w.z << 16u) | w.w, u32(arg(i, 1u).x), u32(arg(i, 1u).y));
            a = vec4<f32>(sample_2d((w.x << 16u) | w.y, n), 0.0, 0.0);
        }
        case 10u: {
            a = vec4<f32>(cosine_direction(arg(i, 0u).xyz, arg(i, 1u).xy), 0.0);
        }
        default: {}
    }
    results[2u * i] = bitcast<vec4<u32>>(a);
    results[2u * i + 1u] = bitcast<vec4<u32>>(b);
}
"#;

/// One function's cases: the harness's inputs, and the Rust function's results as bits.
struct Cases {
    name: &'static str,
    selector: u32,
    inputs: Vec<[f32; 4]>,
    expected: Vec<[u32; 8]>,
    /// What each case was, for the failure message.
    shown: Vec<String>,
}

impl Cases {
    fn new(name: &'static str, selector: u32) -> Self {
        Cases { name, selector, inputs: Vec::new(), expected: Vec::new(), shown: Vec::new() }
    }

    fn push(&mut self, args: &[[f32; 4]], a: [f32; 4], b: [f32; 4], shown: String) {
        assert!(args.len() <= IN);
        let mut block = [[0.0f32; 4]; IN];
        block[..args.len()].copy_from_slice(args);
        self.inputs.extend(block);
        self.expected.push(std::array::from_fn(|k| if k < 4 { a[k].to_bits() } else { b[k - 4].to_bits() }));
        self.shown.push(shown);
    }

    fn len(&self) -> usize {
        self.expected.len()
    }
}

fn v4(v: Vec3, w: f32) -> [f32; 4] {
    [v.x, v.y, v.z, w]
}

/// Interesting coordinates: signed zeros, tiny, huge, subnormal, and ordinary values.
const SPECIAL: [f32; 12] = [0.0, -0.0, 1.0, -1.0, 0.5, 1e-30, -1e-30, 1e30, 1e-40, -3.25, 1e7, 0.1];

fn special_vec(rng: &mut Rng) -> Vec3 {
    let mut c = || SPECIAL[rng.below(SPECIAL.len())];
    Vec3::new(c(), c(), c())
}

fn random_vec(rng: &mut Rng, scale: f32) -> Vec3 {
    Vec3::new(rng.unit() * 2.0 - 1.0, rng.unit() * 2.0 - 1.0, rng.unit() * 2.0 - 1.0) * scale
}

fn unit_vec(rng: &mut Rng) -> Vec3 {
    loop {
        let v = random_vec(rng, 1.0);
        if v.length_squared() > 1e-4 {
            return v.normalize();
        }
    }
}

fn slab_cases(rng: &mut Rng) -> Cases {
    let mut c = Cases::new("slab", 0);
    let mut add = |lo: Vec3, hi: Vec3, o: Vec3, d: Vec3, t_max: f32| {
        let node = Node { min: lo.into(), count: 1, max: hi.into(), index: 0 };
        let r = geometry::slab(&node, &Ray::new(o, d), t_max).unwrap_or(-1.0);
        c.push(
            &[v4(lo, t_max), v4(hi, 0.0), v4(o, 0.0), v4(d, 0.0)],
            [r, 0.0, 0.0, 0.0],
            [0.0; 4],
            format!("box {lo}..{hi} ray {o} + t {d} t_max {t_max}"),
        );
    };
    let (lo, hi) = (Vec3::splat(-1.0), Vec3::splat(1.0));
    // Axis-parallel rays with both zeros, from inside, outside and exactly in a face's plane.
    for o in [
        Vec3::new(0.0, 0.0, -3.0),
        Vec3::new(1.0, 0.5, -3.0),
        Vec3::new(-1.0, -1.0, -3.0),
        Vec3::new(0.0, 2.0, -3.0),
        Vec3::ZERO,
    ] {
        for d in [
            Vec3::new(0.0, 0.0, 1.0),
            Vec3::new(-0.0, 0.0, 1.0),
            Vec3::new(0.0, -0.0, 1.0),
            Vec3::new(-0.0, -0.0, -1.0),
        ] {
            for t_max in [f32::MAX, 10.0, 2.0, 1.0] {
                add(lo, hi, o, d, t_max);
            }
        }
    }
    // A flat box (zero thickness) and an empty-looking one.
    add(
        Vec3::new(-1.0, 0.0, -1.0),
        Vec3::new(1.0, 0.0, 1.0),
        Vec3::new(0.2, 1.0, 0.3),
        Vec3::new(0.0, -1.0, 0.0),
        f32::MAX,
    );
    add(
        Vec3::new(-1.0, 0.0, -1.0),
        Vec3::new(1.0, 0.0, 1.0),
        Vec3::new(0.2, 0.0, 0.3),
        Vec3::new(1.0, 0.0, 0.0),
        f32::MAX,
    );
    for _ in 0..400 {
        let a = random_vec(rng, 4.0);
        let b = a + random_vec(rng, 2.0).abs();
        let (o, d) = if rng.below(3) == 0 {
            (special_vec(rng), special_vec(rng))
        } else {
            (random_vec(rng, 8.0), unit_vec(rng))
        };
        let t_max = [f32::MAX, 1.0, 5.0, 1e-3][rng.below(4)];
        add(a, b, o, d, t_max);
    }
    c
}

/// Cases of the kernels' `intersect`, whose twin is the triangle test `test` of the kernel variant.
fn intersect_cases(rng: &mut Rng, test: Intersect) -> Cases {
    let mut c = Cases::new("intersect", 1);
    let reference = match test {
        Intersect::Watertight => geometry::intersect,
        Intersect::MollerTrumbore => geometry::intersect_moller_trumbore,
    };
    let mut add = |p: [Vec3; 3], o: Vec3, d: Vec3, t_min: f32, t_max: f32| {
        let tri = Triangle::from_vertices(p[0].into(), p[1].into(), p[2].into());
        let r =
            reference(&tri, &Ray::new(o, d), t_min, t_max).map_or([-1.0, 0.0, 0.0, 0.0], |(t, u, v)| [t, u, v, 0.0]);
        c.push(
            &[v4(p[0], 0.0), v4(p[1], 0.0), v4(p[2], 0.0), v4(o, 0.0), v4(d, 0.0), [t_min, t_max, 0.0, 0.0]],
            r,
            [0.0; 4],
            format!("tri {p:?} ray {o} + t {d} in ({t_min}, {t_max}]"),
        );
    };
    let tri = [Vec3::new(0.0, 0.0, 0.0), Vec3::new(1.0, 0.0, 0.0), Vec3::new(0.0, 1.0, 0.0)];
    // Through each vertex, the middle of each edge, the inside and just outside, both sides.
    let targets = [
        tri[0],
        tri[1],
        tri[2],
        (tri[0] + tri[1]) * 0.5,
        (tri[1] + tri[2]) * 0.5,
        (tri[2] + tri[0]) * 0.5,
        Vec3::new(0.25, 0.25, 0.0),
        Vec3::new(-1e-7, 0.5, 0.0),
    ];
    for target in targets {
        for o in [Vec3::new(0.3, 0.2, 1.0), Vec3::new(0.3, 0.2, -1.0), Vec3::new(-2.0, 3.0, 5.0)] {
            add(tri, o, (target - o).normalize(), 0.0, f32::MAX);
            add(tri, o, target - o, 0.0, f32::MAX);
        }
    }
    // In the triangle's plane, degenerate triangles, and a hit beyond t_max or before t_min.
    add(tri, Vec3::new(-1.0, 0.5, 0.0), Vec3::X, 0.0, f32::MAX);
    add([tri[0], tri[1], tri[1]], Vec3::new(0.5, 0.0, 1.0), -Vec3::Z, 0.0, f32::MAX);
    add([tri[0], tri[0], tri[0]], Vec3::new(0.0, 0.0, 1.0), -Vec3::Z, 0.0, f32::MAX);
    add(tri, Vec3::new(0.2, 0.2, 1.0), -Vec3::Z, 0.0, 0.5);
    add(tri, Vec3::new(0.2, 0.2, 1.0), -Vec3::Z, 1.0, f32::MAX);
    add(tri, Vec3::new(0.2, 0.2, 0.0), -Vec3::Z, 0.0, f32::MAX);
    // Random rays at random vertices and edges of random triangles, at several scales.
    for _ in 0..600 {
        let scale = [1e-4, 1.0, 1e3, 1e6][rng.below(4)];
        let centre = random_vec(rng, scale * 10.0);
        let p = [0, 1, 2].map(|_| centre + random_vec(rng, scale));
        let w = [rng.unit(), rng.unit(), rng.unit()];
        let target = match rng.below(3) {
            0 => p[rng.below(3)],
            1 => {
                let (a, b) = (p[rng.below(3)], p[rng.below(3)]);
                a + (b - a) * w[0]
            }
            _ => (p[0] * w[0] + p[1] * w[1] + p[2] * w[2]) / (w[0] + w[1] + w[2]).max(1e-3),
        };
        let o = target + random_vec(rng, scale * 4.0);
        add(p, o, (target - o).normalize_or(Vec3::Z), 0.0, f32::MAX);
    }
    c
}

fn offset_cases(rng: &mut Rng) -> Cases {
    let mut c = Cases::new("offset_origin", 2);
    let mut add = |p: Vec3, n: Vec3| {
        let r = geometry::offset_origin(p, n);
        c.push(&[v4(p, 0.0), v4(n, 0.0)], v4(r, 0.0), [0.0; 4], format!("p {p} n {n}"));
    };
    for p in [
        Vec3::ZERO,
        Vec3::splat(-0.0),
        Vec3::new(1e-30, -1e-30, 1e-40),
        Vec3::new(3e38, -3e38, 1e7),
        Vec3::new(0.5, -0.5, 2.0),
    ] {
        for n in [Vec3::X, -Vec3::Y, Vec3::new(0.0, -0.0, 1.0), Vec3::new(0.6, -0.8, 0.0)] {
            add(p, n);
        }
    }
    for _ in 0..300 {
        let scale = [1e-6, 1.0, 1e4, 1e9][rng.below(4)];
        add(random_vec(rng, scale), unit_vec(rng));
    }
    c
}

fn reflect_refract_cases(rng: &mut Rng) -> (Cases, Cases) {
    let mut refl = Cases::new("reflect_dir", 3);
    let mut refr = Cases::new("refract_dir", 4);
    for k in 0..400 {
        let n = unit_vec(rng);
        // Incoming against the normal, from head-on down to grazing.
        let mut d = unit_vec(rng);
        if d.dot(n) > 0.0 {
            d = -d;
        }
        if k % 10 == 0 {
            d = (d - n * d.dot(n)).normalize_or(d) * 1.0; // grazing: in the plane
        }
        let r = shade::reflect(d, n);
        refl.push(&[v4(d, 0.0), v4(n, 0.0)], v4(r, 0.0), [0.0; 4], format!("d {d} n {n}"));
        let eta = [1.0 / 1.5, 1.5, 1.0, 1.0 / 1.33, 2.4][k % 5];
        let t = shade::refract(d, n, eta).map_or([0.0; 4], |t| v4(t, 1.0));
        refr.push(&[v4(d, eta), v4(n, 0.0)], t, [0.0; 4], format!("d {d} n {n} eta {eta}"));
    }
    (refl, refr)
}

fn phong_cases(rng: &mut Rng) -> Cases {
    let mut c = Cases::new("phong", 5);
    for k in 0..300 {
        let n = unit_vec(rng);
        let d = unit_vec(rng);
        let l = if k % 7 == 0 { -n } else { unit_vec(rng) };
        let shininess = [0.0, 1.0, 8.5, 32.0, 1000.0][k % 5];
        let m = Material {
            kd: [rng.unit(), rng.unit(), rng.unit()],
            shininess,
            ks: [rng.unit(), rng.unit(), rng.unit()],
            ..Default::default()
        };
        let s = Surface { point: Vec3::ZERO, geometric: n, shading: n, front: true };
        let r = shade::phong(&m, &s, d, l);
        c.push(
            &[
                [m.kd[0], m.kd[1], m.kd[2], shininess],
                [m.ks[0], m.ks[1], m.ks[2], 0.0],
                v4(n, 0.0),
                v4(d, 0.0),
                v4(l, 0.0),
            ],
            v4(r, 0.0),
            [0.0; 4],
            format!("n {n} d {d} l {l} shininess {shininess}"),
        );
    }
    c
}

fn worth_cases(stop: BounceStop, rng: &mut Rng) -> Cases {
    let mut c = Cases::new("worth_tracing", 6);
    let edge = stop.cutoff;
    for k in 0..200 {
        let remaining = [0u32, 1, 2, 5, 64, 1024][k % 6];
        let w = match k % 4 {
            0 => edge / stop.bound,
            1 => f32::from_bits((edge / stop.bound).to_bits().saturating_sub(1)),
            2 => rng.unit(),
            _ => rng.unit() * 1e-3,
        };
        let r = if stop.worth_tracing(w, remaining) { 1.0 } else { 0.0 };
        c.push(
            &[[w, remaining as f32, 0.0, 0.0]],
            [r, 0.0, 0.0, 0.0],
            [0.0; 4],
            format!("w {w} remaining {remaining} stop {stop:?}"),
        );
    }
    c
}

/// Surfaces of the triangles in `tris` (case i is triangle i).
fn surface_cases(tris: &[Triangle], rng: &mut Rng) -> Cases {
    let mut c = Cases::new("surface_at", 7);
    for tri in tris {
        let [p0, p1, p2] = tri.vertices().map(Vec3::from);
        let (u, v) = (rng.unit() * 0.5, rng.unit() * 0.5);
        let target = p0 * (1.0 - u - v) + p1 * u + p2 * v;
        let o = target + random_vec(rng, 3.0);
        let d = (target - o).normalize_or(Vec3::Z);
        let t = (target - o).length();
        let s = shade::surface(tri, None, o, d, t, u, v);
        c.push(
            &[v4(o, 0.0), v4(d, 0.0), [t, u, v, 0.0]],
            v4(s.geometric, if s.front { 1.0 } else { 0.0 }),
            v4(s.shading, 0.0),
            format!("tri {tri:?} ray {o} + t {d} at t {t} (u {u}, v {v})"),
        );
    }
    c
}

/// Runs `cases` through the harness with `frame` and `tris` bound, and returns the failures.
fn run(gpu: &Gpu, pipeline: &tracer_vk::Pipeline, cases: &Cases, frame: &[u8], tris: &[Triangle]) -> Vec<String> {
    let buf = |bytes: &[u8], label: &str| gpu.create_buffer_with(bytes, label).expect("a small buffer");
    let dummy = || buf(&[0u8; 64], "unused");
    // The flat-normal marker for every triangle: shading takes the geometric normal.
    let normal_indices: Vec<u32> = vec![render_spec::constants::FLAT_NORMAL; 3 * tris.len().max(1)];
    let frame_buf = buf(frame, "frame");
    let placeholder = [Triangle::from_vertices([0.0; 3], [0.0; 3], [0.0; 3])];
    let tris_buf = buf(bytemuck::cast_slice(if tris.is_empty() { &placeholder } else { tris }), "tris");
    let ni_buf = buf(bytemuck::cast_slice(&normal_indices), "normal indices");
    let inputs = buf(bytemuck::cast_slice(&cases.inputs), "cases");
    let results = gpu.create_buffer((cases.len() * OUT * 16) as u64, "results").expect("a small buffer");
    let others: Vec<Buffer> = (0..11).map(|_| dummy()).collect();
    let mut bound: Vec<&Buffer> = vec![&frame_buf, &others[0], &tris_buf, &ni_buf];
    bound.extend(others[1..11].iter());
    bound.push(&inputs);
    bound.push(&results);
    let mut push = [0u8; kernels::PASS_BYTES as usize];
    push[..4].copy_from_slice(&cases.selector.to_le_bytes());
    gpu.run(|rec| rec.dispatch(pipeline, &bound, &push, [(cases.len() as u32).div_ceil(64), 1, 1]))
        .expect("the harness runs");
    let got: Vec<[u32; 8]> = gpu.download_prefix_as(&results, cases.len()).expect("the results download");
    let mut failures = Vec::new();
    // A device that does not promise to keep subnormals (shaderDenormPreserveFloat32; the H100
    // flushes them even under --exact) may read a subnormal input as zero: such a case is
    // counted apart, not as a difference of the formulas.
    let flushes = !gpu.info().denorm_preserve_f32;
    for (i, (g, e)) in got.iter().zip(&cases.expected).enumerate() {
        let subnormal_input = cases.inputs[i * IN..(i + 1) * IN].iter().flatten().any(|x| x.is_subnormal());
        if g != e && flushes && subnormal_input {
            failures.push(format!("{FLUSHED} {} case {i}", cases.name));
        } else if g != e {
            let f = |w: &[u32; 8]| w.map(f32::from_bits);
            failures.push(format!(
                "{} case {i}: {}\n    GPU  {:?}\n    Rust {:?}",
                cases.name,
                cases.shown[i],
                f(g),
                f(e)
            ));
        }
    }
    failures
}

/// The sequence of the incoherent modes (render_spec::sequence::sample_2d of incoherent_sample):
/// pixels and sample numbers at the ends of the u32 range and where the products wrap.
fn sequence_cases(rng: &mut Rng) -> Cases {
    use render_spec::sequence::{incoherent_sample, sample_2d};
    let mut c = Cases::new("sample_2d", 9);
    let mut add = |pixel: u32, sample: u32, rays: u32, ray: u32| {
        let s = sample_2d(pixel, incoherent_sample(sample, rays, ray));
        let half = |w: u32| [(w >> 16) as f32, (w & 0xffff) as f32];
        let (p, q) = (half(pixel), half(sample));
        c.push(
            &[[p[0], p[1], q[0], q[1]], [rays as f32, ray as f32, 0.0, 0.0]],
            [s[0], s[1], 0.0, 0.0],
            [0.0; 4],
            format!("pixel {pixel} sample {sample}, ray {ray} of {rays}"),
        );
    };
    for pixel in [0, 1, 2, 0xffff, 0x10000, 1 << 28, u32::MAX - 1, u32::MAX] {
        for (sample, rays, ray) in [(0, 1, 0), (0, 8, 7), (3, 8, 5), (u32::MAX, 8, 7), (0x2000_0000, 1024, 1023)] {
            add(pixel, sample, rays, ray);
        }
    }
    for _ in 0..300 {
        let word = |rng: &mut Rng| (rng.unit() * 65536.0) as u32 * 65536 + (rng.unit() * 65536.0) as u32;
        let (pixel, sample) = (word(rng), word(rng) % 1024);
        add(pixel, sample, 1 + rng.below(64) as u32, rng.below(64) as u32);
    }
    c
}

/// render_spec::sequence::cosine_direction: normals along the axes (both signs of z, the frame's
/// branch) and random ones, samples at the quarter turns, the disk's centre and rim, and from the
/// sequence.
fn cosine_cases(rng: &mut Rng) -> Cases {
    use render_spec::sequence::{cosine_direction, sample_2d};
    let mut c = Cases::new("cosine_direction", 10);
    let mut add = |n: Vec3, u: [f32; 2]| {
        let d = cosine_direction(n.into(), u);
        c.push(&[v4(n, 0.0), [u[0], u[1], 0.0, 0.0]], [d[0], d[1], d[2], 0.0], [0.0; 4], format!("n {n} u {u:?}"));
    };
    let below_one = 1.0 - 1.0 / (1u32 << 24) as f32;
    let edges = [0.0, 0.125, 0.25, 0.5, 0.75, below_one, 0.2499999, 0.7500001];
    for n in [Vec3::Z, -Vec3::Z, Vec3::X, -Vec3::Y, Vec3::new(0.0, -0.0, 1.0), Vec3::new(-0.0, 0.0, -1.0)] {
        for u0 in edges {
            for u1 in edges {
                add(n, [u0, u1]);
            }
        }
    }
    for k in 0..400 {
        add(unit_vec(rng), sample_2d(k * 7919, k));
    }
    c
}

/// The frame record with the camera's corner and steps and the bounce-stop words set: eye,
/// top_left, h_step and v_step are its first four vec4s, `stop` sits after six vec4s and `size`
/// (FrameData in tracer-vk/src/render.rs, whose layout test pins these offsets against naga).
fn frame_record(camera: &Frame, stop: BounceStop) -> Vec<u8> {
    let mut words = [0u32; 48];
    for (k, v) in [camera.eye, camera.top_left, camera.h_step, camera.v_step].into_iter().enumerate() {
        for (c, x) in v.to_array().into_iter().enumerate() {
            words[4 * k + c] = x.to_bits();
        }
    }
    words[28] = stop.bound.to_bits();
    words[29] = stop.k_max.to_bits();
    words[30] = stop.cutoff.to_bits();
    // One sample at the pixel centre: (0.5, 0.5), 1 / spp = 1, of 1.
    words[36] = 0.5f32.to_bits();
    words[37] = 0.5f32.to_bits();
    words[38] = 1.0f32.to_bits();
    words[41] = 1;
    bytemuck::cast_slice(&words).to_vec()
}

/// Primary directions of every pixel of a small odd-sized image and of a few far apart in a large
/// one.
fn primary_cases(frame: &Frame, width: u32, height: u32) -> Cases {
    let mut c = Cases::new("primary_dir", 8);
    let pixels: Vec<(u32, u32)> = (0..height).flat_map(|y| (0..width).map(move |x| (x, y))).collect();
    for (x, y) in pixels {
        let d = frame.direction(x, y);
        c.push(
            &[[x as f32, y as f32, 0.0, 0.0]],
            v4(d, 0.0),
            [0.0; 4],
            format!("pixel ({x}, {y}) of {width}x{height}"),
        );
    }
    c
}

#[test]
fn every_shared_wgsl_function_equals_its_rust_twin_bit_for_bit() {
    functions_equal_their_rust_twins(false, Intersect::Watertight);
}

/// The same with the `--exact` pass applied (NoContraction on every float operation), and the
/// Möller-Trumbore kernel variant (`--intersect mt`) against tracer-cpu's.
#[test]
fn every_shared_wgsl_function_equals_its_rust_twin_under_exact() {
    functions_equal_their_rust_twins(true, Intersect::Watertight);
    functions_equal_their_rust_twins(true, Intersect::MollerTrumbore);
}

fn functions_equal_their_rust_twins(exact: bool, intersect: Intersect) {
    let gpu = common::gpu();
    let spec =
        Specialisation { stack_size: 1, leaf_size: 1, exact, intersect, ..Specialisation::every_feature(Method::Lst) };
    let source = format!("{}\n{HARNESS}", kernels::prelude(&spec));
    let mut spirv = tracer_vk::translate(&source, "function harness", &[]).expect("the harness compiles");
    if exact {
        spirv = tracer_vk::no_contraction::forbid_contraction(&spirv, "function harness").expect("the pass takes it");
        // As the renderer does (render.rs): subnormals kept where the device can.
        if gpu.info().denorm_preserve_f32 {
            spirv =
                tracer_vk::no_contraction::preserve_denormals(&spirv, "function harness").expect("the pass takes it");
        }
    }
    let pipeline = gpu.pipeline(&spirv, 16, kernels::PASS_BYTES, "function harness").expect("the pipeline builds");

    let mut rng = Rng(0x5eed_f00d);
    let camera =
        CameraSpec { eye: Vec3::new(0.3, 1.7, -4.0), at: Vec3::new(0.1, 0.2, 0.5), up: Vec3::Y, fov_deg: 53.0 };
    let view = camera.frame(37, 23).expect("a valid camera");
    let plain = frame_record(&view, BounceStop { bound: 1.0, k_max: 0.5, cutoff: STOP_CONTRIBUTION });
    let (refl, refr) = reflect_refract_cases(&mut rng);
    let mut failures = Vec::new();
    let mut total = 0;
    let primary = primary_cases(&view, 37, 23);
    for cases in [
        sequence_cases(&mut rng),
        cosine_cases(&mut rng),
        slab_cases(&mut rng),
        intersect_cases(&mut rng, intersect),
        offset_cases(&mut rng),
        refl,
        refr,
        phong_cases(&mut rng),
        primary,
    ] {
        total += cases.len();
        failures.extend(run(&gpu, &pipeline, &cases, &plain, &[]));
    }
    for stop in [
        BounceStop { bound: 1.0, k_max: 0.5, cutoff: STOP_CONTRIBUTION },
        BounceStop { bound: 3.7, k_max: 0.0, cutoff: STOP_CONTRIBUTION },
        BounceStop { bound: 0.2, k_max: 1.0, cutoff: STOP_CONTRIBUTION },
        BounceStop { bound: 1.0, k_max: 0.5, cutoff: 0.0 },
        BounceStop { bound: 0.7, k_max: 0.9, cutoff: 0.05 },
    ] {
        let cases = worth_cases(stop, &mut rng);
        total += cases.len();
        failures.extend(run(&gpu, &pipeline, &cases, &frame_record(&view, stop), &[]));
    }
    let tris: Vec<Triangle> = (0..300)
        .map(|k| {
            let scale = [1e-3, 1.0, 1e5][k % 3];
            let p0 = random_vec(&mut rng, scale);
            // Every tenth a degenerate one (two equal vertices): it faces the ray.
            let p1 = if k % 10 == 0 { p0 } else { p0 + random_vec(&mut rng, scale) };
            Triangle::from_vertices(p0.into(), p1.into(), (p0 + random_vec(&mut rng, scale)).into())
        })
        .collect();
    let cases = surface_cases(&tris, &mut rng);
    total += cases.len();
    failures.extend(run(&gpu, &pipeline, &cases, &plain, &tris));

    assert!(gpu.validation_messages().is_empty(), "validation: {:?}", gpu.validation_messages());
    let flushed = failures.iter().filter(|f| f.starts_with(FLUSHED)).count();
    failures.retain(|f| !f.starts_with(FLUSHED));
    println!(
        "{total} cases (exact: {exact}, {intersect:?}) on {}: {} differ; {flushed} more with subnormal inputs, which this device flushes",
        gpu.info().name,
        failures.len()
    );
    if !exact && gpu.info().kind != DeviceKind::Cpu {
        // Without the --exact pass a GPU's compiler may fuse multiply-adds (NVIDIA's do: the H100
        // differs on 1,892 of these cases), which the Vulkan spec allows; the exact test holds
        // every device to equal bits. CPU implementations (lavapipe) are held to them here too.
        println!("not asserted on a {}: its compiler may contract; see the --exact test", gpu.info().kind);
        return;
    }
    // The count per function, then the first few cases of each.
    let mut by_name: Vec<(&str, Vec<&String>)> = Vec::new();
    for f in &failures {
        let name = f.split(' ').next().unwrap_or("");
        match by_name.iter_mut().find(|(n, _)| *n == name) {
            Some((_, v)) => v.push(f),
            None => by_name.push((name, vec![f])),
        }
    }
    let report: Vec<String> = by_name
        .iter()
        .map(|(n, v)| {
            format!("{n}: {} differ\n{}", v.len(), v.iter().take(40).map(|s| s.as_str()).collect::<Vec<_>>().join("\n"))
        })
        .collect();
    assert!(failures.is_empty(), "{} of {total} cases differ:\n{}", failures.len(), report.join("\n"));
}
