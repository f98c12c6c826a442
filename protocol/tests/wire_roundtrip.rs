//! Every wire message survives encode → decode unchanged, whole or fed to the
//! streaming decoder in arbitrary pieces; invalid values are refused with
//! typed errors.

mod common;

use proptest::prelude::*;
use protocol::wire::*;
use protocol::{Limits, ValidationError};

proptest! {
    #![proptest_config(ProptestConfig { cases: 512, ..ProptestConfig::default() })]

    #[test]
    fn every_message_round_trips(msg in common::message()) {
        let limits = Limits::default();
        prop_assert!(msg.validate(&limits).is_ok(), "strategy made an invalid message: {msg:?}");
        let bytes = encode(&msg).unwrap();
        let (back, used) = decode_message(&bytes, &limits).unwrap();
        prop_assert_eq!(used, bytes.len());
        prop_assert_eq!(&back, &msg);
        // Any strict prefix is incomplete, never an error or a panic.
        for cut in [0, 1, HEADER_LEN - 1, HEADER_LEN, bytes.len() - 1] {
            if cut < bytes.len() {
                let incomplete = matches!(decode_message(&bytes[..cut], &limits), Err(WireError::Incomplete { .. }));
                prop_assert!(incomplete);
            }
        }
    }

    #[test]
    fn streams_of_messages_decode_in_any_chunking(
        msgs in prop::collection::vec(common::message(), 1..8),
        chunk in 1usize..300,
    ) {
        let mut bytes = Vec::new();
        for m in &msgs {
            encode_into(m, &mut bytes).unwrap();
        }
        let mut decoder = Decoder::new(Limits::default());
        let mut out = Vec::new();
        for piece in bytes.chunks(chunk) {
            decoder.feed(piece);
            while let Some(m) = decoder.next_message().unwrap() {
                out.push(m);
            }
        }
        prop_assert!(decoder.is_at_boundary());
        prop_assert_eq!(out, msgs);
    }
}

#[test]
fn payload_prefix_matches_the_full_encoding() {
    let msg = BufferPayload {
        frame_index: 99,
        kind: protocol::BufferKind::Depth,
        data: (0..=255).collect(),
    };
    let full = encode(&Message::Payload(msg.clone())).unwrap();
    let mut split = payload_prefix(99, protocol::BufferKind::Depth, msg.data.len()).unwrap();
    split.extend_from_slice(&msg.data);
    assert_eq!(full, split);
}

fn header_with(f: impl FnOnce(&mut FrameHeader)) -> Vec<u8> {
    let mut msg = common::seed_messages()
        .into_iter()
        .find_map(|m| match m {
            Message::FrameHeader(h) => Some(h),
            _ => None,
        })
        .expect("a frame header seed");
    f(&mut msg);
    encode(&Message::FrameHeader(msg)).unwrap()
}

fn invalid_reason(bytes: &[u8]) -> ValidationError {
    match decode_message(bytes, &Limits::default()) {
        Err(WireError::Invalid { source, .. }) => source,
        other => panic!("expected an Invalid error, got {other:?}"),
    }
}

#[test]
fn non_finite_camera_values_are_refused_with_a_clear_error() {
    let e = invalid_reason(&header_with(|h| h.meta.camera.pose.position.y = f64::NAN));
    assert_eq!(e, ValidationError::NonFinite("camera position"));
    assert_eq!(e.to_string(), "camera position is not finite");
    let e = invalid_reason(&header_with(|h| {
        h.meta.camera.pose.rotation.w = f64::INFINITY
    }));
    assert_eq!(e, ValidationError::NonFinite("camera rotation"));
    let e = invalid_reason(&header_with(|h| h.meta.camera.projection.fov_y = f64::NAN));
    assert_eq!(e, ValidationError::NonFinite("projection"));
    let e = invalid_reason(&header_with(|h| {
        h.meta.camera.window.u0 = f64::NEG_INFINITY
    }));
    assert_eq!(e, ValidationError::NonFinite("window"));
    let e = invalid_reason(&header_with(|h| h.meta.time = f64::NAN));
    assert_eq!(e, ValidationError::NonFinite("frame time"));
    let input = Message::Input(Input {
        seq: 1,
        client_time_us: 2,
        camera: None,
        buttons: 0,
        axes: [0.0, f32::NAN, 0.0, 0.0],
    });
    assert_eq!(
        invalid_reason(&encode(&input).unwrap()),
        ValidationError::NonFinite("input axes")
    );
}

#[test]
fn header_limits_and_consistency_are_enforced() {
    let e = invalid_reason(&header_with(|h| h.meta.size.width = 8193));
    assert!(matches!(e, ValidationError::BadSize { width: 8193, .. }));
    let e = invalid_reason(&header_with(|h| h.buffers[0].payload_len += 1_000_000_000));
    assert!(matches!(e, ValidationError::PayloadLength { .. }), "{e}");
    let e = invalid_reason(&header_with(|h| {
        let d = h.buffers[1];
        h.buffers.push(d);
    }));
    assert!(
        matches!(
            e,
            ValidationError::DuplicateBuffer(_) | ValidationError::TooMany { .. }
        ),
        "{e}"
    );
    let e = invalid_reason(&header_with(|h| {
        h.buffers.retain(|b| b.kind != protocol::BufferKind::Motion)
    }));
    assert_eq!(
        e,
        ValidationError::MissingBuffer(protocol::BufferKind::Motion)
    );
    let e = invalid_reason(&header_with(|h| {
        h.buffers[1].format = protocol::PixelFormat::Rgba16Float
    }));
    assert!(matches!(e, ValidationError::FormatNotAllowed { .. }));
}

#[test]
fn header_fields_are_checked_before_the_body_is_buffered() {
    let limits = Limits::default();
    let mut bytes = encode(&Message::Ping(Ping { seq: 1, sent_us: 2 })).unwrap();
    // Version.
    let other = WIRE_VERSION + 1;
    bytes[4..6].copy_from_slice(&other.to_le_bytes());
    assert!(matches!(
        decode_message(&bytes[..HEADER_LEN], &limits),
        Err(WireError::UnsupportedVersion { got, supported: WIRE_VERSION }) if got == other
    ));
    bytes[4..6].copy_from_slice(&WIRE_VERSION.to_le_bytes());
    // Kind.
    bytes[6] = 200;
    assert!(matches!(
        decode_message(&bytes[..HEADER_LEN], &limits),
        Err(WireError::UnknownKind(200))
    ));
    bytes[6] = MessageKind::Ping as u8;
    // A control message claiming 4 GiB is refused from the header alone.
    bytes[..4].copy_from_slice(&u32::MAX.to_le_bytes());
    assert!(matches!(
        decode_message(&bytes[..HEADER_LEN], &limits),
        Err(WireError::TooLong {
            kind: MessageKind::Ping,
            ..
        })
    ));
    let mut d = Decoder::new(limits);
    d.feed(&bytes[..HEADER_LEN]);
    assert!(matches!(d.next_message(), Err(WireError::TooLong { .. })));
    assert!(matches!(d.next_message(), Err(WireError::Poisoned)));
    // A tighter payload limit applies to payload messages.
    let tight = Limits {
        max_payload: 10,
        ..limits
    };
    let payload = encode(&Message::Payload(BufferPayload {
        frame_index: 0,
        kind: protocol::BufferKind::Color,
        data: vec![0; 100],
    }))
    .unwrap();
    assert!(matches!(
        decode_message(&payload[..HEADER_LEN], &tight),
        Err(WireError::TooLong {
            kind: MessageKind::Payload,
            ..
        })
    ));
}

#[test]
fn trailing_bytes_inside_a_body_are_refused() {
    let mut bytes = encode(&Message::Pong(Pong { seq: 5, sent_us: 6 })).unwrap();
    bytes.push(0);
    let len = (bytes.len() - HEADER_LEN) as u32;
    bytes[..4].copy_from_slice(&len.to_le_bytes());
    assert!(matches!(
        decode_message(&bytes, &Limits::default()),
        Err(WireError::TrailingBytes { extra: 1, .. })
    ));
}

#[test]
fn a_failed_decoder_stays_failed_and_buffers_nothing_more() {
    let mut d = Decoder::new(Limits::default());
    d.feed(&[0xff; 16]);
    assert!(d.next_message().is_err());
    assert!(d.has_failed());
    assert!(!d.is_at_boundary(), "a failed stream is not a clean end");
    d.feed(&encode(&Message::Ping(Ping { seq: 1, sent_us: 1 })).unwrap());
    assert_eq!(d.buffered(), 0, "bytes after the failure are not kept");
    assert!(matches!(d.next_message(), Err(WireError::Poisoned)));
}

/// A decoder that expects certain kinds refuses any other from its 8-byte
/// header, before a byte of its body is buffered, and the control limits
/// refuse a control message above a few KiB (issue 18 §1).
#[test]
fn unexpected_kinds_are_refused_from_the_header() -> Result<(), WireError> {
    let bye = encode(&Message::Bye(Bye {
        reason: "done".into(),
    }))?;
    let mut d = Decoder::accepting(Limits::control(), &[MessageKind::Hello]);
    d.feed(&bye[..HEADER_LEN]);
    match d.next_message() {
        Err(WireError::UnexpectedKind { got, expected }) => {
            assert_eq!(got, MessageKind::Bye);
            assert_eq!(expected, &[MessageKind::Hello]);
        }
        other => panic!("expected UnexpectedKind, got {other:?}"),
    }
    assert_eq!(d.buffered(), 0);
    // Expected kinds pass; the set can change between messages.
    let mut d = Decoder::accepting(Limits::control(), &[MessageKind::Bye]);
    d.feed(&bye);
    d.feed(&bye);
    assert!(matches!(d.next_message()?, Some(Message::Bye(_))));
    d.accept_only(&[MessageKind::ClientStats]);
    assert!(matches!(
        d.next_message(),
        Err(WireError::UnexpectedKind {
            got: MessageKind::Bye,
            ..
        })
    ));
    // A Bye of 5 KiB is too long for a control stream.
    let long = encode(&Message::Bye(Bye {
        reason: "x".repeat(5 * 1024),
    }))?;
    let mut d = Decoder::new(Limits::control());
    d.feed(&long[..HEADER_LEN]);
    assert!(matches!(d.next_message(), Err(WireError::TooLong { .. })));
    Ok(())
}

/// The limits of a negotiated stream (issue 18 §5): a header for a frame
/// larger in either side or in area than the welcome's largest frame, or a
/// payload larger than such a frame's largest buffer, is refused from the
/// bytes that announce it.
#[test]
fn limits_for_the_agreed_frames_are_tight() -> Result<(), WireError> {
    let max = protocol::FrameSize::new(160, 90);
    let limits = Limits::for_frames(max);
    assert_eq!(limits.max_dimension, 160);
    assert!(limits.check_size(160, 90).is_ok());
    assert!(matches!(
        limits.check_size(161, 1),
        Err(ValidationError::BadSize { .. })
    ));
    assert!(matches!(
        limits.check_size(150, 100),
        Err(ValidationError::TooManyPixels { max: 14_400, .. })
    ));
    // One raw buffer of the largest frame at 8 bytes a pixel fits a payload.
    assert!(limits.max_payload >= 160 * 90 * 8 && limits.max_payload < 160 * 90 * 9);
    assert_eq!(Limits::default().min(limits), limits);

    let header = header_with(|h| h.meta.size = protocol::FrameSize::new(100, 200));
    assert!(matches!(
        decode_message(&header, &limits),
        Err(WireError::Invalid { .. })
    ));
    // A payload message announcing more than that is refused from its header.
    let payload = encode(&Message::Payload(BufferPayload {
        frame_index: 0,
        kind: protocol::BufferKind::Color,
        data: vec![0; limits.max_payload as usize + 64],
    }))?;
    assert!(matches!(
        decode_message(&payload[..HEADER_LEN], &limits),
        Err(WireError::TooLong { .. })
    ));
    Ok(())
}

/// A welcome whose largest frame is smaller than its size is refused.
#[test]
fn a_welcome_largest_frame_covers_its_size() -> Result<(), WireError> {
    let welcome = |max_frame| {
        encode(&Message::Welcome(Welcome {
            session_id: 1,
            server_name: "s".into(),
            size: protocol::FrameSize::new(64, 32),
            fps: 30.0,
            buffers: StreamBuffer::default_set(protocol::Codec::Raw).to_vec(),
            window_mode: WindowMode::KeepDensity,
            max_frame,
            effects: protocol::Effects::UNKNOWN,
        }))
    };
    let ok = welcome(protocol::FrameSize::new(80, 40))?;
    assert!(decode_message(&ok, &Limits::default()).is_ok());
    let e = invalid_reason(&welcome(protocol::FrameSize::new(80, 31))?);
    assert!(matches!(e, ValidationError::OutOfRange(_)), "{e}");
    Ok(())
}

/// Window modes are named as on the command line and in reports, and parse
/// back; anything else is a typed error.
#[test]
fn window_modes_parse_from_their_names() -> Result<(), UnknownWindowMode> {
    for mode in WindowMode::ALL {
        assert_eq!(mode.name().parse::<WindowMode>()?, mode);
    }
    assert_eq!(
        "keep-density".parse::<WindowMode>()?,
        WindowMode::KeepDensity
    );
    let err = "wide".parse::<WindowMode>().err().map(|e| e.to_string());
    assert_eq!(
        err.as_deref(),
        Some("expected off, keep-density or keep-size, not \"wide\"")
    );
    Ok(())
}

#[test]
fn a_long_reject_message_is_cut_to_a_valid_one_at_a_character_boundary() {
    // 'é' is two bytes: a cut at MAX_TEXT would split one.
    let long = format!("x{}", "é".repeat(MAX_TEXT));
    let r = Reject::new(RejectReason::Unavailable, long.clone());
    assert_eq!(r.message.len(), MAX_TEXT - 1);
    assert!(long.starts_with(&r.message));
    let msg = Message::Reject(r);
    assert!(msg.validate(&Limits::default()).is_ok());
    let (back, _) = decode_message(&encode(&msg).unwrap(), &Limits::default()).unwrap();
    assert_eq!(back, msg);
    let short = Reject::new(RejectReason::BadToken, "no");
    assert_eq!(short.message, "no");
}
