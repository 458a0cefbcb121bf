//! The gpsd protocol parser of `navsync gpsd-server` (`parse_commands`): what any local
//! client may send, in whatever pieces the socket delivers it.
//!
//! Checks: no panic; what is consumed lies within the buffer; every command name is ASCII
//! letters and digits in upper case; fed in pieces as the server reads them (consumed bytes
//! drained, the rest kept, at most `MAX_REQUEST_BYTES` held), the commands are those of the
//! whole input parsed at once, and the held buffer stays bounded.
#![no_main]

use libfuzzer_sys::fuzz_target;
use navsync::live::gpsd_server::{Command, MAX_REQUEST_BYTES, parse_commands};

fn check(cmds: &[Command], used: usize, len: usize) {
    assert!(used <= len, "consumed {used} of {len}");
    for c in cmds {
        assert!(
            c.name.bytes().all(|b| b.is_ascii_digit() || b.is_ascii_uppercase()),
            "{:?}",
            c.name
        );
    }
}

fuzz_target!(|data: &[u8]| {
    // The first byte chooses the piece size (1..=256), the rest is the stream.
    let Some((&k, stream)) = data.split_first() else {
        return;
    };
    let (whole, used) = parse_commands(stream);
    check(&whole, used, stream.len());

    let piece = usize::from(k) + 1;
    let mut buf: Vec<u8> = Vec::new();
    let mut pieces = Vec::new();
    let mut overflowed = false;
    for chunk in stream.chunks(piece) {
        buf.extend_from_slice(chunk);
        let (cmds, used) = parse_commands(&buf);
        check(&cmds, used, buf.len());
        buf.drain(..used);
        pieces.extend(cmds);
        if buf.len() >= MAX_REQUEST_BYTES {
            // The server answers ERROR and closes the client here.
            overflowed = true;
            break;
        }
        assert!(buf.len() < MAX_REQUEST_BYTES + piece);
    }
    if !overflowed {
        assert_eq!(pieces, whole, "pieces of {piece} bytes parse differently");
    }
});
