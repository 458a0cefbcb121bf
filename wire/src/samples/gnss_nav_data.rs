//! One broadcast navigation data subframe as the receiver decoded it from a satellite's
//! signal (u-blox UBX-RXM-SFRBX), words unchanged: ephemerides, almanac, ionosphere and UTC
//! parameters for tightly coupled fusion (GPS LNAV per IS-GPS-200).

use super::Stamp;

/// Words one [`GnssNavData`] holds.
pub const MAX_NAV_WORDS: usize = 16;

crate::sample_struct! {
    /// One subframe (or page) of broadcast navigation data.
    pub struct GnssNavData = "navsync.GnssNavData.v1" {
        /// Receipt stamp of the message's first byte and the driver's message counter.
        pub stamp: Stamp,
        /// The data words as the receiver delivers them (u-blox `dwrd`; GPS LNAV: 10 words of
        /// 30 bits, parity included, right-aligned).
        pub words: [u32; MAX_NAV_WORDS],
        /// GNSS id (u-blox: 0 GPS, 1 SBAS, 2 Galileo, 3 BeiDou, 5 QZSS, 6 GLONASS).
        pub gnss_id: u8,
        /// Satellite id within the system.
        pub sv_id: u8,
        /// Signal id.
        pub sig_id: u8,
        /// GLONASS frequency slot + 7, else 0.
        pub freq_id: u8,
        /// Words in `words`.
        pub num_words: u8,
        /// Tracking channel.
        pub channel: u8,
        /// Message version.
        pub version: u8,
        /// Reserved, zero.
        pub reserved: u8,
    }
}
