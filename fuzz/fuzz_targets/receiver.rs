//! Drives the client's sans-IO frame receiver (`client::FrameReceiver`)
//! with arbitrary transport events: opens, data, ends and resets on up to
//! eight interleaved streams, in chunks the input chooses, in either order
//! ([`Order`]). Whatever arrives, the
//! receiver must not panic, must deliver frames in strictly increasing
//! order, keep at most its stream limit in flight and its byte budget
//! buffered, and cancel only streams it was reading.
#![no_main]

use client::receiver::{Delivery, FrameReceiver, IN_FLIGHT_FRAMES, Order, frame_bytes_bound};
use libfuzzer_sys::fuzz_target;
use protocol::{FrameSize, Limits};

const MAX_STREAMS: usize = 4;

fuzz_target!(|data: &[u8]| {
    // The limits a client has after a welcome for 16×9 frames (the seeds'
    // size), with three buffers a frame.
    let limits = Limits::for_frames(FrameSize::new(16, 9));
    let budget = IN_FLIGHT_FRAMES * frame_bytes_bound(&limits, 3);
    // The first byte picks the order (video-coded colour or not).
    let Some((&order, mut rest)) = data.split_first() else {
        return;
    };
    let order = if order & 1 == 1 {
        Order::Every
    } else {
        Order::Newest
    };
    let mut receiver = FrameReceiver::new(limits, MAX_STREAMS)
        .with_byte_budget(budget)
        .with_order(order);
    let mut last: Option<u64> = None;
    // Each event: a byte (kind in the low 2 bits, stream in the next 3),
    // then for data a length byte (×16, +1) and that many bytes.
    while let Some((&op, tail)) = rest.split_first() {
        rest = tail;
        let stream = u64::from(op >> 2 & 7);
        match op & 3 {
            3 if op & 0x80 != 0 => {
                let _ = receiver.on_stream_open(stream);
            }
            0 | 3 => {
                let Some((&len, tail)) = rest.split_first() else {
                    break;
                };
                let len = (usize::from(len) * 16 + 1).min(tail.len());
                let (chunk, tail) = tail.split_at(len);
                rest = tail;
                match receiver.on_data(stream, chunk) {
                    Ok(delivery) => check(delivery, &mut last),
                    Err(_) => {}
                }
            }
            1 => {
                let _ = receiver.on_stream_end(stream);
            }
            _ => check(receiver.on_stream_reset(stream), &mut last),
        }
        assert!(receiver.in_flight() <= MAX_STREAMS);
        assert!(receiver.buffered() <= budget);
        assert_eq!(receiver.last_delivered(), last);
    }
});

/// Frames are delivered in strictly increasing order, and only streams
/// the receiver could have read are cancelled.
fn check(delivery: Delivery, last: &mut Option<u64>) {
    for frame in delivery.frames {
        let index = frame.header.meta.index;
        assert!(last.is_none_or(|l| index > l), "{index} after {last:?}");
        *last = Some(index);
        let _ = frame.decode();
    }
    assert!(delivery.cancel.iter().all(|&s| s < 8));
}
