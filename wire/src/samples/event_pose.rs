//! The pose of the body at an external event (a camera's exposure marked by a receiver's
//! TIM-TM2, a host-stamped trigger): what a photogrammetry or LiDAR pipeline tags its data with.

crate::sample_struct! {
    /// One event with the navigation state at its instant, published by the estimator on
    /// `navsync/event/{id}/pose` (`id`: the receiver whose input marked it) once its delayed
    /// filter has fused past the instant: the pose is the history's `state_at` of the event's
    /// time over the fused states (`navsync_shared::history`), the same answer a query of the
    /// history gives. Position WGS-84, velocity NED, attitude body (FRD) → NED.
    pub struct EventPose = "navsync.EventPose.v1" {
        /// Host time (`CLOCK_MONOTONIC` ns) of the event: of the state interpolated to it.
        pub host_ns: i64,
        /// UTC of the event, ns since 1970 (the receiver's mark converted; `i64::MIN` when
        /// not known).
        pub utc_ns: i64,
        /// GPS time of the event as the receiver marked it, ns since 1980-01-06 (`i64::MIN`
        /// for an event stamped on the host).
        pub gps_ns: i64,
        /// Host time of the report the event came in (its `GnssEvent`'s stamp), ns.
        pub report_host_ns: i64,
        /// Event poses published so far by this estimator.
        pub seq: u64,
        /// Latitude, degrees (NaN when no state covers the instant: `source` 0).
        pub lat_deg: f64,
        /// Longitude, degrees.
        pub lon_deg: f64,
        /// Height above the WGS-84 ellipsoid, m.
        pub height_m: f64,
        /// Velocity, NED, m/s.
        pub vel_ned_mps: [f64; 3],
        /// Attitude quaternion body (FRD) → NED, [w, x, y, z].
        pub q_nb: [f64; 4],
        /// Roll, pitch, yaw (ZYX) of `q_nb`, rad.
        pub rpy_rad: [f64; 3],
        /// 1-σ position, NED, m.
        pub pos_std_ned_m: [f64; 3],
        /// 1-σ velocity, NED, m/s.
        pub vel_std_ned_mps: [f64; 3],
        /// 1-σ attitude (roll, pitch, yaw error angles), rad.
        pub att_std_rad: [f64; 3],
        /// 1-σ of the event's time as the receiver states it (TIM-TM2 `accEst`), ns.
        pub time_std_ns: f64,
        /// Id of the device that marked the event (the receiver's id), NUL-padded.
        pub device_id: [u8; 8],
        /// The device's edge counter (TIM-TM2 `count`).
        pub count: u16,
        /// The device's input channel (u-blox: 0 EXTINT0, 1 EXTINT1).
        pub channel: u8,
        /// Which edge: 0 rising, 1 falling.
        pub edge: u8,
        /// Where the pose comes from, a `history::Source` as `u8`: 2 the delayed filter's
        /// fused states, 1 the real-time predictor's, 0 none (no state covers the instant:
        /// the event is reported without a pose).
        pub source: u8,
        /// `NavStatus` of the state before the instant, as `u8`.
        pub status: u8,
        /// `TimeStatus` of the state before the instant, as `u8`.
        pub time_status: u8,
        /// Integrity flags of the state before the instant (`INTEGRITY_*`).
        pub integrity: u8,
    }
}

/// [`EventPose::edge`] of a rising edge.
pub const EVENT_EDGE_RISING: u8 = 0;
/// [`EventPose::edge`] of a falling edge.
pub const EVENT_EDGE_FALLING: u8 = 1;
