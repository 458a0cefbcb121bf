//! Holding the CPU wake-up latency at 0 µs for a low-latency deployment.
//!
//! While a [`CpuWakeupHold`] is alive the kernel's PM QoS CPU latency request is 0 µs
//! (`/dev/cpu_dma_latency` held open with the value 0, the interface `cyclictest` uses): idle
//! CPUs poll instead of entering a halt/sleep state, so waking a sleeping process does not
//! wait for a CPU to come out of it. On a virtual machine a halted vCPU is woken through the
//! hypervisor; on the 2-core benchmark VM that was 20–40 µs of every wake-up (README
//! "## Performance"). It costs an idle core's power. `navsync estimator --idle-polling` and
//! the `--realtime` benchmarks take it; the file is root's unless a udev rule gives it to the
//! `navsync` group (`systemd/99-navsync.rules`).

use std::io::Write;

/// The held request; released when dropped (the kernel drops it when the file closes).
#[derive(Debug)]
pub struct CpuWakeupHold(#[allow(dead_code)] std::fs::File);

impl CpuWakeupHold {
    /// Takes the hold (needs write access to `/dev/cpu_dma_latency`).
    pub fn take() -> std::io::Result<Self> {
        let mut f = std::fs::OpenOptions::new().write(true).open("/dev/cpu_dma_latency")?;
        f.write_all(&0i32.to_ne_bytes())?;
        Ok(Self(f))
    }
}
