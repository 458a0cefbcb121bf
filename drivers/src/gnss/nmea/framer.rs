//! Splits a serial byte stream into NMEA sentences.
//!
//! An NMEA 0183 sentence (IEC 61162-1 §7.3) starts with `$` (or `!` for encapsulated
//! sentences such as AIS), holds printable ASCII (0x20..=0x7E), and ends with `<CR><LF>`.
//! NMEA allows at most 82 characters including `$` and `<CR><LF>`, but real receivers exceed
//! that (gpsd accepts up to 102; high-precision GGA reaches ~92); this framer accepts up to
//! [`MAX_SENTENCE_LEN`] characters and drops longer ones.
//!
//! The framer does not look inside a sentence (checksums and fields are the job of
//! [`super::epoch::EpochAssembler`]); it only delimits sentences, stamps each with the
//! host time of its first byte, and counts what it had to throw away. It never allocates:
//! the sentence being assembled lives in a fixed internal buffer.

/// Longest sentence delivered, in characters from `$`/`!` up to (not including) CR/LF.
///
/// NMEA 0183 says 80 (82 with CR/LF); gpsd accepts 102; 256 leaves room for long proprietary
/// sentences while still bounding garbage.
pub const MAX_SENTENCE_LEN: usize = 256;

/// One complete sentence, as delivered by [`LineFramer::push`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Sentence<'a> {
    /// The sentence from its leading `$`/`!` up to (not including) the line terminator;
    /// printable ASCII only. Checksum not yet verified.
    pub text: &'a [u8],
    /// Estimated host time (`CLOCK_MONOTONIC`, ns) at which the sentence's first byte
    /// arrived.
    pub host_ns: i64,
}

/// What the framer has seen and dropped since it was created.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FramerCounters {
    /// Bytes pushed.
    pub bytes: u64,
    /// Sentences delivered.
    pub sentences: u64,
    /// Bytes outside any sentence, other than line terminators (binary noise, line noise).
    pub noise_bytes: u64,
    /// Sentences cut short by the start of another (`$`/`!` before CR/LF); dropped.
    pub truncated: u64,
    /// Sentences longer than [`MAX_SENTENCE_LEN`]; dropped up to the next terminator.
    pub overlong: u64,
    /// Sentences that contained a byte that is not printable ASCII; dropped.
    pub non_ascii: u64,
}

impl FramerCounters {
    /// The counters with short names for a `Health` report (names ≤ 24 bytes).
    pub fn named(&self) -> [(&'static str, u64); 6] {
        [
            ("nmea_bytes", self.bytes),
            ("nmea_sentences", self.sentences),
            ("nmea_noise_bytes", self.noise_bytes),
            ("nmea_truncated", self.truncated),
            ("nmea_overlong", self.overlong),
            ("nmea_non_ascii", self.non_ascii),
        ]
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum State {
    /// Between sentences: waiting for `$` or `!`.
    Hunt,
    /// Inside a sentence, collecting bytes into the buffer.
    Collect,
    /// Dropping the rest of an over-long sentence up to the next terminator or start.
    Discard,
}

/// Byte stream → sentences, each stamped with the host time of its first byte.
///
/// Feed it whatever `read()` returned, in order; sentences split across reads are
/// reassembled. See [`LineFramer::push`] for the time-stamp model.
#[derive(Debug, Clone)]
pub struct LineFramer {
    buf: [u8; MAX_SENTENCE_LEN],
    len: usize,
    state: State,
    /// Host time of the first byte of the sentence being collected, ns.
    start_ns: i64,
    counters: FramerCounters,
}

impl Default for LineFramer {
    fn default() -> Self {
        Self::new()
    }
}

impl LineFramer {
    /// A framer waiting for the start of a sentence.
    pub fn new() -> Self {
        Self {
            buf: [0; MAX_SENTENCE_LEN],
            len: 0,
            state: State::Hunt,
            start_ns: 0,
            counters: FramerCounters::default(),
        }
    }

    /// Counters since creation.
    pub fn counters(&self) -> &FramerCounters {
        &self.counters
    }

    /// Host time of byte `index` of a chunk of `chunk_len` bytes whose read returned at
    /// `read_host_ns`: the last byte arrived at `read_host_ns`, each earlier one
    /// `ns_per_byte` before its successor (bytes arrive at the line rate).
    pub fn byte_time_ns(read_host_ns: i64, chunk_len: usize, index: usize, ns_per_byte: i64) -> i64 {
        let after = chunk_len.saturating_sub(index + 1);
        let after = i64::try_from(after).unwrap_or(i64::MAX);
        read_host_ns.saturating_sub(after.saturating_mul(ns_per_byte))
    }

    /// Consumes one chunk of received bytes and calls `out` for every sentence it completes.
    ///
    /// - `read_host_ns`: host time (`CLOCK_MONOTONIC`, ns) at which the read that returned
    ///   `bytes` completed, i.e. (approximately) when its last byte arrived;
    /// - `ns_per_byte`: duration of one character on the line, ns (10 bits per character:
    ///   `10e9 / baud`, e.g. 1_041_667 at 9600 Bd); 0 on a pseudo-terminal.
    ///
    /// A sentence's `host_ns` is the time of its first byte,
    /// `read_host_ns − (bytes after it in this chunk) × ns_per_byte`; for a sentence that
    /// started in an earlier chunk, that chunk's estimate is kept.
    pub fn push(&mut self, bytes: &[u8], read_host_ns: i64, ns_per_byte: i64, out: &mut impl FnMut(Sentence<'_>)) {
        self.counters.bytes += bytes.len() as u64;
        for (i, &b) in bytes.iter().enumerate() {
            match self.state {
                State::Hunt => match b {
                    b'$' | b'!' => self.start(b, Self::byte_time_ns(read_host_ns, bytes.len(), i, ns_per_byte)),
                    b'\r' | b'\n' => {}
                    _ => self.counters.noise_bytes += 1,
                },
                State::Collect => match b {
                    b'\r' | b'\n' => self.finish(out),
                    b'$' | b'!' => {
                        self.counters.truncated += 1;
                        self.start(b, Self::byte_time_ns(read_host_ns, bytes.len(), i, ns_per_byte));
                    }
                    0x20..=0x7e => {
                        if self.len == MAX_SENTENCE_LEN {
                            self.counters.overlong += 1;
                            self.state = State::Discard;
                        } else {
                            self.buf[self.len] = b;
                            self.len += 1;
                        }
                    }
                    _ => {
                        // A control or 8-bit byte inside a sentence: the line is corrupt.
                        self.counters.non_ascii += 1;
                        self.counters.noise_bytes += 1;
                        self.len = 0;
                        self.state = State::Hunt;
                    }
                },
                State::Discard => match b {
                    b'\r' | b'\n' => self.state = State::Hunt,
                    b'$' | b'!' => self.start(b, Self::byte_time_ns(read_host_ns, bytes.len(), i, ns_per_byte)),
                    _ => {}
                },
            }
        }
    }

    /// Drops a partly received sentence (e.g. after the port was reopened).
    pub fn reset(&mut self) {
        self.len = 0;
        self.state = State::Hunt;
    }

    fn start(&mut self, first: u8, host_ns: i64) {
        self.buf[0] = first;
        self.len = 1;
        self.start_ns = host_ns;
        self.state = State::Collect;
    }

    fn finish(&mut self, out: &mut impl FnMut(Sentence<'_>)) {
        self.state = State::Hunt;
        let len = std::mem::take(&mut self.len);
        self.counters.sentences += 1;
        out(Sentence {
            text: &self.buf[..len],
            host_ns: self.start_ns,
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Pushes `chunks` (each read at the given host time) and collects (text, host_ns).
    fn frame(framer: &mut LineFramer, chunks: &[(&[u8], i64)], ns_per_byte: i64) -> Vec<(String, i64)> {
        let mut got = Vec::new();
        for (bytes, t) in chunks {
            framer.push(bytes, *t, ns_per_byte, &mut |s| {
                got.push((String::from_utf8_lossy(s.text).into_owned(), s.host_ns))
            });
        }
        got
    }

    #[test]
    fn splits_lines_and_stamps_first_byte() {
        let mut f = LineFramer::new();
        // 2 sentences of 10 + 2 bytes each in one 24-byte chunk read at t = 1_000_000.
        let chunk = b"$GPAAA,1*0\r\n$GPBBB,2*0\r\n";
        let got = frame(&mut f, &[(chunk, 1_000_000)], 100);
        assert_eq!(got.len(), 2);
        assert_eq!(got[0].0, "$GPAAA,1*0");
        // First `$` is byte 0: 23 bytes after it.
        assert_eq!(got[0].1, 1_000_000 - 23 * 100);
        // Second `$` is byte 12: 11 bytes after it.
        assert_eq!(got[1].1, 1_000_000 - 11 * 100);
        assert_eq!(f.counters().sentences, 2);
        assert_eq!(f.counters().noise_bytes, 0);
    }

    #[test]
    fn sentence_across_reads_keeps_first_chunk_stamp() {
        let mut f = LineFramer::new();
        let got = frame(&mut f, &[(b"xx$GPG", 5_000), (b"GA,1*00\r\n", 9_000)], 10);
        assert_eq!(got, vec![("$GPGGA,1*00".to_string(), 5_000 - 3 * 10)]);
        assert_eq!(f.counters().noise_bytes, 2);
    }

    #[test]
    fn pty_rate_zero_stamps_read_time() {
        let mut f = LineFramer::new();
        let got = frame(&mut f, &[(b"$A*00\n$B*00\n", 77)], 0);
        assert_eq!(got.iter().map(|g| g.1).collect::<Vec<_>>(), vec![77, 77]);
    }

    #[test]
    fn truncated_sentence_is_dropped_and_counted() {
        let mut f = LineFramer::new();
        let got = frame(&mut f, &[(b"$GPGGA,12345$GPRMC,1*00\r\n", 0)], 0);
        assert_eq!(got.len(), 1);
        assert_eq!(got[0].0, "$GPRMC,1*00");
        assert_eq!(f.counters().truncated, 1);
    }

    #[test]
    fn noise_between_sentences_is_counted() {
        let mut f = LineFramer::new();
        let got = frame(&mut f, &[(b"\xb5\x62\x01\x02abc\r\n$GPZDA*00\r\n\r\n\x00", 0)], 0);
        assert_eq!(got.len(), 1);
        assert_eq!(f.counters().noise_bytes, 8);
    }

    #[test]
    fn non_ascii_inside_sentence_drops_it() {
        let mut f = LineFramer::new();
        let got = frame(&mut f, &[(b"$GPRMC,000346.03,A,4808\x00\x00 x\r\n$GPZDA*00\r\n", 0)], 0);
        assert_eq!(got.len(), 1);
        assert_eq!(got[0].0, "$GPZDA*00");
        assert_eq!(f.counters().non_ascii, 1);
    }

    #[test]
    fn overlong_sentence_is_dropped_until_terminator() {
        let mut f = LineFramer::new();
        let mut long = b"$GPTXT,".to_vec();
        long.extend(std::iter::repeat_n(b'A', 400));
        long.extend_from_slice(b"\r\n$GPZDA*00\r\n");
        let got = frame(&mut f, &[(&long, 0)], 0);
        assert_eq!(got.len(), 1);
        assert_eq!(got[0].0, "$GPZDA*00");
        assert_eq!(f.counters().overlong, 1);
        // Exactly MAX_SENTENCE_LEN characters is still accepted.
        let mut max = b"$".to_vec();
        max.extend(std::iter::repeat_n(b'B', MAX_SENTENCE_LEN - 1));
        max.extend_from_slice(b"\n");
        let got = frame(&mut f, &[(&max, 0)], 0);
        assert_eq!(got.len(), 1);
        assert_eq!(got[0].0.len(), MAX_SENTENCE_LEN);
    }

    #[test]
    fn overlong_then_new_start_without_terminator_resyncs() {
        let mut f = LineFramer::new();
        let mut long = b"$".to_vec();
        long.extend(std::iter::repeat_n(b'C', 300));
        long.extend_from_slice(b"$GPZDA*00\n");
        let got = frame(&mut f, &[(&long, 0)], 0);
        assert_eq!(got.len(), 1);
        assert_eq!(got[0].0, "$GPZDA*00");
    }

    #[test]
    fn random_bytes_never_panic() {
        let mut f = LineFramer::new();
        let mut x: u64 = 0x9E37_79B9_7F4A_7C15;
        let mut chunk = [0u8; 97];
        let mut n = 0u64;
        for round in 0..2_000 {
            for b in chunk.iter_mut() {
                x ^= x << 13;
                x ^= x >> 7;
                x ^= x << 17;
                *b = (x >> 24) as u8;
                // Make starts and terminators frequent enough to exercise every state.
                if *b == 1 {
                    *b = b'$';
                } else if *b == 2 {
                    *b = b'\n';
                }
            }
            f.push(&chunk, round * 1_000_000, i64::MAX / 3, &mut |s| {
                assert!(s.text.len() <= MAX_SENTENCE_LEN);
                n += 1;
            });
        }
        assert_eq!(n, f.counters().sentences);
        assert_eq!(f.counters().bytes, 2_000 * 97);
    }
}
