//! The recording reader: MCAP bytes → `McapReader` (magic, footer and summary, then the `mcap`
//! crate's streaming reader through zstd/lz4/plain chunks) → `SampleReader` (channel
//! conventions, CDR and JSON samples, schema compatibility), as `navsync replay` and the
//! clients read a file.
//!
//! Checks: no panic; the reader's position never passes the file's end; every message's
//! channel exists; a scan that ends without error reports how it ended; the sample reader
//! yields at most as many samples as there are messages.
#![no_main]

use std::io::Cursor;
use std::path::Path;

use libfuzzer_sys::fuzz_target;
use navsync_recording::{McapReader, SampleReader};

/// Calls per scan, a bound for inputs that would make the reader loop.
const MAX_STEPS: usize = 100_000;

fuzz_target!(|data: &[u8]| {
    let path = Path::new("fuzz.mcap");
    let Ok(mut r) = McapReader::new(Cursor::new(data), path) else {
        return;
    };
    assert_eq!(r.file_len(), data.len() as u64);
    let _ = (r.header(), r.summary().map(|s| s.channels.len()));
    let mut messages = 0usize;
    let mut clean = false;
    for step in 0.. {
        assert!(step < MAX_STEPS, "the scan does not end");
        match r.next_message() {
            Ok(Some(m)) => {
                messages += 1;
                assert!(
                    m.offset <= data.len() as u64,
                    "message at {} in {} bytes",
                    m.offset,
                    data.len()
                );
                if let Some(s) = m.schema {
                    assert_eq!(s.id, m.channel.schema_id);
                }
            }
            Ok(None) => {
                assert!(r.scan_end().is_some(), "the end of the scan says how it ended");
                clean = true;
                break;
            }
            Err(e) => {
                assert!(!e.to_string().is_empty());
                break;
            }
        }
        assert!(r.position() <= r.file_len(), "{} past {}", r.position(), r.file_len());
    }
    for ch in r.channels() {
        assert_eq!(r.channel(ch.id).map(|c| c.id), Some(ch.id));
    }

    // The same file through the sample reader.
    let Ok(mcap) = McapReader::new(Cursor::new(data), path) else {
        panic!("a file that opened once opens again");
    };
    let mut s = SampleReader::from_mcap(mcap);
    let mut samples = 0usize;
    while let Ok(Some(x)) = s.next_sample() {
        samples += 1;
        // Both scans meet the same messages (and the same damage): samples are a subset.
        assert!(samples <= messages, "more samples than messages");
        let _ = x.sample;
    }
    if clean && samples < messages {
        let _ = s.skipped_channels();
    }
});
