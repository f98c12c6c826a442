//! The codec round trip on a moving synthetic picture: quality in display
//! space, one packet per frame, keyframes, size changes and bad payloads.

use half::f16;

use super::*;

/// A textured picture sliding right by `t` pixels, with HDR highlights.
fn picture(width: u32, height: u32, t: u32) -> Vec<[f16; 4]> {
    (0..width * height)
        .map(|i| {
            let (x, y) = (((i % width) + 1000 - t) as f32, (i / width) as f32);
            let v = |f: f32, p: f32| {
                let s = (x * f + p).sin() * (y * 0.07 + p).cos();
                f16::from_f32(0.5 * (1.0 + s) * if (x as u32 / 16) % 5 == 0 { 6.0 } else { 1.0 })
            };
            [v(0.05, 0.0), v(0.03, 1.0), v(0.09, 2.0), f16::ONE]
        })
        .collect()
}

use crate::transfer::display_psnr as psnr;

fn settings(chroma: Chroma, mbit: f64) -> VideoSettings {
    VideoSettings {
        bitrate: (mbit * 1e6) as u64,
        chroma,
    }
}

#[test]
fn settings_parse_and_print() {
    let s: VideoSettings = "h264@12".parse().unwrap();
    assert_eq!(s, settings(Chroma::Yuv420, 12.0));
    assert_eq!(s.to_string(), "h264@12");
    let s: VideoSettings = "h264-444@2.5".parse().unwrap();
    assert_eq!((s.bitrate, s.chroma), (2_500_000, Chroma::Yuv444));
    assert_eq!("raw".parse::<ColorCodec>().unwrap(), ColorCodec::Raw);
    for name in ["raw", "zstd", "h264", "h264-444", "h264@12", "h264-444@0.5"] {
        assert_eq!(name.parse::<ColorCodec>().unwrap().to_string(), name);
    }
    // The automatic rate: 0.6 bits a pixel a frame.
    let auto = ColorCodec::DEFAULT_LIVE
        .settings(protocol::FrameSize::new(1280, 720), 30.0)
        .unwrap();
    assert_eq!((auto.bitrate, auto.chroma), (16_588_800, Chroma::Yuv420));
    assert_eq!(
        ColorCodec::Zstd.settings(protocol::FrameSize::new(64, 64), 30.0),
        None
    );
    assert!("h264@0".parse::<ColorCodec>().is_err());
    for bad in ["h264", "h265@3", "h264@", "h264@-1", "h264@nan", "h264@1e9"] {
        assert!(bad.parse::<VideoSettings>().is_err(), "{bad}");
    }
}

/// Every frame gives one packet at once; the first is a keyframe and the
/// rest are not; the decoded pictures are close to the sent ones in display
/// space; the stream's size stays near its bitrate.
#[test]
fn a_moving_picture_round_trips_one_frame_at_a_time() {
    let (w, h) = (160, 90);
    for chroma in [Chroma::Yuv420, Chroma::Yuv444] {
        let mbit = 1.0;
        let mut enc = ColorEncoder::new(settings(chroma, mbit), 30.0).unwrap();
        let mut dec = ColorDecoder::new().unwrap();
        let mut out = Vec::new();
        let mut bytes = 0usize;
        let frames = 30;
        for t in 0..frames {
            let color = picture(w, h, t * 2);
            let payload = enc.encode(w, h, &color).unwrap();
            assert_eq!(payload[0] & FLAG_KEYFRAME != 0, t == 0, "frame {t}");
            assert_eq!(payload[0] & FLAG_YUV444 != 0, chroma == Chroma::Yuv444);
            bytes += payload.len();
            dec.decode(&payload, w, h, &mut out).unwrap();
            assert_eq!(out.len(), color.len());
            assert!(out.iter().all(|p| p.iter().all(|c| c.is_finite())));
            let q = psnr(&color, &out);
            assert!(q > 30.0, "{chroma:?} frame {t}: {q:.1} dB");
        }
        let rate = bytes as f64 * 8.0 * 30.0 / f64::from(frames) / 1e6;
        assert!(rate < mbit * 1.5, "{chroma:?}: {rate:.2} Mbit/s for {mbit}");
    }
}

/// A requested keyframe is one; an odd size, then a new size, restart the
/// stream with a keyframe and decode at the frame's size.
#[test]
fn keyframes_on_request_and_on_a_new_size() {
    let mut enc = ColorEncoder::new(settings(Chroma::Yuv420, 0.5), 30.0).unwrap();
    let mut dec = ColorDecoder::new().unwrap();
    let mut out = Vec::new();
    let mut keys = Vec::new();
    for (t, (w, h)) in [(64, 36), (64, 36), (64, 36), (65, 37), (65, 37)]
        .into_iter()
        .enumerate()
    {
        if t == 2 {
            enc.request_keyframe();
        }
        let payload = enc.encode(w, h, &picture(w, h, t as u32)).unwrap();
        keys.push(payload[0] & FLAG_KEYFRAME != 0);
        dec.decode(&payload, w, h, &mut out).unwrap();
        assert_eq!(out.len(), (w * h) as usize);
    }
    assert_eq!(keys, [true, false, true, true, false]);
}

/// Damaged payloads are typed errors, never panics; after one, the decoder
/// waits for a keyframe, and recovers on it.
#[test]
fn bad_payloads_are_errors_and_the_stream_recovers_on_a_keyframe() {
    let (w, h) = (96, 54);
    let mut enc = ColorEncoder::new(settings(Chroma::Yuv420, 0.5), 30.0).unwrap();
    let mut dec = ColorDecoder::new().unwrap();
    let mut out = Vec::new();
    let first = enc.encode(w, h, &picture(w, h, 0)).unwrap();
    let second = enc.encode(w, h, &picture(w, h, 1)).unwrap();
    // A P-frame before any keyframe.
    assert!(matches!(
        dec.decode(&second, w, h, &mut out),
        Err(VideoError::AwaitingKeyframe)
    ));
    assert!(matches!(
        dec.decode(&[], w, h, &mut out),
        Err(VideoError::BadPayload(_))
    ));
    assert!(matches!(
        dec.decode(&[0x80, 0, 0, 1], w, h, &mut out),
        Err(VideoError::BadPayload(_))
    ));
    let mut nan_peak = first.clone();
    nan_peak[5..7].copy_from_slice(&f16::NAN.to_le_bytes());
    assert!(matches!(
        dec.decode(&nan_peak, w, h, &mut out),
        Err(VideoError::BadPayload(_))
    ));
    // The wrong size for the stream: a larger frame is a mismatch; a
    // smaller one is refused before the decoder allocates the picture.
    assert!(matches!(
        dec.decode(&first, w + 2, h, &mut out),
        Err(VideoError::WrongPicture { .. })
    ));
    assert!(matches!(
        dec.decode(&first, w / 2, h / 2, &mut out),
        Err(VideoError::Ffmpeg { .. } | VideoError::WrongPicture { .. })
    ));
    // Truncations and flipped bytes of the keyframe: an error or a picture,
    // never a panic, and a picture is finite.
    for cut in [2, first.len() / 3, first.len() / 2, first.len() - 1] {
        let _ = dec.decode(&first[..cut], w, h, &mut out);
        assert!(out.iter().all(|p| p.iter().all(|c| c.is_finite())));
    }
    let mut flipped = first.clone();
    for i in (40..flipped.len()).step_by(7) {
        flipped[i] ^= 0x5a;
    }
    let _ = dec.decode(&flipped, w, h, &mut out);
    assert!(out.iter().all(|p| p.iter().all(|c| c.is_finite())));
    // A gap, then a P-frame: refused; the keyframe recovers.
    dec.gap();
    assert!(dec.awaiting_keyframe());
    assert!(matches!(
        dec.decode(&second, w, h, &mut out),
        Err(VideoError::AwaitingKeyframe)
    ));
    dec.decode(&first, w, h, &mut out).unwrap();
    assert!(!dec.awaiting_keyframe());
    dec.decode(&second, w, h, &mut out).unwrap();
    assert!(psnr(&picture(w, h, 1), &out) > 25.0);
}

/// A predicted payload that does not follow the last one decoded (one was
/// lost) is a gap, and the decoder waits for a keyframe; protocol's stream
/// traits code through the same encoder and decoder.
#[test]
fn a_missed_payload_is_a_gap_until_the_next_keyframe() {
    use protocol::codec::stream::{ColorStreamDecoder, ColorStreamEncoder};
    let size = protocol::FrameSize::new(64, 48);
    let mut enc = ColorEncoder::new(settings(Chroma::Yuv420, 0.5), 30.0).unwrap();
    let mut dec = ColorDecoder::new().unwrap();
    assert_eq!(enc.codec(), protocol::Codec::H264);
    let mut out = Vec::new();
    let payloads: Vec<Vec<u8>> = (0..4)
        .map(|t| enc.encode_color(size, &picture(64, 48, t)).unwrap())
        .collect();
    assert!(is_keyframe(&payloads[0]) && !is_keyframe(&payloads[1]));
    dec.decode_color(&payloads[0], size, &mut out).unwrap();
    // Payload 1 lost.
    let gap = dec.decode_color(&payloads[2], size, &mut out).unwrap_err();
    assert!(
        matches!(
            gap.downcast_ref::<VideoError>(),
            Some(VideoError::Gap { last: 0, got: 2 })
        ),
        "{gap}"
    );
    assert!(dec.awaiting_keyframe());
    assert!(matches!(
        dec.decode(&payloads[3], 64, 48, &mut out),
        Err(VideoError::AwaitingKeyframe)
    ));
    enc.request_keyframe();
    let key = enc.encode_color(size, &picture(64, 48, 4)).unwrap();
    assert!(is_keyframe(&key));
    dec.decode_color(&key, size, &mut out).unwrap();
    let next = enc.encode_color(size, &picture(64, 48, 5)).unwrap();
    dec.decode_color(&next, size, &mut out).unwrap();
    assert!(psnr(&picture(64, 48, 5), &out) > 25.0);
}

#[test]
fn colour_of_the_wrong_size_is_refused() {
    let mut enc = ColorEncoder::new(settings(Chroma::Yuv420, 1.0), 30.0).unwrap();
    assert!(matches!(
        enc.encode(4, 4, &[[f16::ONE; 4]; 15]),
        Err(VideoError::WrongPixels { got: 15, .. })
    ));
    assert!(enc.encode(0, 4, &[]).is_err());
}
