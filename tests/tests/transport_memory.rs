//! The server's memory before authentication, alone in its test binary:
//! it measures the process's resident memory, which the other loopback
//! tests, run in parallel threads of one binary, would grow too (a
//! clean-clone CI run failed it at 35 MiB for 32 connections while it
//! shared `transport.rs` with them; alone here it passed every run).

mod loopback;

use std::time::Duration;

use loopback::*;
use protocol::Codec;
use protocol::wire::StreamBuffer;

/// The process's resident memory, bytes (Linux).
fn resident_bytes() -> u64 {
    let statm = std::fs::read_to_string("/proc/self/statm").unwrap();
    let pages: u64 = statm.split_whitespace().nth(1).unwrap().parse().unwrap();
    pages * 4096
}

/// Before authentication the server reads nothing but a `Hello` (issue 18
/// §1–2): 32 unauthenticated clients each announce a 500 MiB payload and
/// push 4 MiB of it. Each is refused from the 8-byte header at once (not
/// by the hello timeout), the server's memory does not grow by a MiB per
/// connection, a client cannot open a stream besides its control stream,
/// and a healthy client is not disturbed.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn only_a_hello_is_read_before_authentication() {
    let fx = fixture(StreamBuffer::default_set(Codec::Zstd).to_vec()).await;
    let healthy = client::connect(fx.config()).await.unwrap();
    let header = [
        &(500u32 << 20).to_le_bytes()[..],
        &protocol::wire::WIRE_VERSION.to_le_bytes(),
        &(protocol::wire::MessageKind::Payload as u16).to_le_bytes(),
    ]
    .concat();
    let body = vec![0x5au8; 4 << 20];
    const CLIENTS: u64 = 32;
    let before = resident_bytes();
    let started = std::time::Instant::now();
    let mut held = Vec::new();
    for _ in 0..CLIENTS {
        let (endpoint, conn) = raw_connection(&fx, 8).await;
        let (mut send, _recv) = conn.open_bi().await.unwrap();
        send.write_all(&header).await.unwrap();
        let _ = tokio::time::timeout(Duration::from_secs(1), send.write_all(&body)).await;
        held.push((endpoint, conn, send));
    }
    let grown = resident_bytes().saturating_sub(before);
    for (_, conn, _) in &held {
        let reason = tokio::time::timeout(Duration::from_secs(10), conn.closed())
            .await
            .unwrap()
            .to_string();
        assert!(reason.contains("Payload"), "{reason}");
    }
    let took = started.elapsed();
    assert!(
        took < host::serve::HELLO_TIMEOUT,
        "refused by the timeout, not from the header: {took:?}"
    );
    assert!(
        grown < CLIENTS << 20,
        "resident memory grew {} KiB for {CLIENTS} connections",
        grown >> 10
    );
    // One stream per client: a second bidirectional or any unidirectional
    // stream is never admitted.
    let (_endpoint, conn) = raw_connection(&fx, 8).await;
    let (mut send, _recv) = conn.open_bi().await.unwrap();
    send.write_all(&hello_bytes()).await.unwrap();
    let extra_bi = tokio::time::timeout(Duration::from_millis(500), conn.open_bi()).await;
    let extra_uni = tokio::time::timeout(Duration::from_millis(500), conn.open_uni()).await;
    assert!(
        extra_bi.is_err() && extra_uni.is_err(),
        "a second stream opened"
    );
    for (endpoint, _, _) in held {
        endpoint.close(0u32.into(), b"");
    }
    every_frame_then_shut_down(fx, healthy).await;
}
