//! Mapping of MTL and glTF materials onto the Whitted material of the file (`kd`, `ks`,
//! `shininess`, and either `kr` or `kt` with `ior`). The rules are documented in
//! `docs/materials.md`; keep the two in step.

use bvh_format::Material;

/// Shininess for a glTF roughness of 0, and the bound for MTL `Ns`.
pub const MAX_SHININESS: f32 = 1000.0;
/// glTF roughness at or below which a fully metallic material becomes a mirror.
pub const MIRROR_ROUGHNESS: f32 = 0.1;
/// glTF metallic factor at or above which a smooth material becomes a mirror.
pub const MIRROR_METALLIC: f32 = 0.99;
/// Index of refraction when a file gives none (glTF's default; typical glass).
pub const DEFAULT_IOR: f32 = 1.5;

fn mean(c: [f32; 3]) -> f32 {
    (c[0] + c[1] + c[2]) / 3.0
}

/// Parses an MTL colour given as one value (grey) or three.
fn parse_colour(s: &str) -> Option<[f32; 3]> {
    let v: Vec<f32> = s.split_whitespace().map(str::parse).collect::<Result<_, _>>().ok()?;
    match v.as_slice() {
        [g] => Some([*g; 3]),
        [r, g, b] => Some([*r, *g, *b]),
        _ => None,
    }
}

/// An MTL material (as tobj reads it) in the Whitted model.
pub fn from_mtl(m: &tobj::Material) -> Material {
    let param = |k: &str| m.unknown_param.get(k).map(String::as_str);
    let illum = m.illumination_model;
    let ks = m.specular.unwrap_or([0.0; 3]);
    let dissolve = m.dissolve.or_else(|| param("Tr").and_then(|s| s.trim().parse::<f32>().ok()).map(|tr| 1.0 - tr));
    let glass_model = matches!(illum, Some(4 | 6 | 7));
    let kt = match dissolve {
        Some(d) if d < 1.0 => 1.0 - d,
        _ if glass_model => param("Tf").and_then(parse_colour).map_or(1.0, mean),
        _ => 0.0,
    };
    let kr = if kt <= 0.0 && matches!(illum, Some(3 | 5)) { mean(ks) } else { 0.0 };
    let ior = m.optical_density.filter(|n| n.is_finite() && *n > 0.0);
    sanitize(Material {
        kd: m.diffuse.unwrap_or(Material::default().kd),
        ks,
        shininess: m.shininess.unwrap_or(Material::default().shininess).min(MAX_SHININESS),
        kr,
        kt,
        ior: ior.unwrap_or(if kt > 0.0 { DEFAULT_IOR } else { 1.0 }),
        ..Material::default()
    })
}

/// The glTF material parameters the mapping reads (textures are ignored).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PbrParams {
    pub base_color: [f32; 4],
    pub metallic: f32,
    pub roughness: f32,
    /// `KHR_materials_transmission` transmission factor.
    pub transmission: Option<f32>,
    /// `KHR_materials_ior`.
    pub ior: Option<f32>,
    /// `KHR_materials_specular`: (specular factor, specular colour factor).
    pub specular: Option<(f32, [f32; 3])>,
}

impl Default for PbrParams {
    /// glTF's defaults for a material that gives nothing.
    fn default() -> Self {
        Self { base_color: [1.0; 4], metallic: 1.0, roughness: 1.0, transmission: None, ior: None, specular: None }
    }
}

impl PbrParams {
    pub fn of(m: &gltf::Material<'_>) -> Self {
        let pbr = m.pbr_metallic_roughness();
        Self {
            base_color: pbr.base_color_factor(),
            metallic: pbr.metallic_factor(),
            roughness: pbr.roughness_factor(),
            transmission: m.transmission().map(|t| t.transmission_factor()),
            ior: m.ior(),
            specular: m.specular().map(|s| (s.specular_factor(), s.specular_color_factor())),
        }
    }
}

/// A glTF metallic-roughness material in the Whitted model.
pub fn from_gltf(p: &PbrParams) -> Material {
    let base = [p.base_color[0], p.base_color[1], p.base_color[2]].map(|c| c.clamp(0.0, 1.0));
    let metallic = p.metallic.clamp(0.0, 1.0);
    let roughness = p.roughness.clamp(0.0, 1.0);
    // KHR_materials_ior allows 0 as "infinite" (a pure reflector); treat it as the default.
    let ior = p.ior.filter(|n| n.is_finite() && *n >= 1.0).unwrap_or(DEFAULT_IOR);
    let f0_ior = ((ior - 1.0) / (ior + 1.0)).powi(2);
    let (spec_factor, spec_colour) = p.specular.unwrap_or((1.0, [1.0; 3]));
    let f0 = spec_colour.map(|c| (f0_ior * c).min(1.0) * spec_factor);
    let mut kd = base.map(|c| c * (1.0 - metallic));
    let ks = [0, 1, 2].map(|i| f0[i] * (1.0 - metallic) + base[i] * metallic);
    // The Blinn-Phong exponent equivalent to a GGX width alpha = roughness^2 is 2/alpha^2 - 2.
    let shininess = (2.0 / roughness.powi(4) - 2.0).clamp(1.0, MAX_SHININESS);
    let kt = p.transmission.unwrap_or(0.0).clamp(0.0, 1.0);
    let mut kr = 0.0;
    if kt > 0.0 {
        kd = kd.map(|c| c * (1.0 - kt));
    } else if metallic >= MIRROR_METALLIC && roughness <= MIRROR_ROUGHNESS {
        kr = mean(base);
    }
    sanitize(Material { kd, ks, shininess, kr, kt, ior, ..Material::default() })
}

/// Forces a material into the ranges the file validator accepts: finite, non-negative colours
/// and shininess, `kr` and `kt` in [0, 1] and not both positive (refraction wins), `ior` > 0.
pub fn sanitize(m: Material) -> Material {
    let d = Material::default();
    let colour =
        |c: [f32; 3], fallback: [f32; 3]| [0, 1, 2].map(|i| if c[i].is_finite() { c[i].max(0.0) } else { fallback[i] });
    let weight = |w: f32| if w.is_finite() { w.clamp(0.0, 1.0) } else { 0.0 };
    let kt = weight(m.kt);
    let kr = if kt > 0.0 { 0.0 } else { weight(m.kr) };
    let ior = if m.ior.is_finite() && m.ior > 0.0 {
        m.ior
    } else if kt > 0.0 {
        DEFAULT_IOR
    } else {
        d.ior
    };
    Material {
        kd: colour(m.kd, d.kd),
        ks: colour(m.ks, d.ks),
        shininess: if m.shininess.is_finite() { m.shininess.max(0.0) } else { d.shininess },
        kr,
        kt,
        ior,
        _pad: [0.0; 2],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mtl(f: impl FnOnce(&mut tobj::Material)) -> Material {
        let mut m = tobj::Material { name: "m".into(), ..Default::default() };
        f(&mut m);
        from_mtl(&m)
    }

    #[test]
    fn mtl_plain_material_keeps_its_colours() {
        let m = mtl(|m| {
            m.diffuse = Some([0.1, 0.2, 0.3]);
            m.specular = Some([0.5; 3]);
            m.shininess = Some(64.0);
            m.illumination_model = Some(2);
        });
        assert_eq!((m.kd, m.ks, m.shininess, m.kr, m.kt), ([0.1, 0.2, 0.3], [0.5; 3], 64.0, 0.0, 0.0));
    }

    #[test]
    fn mtl_missing_values_use_the_defaults() {
        let m = mtl(|_| {});
        assert_eq!(m, Material::default());
    }

    #[test]
    fn mtl_illum_3_is_a_mirror_with_kr_from_ks() {
        let m = mtl(|m| {
            m.specular = Some([0.9, 0.8, 0.7]);
            m.illumination_model = Some(3);
        });
        assert!((m.kr - 0.8).abs() < 1e-6 && m.kt == 0.0);
    }

    #[test]
    fn mtl_dissolve_below_one_is_glass() {
        let m = mtl(|m| {
            m.dissolve = Some(0.25);
            m.optical_density = Some(1.33);
            m.illumination_model = Some(3);
        });
        assert_eq!((m.kt, m.ior, m.kr), (0.75, 1.33, 0.0));
    }

    #[test]
    fn mtl_tr_is_one_minus_dissolve() {
        let m = mtl(|m| {
            m.unknown_param.insert("Tr".into(), "0.4".into());
        });
        assert!((m.kt - 0.4).abs() < 1e-6 && m.ior == DEFAULT_IOR);
    }

    #[test]
    fn mtl_glass_illumination_models_take_kt_from_tf() {
        for illum in [4, 6, 7] {
            let m = mtl(|m| {
                m.illumination_model = Some(illum);
                m.unknown_param.insert("Tf".into(), "0.9 0.6 0.6".into());
            });
            assert!((m.kt - 0.7).abs() < 1e-6, "illum {illum}");
        }
        let m = mtl(|m| m.illumination_model = Some(7));
        assert_eq!((m.kt, m.ior), (1.0, DEFAULT_IOR));
    }

    #[test]
    fn gltf_dielectric_gets_diffuse_base_colour_and_weak_specular() {
        let m = from_gltf(&PbrParams {
            base_color: [0.5, 0.25, 1.0, 1.0],
            metallic: 0.0,
            roughness: 0.5,
            ..Default::default()
        });
        assert_eq!(m.kd, [0.5, 0.25, 1.0]);
        assert!(m.ks.iter().all(|&s| (s - 0.04).abs() < 1e-6));
        assert!((m.shininess - 30.0).abs() < 1e-3);
        assert_eq!((m.kr, m.kt), (0.0, 0.0));
    }

    #[test]
    fn gltf_rough_metal_is_specular_not_a_mirror() {
        let m = from_gltf(&PbrParams { base_color: [0.9, 0.6, 0.2, 1.0], ..Default::default() });
        assert_eq!((m.kd, m.ks, m.shininess, m.kr), ([0.0; 3], [0.9, 0.6, 0.2], 1.0, 0.0));
    }

    #[test]
    fn gltf_smooth_metal_is_a_mirror() {
        let m = from_gltf(&PbrParams { base_color: [0.9, 0.9, 0.6, 1.0], roughness: 0.05, ..Default::default() });
        assert!((m.kr - 0.8).abs() < 1e-6 && m.kt == 0.0);
        assert_eq!(m.shininess, MAX_SHININESS);
    }

    #[test]
    fn gltf_transmission_is_glass_with_ior() {
        let p = PbrParams {
            base_color: [0.3, 0.8, 0.3, 1.0],
            metallic: 0.0,
            roughness: 0.0,
            transmission: Some(0.8),
            ..Default::default()
        };
        let m = from_gltf(&p);
        assert_eq!((m.kt, m.ior, m.kr), (0.8, DEFAULT_IOR, 0.0));
        assert!((m.kd[1] - 0.16).abs() < 1e-6);
        let m = from_gltf(&PbrParams { ior: Some(1.33), ..p });
        assert_eq!(m.ior, 1.33);
        // Transmission wins over the mirror rule.
        let m = from_gltf(&PbrParams { metallic: 1.0, transmission: Some(1.0), ..p });
        assert_eq!((m.kt, m.kr), (1.0, 0.0));
    }

    #[test]
    fn gltf_specular_extension_scales_the_dielectric_highlight() {
        let m = from_gltf(&PbrParams { metallic: 0.0, specular: Some((0.5, [1.0, 0.0, 1.0])), ..Default::default() });
        assert!((m.ks[0] - 0.02).abs() < 1e-6 && m.ks[1] == 0.0);
    }

    #[test]
    fn sanitize_never_returns_both_weights_or_bad_numbers() {
        let m = sanitize(Material {
            kd: [f32::NAN, -1.0, 2.0],
            ks: [f32::INFINITY; 3],
            shininess: -3.0,
            kr: 2.0,
            kt: 0.5,
            ior: 0.0,
            _pad: [0.0; 2],
        });
        assert_eq!(m.kd, [0.8, 0.0, 2.0]);
        assert_eq!(m.ks, [0.0; 3]);
        assert_eq!((m.shininess, m.kr, m.kt, m.ior), (0.0, 0.0, 0.5, DEFAULT_IOR));
    }
}
