//! The receiver's sky: every satellite it reports with its elevation, azimuth, carrier-to-noise
//! density and whether the navigation solution uses it (NMEA GSV with GSA, u-blox UBX-NAV-SAT
//! or NAV-SVINFO). For people and dashboards (`navsync web`'s sky plot); the estimator does
//! not read it.

use super::Stamp;

/// Satellites one [`GnssSky`] holds.
pub const MAX_SKY_SATELLITES: usize = 64;

crate::sample_struct! {
    /// One satellite as the receiver sees it.
    pub struct SkySatellite = "navsync.SkySatellite.v1" {
        /// Elevation above the local horizon, degrees (−90..=90); NaN when the receiver does
        /// not know it.
        pub elevation_deg: f32,
        /// Azimuth, degrees clockwise from true north (0..360); NaN when not known.
        pub azimuth_deg: f32,
        /// GNSS id, the same numbering as [`super::RawMeasurement::gnss_id`] (u-blox: 0 GPS,
        /// 1 SBAS, 2 Galileo, 3 BeiDou, 4 IMES, 5 QZSS, 6 GLONASS).
        pub gnss_id: u8,
        /// Satellite id within the system (u-blox `svId`: GPS PRN, SBAS PRN 120–158, GLONASS
        /// slot 1–32 or 255 unknown, Galileo/BeiDou/QZSS PRN).
        pub sv_id: u8,
        /// Carrier-to-noise density, dB-Hz; 0 when not tracked or not known.
        pub cno_dbhz: u8,
        /// 1 when the receiver's navigation solution uses the satellite, else 0.
        pub used: u8,
    }
}

crate::sample_struct! {
    /// The satellites a receiver reported with one navigation epoch. Published on
    /// `navsync/gnss/{id}/sky`.
    pub struct GnssSky = "navsync.GnssSky.v1" {
        /// Receipt stamp (host time of the first byte of the epoch's first message or
        /// sentence that carried the satellites) and the driver's sky counter.
        pub stamp: Stamp,
        /// The epoch's UTC time, ns since 1970; `i64::MIN` when not known.
        pub utc_ns: i64,
        /// Satellites in `sats`.
        pub num_sats: u8,
        /// Satellites the receiver reported beyond [`MAX_SKY_SATELLITES`] (dropped).
        pub dropped: u8,
        /// The `GNSS_PROTOCOL_*` of the receiver's report (see `GnssFix::protocol`).
        pub protocol: u8,
        /// Reserved, zero.
        pub reserved: [u8; 5],
        /// The satellites, `num_sats` of them.
        pub sats: [SkySatellite; MAX_SKY_SATELLITES],
    }
}

impl SkySatellite {
    /// An unused slot: ids 0, elevation and azimuth unknown, no C/N0, not used.
    pub const EMPTY: SkySatellite = SkySatellite {
        elevation_deg: f32::NAN,
        azimuth_deg: f32::NAN,
        gnss_id: 0,
        sv_id: 0,
        cno_dbhz: 0,
        used: 0,
    };
}

impl GnssSky {
    /// A sky without satellites, stamped `stamp`.
    pub fn empty(stamp: Stamp) -> Self {
        Self {
            stamp,
            utc_ns: i64::MIN,
            num_sats: 0,
            dropped: 0,
            protocol: 0,
            reserved: [0; 5],
            sats: [SkySatellite::EMPTY; MAX_SKY_SATELLITES],
        }
    }

    /// The satellites.
    pub fn satellites(&self) -> &[SkySatellite] {
        self.sats.get(..usize::from(self.num_sats)).unwrap_or(&self.sats)
    }

    /// Appends a satellite; false (and counted in `dropped`) when the table is full.
    pub fn push(&mut self, s: SkySatellite) -> bool {
        match self.sats.get_mut(usize::from(self.num_sats)) {
            Some(slot) => {
                *slot = s;
                self.num_sats += 1;
                true
            }
            None => {
                self.dropped = self.dropped.saturating_add(1);
                false
            }
        }
    }

    /// Satellites the solution uses.
    pub fn used(&self) -> usize {
        self.satellites().iter().filter(|s| s.used != 0).count()
    }
}
