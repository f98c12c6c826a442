//! The settings `eval` compares: every knob of [`framegen::Settings`] that
//! trades time for accuracy (issue 8, DESIGN §9), one axis at a time
//! around the defaults.

use framegen::{Method, Resample, Settings};
use protocol::FrameSize;
use protocol::wire::WindowMode;
use serde::Serialize;
use video::ColorCodec;

/// What a variant changes relative to its method's defaults.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Axis {
    /// A method at its defaults (the baseline of every other axis).
    Method,
    /// GFFE history length k (Alg. 1).
    History,
    /// GFFE background levels L (§4.2).
    Levels,
    /// Push-pull pyramid depth of the hole fill.
    Pyramid,
    /// The static-test threshold ε (Alg. 1).
    Epsilon,
    /// The warp's colour filter (sub-pixel resampling).
    Resample,
    /// Shading correction (GFFE §4.4).
    Shading,
    /// The stages the stream's effects call for (issue 17): every stage
    /// against the plan.
    Plan,
    /// The adaptive rendering window (GFFE §4.3, DESIGN §4.5).
    Window,
    /// Generated frames per rendered frame.
    N,
    /// Rendered (and displayed) resolution.
    Resolution,
    /// The stream's colour codec and bitrate (issue 19 §5): gffe and
    /// interp fed through each further setting of `--color-codec`.
    Codec,
}

impl Axis {
    /// Heading in the report.
    pub fn title(self) -> &'static str {
        match self {
            Axis::Method => "methods at their defaults",
            Axis::History => "history length k (gffe)",
            Axis::Levels => "background levels L (gffe)",
            Axis::Pyramid => "push-pull pyramid depth",
            Axis::Epsilon => "static threshold ε (gffe)",
            Axis::Resample => "colour filter (gffe, reproject, interp)",
            Axis::Shading => "shading correction (gffe, GFFE §4.4)",
            Axis::Plan => "stages planned from the stream's effects (gffe)",
            Axis::Window => "adaptive window",
            Axis::N => "generated frames per rendered frame n",
            Axis::Resolution => "resolution",
            Axis::Codec => "colour codec and bitrate (gffe, interp)",
        }
    }
}

/// The label of the oracle-motion row.
pub const ORACLE: &str = "gffe oracle-motion";

/// The label of gffe given the skipped frame's true camera.
pub const GIVEN_CAMERA: &str = "gffe given-camera";

/// The label of gffe without shading correction (the geometry-aware
/// result GFFE eq. 3's focus region is defined from).
pub const NO_SHADING: &str = "gffe no-shading";

/// The label of gffe without shading correction given the exact shading
/// change (the shading-oracle reference, [`framegen::oracle::shade`]).
pub const SHADING_ORACLE: &str = "gffe oracle-shading";

/// The label of gffe running every stage, whatever the stream's effects.
pub const EVERY_STAGE: &str = "gffe every-stage";

/// Which variants to run.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Sweep {
    /// The four methods at their defaults.
    Methods,
    /// Every axis (history, levels, pyramid, ε, colour filter, window, n)
    /// around the defaults.
    Full,
}

/// One configuration to measure.
#[derive(Clone, Debug, PartialEq)]
pub struct Variant {
    /// Short unique name, e.g. `gffe k=4`.
    pub label: String,
    /// What it varies.
    pub axis: Axis,
    /// The generator's settings.
    pub settings: Settings,
    /// The adaptive window the frames are rendered with.
    pub window: WindowMode,
    /// The displayed size.
    pub size: FrameSize,
    /// Not a generator: the oracle-motion reference
    /// ([`framegen::oracle`]), the skipped frame's true geometry applied to
    /// the rendered frame with `settings`' filter and pyramid. Untimed
    /// (it is not realisable), so on no Pareto front.
    pub oracle: bool,
    /// Generates with the skipped frame's own camera instead of GFFE eq. 2's
    /// extrapolation (`CameraSource::Given`): what an interactive stream's
    /// late input gives (the viewer's newest pose is the displayed camera,
    /// issue 20), and what eq. 2's guess of the camera costs. It needs
    /// input, so it is on no Pareto front.
    pub given_camera: bool,
    /// gffe without shading correction, its output given the exact change
    /// of shading from the fed frame to the displayed one (the truth over
    /// the truth rendered with the fed frame's lights and shadows,
    /// [`framegen::oracle::shade`]): what a perfect shading correction
    /// (GFFE §4.4) would reach, the rest being the warp's error. Needs the
    /// renderer (scenes only); on no Pareto front.
    pub shading_oracle: bool,
    /// Runs every stage: the stream's effects are not applied
    /// ([`for_stream`]).
    pub every_stage: bool,
    /// How the fed frames' colour travels ([`with_codecs`]).
    pub color: ColorCodec,
}

impl Variant {
    fn new(axis: Axis, label: String, settings: Settings, size: FrameSize) -> Self {
        Self {
            label,
            axis,
            settings,
            window: WindowMode::Off,
            size,
            oracle: false,
            given_camera: false,
            shading_oracle: false,
            every_stage: false,
            color: ColorCodec::Raw,
        }
    }

    /// Frames the renderer makes per generated-frame group: n + 1.
    pub fn step(&self) -> usize {
        self.settings.n as usize + 1
    }

    /// Render intervals of latency the method adds (interpolation holds
    /// one frame back, DESIGN §6).
    pub fn added_latency_frames(&self) -> u32 {
        self.settings.method.descriptor().held_back
    }
}

/// The adaptive window a method's frames are rendered with at its
/// defaults, as `server serve` renders a scene: keep-density for the
/// extrapolators (GFFE §4.3: an extrapolated frame's border shows what the
/// previous frame's view did not), off for the rest and for dumps
/// (whatever they were recorded with). Evidence (`client eval --all-scenes
/// --sweep full --only gffe,interp --backends cpu`, 320×180, margins to the
/// pixel): gffe's mean ꟻLIP 0.0309 plain against 0.0292 keep-density, no
/// scene worse by more than 0.0001, fast_rotation 0.0524 → 0.0324.
/// Keep-size costs detail: 0.0326. (`client run`'s in-process server
/// renders plain by default: it shares the client's cores.)
pub fn default_window(method: Method, rendered: bool) -> WindowMode {
    let extrapolates = matches!(method, Method::Gffe | Method::Reproject);
    if rendered && extrapolates {
        WindowMode::KeepDensity
    } else {
        WindowMode::Off
    }
}

/// Gives every variant but the window axis's and the oracle its method's
/// [`default_window`].
fn with_default_windows(variants: &mut [Variant], rendered: bool) {
    for v in variants
        .iter_mut()
        .filter(|v| v.axis != Axis::Window && !v.oracle)
    {
        v.window = default_window(v.settings.method, rendered);
    }
}

/// Gives every variant but the every-stage one the stream's `effects`, so
/// that it runs the stages its content calls for
/// ([`framegen::pipeline::plan::Plan`]).
pub fn for_stream(variants: &mut [Variant], effects: framegen::Effects) {
    for v in variants.iter_mut().filter(|v| !v.every_stage) {
        v.settings.effects = effects;
    }
}

/// The variants of one scene at `size`; `windows` is false for dumps (their
/// window is whatever they were rendered with, and no renderer gives the
/// shading oracle its frames).
pub fn sweep(kind: Sweep, size: FrameSize, windows: bool) -> Vec<Variant> {
    let at = |m| Settings::for_method(m);
    let mut out: Vec<Variant> = Method::ALL
        .into_iter()
        .map(|m| Variant::new(Axis::Method, m.name().into(), at(m), size))
        .collect();
    // Beside gffe: the same with the skipped frame's true geometry (one row
    // serves both extrapolators: with true geometry, gffe and reproject
    // make the same frame).
    let gffe_at = out.iter().position(|v| v.settings.method == Method::Gffe);
    let oracle = Variant {
        oracle: true,
        ..Variant::new(Axis::Method, ORACLE.into(), at(Method::Gffe), size)
    };
    // Then gffe with the true camera and its own estimated geometry.
    let given = Variant {
        given_camera: true,
        ..Variant::new(Axis::Method, GIVEN_CAMERA.into(), at(Method::Gffe), size)
    };
    let after = gffe_at.map_or(out.len(), |i| i + 1);
    out.splice(after..after, [oracle, given]);
    let plain = Settings {
        shading: false,
        ..at(Method::Gffe)
    };
    out.push(Variant::new(Axis::Shading, NO_SHADING.into(), plain, size));
    // Its bound: the exact shading change, where a renderer can give it.
    if windows {
        out.push(Variant {
            shading_oracle: true,
            ..Variant::new(Axis::Shading, SHADING_ORACLE.into(), plain, size)
        });
    }
    out.push(Variant {
        every_stage: true,
        ..Variant::new(Axis::Plan, EVERY_STAGE.into(), at(Method::Gffe), size)
    });
    if kind == Sweep::Methods {
        with_default_windows(&mut out, windows);
        return out;
    }
    let gffe = at(Method::Gffe);
    for k in [3, 4, 8] {
        let s = Settings { history: k, ..gffe };
        out.push(Variant::new(Axis::History, format!("gffe k={k}"), s, size));
    }
    for l in [0, 1, 3] {
        let s = Settings {
            background_levels: l,
            ..gffe
        };
        out.push(Variant::new(Axis::Levels, format!("gffe L={l}"), s, size));
    }
    for method in [Method::Gffe, Method::Interp] {
        for levels in [1, 3, 5] {
            let s = Settings {
                pushpull_levels: levels,
                ..at(method)
            };
            let label = format!("{method} pyramid={levels}");
            out.push(Variant::new(Axis::Pyramid, label, s, size));
        }
    }
    for eps in [0.25, 2.0] {
        let s = Settings {
            static_epsilon: eps,
            ..gffe
        };
        out.push(Variant::new(
            Axis::Epsilon,
            format!("gffe ε={eps}"),
            s,
            size,
        ));
    }
    for method in [Method::Reproject, Method::Gffe, Method::Interp] {
        for filter in Resample::ALL {
            if filter == at(method).resample {
                continue;
            }
            let s = Settings {
                resample: filter,
                ..at(method)
            };
            let label = format!("{method} filter={filter}");
            out.push(Variant::new(Axis::Resample, label, s, size));
        }
    }
    if windows {
        // Interpolation works on the rendered grid and ignores the window;
        // the extrapolators' rows around their default (keep-density).
        for method in [Method::Reproject, Method::Gffe] {
            for mode in [WindowMode::Off, WindowMode::KeepSize] {
                let settings = Settings {
                    display_size: (mode == WindowMode::KeepSize)
                        .then_some((size.width, size.height)),
                    ..at(method)
                };
                let mut v = Variant::new(
                    Axis::Window,
                    format!("{method} window={}", mode.name()),
                    settings,
                    size,
                );
                v.window = mode;
                out.push(v);
            }
        }
    }
    for n in [2, 3] {
        for method in Method::ALL {
            let s = Settings { n, ..at(method) };
            out.push(Variant::new(Axis::N, format!("{method} n={n}"), s, size));
        }
    }
    with_default_windows(&mut out, windows);
    out
}

/// The methods [`with_codecs`] feeds through each further colour setting:
/// the extrapolator and the interpolator the issue measures (19 §5).
pub const CODEC_METHODS: [Method; 2] = [Method::Gffe, Method::Interp];

/// Feeds every variant colour through `codecs[0]` (raw if empty) and adds
/// [`CODEC_METHODS`] at their defaults at `size` through each further
/// setting, labelled `gffe h264@8`: one axis around the defaults, as the
/// other knobs are swept; `rendered` as for [`sweep`].
pub fn with_codecs(
    variants: &mut Vec<Variant>,
    codecs: &[ColorCodec],
    size: FrameSize,
    rendered: bool,
) {
    let first = codecs.first().copied().unwrap_or(ColorCodec::Raw);
    for v in variants.iter_mut() {
        v.color = first;
    }
    let mut seen = vec![first];
    for &codec in codecs.iter().skip(1) {
        if seen.contains(&codec) {
            continue;
        }
        seen.push(codec);
        for m in CODEC_METHODS {
            variants.push(Variant {
                color: codec,
                window: default_window(m, rendered),
                ..Variant::new(
                    Axis::Codec,
                    format!("{m} {codec}"),
                    Settings::for_method(m),
                    size,
                )
            });
        }
    }
}

/// The methods at their defaults at each extra resolution (of a scene).
pub fn resolutions(sizes: &[FrameSize]) -> Vec<Variant> {
    sizes
        .iter()
        .flat_map(|&size| {
            Method::ALL.into_iter().map(move |m| Variant {
                window: default_window(m, true),
                ..Variant::new(
                    Axis::Resolution,
                    format!("{m} {}p", size.height),
                    Settings::for_method(m),
                    size,
                )
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn labels_are_unique_and_settings_valid() {
        let size = FrameSize::new(64, 36);
        let mut all = sweep(Sweep::Full, size, true);
        all.extend(resolutions(&[FrameSize::new(96, 54)]));
        let mut labels: Vec<&str> = all.iter().map(|v| v.label.as_str()).collect();
        labels.sort_unstable();
        let before = labels.len();
        labels.dedup();
        assert_eq!(labels.len(), before);
        for v in &all {
            v.settings.validate().unwrap();
        }
        // The four methods, the oracle beside gffe, gffe without shading
        // correction, gffe with every stage.
        let mut methods = sweep(Sweep::Methods, size, true);
        let labels: Vec<&str> = methods.iter().map(|v| v.label.as_str()).collect();
        assert_eq!(
            labels,
            [
                "repeat",
                "reproject",
                "gffe",
                ORACLE,
                GIVEN_CAMERA,
                "interp",
                NO_SHADING,
                SHADING_ORACLE,
                EVERY_STAGE
            ]
        );
        assert!(
            methods
                .iter()
                .all(|v| v.settings.shading == (v.label != NO_SHADING && !v.shading_oracle))
        );
        // The stream's effects reach all but the every-stage row.
        for_stream(&mut methods, framegen::Effects::STATIC);
        for v in &methods {
            let expected = if v.every_stage {
                framegen::Effects::UNKNOWN
            } else {
                framegen::Effects::STATIC
            };
            assert_eq!(v.settings.effects, expected, "{}", v.label);
        }
        assert_eq!(methods.iter().filter(|v| v.every_stage).count(), 1);
        assert_eq!(methods.iter().filter(|v| v.oracle).count(), 1);
        assert_eq!(methods.iter().filter(|v| v.given_camera).count(), 1);
        assert_eq!(methods.iter().filter(|v| v.shading_oracle).count(), 1);
        // A dump has neither window rows nor a renderer for the oracle.
        assert!(
            !sweep(Sweep::Full, size, false)
                .iter()
                .any(|v| v.axis == Axis::Window || v.shading_oracle)
        );
    }

    #[test]
    fn further_colour_settings_add_gffe_and_interp_rows() {
        let size = FrameSize::new(64, 36);
        let codecs: Vec<ColorCodec> = ["raw", "h264@4", "h264@16", "h264@4"]
            .iter()
            .map(|c| c.parse().unwrap())
            .collect();
        let mut all = sweep(Sweep::Methods, size, true);
        let before = all.len();
        with_codecs(&mut all, &codecs, size, true);
        // Every swept variant on the first setting; the repeated one once.
        assert!(all[..before].iter().all(|v| v.color == ColorCodec::Raw));
        let added: Vec<(&str, ColorCodec)> = all[before..]
            .iter()
            .map(|v| (v.label.as_str(), v.color))
            .collect();
        assert_eq!(
            added,
            [
                ("gffe h264@4", codecs[1]),
                ("interp h264@4", codecs[1]),
                ("gffe h264@16", codecs[2]),
                ("interp h264@16", codecs[2]),
            ]
        );
        for v in &all[before..] {
            assert_eq!(v.axis, Axis::Codec);
            assert_eq!(v.settings, Settings::for_method(v.settings.method));
        }
    }
}
