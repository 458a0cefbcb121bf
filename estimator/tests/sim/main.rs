//! The estimator offline on the simulator's data: the filter, the IMU array, the mechanization
//! against the truth, the faults of "Faults it survives", the integrity monitor and no allocation per sample. One test
//! binary; its tests run concurrently.

mod fault_drive;

mod estimator_sim;
mod faults_gnss_jump;
mod faults_imu_samples;
mod faults_pps_silence;
mod imu_array_sim;
mod integrity;
mod mechanization_vs_sim;
mod no_alloc;
