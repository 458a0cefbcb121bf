//! The drivers' decoders and kernel structures against independent references: the NMEA and
//! UBX decoders over gpsd's regression corpus against gpsd's own reports, and the PPS and
//! serial ioctl structures against the system's C headers. One test binary.

mod gpsd_common;

mod gpsd_conformance;
mod gpsd_ubx_conformance;
mod pps_kernel_abi;
