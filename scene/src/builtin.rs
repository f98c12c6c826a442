//! The scenes shipped in `scene/scenes/`, embedded in the binary so
//! `builtin:NAME` works from anywhere. Each file starts with a comment that
//! says which challenge it stresses.

/// `(name, RON source)` of every built-in scene.
pub const SCENES: &[(&str, &str)] = &[
    ("default", include_str!("../scenes/default.ron")),
    ("pan", include_str!("../scenes/pan.ron")),
    ("dolly", include_str!("../scenes/dolly.ron")),
    ("crossing", include_str!("../scenes/crossing.ron")),
    ("moving_light", include_str!("../scenes/moving_light.ron")),
    ("sky", include_str!("../scenes/sky.ron")),
    ("thin", include_str!("../scenes/thin.ron")),
    ("fast_rotation", include_str!("../scenes/fast_rotation.ron")),
    ("translucent", include_str!("../scenes/translucent.ron")),
    ("cut", include_str!("../scenes/cut.ron")),
    ("huge", include_str!("../scenes/huge.ron")),
    ("sun_sweep", include_str!("../scenes/sun_sweep.ron")),
    (
        "spinning_shadow",
        include_str!("../scenes/spinning_shadow.ron"),
    ),
];

/// `(name, glTF JSON)` of the assets built-in scenes use, as
/// `Gltf(path: "builtin:NAME")`. Buffers are embedded as data URIs.
pub const ASSETS: &[(&str, &str)] = &[(
    "pyramid.gltf",
    include_str!("../scenes/assets/pyramid.gltf"),
)];

/// The bytes of a built-in asset.
pub fn asset(name: &str) -> Option<&'static [u8]> {
    ASSETS
        .iter()
        .find(|(n, _)| *n == name)
        .map(|(_, s)| s.as_bytes())
}

/// The RON source of a built-in scene.
pub fn source(name: &str) -> Option<&'static str> {
    SCENES.iter().find(|(n, _)| *n == name).map(|(_, s)| *s)
}

/// Names of all built-in scenes.
pub fn names() -> impl Iterator<Item = &'static str> {
    SCENES.iter().map(|(n, _)| *n)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Scene;

    #[test]
    fn every_builtin_scene_parses_and_validates() {
        for (name, src) in SCENES {
            let s = Scene::from_ron(src, name).unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(&s.name, name);
            assert!(!s.description.is_empty(), "{name} says what it stresses");
            let st = s.evaluate(1.25);
            assert_eq!(st.models.len(), s.instances().len());
            assert!(st.eye.is_finite() && st.target.is_finite());
        }
    }

    /// The effects a stream of each built-in scene announces: dynamic
    /// where an object is animated, moving shading where a light moves or a
    /// dynamic object casts a shadow.
    #[test]
    fn builtin_stream_effects() {
        let effects = |name: &str| {
            Scene::load(&format!("builtin:{name}"))
                .unwrap_or_else(|e| panic!("{e}"))
                .stream_effects()
        };
        let e = |dynamic_objects, moving_shading| protocol::Effects {
            dynamic_objects,
            moving_shading,
        };
        assert_eq!(effects("dolly"), protocol::Effects::STATIC);
        assert_eq!(effects("fast_rotation"), protocol::Effects::STATIC);
        assert_eq!(effects("moving_light"), e(false, true));
        assert_eq!(effects("sun_sweep"), e(false, true));
        assert_eq!(effects("spinning_shadow"), e(true, true));
        assert_eq!(effects("crossing"), e(true, true));
        // Moving, but casting no shadow (no `shadows` effect).
        assert_eq!(effects("translucent"), e(true, false));
    }
}
