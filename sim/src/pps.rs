//! The receiver's 1 PPS output as the host's kernel PPS would stamp it.
//!
//! An assert edge at every integer UTC second T within the scenario, stamped
//! host(T + q(T)) + N(0, σ²) (σ = `clock.pps_jitter_s`; q the receiver's time-pulse
//! quantisation, `gnss.timepulse_quantization_ns`, reported by UBX TIM-TP), never earlier than
//! the previous stamp.
//! During a GNSS outage whose `pps_continues` is false, and during a PPS outage
//! (`[[clock.pps_outage]]`), there is no edge. `stamp.seq` counts the
//! edges emitted from 0; `source_seq` is the kernel-style assert counter starting at 1.

use navsync_shared::samples::{PpsEdge, Stamp, StampSource};
use navsync_shared::time::NS_PER_S;

use super::oscillator::Oscillator;
use super::rng::{Rng, streams};
use super::scenario::{OutageConfig, PpsOutageConfig};

/// The PPS edge generator.
#[derive(Debug, Clone)]
pub struct PpsGenerator {
    next_utc_ns: i64,
    end_utc_ns: i64,
    jitter_s: f64,
    quantization_ns: f64,
    silent: Vec<(f64, f64)>,
    seq: u64,
    last_host_ns: i64,
    rng: Rng,
}

impl PpsGenerator {
    /// Edges at whole UTC seconds in [`start_utc_ns`, `start_utc_ns` + `duration_s`], silent
    /// during the GNSS `outages` without PPS and the `pps_outages`.
    pub fn new(
        seed: u64,
        start_utc_ns: i64,
        duration_s: f64,
        jitter_s: f64,
        quantization_ns: f64,
        outages: &[OutageConfig],
        pps_outages: &[PpsOutageConfig],
    ) -> Self {
        let first = start_utc_ns.div_euclid(NS_PER_S) * NS_PER_S;
        let first = if first < start_utc_ns { first + NS_PER_S } else { first };
        Self {
            next_utc_ns: first,
            end_utc_ns: start_utc_ns + (duration_s * 1e9).round() as i64,
            jitter_s,
            quantization_ns,
            silent: outages
                .iter()
                .filter(|o| !o.pps_continues)
                .map(|o| (o.start_s, o.start_s + o.duration_s))
                .chain(pps_outages.iter().map(|o| (o.start_s, o.start_s + o.duration_s)))
                .collect(),
            seq: 0,
            last_host_ns: i64::MIN,
            rng: Rng::stream(seed, streams::PPS),
        }
    }

    /// The next edge, `None` after the scenario's last second.
    pub fn next_edge(&mut self, osc: &Oscillator) -> Option<PpsEdge> {
        loop {
            let utc = self.next_utc_ns;
            if utc > self.end_utc_ns {
                return None;
            }
            self.next_utc_ns += NS_PER_S;
            let jitter_ns = (self.rng.gaussian(self.jitter_s) * 1e9).round() as i64;
            let tau = osc.tau_of_utc(utc);
            if self.silent.iter().any(|&(a, b)| tau >= a && tau < b) {
                continue;
            }
            let q_ns =
                (f64::from(super::ubx::timepulse_q_err_ps(self.quantization_ns, utc / NS_PER_S)) * 1e-3).round() as i64;
            let host_ns = (osc.host_ns_at_utc(utc + q_ns) + jitter_ns).max(self.last_host_ns);
            self.last_host_ns = host_ns;
            let seq = self.seq;
            self.seq += 1;
            return Some(PpsEdge {
                stamp: Stamp::host(host_ns, seq, StampSource::Simulated),
                source_seq: seq + 1,
                jitter_ns: self.jitter_s * 1e9,
                assert_edge: 1,
                reserved: [0; 7],
            });
        }
    }
}
