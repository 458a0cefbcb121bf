//! Standard ROS 2 messages written next to navsync's own (`navsync record --ros-std`,
//! `[outputs.record] ros_std = true`), so ROS tools that know only the common types (RViz,
//! `robot_localization`, PlotJuggler's ROS parsers) can use a recording as it is:
//!
//! | navsync sample | topic | type |
//! |---|---|---|
//! | `ImuSample` on `navsync/imu/ID/sample` | `/navsync/imu/ID/imu` | `sensor_msgs/msg/Imu` |
//! | `GnssFix` on `navsync/gnss/ID/fix` | `/navsync/gnss/ID/navsatfix` | `sensor_msgs/msg/NavSatFix` |
//! | `NavState` on `navsync/nav/state` | `/navsync/nav/odometry` | `nav_msgs/msg/Odometry` |
//! | `TimeState` on `navsync/time/state` | `/navsync/time/reference` | `sensor_msgs/msg/TimeReference` |
//!
//! Conventions (REP 103, REP 145, the messages' own comments):
//! * Header stamps are UTC (ns since 1970 as `sec`/`nanosec`): a fix's and a state's own UTC;
//!   an IMU sample's host time mapped through the latest valid `TimeState` in the recording
//!   (before the first one, the message's log time). `TimeReference` is the exception the
//!   message defines: its header stamp is the host clock (`CLOCK_MONOTONIC`) at the mapping's
//!   reference point and `time_ref` the UTC there.
//! * `Imu`: rates and specific forces in the IMU's own sensor axes (frame id
//!   [`RosFrames::imu`], `{id}` replaced by the IMU id), no orientation
//!   (`orientation_covariance[0] = -1`), covariances unknown (zeros).
//! * `NavSatFix`: WGS-84 latitude/longitude, ellipsoidal height (MSL altitude + geoid
//!   separation), covariance diagonal in ENU from the receiver's 1σ (`DIAGONAL_KNOWN`, else
//!   from hAcc/vAcc as `APPROXIMATED`, else `UNKNOWN`); status from the fix quality
//!   (RTK → `GBAS_FIX`, DGPS → `SBAS_FIX`).
//! * `Odometry`: pose of the body in a local ENU frame ([`RosFrames::map`]) whose origin is the
//!   first state's position (channel metadata [`META_ORIGIN`]: `[lat_deg, lon_deg, height_m]`),
//!   orientation of the body as forward-left-up ([`RosFrames::base`]), twist in that body
//!   frame; covariances from the filter's 1σ (position and attitude diagonal in ENU axes;
//!   velocity rotated into the body frame; angular rate from the gyro-bias σ).

use navsync_shared::cdr::Writer;
use navsync_shared::earth::ned_between;
use navsync_shared::reflect::str_of;
use navsync_shared::samples::{AnySample, GnssFix, ImuSample, NavState, TimeState};

/// Channel metadata of the Odometry channel: the ENU origin, `[lat_deg, lon_deg, height_m]`.
pub const META_ORIGIN: &str = "navsync.enu_origin";

/// Frame ids of the standard messages.
#[derive(Debug, Clone, PartialEq, Eq, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RosFrames {
    /// IMU sensor frame; `{id}` is replaced by the IMU id. Default `navsync_imu_{id}`.
    pub imu: String,
    /// GNSS antenna frame; `{id}` is replaced by the receiver id. Default `navsync_gnss_{id}`.
    pub gnss: String,
    /// The local ENU frame of the odometry. Default `map`.
    pub map: String,
    /// The body frame (forward-left-up) of the odometry. Default `base_link`.
    pub base: String,
}

impl Default for RosFrames {
    fn default() -> Self {
        Self {
            imu: "navsync_imu_{id}".into(),
            gnss: "navsync_gnss_{id}".into(),
            map: "map".into(),
            base: "base_link".into(),
        }
    }
}

const TIME: &str = "int32 sec\nuint32 nanosec\n";
const HEADER: &str = "builtin_interfaces/Time stamp\nstring frame_id\n";
const VECTOR3: &str = "float64 x\nfloat64 y\nfloat64 z\n";
const QUATERNION: &str = "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n";

fn with_deps(main: &str, deps: &[(&str, &str)]) -> String {
    let mut s = main.to_string();
    for (name, text) in deps {
        s.push_str(navsync_shared::ros2msg::SEPARATOR);
        s.push_str(&format!("\nMSG: {name}\n{text}"));
    }
    s
}

/// One standard message type: its ROS 2 name and `ros2msg` definition with dependencies.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StdType {
    /// `sensor_msgs/msg/Imu`
    Imu,
    /// `sensor_msgs/msg/NavSatFix`
    NavSatFix,
    /// `nav_msgs/msg/Odometry`
    Odometry,
    /// `sensor_msgs/msg/TimeReference`
    TimeReference,
}

impl StdType {
    /// Every standard type navsync writes.
    pub const ALL: [StdType; 4] = [Self::Imu, Self::NavSatFix, Self::Odometry, Self::TimeReference];

    /// The ROS 2 type name.
    pub fn name(self) -> &'static str {
        match self {
            Self::Imu => "sensor_msgs/msg/Imu",
            Self::NavSatFix => "sensor_msgs/msg/NavSatFix",
            Self::Odometry => "nav_msgs/msg/Odometry",
            Self::TimeReference => "sensor_msgs/msg/TimeReference",
        }
    }

    /// The full definition (ROS 2 Humble's, comments left out).
    pub fn definition(self) -> String {
        match self {
            Self::Imu => with_deps(
                "std_msgs/Header header\ngeometry_msgs/Quaternion orientation\nfloat64[9] orientation_covariance\n\
                 geometry_msgs/Vector3 angular_velocity\nfloat64[9] angular_velocity_covariance\n\
                 geometry_msgs/Vector3 linear_acceleration\nfloat64[9] linear_acceleration_covariance\n",
                &[
                    ("std_msgs/Header", HEADER),
                    ("builtin_interfaces/Time", TIME),
                    ("geometry_msgs/Quaternion", QUATERNION),
                    ("geometry_msgs/Vector3", VECTOR3),
                ],
            ),
            Self::NavSatFix => with_deps(
                "std_msgs/Header header\nsensor_msgs/NavSatStatus status\nfloat64 latitude\nfloat64 longitude\n\
                 float64 altitude\nfloat64[9] position_covariance\nuint8 COVARIANCE_TYPE_UNKNOWN=0\n\
                 uint8 COVARIANCE_TYPE_APPROXIMATED=1\nuint8 COVARIANCE_TYPE_DIAGONAL_KNOWN=2\n\
                 uint8 COVARIANCE_TYPE_KNOWN=3\nuint8 position_covariance_type\n",
                &[
                    ("std_msgs/Header", HEADER),
                    ("builtin_interfaces/Time", TIME),
                    (
                        "sensor_msgs/NavSatStatus",
                        "int8 STATUS_NO_FIX=-1\nint8 STATUS_FIX=0\nint8 STATUS_SBAS_FIX=1\nint8 STATUS_GBAS_FIX=2\n\
                         int8 status\nuint16 SERVICE_GPS=1\nuint16 SERVICE_GLONASS=2\nuint16 SERVICE_COMPASS=4\n\
                         uint16 SERVICE_GALILEO=8\nuint16 service\n",
                    ),
                ],
            ),
            Self::Odometry => with_deps(
                "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/PoseWithCovariance pose\n\
                 geometry_msgs/TwistWithCovariance twist\n",
                &[
                    ("std_msgs/Header", HEADER),
                    ("builtin_interfaces/Time", TIME),
                    (
                        "geometry_msgs/PoseWithCovariance",
                        "geometry_msgs/Pose pose\nfloat64[36] covariance\n",
                    ),
                    (
                        "geometry_msgs/Pose",
                        "geometry_msgs/Point position\ngeometry_msgs/Quaternion orientation\n",
                    ),
                    ("geometry_msgs/Point", VECTOR3),
                    ("geometry_msgs/Quaternion", QUATERNION),
                    (
                        "geometry_msgs/TwistWithCovariance",
                        "geometry_msgs/Twist twist\nfloat64[36] covariance\n",
                    ),
                    (
                        "geometry_msgs/Twist",
                        "geometry_msgs/Vector3 linear\ngeometry_msgs/Vector3 angular\n",
                    ),
                    ("geometry_msgs/Vector3", VECTOR3),
                ],
            ),
            Self::TimeReference => with_deps(
                "std_msgs/Header header\nbuiltin_interfaces/Time time_ref\nstring source\n",
                &[("std_msgs/Header", HEADER), ("builtin_interfaces/Time", TIME)],
            ),
        }
    }
}

/// A `builtin_interfaces/Time` from ns since the epoch (floor division: negative times have
/// a positive `nanosec`).
fn time(w: &mut Writer<'_>, ns: i64) {
    let sec = ns.div_euclid(1_000_000_000);
    let nsec = ns.rem_euclid(1_000_000_000) as u32;
    w.i32(sec.clamp(i32::MIN as i64, i32::MAX as i64) as i32).u32(nsec);
}

fn header(w: &mut Writer<'_>, stamp_ns: i64, frame: &str) {
    time(w, stamp_ns);
    w.str(frame);
}

/// One converted message: where it goes and its CDR bytes (in the converter's buffer).
#[derive(Debug)]
pub struct StdMessage<'a> {
    /// The ROS 2 topic.
    pub topic: String,
    /// The message type.
    pub ty: StdType,
    /// Channel metadata to add when the channel is created.
    pub metadata: Vec<(&'static str, String)>,
    /// The CDR message.
    pub data: &'a [u8],
}

/// Converts navsync samples to standard ROS 2 messages; keeps what the conversions need
/// (the latest time mapping, the odometry origin).
#[derive(Debug, Default)]
pub struct RosStd {
    frames: RosFrames,
    time: Option<TimeState>,
    origin: Option<[f64; 3]>,
    buf: Vec<u8>,
}

fn id_of(service: &str) -> &str {
    service.split('/').nth(2).unwrap_or("")
}

/// Row-major 3×3 rotation body (FRD) → NED from `q_nb` = [w, x, y, z].
fn dcm(q: [f64; 4]) -> [[f64; 3]; 3] {
    let [w, x, y, z] = q;
    [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - w * z),
            2.0 * (x * z + w * y),
        ],
        [
            2.0 * (x * y + w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - w * x),
        ],
        [
            2.0 * (x * z - w * y),
            2.0 * (y * z + w * x),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ]
}

/// Quaternion [x, y, z, w] of a rotation matrix (Shepperd's method).
fn quat_of(m: [[f64; 3]; 3]) -> [f64; 4] {
    let t = m[0][0] + m[1][1] + m[2][2];
    let (x, y, z, w);
    if t > 0.0 {
        let s = (t + 1.0).sqrt() * 2.0;
        w = 0.25 * s;
        x = (m[2][1] - m[1][2]) / s;
        y = (m[0][2] - m[2][0]) / s;
        z = (m[1][0] - m[0][1]) / s;
    } else if m[0][0] > m[1][1] && m[0][0] > m[2][2] {
        let s = (1.0 + m[0][0] - m[1][1] - m[2][2]).sqrt() * 2.0;
        w = (m[2][1] - m[1][2]) / s;
        x = 0.25 * s;
        y = (m[0][1] + m[1][0]) / s;
        z = (m[0][2] + m[2][0]) / s;
    } else if m[1][1] > m[2][2] {
        let s = (1.0 + m[1][1] - m[0][0] - m[2][2]).sqrt() * 2.0;
        w = (m[0][2] - m[2][0]) / s;
        x = (m[0][1] + m[1][0]) / s;
        y = 0.25 * s;
        z = (m[1][2] + m[2][1]) / s;
    } else {
        let s = (1.0 + m[2][2] - m[0][0] - m[1][1]).sqrt() * 2.0;
        w = (m[1][0] - m[0][1]) / s;
        x = (m[0][2] + m[2][0]) / s;
        y = (m[1][2] + m[2][1]) / s;
        z = 0.25 * s;
    }
    [x, y, z, w]
}

/// Orientation of the body as FLU in ENU: R_enu_flu = P · R_ned_frd · F, with P swapping
/// north/east and negating down, F = diag(1, −1, −1).
fn enu_flu(r_ned_frd: [[f64; 3]; 3]) -> [[f64; 3]; 3] {
    let p = |i: usize| match i {
        0 => (1, 1.0),
        1 => (0, 1.0),
        _ => (2, -1.0),
    };
    let f = [1.0, -1.0, -1.0];
    let mut out = [[0.0; 3]; 3];
    for (i, row) in out.iter_mut().enumerate() {
        let (src, sign) = p(i);
        for (j, v) in row.iter_mut().enumerate() {
            *v = sign * r_ned_frd[src][j] * f[j];
        }
    }
    out
}

impl RosStd {
    /// A converter with these frame ids.
    pub fn new(frames: RosFrames) -> Self {
        Self {
            frames,
            ..Self::default()
        }
    }

    /// The standard message of `sample` published on `service`, if there is one.
    /// `log_time` (ns, UTC-like) stamps IMU samples before the first valid time mapping.
    pub fn convert(&mut self, service: &str, sample: &AnySample, log_time: u64) -> Option<StdMessage<'_>> {
        let mut metadata = Vec::new();
        let (topic, ty) = match sample {
            AnySample::Imu(s) => {
                let stamp = match &self.time {
                    Some(t) => t.utc_ns_at(s.stamp.host_ns),
                    None => log_time as i64,
                };
                let frame = self.frames.imu.replace("{id}", str_of(&s.imu_id));
                imu(&mut self.buf, s, stamp, &frame);
                (format!("/navsync/imu/{}/imu", id_of(service)), StdType::Imu)
            }
            AnySample::GnssFix(f) => {
                let frame = self.frames.gnss.replace("{id}", id_of(service));
                navsatfix(&mut self.buf, f, &frame);
                (
                    format!("/navsync/gnss/{}/navsatfix", id_of(service)),
                    StdType::NavSatFix,
                )
            }
            AnySample::Nav(n) => {
                if n.utc_ns == i64::MIN || !n.lat_deg.is_finite() || !n.q_nb[0].is_finite() {
                    return None;
                }
                let origin = *self.origin.get_or_insert([n.lat_deg, n.lon_deg, n.height_m]);
                metadata.push((META_ORIGIN, format!("[{},{},{}]", origin[0], origin[1], origin[2])));
                odometry(&mut self.buf, n, origin, &self.frames);
                ("/navsync/nav/odometry".to_string(), StdType::Odometry)
            }
            AnySample::Time(t) => {
                if !t.is_valid() {
                    return None;
                }
                self.time = Some(*t);
                let mut w = Writer::new(&mut self.buf);
                header(&mut w, t.ref_host_ns, "");
                time(&mut w, t.ref_utc_ns);
                w.str(&format!("navsync {}", t.status().name()));
                ("/navsync/time/reference".to_string(), StdType::TimeReference)
            }
            _ => return None,
        };
        Some(StdMessage {
            topic,
            ty,
            metadata,
            data: &self.buf,
        })
    }
}

fn imu(buf: &mut Vec<u8>, s: &ImuSample, stamp_ns: i64, frame: &str) {
    let mut w = Writer::new(buf);
    header(&mut w, stamp_ns, frame);
    w.f64s(&[0.0, 0.0, 0.0, 1.0]);
    let mut unknown = [0.0; 9];
    unknown[0] = -1.0;
    w.f64s(&unknown);
    w.f64s(&s.gyro_rps).f64s(&[0.0; 9]);
    w.f64s(&s.accel_mps2).f64s(&[0.0; 9]);
}

fn navsatfix(buf: &mut Vec<u8>, f: &GnssFix, frame: &str) {
    let mut w = Writer::new(buf);
    header(&mut w, if f.utc_ns == i64::MIN { 0 } else { f.utc_ns }, frame);
    // NavSatStatus: status, service (GPS).
    // No fix; DGPS → SBAS_FIX (ROS has no status for ground-based DGPS); RTK fixed or float
    // → GBAS_FIX; any other fix → FIX.
    let status: i8 = match f.quality {
        _ if f.mode == 1 || f.quality == 0 => -1,
        2 => 1,
        4 | 5 => 2,
        _ => 0,
    };
    w.i8(status).u16(1);
    let alt = f.alt_msl_m + if f.geoid_sep_m.is_finite() { f.geoid_sep_m } else { 0.0 };
    w.f64(f.lat_deg).f64(f.lon_deg).f64(alt);
    let (cov, kind) = if f.std_lat_m.is_finite() && f.std_lon_m.is_finite() && f.std_alt_m.is_finite() {
        ([f.std_lon_m, f.std_lat_m, f.std_alt_m], 2u8)
    } else if f.h_acc_m.is_finite() && f.v_acc_m.is_finite() {
        let h = f.h_acc_m / 2f64.sqrt();
        ([h, h, f.v_acc_m], 1u8)
    } else {
        ([0.0; 3], 0u8)
    };
    let mut c = [0.0; 9];
    for i in 0..3 {
        c[i * 4] = cov[i] * cov[i];
    }
    w.f64s(&c).u8(kind);
}

fn odometry(buf: &mut Vec<u8>, n: &NavState, origin: [f64; 3], frames: &RosFrames) {
    let rad = core::f64::consts::PI / 180.0;
    let ned = ned_between(
        origin[0] * rad,
        origin[1] * rad,
        origin[2],
        n.lat_deg * rad,
        n.lon_deg * rad,
        n.height_m,
    );
    let r = dcm(n.q_nb);
    let q = quat_of(enu_flu(r));
    let mut w = Writer::new(buf);
    header(&mut w, n.utc_ns, &frames.map);
    w.str(&frames.base);
    w.f64s(&[ned[1], ned[0], -ned[2]]).f64s(&q);
    let p = n.pos_std_ned_m;
    let a = n.att_std_rad;
    let mut pose = [0.0; 36];
    for (i, s) in [p[1], p[0], p[2], a[1], a[0], a[2]].iter().enumerate() {
        pose[i * 7] = s * s;
    }
    w.f64s(&pose);
    // Twist in the body frame: v_frd = Rᵀ v_ned, then FRD → FLU.
    let v = n.vel_ned_mps;
    let v_frd: [f64; 3] = core::array::from_fn(|j| (0..3).map(|i| r[i][j] * v[i]).sum());
    let g = n.gyro_body_rps;
    w.f64s(&[v_frd[0], -v_frd[1], -v_frd[2]]).f64s(&[g[0], -g[1], -g[2]]);
    // Velocity covariance Rᵀ C R (C diagonal in NED), then FRD → FLU signs.
    let c = n.vel_std_ned_mps.map(|s| s * s);
    let f = [1.0, -1.0, -1.0];
    let mut twist = [0.0; 36];
    for j in 0..3 {
        for k in 0..3 {
            let v: f64 = (0..3).map(|i| r[i][j] * c[i] * r[i][k]).sum();
            twist[j * 6 + k] = v * f[j] * f[k];
        }
    }
    for (i, s) in n.gyro_bias_std_rps.iter().enumerate() {
        twist[(i + 3) * 7] = s * s;
    }
    w.f64s(&twist);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_level_body_heading_north_is_x_north_in_enu_rotated_90_degrees() {
        // Body FRD aligned with NED (yaw 0: heading north). In ENU with FLU, the body's x
        // (forward) points north = ENU y: a rotation of +90° about z.
        let q = quat_of(enu_flu(dcm([1.0, 0.0, 0.0, 0.0])));
        let h = core::f64::consts::FRAC_1_SQRT_2;
        assert!((q[2] - h).abs() < 1e-12 && (q[3] - h).abs() < 1e-12, "{q:?}");
        // Heading east (yaw +90° about down): forward = ENU x: identity.
        let yaw = core::f64::consts::FRAC_PI_4;
        let q = quat_of(enu_flu(dcm([yaw.cos(), 0.0, 0.0, yaw.sin()])));
        assert!((q[3].abs() - 1.0).abs() < 1e-12, "{q:?}");
    }

    #[test]
    fn times_split_into_seconds_and_nanoseconds() {
        let mut buf = Vec::new();
        let mut w = Writer::new(&mut buf);
        time(&mut w, -1);
        assert_eq!(&buf[4..8], &(-1i32).to_le_bytes());
        assert_eq!(&buf[8..12], &999_999_999u32.to_le_bytes());
    }
}
