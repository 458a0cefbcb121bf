//! Cross-check of navsync's UBX message decoders with pyubx2 (PyPI, the widely used Python
//! UBX parser), field by field, on the real u-blox captures of `shared/corpora/gpsd-ubx`.
//!
//! **What runs.** pyubx2 ([`PYUBX2`], installed with pip into a scratch virtual environment)
//! reads every capture through `tests/python/ubx_pyubx2_dump.py`, which prints each UBX frame
//! pyubx2's stream reader delivers: its stream offset, class/id, length, whether its checksum
//! verifies, its index among the frames that verify, pyubx2's name for it and, for the
//! messages navsync decodes, pyubx2's values under the names and in the units of navsync's
//! structs (`height_m` = pyubx2's `height` / 1000 …; see the script). The same bytes (after
//! gpsd's leading `#` comment lines, skipped the same way on both sides) go through navsync's
//! [`UbxFramer`] in one read, stamped so that a frame's time is its stream offset, and every
//! UBX frame through [`messages::decode`].
//!
//! **Pairing.** A frame of each side is paired with the frame of the other side that starts
//! at the same stream offset; a paired frame must have the same class, id and length on both
//! sides. A frame one side delivers and the other does not (the two framers resynchronise
//! differently after a candidate that fails: navsync one byte after its start, pyubx2 after
//! its announced length) is listed with its offset and fails the test. The paired frames are
//! taken in stream order, which is the order of both sides' indices.
//!
//! **Fields.** For every paired frame of the messages navsync decodes (NAV-PVT, NAV-SOL,
//! NAV-TIMEGPS, NAV-POSLLH, NAV-VELNED, NAV-DOP, NAV-STATUS, NAV-TIMEUTC, NAV-SAT,
//! NAV-SVINFO, NAV-EOE, TIM-TP, TIM-TM2, RXM-RAWX, RXM-SFRBX, ESF-MEAS, ESF-RAW, HNR-PVT,
//! MON-VER, ACK-ACK/NAK), navsync's decoded message must have pyubx2's name and every field
//! of its struct (repeated blocks flattened as `sats[3].cno_dbhz`, [`ours`]) must agree with
//! pyubx2's, and neither side may have a field the other lacks:
//!
//! - integers, flag bytes, booleans (navsync's accessors such as `carr_soln()`, against
//!   pyubx2's single bits) and text: exactly;
//! - scaled values: to their resolution, i.e. within half of the unit of the field's last
//!   digit on the wire ([`V::Num`]: 1e-7° for latitude, 1 mm for heights, …), so that a
//!   difference of one unit fails while the two libraries' different floating-point
//!   arithmetic (pyubx2 multiplies by the scale and rounds to 12 decimals, navsync divides)
//!   passes; `R4`/`R8` values and the standard deviations of RXM-RAWX: exactly.
//!
//! The test proves that tightness on the data: in the first compared message of every type
//! each field, changed by one unit of its resolution (one ULP for exact floats), must be a
//! disagreement.
//!
//! Where the two decoders deliberately differ, the difference is a [`DELIBERATE`] entry with
//! its reason: a representation pyubx2 chose, converted before the comparison (and then
//! counted as compared), or a field navsync withholds, because the protocol declares it
//! invalid or because it did not fit navsync's fixed-size arrays (and was counted as
//! dropped), not compared. The test fails on an entry that no longer applies.
//!
//! **Types the corpus lacks.** NAV-VELNED, TIM-TM2 and RXM-RAWX (0, 1, 17 and 32
//! measurements) occur in none of the captures; `tests/python/ubx_pyubx2_build.py` has pyubx2
//! serialise them from seeded random values over each field's range, and that file is
//! compared like a capture (`pyubx2-built.ubx` in the report).
//!
//! **The simulator's receiver.** `sim-written.ubx` is 30 s of what `navsync sim`'s UBX
//! receiver writes (NAV-PVT, NAV-EOE, TIM-TP, and the TIM-TM2 time marks of its camera; written
//! from the interface description, not from these decoders, [`sim_receiver_bytes`]), compared
//! like a capture: pyubx2 must read the simulator's frames as navsync's decoders do, whose
//! reading the simulator's round-trip tests compare with what it meant to write.
//!
//! **Asserts.** Every message type of the list above that occurs in the corpus (on either
//! side) was compared; ≥ [`MIN_AGREEMENT`] of all compared fields agree; there is no
//! disagreement (each is listed with capture, both indices, offset, field and both values).
//! The table of messages and fields compared per type is printed (`-- --nocapture`).
//!
//! Needs `python3` with pip and access to PyPI; without them the test fails and says why.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;

use navsync_drivers::gnss::ubx::framer::{Frame, UbxFramer};
use navsync_drivers::gnss::ubx::messages::{self, Message};
use navsync_drivers::gnss::ubx::mon::MonVer;
use navsync_drivers::gnss::ubx::nav::SatInfo;
use navsync_tests::{TestEnv, python_with, shared_material};
use serde_json::Value;

/// The pyubx2 release the comparison was made with (the Python package is pinned so that a
/// new release cannot change the outcome unnoticed).
const PYUBX2: &str = "pyubx2==1.4.0";

/// Captures in the corpus (fewer: it is incomplete).
const EXPECTED_CAPTURES: usize = 21;

/// Share of compared fields that must agree.
const MIN_AGREEMENT: f64 = 0.999;

/// The message types navsync decodes, in the order of the report.
const TYPES: &[&str] = &[
    "NAV-PVT",
    "NAV-SOL",
    "NAV-TIMEGPS",
    "NAV-POSLLH",
    "NAV-VELNED",
    "NAV-DOP",
    "NAV-STATUS",
    "NAV-TIMEUTC",
    "NAV-SAT",
    "NAV-SVINFO",
    "NAV-EOE",
    "TIM-TP",
    "TIM-TM2",
    "RXM-RAWX",
    "RXM-SFRBX",
    "ESF-MEAS",
    "ESF-RAW",
    "HNR-PVT",
    "MON-VER",
    "ACK-ACK",
    "ACK-NAK",
];

/// Resolutions (one unit of the last digit on the wire) in navsync's units.
const DEG7: f64 = 1e-7;
const DEG5: f64 = 1e-5;
const DEG2: f64 = 1e-2;
const MILLI: f64 = 1e-3;
const CENTI: f64 = 1e-2;
const DECI: f64 = 1e-1;
/// TIM-TP `towSubMS`: navsync keeps the integer (unit 2^-32 ms), pyubx2's scaled value is
/// rescaled to it by the dump, so one unit.
const ONE: f64 = 1.0;
/// Values sent as IEEE floats (R4, R8) or computed by the protocol's formula from an index:
/// bit for bit.
const EXACT: f64 = 0.0;

/// One field of navsync's decoded message.
#[derive(Debug, Clone, PartialEq)]
enum V {
    /// An integer (counts, raw flag bytes, unscaled values): exact.
    Int(i64),
    /// A scaled or floating-point value and its resolution: agrees within `res / 2` (exactly
    /// when `res` is 0).
    Num { v: f64, res: f64 },
    /// A flag (an accessor method of navsync's struct): exact.
    Bool(bool),
    /// Text (NUL-padded strings up to the first NUL): exact.
    Text(String),
    /// A field navsync does not report (an `Option` that is `None`).
    Absent,
}

impl V {
    fn agrees(&self, theirs: &Value) -> bool {
        match (self, theirs) {
            (V::Int(a), t) => t.as_i64() == Some(*a) || (t.is_f64() && t.as_f64() == Some(*a as f64)),
            (V::Num { v, res }, t) => t.as_f64().is_some_and(|x| {
                if *res == 0.0 {
                    x == *v || (x.is_nan() && v.is_nan())
                } else {
                    (x - v).abs() <= res / 2.0
                }
            }),
            (V::Bool(a), Value::Bool(b)) => a == b,
            (V::Text(a), Value::String(b)) => a == b,
            (V::Absent, Value::Null) => true,
            _ => false,
        }
    }

    /// The value changed by one unit of its resolution (`None`: nothing to change).
    fn nudged(&self) -> Option<V> {
        Some(match self {
            V::Int(a) => V::Int(a + 1),
            V::Num { v, res } if *res == 0.0 => V::Num {
                v: v.next_up(),
                res: 0.0,
            },
            V::Num { v, res } => V::Num { v: v + res, res: *res },
            V::Bool(b) => V::Bool(!b),
            V::Text(s) => V::Text(format!("{s}?")),
            V::Absent => return None,
        })
    }
}

impl std::fmt::Display for V {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            V::Int(a) => write!(f, "{a}"),
            V::Num { v, .. } => write!(f, "{v}"),
            V::Bool(b) => write!(f, "{b}"),
            V::Text(s) => write!(f, "{s:?}"),
            V::Absent => f.write_str("(none)"),
        }
    }
}

/// navsync's fields of one message, in struct order.
#[derive(Default, Clone)]
struct Fields {
    /// Name and value of every field.
    v: Vec<(String, V)>,
    /// The message's repeated blocks (satellites, readings, …): how many navsync stored and
    /// how many it dropped because its fixed-size array was full.
    blocks: (usize, usize),
}

impl Fields {
    fn int(&mut self, k: impl Into<String>, v: impl Into<i64>) {
        self.v.push((k.into(), V::Int(v.into())));
    }
    fn num(&mut self, k: impl Into<String>, v: f64, res: f64) {
        self.v.push((k.into(), V::Num { v, res }));
    }
    fn opt_num(&mut self, k: impl Into<String>, v: Option<f64>, res: f64) {
        self.v.push((k.into(), v.map_or(V::Absent, |v| V::Num { v, res })));
    }
    fn flag(&mut self, k: impl Into<String>, v: bool) {
        self.v.push((k.into(), V::Bool(v)));
    }
    fn text(&mut self, k: impl Into<String>, v: &[u8]) {
        self.v.push((k.into(), V::Text(MonVer::text(v).to_string())));
    }
    /// The fields of one satellite of NAV-SAT / NAV-SVINFO.
    fn sat(&mut self, p: &str, s: &SatInfo, pr_res: f64) {
        self.int(format!("{p}gnss_id"), s.gnss_id);
        self.int(format!("{p}sv_id"), s.sv_id);
        self.int(format!("{p}cno_dbhz"), s.cno_dbhz);
        self.int(format!("{p}elev_deg"), s.elev_deg);
        self.int(format!("{p}azim_deg"), s.azim_deg);
        self.num(format!("{p}pr_res_m"), s.pr_res_m, pr_res);
        self.flag(format!("{p}used"), s.used);
        self.int(format!("{p}quality"), s.quality);
        self.int(format!("{p}health"), s.health);
        self.int(format!("{p}flags"), s.flags);
    }
}

/// navsync's decoded message as named fields (names and units of its structs; accessor
/// methods end in `()`).
fn ours(msg: &Message) -> Fields {
    let mut f = Fields::default();
    match msg {
        Message::NavPvt(m) => {
            f.int("itow_ms", m.itow_ms);
            f.int("year", m.year);
            f.int("month", m.month);
            f.int("day", m.day);
            f.int("hour", m.hour);
            f.int("min", m.min);
            f.int("sec", m.sec);
            f.int("valid", m.valid);
            f.int("t_acc_ns", m.t_acc_ns);
            f.int("nano_ns", m.nano_ns);
            f.int("fix_type", m.fix_type);
            f.int("flags", m.flags);
            f.int("flags2", m.flags2);
            f.int("num_sv", m.num_sv);
            f.num("lon_deg", m.lon_deg, DEG7);
            f.num("lat_deg", m.lat_deg, DEG7);
            f.num("height_m", m.height_m, MILLI);
            f.num("h_msl_m", m.h_msl_m, MILLI);
            f.num("h_acc_m", m.h_acc_m, MILLI);
            f.num("v_acc_m", m.v_acc_m, MILLI);
            f.num("vel_n_mps", m.vel_n_mps, MILLI);
            f.num("vel_e_mps", m.vel_e_mps, MILLI);
            f.num("vel_d_mps", m.vel_d_mps, MILLI);
            f.num("g_speed_mps", m.g_speed_mps, MILLI);
            f.num("head_mot_deg", m.head_mot_deg, DEG5);
            f.num("s_acc_mps", m.s_acc_mps, MILLI);
            f.num("head_acc_deg", m.head_acc_deg, DEG5);
            f.num("p_dop", m.p_dop, CENTI);
            f.flag("valid_date_time()", m.valid_date_time());
            f.flag("fully_resolved()", m.fully_resolved());
            f.flag("gnss_fix_ok()", m.gnss_fix_ok());
            f.flag("diff_soln()", m.diff_soln());
            f.int("carr_soln()", m.carr_soln());
            if m.head_veh_deg.is_some() {
                // The 92-byte layout (the 84-byte one of u-blox 7 ends before flags3).
                f.int("flags3", m.flags3);
                f.flag("invalid_llh()", m.invalid_llh());
                f.opt_num("head_veh_deg", m.head_veh_deg, DEG5);
                f.opt_num("mag_dec_deg", m.mag_dec_deg, DEG2);
                f.opt_num("mag_acc_deg", m.mag_acc_deg, DEG2);
            }
        }
        Message::NavSol(m) => {
            f.int("itow_ms", m.itow_ms);
            f.int("ftow_ns", m.ftow_ns);
            f.int("week", m.week);
            f.int("gps_fix", m.gps_fix);
            f.int("flags", m.flags);
            f.num("ecef_x_m", m.ecef_x_m, CENTI);
            f.num("ecef_y_m", m.ecef_y_m, CENTI);
            f.num("ecef_z_m", m.ecef_z_m, CENTI);
            f.num("p_acc_m", m.p_acc_m, CENTI);
            f.num("ecef_vx_mps", m.ecef_vx_mps, CENTI);
            f.num("ecef_vy_mps", m.ecef_vy_mps, CENTI);
            f.num("ecef_vz_mps", m.ecef_vz_mps, CENTI);
            f.num("s_acc_mps", m.s_acc_mps, CENTI);
            f.num("p_dop", m.p_dop, CENTI);
            f.int("num_sv", m.num_sv);
            f.flag("fix_ok()", m.fix_ok());
            f.flag("diff_soln()", m.diff_soln());
            f.flag("time_valid()", m.time_valid());
        }
        Message::NavTimegps(m) => {
            f.int("itow_ms", m.itow_ms);
            f.int("ftow_ns", m.ftow_ns);
            f.int("week", m.week);
            f.int("leap_s", m.leap_s);
            f.int("valid", m.valid);
            f.int("t_acc_ns", m.t_acc_ns);
            f.flag("time_valid()", m.time_valid());
            f.flag("leap_valid()", m.leap_valid());
        }
        Message::NavPosllh(m) => {
            f.int("itow_ms", m.itow_ms);
            f.num("lon_deg", m.lon_deg, DEG7);
            f.num("lat_deg", m.lat_deg, DEG7);
            f.num("height_m", m.height_m, MILLI);
            f.num("h_msl_m", m.h_msl_m, MILLI);
            f.num("h_acc_m", m.h_acc_m, MILLI);
            f.num("v_acc_m", m.v_acc_m, MILLI);
        }
        Message::NavVelned(m) => {
            f.int("itow_ms", m.itow_ms);
            f.num("vel_n_mps", m.vel_n_mps, CENTI);
            f.num("vel_e_mps", m.vel_e_mps, CENTI);
            f.num("vel_d_mps", m.vel_d_mps, CENTI);
            f.num("speed_mps", m.speed_mps, CENTI);
            f.num("g_speed_mps", m.g_speed_mps, CENTI);
            f.num("heading_deg", m.heading_deg, DEG5);
            f.num("s_acc_mps", m.s_acc_mps, CENTI);
            f.num("c_acc_deg", m.c_acc_deg, DEG5);
        }
        Message::NavDop(m) => {
            f.int("itow_ms", m.itow_ms);
            f.num("g_dop", m.g_dop, CENTI);
            f.num("p_dop", m.p_dop, CENTI);
            f.num("t_dop", m.t_dop, CENTI);
            f.num("v_dop", m.v_dop, CENTI);
            f.num("h_dop", m.h_dop, CENTI);
            f.num("n_dop", m.n_dop, CENTI);
            f.num("e_dop", m.e_dop, CENTI);
        }
        Message::NavStatus(m) => {
            f.int("itow_ms", m.itow_ms);
            f.int("gps_fix", m.gps_fix);
            f.int("flags", m.flags);
            f.int("fix_stat", m.fix_stat);
            f.int("flags2", m.flags2);
            f.int("ttff_ms", m.ttff_ms);
            f.int("msss_ms", m.msss_ms);
            f.flag("fix_ok()", m.fix_ok());
            f.flag("diff_soln()", m.diff_soln());
            f.int("carr_soln()", m.carr_soln());
        }
        Message::NavTimeutc(m) => {
            f.int("itow_ms", m.itow_ms);
            f.int("t_acc_ns", m.t_acc_ns);
            f.int("nano_ns", m.nano_ns);
            f.int("year", m.year);
            f.int("month", m.month);
            f.int("day", m.day);
            f.int("hour", m.hour);
            f.int("min", m.min);
            f.int("sec", m.sec);
            f.int("valid", m.valid);
            f.flag("utc_valid()", m.utc_valid());
        }
        Message::NavSat(m) => {
            f.int("itow_ms", m.itow_ms);
            f.int("num_svs", m.num_svs);
            f.blocks = (m.len, m.dropped);
            for (i, s) in m.satellites().iter().enumerate() {
                f.sat(&format!("sats[{i}]."), s, DECI);
            }
        }
        Message::NavSvinfo(m) => {
            f.int("itow_ms", m.itow_ms);
            f.int("num_ch", m.num_ch);
            f.int("global_flags", m.global_flags);
            f.blocks = (m.len, m.dropped);
            for (i, s) in m.satellites().iter().enumerate() {
                let p = format!("sats[{i}].");
                f.int(format!("{p}chn"), m.chn[i]);
                f.sat(&p, s, CENTI);
            }
            f.int("unknown", m.unknown as i64);
        }
        Message::NavEoe(m) => f.int("itow_ms", m.itow_ms),
        Message::TimTp(m) => {
            f.int("tow_ms", m.tow_ms);
            f.num("tow_sub_ms", f64::from(m.tow_sub_ms), ONE);
            f.int("q_err_ps", m.q_err_ps);
            f.int("week", m.week);
            f.int("flags", m.flags);
            f.int("ref_info", m.ref_info);
            f.flag("utc_time_base()", m.utc_time_base());
            f.flag("q_err_valid()", m.q_err_valid());
            f.int("tow_ns()", m.tow_ns());
        }
        Message::TimTm2(m) => {
            f.int("ch", m.ch);
            f.int("flags", m.flags);
            f.int("count", m.count);
            f.int("week_rising", m.week_rising);
            f.int("week_falling", m.week_falling);
            f.int("tow_rising_ms", m.tow_rising_ms);
            f.int("tow_sub_rising_ns", m.tow_sub_rising_ns);
            f.int("tow_falling_ms", m.tow_falling_ms);
            f.int("tow_sub_falling_ns", m.tow_sub_falling_ns);
            f.int("acc_est_ns", m.acc_est_ns);
            f.flag("time_valid()", m.time_valid());
            f.int("time_base()", m.time_base());
        }
        Message::RxmRawx(m) => {
            f.num("rcv_tow_s", m.rcv_tow_s, EXACT);
            f.int("week", m.week);
            f.int("leap_s", m.leap_s);
            f.int("num_meas", m.num_meas);
            f.int("rec_stat", m.rec_stat);
            f.int("version", m.version);
            f.blocks = (m.len, m.dropped);
            for (i, r) in m.measurements().iter().enumerate() {
                let p = format!("meas[{i}].");
                f.num(format!("{p}pr_mes_m"), r.pr_mes_m, EXACT);
                f.num(format!("{p}cp_mes_cycles"), r.cp_mes_cycles, EXACT);
                f.num(format!("{p}do_mes_hz"), f64::from(r.do_mes_hz), EXACT);
                f.int(format!("{p}gnss_id"), r.gnss_id);
                f.int(format!("{p}sv_id"), r.sv_id);
                f.int(format!("{p}sig_id"), r.sig_id);
                f.int(format!("{p}freq_id"), r.freq_id);
                f.int(format!("{p}locktime_ms"), r.locktime_ms);
                f.int(format!("{p}cno_dbhz"), r.cno_dbhz);
                f.num(format!("{p}pr_stdev_m"), r.pr_stdev_m, EXACT);
                f.num(format!("{p}cp_stdev_cycles"), r.cp_stdev_cycles, EXACT);
                f.num(format!("{p}do_stdev_hz"), r.do_stdev_hz, EXACT);
                f.int(format!("{p}trk_stat"), r.trk_stat);
            }
        }
        Message::RxmSfrbx(m) => {
            f.int("gnss_id", m.gnss_id);
            f.int("sv_id", m.sv_id);
            f.int("sig_id", m.sig_id);
            f.int("freq_id", m.freq_id);
            f.int("num_words", m.num_words);
            f.int("chn", m.chn);
            f.int("version", m.version);
            f.blocks = (m.len, m.dropped);
            for (i, w) in m.data_words().iter().enumerate() {
                f.int(format!("words[{i}]"), *w);
            }
        }
        Message::EsfMeas(m) => {
            f.int("time_tag_ms", m.time_tag_ms);
            f.int("flags", m.flags);
            f.int("id", m.id);
            f.blocks = (m.len, m.dropped);
            for (i, r) in m.readings().iter().enumerate() {
                f.int(format!("readings[{i}].data_type"), r.data_type);
                f.int(format!("readings[{i}].value"), r.value);
            }
            f.v.push((
                "calib_ttag_ms".into(),
                m.calib_ttag_ms.map_or(V::Absent, |t| V::Int(t.into())),
            ));
        }
        Message::EsfRaw(m) => {
            f.blocks = (m.len, m.dropped);
            for (i, r) in m.readings().iter().enumerate() {
                f.int(format!("readings[{i}].data_type"), r.data.data_type);
                f.int(format!("readings[{i}].value"), r.data.value);
                f.int(format!("readings[{i}].s_ttag"), r.s_ttag);
            }
        }
        Message::HnrPvt(m) => {
            f.int("itow_ms", m.itow_ms);
            f.int("year", m.year);
            f.int("month", m.month);
            f.int("day", m.day);
            f.int("hour", m.hour);
            f.int("min", m.min);
            f.int("sec", m.sec);
            f.int("valid", m.valid);
            f.int("nano_ns", m.nano_ns);
            f.int("gps_fix", m.gps_fix);
            f.int("flags", m.flags);
            f.num("lon_deg", m.lon_deg, DEG7);
            f.num("lat_deg", m.lat_deg, DEG7);
            f.num("height_m", m.height_m, MILLI);
            f.num("h_msl_m", m.h_msl_m, MILLI);
            f.num("g_speed_mps", m.g_speed_mps, MILLI);
            f.num("speed_mps", m.speed_mps, MILLI);
            f.num("head_mot_deg", m.head_mot_deg, DEG5);
            f.num("head_veh_deg", m.head_veh_deg, DEG5);
            f.num("h_acc_m", m.h_acc_m, MILLI);
            f.num("v_acc_m", m.v_acc_m, MILLI);
            f.num("s_acc_mps", m.s_acc_mps, MILLI);
            f.num("head_acc_deg", m.head_acc_deg, DEG5);
            f.flag("valid_date_time()", m.valid_date_time());
            f.flag("fix_ok()", m.fix_ok());
            f.flag("diff_soln()", m.diff_soln());
        }
        Message::MonVer(m) => {
            f.text("sw_version", &m.sw_version);
            f.text("hw_version", &m.hw_version);
            f.blocks = (m.len, m.dropped);
            for (i, e) in m.extensions.iter().take(m.len).enumerate() {
                f.text(format!("extensions[{i}]"), e);
            }
        }
        Message::AckAck(a) | Message::AckNak(a) => {
            f.int("cls_id", a.cls_id);
            f.int("msg_id", a.msg_id);
        }
        Message::Other { .. } => {}
    }
    f
}

/// How a deliberate difference is treated.
enum Treatment {
    /// pyubx2 represents the field differently: its value is converted by the function
    /// (`None`: nothing to convert) and then compared as any other.
    Convert(fn(&Value) -> Option<Value>),
    /// navsync withholds the field (reports it as absent); not compared.
    NotCompared,
}

/// A deliberate difference between the two decoders.
struct Deliberate {
    /// Short name for the report.
    name: &'static str,
    /// Message types it concerns.
    types: &'static [&'static str],
    /// The field, with block indices written `[*]` (`readings[*].value`); a final `*` stands
    /// for any rest (`readings[*].*`: every field of a reading).
    field: &'static str,
    /// Whether it applies to this field of this message.
    applies: fn(&Ctx) -> bool,
    treatment: Treatment,
    /// Why the decoders differ.
    reason: &'static str,
}

impl Deliberate {
    /// Whether it concerns `field` (pattern as [`pattern`] writes it) of an `identity` message.
    fn concerns(&self, identity: &str, field: &str) -> bool {
        self.types.contains(&identity)
            && match self.field.strip_suffix('*') {
                Some(prefix) => field.starts_with(prefix),
                None => field == self.field,
            }
    }
}

/// What a [`Deliberate`] condition sees.
struct Ctx<'a> {
    /// navsync's value ([`V::Absent`] where navsync has no such field).
    ours: &'a V,
    /// pyubx2's fields of the message.
    theirs: &'a serde_json::Map<String, Value>,
    /// The repeated block the field belongs to (`sats[3].cno_dbhz`: 3).
    block: Option<usize>,
    /// navsync's repeated blocks: stored, dropped ([`Fields::blocks`]).
    blocks: (usize, usize),
}

impl Ctx<'_> {
    /// The field belongs to a block navsync counted as dropped (its array was full).
    fn beyond_capacity(&self) -> bool {
        let (stored, dropped) = self.blocks;
        self.block.is_some_and(|i| i >= stored && i < stored + dropped)
    }
}

/// ESF data types whose 24-bit field is a signed two's-complement value (M8 protocol, "ESF
/// sensor data types"): 5 gyroscope z, 11 speed, 12 gyroscope temperature, 13/14 gyroscope
/// y/x, 16/17/18 accelerometer x/y/z. The wheel-tick types 6–10 are not among them: bits 0–22
/// count ticks and bit 23 is the direction.
const SIGNED_ESF_TYPES: &[i64] = &[5, 11, 12, 13, 14, 16, 17, 18];

/// A 24-bit field given as unsigned, sign-extended (`None` where bit 23 is clear).
fn sign_extend_24(v: &Value) -> Option<Value> {
    let u = v.as_i64()?;
    (u & 0x80_0000 != 0).then(|| Value::from(u - 0x100_0000))
}

const DELIBERATE: &[Deliberate] = &[
    Deliberate {
        name: "esf-raw-capacity",
        types: &["ESF-RAW"],
        field: "readings[*].*",
        applies: |c| *c.ours == V::Absent && c.beyond_capacity(),
        treatment: Treatment::NotCompared,
        reason: "navsync stores the first MAX_ESF (32) readings of a message without \
                 allocating and counts the rest as dropped (exactly these); the NEO-M8U's ESF-RAW \
                 messages carry more",
    },
    Deliberate {
        name: "esf-data-signed",
        types: &["ESF-MEAS", "ESF-RAW"],
        field: "readings[*].value",
        applies: |c| {
            let ty = c.block.and_then(|i| c.theirs.get(&format!("readings[{i}].data_type")));
            ty.and_then(Value::as_i64)
                .is_some_and(|t| SIGNED_ESF_TYPES.contains(&t))
        },
        treatment: Treatment::Convert(sign_extend_24),
        reason: "pyubx2 gives the 24-bit data field as an unsigned bit field (X24) whatever the \
                 data type; navsync sign-extends it, as the protocol defines it for the signed \
                 types (SIGNED_ESF_TYPES: gyroscope, accelerometer, temperature, speed)",
    },
    Deliberate {
        name: "nav-pvt-mag-invalid",
        types: &["NAV-PVT"],
        field: "mag_*",
        applies: |c| *c.ours == V::Absent && c.theirs["valid"].as_i64().is_some_and(|v| v & 0x08 == 0),
        treatment: Treatment::NotCompared,
        reason: "navsync reports no magnetic declination (mag_dec_deg, mag_acc_deg) unless \
                 validMag is set; pyubx2 decodes the bytes regardless",
    },
];

/// The index of the first repeated block in a field name (`sats[3].cno_dbhz`: 3).
fn block_index(field: &str) -> Option<usize> {
    let (_, rest) = field.split_once('[')?;
    rest.split_once(']')?.0.parse().ok()
}

/// `readings[12].value` → `readings[*].value`.
fn pattern(field: &str) -> String {
    let mut out = String::with_capacity(field.len());
    let mut in_index = false;
    for c in field.chars() {
        match c {
            '[' => {
                in_index = true;
                out.push_str("[*");
            }
            ']' => {
                in_index = false;
                out.push(']');
            }
            _ if in_index => {}
            _ => out.push(c),
        }
    }
    out
}

/// The UBX frames navsync's framer delivers from a capture: (offset, class, id, payload).
fn navsync_frames(bytes: &[u8]) -> Vec<(u64, u8, u8, Vec<u8>)> {
    let mut framer = UbxFramer::new();
    let mut frames = Vec::new();
    // One read whose last byte arrives at `len − 1` ns, one ns per byte: a frame's time is
    // the stream offset of its first byte.
    let last = bytes.len() as i64 - 1;
    framer.push(bytes, last, 1, &mut |f| {
        if let Frame::Ubx {
            class,
            id,
            payload,
            host_ns,
        } = f
        {
            frames.push((host_ns as u64, class, id, payload.to_vec()));
        }
    });
    assert_eq!(framer.counters().bytes, bytes.len() as u64);
    frames
}

/// The capture without gpsd's leading `#` comment lines (as `navsync decode` and the dump
/// script skip them).
fn receiver_bytes(path: &Path) -> Vec<u8> {
    let data = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut rest = &data[..];
    while rest.first() == Some(&b'#') {
        let len = rest.iter().position(|&b| b == b'\n').map_or(rest.len(), |i| i + 1);
        rest = &rest[len..];
    }
    rest.to_vec()
}

/// Per message type: messages and fields compared, fields agreeing.
#[derive(Default, Clone, Copy)]
struct Tally {
    messages: u64,
    fields: u64,
    agree: u64,
}

/// One disagreement, for the list.
struct Disagreement {
    capture: String,
    /// Index among the capture's UBX frames with a valid checksum: pyubx2's, navsync's.
    index: (i64, usize),
    offset: u64,
    identity: String,
    field: String,
    ours: String,
    theirs: String,
}

/// Compares navsync's fields with pyubx2's; the disagreeing fields (name, ours, theirs), the
/// fields compared, and for each [`DELIBERATE`] entry applied its name and whether it
/// converted (`true`) or skipped (`false`) the field.
fn compare(
    identity: &str,
    ours: &Fields,
    theirs: &serde_json::Map<String, Value>,
    applied: &mut Vec<(&'static str, bool)>,
) -> (Vec<(String, String, String)>, u64) {
    let mut bad = Vec::new();
    let mut compared = 0;
    let absent = V::Absent;
    let missing = Value::String("(missing)".into());
    // navsync's fields, then those only pyubx2 has.
    let ours_keys: BTreeSet<&str> = ours.v.iter().map(|(k, _)| k.as_str()).collect();
    let only_theirs = theirs.keys().filter(|k| !ours_keys.contains(k.as_str()));
    let all = ours
        .v
        .iter()
        .map(|(k, v)| (k.as_str(), v))
        .chain(only_theirs.map(|k| (k.as_str(), &absent)));
    for (key, v) in all {
        let t = theirs.get(key).unwrap_or(&missing);
        let pat = pattern(key);
        let ctx = Ctx {
            ours: v,
            theirs,
            block: block_index(key),
            blocks: ours.blocks,
        };
        let rule = DELIBERATE
            .iter()
            .find(|d| d.concerns(identity, &pat) && (d.applies)(&ctx));
        let mut t = t.clone();
        match rule.map(|d| (d.name, &d.treatment)) {
            Some((name, Treatment::NotCompared)) => {
                applied.push((name, false));
                continue;
            }
            Some((name, Treatment::Convert(conv))) => {
                if let Some(c) = conv(&t) {
                    applied.push((name, true));
                    t = c;
                }
            }
            None => {}
        }
        compared += 1;
        let shown = |v: &V| {
            if ours_keys.contains(key) {
                v.to_string()
            } else {
                "(missing)".into()
            }
        };
        if !v.agrees(&t) || t == missing {
            bad.push((key.to_string(), shown(v), t.to_string()));
        }
    }
    (bad, compared)
}

/// The file name of the simulator's receiver output among the captures.
const SIM_CAPTURE: &str = "sim-written.ubx";

/// 30 s of the simulated UBX receiver's bytes: 4 Hz epochs (NAV-PVT, NAV-EOE; TIM-TP on whole
/// seconds, its pulse on a 20.83 ns clock) and a 4 Hz camera on EXTINT0 (TIM-TM2).
fn sim_receiver_bytes() -> Vec<u8> {
    use navsync_sim::scenario::{OutputProtocol, SimConfig};
    use navsync_sim::world::{SimEvent, World};
    let mut cfg = SimConfig::default_drive();
    cfg.trajectory.segments.truncate(1);
    cfg.trajectory.segments[0].duration_s = 30.0;
    cfg.set_gnss_protocol(OutputProtocol::Ubx);
    cfg.set_gnss_rate_hz(4);
    cfg.set_camera_rate_hz(4.0);
    cfg.set_camera_exposure_offset_s(0.1);
    cfg.gnss.timepulse_quantization_ns = 20.83;
    // 2026-12-01 00:00:00.4 UTC.
    let mut world = World::new(&cfg, 1_000_000_000_000, 1_796_083_200_400_000_000).expect("the simulated world");
    let mut bytes = Vec::new();
    while let Some(e) = world.next_event() {
        if let SimEvent::Nmea { bytes: b, .. } = e {
            bytes.extend(b);
        }
    }
    bytes
}

fn run_dump(py: &Path, pythonpath: &Option<PathBuf>, captures: &[PathBuf]) -> Vec<Value> {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("python/ubx_pyubx2_dump.py");
    let mut c = Command::new(py);
    c.arg(&script).args(captures);
    if let Some(p) = pythonpath {
        c.env("PYTHONPATH", p);
    }
    let o = c.output().expect("running python");
    assert!(
        o.status.success(),
        "{} failed: {}",
        script.display(),
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8(o.stdout)
        .expect("UTF-8 output")
        .lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("bad dump line {l}: {e}")))
        .collect()
}

#[test]
fn ubx_decoders_agree_with_pyubx2_on_the_gpsd_captures() {
    let dir = shared_material("corpora/gpsd-ubx");
    let mut captures: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "log"))
        .collect();
    captures.sort();
    assert!(
        captures.len() >= EXPECTED_CAPTURES,
        "{} holds {} captures, expected {EXPECTED_CAPTURES}: the corpus is incomplete",
        dir.display(),
        captures.len()
    );

    let env = TestEnv::new("pyubx2");
    let (py, pythonpath) = python_with(&env.dir, &[PYUBX2])
        .unwrap_or_else(|why| panic!("cannot install {PYUBX2} (needs python3, pip and PyPI): {why}"));
    // The types the corpus lacks (NAV-VELNED, TIM-TM2, RXM-RAWX), built by pyubx2.
    let built = env.dir.join("pyubx2-built.ubx");
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("python/ubx_pyubx2_build.py");
    let mut c = Command::new(&py);
    c.arg(&script).arg(&built);
    if let Some(p) = &pythonpath {
        c.env("PYTHONPATH", p);
    }
    let o = c.output().expect("running python");
    assert!(
        o.status.success(),
        "{} failed: {}",
        script.display(),
        String::from_utf8_lossy(&o.stderr)
    );
    captures.push(built);
    let sim = env.dir.join(SIM_CAPTURE);
    std::fs::write(&sim, sim_receiver_bytes()).unwrap();
    captures.push(sim);
    let dump = run_dump(&py, &pythonpath, &captures);

    // pyubx2's frames by capture and offset.
    let mut theirs: HashMap<(String, u64), &Value> = HashMap::new();
    for rec in &dump {
        let key = (
            rec["capture"].as_str().expect("capture").to_string(),
            rec["offset"].as_u64().expect("offset"),
        );
        assert!(
            theirs.insert(key, rec).is_none(),
            "two pyubx2 frames at one offset: {rec}"
        );
    }

    let mut tally: BTreeMap<&str, Tally> = BTreeMap::new();
    let mut occurs: BTreeSet<String> = BTreeSet::new();
    let mut disagreements: Vec<Disagreement> = Vec::new();
    let mut unpaired: Vec<String> = Vec::new();
    let mut deliberate_used: BTreeMap<&str, (u64, u64)> = BTreeMap::new();
    // The first compared message of each type (pyubx2's fields, navsync's), for the
    // tightness check below.
    let mut first: BTreeMap<String, (serde_json::Map<String, Value>, Fields)> = BTreeMap::new();
    let mut per_capture = String::new();
    // TIM-TM2 of the simulator's camera compared.
    let mut sim_time_marks = 0u64;

    for path in &captures {
        let name = path.file_name().unwrap().to_string_lossy().to_string();
        let bytes = receiver_bytes(path);
        let ours_frames = navsync_frames(&bytes);
        let mut paired_offsets = BTreeSet::new();
        let (mut paired, mut listed) = (0u64, 0u64);
        for (index, (offset, class, id, payload)) in ours_frames.iter().enumerate() {
            let decoded = messages::decode(*class, *id, payload);
            if let Ok(m) = &decoded
                && TYPES.contains(&m.name())
            {
                occurs.insert(m.name().to_string());
            }
            let Some(rec) = theirs.get(&(name.clone(), *offset)) else {
                unpaired.push(format!(
                    "{name} @{offset}: navsync frame {class:#04x}/{id:#04x} ({} bytes) that pyubx2 does not deliver",
                    payload.len()
                ));
                continue;
            };
            paired_offsets.insert(*offset);
            paired += 1;
            let mut disagree = |identity: &str, field: &str, ours: String, theirs: String| {
                disagreements.push(Disagreement {
                    capture: name.clone(),
                    index: (rec["index"].as_i64().unwrap_or(-1), index),
                    offset: *offset,
                    identity: identity.to_string(),
                    field: field.to_string(),
                    ours,
                    theirs,
                })
            };
            let frame_ours = format!("{class:#04x}/{id:#04x}/{} bytes/checksum ok", payload.len());
            let frame_theirs = format!(
                "{:#04x}/{:#04x}/{} bytes/checksum {}",
                rec["class"].as_u64().unwrap_or(999),
                rec["id"].as_u64().unwrap_or(999),
                rec["length"],
                if rec["checksum_ok"] == true { "ok" } else { "bad" }
            );
            if frame_ours != frame_theirs {
                disagree("(frame)", "frame", frame_ours, frame_theirs);
                continue;
            }
            let identity = rec["identity"].as_str().unwrap_or("(pyubx2 parse error)");
            if TYPES.contains(&identity) {
                occurs.insert(identity.to_string());
            }
            let is_listed = TYPES.contains(&identity) || decoded.as_ref().is_ok_and(|m| TYPES.contains(&m.name()));
            if !is_listed {
                continue;
            }
            listed += 1;
            let t = tally
                .entry(TYPES.iter().find(|t| **t == identity).copied().unwrap_or("?"))
                .or_default();
            let msg = match decoded {
                Ok(m) if m.name() == identity => m,
                Ok(m) => {
                    disagree(identity, "identity", m.name().into(), identity.into());
                    continue;
                }
                Err(e) => {
                    disagree(identity, "decode", format!("error: {e}"), rec["error"].to_string());
                    continue;
                }
            };
            let Some(fields) = rec["fields"].as_object() else {
                disagree(identity, "decode", "decoded".into(), rec["error"].to_string());
                continue;
            };
            let mine = ours(&msg);
            let mut applied = Vec::new();
            let (bad, compared) = compare(identity, &mine, fields, &mut applied);
            for (dname, converted) in applied {
                let e = deliberate_used.entry(dname).or_default();
                if converted { e.0 += 1 } else { e.1 += 1 }
            }
            t.messages += 1;
            if name == SIM_CAPTURE && identity == "TIM-TM2" {
                sim_time_marks += 1;
            }
            t.fields += compared;
            t.agree += compared - bad.len() as u64;
            for (field, o, th) in bad {
                disagree(identity, &field, o, th);
            }
            first
                .entry(identity.to_string())
                .or_insert_with(|| (fields.clone(), mine));
        }
        // pyubx2's frames with a valid checksum that navsync's framer did not deliver.
        let mut theirs_here: Vec<&Value> = dump
            .iter()
            .filter(|r| r["capture"] == name.as_str() && r["checksum_ok"] == true)
            .collect();
        theirs_here.sort_by_key(|r| r["offset"].as_u64());
        for rec in &theirs_here {
            let offset = rec["offset"].as_u64().unwrap();
            if paired_offsets.contains(&offset) {
                continue;
            }
            if let Some(id) = rec["identity"].as_str()
                && TYPES.contains(&id)
            {
                occurs.insert(id.to_string());
            }
            unpaired.push(format!(
                "{name} @{offset}: pyubx2 frame {} (index {}) that navsync's framer does not deliver",
                rec["identity"], rec["index"]
            ));
        }
        writeln!(
            per_capture,
            "  {name:<34} navsync {:>5} UBX frames, pyubx2 {:>5} (valid checksum), paired {:>5}, compared {:>5}",
            ours_frames.len(),
            theirs_here.len(),
            paired,
            listed
        )
        .unwrap();
    }

    // --- report ---------------------------------------------------------------------------
    let mut report = String::new();
    writeln!(report, "pyubx2 cross-check ({PYUBX2}), {} captures:", captures.len()).unwrap();
    report.push_str(&per_capture);
    writeln!(
        report,
        "\n  {:<12} {:>8} {:>9} {:>9} {:>9}",
        "message", "messages", "fields", "agree", "agree %"
    )
    .unwrap();
    let mut total = Tally::default();
    for ty in TYPES {
        match tally.get(ty) {
            Some(t) => {
                writeln!(
                    report,
                    "  {ty:<12} {:>8} {:>9} {:>9} {:>9.3}",
                    t.messages,
                    t.fields,
                    t.agree,
                    100.0 * t.agree as f64 / t.fields.max(1) as f64
                )
                .unwrap();
                total.messages += t.messages;
                total.fields += t.fields;
                total.agree += t.agree;
            }
            None => writeln!(report, "  {ty:<12} {:>8}  (not in the corpus)", 0).unwrap(),
        }
    }
    let ratio = total.agree as f64 / total.fields.max(1) as f64;
    writeln!(
        report,
        "  {:<12} {:>8} {:>9} {:>9} {:>9.3}",
        "total",
        total.messages,
        total.fields,
        total.agree,
        100.0 * ratio
    )
    .unwrap();
    writeln!(report, "\n  deliberate differences (converted / not compared):").unwrap();
    for d in DELIBERATE {
        let (c, s) = deliberate_used.get(d.name).copied().unwrap_or_default();
        writeln!(report, "    {:<26} {c:>6} / {s:>6}  {}", d.name, d.reason).unwrap();
    }
    writeln!(report, "\n  disagreements: {}", disagreements.len()).unwrap();
    for d in &disagreements {
        writeln!(
            report,
            "    {} index {} (navsync {}) @{} {} {}: navsync {} pyubx2 {}",
            d.capture, d.index.0, d.index.1, d.offset, d.identity, d.field, d.ours, d.theirs
        )
        .unwrap();
    }
    writeln!(report, "  frames delivered by one side only: {}", unpaired.len()).unwrap();
    for u in &unpaired {
        writeln!(report, "    {u}").unwrap();
    }
    println!("{report}");

    // --- tightness: one unit of resolution is a disagreement ------------------------------
    let mut loose = Vec::new();
    for (identity, (fields, mine)) in &first {
        for (i, (key, v)) in mine.v.iter().enumerate() {
            let Some(nudged) = v.nudged() else { continue };
            let mut changed = mine.clone();
            changed.v[i].1 = nudged;
            let (bad, _) = compare(identity, &changed, fields, &mut Vec::new());
            if !bad.iter().any(|(k, _, _)| k == key) {
                loose.push(format!("{identity} {key}"));
            }
        }
    }

    // --- asserts ---------------------------------------------------------------------------
    let missing: Vec<&String> = occurs
        .iter()
        .filter(|ty| tally.get(ty.as_str()).is_none_or(|t| t.messages == 0))
        .collect();
    assert!(
        missing.is_empty(),
        "message types in the corpus never compared: {missing:?}"
    );
    // The 4 Hz camera from the first whole second (0.6 s into the scenario), its exposures
    // 0.1 s later, each in the TIM-TM2 of the next epoch up to the last (29.85 s): 117 marks.
    assert_eq!(sim_time_marks, 117, "the simulator's TIM-TM2 compared");
    assert!(
        loose.is_empty(),
        "a change of one unit of resolution goes unnoticed in: {loose:?}"
    );
    let stale: Vec<&str> = DELIBERATE
        .iter()
        .filter(|d| !deliberate_used.contains_key(d.name))
        .map(|d| d.name)
        .collect();
    assert!(
        stale.is_empty(),
        "deliberate differences that no longer apply: {stale:?}"
    );
    assert!(
        ratio >= MIN_AGREEMENT,
        "only {:.4} % of {} compared fields agree (need {} %)",
        100.0 * ratio,
        total.fields,
        100.0 * MIN_AGREEMENT
    );
    assert!(
        disagreements.is_empty() && unpaired.is_empty(),
        "{} field disagreements and {} unpaired frames with pyubx2 (listed above)",
        disagreements.len(),
        unpaired.len()
    );
    env.finish();
}
