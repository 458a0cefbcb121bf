//! Process shells: each role wires a functional core to its iceoryx2 services.

pub mod analyze;
pub mod demo;
pub mod echo;
pub mod estimator;
pub mod eval;
pub mod gpsd_server;
pub mod kf_gins;
pub mod liveness;
pub mod ntpshm;
pub mod python_types;
pub mod reclaimer;
pub mod record;
pub mod replay;
pub mod report;
pub mod service;
pub mod sim_estimate;
pub mod status;
