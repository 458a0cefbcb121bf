//! Writer and reader against each other: round trip in both encodings, summary, truncation
//! near every chunk boundary, corruption, foreign records.

use std::io::Cursor;
use std::path::Path;

use super::RecordingError;
use super::channels::Encoding;
use super::mcap_reader::{McapReader, ScanEnd};
use super::mcap_writer::{ChunkCompression, McapWriter};
use super::sample_file::{RecordingOptions, SampleReader, SampleRecorder};
use navsync_shared::reflect::Reflect;
use navsync_shared::samples::{AnySample, ImuSample, NavState, Stamp, StampSource};
use navsync_shared::services;

fn imu(i: u64) -> AnySample {
    let mut s = ImuSample::zeroed();
    s.stamp = Stamp::host(1_000_000_000 + i as i64 * 5_000_000, i, StampSource::Simulated);
    s.gyro_rps = [0.1 * i as f64, -1e-7, 3.0f64.sqrt()];
    s.accel_mps2 = [0.0, -0.0, -9.80665 + i as f64 * 1e-9];
    s.dt_s = 0.005;
    s.temperature_c = f64::NAN;
    s.imu_id[0] = b'0';
    AnySample::Imu(s)
}

fn nav(i: u64) -> AnySample {
    let mut s = NavState::zeroed();
    s.host_ns = 1_000_000_000 + i as i64 * 5_000_000;
    s.seq = i + 1;
    s.lat_deg = 48.137154 + i as f64 * 1e-9;
    s.gnss_delay_s = f64::NAN;
    AnySample::Nav(s)
}

const MAGIC: [u8; 8] = [0x89, b'M', b'C', b'A', b'P', b'0', b'\r', b'\n'];

fn options(chunk: usize) -> RecordingOptions {
    RecordingOptions {
        chunk_size: chunk,
        ..RecordingOptions::default()
    }
}

/// A recording of `n` IMU samples and states, closed properly, in small chunks.
fn recording(n: u64, chunk: usize) -> Vec<u8> {
    recording_with(n, options(chunk))
}

fn recording_with(n: u64, options: RecordingOptions) -> Vec<u8> {
    let mut r = SampleRecorder::new(Cursor::new(Vec::new()), Path::new("mem.mcap"), options).unwrap();
    for i in 0..n {
        r.write(
            &services::imu_sample("0"),
            &imu(i),
            1_700_000_000_000_000_000 + i,
            5 + i,
        )
        .unwrap();
        r.write(services::NAV_STATE, &nav(i), 1_700_000_000_000_000_000 + i, 5 + i)
            .unwrap();
    }
    r.finish().unwrap().into_inner()
}

/// (service, sample, log_time, publish_time)
type Read = (String, AnySample, u64, u64);

fn read_all(bytes: &[u8]) -> Result<(Vec<Read>, ScanEnd), RecordingError> {
    let mcap = McapReader::new(Cursor::new(bytes), Path::new("mem.mcap"))?;
    let mut r = SampleReader::from_mcap(mcap);
    let mut out = Vec::new();
    while let Some(s) = r.next_sample()? {
        out.push((s.service.to_string(), s.sample, s.log_time, s.publish_time));
    }
    Ok((out, r.scan_end().cloned().unwrap()))
}

#[test]
fn samples_round_trip_with_summary() {
    for (encoding, compression) in [
        (Encoding::Cdr, ChunkCompression::Zstd),
        (Encoding::Json, ChunkCompression::Zstd),
        (Encoding::Cdr, ChunkCompression::None),
    ] {
        let bytes = recording_with(
            50,
            RecordingOptions {
                encoding,
                compression,
                chunk_size: 2000,
                ros_std: None,
            },
        );
        round_trip_with_summary(&bytes, encoding, compression);
    }
}

fn round_trip_with_summary(bytes: &[u8], encoding: Encoding, compression: ChunkCompression) {
    assert_eq!(&bytes[..8], &MAGIC);
    assert_eq!(&bytes[bytes.len() - 8..], &MAGIC);
    let (msgs, end) = read_all(bytes).unwrap();
    assert_eq!(end, ScanEnd::Clean);
    assert_eq!(msgs.len(), 100);
    for (i, (svc, s, lt, pt)) in msgs.iter().enumerate() {
        let k = (i / 2) as u64;
        let (want_svc, want) = if i % 2 == 0 {
            (services::imu_sample("0"), imu(k))
        } else {
            (services::NAV_STATE.to_string(), nav(k))
        };
        assert_eq!(svc, &want_svc);
        assert_eq!(*lt, 1_700_000_000_000_000_000 + k);
        assert_eq!(*pt, 5 + k);
        // Bit for bit (NaN included): compare the JSON encodings and the float bits.
        assert_eq!(super::channels::sample_json(s), super::channels::sample_json(&want));
        if let (AnySample::Imu(a), AnySample::Imu(b)) = (s, &want) {
            assert_eq!(a.accel_mps2.map(f64::to_bits), b.accel_mps2.map(f64::to_bits));
        }
    }
    let mcap = McapReader::new(Cursor::new(bytes), Path::new("mem.mcap")).unwrap();
    let summary = mcap.summary().expect("summary");
    let stats = summary.statistics.as_ref().unwrap();
    assert_eq!(stats.message_count, 100);
    assert_eq!(stats.schema_count, 2);
    assert_eq!(stats.channel_count, 2);
    assert_eq!(stats.channel_message_counts, vec![(1, 50), (2, 50)]);
    assert_eq!(stats.message_start_time, 1_700_000_000_000_000_000);
    assert_eq!(stats.message_end_time, 1_700_000_000_000_000_049);
    assert!(stats.chunk_count > 3, "{} chunks", stats.chunk_count);
    assert_eq!(summary.chunk_indexes.len() as u32, stats.chunk_count);
    let (topic, schema, profile) = match encoding {
        Encoding::Cdr => ("/navsync/imu/0/sample", "navsync_msgs/msg/NavState", "ros2"),
        Encoding::Json => ("navsync/imu/0/sample", "navsync.NavState.v2", ""),
    };
    assert_eq!(summary.channels[0].topic, topic);
    assert_eq!(summary.schemas[1].name, schema);
    assert_eq!(mcap.header().profile, profile);
    let want = match compression {
        ChunkCompression::Zstd => "zstd",
        ChunkCompression::None => "",
    };
    for ci in &summary.chunk_indexes {
        assert_eq!(ci.compression, want);
        // The chunk indexes point at Chunk records (opcode 0x06) of the indexed length.
        let at = ci.chunk_start_offset as usize;
        assert_eq!(bytes[at], 0x06);
        let len = u64::from_le_bytes(bytes[at + 1..at + 9].try_into().unwrap());
        assert_eq!(ci.chunk_length, len + 9);
    }
}

/// Messages of a chunk, from its Message Index records.
fn chunk_message_count(bytes: &[u8], ci: &super::mcap_reader::ChunkIndex) -> usize {
    ci.message_index_offsets
        .iter()
        .map(|&(_, off)| {
            let at = off as usize + 9 + 2;
            u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap()) as usize / 16
        })
        .sum()
}

fn keys(msgs: &[Read]) -> Vec<String> {
    msgs.iter()
        .map(|(s, x, lt, pt)| format!("{s} {lt} {pt} {}", super::channels::sample_json(x)))
        .collect()
}

#[test]
fn a_schema_of_other_fields_is_refused_with_the_difference() {
    let mut w = McapWriter::new(
        Cursor::new(Vec::new()),
        Path::new("mem.mcap"),
        "ros2",
        "test",
        1 << 20,
        ChunkCompression::Zstd,
    )
    .unwrap();
    let kind = navsync_shared::services::ServiceKind::ImuSample;
    let text = String::from_utf8(Encoding::Cdr.schema_data(kind))
        .unwrap()
        .replace("float64 dt_s", "float32 dt_s");
    let s = w
        .add_schema(&Encoding::Cdr.schema_name(kind), "ros2msg", text.as_bytes())
        .unwrap();
    let c = w.add_channel(s, "/navsync/imu/0/sample", "cdr", &[]).unwrap();
    let mut cdr = Vec::new();
    Encoding::Cdr.encode(&imu(1), &mut cdr);
    w.write_message(c, 2, 2, &cdr).unwrap();
    let buf = w.finish().unwrap().into_inner();
    let mcap = McapReader::new(Cursor::new(&buf[..]), Path::new("mem.mcap")).unwrap();
    let mut r = SampleReader::from_mcap(mcap);
    assert!(r.next_sample().unwrap().is_none());
    let skipped = r.skipped_channels();
    assert_eq!(skipped.len(), 1);
    assert!(skipped[0].1.contains("dt_s"), "{skipped:?}");
}

#[test]
fn a_truncated_file_yields_every_complete_chunk() {
    let full = recording(40, 1500);
    let all = keys(&read_all(&full).unwrap().0);
    let mcap = McapReader::new(Cursor::new(&full[..]), Path::new("mem.mcap")).unwrap();
    let chunks = mcap.summary().unwrap().chunk_indexes.clone();
    let header_end = 8 + 9 + u64::from_le_bytes(full[9..17].try_into().unwrap()) as usize;
    // Every byte near the record boundaries that matter, and a spread in between.
    let mut cuts: Vec<usize> = (0..full.len()).step_by(101).collect();
    cuts.extend(0..header_end + 12);
    for c in &chunks {
        let (start, end) = (
            c.chunk_start_offset as usize,
            (c.chunk_start_offset + c.chunk_length) as usize,
        );
        let index_end = end + c.message_index_length as usize;
        for edge in [start, end, index_end] {
            cuts.extend(edge.saturating_sub(12)..(edge + 12).min(full.len()));
        }
    }
    cuts.extend(full.len() - 200..full.len());
    cuts.sort_unstable();
    cuts.dedup();
    let mut prev = 0;
    for cut in cuts {
        match read_all(&full[..cut]) {
            Ok((msgs, end)) => {
                assert!(cut >= header_end, "cut {cut} opened");
                let got = keys(&msgs);
                assert_eq!(got[..], all[..got.len()], "cut {cut}: not a prefix");
                assert!(got.len() >= prev, "cut {cut}: fewer messages than a shorter cut");
                prev = got.len();
                let complete: usize = chunks
                    .iter()
                    .filter(|c| (c.chunk_start_offset + c.chunk_length) as usize <= cut)
                    .map(|c| chunk_message_count(&full, c))
                    .sum();
                assert!(got.len() >= complete, "cut {cut}: {} < {complete}", got.len());
                if got.len() < all.len() {
                    assert!(matches!(end, ScanEnd::Truncated { .. }), "cut {cut}: {end:?}");
                }
            }
            Err(RecordingError::NotMcap { .. }) => assert!(cut < 8, "cut {cut}"),
            Err(RecordingError::Corrupt { record, problem, .. }) => {
                assert!(cut < header_end, "cut {cut}: {record}: {problem}")
            }
            Err(e) => panic!("cut {cut}: {e}"),
        }
    }
    assert_eq!(prev, all.len());
}

/// Reads every sample of `bytes`; the samples and the chunks skipped.
fn read_skipping(bytes: &[u8]) -> (Vec<Read>, Vec<super::mcap_reader::SkippedChunk>, ScanEnd) {
    let mcap = McapReader::new(Cursor::new(bytes), Path::new("mem.mcap")).unwrap();
    let mut r = SampleReader::from_mcap(mcap);
    let mut out = Vec::new();
    while let Some(s) = r.next_sample().unwrap() {
        out.push((s.service.to_string(), s.sample, s.log_time, s.publish_time));
    }
    (out, r.skipped_chunks().to_vec(), r.scan_end().cloned().unwrap())
}

#[test]
fn a_damaged_chunk_is_skipped_with_its_time_range_and_the_rest_is_read() {
    for compression in [ChunkCompression::None, ChunkCompression::Zstd] {
        let mut bytes = recording_with(
            20,
            RecordingOptions {
                compression,
                ..options(1000)
            },
        );
        let all = keys(&read_all(&bytes).unwrap().0);
        let chunks = mcap_chunks(&bytes);
        assert!(chunks.len() >= 3, "{compression:?}: {} chunks", chunks.len());
        let second = chunks[1].clone();
        let in_second = chunk_message_count(&bytes, &second);
        // Flip a byte inside the second chunk's records.
        let at = (second.chunk_start_offset + second.chunk_length - 10) as usize;
        bytes[at] ^= 0x55;
        let (got, skipped, end) = read_skipping(&bytes);
        assert_eq!(end, ScanEnd::Clean, "{compression:?}");
        assert_eq!(skipped.len(), 1, "{compression:?}: {skipped:?}");
        let s = &skipped[0];
        assert_eq!((s.offset, s.length), (second.chunk_start_offset, second.chunk_length));
        assert_eq!(
            (s.message_start_time, s.message_end_time),
            (second.message_start_time, second.message_end_time),
            "the time range from the summary's chunk index"
        );
        assert!(!s.problem.is_empty());
        let shown = s.to_string();
        assert!(
            shown.contains(&format!("byte offset {}", second.chunk_start_offset)),
            "{shown}"
        );
        assert!(shown.contains("2023-11-14T22:13:20"), "{shown}");
        // Every message of the other chunks, in order; none of the damaged one.
        assert_eq!(got.len(), all.len() - in_second, "{compression:?}");
        let first = chunk_message_count(&bytes, &chunks[0]);
        assert_eq!(keys(&got)[..first], all[..first]);
        assert_eq!(keys(&got)[first..], all[first + in_second..]);
    }
    // A summary that does not match its CRC is an error at the footer.
    let mut bytes = recording(5, 1000);
    let n = bytes.len();
    bytes[n - 60] ^= 1;
    let err = McapReader::new(Cursor::new(&bytes[..]), Path::new("mem.mcap"))
        .err()
        .unwrap();
    assert!(err.to_string().contains("footer's CRC"), "{err}");
    // Not an MCAP file at all.
    let err = McapReader::new(Cursor::new(&b"hello world, not mcap"[..]), Path::new("x.txt"))
        .err()
        .unwrap();
    assert!(matches!(err, RecordingError::NotMcap { .. }), "{err}");
}

fn mcap_chunks(bytes: &[u8]) -> Vec<super::mcap_reader::ChunkIndex> {
    let mcap = McapReader::new(Cursor::new(bytes), Path::new("mem.mcap")).unwrap();
    mcap.summary().unwrap().chunk_indexes.clone()
}

#[test]
fn unknown_records_and_foreign_channels_are_skipped() {
    let mut w = McapWriter::new(
        Cursor::new(Vec::new()),
        Path::new("mem.mcap"),
        "",
        "test",
        1 << 20,
        ChunkCompression::None,
    )
    .unwrap();
    let s = w.add_schema("foo.Bar", "protobuf", b"\x01\x02").unwrap();
    let foreign = w.add_channel(s, "/tf", "protobuf", &[("k", "v")]).unwrap();
    let kind = navsync_shared::services::ServiceKind::NavState;
    let s = w
        .add_schema(
            &Encoding::Cdr.schema_name(kind),
            Encoding::Cdr.schema_encoding(),
            &Encoding::Cdr.schema_data(kind),
        )
        .unwrap();
    // No navsync.layout: as another tool writes it; the schema's fields are checked instead.
    let ours = w.add_channel(s, "/navsync/nav/state", "cdr", &[]).unwrap();
    w.write_message(foreign, 1, 1, b"\x00\x01").unwrap();
    let mut cdr = Vec::new();
    Encoding::Cdr.encode(&nav(3), &mut cdr);
    w.write_message(ours, 2, 2, &cdr).unwrap();
    let buf = w.finish().unwrap().into_inner();
    let first_chunk = McapReader::new(Cursor::new(&buf[..]), Path::new("mem.mcap"))
        .unwrap()
        .summary()
        .unwrap()
        .chunk_indexes[0]
        .chunk_start_offset as usize;
    // An unknown record type before the chunk (spec: readers skip unknown opcodes), and the
    // file cut after the chunk (a writer that died).
    let mut file = buf[..first_chunk].to_vec();
    file.extend_from_slice(&[0x80, 3, 0, 0, 0, 0, 0, 0, 0, 1, 2, 3]);
    let chunk_len = 9 + u64::from_le_bytes(buf[first_chunk + 1..first_chunk + 9].try_into().unwrap()) as usize;
    file.extend_from_slice(&buf[first_chunk..first_chunk + chunk_len]);
    let (msgs, end) = read_all(&file).unwrap();
    assert!(
        matches!(end, ScanEnd::Truncated { offset, .. } if offset == file.len() as u64),
        "{end:?}"
    );
    assert_eq!(msgs.len(), 1);
    assert_eq!(msgs[0].0, services::NAV_STATE);
    assert_eq!(keys(&msgs)[0], keys(&[(services::NAV_STATE.into(), nav(3), 2, 2)])[0]);
    let mcap = McapReader::new(Cursor::new(&file[..]), Path::new("mem.mcap")).unwrap();
    let mut r = SampleReader::from_mcap(mcap);
    while r.next_sample().unwrap().is_some() {}
    assert_eq!(
        r.skipped_channels(),
        vec![("/tf".to_string(), "not a navsync service name".to_string())]
    );
}

#[test]
fn wrong_types_and_names_are_refused() {
    let mut r = SampleRecorder::new(Cursor::new(Vec::new()), Path::new("x.mcap"), options(1000)).unwrap();
    let e = r.write("navsync/imu/0/sample", &nav(0), 0, 0).unwrap_err();
    assert!(e.to_string().contains("x.mcap: a Nav"), "{e}");
    let e = r.write("/tf", &nav(0), 0, 0).unwrap_err();
    assert!(e.to_string().contains("not a navsync service"), "{e}");
}

#[test]
fn damaged_files_give_errors_not_panics() {
    let good = recording(30, 1200);
    let mut x: u64 = 0x2545_F491_4F6C_DD1D;
    let mut rand = move || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        x
    };
    let (mut ok, mut errors) = (0, 0);
    for round in 0..400 {
        let mut bytes = good.clone();
        // A few random bytes changed (lengths, opcodes, CRCs, JSON) and sometimes a cut.
        for _ in 0..1 + round % 4 {
            let at = (rand() as usize) % bytes.len();
            bytes[at] = rand() as u8;
        }
        if round % 3 == 0 {
            let cut = (rand() as usize) % bytes.len();
            bytes.truncate(cut);
        }
        match read_all(&bytes) {
            Ok(_) => ok += 1,
            Err(e) => {
                // Every error names the file.
                assert!(e.to_string().starts_with("mem.mcap"), "{e}");
                errors += 1;
            }
        }
    }
    assert!(ok > 0 && errors > 0, "{ok} read, {errors} errors");
}

#[test]
fn a_string_longer_than_its_record_is_an_error_not_an_allocation() {
    // Found by the fuzzer (mcap_reader): a Header whose profile claims 4 GiB; the mcap crate's
    // parser would allocate that much before noticing the record is 38 bytes long.
    let mut bytes = MAGIC.to_vec();
    bytes.push(0x01);
    bytes.extend_from_slice(&38u64.to_le_bytes());
    bytes.extend_from_slice(&[4, 0, 255, 255]);
    bytes.extend_from_slice(&[0u8; 34]);
    bytes.extend_from_slice(&MAGIC);
    let err = McapReader::new(Cursor::new(&bytes[..]), Path::new("mem.mcap"))
        .err()
        .unwrap();
    assert!(err.to_string().contains("overruns"), "{err}");
    // The same inside a channel's metadata map.
    let good = recording(3, 1000);
    let mcap = McapReader::new(Cursor::new(&good[..]), Path::new("mem.mcap")).unwrap();
    assert!(mcap.summary().is_some());
}

#[test]
fn a_record_longer_than_its_chunk_skips_the_chunk_not_a_panic() {
    // Found by the fuzzer (mcap_reader): an uncompressed chunk without a CRC whose first
    // record claims more bytes than the chunk holds made mcap 0.26's chunk reader overflow.
    let mut bytes = recording_with(
        10,
        RecordingOptions {
            compression: ChunkCompression::None,
            ..options(1000)
        },
    );
    let chunks = mcap_chunks(&bytes);
    let first = chunks[0].chunk_start_offset as usize;
    let content = first + 9;
    bytes[content + 24..content + 28].fill(0); // no CRC
    let records = content + 8 * 3 + 4 + 4 + 8; // empty compression string
    bytes[records + 1..records + 9].copy_from_slice(&0xFFFF_FFFFu64.to_le_bytes());
    let (got, skipped, _) = read_skipping(&bytes);
    assert_eq!(skipped.len(), 1, "{skipped:?}");
    assert!(skipped[0].problem.contains("overruns the chunk"), "{:?}", skipped[0]);
    let total: usize = chunks.iter().map(|c| chunk_message_count(&bytes, c)).sum();
    assert_eq!(got.len(), total - chunk_message_count(&bytes, &chunks[0]));
}
