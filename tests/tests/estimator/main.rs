//! The estimator on the simulator, on real satellites and on data navsync did not generate:
//! the GPS models against the simulator and gpsd, tightly against loosely coupled (offline and
//! live), the offline tools (`import`, `replay --estimate`). One test binary; its tests run
//! concurrently.

mod gps_sky;

mod broadcast_walk;
mod external_data;
mod glonass;
mod history_generated;
mod kf_gins;
mod lnav_gpsd;
mod recorded_models;
mod rinex_export;
mod rinex_spp;
mod sim_gps;
mod sim_sky;
mod spp_walk;
mod tight_coupling;
mod tight_coupling_live;
mod tight_walk;
