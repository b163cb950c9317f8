//! The numeric constants of the shading contract (docs/shading.md), defined once: the CPU tracer
//! uses them as Rust constants, and the Vulkan kernels get them as a generated WGSL header
//! ([`wgsl_header`]), so that no `.wgsl` file repeats a value.

/// Relative slack of every comparison of a box's distance with a hit's distance: both are rounded
/// (the box's by two operations, the triangle's by more), so a triangle exactly on its box's
/// boundary can come out a few units in the last place nearer than the box. Without the slack a
/// ray through a shared vertex could skip the box of the triangle that should win.
pub const T_SLACK: f32 = 1.0 / (1 << 20) as f32;

/// Origin offset (Wächter and Binder 2019): coordinates smaller than this in magnitude are moved by
/// an absolute step ([`OFFSET_FLOAT_SCALE`]) instead of a number of ulps, because near zero an
/// ulp is too small to leave the surface.
pub const OFFSET_ORIGIN: f32 = 1.0 / 32.0;
/// Origin offset: the absolute step near zero, scaled by the normal's component.
pub const OFFSET_FLOAT_SCALE: f32 = 1.0 / 65536.0;
/// Origin offset: ulps moved per unit of the normal's component (so up to 256 ulps).
pub const OFFSET_INT_SCALE: f32 = 256.0;

/// Adaptive bounce stop: a secondary ray whose whole chain can add less than half an 8-bit step
/// cannot move the rounded pixel by a full step, so it is not traced.
pub const STOP_CONTRIBUTION: f32 = 0.5 / 255.0;
/// Adaptive bounce stop: the chain sum `1 + k + k^2 + ...` ends at a term below this (it can no
/// longer change an f32 sum that starts at 1).
pub const STOP_CHAIN_TERM: f32 = 1e-9;

/// The miss sentinel: the triangle index of a hit record that found nothing, and the `prim` AOV
/// of a pixel whose primary ray hit nothing.
pub const NO_TRIANGLE: u32 = u32::MAX;

/// A flat triangle's normal index (each of the three of [`bvh_format::FLAT`]): the kernels shade it
/// with its geometric normal.
pub const FLAT_NORMAL: u32 = bvh_format::FLAT[0];

/// The largest finite f32: the kernels' "no upper limit" for a ray's distance, and the bound of
/// their finiteness tests.
pub const F32_MAX: f32 = f32::MAX;

/// Steps of the R2 sequence in 0.32 fixed point: `2^32 / phi2` and `2^32 / phi2^2`, rounded, with
/// `phi2` the plastic number (see [`crate::sequence`]).
pub const R2_STEP_X: u32 = 0xC13F_A9A9;
pub const R2_STEP_Y: u32 = 0x91E1_0DA6;

/// Coefficients of the log2 of a mantissa in [sqrt(1/2), sqrt(2)): `log2(1 + t) = t * P(t)` with
/// `P(t) = sum POW_LOG2[k] t^k` (see [`crate::power`]). Fitted values: the leading ones are near
/// log2(e) and ln(2) but not equal to them, so clippy's suggestion of the constants would be wrong.
#[allow(clippy::excessive_precision, clippy::approx_constant)]
pub const POW_LOG2: [f32; 9] =
    [1.442695, -0.72134745, 0.48091075, -0.36069328, 0.28790325, -0.23916988, 0.21607822, -0.20586188, 0.12310968];
/// Coefficients of `2^f = sum POW_EXP2[k] f^k` for `|f| <= 1/2` (see [`crate::power`]).
#[allow(clippy::approx_constant)]
pub const POW_EXP2: [f32; 7] = [1.0, 0.6931472, 0.2402265, 0.05550327, 0.009618057, 0.0013400428, 0.00015461445];

/// Taylor coefficients of `sin(pi/2 x) = x * sum QUARTER_SIN[k] x^(2k)` and
/// `cos(pi/2 x) = sum QUARTER_COS[k] x^(2k)` for `x` in `[0, 1]`, the quarter turn of
/// [`crate::sequence::cosine_direction`]'s azimuth (within 1e-8 before rounding; a driver's `sin` and
/// `cos` are approximations of their own, these are additions and multiplications only).
#[allow(clippy::excessive_precision, clippy::approx_constant)]
pub const QUARTER_SIN: [f32; 7] =
    [1.5707964, -0.6459641, 0.079692625, -0.004681754, 0.00016044118, -3.5988433e-6, 5.6921728e-8];
#[allow(clippy::excessive_precision, clippy::approx_constant)]
pub const QUARTER_COS: [f32; 8] =
    [1.0, -1.2337005, 0.2536695, -0.020863481, 0.00091926026, -2.5202042e-5, 4.7108747e-7, -6.3866032e-9];

/// A constant's value, typed as the kernels declare it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Value {
    F32(f32),
    U32(u32),
}

/// Every constant the kernels share with the Rust side, by the name both use.
pub const SHARED: &[(&str, Value)] = &[
    ("T_SLACK", Value::F32(T_SLACK)),
    ("OFFSET_ORIGIN", Value::F32(OFFSET_ORIGIN)),
    ("OFFSET_FLOAT_SCALE", Value::F32(OFFSET_FLOAT_SCALE)),
    ("OFFSET_INT_SCALE", Value::F32(OFFSET_INT_SCALE)),
    ("STOP_CONTRIBUTION", Value::F32(STOP_CONTRIBUTION)),
    ("STOP_CHAIN_TERM", Value::F32(STOP_CHAIN_TERM)),
    ("NO_TRIANGLE", Value::U32(NO_TRIANGLE)),
    ("FLAT_NORMAL", Value::U32(FLAT_NORMAL)),
    ("F32_MAX", Value::F32(F32_MAX)),
    ("R2_STEP_X", Value::U32(R2_STEP_X)),
    ("R2_STEP_Y", Value::U32(R2_STEP_Y)),
    ("POW_LOG2_0", Value::F32(POW_LOG2[0])),
    ("POW_LOG2_1", Value::F32(POW_LOG2[1])),
    ("POW_LOG2_2", Value::F32(POW_LOG2[2])),
    ("POW_LOG2_3", Value::F32(POW_LOG2[3])),
    ("POW_LOG2_4", Value::F32(POW_LOG2[4])),
    ("POW_LOG2_5", Value::F32(POW_LOG2[5])),
    ("POW_LOG2_6", Value::F32(POW_LOG2[6])),
    ("POW_LOG2_7", Value::F32(POW_LOG2[7])),
    ("POW_LOG2_8", Value::F32(POW_LOG2[8])),
    ("POW_EXP2_0", Value::F32(POW_EXP2[0])),
    ("POW_EXP2_1", Value::F32(POW_EXP2[1])),
    ("POW_EXP2_2", Value::F32(POW_EXP2[2])),
    ("POW_EXP2_3", Value::F32(POW_EXP2[3])),
    ("POW_EXP2_4", Value::F32(POW_EXP2[4])),
    ("POW_EXP2_5", Value::F32(POW_EXP2[5])),
    ("POW_EXP2_6", Value::F32(POW_EXP2[6])),
    ("QUARTER_SIN_0", Value::F32(QUARTER_SIN[0])),
    ("QUARTER_SIN_1", Value::F32(QUARTER_SIN[1])),
    ("QUARTER_SIN_2", Value::F32(QUARTER_SIN[2])),
    ("QUARTER_SIN_3", Value::F32(QUARTER_SIN[3])),
    ("QUARTER_SIN_4", Value::F32(QUARTER_SIN[4])),
    ("QUARTER_SIN_5", Value::F32(QUARTER_SIN[5])),
    ("QUARTER_SIN_6", Value::F32(QUARTER_SIN[6])),
    ("QUARTER_COS_0", Value::F32(QUARTER_COS[0])),
    ("QUARTER_COS_1", Value::F32(QUARTER_COS[1])),
    ("QUARTER_COS_2", Value::F32(QUARTER_COS[2])),
    ("QUARTER_COS_3", Value::F32(QUARTER_COS[3])),
    ("QUARTER_COS_4", Value::F32(QUARTER_COS[4])),
    ("QUARTER_COS_5", Value::F32(QUARTER_COS[5])),
    ("QUARTER_COS_6", Value::F32(QUARTER_COS[6])),
    ("QUARTER_COS_7", Value::F32(QUARTER_COS[7])),
];

/// The WGSL declarations of [`SHARED`], for the kernels to be prepended with.
///
/// An f32 is written as Rust's shortest representation that reads back to the same bits, with
/// WGSL's `f` suffix, so the kernel's constant is exactly the Rust value (a value written as a
/// formula, such as `0.5 / 255.0`, would be evaluated in WGSL's abstract precision and rounded
/// once more).
pub fn wgsl_header() -> String {
    let mut out = String::from("// Generated from render_spec::constants: the shading contract's constants.\n");
    for (name, value) in SHARED {
        let (ty, literal) = match value {
            Value::F32(v) => ("f32", wgsl_f32(*v)),
            Value::U32(v) => ("u32", format!("{v}u")),
        };
        out.push_str(&format!("const {name}: {ty} = {literal};\n"));
    }
    out
}

/// A finite f32 as a WGSL literal that denotes exactly it.
fn wgsl_f32(v: f32) -> String {
    assert!(v.is_finite(), "WGSL has no literal for {v}");
    let s = format!("{v:?}");
    // `{:?}` writes `1e-9` or `256.0`; both are WGSL float literals once suffixed.
    format!("{s}f")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_shared_constant_is_declared_once_with_a_literal_that_reads_back_exactly() {
        let header = wgsl_header();
        for (name, value) in SHARED {
            let prefix = format!("const {name}: ");
            let lines: Vec<&str> = header.lines().filter(|l| l.starts_with(&prefix)).collect();
            assert_eq!(lines.len(), 1, "{name}");
            let literal = lines[0][prefix.len() + 6..].trim_end_matches(';');
            match value {
                Value::F32(v) => {
                    let parsed: f32 = literal.trim_end_matches('f').parse().unwrap();
                    assert_eq!(parsed.to_bits(), v.to_bits(), "{name}: {literal}");
                }
                Value::U32(v) => assert_eq!(literal, format!("{v}u"), "{name}"),
            }
        }
        let names: std::collections::HashSet<&str> = SHARED.iter().map(|(n, _)| *n).collect();
        assert_eq!(names.len(), SHARED.len(), "a name appears twice");
        assert!(header.contains("const T_SLACK: f32 = 9.536743e-7f;"), "{header}");
        assert!(header.contains("const NO_TRIANGLE: u32 = 4294967295u;"), "{header}");
    }
}
