//! Sans-IO frame reception (DESIGN §7): one unidirectional stream per frame.
//!
//! The transport hands every chunk it reads to [`FrameReceiver::on_data`]
//! with the stream it came from, and reports stream ends and resets. The
//! receiver decodes and checks the messages ([`protocol::wire::Decoder`],
//! [`FrameAssembler`]), and when a frame completes it is delivered only if it
//! is newer than every frame delivered before; an older one is *late* and is
//! superseded. Streams still carrying frames older than a delivered one are
//! returned for cancellation, so a late frame never costs bandwidth or
//! decoding time once a newer one is shown.
//!
//! That is right when every frame stands alone. When each frame is
//! predicted from the one before (video-coded colour, [`Order::Every`]), a
//! superseded frame breaks the chain: every frame after it is undecodable
//! until the next keyframe, a round trip and a keyframe's bytes away. So
//! there a frame that completes while an older one is still arriving
//! (its last packet lost and being retransmitted, issue 18 §8) waits for
//! it, and both are delivered in order, up to [`MAX_HELD`] frames waiting.
//!
//! Like `quinn-proto`, this does no IO and reads no clock, so it is tested
//! deterministically.

use std::collections::{BTreeMap, HashMap, VecDeque};

use protocol::Limits;
use protocol::assemble::{AssembleError, EncodedFrame, FrameAssembler};
use protocol::wire::{ClientStats, Decoder};

/// Identifies a transport stream (quinn's stream id as a number).
pub type StreamId = u64;

/// A per-frame stream that broke the protocol. The caller closes the
/// connection with this as the reason.
#[derive(Debug, thiserror::Error)]
pub enum ReceiveError {
    /// The stream's bytes are not a valid frame.
    #[error("stream {stream}: {source}")]
    Stream {
        /// The stream.
        stream: StreamId,
        /// What is wrong.
        #[source]
        source: AssembleError,
    },
    /// More streams open at once than allowed.
    #[error("more than {max} frame streams in flight")]
    TooManyStreams {
        /// The limit.
        max: usize,
    },
}

/// Frames' worth of bytes the receiver buffers across all in-flight
/// streams ([`FrameReceiver::with_byte_budget`]): a real-time stream has a
/// frame or two in flight; beyond this the oldest are dropped.
pub const IN_FLIGHT_FRAMES: u64 = 4;

/// The most bytes one frame stream of `buffers` buffers can carry within
/// `limits`: its header message and one payload message per buffer.
pub fn frame_bytes_bound(limits: &Limits, buffers: usize) -> u64 {
    let message_head = protocol::wire::HEADER_LEN as u64 + 16;
    let header = message_head + u64::from(limits.max_control);
    header.saturating_add((buffers as u64).saturating_mul(message_head + limits.max_payload))
}

/// Most complete frames an [`Order::Every`] receiver keeps waiting for
/// older ones: past this, the streams they wait for are given up
/// (cancelled, counted late) and the frames delivered. A server has at most
/// `host::serve::MAX_IN_FLIGHT` (3) frames unacknowledged, so a real one
/// never comes near it; it bounds the memory and the wait a server that
/// never finishes a stream can cause.
pub const MAX_HELD: usize = IN_FLIGHT_FRAMES as usize;

/// How frames that complete out of order are treated.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Order {
    /// Each frame stands alone (raw or intra-coded buffers): the newest
    /// complete frame is delivered at once, and older ones still arriving
    /// are superseded.
    #[default]
    Newest,
    /// Each frame is needed to decode the next (video-coded colour): a
    /// complete frame waits for older ones still arriving, and all are
    /// delivered in order.
    Every,
}

/// What one call produced.
#[derive(Debug, Default)]
pub struct Delivery {
    /// Complete frames, each newer than any delivered before, oldest
    /// first (more than one only when an [`Order::Every`] receiver
    /// releases frames that waited).
    pub frames: Vec<EncodedFrame>,
    /// Streams whose frames are now superseded: stop reading them.
    pub cancel: Vec<StreamId>,
}

#[derive(Debug)]
struct InFlight {
    decoder: Decoder,
    assembler: FrameAssembler,
    /// Bytes taken from the stream so far.
    bytes: u64,
    /// Its frame is complete (the stream waits for its FIN).
    done: bool,
}

impl InFlight {
    fn new(limits: Limits) -> Self {
        Self {
            decoder: Decoder::new(limits),
            assembler: FrameAssembler::new(),
            bytes: 0,
            done: false,
        }
    }
}

/// Reassembles and orders frames from many concurrent streams.
#[derive(Debug)]
pub struct FrameReceiver {
    limits: Limits,
    max_streams: usize,
    streams: HashMap<StreamId, InFlight>,
    /// Streams cancelled as superseded: bytes the transport had already
    /// buffered for them are ignored. Bounded to [`CANCELLED_MEMORY`].
    cancelled: VecDeque<StreamId>,
    last_delivered: Option<u64>,
    stats: ClientStats,
    /// Most bytes buffered across in-flight streams.
    byte_budget: u64,
    /// Bytes buffered across in-flight streams.
    buffered: u64,
    order: Order,
    /// Complete frames waiting for older ones ([`Order::Every`]), by index,
    /// with their streams.
    held: BTreeMap<u64, (StreamId, EncodedFrame)>,
}

/// How many cancelled stream ids are remembered.
const CANCELLED_MEMORY: usize = 256;

impl FrameReceiver {
    /// A receiver enforcing `limits` on every stream, with at most
    /// `max_streams` frames in flight.
    pub fn new(limits: Limits, max_streams: usize) -> Self {
        Self {
            limits,
            max_streams,
            streams: HashMap::new(),
            cancelled: VecDeque::new(),
            last_delivered: None,
            stats: ClientStats::default(),
            byte_budget: u64::MAX,
            buffered: 0,
            order: Order::Newest,
            held: BTreeMap::new(),
        }
    }

    /// Treats frames that complete out of order as `order` says.
    pub fn with_order(mut self, order: Order) -> Self {
        self.order = order;
        self
    }

    /// Buffers at most `bytes` across in-flight streams: when a chunk takes
    /// the total past it, the streams of the oldest frames are dropped and
    /// cancelled until it fits (issue 18 §5), which bounds the memory a
    /// server can make the client hold, whatever it sends.
    pub fn with_byte_budget(mut self, bytes: u64) -> Self {
        self.byte_budget = bytes;
        self
    }

    /// Bytes buffered across in-flight streams.
    pub fn buffered(&self) -> u64 {
        self.buffered
    }

    /// Removes an in-flight stream and its bytes from the total.
    fn take(&mut self, stream: StreamId) -> Option<InFlight> {
        let s = self.streams.remove(&stream)?;
        self.buffered -= s.bytes;
        Some(s)
    }

    /// Drops the oldest frames' streams until the buffered bytes fit the
    /// budget; returns them, for cancellation.
    fn fit_budget(&mut self) -> Vec<StreamId> {
        let mut dropped = vec![];
        while self.buffered > self.byte_budget {
            // Oldest first: by frame index, a stream whose header has not
            // arrived yet counting as newest; then by stream id.
            let victim = self
                .streams
                .iter()
                .min_by_key(|&(&id, s)| {
                    (s.assembler.header().map_or(u64::MAX, |h| h.meta.index), id)
                })
                .map(|(&id, _)| id);
            let Some(victim) = victim else { break };
            self.take(victim);
            self.stats.frames_dropped += 1;
            self.remember_cancelled(victim);
            dropped.push(victim);
        }
        dropped
    }

    /// The transport accepted `stream`, before any of its bytes: an
    /// [`Order::Every`] receiver then knows a frame is on its way there
    /// even while its first packet is being retransmitted (a transport
    /// opens streams in order, so this comes before a newer stream's data).
    pub fn on_stream_open(&mut self, stream: StreamId) -> Result<(), ReceiveError> {
        self.open(stream).map(|_| ())
    }

    /// Makes the in-flight entry of `stream` if it is new; false if the
    /// stream was cancelled.
    fn open(&mut self, stream: StreamId) -> Result<bool, ReceiveError> {
        if self.cancelled.contains(&stream) {
            return Ok(false);
        }
        if !self.streams.contains_key(&stream) && self.streams.len() >= self.max_streams {
            return Err(ReceiveError::TooManyStreams {
                max: self.max_streams,
            });
        }
        let limits = self.limits;
        self.streams
            .entry(stream)
            .or_insert_with(|| InFlight::new(limits));
        Ok(true)
    }

    /// Bytes read from `stream`.
    pub fn on_data(&mut self, stream: StreamId, bytes: &[u8]) -> Result<Delivery, ReceiveError> {
        if !self.open(stream)? {
            return Ok(Delivery::default());
        }
        let Some(entry) = self.streams.get_mut(&stream) else {
            return Ok(Delivery::default());
        };
        entry.bytes += bytes.len() as u64;
        entry.decoder.feed(bytes);
        self.stats.bytes_received += bytes.len() as u64;
        self.buffered += bytes.len() as u64;
        let fail = |source: AssembleError| ReceiveError::Stream { stream, source };
        let mut complete = None;
        loop {
            let msg = match entry.decoder.next_message() {
                Ok(Some(m)) => m,
                Ok(None) => break,
                Err(e) => {
                    self.take(stream);
                    return Err(fail(e.into()));
                }
            };
            match entry.assembler.push(msg) {
                Ok(Some(frame)) => {
                    // The frame is handed on: the stream holds nothing now.
                    self.buffered -= std::mem::take(&mut entry.bytes);
                    entry.done = true;
                    complete = Some(frame);
                }
                Ok(None) => {}
                Err(e) => {
                    self.take(stream);
                    return Err(fail(e));
                }
            }
        }
        let mut delivery = Delivery::default();
        // A header that is already superseded: stop the stream early.
        if let (Some(h), Some(last)) = (entry.assembler.header(), self.last_delivered) {
            if complete.is_none() && h.meta.index <= last {
                self.take(stream);
                self.stats.frames_late += 1;
                self.remember_cancelled(stream);
                delivery.cancel.push(stream);
                return Ok(delivery);
            }
        }
        if let Some(frame) = complete {
            self.stats.frames_received += 1;
            let index = frame.header.meta.index;
            let stale = self.last_delivered.is_some_and(|last| index <= last);
            match self.held.entry(index) {
                std::collections::btree_map::Entry::Vacant(v) if !stale => {
                    v.insert((stream, frame));
                }
                // Older than one delivered, or a second frame of one index.
                _ => self.stats.frames_late += 1,
            }
        }
        delivery.cancel.extend(self.fit_budget());
        self.release(&mut delivery);
        Ok(delivery)
    }

    /// Whether the frame `index` on `stream` waits for an older one: an
    /// [`Order::Every`] receiver has a stream still arriving whose frame is
    /// older, or whose header has not come yet and that the transport
    /// opened first.
    fn waits(&self, index: u64, stream: StreamId) -> bool {
        self.order == Order::Every && self.awaited(index, stream).next().is_some()
    }

    /// The streams still arriving with a frame older than `index` on
    /// `stream`, or without a header yet and opened before it.
    fn awaited(&self, index: u64, stream: StreamId) -> impl Iterator<Item = StreamId> + '_ {
        self.streams
            .iter()
            .filter(move |&(&id, s)| {
                !s.done
                    && id != stream
                    && s.assembler
                        .header()
                        .map_or(id < stream, |h| h.meta.index < index)
            })
            .map(|(&id, _)| id)
    }

    /// Delivers the held frames that wait for nothing, oldest first; past
    /// [`MAX_HELD`] waiting, gives up the streams the oldest waits for.
    fn release(&mut self, delivery: &mut Delivery) {
        loop {
            while let Some((&index, &(stream, _))) = self.held.first_key_value() {
                if self.waits(index, stream) {
                    break;
                }
                // Held frames are newer than any delivered (`on_data`), and
                // leave oldest first.
                let Some((_, (stream, frame))) = self.held.pop_first() else {
                    break;
                };
                self.last_delivered = Some(index);
                delivery.cancel.extend(self.supersede(index, stream));
                delivery.frames.push(frame);
            }
            if self.held.len() <= MAX_HELD {
                return;
            }
            let Some((&index, &(stream, _))) = self.held.first_key_value() else {
                return;
            };
            let awaited: Vec<StreamId> = self.awaited(index, stream).collect();
            for id in awaited {
                self.take(id);
                self.stats.frames_late += 1;
                self.remember_cancelled(id);
                delivery.cancel.push(id);
            }
        }
    }

    /// Drops every in-flight stream other than `keep` whose frame is not
    /// newer than `index`.
    fn supersede(&mut self, index: u64, keep: StreamId) -> Vec<StreamId> {
        let stale: Vec<StreamId> = self
            .streams
            .iter()
            .filter(|&(&id, s)| {
                !s.done && id != keep && s.assembler.header().is_some_and(|h| h.meta.index <= index)
            })
            .map(|(&id, _)| id)
            .collect();
        for &id in &stale {
            self.take(id);
            self.stats.frames_late += 1;
            self.remember_cancelled(id);
        }
        stale
    }

    fn remember_cancelled(&mut self, stream: StreamId) {
        if self.cancelled.len() == CANCELLED_MEMORY {
            self.cancelled.pop_front();
        }
        self.cancelled.push_back(stream);
    }

    fn forget_cancelled(&mut self, stream: StreamId) -> bool {
        let found = self.cancelled.iter().position(|&s| s == stream);
        if let Some(i) = found {
            self.cancelled.remove(i);
        }
        found.is_some()
    }

    /// The stream ended (FIN). A complete frame has already been delivered;
    /// ending mid-frame is a protocol error.
    pub fn on_stream_end(&mut self, stream: StreamId) -> Result<(), ReceiveError> {
        if self.forget_cancelled(stream) {
            return Ok(());
        }
        let Some(s) = self.take(stream) else {
            return Ok(());
        };
        let result = if s.decoder.is_at_boundary() {
            s.assembler.finish()
        } else {
            Err(AssembleError::Wire(protocol::wire::WireError::Incomplete {
                needed: s.decoder.buffered(),
            }))
        };
        result.map_err(|source| {
            self.stats.frames_dropped += 1;
            ReceiveError::Stream { stream, source }
        })
    }

    /// The sender reset the stream (it cancelled a stale frame): the frame is
    /// dropped, which is not an error. Frames that waited for it are
    /// delivered.
    pub fn on_stream_reset(&mut self, stream: StreamId) -> Delivery {
        self.forget_cancelled(stream);
        if let Some(s) = self.take(stream) {
            if !s.done {
                self.stats.frames_dropped += 1;
            }
        }
        let mut delivery = Delivery::default();
        self.release(&mut delivery);
        delivery
    }

    /// Index of the newest delivered frame.
    pub fn last_delivered(&self) -> Option<u64> {
        self.last_delivered
    }

    /// Frames currently in flight.
    pub fn in_flight(&self) -> usize {
        self.streams.len()
    }

    /// Statistics to report to the server (`rtt_us` is the caller's to fill).
    pub fn stats(&self) -> ClientStats {
        self.stats
    }

    /// Forgets ordering, e.g. after a new session starts.
    pub fn reset(&mut self) {
        self.streams.clear();
        self.cancelled.clear();
        self.held.clear();
        self.buffered = 0;
        self.last_delivered = None;
    }
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use glam::{DQuat, DVec3};
    use half::f16;
    use protocol::assemble::encode_frame;
    use protocol::wire::StreamBuffer;
    use protocol::{Camera, Codec, Frame, FrameMeta, FrameSize, Pose, Projection};

    use super::*;

    fn stream_bytes(index: u64) -> Vec<u8> {
        let size = FrameSize::new(6, 4);
        let n = 24;
        let frame = Frame {
            meta: FrameMeta {
                index,
                time: index as f64 / 30.0,
                camera: Camera::new(
                    Pose::new(DVec3::new(0.0, 1.0, index as f64), DQuat::IDENTITY),
                    Projection::perspective(1.0, 1.5, 0.1, 100.0),
                ),
                size,
                host_processing: Duration::from_millis(3),
                cut: false,
            },
            color: vec![[f16::from_f32(index as f32); 4]; n],
            depth: vec![2.0; n],
            motion: vec![[0.5, -0.5]; n],
            extras: vec![],
        };
        let buffers = StreamBuffer::default_set(Codec::Raw);
        encode_frame(&frame, &buffers, 1)
            .unwrap()
            .to_stream_bytes()
            .unwrap()
    }

    fn receiver() -> FrameReceiver {
        FrameReceiver::new(Limits::default(), 8)
    }

    /// The indices of the frames delivered.
    fn indices(d: &Delivery) -> Vec<u64> {
        d.frames.iter().map(|f| f.header.meta.index).collect()
    }

    #[test]
    fn frames_are_delivered_in_order_and_late_ones_superseded() {
        let mut r = receiver();
        let (a, b, c) = (stream_bytes(1), stream_bytes(2), stream_bytes(3));
        // Frame 1 arrives in pieces, frame 3 overtakes frame 2.
        assert!(r.on_data(10, &a[..20]).unwrap().frames.is_empty());
        let d = r.on_data(10, &a[20..]).unwrap();
        assert_eq!(indices(&d), [1]);
        r.on_stream_end(10).unwrap();
        // Frame 2's header arrives, then all of frame 3.
        assert!(r.on_data(12, &b[..b.len() / 2]).unwrap().frames.is_empty());
        let d = r.on_data(14, &c).unwrap();
        assert_eq!(indices(&d), [3]);
        assert_eq!(d.cancel, vec![12], "frame 2's stream is superseded");
        assert_eq!(r.in_flight(), 1, "frame 3's stream until its FIN");
        r.on_stream_end(14).unwrap();
        // A complete but older frame on a new stream is late, not delivered.
        let d = r.on_data(16, &b).unwrap();
        assert!(d.frames.is_empty());
        let s = r.stats();
        assert_eq!(s.frames_received, 3);
        assert_eq!(s.frames_late, 2);
        assert_eq!(s.frames_dropped, 0);
        assert_eq!(
            s.bytes_received,
            (a.len() + b.len() / 2 + c.len() + b.len()) as u64
        );
        assert_eq!(r.last_delivered(), Some(3));
    }

    #[test]
    fn stale_headers_are_cancelled_before_their_payloads_arrive() {
        let mut r = receiver();
        r.on_data(1, &stream_bytes(5)).unwrap();
        let old = stream_bytes(4);
        // Exactly the header message: 8 header bytes plus the body length.
        let header_len = 8 + u32::from_le_bytes(old[..4].try_into().unwrap()) as usize;
        let d = r.on_data(2, &old[..header_len]).unwrap();
        assert_eq!(d.cancel, vec![2]);
        assert_eq!(r.stats().frames_late, 1);
        // Bytes the transport still had for the cancelled stream are ignored,
        // and its FIN is not an error.
        assert!(r.on_data(2, &old[header_len..]).unwrap().frames.is_empty());
        assert_eq!(r.in_flight(), 1);
        r.on_stream_end(2).unwrap();
        assert_eq!(r.stats().frames_dropped, 0);
    }

    #[test]
    fn broken_streams_are_errors_and_do_not_disturb_others() {
        let mut r = receiver();
        let good = stream_bytes(1);
        r.on_data(1, &good[..30]).unwrap();
        // Garbage on another stream.
        let e = r.on_data(2, &[0xff; 64]).unwrap_err();
        assert!(matches!(e, ReceiveError::Stream { stream: 2, .. }), "{e}");
        // A stream that ends mid-frame.
        r.on_data(3, &stream_bytes(7)[..50]).unwrap();
        assert!(r.on_stream_end(3).is_err());
        assert_eq!(r.stats().frames_dropped, 1);
        // A reset stream is a drop, not an error.
        r.on_data(4, &stream_bytes(8)[..50]).unwrap();
        assert!(r.on_stream_reset(4).frames.is_empty());
        assert_eq!(r.stats().frames_dropped, 2);
        // The first stream still completes.
        let d = r.on_data(1, &good[30..]).unwrap();
        assert_eq!(d.frames[0].decode().unwrap().meta.index, 1);
    }

    /// The bytes buffered across streams stay within the budget: the
    /// oldest frames' streams are dropped and cancelled to make room, and a
    /// delivered frame's bytes leave the total (issue 18 §5).
    #[test]
    fn buffered_bytes_stay_within_the_budget() {
        let (a, b, c) = (stream_bytes(1), stream_bytes(2), stream_bytes(3));
        let frame = a.len() as u64;
        let mut r = receiver().with_byte_budget(2 * frame);
        // Frames 2 and 1, all but their last byte: two frames' worth.
        r.on_data(20, &b[..b.len() - 1]).unwrap();
        r.on_data(10, &a[..a.len() - 1]).unwrap();
        assert_eq!(r.buffered(), 2 * frame - 2);
        // Frame 3's first bytes take the total over: frame 1 (the oldest)
        // is dropped and cancelled, frame 2 kept.
        let d = r.on_data(30, &c[..10]).unwrap();
        assert_eq!(d.cancel, vec![10]);
        assert_eq!(r.buffered(), frame - 1 + 10);
        assert!(r.buffered() <= 2 * frame);
        assert_eq!(r.stats().frames_dropped, 1);
        // Its remaining byte is ignored; frame 2 completes and its bytes
        // leave the total before its FIN.
        assert!(r.on_data(10, &a[a.len() - 1..]).unwrap().frames.is_empty());
        let d = r.on_data(20, &b[b.len() - 1..]).unwrap();
        assert_eq!(indices(&d), [2]);
        assert_eq!(r.buffered(), 10);
        r.on_stream_end(20).unwrap();
        r.on_stream_end(10).unwrap();
        let d = r.on_data(30, &c[10..]).unwrap();
        assert_eq!(indices(&d), [3]);
        assert_eq!(r.buffered(), 0);
        // Whatever a sender does, the total never passes the budget.
        let mut r = receiver().with_byte_budget(frame + frame / 2);
        for id in 0..8u64 {
            let bytes = stream_bytes(10 + id);
            r.on_data(id, &bytes[..bytes.len() - 1]).unwrap();
            assert!(r.buffered() <= frame + frame / 2, "stream {id}");
        }
        assert_eq!(r.stats().frames_dropped, 7);
    }

    /// A complete frame whose stream has not ended yet is not superseded by
    /// a newer one (it was delivered; it is not late).
    #[test]
    fn a_delivered_frame_awaiting_its_fin_is_not_late() {
        let mut r = receiver();
        assert_eq!(indices(&r.on_data(1, &stream_bytes(1)).unwrap()), [1]);
        let d = r.on_data(2, &stream_bytes(2)).unwrap();
        assert_eq!(indices(&d), [2]);
        assert!(d.cancel.is_empty());
        r.on_stream_end(1).unwrap();
        r.on_stream_end(2).unwrap();
        assert_eq!(r.stats().frames_late, 0);
    }

    fn every() -> FrameReceiver {
        receiver().with_order(Order::Every)
    }

    /// Video-coded frames: a frame that overtakes an older one waits for
    /// it, and both are delivered in order; nothing is cancelled or late.
    /// The same arrivals in `Newest` order supersede the older frame.
    #[test]
    fn every_frame_order_waits_for_an_overtaken_frame() {
        let (a, b, c) = (stream_bytes(1), stream_bytes(2), stream_bytes(3));
        let mut r = every();
        // Frame 1 lacks its last bytes (being retransmitted); frames 2 and
        // 3 complete.
        assert!(r.on_data(4, &a[..a.len() - 5]).unwrap().frames.is_empty());
        let d = r.on_data(8, &b).unwrap();
        assert!(d.frames.is_empty() && d.cancel.is_empty());
        assert!(r.on_data(12, &c).unwrap().frames.is_empty());
        assert_eq!(r.last_delivered(), None);
        // Frame 1's last bytes release all three, oldest first.
        let d = r.on_data(4, &a[a.len() - 5..]).unwrap();
        assert_eq!(indices(&d), [1, 2, 3]);
        assert!(d.cancel.is_empty());
        for id in [4, 8, 12] {
            r.on_stream_end(id).unwrap();
        }
        let s = r.stats();
        assert_eq!(
            (s.frames_received, s.frames_late, s.frames_dropped),
            (3, 0, 0)
        );
        assert_eq!(r.last_delivered(), Some(3));

        let mut r = receiver();
        r.on_data(4, &a[..a.len() - 5]).unwrap();
        let d = r.on_data(8, &b).unwrap();
        assert_eq!(indices(&d), [2]);
        assert_eq!(d.cancel, vec![4]);
    }

    /// A stream the transport opened before a newer one is waited for even
    /// when none of its bytes (not even its header) has come; one opened
    /// after is not.
    #[test]
    fn every_frame_order_waits_for_an_opened_stream_without_bytes() {
        let mut r = every();
        r.on_stream_open(4).unwrap();
        r.on_stream_open(12).unwrap();
        assert!(r.on_data(8, &stream_bytes(2)).unwrap().frames.is_empty());
        // Stream 12, opened after stream 8, does not hold frame 2 back.
        let d = r.on_data(4, &stream_bytes(1)).unwrap();
        assert_eq!(indices(&d), [1, 2]);
        // It does hold back a frame on a stream opened after it.
        assert!(r.on_data(16, &stream_bytes(4)).unwrap().frames.is_empty());
        let header = stream_bytes(3);
        let header_len = 8 + u32::from_le_bytes(header[..4].try_into().unwrap()) as usize;
        // Its header says frame 3: frame 4 waits for it.
        assert!(
            r.on_data(12, &header[..header_len])
                .unwrap()
                .frames
                .is_empty()
        );
        assert_eq!(
            indices(&r.on_data(12, &header[header_len..]).unwrap()),
            [3, 4]
        );
    }

    /// A frame waited for that the sender resets is dropped, and the frames
    /// that waited are delivered.
    #[test]
    fn every_frame_order_delivers_past_a_reset_stream() {
        let mut r = every();
        let a = stream_bytes(1);
        r.on_data(4, &a[..a.len() / 2]).unwrap();
        assert!(r.on_data(8, &stream_bytes(2)).unwrap().frames.is_empty());
        let d = r.on_stream_reset(4);
        assert_eq!(indices(&d), [2]);
        assert_eq!(r.stats().frames_dropped, 1);
        assert_eq!(r.in_flight(), 1, "frame 2's stream until its FIN");
    }

    /// However long a stream stalls, at most `MAX_HELD` complete frames
    /// wait for it: then it is given up (cancelled, late) and they are
    /// delivered.
    #[test]
    fn every_frame_order_gives_up_a_stalled_stream() {
        let mut r = every();
        let a = stream_bytes(1);
        r.on_data(1, &a[..10]).unwrap();
        let held = MAX_HELD as u64;
        for i in 0..held {
            let d = r.on_data(2 + i, &stream_bytes(2 + i)).unwrap();
            assert!(d.frames.is_empty(), "frame {} waits", 2 + i);
        }
        let d = r.on_data(2 + held, &stream_bytes(2 + held)).unwrap();
        assert_eq!(d.cancel, vec![1]);
        assert_eq!(indices(&d), (2..=2 + held).collect::<Vec<_>>());
        assert_eq!(r.stats().frames_late, 1);
        // The stalled stream's remaining bytes are ignored.
        assert!(r.on_data(1, &a[10..]).unwrap().frames.is_empty());
    }

    #[test]
    fn in_flight_streams_are_bounded() {
        let mut r = FrameReceiver::new(Limits::default(), 2);
        r.on_data(1, &[1]).unwrap();
        r.on_data(2, &[1]).unwrap();
        assert!(matches!(
            r.on_data(3, &[1]),
            Err(ReceiveError::TooManyStreams { max: 2 })
        ));
        r.on_stream_reset(1);
        assert!(r.on_data(3, &[1]).is_ok());
        // A stream the transport opened counts too.
        assert!(matches!(
            r.on_stream_open(4),
            Err(ReceiveError::TooManyStreams { max: 2 })
        ));
    }
}
