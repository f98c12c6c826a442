//! Proptest strategies for every wire message, shared by the round-trip and
//! robustness tests.
#![allow(dead_code)]

use std::time::Duration;

use glam::{DQuat, DVec3};
use proptest::prelude::*;
use protocol::wire::*;
use protocol::{
    BufferDesc, BufferKind, Camera, Codec, FrameMeta, FrameSize, Pose, Projection, Window,
};

pub fn finite(range: f64) -> impl Strategy<Value = f64> {
    -range..range
}

pub fn pose() -> impl Strategy<Value = Pose> {
    (
        finite(1e7),
        finite(1e7),
        finite(1e7),
        (-1.0f64..1.0, -1.0f64..1.0, -1.0f64..1.0, 0.1f64..1.0),
    )
        .prop_map(|(x, y, z, (a, b, c, d))| {
            Pose::new(
                DVec3::new(x, y, z),
                DQuat::from_xyzw(a, b, c, d).normalize(),
            )
        })
}

pub fn camera() -> impl Strategy<Value = Camera> {
    (
        pose(),
        0.1f64..3.0,
        0.2f64..5.0,
        0.001f64..1.0,
        prop_oneof![Just(f64::INFINITY), 10.0f64..1e6],
        prop_oneof![
            Just(Window::FULL),
            (-3.0f64..-1.0, -3.0f64..-1.0, 1.0f64..3.0, 1.0f64..3.0)
                .prop_map(|(u0, v0, u1, v1)| Window { u0, v0, u1, v1 })
        ],
    )
        .prop_map(|(pose, fov, aspect, near, far, window)| Camera {
            pose,
            projection: Projection::perspective(fov, aspect, near, far),
            window,
        })
}

pub fn size() -> impl Strategy<Value = FrameSize> {
    (1u32..=8192, 1u32..=8192).prop_map(|(w, h)| FrameSize::new(w, h))
}

pub fn kind() -> impl Strategy<Value = BufferKind> {
    prop::sample::select(BufferKind::ALL.to_vec())
}

pub fn codec() -> impl Strategy<Value = Codec> {
    prop_oneof![Just(Codec::Raw), Just(Codec::Zstd)]
}

pub fn window_mode() -> impl Strategy<Value = WindowMode> {
    prop_oneof![
        Just(WindowMode::Off),
        Just(WindowMode::KeepDensity),
        Just(WindowMode::KeepSize)
    ]
}

pub fn text() -> impl Strategy<Value = String> {
    "\\PC{0,40}"
}

pub fn meta() -> impl Strategy<Value = FrameMeta> {
    (
        any::<u64>(),
        0.0f64..1e6,
        camera(),
        size(),
        0u64..10_000_000,
        any::<bool>(),
    )
        .prop_map(|(index, time, camera, size, us, cut)| FrameMeta {
            index,
            time,
            camera,
            size,
            host_processing: Duration::from_micros(us),
            cut,
        })
}

/// The three required buffers plus any subset of extras, with formats and
/// payload lengths consistent with `size`.
pub fn buffers(size: FrameSize) -> impl Strategy<Value = Vec<BufferDesc>> {
    let kinds = prop::sample::subsequence(
        vec![BufferKind::Normal, BufferKind::Albedo, BufferKind::Mask],
        0..=3,
    );
    (
        kinds,
        prop::collection::vec((codec(), 0usize..2, 0.0f64..1.0), 6),
    )
        .prop_map(move |(extras, picks)| {
            BufferKind::REQUIRED
                .into_iter()
                .chain(extras)
                .zip(picks)
                .map(|(kind, (codec, f, frac))| {
                    let formats = kind.allowed_formats();
                    let format = formats[f % formats.len()];
                    let (min, max) = codec.encoded_len_range(format, format.raw_len(size));
                    let max = max.min(protocol::Limits::default().max_payload);
                    let payload_len = min + ((max - min) as f64 * frac) as u64;
                    BufferDesc {
                        kind,
                        format,
                        codec,
                        payload_len,
                    }
                })
                .collect()
        })
}

pub fn stream_buffers() -> impl Strategy<Value = Vec<StreamBuffer>> {
    buffers(FrameSize::new(4, 4)).prop_map(|v| {
        v.into_iter()
            .map(|d| StreamBuffer {
                kind: d.kind,
                format: d.format,
                codec: d.codec,
            })
            .collect()
    })
}

pub fn message() -> impl Strategy<Value = Message> {
    let reason = prop_oneof![
        Just(RejectReason::BadToken),
        any::<u16>().prop_map(|server| RejectReason::UnsupportedVersion { server }),
        Just(RejectReason::Incompatible),
        Just(RejectReason::ServerFull),
        Just(RejectReason::ShuttingDown),
        Just(RejectReason::BadRequest),
        Just(RejectReason::Unavailable),
    ];
    prop_oneof![
        (
            text(),
            text(),
            prop::collection::vec(codec(), 0..4),
            size(),
            prop::collection::vec(window_mode(), 0..3),
            prop::sample::subsequence(
                vec![BufferKind::Normal, BufferKind::Albedo, BufferKind::Mask],
                0..=3
            ),
        )
            .prop_map(
                |(client_name, token, codecs, max_size, window_modes, extras)| {
                    Message::Hello(Hello {
                        version: WIRE_VERSION,
                        client_name,
                        token,
                        codecs,
                        max_size,
                        window_modes,
                        extras,
                    })
                }
            ),
        (
            any::<u64>(),
            text(),
            size(),
            1.0f64..240.0,
            stream_buffers(),
            window_mode(),
            (0u32..=64, 0u32..=64),
            (any::<bool>(), any::<bool>())
        )
            .prop_map(
                |(session_id, server_name, size, fps, buffers, window_mode, grow, effects)| {
                    // The largest frame: the size, widened within the limits.
                    let max_frame = FrameSize::new(
                        (size.width + grow.0).min(8192),
                        (size.height + grow.1).min(8192),
                    );
                    Message::Welcome(Welcome {
                        session_id,
                        server_name,
                        size,
                        fps,
                        buffers,
                        window_mode,
                        max_frame,
                        effects: protocol::Effects {
                            dynamic_objects: effects.0,
                            moving_shading: effects.1,
                        },
                    })
                }
            ),
        (reason, text()).prop_map(|(reason, message)| Message::Reject(Reject { reason, message })),
        meta()
            .prop_flat_map(|meta| (Just(meta), buffers(meta.size), any::<Option<(u64, u64)>>()))
            .prop_map(|(meta, buffers, input)| Message::FrameHeader(FrameHeader {
                meta,
                buffers,
                input: input.map(|(seq, client_time_us)| InputEcho {
                    seq,
                    client_time_us
                }),
            })),
        (
            any::<u64>(),
            kind(),
            prop::collection::vec(any::<u8>(), 0..2048)
        )
            .prop_map(|(frame_index, kind, data)| Message::Payload(BufferPayload {
                frame_index,
                kind,
                data
            })),
        any::<[u64; 5]>().prop_map(|v| Message::ClientStats(ClientStats {
            frames_received: v[0],
            frames_late: v[1],
            frames_dropped: v[2],
            bytes_received: v[3],
            rtt_us: v[4],
        })),
        any::<[u64; 3]>().prop_map(|v| Message::ServerStats(ServerStats {
            frames_sent: v[0],
            frames_dropped: v[1],
            bytes_sent: v[2],
        })),
        (
            any::<u64>(),
            any::<u64>(),
            prop::option::of(pose()),
            any::<u32>(),
            prop::array::uniform4(-1.0f32..=1.0)
        )
            .prop_map(|(seq, client_time_us, camera, buttons, axes)| {
                Message::Input(Input {
                    seq,
                    client_time_us,
                    camera,
                    buttons,
                    axes,
                })
            }),
        (any::<u64>(), any::<u64>())
            .prop_map(|(seq, sent_us)| Message::Ping(Ping { seq, sent_us })),
        (any::<u64>(), any::<u64>())
            .prop_map(|(seq, sent_us)| Message::Pong(Pong { seq, sent_us })),
        text().prop_map(|reason| Message::Bye(Bye { reason })),
        any::<Option<u64>>()
            .prop_map(|last_decoded| Message::KeyframeRequest(KeyframeRequest { last_decoded })),
    ]
}

/// A deterministic valid message of every kind, as mutation seeds.
pub fn seed_messages() -> Vec<Message> {
    use proptest::strategy::ValueTree;
    use proptest::test_runner::{Config, TestRunner};
    let mut runner = TestRunner::new_with_rng(
        Config::default(),
        proptest::test_runner::TestRng::deterministic_rng(
            proptest::test_runner::RngAlgorithm::ChaCha,
        ),
    );
    (0..64)
        .map(|_| message().new_tree(&mut runner).expect("strategy").current())
        .collect()
}
