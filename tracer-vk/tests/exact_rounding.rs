//! The correctly rounded division and square root of `--exact` kernels (`div_rn`, `sqrt_rn` in
//! common.wgsl): a Rust model of the WGSL, operation for operation, is held to Rust's `/` and `sqrt` (IEEE 754) on every special class, every
//! significand and tens of millions of random operands, with the device's own division and sqrt
//! (which only seed the routines) off by up to 3 ulp either way or good to 12 bits only, and its
//! fma fused or not. The model's `mul_wide` is also held to u64 products. Then the
//! WGSL itself runs on the Vulkan device and must equal the same operators bit for bit.

use tests::Rng;
use tracer_vk::{Gpu, kernels, no_contraction};

/// How the device's own operations may be off: its division and sqrt `k` ulps from the correctly
/// rounded result or good to their top 12 significand bits only; its fma fused or two roundings
/// (Vulkan allows both).
#[derive(Clone, Copy, Debug)]
enum Seed {
    Ulps(i32),
    Bits12,
    Unfused(i32),
}

const SEEDS: [Seed; 12] = [
    Seed::Ulps(-3),
    Seed::Ulps(-2),
    Seed::Ulps(-1),
    Seed::Ulps(0),
    Seed::Ulps(1),
    Seed::Ulps(2),
    Seed::Ulps(3),
    Seed::Bits12,
    Seed::Unfused(-3),
    Seed::Unfused(0),
    Seed::Unfused(2),
    Seed::Unfused(3),
];

impl Seed {
    /// `exact` (positive, normal) as the device might return it.
    fn apply(self, exact: f32) -> f32 {
        match self {
            Seed::Ulps(k) | Seed::Unfused(k) => f32::from_bits(exact.to_bits().wrapping_add_signed(k)),
            Seed::Bits12 => f32::from_bits(exact.to_bits() & !0x7ff),
        }
    }

    fn fma(self, a: f32, b: f32, c: f32) -> f32 {
        match self {
            Seed::Unfused(_) => a * b + c,
            _ => a.mul_add(b, c),
        }
    }
}

// ---- The model: common.wgsl's EXACT block, line for line. ----

fn split(magnitude: u32) -> (f32, i32) {
    let field = magnitude & 0x7f_ffff;
    let biased = magnitude >> 23;
    if biased != 0 {
        return (f32::from_bits(field | 0x3f80_0000), biased as i32 - 127);
    }
    let top = 31 - field.leading_zeros();
    (f32::from_bits(((field << (23 - top)) & 0x7f_ffff) | 0x3f80_0000), top as i32 - 149)
}

fn significand(m: f32) -> u32 {
    (m.to_bits() & 0x7f_ffff) | 0x80_0000
}

/// (high word, low word), as the WGSL computes it in 32-bit words.
fn mul_wide(a: u32, b: u32) -> (u32, u32) {
    let a0 = a & 0xffff;
    let b0 = b & 0xffff;
    let low = a0 * b0;
    let mid = (a >> 16) * b0 + a0 * (b >> 16);
    let lo = low.wrapping_add(mid << 16);
    ((a >> 16) * (b >> 16) + (mid >> 16) + (lo < low) as u32, lo)
}

fn shl_wide(x: u32, k: u32) -> (u32, u32) {
    (x >> (32 - k), x << k)
}

fn wide_less(a: (u32, u32), b: (u32, u32)) -> bool {
    a.0 < b.0 || (a.0 == b.0 && a.1 < b.1)
}

fn div_rn(a: f32, b: f32, seed: Seed) -> f32 {
    let sign = (a.to_bits() ^ b.to_bits()) & 0x8000_0000;
    let ma = a.to_bits() & 0x7fff_ffff;
    let mb = b.to_bits() & 0x7fff_ffff;
    let inf = 0x7f80_0000;
    if ma > inf || mb > inf || (ma == inf && mb == inf) || (ma == 0 && mb == 0) {
        return a / b;
    }
    if ma == inf || mb == 0 {
        return f32::from_bits(sign | inf);
    }
    if ma == 0 || mb == inf {
        return f32::from_bits(sign);
    }
    let (xm, xe) = split(ma);
    let (ym, ye) = split(mb);
    let big_x = significand(xm);
    let big_y = significand(ym);
    let k = if big_x >= big_y { 23 } else { 24 };
    let mut r = seed.apply(1.0 / ym);
    r = seed.fma(seed.fma(-ym, r, 1.0), r, r);
    let mut q = xm * r;
    q = seed.fma(seed.fma(-q, ym, xm), r, q);
    let mut n = (q * f32::from_bits((127 + k) << 23)) as u32;
    let scaled = shl_wide(big_x, k + 1);
    for _ in 0..2 {
        if wide_less(mul_wide(2 * n + 1, big_y), scaled) {
            n += 1;
        }
        if wide_less(scaled, mul_wide(2 * n - 1, big_y)) {
            n -= 1;
        }
    }
    let exact = shl_wide(big_x, k);
    let product = mul_wide(n, big_y);
    let above = wide_less(product, exact);
    let below = wide_less(exact, product);
    let mut e = xe - ye + 23 - k as i32;
    if n == 0x100_0000 {
        n = 0x80_0000;
        e += 1;
    }
    if e > 127 {
        return f32::from_bits(sign | inf);
    }
    if e >= -126 {
        return f32::from_bits(sign | (((e + 127) as u32) << 23) | (n & 0x7f_ffff));
    }
    let s = (-126 - e).min(25) as u32;
    let kept = n >> s;
    let dropped = n & ((1 << s) - 1);
    let half = 1 << (s - 1);
    let up = dropped > half || (dropped == half && (above || (!below && kept & 1 == 1)));
    f32::from_bits(sign | (kept + up as u32))
}

fn sqrt_rn(x: f32, seed: Seed) -> f32 {
    let bits = x.to_bits();
    if bits == 0 || bits == 0x8000_0000 || bits == 0x7f80_0000 {
        return x;
    }
    if bits > 0x7f80_0000 {
        return x.sqrt();
    }
    let (vm, ve) = split(bits);
    let odd = ve & 1 != 0;
    let m = if odd { 2.0 * vm } else { vm };
    let e = if odd { ve - 1 } else { ve };
    let w = significand(vm) << odd as u32;
    let mut s = seed.apply(m.sqrt());
    s = seed.fma(seed.fma(-s, s, m), seed.apply(0.5 / s), s);
    let mut n = (s * 8_388_608.0) as u32;
    let scaled = shl_wide(w, 25);
    for _ in 0..2 {
        if wide_less(mul_wide(2 * n + 1, 2 * n + 1), scaled) {
            n += 1;
        }
        if wide_less(scaled, mul_wide(2 * n - 1, 2 * n - 1)) {
            n -= 1;
        }
    }
    f32::from_bits((n as f32 * f32::from_bits(0x3400_0000)).to_bits().wrapping_add(((e / 2) as u32) << 23))
}

// ---- Checks ----

fn same(a: f32, b: f32) -> bool {
    a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())
}

fn check_div(a: f32, b: f32, seed: Seed) {
    let got = div_rn(a, b, seed);
    let want = a / b;
    assert!(
        same(got, want),
        "{a:e} / {b:e} ({:#x} / {:#x}), seed {seed:?}: {got:e}, IEEE {want:e}",
        a.to_bits(),
        b.to_bits()
    );
}

fn check_sqrt(x: f32, seed: Seed) {
    let got = sqrt_rn(x, seed);
    let want = x.sqrt();
    assert!(same(got, want), "sqrt({x:e}) ({:#x}), seed {seed:?}: {got:e}, IEEE {want:e}", x.to_bits());
}

/// One of every class an operand can be in, with both signs: zeros, subnormals (the least, the
/// greatest, one between), the least normal, ordinary numbers, significands of all ones, the
/// greatest finite, infinity and NaN.
fn special_values() -> Vec<f32> {
    let magnitudes = [
        0u32,
        1,
        2,
        3,
        0x0000_1234,
        0x0040_0000,
        0x007f_ffff,
        0x0080_0000,
        0x0080_0001,
        0x00ff_ffff,
        0x0d00_0000,
        0x3f00_0000,
        0x3f7f_ffff,
        0x3f80_0000,
        0x3f80_0001,
        0x3fff_ffff,
        0x4040_0000,
        0x3dcc_cccd,
        0x4b00_0001,
        0x7e80_0000,
        0x7f00_0000,
        0x7f7f_fffe,
        0x7f7f_ffff,
        0x7f80_0000,
        0x7fc0_0000,
        0x7f80_0001,
    ];
    magnitudes.iter().flat_map(|&m| [f32::from_bits(m), f32::from_bits(m | 0x8000_0000)]).collect()
}

/// A random operand: random bits (every exponent, NaN and infinity included) half the time,
/// else a number near `near` in magnitude (exponent within +-3), so that quotients of two of them
/// are mostly normal.
fn random_operand(rng: &mut Rng, near: i32) -> f32 {
    let bits = rng.next_u64() as u32;
    if bits & 1 == 0 {
        return f32::from_bits(bits);
    }
    let exponent = (near + 127 + (rng.below(7) as i32 - 3)).clamp(0, 254) as u32;
    f32::from_bits((bits & 0x807f_ffff) | (exponent << 23))
}

#[test]
fn wide_products_are_exact() {
    let mut rng = Rng(0x31de);
    let edges = [0u32, 1, 0xffff, 0x1_0000, 0x7f_ffff, 0x80_0000, 0xff_ffff, 0x100_0000, 0x1ff_ffff, 0x3ff_ffff];
    let pairs = edges.iter().flat_map(|&a| edges.iter().map(move |&b| (a, b)));
    let random = (0..1_000_000).map(|_| (rng.next_u64() as u32 >> 6, rng.next_u64() as u32 >> 6));
    for (a, b) in pairs.chain(random.collect::<Vec<_>>()) {
        let (hi, lo) = mul_wide(a, b);
        assert_eq!(((hi as u64) << 32) | lo as u64, a as u64 * b as u64, "{a} * {b}");
    }
    assert_eq!(shl_wide(0xff_ffff, 25), ((0xff_ffffu64 << 25 >> 32) as u32, (0xff_ffffu64 << 25) as u32));
}

#[test]
fn division_equals_ieee_on_every_pair_of_special_classes() {
    let values = special_values();
    for &a in &values {
        for &b in &values {
            for seed in SEEDS {
                check_div(a, b, seed);
            }
        }
    }
}

#[test]
fn division_equals_ieee_on_random_operands() {
    let mut rng = Rng(0x00d1_e50f_f00d);
    // Exponents around 0, at the ends of the range (overflow, subnormal quotients) and between.
    for near in [0, 0, 60, -60, 120, -120, -140] {
        for _ in 0..2_000_000 {
            let a = random_operand(&mut rng, near);
            let b = random_operand(&mut rng, if near < -100 { 10 } else { 0 });
            check_div(a, b, SEEDS[rng.below(SEEDS.len())]);
        }
    }
}

/// The rounding depends on the significands only (the exponents are put back exactly or rounded
/// with integers): every divisor significand, each with a random dividend and a seed in turn,
/// and again with the quotient subnormal.
#[test]
fn division_equals_ieee_for_every_divisor_significand() {
    let mut rng = Rng(0x5eed_d1f0);
    for field in 0..1u32 << 23 {
        let b = f32::from_bits(0x3f80_0000 | field);
        let a = f32::from_bits(0x3f80_0000 | (rng.next_u64() as u32 & 0x7f_ffff));
        check_div(a, b, SEEDS[field as usize % SEEDS.len()]);
        let tiny = f32::from_bits((rng.below(0x0180_0000) as u32) | (rng.next_u64() as u32 & 0x8000_0000));
        check_div(tiny, b * 8.0, SEEDS[(field as usize + 3) % SEEDS.len()]);
    }
}

/// Every significand in [1, 4) (the two exponent parities: the square root of any normal number
/// is one of these scaled exactly by a power of two), every subnormal, with every seed.
#[test]
fn sqrt_equals_ieee_on_every_significand_and_every_subnormal() {
    for bits in 0x3f80_0000u32..0x4080_0000 {
        for seed in SEEDS {
            check_sqrt(f32::from_bits(bits), seed);
        }
    }
    for bits in 0..0x0080_0000u32 {
        check_sqrt(f32::from_bits(bits), SEEDS[bits as usize % SEEDS.len()]);
    }
    for x in special_values() {
        for seed in SEEDS {
            check_sqrt(x, seed);
        }
    }
    let mut rng = Rng(0x5a_4e);
    for _ in 0..4_000_000 {
        check_sqrt(f32::from_bits(rng.next_u64() as u32), SEEDS[rng.below(SEEDS.len())]);
    }
}

/// The WGSL on the Vulkan device (lavapipe here), as an --exact kernel gets it: the pass's
/// NoContraction, DenormPreserve where the device has it.
#[test]
fn the_wgsl_equals_ieee_on_the_device() {
    const N: usize = 1 << 20;
    let gpu = Gpu::new(None, true).unwrap_or_else(|e| panic!("this test needs a Vulkan device: {e}"));
    let src = format!(
        "{}\n@group(0) @binding(0) var<storage, read_write> v: array<vec4<u32>>;\n\
         @compute @workgroup_size(64) fn main(@builtin(global_invocation_id) id: vec3<u32>) {{\n\
         let a = bitcast<f32>(v[id.x].x);\n let b = bitcast<f32>(v[id.x].y);\n\
         v[id.x].z = bitcast<u32>(div_rn(a, b));\n v[id.x].w = bitcast<u32>(sqrt_rn(a));\n}}\n",
        kernels::exact_rounding_wgsl()
    );
    let label = "exact rounding";
    let mut words = tracer_vk::translate(&src, label, &[]).expect("the WGSL translates");
    words = no_contraction::forbid_contraction(&words, label).expect("the pass takes it");
    if gpu.info().denorm_preserve_f32 {
        words = no_contraction::preserve_denormals(&words, label).expect("the pass takes it");
    }
    let pipeline = gpu.pipeline(&words, 1, kernels::PASS_BYTES, label).expect("the pipeline is made");

    let mut rng = Rng(0x6e0_d1ce);
    let specials = special_values();
    let mut input: Vec<[u32; 4]> = Vec::with_capacity(N);
    for &a in &specials {
        for &b in &specials {
            input.push([a.to_bits(), b.to_bits(), 0, 0]);
        }
    }
    while input.len() < N {
        let near = [0, 0, 100, -100, -140][rng.below(5)];
        let a = random_operand(&mut rng, near);
        let b = random_operand(&mut rng, if near < -100 { 10 } else { 0 });
        input.push([a.to_bits(), b.to_bits(), 0, 0]);
    }
    let buf = gpu.create_buffer_with(&input, label).expect("the buffer is made");
    gpu.run(|rec| rec.dispatch(&pipeline, &[&buf], &[0; kernels::PASS_BYTES as usize], [(N / 64) as u32, 1, 1]))
        .expect("the dispatch runs");
    let out: Vec<[u32; 4]> = gpu.download_as(&buf).expect("the buffer downloads");
    // A device without shaderDenormPreserveFloat32 (the H100) may read a subnormal input as a
    // zero of its sign before the routine sees it: there the result must be IEEE's for the
    // flushed input (counted apart).
    let flushes = !gpu.info().denorm_preserve_f32;
    let ftz = |x: f32| if x.is_subnormal() { 0.0f32.copysign(x) } else { x };
    let (mut div_wrong, mut sqrt_wrong, mut flushed, mut first) = (0, 0, 0, None);
    for (o, i) in out.iter().zip(&input) {
        let (a, b) = (f32::from_bits(i[0]), f32::from_bits(i[1]));
        let (q, r) = (f32::from_bits(o[2]), f32::from_bits(o[3]));
        if same(q, a / b) {
        } else if flushes && same(q, ftz(a) / ftz(b)) {
            flushed += 1;
        } else {
            div_wrong += 1;
            first.get_or_insert(format!("{a:e} / {b:e} = {q:e}, IEEE {:e}", a / b));
        }
        if same(r, a.sqrt()) {
        } else if flushes && same(r, ftz(a).sqrt()) {
            flushed += 1;
        } else {
            sqrt_wrong += 1;
            first.get_or_insert(format!("sqrt({a:e}) = {r:e}, IEEE {:e}", a.sqrt()));
        }
    }
    println!(
        "{} (denormals preserved: {}): div_rn differs from IEEE on {div_wrong} of {N}, sqrt_rn on {sqrt_wrong}; \
         {flushed} results are IEEE's for subnormal inputs read as zero",
        gpu.info().name,
        gpu.info().denorm_preserve_f32
    );
    assert!(div_wrong == 0 && sqrt_wrong == 0, "{div_wrong} quotients and {sqrt_wrong} roots differ, first {first:?}");
    assert!(gpu.validation_messages().is_empty(), "{:#?}", gpu.validation_messages());
}
