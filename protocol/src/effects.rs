//! What a stream's content does, as far as frame generation is concerned
//! (issue 17): the client builds its generation plan from it and runs only
//! the stages the content calls for, as the renderer builds only the passes
//! a scene's effects call for.
//!
//! A live scene's effects are known from the scene file (`scene`'s
//! `Scene::stream_effects`) and sent in the [`crate::wire::Welcome`]; a
//! dump records them in its manifest (written by `server record`, inferred
//! by the importers where the source says what moves). They hold for the
//! whole stream: a scene is one stream, and so is a dump. Where nothing is
//! known, [`Effects::UNKNOWN`] asks for every stage.

use serde::{Deserialize, Serialize};

/// The content properties that decide which client stages are worth their
/// time. `true` means "may happen": a stage is only skipped on a `false`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct Effects {
    /// Objects move on their own, not only through the camera: some pixel's
    /// motion vector disagrees with depth + camera. Without them every
    /// surface is static and a pixel's position at α is its current one
    /// (camera-only reprojection): no trajectories need tracking.
    pub dynamic_objects: bool,
    /// Shading moves over surfaces: a light moves, or a shadow-casting
    /// light's shadows move with moving objects. Without it, geometry-aware
    /// warping already carries the shading with its surface and shading
    /// correction (GFFE §4.4) has nothing to correct.
    pub moving_shading: bool,
}

impl Effects {
    /// Nothing known: every stage runs.
    pub const UNKNOWN: Effects = Effects {
        dynamic_objects: true,
        moving_shading: true,
    };
    /// A static world under fixed lights: only the camera moves.
    pub const STATIC: Effects = Effects {
        dynamic_objects: false,
        moving_shading: false,
    };

    /// The stages these effects call for, in words (for logs and reports).
    pub fn describe(&self) -> String {
        let mut parts = Vec::new();
        parts.push(if self.dynamic_objects {
            "dynamic objects"
        } else {
            "no dynamic objects"
        });
        parts.push(if self.moving_shading {
            "moving shading"
        } else {
            "no moving shading"
        });
        parts.join(", ")
    }
}

impl Default for Effects {
    fn default() -> Self {
        Self::UNKNOWN
    }
}

impl std::fmt::Display for Effects {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.describe())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unknown_is_every_stage_and_the_default() {
        let unknown = Effects::default();
        assert!(unknown.dynamic_objects && unknown.moving_shading);
        assert_eq!(unknown, Effects::UNKNOWN);
        assert_eq!(
            Effects::STATIC.to_string(),
            "no dynamic objects, no moving shading"
        );
    }
}
