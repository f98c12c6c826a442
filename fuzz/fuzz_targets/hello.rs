//! The server's answer to a client's first message: arbitrary bytes are
//! decoded as the server decodes them before authentication (only a
//! `Hello`, control-stream limits) and answered by `host::session::answer`.
//! It must not panic, and a welcome it gives must be one a client accepts:
//! valid under the default limits and the same after a round trip.
#![no_main]

use host::session::{Policy, answer};
use libfuzzer_sys::fuzz_target;
use protocol::wire::{self, Decoder, Message, MessageKind, StreamBuffer, WindowMode};
use protocol::{Codec, FrameSize, Limits};

fuzz_target!(|data: &[u8]| {
    let policy = Policy {
        // The seed Hello's token, so that fuzzing reaches past the check.
        token: "fuzz-token".into(),
        server_name: "fuzz".into(),
        size: FrameSize::new(16, 9),
        max_frame: FrameSize::new(20, 12),
        fps: 30.0,
        buffers: StreamBuffer::default_set(Codec::Zstd).to_vec(),
        window_mode: WindowMode::KeepDensity,
        max_sessions: 1,
        congestion: host::tls::Congestion::default(),
        effects: protocol::Effects::UNKNOWN,
    };
    let mut decoder = Decoder::accepting(Limits::control(), &[MessageKind::Hello]);
    decoder.feed(data);
    let Ok(Some(Message::Hello(hello))) = decoder.next_message() else {
        return;
    };
    if let Ok(welcome) = answer(&policy, &hello, 7) {
        let message = Message::Welcome(welcome);
        assert!(message.validate(&Limits::default()).is_ok());
        let bytes = wire::encode(&message).expect("a welcome encodes");
        let (back, used) = wire::decode_message(&bytes, &Limits::default()).expect("and decodes");
        assert_eq!((back, used), (message, bytes.len()));
    }
});
