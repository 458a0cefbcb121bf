//! UBX messages as the samples navsync publishes beside the fixes: RXM-RAWX → [`GnssRaw`],
//! RXM-SFRBX → [`GnssNavData`], ESF-MEAS → [`ImuSample`] (the receiver's own IMU), the
//! satellites of an epoch (NAV-SAT, NAV-SVINFO) → [`GnssSky`]. Pure.
//!
//! ESF-MEAS data types and scales (u-blox 8 / M8 Receiver Description, UBX-ESF-MEAS, "data
//! type" table): 14/13/5 gyroscope x/y/z angular rate, deg/s × 2⁻¹², 16/17/18 accelerometer
//! x/y/z specific force, m/s² × 2⁻¹⁰, 12 gyroscope temperature, °C × 10⁻². The axes are the
//! receiver's IMU frame as the receiver reports it (u-blox: x forward, y right, z down once
//! installed as its integration manual says); a different mounting is the IMU's `mounting`
//! in navsync's configuration, as for any IMU.

use navsync_shared::reflect::Reflect;
use navsync_shared::samples::{
    GNSS_PROTOCOL_UBX, GnssNavData, GnssRaw, GnssSky, ImuSample, MAX_NAV_WORDS, MAX_RAW_MEASUREMENTS, RawMeasurement,
    SkySatellite, Stamp, StampSource,
};

use super::epoch::SatView;
use super::esf::EsfMeas;
use super::rxm::{RawxMeas, RxmRawx, RxmSfrbx};

/// The satellites of an epoch (NAV-SAT, or NAV-SVINFO with its legacy numbers converted) as a
/// [`GnssSky`] sample stamped at the message's receipt with sequence number `seq`: elevation
/// and azimuth where the message gives them (|elev| ≤ 90°, azimuth 0..=360°, 360 as 0), C/N0
/// (0 not tracked), `svUsed`.
pub fn sky_sample(v: &SatView, seq: u64) -> GnssSky {
    let mut out = GnssSky::empty(Stamp::host(v.host_ns, seq, StampSource::Receipt));
    out.utc_ns = v.utc_ns;
    out.protocol = GNSS_PROTOCOL_UBX;
    for s in v.satellites() {
        out.push(SkySatellite {
            elevation_deg: s.elevation_deg().map_or(f32::NAN, f32::from),
            azimuth_deg: s.azimuth_deg().map_or(f32::NAN, f32::from),
            gnss_id: s.gnss_id,
            sv_id: s.sv_id,
            cno_dbhz: s.cno_dbhz,
            used: u8::from(s.used),
        });
    }
    out.dropped = out.dropped.saturating_add(u8::try_from(v.dropped).unwrap_or(u8::MAX));
    out
}

/// RXM-RAWX as a [`GnssRaw`] sample stamped at `host_ns` with sequence number `seq`.
pub fn raw_sample(m: &RxmRawx, host_ns: i64, seq: u64) -> GnssRaw {
    let mut out = GnssRaw {
        stamp: Stamp::host(host_ns, seq, StampSource::Receipt),
        rcv_tow_s: m.rcv_tow_s,
        week: m.week,
        leap_s: i16::from(m.leap_s),
        num_meas: 0,
        rec_stat: m.rec_stat,
        dropped: 0,
        reserved: 0,
        meas: [RawMeasurement {
            pseudorange_m: 0.0,
            carrier_phase_cycles: 0.0,
            doppler_hz: 0.0,
            pseudorange_std_m: 0.0,
            carrier_phase_std_cycles: 0.0,
            doppler_std_hz: 0.0,
            lock_time_ms: 0,
            gnss_id: 0,
            sv_id: 0,
            sig_id: 0,
            freq_id: 0,
            cno_dbhz: 0,
            trk_stat: 0,
        }; MAX_RAW_MEASUREMENTS],
    };
    let valid = m.meas.get(..m.len).unwrap_or(&[]);
    // Beyond the capacity the signals of lower `keep_rank` are kept first.
    let ranked = (0..=2u8).flat_map(|rank| valid.iter().map(raw_measurement).filter(move |r| r.keep_rank() == rank));
    for (o, r) in out.meas.iter_mut().zip(ranked) {
        *o = r;
    }
    let kept = valid.len().min(MAX_RAW_MEASUREMENTS);
    out.num_meas = kept as u8;
    out.dropped = (m.dropped + valid.len() - kept).min(255) as u8;
    out
}

/// One RXM-RAWX measurement as a [`RawMeasurement`].
fn raw_measurement(x: &RawxMeas) -> RawMeasurement {
    RawMeasurement {
        pseudorange_m: x.pr_mes_m,
        carrier_phase_cycles: x.cp_mes_cycles,
        doppler_hz: x.do_mes_hz,
        pseudorange_std_m: x.pr_stdev_m as f32,
        carrier_phase_std_cycles: x.cp_stdev_cycles as f32,
        doppler_std_hz: x.do_stdev_hz as f32,
        lock_time_ms: x.locktime_ms,
        gnss_id: x.gnss_id,
        sv_id: x.sv_id,
        sig_id: x.sig_id,
        freq_id: x.freq_id,
        cno_dbhz: x.cno_dbhz,
        trk_stat: x.trk_stat,
    }
}

/// RXM-SFRBX as a [`GnssNavData`] sample (words unchanged) stamped at `host_ns`, sequence `seq`.
pub fn nav_data_sample(m: &RxmSfrbx, host_ns: i64, seq: u64) -> GnssNavData {
    let mut words = [0u32; MAX_NAV_WORDS];
    let n = m.len.min(MAX_NAV_WORDS);
    words[..n].copy_from_slice(&m.words[..n]);
    GnssNavData {
        stamp: Stamp::host(host_ns, seq, StampSource::Receipt),
        words,
        gnss_id: m.gnss_id,
        sv_id: m.sv_id,
        sig_id: m.sig_id,
        freq_id: m.freq_id,
        num_words: n as u8,
        channel: m.chn,
        version: m.version,
        reserved: 0,
    }
}

/// Gyroscope rate scale, deg/s per LSB.
const GYRO_DPS_PER_LSB: f64 = 1.0 / 4096.0;
/// Accelerometer scale, m/s² per LSB.
const ACCEL_MPS2_PER_LSB: f64 = 1.0 / 1024.0;

/// Gyroscope and accelerometer readings farther apart than this are not one sample, ms.
pub const ESF_PAIR_MS: u32 = 25;

/// Assembles the receiver's IMU readings (ESF-MEAS) into [`ImuSample`]s. Receivers send the
/// gyroscope triad and the accelerometer triad in one message or in two with their own time
/// tags a few ms apart (NEO-M8L: accelerometer 5 ms after the gyroscope); a sample is the
/// latest gyroscope triad with the latest accelerometer triad within [`ESF_PAIR_MS`], at the
/// later time tag. Other readings (wheel ticks) do not disturb the pairing. The interval is the
/// time-tag difference to the previous sample (the first one, without a predecessor, is not
/// emitted).
#[derive(Debug, Clone, Copy, Default)]
pub struct EsfImu {
    gyro: Option<(u32, [Option<f64>; 3])>,
    accel: Option<(u32, [Option<f64>; 3])>,
    temperature_c: Option<f64>,
    last_emitted_tag_ms: Option<u32>,
    seq: u64,
}

impl EsfImu {
    /// Takes one ESF-MEAS received at `host_ns`; returns the sample it completes, if any.
    /// `imu_id` is left empty (the driver names the IMU); `device_ns` carries the time tag.
    pub fn push(&mut self, m: &EsfMeas, host_ns: i64) -> Option<ImuSample> {
        let tag = m.time_tag_ms;
        for r in m.readings() {
            let v = f64::from(r.value);
            let (slot, axis, value) = match r.data_type {
                14 => (&mut self.gyro, 0, v * GYRO_DPS_PER_LSB),
                13 => (&mut self.gyro, 1, v * GYRO_DPS_PER_LSB),
                5 => (&mut self.gyro, 2, v * GYRO_DPS_PER_LSB),
                16 => (&mut self.accel, 0, v * ACCEL_MPS2_PER_LSB),
                17 => (&mut self.accel, 1, v * ACCEL_MPS2_PER_LSB),
                18 => (&mut self.accel, 2, v * ACCEL_MPS2_PER_LSB),
                12 => {
                    self.temperature_c = Some(v * 1e-2);
                    continue;
                }
                _ => continue,
            };
            let triad = slot.get_or_insert((tag, [None; 3]));
            if triad.0 != tag {
                *triad = (tag, [None; 3]);
            }
            triad.1[axis] = Some(value);
        }
        let (Some((tg, [Some(gx), Some(gy), Some(gz)])), Some((ta, [Some(ax), Some(ay), Some(az)]))) =
            (self.gyro, self.accel)
        else {
            return None;
        };
        if tg.abs_diff(ta) > ESF_PAIR_MS {
            return None;
        }
        let tag = tg.max(ta);
        self.gyro = None;
        self.accel = None;
        let prev = self.last_emitted_tag_ms.replace(tag);
        let dt_ms = tag.wrapping_sub(prev?);
        if dt_ms == 0 || dt_ms > 1000 {
            return None;
        }
        let mut s = ImuSample::zeroed();
        s.stamp = Stamp::with_device(host_ns, i64::from(tag) * 1_000_000, self.seq, StampSource::Receipt);
        self.seq += 1;
        s.gyro_rps = [gx.to_radians(), gy.to_radians(), gz.to_radians()];
        s.accel_mps2 = [ax, ay, az];
        s.dt_s = f64::from(dt_ms) / 1e3;
        s.temperature_c = self.temperature_c.unwrap_or(f64::NAN);
        Some(s)
    }
}

#[cfg(test)]
mod tests {
    use super::super::esf::EsfData;
    use super::super::messages::MAX_ESF;
    use super::*;

    fn meas(tag: u32, readings: &[(u8, i32)]) -> EsfMeas {
        let mut data = [EsfData { data_type: 0, value: 0 }; MAX_ESF];
        for (d, &(t, v)) in data.iter_mut().zip(readings) {
            *d = EsfData { data_type: t, value: v };
        }
        EsfMeas {
            time_tag_ms: tag,
            flags: (readings.len() as u16) << 11,
            id: 0,
            data,
            len: readings.len(),
            dropped: 0,
            calib_ttag_ms: None,
        }
    }

    #[test]
    fn esf_readings_become_imu_samples_in_si_units() {
        let mut imu = EsfImu::default();
        let gyro = |tag| meas(tag, &[(14, 4096), (13, -2048), (5, 0), (12, 2_550)]);
        let accel = |tag| meas(tag, &[(16, 1024), (17, 0), (18, -10_035)]);
        assert_eq!(imu.push(&accel(1005), 1), None);
        assert_eq!(imu.push(&gyro(1000), 2), None, "no interval before the first");
        // As a NEO-M8L sends them: the gyroscope, wheel ticks, then the accelerometer 5 ms later.
        assert_eq!(imu.push(&gyro(1090), 3), None);
        assert_eq!(imu.push(&meas(1100, &[(10, 77)]), 4), None);
        let s = imu.push(&accel(1095), 5).expect("complete");
        assert!(
            (s.gyro_rps[0] - 1f64.to_radians()).abs() < 1e-12 && (s.gyro_rps[1] + 0.5f64.to_radians()).abs() < 1e-12
        );
        assert!((s.accel_mps2[0] - 1.0).abs() < 1e-12 && (s.accel_mps2[2] + 10_035.0 / 1024.0).abs() < 1e-12);
        assert_eq!(
            (s.dt_s, s.stamp.host_ns, s.stamp.device_ns, s.stamp.seq),
            (0.09, 5, 1_095_000_000, 0)
        );
        assert_eq!(s.temperature_c, 25.5);
        // Triads too far apart are not one sample.
        assert_eq!(imu.push(&gyro(1180), 6), None);
        assert_eq!(imu.push(&accel(1240), 7), None);
        // One message with both triads.
        let both = meas(1300, &[(14, 0), (13, 0), (5, 0), (16, 0), (17, 0), (18, 0)]);
        assert_eq!(imu.push(&both, 8).map(|s| (s.stamp.seq, s.dt_s)), Some((1, 0.205)));
    }
}
