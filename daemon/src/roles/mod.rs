//! Process shells: each role wires a functional core to its iceoryx2 services.

pub mod bench_timing;
pub mod analyze;
pub mod demo;
pub mod echo;
pub mod estimator;
pub mod ntpshm;
pub mod record;
pub mod replay;
pub mod sim_estimate;
