//! Epoch assembly as properties, not special cases: on every shared capture
//! (`shared/corpora/gpsd-nmea`, `shared/corpora/gpsd-ubx`, outside the repository), and on the
//! same captures perturbed at random, per output of a receiver (the GNSS epochs of
//! `navsync/gnss/{id}/fix`, the HNR-PVT fixes of `navsync/gnss/{id}/hnr`):
//!
//! 1. **exactly once**: no two published epochs have the same time;
//! 2. **strictly increasing**: each epoch's time is after the previous one's, except where
//!    the decoder counted a reset of the receiver's time line (`*_time_resets`: a jump back
//!    by more than a minute, as in a capture spliced from two sessions); on the unperturbed
//!    captures these are only the ones [`RESETS`] names;
//! 3. **nothing dropped that the receiver sent complete**: split and reordered, the capture
//!    publishes exactly the epoch times of the unperturbed one; with messages sent twice, at
//!    least those (a repeated ZDA may report its own time besides); with dropped messages,
//!    every epoch none of whose messages was dropped is still published (bounded: at most one
//!    epoch missing per epoch touched and per other unit dropped, such as a date).
//!
//! **Perturbations** (reproducible: a seeded xorshift generator per capture and round; a
//! failure names capture, mode and seed). A capture is cut into units (a UBX capture into its
//! frames — UBX, NMEA, RTCM3 — with the bytes up to the next frame; an NMEA capture into its
//! lines) and an epoch's units identified (UBX: the NAV messages of one `iTOW`; NMEA: the fix
//! sentences, GGA/RMC/GLL/GNS, of one time tag). Each mode is run with [`ROUNDS`] seeds:
//!
//! - `split`: the bytes in reads of random length (1 to 300 bytes);
//! - `duplicate`: 5 % of the units sent twice in a row;
//! - `reorder`: the units of each epoch shuffled among their places (other units stay);
//! - `drop`: 5 % of the units left out;
//! - `all`: the four together.
//!
//! Every mode splits its reads at random. Times are compared as UTC for UBX and as UTC time of
//! day for NMEA (a dropped date sentence leaves later epochs without a date, not without their
//! time). UBX captures are decoded with `auto` (the default protocol), NMEA captures with
//! `nmea` and with `auto`.

use std::collections::BTreeSet;
use std::path::Path;

use navsync_drivers::gnss::ubx::framer::{Frame, UbxFramer};
use navsync_drivers::gnss::ubx::messages::{self, Message};
use navsync_drivers::gnss::{Decoder, GnssDecoder, GnssExtra, Protocol};
use navsync_shared::samples::GnssFix;

/// Seeds per perturbation mode and capture (`EPOCH_PROPERTY_ROUNDS` overrides).
const ROUNDS: u64 = 4;

/// Captures whose receiver's time really goes back (counted resets on the unperturbed
/// capture), with why.
const RESETS: &[(&str, &str)] = &[
    (
        "bt451.log",
        "two sessions spliced: 15:25 then 14:33 of the same day (gpsd reports both)",
    ),
    (
        "gp-320fw-2019-04-07-coldboot.log",
        "the cold boot's ZDA says 1999-08-22 (week rollover), then 2019 again",
    ),
];

/// xorshift64.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        let x = &mut self.0;
        *x ^= *x << 13;
        *x ^= *x >> 7;
        *x ^= *x << 17;
        *x
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
    fn chance(&mut self, percent: u64) -> bool {
        self.next() % 100 < percent
    }
}

/// One piece of a capture: its bytes and the epoch it belongs to (a UBX `iTOW` or an NMEA
/// time tag as text), if any.
#[derive(Clone)]
struct Unit {
    bytes: Vec<u8>,
    epoch: Option<String>,
}

/// `iTOW` of a NAV message of an epoch.
fn itow(m: &Message) -> Option<u32> {
    Some(match m {
        Message::NavPvt(m) => m.itow_ms,
        Message::NavSol(m) => m.itow_ms,
        Message::NavTimegps(m) => m.itow_ms,
        Message::NavPosllh(m) => m.itow_ms,
        Message::NavVelned(m) => m.itow_ms,
        Message::NavDop(m) => m.itow_ms,
        Message::NavStatus(m) => m.itow_ms,
        Message::NavTimeutc(m) => m.itow_ms,
        Message::NavSat(m) => m.itow_ms,
        Message::NavSvinfo(m) => m.itow_ms,
        Message::NavEoe(m) => m.itow_ms,
        _ => return None,
    })
}

/// A binary capture's units: its frames (after gpsd's `#` header), each with the bytes up to
/// the next frame.
fn ubx_units(bytes: &[u8]) -> Vec<Unit> {
    let (header, _) = navsync_drivers::gnss::capture::gpsd_header(bytes);
    let body = &bytes[header..];
    let mut starts: Vec<(usize, Option<String>)> = Vec::new();
    // Stamped so that a frame's host time is the offset of its first byte.
    let last = body.len() as i64 - 1;
    UbxFramer::new().push(body, last, 1, &mut |f| {
        let (at, epoch) = match f {
            Frame::Ubx {
                class,
                id,
                payload,
                host_ns,
            } => (
                host_ns,
                messages::decode(class, id, payload)
                    .ok()
                    .and_then(|m| itow(&m))
                    .map(|t| t.to_string()),
            ),
            Frame::Nmea { host_ns, .. } | Frame::Rtcm3 { host_ns, .. } => (host_ns, None),
        };
        starts.push((at as usize, epoch));
    });
    let mut units = vec![Unit {
        bytes: bytes[..header].to_vec(),
        epoch: None,
    }];
    let first = starts.first().map_or(body.len(), |s| s.0);
    units.push(Unit {
        bytes: body[..first].to_vec(),
        epoch: None,
    });
    for (i, (at, epoch)) in starts.iter().enumerate() {
        let end = starts.get(i + 1).map_or(body.len(), |s| s.0);
        units.push(Unit {
            bytes: body[*at..end].to_vec(),
            epoch: epoch.clone(),
        });
    }
    units
}

/// The time tag of an NMEA fix sentence (GGA, RMC, GLL, GNS), if any.
fn nmea_tag(line: &[u8]) -> Option<String> {
    let text = std::str::from_utf8(line).ok()?.trim_end();
    let body = text.strip_prefix('$')?;
    let fields: Vec<&str> = body.split(['*', ',']).collect();
    let kind = fields.first()?.get(2..)?;
    let tag = match kind {
        "GGA" | "RMC" | "GNS" => fields.get(1)?,
        "GLL" => fields.get(5)?,
        _ => return None,
    };
    (!tag.is_empty()).then(|| tag.to_string())
}

/// An NMEA capture's units: its lines (gpsd's `#` comments and a declared delay cookie left
/// out: they are not receiver output).
fn nmea_units(bytes: &[u8]) -> Vec<Unit> {
    let cookie = bytes
        .split(|&b| b == b'\n')
        .filter_map(|l| std::str::from_utf8(l).ok())
        .find_map(|l| l.trim_start_matches('#').trim_start().strip_prefix("Delay-Cookie:"))
        .and_then(|rest| rest.trim_start().bytes().next());
    bytes
        .split_inclusive(|&b| b == b'\n')
        .filter(|l| l.first() != Some(&b'#'))
        .map(|l| {
            let bytes: Vec<u8> = l.iter().copied().filter(|&b| Some(b) != cookie).collect();
            Unit {
                epoch: nmea_tag(&bytes),
                bytes,
            }
        })
        .collect()
}

/// What a perturbation did.
#[derive(Default)]
struct Perturbed {
    bytes: Vec<u8>,
    /// Epochs at least one of whose units was dropped.
    touched: BTreeSet<String>,
    /// Units dropped that belong to no epoch.
    dropped_other: usize,
}

fn perturb(units: &[Unit], mode: &str, rng: &mut Rng) -> Perturbed {
    let (dup, reorder, drop) = match mode {
        "split" => (false, false, false),
        "duplicate" => (true, false, false),
        "reorder" => (false, true, false),
        "drop" => (false, false, true),
        _ => (true, true, true),
    };
    let mut units = units.to_vec();
    if reorder {
        // Shuffle each run of units of one epoch among the run's places (units of no epoch
        // keep their place and do not end a run).
        let mut i = 0;
        while i < units.len() {
            let Some(e) = units[i].epoch.clone() else {
                i += 1;
                continue;
            };
            let mut places = vec![i];
            let mut j = i + 1;
            while j < units.len() {
                match &units[j].epoch {
                    Some(f) if *f == e => places.push(j),
                    Some(_) => break,
                    None => {}
                }
                j += 1;
            }
            for k in (1..places.len()).rev() {
                let m = rng.below(k + 1);
                units.swap(places[k], places[m]);
            }
            i = j;
        }
    }
    let mut out = Perturbed::default();
    for (n, u) in units.iter().enumerate() {
        // The header and leading bytes of a binary capture are never dropped or doubled.
        if n > 1 && drop && rng.chance(5) {
            match &u.epoch {
                Some(e) => {
                    out.touched.insert(e.clone());
                }
                None => out.dropped_other += 1,
            }
            continue;
        }
        out.bytes.extend(&u.bytes);
        if n > 1 && dup && rng.chance(5) {
            out.bytes.extend(&u.bytes);
        }
    }
    out
}

/// The decoder's outputs for `bytes` read in chunks of random length (a seed of 0: the whole
/// capture in reads of 64 bytes), and the resets it counted.
struct Outputs {
    fixes: Vec<GnssFix>,
    hnr: Vec<GnssFix>,
    resets: u64,
}

fn decode(bytes: &[u8], protocol: Protocol, rng: Option<&mut Rng>) -> Outputs {
    let (header, _) = navsync_drivers::gnss::capture::gpsd_header(bytes);
    let body = &bytes[header..];
    let mut d = Decoder::new(protocol);
    let (mut fixes, mut hnr) = (Vec::new(), Vec::new());
    let mut at = 0;
    let mut rng = rng;
    while at < body.len() {
        let n = match rng.as_deref_mut() {
            Some(r) => 1 + r.below(300),
            None => 64,
        };
        let end = (at + n).min(body.len());
        d.push_extras(
            &body[at..end],
            end as i64 * 1_000_000,
            1_000_000,
            &mut |f| fixes.push(*f),
            &mut |x| {
                if let GnssExtra::Hnr(h) = x {
                    hnr.push(*h);
                }
            },
        );
        at = end;
    }
    d.flush(&mut |f| fixes.push(*f));
    let mut resets = 0;
    d.each_counter(&mut |name, v| {
        if name.ends_with("time_resets") {
            resets += v;
        }
    });
    Outputs { fixes, hnr, resets }
}

/// The time of an epoch compared: UTC (UBX), UTC time of day (NMEA); `None` without.
fn key(f: &GnssFix, nmea: bool) -> Option<i64> {
    if nmea {
        (f.tod_ns >= 0).then_some(f.tod_ns)
    } else {
        (f.utc_ns != i64::MIN).then_some(f.utc_ns)
    }
}

/// Properties 1 and 2 on one output: the steps back (each a counted reset).
fn check_order(what: &str, out: &[GnssFix]) -> Result<u64, String> {
    let times: Vec<i64> = out.iter().map(|f| f.utc_ns).filter(|&t| t != i64::MIN).collect();
    let mut seen = BTreeSet::new();
    let mut back = 0;
    for w in times.windows(2) {
        if w[1] == w[0] {
            return Err(format!("{what}: epoch {} published twice in a row", w[0]));
        }
        if w[1] < w[0] {
            back += 1;
        }
    }
    for t in &times {
        if !seen.insert(*t) {
            return Err(format!("{what}: epoch {t} published twice"));
        }
    }
    Ok(back)
}

fn times(out: &[GnssFix], nmea: bool) -> BTreeSet<i64> {
    out.iter().filter_map(|f| key(f, nmea)).collect()
}

/// Checks one capture under every mode; the failures.
fn check_capture(name: &str, bytes: &[u8], nmea_capture: bool, protocol: Protocol) -> Vec<String> {
    let mut failures = Vec::new();
    let nmea = protocol == Protocol::Nmea || nmea_capture;
    let base = decode(bytes, protocol, None);
    let label = format!("{name} as {protocol}");
    for (what, out) in [("fix", &base.fixes), ("hnr", &base.hnr)] {
        match check_order(&format!("{label} {what}"), out) {
            Ok(back) => {
                if back > base.resets {
                    failures.push(format!(
                        "{label} {what}: {back} steps back, {} resets counted",
                        base.resets
                    ));
                }
            }
            Err(e) => failures.push(e),
        }
    }
    let allowed = RESETS.iter().any(|(n, _)| *n == name);
    if base.resets > 0 && !allowed {
        failures.push(format!(
            "{label}: {} time resets on the unperturbed capture",
            base.resets
        ));
    }
    let units = if nmea_capture {
        nmea_units(bytes)
    } else {
        ubx_units(bytes)
    };
    // The units put together again are the capture (the cut loses nothing).
    let whole: Vec<u8> = units.iter().flat_map(|u| u.bytes.clone()).collect();
    let reference = if nmea_capture {
        decode(&whole, protocol, None)
    } else {
        base
    };
    let ref_times = times(&reference.fixes, nmea);
    let ref_hnr = times(&reference.hnr, false);
    let rounds = std::env::var("EPOCH_PROPERTY_ROUNDS")
        .ok()
        .and_then(|r| r.parse().ok())
        .unwrap_or(ROUNDS);
    for mode in ["split", "duplicate", "reorder", "drop", "all"] {
        for round in 0..rounds {
            let seed = 0x9E37_79B9_7F4A_7C15 ^ (round + 1).wrapping_mul(0x2545_F491_4F6C_DD1D) ^ name.len() as u64;
            let mut rng = Rng(seed);
            let p = perturb(&units, mode, &mut rng);
            let out = decode(&p.bytes, protocol, Some(&mut rng));
            let tag = format!("{label} mode {mode} seed {seed:#x}");
            if std::env::var("EPOCH_PROPERTY_DUMP").is_ok_and(|d| d == format!("{name} {mode} {seed:#x}")) {
                for (which, o) in [("ref", &reference.fixes), ("got", &out.fixes)] {
                    for f in o {
                        println!("{which} tod={} utc={} bits={:#x}", f.tod_ns, f.utc_ns, f.sentences);
                    }
                }
                println!("{}", String::from_utf8_lossy(&p.bytes));
            }
            for (what, o) in [("fix", &out.fixes), ("hnr", &out.hnr)] {
                match check_order(&format!("{tag} {what}"), o) {
                    Ok(back) if back > out.resets => {
                        failures.push(format!(
                            "{tag} {what}: {back} steps back, {} resets counted",
                            out.resets
                        ));
                    }
                    Ok(_) => {}
                    Err(e) => failures.push(e),
                }
            }
            let got = times(&out.fixes, nmea);
            let got_hnr = times(&out.hnr, false);
            if p.touched.is_empty() && p.dropped_other == 0 {
                // Nothing dropped: the same epochs, each once (a message sent twice may add a
                // report of its own time, as a repeated ZDA does, but loses none).
                for (what, want, got) in [("fix", &ref_times, &got), ("hnr", &ref_hnr, &got_hnr)] {
                    let ok = if mode == "duplicate" {
                        want.is_subset(got)
                    } else {
                        want == got
                    };
                    if !ok {
                        let missing: Vec<_> = want.difference(got).take(3).collect();
                        let extra: Vec<_> = got.difference(want).take(3).collect();
                        failures.push(format!(
                            "{tag} {what}: {} epochs, {} expected; missing {missing:?}, extra {extra:?}",
                            got.len(),
                            want.len()
                        ));
                    }
                }
            } else {
                // Every epoch none of whose messages was dropped is still published: at most
                // one epoch per touched epoch and per dropped other unit (a date, a leap
                // second count) may be missing.
                let missing = ref_times.difference(&got).count();
                let bound = p.touched.len() + p.dropped_other;
                if missing > bound {
                    failures.push(format!(
                        "{tag}: {missing} epochs missing, {} epochs touched and {} other units dropped",
                        p.touched.len(),
                        p.dropped_other
                    ));
                }
            }
        }
    }
    failures
}

fn corpus(kind: &str) -> std::path::PathBuf {
    std::env::var_os("NAVSYNC_SHARED_DIR")
        .map(|d| Path::new(&d).join("corpora").join(kind))
        .unwrap_or_else(|| {
            Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../../shared/corpora")
                .join(kind)
        })
}

#[test]
fn ubx_captures_publish_every_epoch_once_in_order() {
    let captures = crate::gpsd_common::captures(&corpus("gpsd-ubx"), 21);
    let mut failures = Vec::new();
    let mut epochs = 0;
    for c in &captures {
        assert!(!c.chk.is_empty(), "{}: gpsd's output missing", c.name);
        epochs += decode(&c.bytes, Protocol::Auto, None).fixes.len();
        failures.extend(check_capture(&c.name, &c.bytes, false, Protocol::Auto));
    }
    assert!(
        epochs > 800,
        "only {epochs} epochs decoded: the corpus is not what it was"
    );
    assert!(
        failures.is_empty(),
        "{} failures:\n{}",
        failures.len(),
        failures.join("\n")
    );
}

#[test]
fn nmea_captures_publish_every_epoch_once_in_order() {
    let captures = crate::gpsd_common::captures(&corpus("gpsd-nmea"), 76);
    let mut failures = Vec::new();
    let mut resets = BTreeSet::new();
    for c in &captures {
        for protocol in [Protocol::Nmea, Protocol::Auto] {
            if decode(&c.bytes, protocol, None).resets > 0 {
                resets.insert(c.name.clone());
            }
            failures.extend(check_capture(&c.name, &c.bytes, true, protocol));
        }
    }
    assert!(
        failures.is_empty(),
        "{} failures:\n{}",
        failures.len(),
        failures.join("\n")
    );
    // The named resets are still there (a list that no longer applies fails).
    let named: BTreeSet<String> = RESETS.iter().map(|(n, _)| (*n).to_owned()).collect();
    assert_eq!(resets, named, "captures whose time goes back");
}
