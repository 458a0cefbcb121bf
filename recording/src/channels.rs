//! navsync's channel conventions in MCAP: what recorders, replayers, clients and tests agree on.
//!
//! * One channel per service; the topic is the service name (`navsync/imu/0/sample`).
//! * One schema per sample type: name = the type name with its layout version
//!   (`navsync.ImuSample.v1`), encoding `jsonschema`, data = [`json::schema`](navsync_shared::json::schema) of the type
//!   (JSON Schema draft 2020-12 with every field's units and frame as its description).
//! * Message encoding `json`: the sample as [`json::to_json`](navsync_shared::json::to_json) writes it (UTF-8, compact).
//!   Foxglove and the `mcap` tools display and plot these without navsync.
//! * Decoding is [`json::from_json`](navsync_shared::json::from_json), exact to the bit for every field (floats are written in
//!   the shortest form that parses back to the same `f64`, NaN as `null`).
//! * Channel metadata says what the data were made with, so `navsync replay --estimate` runs
//!   the estimator with the right models unless told otherwise: [`META_IMU_NOISE`] on IMU
//!   channels, [`META_INITIAL_STATE`] on the reference IMU's, [`META_LEVER_ARM`] and
//!   [`META_GNSS_VEL_STD`] on GNSS fix channels. Values are JSON.

use core::fmt::Debug;

use iceoryx2::prelude::ZeroCopySend;

use super::mcap_reader::{Channel, Schema};
use navsync_shared::json::{from_json, from_json_onto, schema, to_json};
use navsync_shared::reflect::Reflect;
use navsync_shared::samples::{
    AnySample, GnssEvent, GnssFix, GnssNavData, GnssRaw, GnssTimePulse, Health, ImuSample, NavState, PpsEdge, SimTruth,
    TimeState,
};
use navsync_shared::services::ServiceKind;

/// Message encoding of every navsync channel.
pub const MESSAGE_ENCODING: &str = "json";
/// Schema encoding of every navsync schema.
pub const SCHEMA_ENCODING: &str = "jsonschema";
/// The MCAP profile navsync writes (none of the well-known ROS profiles applies).
pub const PROFILE: &str = "";
/// The library string in the Header of files navsync writes.
pub const LIBRARY: &str = "navsync";

/// IMU channels: the IMU's noise model, `navsync_shared::imu_spec::ImuNoise` as JSON
/// (KF-GINS units).
pub const META_IMU_NOISE: &str = "navsync.imu_noise";
/// The reference IMU's channel: a known initial state, `navsync_estimator::settings::InitialState`
/// as JSON.
pub const META_INITIAL_STATE: &str = "navsync.initial_state";
/// GNSS fix channels: the antenna in the body frame (FRD) from the IMU, m, as `[x, y, z]`.
pub const META_LEVER_ARM: &str = "navsync.lever_arm_m";
/// GNSS fix channels: the receiver's velocity 1-sigma per axis, m/s, as a number.
pub const META_GNSS_VEL_STD: &str = "navsync.gnss_vel_std_mps";

/// A channel metadata value: `v` as compact JSON (what the `META_*` keys hold).
pub fn metadata_value<T: serde::Serialize + ?Sized>(v: &T) -> String {
    serde_json::to_string(v).unwrap_or_default()
}

/// A navsync sample type and its place in [`AnySample`].
pub trait SampleType: Reflect + ZeroCopySend + Debug {
    /// The kind of service that carries it.
    const KIND: ServiceKind;
    /// Wraps it.
    fn wrap(self) -> AnySample;
    /// Unwraps it, if `s` is of this type.
    fn unwrap(s: &AnySample) -> Option<&Self>;
}

macro_rules! sample_type {
    ($t:ty, $kind:ident, $variant:ident) => {
        impl SampleType for $t {
            const KIND: ServiceKind = ServiceKind::$kind;
            fn wrap(self) -> AnySample {
                AnySample::$variant(self)
            }
            fn unwrap(s: &AnySample) -> Option<&Self> {
                match s {
                    AnySample::$variant(x) => Some(x),
                    _ => None,
                }
            }
        }
    };
}
sample_type!(GnssFix, GnssFix, GnssFix);
sample_type!(PpsEdge, PpsEdge, PpsEdge);
sample_type!(ImuSample, ImuSample, Imu);
sample_type!(TimeState, TimeState, Time);
sample_type!(NavState, NavState, Nav);
sample_type!(Health, Health, Health);
sample_type!(SimTruth, SimTruth, Truth);
sample_type!(GnssTimePulse, GnssTimePulse, TimePulse);
sample_type!(GnssEvent, GnssEvent, Event);
sample_type!(GnssRaw, GnssRaw, Raw);
sample_type!(GnssNavData, GnssNavData, NavData);

/// Evaluates `$body` with the type alias `$T` set to the sample type of `$kind`.
#[macro_export]
macro_rules! with_sample_type {
    ($kind:expr, $T:ident => $body:expr) => {
        match $kind {
            navsync_shared::services::ServiceKind::GnssFix => {
                type $T = navsync_shared::samples::GnssFix;
                $body
            }
            navsync_shared::services::ServiceKind::PpsEdge => {
                type $T = navsync_shared::samples::PpsEdge;
                $body
            }
            navsync_shared::services::ServiceKind::ImuSample => {
                type $T = navsync_shared::samples::ImuSample;
                $body
            }
            navsync_shared::services::ServiceKind::TimeState => {
                type $T = navsync_shared::samples::TimeState;
                $body
            }
            navsync_shared::services::ServiceKind::NavState => {
                type $T = navsync_shared::samples::NavState;
                $body
            }
            navsync_shared::services::ServiceKind::Health => {
                type $T = navsync_shared::samples::Health;
                $body
            }
            navsync_shared::services::ServiceKind::SimTruth => {
                type $T = navsync_shared::samples::SimTruth;
                $body
            }
            navsync_shared::services::ServiceKind::GnssTimePulse => {
                type $T = navsync_shared::samples::GnssTimePulse;
                $body
            }
            navsync_shared::services::ServiceKind::GnssEvent => {
                type $T = navsync_shared::samples::GnssEvent;
                $body
            }
            navsync_shared::services::ServiceKind::GnssRaw => {
                type $T = navsync_shared::samples::GnssRaw;
                $body
            }
            navsync_shared::services::ServiceKind::GnssNavData => {
                type $T = navsync_shared::samples::GnssNavData;
                $body
            }
        }
    };
}

/// The schema name of a kind: its type name, e.g. `navsync.ImuSample.v1`.
pub fn schema_name(kind: ServiceKind) -> &'static str {
    kind.type_name()
}

/// The JSON Schema of a kind, as the bytes of a Schema record.
pub fn schema_data(kind: ServiceKind) -> Vec<u8> {
    with_sample_type!(kind, T => serde_json::to_vec(&schema::<T>()).unwrap_or_default())
}

/// The JSON value of a sample.
pub fn sample_json(sample: &AnySample) -> serde_json::Value {
    match sample {
        AnySample::GnssFix(x) => to_json(x),
        AnySample::PpsEdge(x) => to_json(x),
        AnySample::Imu(x) => to_json(x),
        AnySample::Time(x) => to_json(x),
        AnySample::Nav(x) => to_json(x),
        AnySample::Health(x) => to_json(x),
        AnySample::Truth(x) => to_json(x),
        AnySample::TimePulse(x) => to_json(x),
        AnySample::Event(x) => to_json(x),
        AnySample::Raw(x) => to_json(x),
        AnySample::NavData(x) => to_json(x),
    }
}

/// Encodes a sample as a message payload into `out` (cleared first; its capacity is reused).
pub fn encode(sample: &AnySample, out: &mut Vec<u8>) {
    out.clear();
    // Writing a `Value` into a `Vec` cannot fail.
    let _ = serde_json::to_writer(&mut *out, &sample_json(sample));
}

/// Decodes a message payload of a channel of `kind`.
pub fn decode(kind: ServiceKind, data: &[u8]) -> Result<AnySample, String> {
    decode_layout(ChannelType { kind, older: false }, data)
}

/// Decodes a message payload of a channel of type `ty`: an older layout
/// ([`OLDER_LAYOUTS`]) onto the type's "not known" values, so the fields added since read as
/// not known.
pub fn decode_layout(ty: ChannelType, data: &[u8]) -> Result<AnySample, String> {
    let v: serde_json::Value = serde_json::from_slice(data).map_err(|e| format!("not JSON: {e}"))?;
    if ty.older {
        return match ty.kind {
            ServiceKind::GnssFix => from_json_onto(&v, GnssFix::empty(navsync_shared::samples::Stamp::zeroed()))
                .map(AnySample::GnssFix)
                .map_err(|e| e.to_string()),
            _ => Err(format!("no older layout of {} is readable", ty.kind.type_name())),
        };
    }
    with_sample_type!(ty.kind, T => from_json::<T>(&v).map(T::wrap).map_err(|e| e.to_string()))
}

/// Schema names of older layouts that navsync still reads, with their kind: each newer layout
/// only added fields.
pub const OLDER_LAYOUTS: &[(&str, ServiceKind)] = &[("navsync.GnssFix.v1", ServiceKind::GnssFix)];

/// A channel's sample kind, and whether its messages have an older layout ([`OLDER_LAYOUTS`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ChannelType {
    /// The kind of sample.
    pub kind: ServiceKind,
    /// The messages have an older layout.
    pub older: bool,
}

/// The sample kind of a channel, checked against navsync's conventions: a navsync service
/// name as topic, `json` messages, and (when present) a `jsonschema` schema named after the
/// service's type. An error says what does not match.
pub fn channel_kind(channel: &Channel, schema: Option<&Schema>) -> Result<ChannelType, String> {
    let kind = ServiceKind::of(&channel.topic).ok_or_else(|| "not a navsync service name".to_string())?;
    if channel.message_encoding != MESSAGE_ENCODING {
        return Err(format!(
            "message encoding `{}`, expected `{MESSAGE_ENCODING}`",
            channel.message_encoding
        ));
    }
    if let Some(s) = schema
        && s.encoding == SCHEMA_ENCODING
        && OLDER_LAYOUTS.iter().any(|(name, k)| *name == s.name && *k == kind)
    {
        return Ok(ChannelType { kind, older: true });
    }
    if let Some(s) = schema
        && (s.name != kind.type_name() || s.encoding != SCHEMA_ENCODING)
    {
        return Err(format!(
            "schema `{}` ({}), expected `{}` ({SCHEMA_ENCODING}): a recording of another layout version",
            s.name,
            s.encoding,
            kind.type_name()
        ));
    }
    Ok(ChannelType { kind, older: false })
}

#[cfg(test)]
mod tests {
    use super::*;
    use navsync_shared::samples::{Stamp, StampSource};

    #[test]
    fn every_kind_has_a_schema_and_round_trips_bit_for_bit() {
        let mut x: u64 = 0x9E37_79B9_7F4A_7C15;
        let mut next = || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x
        };
        let mut buf = Vec::new();
        for _ in 0..2000 {
            let mut imu = ImuSample::zeroed();
            imu.stamp = Stamp::host(next() as i64 >> 1, next(), StampSource::Simulated);
            for v in imu.gyro_rps.iter_mut().chain(imu.accel_mps2.iter_mut()) {
                // Typical magnitudes and arbitrary bit patterns.
                *v = (next() >> 11) as f64 / (1u64 << 53) as f64 * 20.0 - 10.0;
            }
            imu.dt_s = f64::from_bits(next() & 0x7FEF_FFFF_FFFF_FFFF);
            imu.temperature_c = f64::NAN;
            let s = AnySample::Imu(imu);
            encode(&s, &mut buf);
            let back = decode(ServiceKind::ImuSample, &buf).unwrap();
            let AnySample::Imu(b) = back else { panic!("wrong kind") };
            assert_eq!(b.gyro_rps.map(f64::to_bits), imu.gyro_rps.map(f64::to_bits));
            assert_eq!(b.accel_mps2.map(f64::to_bits), imu.accel_mps2.map(f64::to_bits));
            assert_eq!(b.dt_s.to_bits(), imu.dt_s.to_bits());
            assert!(b.temperature_c.is_nan());
            assert_eq!(b.stamp, imu.stamp);
        }
        for kind in ServiceKind::ALL {
            let v: serde_json::Value = serde_json::from_slice(&schema_data(kind)).unwrap();
            assert_eq!(v["title"], kind.type_name());
            assert_eq!(v["type"], "object");
        }
    }

    #[test]
    fn channels_are_checked() {
        let ch = Channel {
            id: 1,
            schema_id: 1,
            topic: "navsync/imu/0/sample".into(),
            message_encoding: "json".into(),
            metadata: vec![],
        };
        let good = Schema {
            id: 1,
            name: "navsync.ImuSample.v1".into(),
            encoding: "jsonschema".into(),
            data: vec![],
        };
        assert_eq!(
            channel_kind(&ch, Some(&good)),
            Ok(ChannelType {
                kind: ServiceKind::ImuSample,
                older: false
            })
        );
        let old = Schema {
            name: "navsync.ImuSample.v0".into(),
            ..good.clone()
        };
        assert!(channel_kind(&ch, Some(&old)).unwrap_err().contains("layout version"));
        let other = Channel {
            topic: "/tf".into(),
            ..ch.clone()
        };
        assert!(channel_kind(&other, None).is_err());
        assert!(decode(ServiceKind::NavState, b"{").unwrap_err().starts_with("not JSON"));
    }

    #[test]
    fn a_gnss_fix_of_the_older_layout_reads_with_the_new_fields_not_known() {
        let mut fix = GnssFix::empty(Stamp::host(5, 7, StampSource::Receipt));
        fix.lat_deg = 48.1;
        fix.h_acc_m = 0.02;
        let mut v = sample_json(&AnySample::GnssFix(fix));
        let obj = v.as_object_mut().unwrap();
        for added in [
            "h_acc_m",
            "v_acc_m",
            "s_acc_mps",
            "head_acc_deg",
            "fix_flags",
            "protocol",
        ] {
            assert!(obj.remove(added).is_some(), "{added}");
        }
        let data = serde_json::to_vec(&v).unwrap();
        let ch = Channel {
            id: 1,
            schema_id: 1,
            topic: "navsync/gnss/0/fix".into(),
            message_encoding: "json".into(),
            metadata: vec![],
        };
        let v1 = Schema {
            id: 1,
            name: "navsync.GnssFix.v1".into(),
            encoding: "jsonschema".into(),
            data: vec![],
        };
        let ty = channel_kind(&ch, Some(&v1)).unwrap();
        assert!(ty.older);
        let AnySample::GnssFix(back) = decode_layout(ty, &data).unwrap() else {
            panic!("not a fix")
        };
        assert_eq!(back.lat_deg, 48.1);
        assert_eq!(back.stamp.seq, 7);
        assert!(back.h_acc_m.is_nan(), "added since: not known");
        assert!(decode(ServiceKind::GnssFix, &data).unwrap_err().contains("missing"));
    }
}
