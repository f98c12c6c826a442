//! The QUIC streaming endpoint (DESIGN §7).
//!
//! Per connection: the client opens the control stream and sends a
//! [`Hello`]; the server answers [`Welcome`] or [`Reject`] (then closes).
//! After a welcome every frame goes out on a unidirectional stream of its
//! own, at most [`MAX_IN_FLIGHT`] at a time: when a client cannot keep up,
//! new frames are dropped for it (and counted) instead of queueing, so a slow
//! client costs the others nothing. Stats go both ways on the control
//! stream; pings and input arrive as datagrams.

use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use protocol::Limits;
use protocol::wire::{self, Decoder, Hello, Message, MessageKind, Pong, ServerStats};
use tokio::sync::{Semaphore, broadcast};

use crate::input::{InputCounts, InputGate};
use crate::recovery::{Decision, Recovery};
use crate::session::{self, Policy};
use crate::source::{Feed, KeyframeRequests};
use crate::tls::Identity;

/// Most frame streams one client may have open at once.
pub const MAX_IN_FLIGHT: usize = 3;
/// Connections a server holds at once, sessions and handshakes together,
/// for a cap of `max_sessions` sessions: one more is refused at the QUIC
/// level, before any TLS work.
pub fn max_connections(max_sessions: usize) -> usize {
    max_sessions.saturating_mul(2).saturating_add(16)
}

/// How long a client has to send its hello.
pub const HELLO_TIMEOUT: Duration = Duration::from_secs(5);

/// QUIC application error codes used when closing.
pub mod close_code {
    /// Normal end.
    pub const DONE: u32 = 0;
    /// The handshake was refused (the reason was sent first).
    pub const REJECTED: u32 = 1;
    /// The peer broke the protocol.
    pub const PROTOCOL: u32 = 2;
    /// The server is shutting down.
    pub const SHUTDOWN: u32 = 3;
}

/// Per-client counters, shared with the server for reports.
#[derive(Debug, Default)]
pub struct ClientCounters {
    /// Frame streams completed.
    pub sent: AtomicU64,
    /// Frames dropped because the client was behind.
    pub dropped: AtomicU64,
    /// Payload bytes written.
    pub bytes: AtomicU64,
    /// Frames held back while the client waited for a keyframe.
    pub held_back: AtomicU64,
    /// Keyframe requests the client sent.
    pub keyframe_requests: AtomicU64,
    /// Set by a keyframe request, taken by the session.
    lost: std::sync::atomic::AtomicBool,
    /// What the session's input gate did.
    pub input: std::sync::Mutex<InputCounts>,
}

/// Server-wide counters.
#[derive(Debug, Default)]
pub struct ServerCounters {
    /// Connections accepted into a session.
    pub sessions: AtomicU64,
    /// Connections refused or broken during the handshake.
    pub refused: AtomicU64,
    /// Frames sent over all sessions.
    pub frames_sent: AtomicU64,
    /// Frames dropped over all sessions.
    pub frames_dropped: AtomicU64,
}

/// A running endpoint.
pub struct Server {
    endpoint: quinn::Endpoint,
    /// Counters over all sessions.
    pub counters: Arc<ServerCounters>,
    accept: tokio::task::JoinHandle<()>,
}

impl Server {
    /// Binds `addr` and serves frames from `feed` to every client that
    /// passes `policy`.
    pub fn start(
        addr: SocketAddr,
        identity: &Identity,
        policy: Policy,
        feed: Feed,
    ) -> std::io::Result<Self> {
        if policy.token.is_empty() {
            return Err(std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                "the access token is empty: it would admit no one (or, compared naively, anyone)",
            ));
        }
        let config = identity
            .quic_server_config(policy.congestion)
            .map_err(std::io::Error::other)?;
        let endpoint = quinn::Endpoint::new(
            identity.quic_endpoint_config(),
            Some(config),
            std::net::UdpSocket::bind(addr)?,
            Arc::new(quinn::TokioRuntime),
        )?;
        let counters = Arc::new(ServerCounters::default());
        let accept = tokio::spawn(accept_loop(
            endpoint.clone(),
            Arc::new(policy),
            feed,
            counters.clone(),
        ));
        Ok(Self {
            endpoint,
            counters,
            accept,
        })
    }

    /// The bound address (with the real port when 0 was asked for).
    pub fn local_addr(&self) -> std::io::Result<SocketAddr> {
        self.endpoint.local_addr()
    }

    /// Closes every connection with a reason and stops accepting.
    pub async fn shutdown(self) {
        self.endpoint
            .close(close_code::SHUTDOWN.into(), b"server shutting down");
        self.accept.abort();
        self.endpoint.wait_idle().await;
    }
}

async fn accept_loop(
    endpoint: quinn::Endpoint,
    policy: Arc<Policy>,
    feed: Feed,
    counters: Arc<ServerCounters>,
) {
    let mut next_session = 1u64;
    let connections = Arc::new(Semaphore::new(max_connections(policy.max_sessions)));
    let sessions = Arc::new(Semaphore::new(policy.max_sessions));
    while let Some(incoming) = endpoint.accept().await {
        // Address validation: a client whose address is not validated yet
        // is asked to retry with a token, so a spoofed source address makes
        // the server do no handshake work.
        if !incoming.remote_address_validated() && incoming.may_retry() {
            if let Err(e) = incoming.retry() {
                tracing::debug!("retry not sent: {e}");
            }
            continue;
        }
        let Ok(slot) = connections.clone().try_acquire_owned() else {
            counters.refused.fetch_add(1, Ordering::Relaxed);
            tracing::warn!(peer = %incoming.remote_address(), "connection refused: too many connections");
            incoming.refuse();
            continue;
        };
        let (policy, feed, counters) = (policy.clone(), feed.clone(), counters.clone());
        let sessions = sessions.clone();
        let session_id = next_session;
        next_session += 1;
        tokio::spawn(async move {
            let _slot = slot;
            let peer = incoming.remote_address();
            let caps = Caps {
                policy: &policy,
                sessions,
                counters: &counters,
            };
            match connection(incoming, caps, session_id, &feed).await {
                Ok(()) => tracing::info!(session_id, %peer, "session ended"),
                Err(e) => tracing::warn!(session_id, %peer, "session failed: {e:#}"),
            }
        });
    }
}

/// What a connection is admitted under: the policy, the session slots and
/// the counters it reports to.
struct Caps<'a> {
    policy: &'a Policy,
    sessions: Arc<Semaphore>,
    counters: &'a ServerCounters,
}

/// Sends `reject` on the control stream, lets it reach the client, then
/// closes the connection with `code`; the error is what the session
/// failed with.
async fn refuse(
    conn: &quinn::Connection,
    send: &mut quinn::SendStream,
    reject: wire::Reject,
    code: u32,
) -> anyhow::Error {
    let what = anyhow::anyhow!("refused {:?}: {}", reject.reason, reject.message);
    let sent = async {
        send.write_all(&wire::encode(&Message::Reject(reject.clone()))?)
            .await?;
        send.finish()?;
        // Let the refusal reach the client before closing.
        let _ = tokio::time::timeout(Duration::from_secs(1), send.stopped()).await;
        anyhow::Ok(())
    };
    let sent = sent.await;
    conn.close(code.into(), reject.message.as_bytes());
    match sent {
        Ok(()) => what,
        Err(e) => what.context(format!("the refusal was not sent: {e:#}")),
    }
}

/// Reads one message from a stream with a decoder, within `limits`.
async fn read_message(
    recv: &mut quinn::RecvStream,
    decoder: &mut Decoder,
) -> anyhow::Result<Option<Message>> {
    loop {
        if let Some(m) = decoder.next_message()? {
            return Ok(Some(m));
        }
        match recv.read_chunk(64 * 1024, true).await? {
            Some(chunk) => decoder.feed(&chunk.bytes),
            None => return Ok(None),
        }
    }
}

async fn connection(
    incoming: quinn::Incoming,
    caps: Caps<'_>,
    session_id: u64,
    feed: &Feed,
) -> anyhow::Result<()> {
    let Caps {
        policy,
        sessions,
        counters,
    } = caps;
    // The timeout covers the TLS handshake too: a peer that stalls it
    // holds no slot longer than one that never says hello.
    let mut connected = None;
    let handshake = async {
        let conn = incoming.await?;
        connected = Some(conn.clone());
        let (send, mut recv) = conn.accept_bi().await?;
        // Nothing but a Hello, refused from its header otherwise, and no
        // control message above a few KiB, before and after authentication.
        let mut decoder = Decoder::accepting(Limits::control(), &[MessageKind::Hello]);
        let hello = match read_message(&mut recv, &mut decoder).await {
            Ok(Some(Message::Hello(h))) => Ok(h),
            Ok(Some(other)) => Err(anyhow::anyhow!("expected Hello, got {:?}", other.kind())),
            Ok(None) => Err(anyhow::anyhow!("control stream ended before Hello")),
            Err(e) => Err(e),
        };
        anyhow::Ok((conn, send, recv, decoder, hello))
    };
    let (conn, mut send, recv, mut decoder, hello) =
        match tokio::time::timeout(HELLO_TIMEOUT, handshake).await {
            Ok(r) => r?,
            Err(_) => {
                counters.refused.fetch_add(1, Ordering::Relaxed);
                if let Some(conn) = connected {
                    conn.close(close_code::PROTOCOL.into(), b"no hello in time");
                }
                anyhow::bail!("no hello within {HELLO_TIMEOUT:?}");
            }
        };
    decoder.accept_only(&[
        MessageKind::ClientStats,
        MessageKind::Bye,
        MessageKind::KeyframeRequest,
    ]);
    let hello: Hello = match hello {
        Ok(h) => h,
        Err(e) => {
            counters.refused.fetch_add(1, Ordering::Relaxed);
            let reason = format!("bad hello: {e:#}");
            // A client of another wire version gets told which one we speak.
            let code = match e.downcast_ref::<wire::WireError>() {
                Some(wire::WireError::UnsupportedVersion { supported, .. }) => {
                    wire::RejectReason::UnsupportedVersion { server: *supported }
                }
                _ => wire::RejectReason::BadRequest,
            };
            let reject = wire::Reject::new(code, reason);
            return Err(refuse(&conn, &mut send, reject, close_code::PROTOCOL).await);
        }
    };
    // An authenticated client beyond the session cap is told so.
    let admitted = session::answer(policy, &hello, session_id).and_then(|w| {
        let slot = sessions.try_acquire_owned().map_err(|_| {
            let most = policy.max_sessions;
            wire::Reject::new(
                wire::RejectReason::ServerFull,
                format!("the server serves {most} sessions at most"),
            )
        })?;
        Ok((w, slot))
    });
    let (welcome, _session_slot) = match admitted {
        Ok(w) => w,
        Err(reject) => {
            counters.refused.fetch_add(1, Ordering::Relaxed);
            return Err(refuse(&conn, &mut send, reject, close_code::REJECTED).await);
        }
    };
    // Subscribed before the welcome, so a live stream loses nothing after
    // it; a per-session source starts here and stops with the session.
    // A per-session source opens its dump and starts its (paused)
    // producer thread off the runtime, and is stopped and joined off it at
    // the end. One that cannot start (an interactive renderer without a
    // usable GPU) is a refusal with the reason, not a bare close.
    let subscription = {
        let feed = feed.clone();
        tokio::task::spawn_blocking(move || feed.subscribe()).await?
    };
    let subscription = match subscription {
        Ok(s) => s,
        Err(e) => {
            counters.refused.fetch_add(1, Ordering::Relaxed);
            let reject = wire::Reject::new(
                wire::RejectReason::Unavailable,
                format!("the server could not start this session's stream: {e:#}"),
            );
            return Err(refuse(&conn, &mut send, reject, close_code::REJECTED).await);
        }
    };
    counters.sessions.fetch_add(1, Ordering::Relaxed);
    tracing::info!(session_id, client = %hello.client_name, "session started");
    let (mut rx, keyframes, viewer) = (
        subscription.frames,
        subscription.keyframes,
        subscription.viewer,
    );
    let mut source = JoinedOffRuntime(subscription.source);
    // The client starts from a keyframe: ask for one now.
    let mut recovery = Recovery::new();
    ask_keyframe(&mut recovery, &keyframes, Instant::now());
    send.write_all(&wire::encode(&Message::Welcome(welcome))?)
        .await?;
    // A per-session replay paces from here, not from before the welcome:
    // its first frames do not pile up while the client is still reading it.
    if let Some(s) = source.0.as_mut() {
        s.resume();
    }

    let client = Arc::new(ClientCounters::default());
    let control = tokio::spawn(control_loop(
        conn.clone(),
        send,
        recv,
        decoder,
        client.clone(),
    ));
    let datagrams = tokio::spawn(datagram_loop(
        conn.clone(),
        InputGate::new(feed.input_limits()),
        viewer,
        client.clone(),
    ));
    let permits = Arc::new(Semaphore::new(MAX_IN_FLIGHT));
    // Signalled (dropped) when the last frame's stream is open.
    let mut previous_opened = tokio::sync::oneshot::channel::<()>().1;
    let result = loop {
        let frame = tokio::select! {
            r = rx.recv() => r,
            reason = conn.closed() => {
                tracing::debug!(session_id, "closed: {reason}");
                break Ok::<_, anyhow::Error>(());
            }
        };
        let now = Instant::now();
        if client.lost.swap(false, Ordering::Relaxed) {
            recovery.lost();
        }
        let frame = match frame {
            Ok(f) => f,
            Err(broadcast::error::RecvError::Lagged(n)) => {
                client.dropped.fetch_add(n, Ordering::Relaxed);
                counters.frames_dropped.fetch_add(n, Ordering::Relaxed);
                recovery.lost();
                ask_keyframe(&mut recovery, &keyframes, now);
                continue;
            }
            Err(broadcast::error::RecvError::Closed) => {
                // A finite source ended: let the frames in flight arrive
                // (each permit is held until its stream is acknowledged),
                // then close.
                let all = MAX_IN_FLIGHT as u32;
                let _ =
                    tokio::time::timeout(Duration::from_secs(10), permits.acquire_many(all)).await;
                conn.close(close_code::DONE.into(), b"end of stream");
                break Ok(());
            }
        };
        if recovery.on_frame(frame.keyframe) == Decision::Skip {
            // Predicted from a frame the client does not have.
            client.held_back.fetch_add(1, Ordering::Relaxed);
            ask_keyframe(&mut recovery, &keyframes, now);
            continue;
        }
        let Ok(permit) = permits.clone().try_acquire_owned() else {
            // The client is behind: drop this frame rather than queue it.
            client.dropped.fetch_add(1, Ordering::Relaxed);
            counters.frames_dropped.fetch_add(1, Ordering::Relaxed);
            recovery.lost();
            ask_keyframe(&mut recovery, &keyframes, now);
            continue;
        };
        let conn = conn.clone();
        let client = client.clone();
        // Streams are opened in frame order, each task after the one
        // before: a client of video-coded colour waits for a frame on a
        // stream opened before a newer one's (`client::Order::Every`).
        let (opened, next) = tokio::sync::oneshot::channel::<()>();
        let before = std::mem::replace(&mut previous_opened, next);
        // Older frames first: a frame's stream completes before a newer
        // one's, so a video decoder gets them in order.
        let priority = i32::try_from(frame.index).map_or(i32::MIN, |i| -i);
        tokio::spawn(async move {
            let _permit = permit;
            let sent = async {
                // Done or given up, the task before has opened its stream.
                let _ = before.await;
                let stream = conn.open_uni().await;
                drop(opened);
                let mut stream = stream?;
                stream.set_priority(priority)?;
                stream.write_all(&frame.bytes).await?;
                stream.finish()?;
                // Hold the in-flight slot until the client has acknowledged
                // the whole frame (or stopped the stream).
                let _ = stream.stopped().await;
                anyhow::Ok(())
            };
            match sent.await {
                Ok(()) => {
                    client.sent.fetch_add(1, Ordering::Relaxed);
                    client
                        .bytes
                        .fetch_add(frame.bytes.len() as u64, Ordering::Relaxed);
                }
                Err(e) => tracing::debug!("frame {} not sent: {e:#}", frame.index),
            }
        });
    };
    counters
        .frames_sent
        .fetch_add(client.sent.load(Ordering::Relaxed), Ordering::Relaxed);
    tracing::debug!(
        session_id,
        held_back = client.held_back.load(Ordering::Relaxed),
        keyframe_requests = client.keyframe_requests.load(Ordering::Relaxed),
        "session counters"
    );
    let input = client.input.lock().map(|c| *c).unwrap_or_default();
    if input != InputCounts::default() {
        tracing::info!(session_id, ?input, "viewer input");
    }
    control.abort();
    datagrams.abort();
    result
}

/// A per-session source, stopped and joined on a blocking thread when the
/// session ends however it ends (its drop waits for the frame being read
/// or rendered, which must not hold a runtime worker).
struct JoinedOffRuntime(Option<crate::source::Source>);

impl Drop for JoinedOffRuntime {
    fn drop(&mut self) {
        if let Some(source) = self.0.take() {
            match tokio::runtime::Handle::try_current() {
                Ok(runtime) => {
                    runtime.spawn_blocking(move || drop(source));
                }
                Err(_) => drop(source),
            }
        }
    }
}

/// Asks the producer for a keyframe when the session's recovery is due to
/// ([`Recovery::ask`]: while its client waits for one, at most every
/// [`crate::recovery::KEYFRAME_RETRY`]).
fn ask_keyframe(recovery: &mut Recovery, keyframes: &KeyframeRequests, now: Instant) {
    if recovery.ask(now) {
        keyframes.request();
    }
}

/// Sends [`ServerStats`] every second and reads the client's messages.
async fn control_loop(
    conn: quinn::Connection,
    mut send: quinn::SendStream,
    mut recv: quinn::RecvStream,
    mut decoder: Decoder,
    client: Arc<ClientCounters>,
) {
    let reader = async {
        while let Ok(Some(msg)) = read_message(&mut recv, &mut decoder).await {
            match msg {
                Message::ClientStats(s) => tracing::debug!(?s, "client stats"),
                Message::KeyframeRequest(k) => {
                    tracing::debug!(last_decoded = ?k.last_decoded, "keyframe requested");
                    client.keyframe_requests.fetch_add(1, Ordering::Relaxed);
                    client.lost.store(true, Ordering::Relaxed);
                }
                Message::Bye(b) => {
                    conn.close(close_code::DONE.into(), b.reason.as_bytes());
                    return;
                }
                other => {
                    conn.close(
                        close_code::PROTOCOL.into(),
                        format!("unexpected {:?}", other.kind()).as_bytes(),
                    );
                    return;
                }
            }
        }
    };
    let writer = async {
        let mut tick = tokio::time::interval(Duration::from_secs(1));
        loop {
            tick.tick().await;
            let stats = Message::ServerStats(ServerStats {
                frames_sent: client.sent.load(Ordering::Relaxed),
                frames_dropped: client.dropped.load(Ordering::Relaxed),
                bytes_sent: client.bytes.load(Ordering::Relaxed),
            });
            let Ok(bytes) = wire::encode(&stats) else {
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

/// Answers pings; passes input through the session's gate to its viewer
/// camera (interactive feeds; otherwise input is only counted).
async fn datagram_loop(
    conn: quinn::Connection,
    mut gate: InputGate,
    viewer: Option<crate::source::ViewerSender>,
    client: Arc<ClientCounters>,
) {
    let limits = Limits::control();
    while let Ok(d) = conn.read_datagram().await {
        let decoded = wire::decode_message(&d, &limits);
        match &decoded {
            Ok((Message::Input(i), _)) => {
                if let (Some(taken), Some(viewer)) = (gate.admit(i, Instant::now()), &viewer) {
                    viewer.send_replace(Some(taken));
                }
            }
            Ok(_) => {}
            // Bad input, or garbage: counted with the inputs refused.
            Err(_) => gate.invalid(),
        }
        if let Ok(mut c) = client.input.lock() {
            *c = gate.counts();
        }
        match decoded {
            Ok((Message::Ping(p), _)) => {
                let pong = Message::Pong(Pong {
                    seq: p.seq,
                    sent_us: p.sent_us,
                });
                if let Ok(bytes) = wire::encode(&pong) {
                    let _ = conn.send_datagram(bytes.into());
                }
            }
            Ok((Message::Input(i), _)) => tracing::trace!(seq = i.seq, "input"),
            Ok((other, _)) => tracing::debug!("ignored datagram {:?}", other.kind()),
            Err(e) => tracing::debug!("bad datagram: {e}"),
        }
    }
}
