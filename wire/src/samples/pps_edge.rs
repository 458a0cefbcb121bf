//! A pulse-per-second edge.

use super::Stamp;

crate::sample_struct! {
    /// One 1 PPS edge: the receiver's mark of the start of a GNSS second, time stamped on the host.
    ///
    /// Which GNSS second it marks is decided by the estimator from the NMEA that follows.
    pub struct PpsEdge = "navsync.PpsEdge.v1" {
        /// Host time of the edge (`stamp.host_ns`) and how it was taken; `stamp.seq` counts edges.
        pub stamp: Stamp,
        /// Source's own edge counter (kernel PPS `assert_sequence`), 0 when not known.
        pub source_seq: u64,
        /// Expected 1-sigma time-stamp jitter of this source, ns (1e3 kernel, 3e4 user space).
        pub jitter_ns: f64,
        /// 1 for the assert (leading) edge, 0 for clear.
        pub assert_edge: u8,
        /// Reserved, zero.
        pub reserved: [u8; 7],
    }
}
