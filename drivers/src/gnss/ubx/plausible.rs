//! Plausibility at the UBX decoder's edge: a frame whose checksum is right can still carry
//! values the message's interface description does not allow (u-blox 8 / M8 Receiver
//! Description and Protocol Specification, UBX-13003221, and the ZED-F9P Interface
//! Description, UBX-18010854: NAV-PVT, NAV-SOL, NAV-POSLLH, NAV-VELNED, NAV-STATUS, HNR-PVT). Such
//! values are counted (`ubx_out_of_range`) and dropped before the epoch assembler sees them:
//!
//! * a field that is one measurement (ground speed below 0, a heading of motion outside
//!   [0°, 360°), a UTC date or time of day outside the calendar) becomes "not available" (NaN,
//!   or its validity flag cleared), the rest of the message is used;
//! * a message whose solution itself is out of range (a fix type above 5, a latitude beyond
//!   ±90° or a longitude beyond ±180° where the position is claimed valid) is dropped whole.

use super::messages::Message;

/// The highest fix type the interface description defines (5: time only).
pub const MAX_FIX_TYPE: u8 = 5;

/// What [`check`] did to a message.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Checked {
    /// Fields made "not available".
    pub fields_dropped: u32,
    /// The whole message is out of range: dropped.
    pub dropped: bool,
}

impl Checked {
    /// Values out of range found (a dropped message counts once).
    pub fn out_of_range(&self) -> u64 {
        u64::from(self.fields_dropped) + u64::from(self.dropped)
    }
}

fn lat_lon_ok(lat: f64, lon: f64) -> bool {
    lat.abs() <= 90.0 && lon.abs() <= 180.0
}

/// NaN (and one more field dropped) when `v` is outside `ok`.
fn field(v: &mut f64, ok: impl Fn(f64) -> bool, c: &mut Checked) {
    if v.is_finite() && !ok(*v) {
        *v = f64::NAN;
        c.fields_dropped += 1;
    }
}

fn speed_ok(v: f64) -> bool {
    v >= 0.0
}

fn heading_ok(v: f64) -> bool {
    (0.0..360.0).contains(&v)
}

/// `valid` with its date (bit 0) and time (bit 1) flags cleared where the calendar says no.
fn utc_valid(valid: u8, month: u8, day: u8, hour: u8, min: u8, sec: u8, c: &mut Checked) -> u8 {
    let mut v = valid;
    if v & 0x01 != 0 && !((1..=12).contains(&month) && (1..=31).contains(&day)) {
        v &= !0x01;
        c.fields_dropped += 1;
    }
    if v & 0x02 != 0 && !(hour <= 23 && min <= 59 && sec <= 60) {
        v &= !0x02;
        c.fields_dropped += 1;
    }
    v
}

/// Checks a decoded message against its interface description, dropping what is out of range
/// (see the [module](self) documentation).
pub fn check(msg: &mut Message) -> Checked {
    let mut c = Checked::default();
    match msg {
        Message::NavPvt(m) => {
            let llh_valid = m.fix_type >= 2 && !m.invalid_llh();
            if m.fix_type > MAX_FIX_TYPE || (llh_valid && !lat_lon_ok(m.lat_deg, m.lon_deg)) {
                c.dropped = true;
                return c;
            }
            m.valid = utc_valid(m.valid, m.month, m.day, m.hour, m.min, m.sec, &mut c);
            field(&mut m.g_speed_mps, speed_ok, &mut c);
            field(&mut m.head_mot_deg, heading_ok, &mut c);
        }
        Message::HnrPvt(m) => {
            if m.gps_fix > MAX_FIX_TYPE || (m.gps_fix >= 2 && !lat_lon_ok(m.lat_deg, m.lon_deg)) {
                c.dropped = true;
                return c;
            }
            m.valid = utc_valid(m.valid, m.month, m.day, m.hour, m.min, m.sec, &mut c);
            field(&mut m.g_speed_mps, speed_ok, &mut c);
            field(&mut m.speed_mps, speed_ok, &mut c);
            field(&mut m.head_mot_deg, heading_ok, &mut c);
        }
        Message::NavSol(m) => c.dropped = m.gps_fix > MAX_FIX_TYPE,
        Message::NavStatus(m) => c.dropped = m.gps_fix > MAX_FIX_TYPE,
        Message::NavPosllh(m) => c.dropped = !lat_lon_ok(m.lat_deg, m.lon_deg),
        Message::NavVelned(m) => field(&mut m.heading_deg, heading_ok, &mut c),
        _ => {}
    }
    c
}

#[cfg(test)]
mod tests {
    use super::super::messages::decode;
    use super::super::nav::tests::pvt;
    use super::*;

    fn set_i4(p: &mut [u8], at: usize, v: i32) {
        p[at..at + 4].copy_from_slice(&v.to_le_bytes());
    }

    #[test]
    fn a_pvt_within_the_description_passes_untouched() {
        let p = pvt(1000, 3, 1);
        let mut m = decode(1, 7, &p).unwrap();
        let before = m;
        assert_eq!(check(&mut m), Checked::default());
        assert_eq!(m, before);
    }

    #[test]
    fn out_of_range_fields_are_dropped_and_out_of_range_solutions_whole() {
        // gSpeed −11.5 m/s and headMot 999.4°: the fields go, the fix stays.
        let mut p = pvt(1000, 3, 1);
        set_i4(&mut p, 60, -11_500);
        set_i4(&mut p, 64, 99_940_000);
        let mut m = decode(1, 7, &p).unwrap();
        let c = check(&mut m);
        assert_eq!((c.fields_dropped, c.dropped), (2, false));
        let Message::NavPvt(v) = m else { panic!() };
        assert!(v.g_speed_mps.is_nan() && v.head_mot_deg.is_nan());
        assert!(v.lat_deg.is_finite());
        // A fix type the description does not define: the message goes.
        let mut m = decode(1, 7, &pvt(1000, 9, 1)).unwrap();
        assert!(check(&mut m).dropped);
        // A latitude of 120° with a valid 3D fix (flags3 without invalidLlh).
        let mut p = pvt(1000, 3, 1);
        set_i4(&mut p, 28, 1_200_000_000);
        p[78] = 0;
        let mut m = decode(1, 7, &p).unwrap();
        assert_eq!(check(&mut m).out_of_range(), 1);
        // A month 13 claimed valid: the date flag is cleared.
        let mut p = pvt(1000, 3, 1);
        p[6] = 13;
        p[11] |= 0x03;
        let mut m = decode(1, 7, &p).unwrap();
        let c = check(&mut m);
        let Message::NavPvt(v) = m else { panic!() };
        assert_eq!((c.fields_dropped, v.valid & 0x01), (1, 0));
    }
}
