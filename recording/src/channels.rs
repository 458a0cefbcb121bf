//! navsync's channel conventions in MCAP: what recorders, replayers, clients and tests agree on.
//! A navsync recording is a ROS 2 bag in MCAP storage (profile `ros2`):
//!
//! * One channel per service; the topic is the service name as a ROS 2 topic
//!   (`/navsync/imu/0/sample` for the service `navsync/imu/0/sample`).
//! * Message encoding `cdr` ([`cdr`](navsync_shared::cdr), exact to the bit for every field);
//!   one schema per sample type, encoding `ros2msg`, named after the ROS 2 type
//!   (`navsync_msgs/msg/ImuSample`), data = the full `.msg` definition with its dependencies
//!   ([`ros2msg::definition`](navsync_shared::ros2msg::definition)), every field's units and frame in comments.
//!   `ros2 bag`, Foxglove, PlotJuggler and rosbags open these without navsync.
//! * Channel metadata: `offered_qos_profiles` (what rosbag2 writes: reliable, volatile,
//!   keep last), [`META_LAYOUT`] (the layout version, `navsync.ImuSample.v1`), and what the data
//!   were made with, so `navsync replay --estimate` runs the estimator with the right models
//!   unless told otherwise: [`META_IMU_NOISE`] on IMU channels, [`META_INITIAL_STATE`] and
//!   [`META_TIME_AXIS`] on the reference IMU's, [`META_LEVER_ARM`] and [`META_GNSS_VEL_STD`] on
//!   GNSS fix channels. Values are JSON.
//! * Text instead of CDR (`navsync record --encoding json`, and every recording of navsync
//!   before CDR): message encoding `json` ([`json::to_json`](navsync_shared::json::to_json)),
//!   schema encoding `jsonschema` named `navsync.ImuSample.v1`. Both are read.
//! * A channel written by another tool (no [`META_LAYOUT`]) is read when its schema's fields
//!   equal navsync's definition ([`ros2msg::check_compatible`](navsync_shared::ros2msg::check_compatible)).

use core::fmt::Debug;

use super::mcap_reader::{Channel, Schema};
use navsync_shared::json::{from_json, from_json_onto, schema, to_json};
use navsync_shared::reflect::Reflect;
use navsync_shared::samples::{
    AnySample, EstimatorSettings, EventPose, GnssEvent, GnssFix, GnssNavData, GnssRaw, GnssSky, GnssTimePulse, Health,
    ImuSample, NavState, NetworkTime, PpsEdge, SimTruth, TimeState,
};
use navsync_shared::services::ServiceKind;
use navsync_shared::{cdr, ros2msg};

/// How the messages of a recording are encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Encoding {
    /// CDR with `ros2msg` schemas: a ROS 2 bag (the default).
    #[default]
    Cdr,
    /// JSON with JSON Schemas: text a person can read (larger, slower to replay).
    Json,
}

impl Encoding {
    /// The MCAP message encoding.
    pub fn message_encoding(self) -> &'static str {
        match self {
            Self::Cdr => "cdr",
            Self::Json => "json",
        }
    }

    /// The MCAP schema encoding.
    pub fn schema_encoding(self) -> &'static str {
        match self {
            Self::Cdr => "ros2msg",
            Self::Json => "jsonschema",
        }
    }

    /// The schema name of a kind in this encoding.
    pub fn schema_name(self, kind: ServiceKind) -> String {
        match self {
            Self::Cdr => ros2msg::ros_type_name(kind.type_name()),
            Self::Json => kind.type_name().to_string(),
        }
    }

    /// The schema of a kind in this encoding, as the bytes of a Schema record.
    pub fn schema_data(self, kind: ServiceKind) -> Vec<u8> {
        match self {
            Self::Cdr => crate::with_sample_type!(kind, T => ros2msg::definition::<T>().into_bytes()),
            Self::Json => crate::with_sample_type!(kind, T => serde_json::to_vec(&schema::<T>()).unwrap_or_default()),
        }
    }

    /// Encodes a sample as a message payload into `out` (cleared first; its capacity is
    /// reused: CDR allocates nothing once it has grown).
    pub fn encode(self, sample: &AnySample, out: &mut Vec<u8>) {
        match self {
            Self::Cdr => encode_cdr(sample, out),
            Self::Json => {
                out.clear();
                // Writing a `Value` into a `Vec` cannot fail.
                let _ = serde_json::to_writer(&mut *out, &sample_json(sample));
            }
        }
    }
}

/// The MCAP profile navsync writes: its files are ROS 2 bags.
pub const PROFILE: &str = "ros2";
/// The library string in the Header of files navsync writes.
pub const LIBRARY: &str = concat!("navsync ", env!("CARGO_PKG_VERSION"), " (mcap crate)");

/// Every channel navsync writes: the sample type's layout version, e.g. `navsync.ImuSample.v1`.
pub const META_LAYOUT: &str = "navsync.layout";
/// Channel metadata key of the QoS profiles rosbag2 expects on every channel.
pub const META_QOS: &str = "offered_qos_profiles";
/// The QoS that `ros2 bag record` stores for a reliable, volatile, keep-last publisher (YAML,
/// rosbag2's format since Humble): what `ros2 bag play` offers when it plays the file.
pub const QOS_PROFILES: &str = "- history: 3
  depth: 0
  reliability: 1
  durability: 2
  deadline:
    sec: 2147483647
    nsec: 4294967295
  lifespan:
    sec: 2147483647
    nsec: 4294967295
  liveliness: 1
  liveliness_lease_duration:
    sec: 2147483647
    nsec: 4294967295
  avoid_ros_namespace_conventions: false";

/// The ROS 2 topic of a navsync service: `navsync/imu/0/sample` → `/navsync/imu/0/sample`.
pub fn topic_of(service: &str) -> String {
    format!("/{service}")
}

/// The navsync service of a topic: `/navsync/imu/0/sample` (or the bare service name, as
/// JSON recordings have it) → `navsync/imu/0/sample`.
pub fn service_of(topic: &str) -> &str {
    topic.strip_prefix('/').unwrap_or(topic)
}

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
/// The reference IMU's channel: the recording's exact time axis (an import's time tags),
/// `navsync_estimator::settings::TimeAxis` as JSON: outputs are labelled on it.
pub const META_TIME_AXIS: &str = "navsync.time_axis";

/// A channel metadata value: `v` as compact JSON (what the `META_*` keys hold).
pub fn metadata_value<T: serde::Serialize + ?Sized>(v: &T) -> String {
    serde_json::to_string(v).unwrap_or_default()
}

/// A navsync sample type and its place in [`AnySample`].
pub trait SampleType: navsync_shared::ipc::IpcSample {
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
sample_type!(EstimatorSettings, EstimatorSettings, Settings);
sample_type!(NetworkTime, NetworkTime, NetworkTime);
sample_type!(GnssSky, GnssSky, Sky);
sample_type!(EventPose, EventPose, EventPose);

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
            navsync_shared::services::ServiceKind::EstimatorSettings => {
                type $T = navsync_shared::samples::EstimatorSettings;
                $body
            }
            navsync_shared::services::ServiceKind::NetworkTime => {
                type $T = navsync_shared::samples::NetworkTime;
                $body
            }
            navsync_shared::services::ServiceKind::GnssSky => {
                type $T = navsync_shared::samples::GnssSky;
                $body
            }
            navsync_shared::services::ServiceKind::EventPose => {
                type $T = navsync_shared::samples::EventPose;
                $body
            }
        }
    };
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
        AnySample::Settings(x) => to_json(x),
        AnySample::NetworkTime(x) => to_json(x),
        AnySample::Sky(x) => to_json(x),
        AnySample::EventPose(x) => to_json(x),
    }
}

/// Encodes a sample as CDR into `out`.
fn encode_cdr(sample: &AnySample, out: &mut Vec<u8>) {
    match sample {
        AnySample::GnssFix(x) => cdr::encode(x, out),
        AnySample::PpsEdge(x) => cdr::encode(x, out),
        AnySample::Imu(x) => cdr::encode(x, out),
        AnySample::Time(x) => cdr::encode(x, out),
        AnySample::Nav(x) => cdr::encode(x, out),
        AnySample::Health(x) => cdr::encode(x, out),
        AnySample::Truth(x) => cdr::encode(x, out),
        AnySample::TimePulse(x) => cdr::encode(x, out),
        AnySample::Event(x) => cdr::encode(x, out),
        AnySample::Raw(x) => cdr::encode(x, out),
        AnySample::NavData(x) => cdr::encode(x, out),
        AnySample::Settings(x) => cdr::encode(x, out),
        AnySample::NetworkTime(x) => cdr::encode(x, out),
        AnySample::Sky(x) => cdr::encode(x, out),
        AnySample::EventPose(x) => cdr::encode(x, out),
    }
}

/// Schema names of older JSON layouts that navsync still reads, with their kind: each newer
/// layout only added fields.
pub const OLDER_LAYOUTS: &[(&str, ServiceKind)] = &[
    ("navsync.GnssFix.v1", ServiceKind::GnssFix),
    // v2 names the formerly reserved byte `integrity` (0 = no flag, as every v1 state was).
    ("navsync.NavState.v1", ServiceKind::NavState),
];

/// How a channel's messages decode.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Codec {
    /// CDR of the current layout.
    Cdr,
    /// JSON of the current layout.
    Json,
    /// JSON of an older layout ([`OLDER_LAYOUTS`]): the fields added since read as not known.
    JsonOlder,
}

/// A channel's sample kind and codec.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ChannelType {
    /// The kind of sample.
    pub kind: ServiceKind,
    /// How its messages decode.
    pub codec: Codec,
}

/// Decodes a message payload of a channel of type `ty`.
pub fn decode(ty: ChannelType, data: &[u8]) -> Result<AnySample, String> {
    match ty.codec {
        Codec::Cdr => {
            crate::with_sample_type!(ty.kind, T => cdr::decode::<T>(data).map(T::wrap).map_err(|e| e.to_string()))
        }
        Codec::Json | Codec::JsonOlder => {
            let v: serde_json::Value = serde_json::from_slice(data).map_err(|e| format!("not JSON: {e}"))?;
            if ty.codec == Codec::JsonOlder {
                return match ty.kind {
                    ServiceKind::GnssFix => {
                        from_json_onto(&v, GnssFix::empty(navsync_shared::samples::Stamp::zeroed()))
                            .map(AnySample::GnssFix)
                            .map_err(|e| e.to_string())
                    }
                    ServiceKind::NavState => from_json_onto(&v, NavState::zeroed())
                        .map(AnySample::Nav)
                        .map_err(|e| e.to_string()),
                    _ => Err(format!("no older layout of {} is readable", ty.kind.type_name())),
                };
            }
            crate::with_sample_type!(ty.kind, T => from_json::<T>(&v).map(T::wrap).map_err(|e| e.to_string()))
        }
    }
}

/// The sample kind and codec of a channel, checked against navsync's conventions: a navsync
/// service as topic (with or without the leading `/`), and either `cdr` messages with a
/// `ros2msg` schema of the service's type (navsync's layout version in [`META_LAYOUT`], or, from
/// another writer, the same fields), or `json` messages with a `jsonschema` schema named after
/// the type. An error says what does not match.
pub fn channel_kind(channel: &Channel, schema: Option<&Schema>) -> Result<ChannelType, String> {
    if let Some(s) = schema
        && crate::ros_std::StdType::ALL.iter().any(|t| t.name() == s.name)
    {
        return Err(format!(
            "{}: a standard ROS 2 message derived from navsync's own (--ros-std)",
            s.name
        ));
    }
    let kind = ServiceKind::of(service_of(&channel.topic)).ok_or_else(|| "not a navsync service name".to_string())?;
    match channel.message_encoding.as_str() {
        "cdr" => {
            let Some(s) = schema else {
                return Err("a cdr channel without a schema".into());
            };
            let want = ros2msg::ros_type_name(kind.type_name());
            if s.encoding != "ros2msg" || s.name.replace("/msg/", "/") != want.replace("/msg/", "/") {
                return Err(format!(
                    "schema `{}` ({}), expected `{want}` (ros2msg)",
                    s.name, s.encoding
                ));
            }
            match channel.metadata.iter().find(|(k, _)| k == META_LAYOUT) {
                Some((_, layout)) if layout != kind.type_name() => Err(format!(
                    "layout `{layout}`, expected `{}`: a recording of another layout version",
                    kind.type_name()
                )),
                Some(_) => Ok(ChannelType {
                    kind,
                    codec: Codec::Cdr,
                }),
                None => {
                    let text = String::from_utf8_lossy(&s.data);
                    crate::with_sample_type!(kind, T => ros2msg::check_compatible::<T>(&text))
                        .map(|()| ChannelType {
                            kind,
                            codec: Codec::Cdr,
                        })
                        .map_err(|e| format!("schema `{}`: {e}", s.name))
                }
            }
        }
        "json" => {
            if let Some(s) = schema
                && s.encoding == "jsonschema"
                && OLDER_LAYOUTS.iter().any(|(name, k)| *name == s.name && *k == kind)
            {
                return Ok(ChannelType {
                    kind,
                    codec: Codec::JsonOlder,
                });
            }
            if let Some(s) = schema
                && (s.name != kind.type_name() || s.encoding != "jsonschema")
            {
                return Err(format!(
                    "schema `{}` ({}), expected `{}` (jsonschema): a recording of another layout version",
                    s.name,
                    s.encoding,
                    kind.type_name()
                ));
            }
            Ok(ChannelType {
                kind,
                codec: Codec::Json,
            })
        }
        other => Err(format!("message encoding `{other}`, expected `cdr` or `json`")),
    }
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
            Encoding::Json.encode(&s, &mut buf);
            let back = decode(
                ChannelType {
                    kind: ServiceKind::ImuSample,
                    codec: Codec::Json,
                },
                &buf,
            )
            .unwrap();
            let AnySample::Imu(b) = back else { panic!("wrong kind") };
            assert_eq!(b.gyro_rps.map(f64::to_bits), imu.gyro_rps.map(f64::to_bits));
            assert_eq!(b.accel_mps2.map(f64::to_bits), imu.accel_mps2.map(f64::to_bits));
            assert_eq!(b.dt_s.to_bits(), imu.dt_s.to_bits());
            assert!(b.temperature_c.is_nan());
            assert_eq!(b.stamp, imu.stamp);
        }
        for kind in ServiceKind::ALL {
            let v: serde_json::Value = serde_json::from_slice(&Encoding::Json.schema_data(kind)).unwrap();
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
                codec: Codec::Json
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
        let json_nav = ChannelType {
            kind: ServiceKind::NavState,
            codec: Codec::Json,
        };
        assert!(decode(json_nav, b"{").unwrap_err().starts_with("not JSON"));
        let cdr = Channel {
            topic: "/navsync/imu/0/sample".into(),
            message_encoding: "cdr".into(),
            metadata: vec![(META_LAYOUT.into(), "navsync.ImuSample.v0".into())],
            ..ch.clone()
        };
        let ros = Schema {
            name: "navsync_msgs/msg/ImuSample".into(),
            encoding: "ros2msg".into(),
            data: Encoding::Cdr.schema_data(ServiceKind::ImuSample),
            ..good.clone()
        };
        assert!(channel_kind(&cdr, Some(&ros)).unwrap_err().contains("layout version"));
        let cdr = Channel {
            metadata: vec![(META_LAYOUT.into(), "navsync.ImuSample.v1".into())],
            ..cdr
        };
        assert_eq!(channel_kind(&cdr, Some(&ros)).map(|t| t.codec), Ok(Codec::Cdr));
        assert!(channel_kind(&cdr, None).is_err());
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
        assert_eq!(ty.codec, Codec::JsonOlder);
        let AnySample::GnssFix(back) = decode(ty, &data).unwrap() else {
            panic!("not a fix")
        };
        assert_eq!(back.lat_deg, 48.1);
        assert_eq!(back.stamp.seq, 7);
        assert!(back.h_acc_m.is_nan(), "added since: not known");
        let current = ChannelType {
            kind: ServiceKind::GnssFix,
            codec: Codec::Json,
        };
        assert!(decode(current, &data).unwrap_err().contains("missing"));
    }
}
