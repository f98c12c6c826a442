//! The client side of the stream (DESIGN §7): connect with a pinned
//! certificate, handshake on the control stream, then receive one frame per
//! unidirectional stream through the sans-IO [`FrameReceiver`], decode, and
//! hand complete frames to the consumer in order. Stats go back to the
//! server every second; pings measure the round trip.

use std::collections::HashSet;
use std::net::SocketAddr;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use protocol::assemble::AssembleError;
use protocol::wire::{
    self, ClientStats, Decoder, Hello, Input, InputEcho, KeyframeRequest, Message, Ping, Reject,
    ServerStats, WIRE_VERSION, Welcome, WindowMode,
};
use protocol::{Codec, Frame, FrameSize, Limits};
use tokio::sync::mpsc;

use crate::receiver::{
    FrameReceiver, IN_FLIGHT_FRAMES, Order, ReceiveError, StreamId, frame_bytes_bound,
};
use crate::tls::{Pin, PinError};

/// How to reach and authenticate to a server.
#[derive(Clone, Debug)]
pub struct ConnectConfig {
    /// Server address.
    pub addr: SocketAddr,
    /// Name for TLS (SNI); the pin decides trust.
    pub server_name: String,
    /// Which certificate to trust.
    pub pin: Pin,
    /// Access token.
    pub token: String,
    /// Client name for the server's logs.
    pub client_name: String,
    /// Wire version to announce (tests use others).
    pub version: u16,
    /// Limits for everything received.
    pub limits: Limits,
    /// Frames buffered for a slow consumer before the receiver waits.
    pub queue: usize,
}

impl ConnectConfig {
    /// Defaults for `addr` with `pin` and `token`.
    pub fn new(addr: SocketAddr, pin: Pin, token: impl Into<String>) -> Self {
        Self {
            addr,
            server_name: "localhost".into(),
            pin,
            token: token.into(),
            client_name: "client".into(),
            version: WIRE_VERSION,
            limits: Limits::default(),
            queue: 8,
        }
    }
}

/// Why a session could not start or ended badly.
#[derive(Debug, thiserror::Error)]
pub enum ConnectError {
    /// The access token is empty (no server accepts it; refused before
    /// anything is sent).
    #[error("the access token is empty")]
    EmptyToken,
    /// The pin is unusable.
    #[error(transparent)]
    Pin(#[from] PinError),
    /// The local endpoint could not be created.
    #[error("local endpoint: {0}")]
    Endpoint(#[from] std::io::Error),
    /// The connection could not be started.
    #[error("connect: {0}")]
    Connect(#[from] quinn::ConnectError),
    /// The connection failed or was closed (including a pin mismatch).
    #[error("connection: {0}")]
    Connection(#[from] quinn::ConnectionError),
    /// The server refused the client.
    #[error("refused ({:?}): {}", .0.reason, .0.message)]
    Rejected(Reject),
    /// The server broke the protocol.
    #[error("protocol: {0}")]
    Protocol(String),
    /// No answer in time.
    #[error("timed out waiting for {0}")]
    Timeout(&'static str),
}

/// Live statistics of a session.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SessionStats {
    /// What the client reports to the server.
    pub client: ClientStats,
    /// The server's last report.
    pub server: Option<ServerStats>,
    /// Frame streams that broke the protocol (each also closes the session).
    pub stream_errors: u64,
    /// Frames whose video-coded colour could not be decoded (corrupt, or
    /// predicted from a frame this client lost): each dropped, the stream
    /// goes on from the next keyframe.
    pub color_errors: u64,
    /// Keyframes asked of the server.
    pub keyframe_requests: u64,
    /// Index of the newest frame decoded.
    pub last_decoded: Option<u64>,
}

/// A complete, decoded frame and when it got there.
#[derive(Debug)]
pub struct Arrived {
    /// The frame, shared: the presenter keeps it and the generator reads
    /// its buffers where they are (`FrameGenerator::push_shared`).
    pub frame: Arc<Frame>,
    /// When its last byte had been taken from the connection (a video
    /// frame that waited for an older one: when that one came).
    pub received: Instant,
    /// When it was decoded (it could be shown from then on).
    pub decoded: Instant,
    /// The viewer input its camera came from (interactive streams, issue
    /// 20), as the server echoed it.
    pub input: Option<InputEcho>,
}

/// A connected session. Frames arrive on [`Session::frames`].
pub struct Session {
    /// The server's welcome.
    pub welcome: Welcome,
    /// Complete, decoded frames, in order; closed when the session ends.
    pub frames: mpsc::Receiver<Arrived>,
    conn: quinn::Connection,
    endpoint: quinn::Endpoint,
    stats: Arc<Mutex<SessionStats>>,
    failure: Arc<Mutex<Option<String>>>,
    tasks: Vec<tokio::task::JoinHandle<()>>,
}

impl Session {
    /// Current statistics.
    pub fn stats(&self) -> SessionStats {
        *self.stats.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// The protocol violation that ended the session, if one did.
    pub fn failure(&self) -> Option<String> {
        self.failure.lock().ok().and_then(|f| f.clone())
    }

    /// Sends the viewer's input as a datagram (unreliable: a lost one is
    /// superseded by the next). An interactive server renders from the
    /// newest it took.
    pub fn send_input(&self, input: &Input) -> Result<(), ConnectError> {
        send_input(&self.conn, input)
    }

    /// The QUIC connection, for tools and tests that speak the wire
    /// directly.
    pub fn connection(&self) -> &quinn::Connection {
        &self.conn
    }

    /// Why the connection closed, once it has.
    pub fn close_reason(&self) -> Option<quinn::ConnectionError> {
        self.conn.close_reason()
    }

    /// Ends the session politely.
    pub async fn close(self) {
        self.conn.close(0u32.into(), b"client done");
        for t in &self.tasks {
            t.abort();
        }
        self.endpoint.wait_idle().await;
    }
}

/// Sends `input` as a datagram on `conn`.
pub(crate) fn send_input(conn: &quinn::Connection, input: &Input) -> Result<(), ConnectError> {
    let bytes = wire::encode(&Message::Input(*input)).map_err(protocol_err)?;
    conn.send_datagram(bytes.into())
        .map_err(|e| ConnectError::Protocol(format!("input not sent: {e}")))
}

/// How often the client makes sure the connection carries a packet.
const KEEP_ALIVE: Duration = Duration::from_secs(1);

/// A server silent this long is gone: the session ends (and a
/// [`crate::Stream`] reconnects). A server that restarted says so at once
/// with a stateless reset (`host::tls::Identity::quic_endpoint_config`).
pub const IDLE_TIMEOUT: Duration = Duration::from_secs(5);

/// Frame streams a session reads at once (more is a protocol error).
const MAX_FRAME_STREAMS: usize = 64;

fn protocol_err(e: impl std::fmt::Display) -> ConnectError {
    ConnectError::Protocol(e.to_string())
}

/// Connects, handshakes and starts receiving.
pub async fn connect(config: ConnectConfig) -> Result<Session, ConnectError> {
    if config.token.is_empty() {
        return Err(ConnectError::EmptyToken);
    }
    let tls = config.pin.client_config()?;
    let crypto = quinn::crypto::rustls::QuicClientConfig::try_from(tls).map_err(protocol_err)?;
    let mut client_config = quinn::ClientConfig::new(Arc::new(crypto));
    let mut transport = quinn::TransportConfig::default();
    transport
        .max_concurrent_uni_streams(64u32.into())
        .stream_receive_window((64u32 << 20).into())
        .receive_window((256u32 << 20).into())
        .keep_alive_interval(Some(KEEP_ALIVE))
        .max_idle_timeout(Some(IDLE_TIMEOUT.try_into().map_err(protocol_err)?));
    client_config.transport_config(Arc::new(transport));
    let bind: SocketAddr = if config.addr.is_ipv6() {
        "[::]:0".parse().map_err(protocol_err)?
    } else {
        "0.0.0.0:0".parse().map_err(protocol_err)?
    };
    let endpoint = quinn::Endpoint::client(bind)?;
    let conn = endpoint
        .connect_with(client_config, config.addr, &config.server_name)?
        .await?;

    let (mut send, mut recv) = conn.open_bi().await?;
    let hello = Message::Hello(Hello {
        version: config.version,
        client_name: config.client_name.clone(),
        token: config.token.clone(),
        codecs: decodable_codecs(),
        max_size: FrameSize::new(config.limits.max_dimension, config.limits.max_dimension),
        window_modes: vec![WindowMode::KeepDensity, WindowMode::KeepSize],
        extras: vec![],
    });
    let mut bytes = wire::encode(&hello).map_err(protocol_err)?;
    if config.version != WIRE_VERSION {
        // Announce the version in the header as well, as that client would.
        bytes[4..6].copy_from_slice(&config.version.to_le_bytes());
    }
    send.write_all(&bytes).await.map_err(protocol_err)?;
    // The control stream carries small messages only, and frames are
    // bounded by what the welcome agreed (issue 18 §5).
    let mut decoder = Decoder::new(config.limits.min(Limits::control()));
    let answer = tokio::time::timeout(
        Duration::from_secs(10),
        read_message(&mut recv, &mut decoder),
    )
    .await
    .map_err(|_| ConnectError::Timeout("the welcome"))?;
    let welcome = match answer {
        Ok(Some(Message::Welcome(w))) => w,
        Ok(Some(Message::Reject(r))) => return Err(ConnectError::Rejected(r)),
        Ok(Some(other)) => {
            return Err(protocol_err(format!(
                "expected Welcome, got {:?}",
                other.kind()
            )));
        }
        Ok(None) => {
            // The server closed: report its reason if it gave one.
            return Err(match conn.close_reason() {
                Some(e) => ConnectError::Connection(e),
                None => protocol_err("control stream closed before the welcome"),
            });
        }
        Err(e) => {
            return Err(match conn.close_reason() {
                Some(e) => ConnectError::Connection(e),
                None => protocol_err(e),
            });
        }
    };

    let limits = config.limits.min(Limits::for_frames(welcome.max_frame));
    let byte_budget = IN_FLIGHT_FRAMES * frame_bytes_bound(&limits, welcome.buffers.len());
    // Video-coded colour predicts each frame from the one before: a frame
    // overtaken by a newer one is waited for, not superseded.
    let order = if welcome.buffers.iter().any(|b| b.codec == Codec::H264) {
        Order::Every
    } else {
        Order::Newest
    };
    let receiver = FrameReceiver::new(limits, MAX_FRAME_STREAMS)
        .with_byte_budget(byte_budget)
        .with_order(order);
    let stats = Arc::new(Mutex::new(SessionStats::default()));
    let (frames_tx, frames_rx) = mpsc::channel(config.queue.max(1));
    let (chunks_tx, chunks_rx) = mpsc::channel::<StreamEvent>(256);
    let cancelled = Arc::new(Mutex::new(HashSet::new()));
    let failure = Arc::new(Mutex::new(None));
    let keyframe = Arc::new(tokio::sync::Notify::new());
    let tasks = vec![
        tokio::spawn(accept_streams(conn.clone(), chunks_tx, cancelled.clone())),
        tokio::spawn(assemble(
            Shared {
                conn: conn.clone(),
                cancelled,
                stats: stats.clone(),
                failure: failure.clone(),
                keyframe: keyframe.clone(),
            },
            receiver,
            chunks_rx,
            frames_tx,
        )),
        tokio::spawn(control(
            conn.clone(),
            (send, recv, decoder),
            stats.clone(),
            keyframe,
        )),
    ];
    Ok(Session {
        welcome,
        frames: frames_rx,
        conn,
        endpoint,
        stats,
        failure,
        tasks,
    })
}

/// The codecs this client decodes: all of protocol's, H.264 only where
/// libavcodec has its decoder (without it, a server sending video-coded
/// colour refuses the hello and says why). libavcodec is probed once per
/// process, not on every (re)connect.
fn decodable_codecs() -> Vec<Codec> {
    static H264: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    let h264 = *H264.get_or_init(|| video::ColorDecoder::new().is_ok());
    Codec::ALL
        .into_iter()
        .filter(|&c| c != Codec::H264 || h264)
        .collect()
}

async fn read_message(
    recv: &mut quinn::RecvStream,
    decoder: &mut Decoder,
) -> Result<Option<Message>, ConnectError> {
    loop {
        if let Some(m) = decoder.next_message().map_err(protocol_err)? {
            return Ok(Some(m));
        }
        match recv
            .read_chunk(64 * 1024, true)
            .await
            .map_err(protocol_err)?
        {
            Some(chunk) => decoder.feed(&chunk.bytes),
            None => return Ok(None),
        }
    }
}

enum StreamEvent {
    /// Accepted, in stream order, before any of its data.
    Open(StreamId),
    Data(StreamId, bytes::Bytes),
    End(StreamId),
    Reset(StreamId),
}

/// Accepts frame streams; one reader task per stream forwards its chunks.
async fn accept_streams(
    conn: quinn::Connection,
    tx: mpsc::Sender<StreamEvent>,
    cancelled: Arc<Mutex<HashSet<StreamId>>>,
) {
    while let Ok(mut recv) = conn.accept_uni().await {
        let id = recv.id().index();
        if tx.send(StreamEvent::Open(id)).await.is_err() {
            return;
        }
        let (tx, cancelled) = (tx.clone(), cancelled.clone());
        tokio::spawn(async move {
            // However the stream ends, its id leaves the cancelled set, so
            // the set holds only streams still being read (issue 18 §10).
            let _forget = Forget(&cancelled, id);
            loop {
                if cancelled.lock().map(|c| c.contains(&id)).unwrap_or(false) {
                    let _ = recv.stop(0u32.into());
                    return;
                }
                match recv.read_chunk(256 * 1024, true).await {
                    Ok(Some(chunk)) => {
                        if tx.send(StreamEvent::Data(id, chunk.bytes)).await.is_err() {
                            return;
                        }
                    }
                    Ok(None) => {
                        let _ = tx.send(StreamEvent::End(id)).await;
                        return;
                    }
                    Err(_) => {
                        let _ = tx.send(StreamEvent::Reset(id)).await;
                        return;
                    }
                }
            }
        });
    }
}

/// Removes a stream's id from the cancelled set when its reader ends.
struct Forget<'a>(&'a Mutex<HashSet<StreamId>>, StreamId);

impl Drop for Forget<'_> {
    fn drop(&mut self) {
        if let Ok(mut c) = self.0.lock() {
            c.remove(&self.1);
        }
    }
}

/// Cancelled ids this far below the newest one are forgotten: their
/// streams ended long ago (a cancellation that raced its stream's end would
/// otherwise stay in the set for the whole session).
const CANCELLED_SPAN: StreamId = 256;

/// Adds `ids` to the cancelled set and forgets those [`CANCELLED_SPAN`] or
/// more below the newest; the set stays bounded.
fn cancel(set: &mut HashSet<StreamId>, ids: &[StreamId]) {
    set.extend(ids.iter().copied());
    if let Some(&newest) = set.iter().max() {
        set.retain(|&id| id + CANCELLED_SPAN > newest);
    }
}

/// What the frame tasks share with the session.
struct Shared {
    conn: quinn::Connection,
    cancelled: Arc<Mutex<HashSet<StreamId>>>,
    stats: Arc<Mutex<SessionStats>>,
    failure: Arc<Mutex<Option<String>>>,
    /// Wakes the control task to ask for a keyframe.
    keyframe: Arc<tokio::sync::Notify>,
}

/// How long a client that waits for a keyframe waits before asking again.
const KEYFRAME_RETRY: Duration = Duration::from_millis(250);

/// Owns the [`FrameReceiver`] and the colour decoder: reassembles, orders,
/// decodes, delivers. A frame whose video-coded colour cannot be decoded is
/// dropped and counted, and a keyframe is asked for; any other broken
/// frame ends the session.
async fn assemble(
    shared: Shared,
    mut receiver: FrameReceiver,
    mut rx: mpsc::Receiver<StreamEvent>,
    frames: mpsc::Sender<Arrived>,
) {
    let Shared {
        conn,
        cancelled,
        stats,
        failure,
        keyframe,
    } = shared;
    let fail = |e: ReceiveError| {
        let reason = e.to_string();
        tracing::warn!("closing: {reason}");
        conn.close(2u32.into(), reason.as_bytes());
        if let Ok(mut f) = failure.lock() {
            f.get_or_insert(reason);
        }
    };
    // A stream that breaks the protocol ends the session: the server is
    // broken or hostile, and nothing it sends can be trusted after that.
    let broken = |e: ReceiveError| {
        if let Ok(mut s) = stats.lock() {
            s.stream_errors += 1;
        }
        fail(e);
    };
    // Made when the first frame needs it; frames are decoded one at a
    // time, in the order they are delivered.
    let mut color: Option<video::ColorDecoder> = None;
    let mut asked: Option<Instant> = None;
    while let Some(event) = rx.recv().await {
        let delivery = match event {
            StreamEvent::Data(id, bytes) => match receiver.on_data(id, &bytes) {
                Ok(d) => Some(d),
                Err(e) => return broken(e),
            },
            StreamEvent::End(id) => {
                if let Err(e) = receiver.on_stream_end(id) {
                    return broken(e);
                }
                None
            }
            StreamEvent::Open(id) => {
                if let Err(e) = receiver.on_stream_open(id) {
                    return broken(e);
                }
                None
            }
            StreamEvent::Reset(id) => Some(receiver.on_stream_reset(id)),
        };
        if let Ok(mut s) = stats.lock() {
            s.client = ClientStats {
                rtt_us: conn.rtt().as_micros() as u64,
                ..receiver.stats()
            };
        }
        let Some(delivery) = delivery else { continue };
        if !delivery.cancel.is_empty() {
            if let Ok(mut c) = cancelled.lock() {
                cancel(&mut c, &delivery.cancel);
            }
        }
        for encoded in delivery.frames {
            let received = Instant::now();
            let input = encoded.header.input;
            let video = encoded
                .header
                .buffers
                .iter()
                .any(|b| b.codec == Codec::H264);
            if video && color.is_none() {
                match video::ColorDecoder::new() {
                    Ok(d) => color = Some(d),
                    Err(e) => {
                        // The hello did not list H.264 then: the server broke
                        // the agreement.
                        return fail(ReceiveError::Stream {
                            stream: 0,
                            source: AssembleError::Codec {
                                kind: protocol::BufferKind::Color,
                                source: protocol::codec::CodecError::Stream {
                                    codec: Codec::H264,
                                    source: Box::new(e),
                                },
                            },
                        });
                    }
                }
            }
            // Decoding takes milliseconds per frame: off the runtime, the
            // decoder going with the frame and coming back.
            let mut decoder = color.take();
            let decoded = tokio::task::spawn_blocking(move || {
                let frame = encoded.decode_with(
                    decoder
                        .as_mut()
                        .map(|d| d as &mut dyn protocol::codec::stream::ColorStreamDecoder),
                );
                (decoder, frame)
            })
            .await;
            let Ok((decoder, decoded)) = decoded else {
                // The runtime is shutting down.
                return;
            };
            color = decoder;
            match decoded {
                Ok(frame) => {
                    if let Ok(mut s) = stats.lock() {
                        s.last_decoded = Some(frame.meta.index);
                    }
                    let arrived = Arrived {
                        frame: Arc::new(frame),
                        received,
                        decoded: Instant::now(),
                        input,
                    };
                    if frames.send(arrived).await.is_err() {
                        return;
                    }
                }
                Err(AssembleError::Codec {
                    kind: protocol::BufferKind::Color,
                    source: protocol::codec::CodecError::Stream { source, .. },
                }) => {
                    // This frame is lost; the stream goes on from a keyframe.
                    tracing::debug!("colour of a frame not decoded: {source}");
                    let ask = asked.is_none_or(|at| at.elapsed() >= KEYFRAME_RETRY);
                    if let Ok(mut s) = stats.lock() {
                        s.color_errors += 1;
                        s.keyframe_requests += u64::from(ask);
                    }
                    if ask {
                        asked = Some(Instant::now());
                        keyframe.notify_one();
                    }
                }
                Err(e) => {
                    return fail(ReceiveError::Stream {
                        stream: 0,
                        source: e,
                    });
                }
            }
        }
    }
}

/// Reports stats and pings every second; reads the server's stats.
async fn control(
    conn: quinn::Connection,
    (mut send, mut recv, mut decoder): (quinn::SendStream, quinn::RecvStream, Decoder),
    stats: Arc<Mutex<SessionStats>>,
    keyframe: Arc<tokio::sync::Notify>,
) {
    let reader = {
        let stats = stats.clone();
        async move {
            while let Ok(Some(msg)) = read_message(&mut recv, &mut decoder).await {
                if let Message::ServerStats(s) = msg {
                    if let Ok(mut st) = stats.lock() {
                        st.server = Some(s);
                    }
                }
            }
        }
    };
    let writer = async {
        let start = Instant::now();
        let mut tick = tokio::time::interval(Duration::from_secs(1));
        let mut seq = 0;
        loop {
            tokio::select! {
                _ = tick.tick() => {}
                () = keyframe.notified() => {
                    let last_decoded = stats.lock().ok().and_then(|s| s.last_decoded);
                    tracing::debug!(?last_decoded, "asking for a keyframe");
                    let request = Message::KeyframeRequest(KeyframeRequest { last_decoded });
                    let Ok(bytes) = wire::encode(&request) else {
                        return;
                    };
                    if send.write_all(&bytes).await.is_err() {
                        return;
                    }
                    continue;
                }
            }
            seq += 1;
            let ping = Message::Ping(Ping {
                seq,
                sent_us: start.elapsed().as_micros() as u64,
            });
            if let Ok(bytes) = wire::encode(&ping) {
                let _ = conn.send_datagram(bytes.into());
            }
            let report = stats.lock().map(|s| s.client).unwrap_or_default();
            let Ok(bytes) = wire::encode(&Message::ClientStats(report)) else {
                return;
            };
            if send.write_all(&bytes).await.is_err() {
                return;
            }
        }
    };
    tokio::select! {
        () = reader => {}
        () = writer => {}
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The cancelled set stays bounded over a long session, whatever the
    /// order of cancellations and stream ends (issue 18 §10).
    #[test]
    fn the_cancelled_set_is_bounded() {
        let mut set = HashSet::new();
        for id in (0..100_000u64).step_by(4) {
            cancel(&mut set, &[id, id + 1]);
        }
        assert!(
            set.len() <= 2 * CANCELLED_SPAN as usize / 4 + 2,
            "{}",
            set.len()
        );
        assert!(set.contains(&99_997) && !set.contains(&1));
        // A stream's reader forgets its own id when it ends.
        let shared = Mutex::new(set);
        drop(Forget(&shared, 99_997));
        assert!(!shared.lock().unwrap().contains(&99_997));
    }
}
