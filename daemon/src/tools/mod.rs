//! Offline tools over files, and the installation helpers.

pub mod analyze;
pub mod check_config;
pub mod convert;
pub mod decode;
pub mod estimate;
pub mod eval;
pub mod geotag;
pub mod install;
pub mod kf_gins;
pub mod kf_gins_config;
pub mod ptp_config;
pub mod python_types;
pub mod report;
pub mod rinex;
pub mod rinex_export;
pub mod sim_fast;
pub mod spp;
pub mod ubx_import;
