//! The adaptive bounce stop (docs/shading.md, "Adaptive stop"): a secondary ray is traced only
//! while it can still change an 8-bit pixel.

use crate::constants::{STOP_CHAIN_TERM, STOP_CONTRIBUTION};
use bvh_format::{Light, SceneFile};

/// The scene's bound behind the stop, for one set of lights.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BounceStop {
    /// The most radiance one Whitted hit can add before weighting: `max over materials and
    /// channels of Ia kd + (sum of light colours) (kd + ks)`, and the background.
    pub bound: f32,
    /// The largest `kr` or `kt` of the scene.
    pub k_max: f32,
    /// The least a chain must be able to add to be traced ([`crate::Accuracy::cutoff`]); 0 traces
    /// every bounce.
    pub cutoff: f32,
}

impl BounceStop {
    /// The stop for `scene` lit by `lights`, at the default cutoff of half an 8-bit step
    /// ([`Self::with_cutoff`] sets another).
    pub fn new(scene: &SceneFile, lights: &[Light]) -> Self {
        let sum: [f32; 3] =
            lights.iter().fold([0.0; 3], |a, l| [a[0] + l.colour[0], a[1] + l.colour[1], a[2] + l.colour[2]]);
        let amb = scene.settings.ambient;
        let per_material =
            scene.materials.iter().flat_map(|m| (0..3).map(move |k| amb[k] * m.kd[k] + sum[k] * (m.kd[k] + m.ks[k])));
        let bound = per_material.fold(scene.settings.background.iter().copied().fold(0.0, f32::max), f32::max);
        let k_max = scene.materials.iter().map(|m| m.kr.max(m.kt)).fold(0.0, f32::max);
        Self { bound, k_max, cutoff: STOP_CONTRIBUTION }
    }

    /// This stop with another cutoff ([`crate::Accuracy::cutoff`]).
    pub fn with_cutoff(self, cutoff: f32) -> Self {
        Self { cutoff, ..self }
    }

    /// Whether a secondary ray of weight `w`, with `remaining` indirections left after it (itself
    /// included), can still add the cutoff (by default: change an 8-bit pixel): the most the chain
    /// can add is `w * bound * (1 + k + k^2 + ... )` over `remaining` terms, with `k` the largest
    /// kr or kt. A cutoff of 0 passes every ray with an indirection left.
    pub fn worth_tracing(&self, w: f32, remaining: u32) -> bool {
        remaining > 0 && w * self.bound * self.chain(remaining) >= self.cutoff
    }

    /// The sum `1 + k + k^2 + ...` of [`Self::worth_tracing`] over `remaining` terms, stopping once
    /// the terms are negligible. Public for tracers that test many weights at one depth at once.
    pub fn chain(&self, remaining: u32) -> f32 {
        let mut chain = 0.0f32;
        let mut f = 1.0f32;
        for _ in 0..remaining {
            chain += f;
            f *= self.k_max;
            if f < STOP_CHAIN_TERM {
                break;
            }
        }
        chain
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_bounce_stop_is_exact_at_half_a_step() {
        let stop = |bound, k_max| BounceStop { bound, k_max, cutoff: STOP_CONTRIBUTION };
        assert!(stop(1.0, 0.5).worth_tracing(1.0, 1));
        assert!(!stop(1.0, 0.0).worth_tracing(0.5 / 255.0 * 0.99, 1));
        assert!(stop(1.0, 0.5).worth_tracing(0.5 / 255.0 * 0.99, 2), "a longer chain adds more");
        assert!(!stop(1.0, 1.0).worth_tracing(0.1, 0), "no indirection left");
        assert!(stop(1.0, 0.0).worth_tracing(STOP_CONTRIBUTION, 1), "exactly half a step is traced");
        let never = stop(1.0, 0.0).with_cutoff(0.0);
        assert!(never.worth_tracing(0.0, 1) && never.worth_tracing(1e-30, 1), "a cutoff of 0 traces everything");
        assert!(!never.worth_tracing(1.0, 0), "but not beyond the indirections");
        assert!(!stop(1.0, 0.0).with_cutoff(0.1).worth_tracing(0.099, 1), "a higher cutoff stops earlier");
    }

    #[test]
    fn the_bound_covers_every_material_and_the_background() {
        let mut scene = SceneFile {
            build: Default::default(),
            settings: Default::default(),
            origin: [0.0; 3],
            scale_log2: 0,
            vertices: vec![],
            triangles: vec![],
            normals: vec![],
            normal_indices: vec![],
            materials: vec![
                bvh_format::Material { kd: [0.5, 0.1, 0.1], ks: [0.25; 3], kr: 0.3, ..Default::default() },
                bvh_format::Material { kd: [0.1; 3], kt: 0.6, ..Default::default() },
            ],
            material_names: vec![],
            input_index: vec![],
            child_pair: None,
            escape: None,
            wide: None,
            cameras: vec![],
            lights: vec![],
        };
        scene.settings.ambient = [0.1; 3];
        scene.settings.background = [0.0; 3];
        let lights = [Light::new([0.0; 3], [1.0, 0.5, 0.5]), Light::new([1.0; 3], [1.0, 0.5, 0.5])];
        let s = BounceStop::new(&scene, &lights);
        // Red channel of the first material: 0.1 * 0.5 + 2 * (0.5 + 0.25).
        assert_eq!(s.bound, 0.1 * 0.5 + 2.0 * (0.5 + 0.25));
        assert_eq!(s.k_max, 0.6);
        scene.settings.background = [9.0, 0.0, 0.0];
        assert_eq!(BounceStop::new(&scene, &lights).bound, 9.0);
    }
}
