//! Process shells: each wires a functional core to its iceoryx2 services, or is a client of
//! the live services.

pub mod bridge;
pub mod demo;
pub mod echo;
pub mod estimator;
pub mod feed;
pub mod foxglove;
pub mod gnss;
pub mod gnss_seconds;
pub mod gpsd_server;
pub mod imu;
pub mod liveness;
pub mod network_time;
pub mod nmea_out;
pub mod ntpshm;
pub mod pps;
pub mod pps_out;
pub mod reclaimer;
pub mod record;
pub mod replay;
pub mod sim;
pub mod status;
pub mod web;
