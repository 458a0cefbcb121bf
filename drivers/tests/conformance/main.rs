//! The drivers' decoders and kernel structures against independent references: the NMEA and
//! UBX decoders over gpsd's regression corpus against gpsd's own reports, epoch assembly as properties over the captures and perturbed copies, and the PPS and
//! serial ioctl structures against the system's C headers. One test binary.

mod gpsd_common;

mod epoch_properties;
mod gpsd_conformance;
mod gpsd_nmea_sky;
mod gpsd_ubx_conformance;
mod pps_kernel_abi;
