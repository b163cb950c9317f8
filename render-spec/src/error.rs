//! The render errors both tracers report: the same mistake gets the same sentence from each.

/// Why an image cannot be rendered, whichever tracer renders it. One sentence each.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RenderError {
    #[error("the image must be at least 1 x 1 pixels")]
    EmptyImage,
    #[error("the camera is degenerate: the eye is on the look-at point or the up vector is parallel to the view")]
    DegenerateCamera,
    #[error("the field of view must lie between 0 and 180 degrees, not {0}")]
    FieldOfView(f32),
    #[error("{0} indirections are more than the {max} a frame may trace", max = crate::settings::MAX_INDIRECTIONS)]
    TooManyIndirections(u32),
    #[error(
        "the {method} traversal needs the {layout} layout, which the scene file does not contain (compile it with `bvhc compile --layout all`)"
    )]
    MissingLayout { method: &'static str, layout: &'static str },
    #[error("{0} samples per pixel are not a square of a whole number from 1 to {max} (1, 4, 9, 16, ...)", max = crate::accuracy::MAX_SPP)]
    SamplesPerPixel(u32),
    #[error("the bounce cutoff must be a finite number of at least 0 (0 traces every bounce), not {0}")]
    Cutoff(f32),
    #[error("a fixed ray offset must be a finite distance of at least 0, not {0}")]
    Offset(f32),
    #[error("{0} ambient-occlusion rays per hit are not a whole number from 1 to {max}", max = crate::settings::MAX_AO_SAMPLES)]
    AoSamples(u32),
    #[error("the ambient-occlusion length must be a finite fraction of the scene's diagonal above 0, not {0}")]
    AoLength(f32),
    #[error("{renderer} does not implement the {mode} mode")]
    ModeUnsupported { renderer: &'static str, mode: &'static str },
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_message_is_one_sentence() {
        for e in [
            RenderError::EmptyImage,
            RenderError::DegenerateCamera,
            RenderError::FieldOfView(180.0),
            RenderError::TooManyIndirections(2000),
            RenderError::MissingLayout { method: "stackless", layout: "escape-pointer" },
            RenderError::SamplesPerPixel(2),
            RenderError::Cutoff(-1.0),
            RenderError::Offset(f32::NAN),
            RenderError::AoSamples(0),
            RenderError::AoLength(-1.0),
            RenderError::ModeUnsupported { renderer: "the exact reference", mode: "ao" },
        ] {
            let s = e.to_string();
            assert!(!s.contains('\n') && !s.ends_with('.') && !s.starts_with(char::is_uppercase), "{s}");
        }
    }
}
