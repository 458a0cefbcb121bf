//! The samples the drivers would publish for a simulated world, produced as fast as the CPU
//! allows: IMU samples and PPS edges as the simulator publishes them, GNSS fixes, time pulses,
//! time marks (the camera's, TIM-TM2), raw measurements and navigation data decoded from the
//! world's receiver bytes (NMEA or UBX) by the GNSS driver's own [`Decoder`]
//! with the same receipt stamps a UART at the configured baud rate would give, and the truth.
//!
//! A time mark ([`GnssEvent`](navsync_shared::samples::GnssEvent)) carries its edges' GNSS
//! times; its host times stay unknown (`i64::MIN`): the live driver maps them with the
//! estimator's published time state, which this stream, made before any estimator runs, does
//! not have. Their truth is [`World::camera`].
//!
//! Each item carries its service name and the host time at which it would be delivered
//! (a fix is delivered when its burst has been read and the line has been idle for the
//! driver's flush interval).

use std::collections::VecDeque;
use std::rc::Rc;

use navsync_shared::samples::AnySample;
use navsync_shared::services;
use navsync_shared::time::NS_PER_S;

use super::world::{SimEvent, World};
use navsync_drivers::gnss::driver::IDLE_FLUSH;
use navsync_drivers::gnss::{Decoder, GnssDecoder, GnssExtra, Protocol};

use crate::scenario::OutputProtocol;

/// One published sample.
#[derive(Debug, Clone)]
pub struct Published {
    /// Service it would be published on.
    pub service: Rc<str>,
    /// Host time at which it would be delivered, ns.
    pub delivered_ns: i64,
    /// The sample.
    pub sample: AnySample,
}

/// Iterator over the published samples of a [`World`], in delivery order.
pub struct PublishedStream {
    world: World,
    decoder: Decoder,
    protocol: Protocol,
    time_pulse_service: Rc<str>,
    event_service: Rc<str>,
    raw_service: Rc<str>,
    nav_data_service: Rc<str>,
    char_ns: i64,
    gnss_service: Rc<str>,
    pps_service: Rc<str>,
    truth_service: Rc<str>,
    imu_services: Vec<Rc<str>>,
    fixes: VecDeque<Published>,
    next_event: Option<SimEvent>,
}

impl PublishedStream {
    /// The stream of `world` (GNSS and PPS id "0", IMU ids "0", "1", …).
    pub fn new(mut world: World) -> Self {
        let char_ns = 10 * NS_PER_S / world.baud() as i64;
        let imu_services = (0..world.imu_count())
            .map(|i| services::imu_sample(&i.to_string()).into())
            .collect();
        let next_event = world.next_event();
        let protocol = match world.gnss_protocol() {
            OutputProtocol::Nmea => Protocol::Nmea,
            OutputProtocol::Ubx => Protocol::Ubx,
        };
        Self {
            world,
            decoder: Decoder::new(protocol),
            protocol,
            time_pulse_service: services::gnss_time_pulse("0").into(),
            event_service: services::gnss_event("0").into(),
            raw_service: services::gnss_raw("0").into(),
            nav_data_service: services::gnss_nav_data("0").into(),
            char_ns,
            gnss_service: services::gnss_fix("0").into(),
            pps_service: services::pps_edge("0").into(),
            truth_service: services::SIM_TRUTH.into(),
            imu_services,
            fixes: VecDeque::new(),
            next_event,
        }
    }

    /// The world (for its truth and oscillator).
    pub fn world(&self) -> &World {
        &self.world
    }

    fn decode_burst(&mut self, host_ns: i64, bytes: &[u8]) {
        let n = bytes.len() as i64;
        let read_ns = host_ns + (n - 1) * self.char_ns;
        // NMEA: the driver publishes an epoch after the line has been idle (the fast path
        // models that for every NMEA epoch); UBX: at its NAV-EOE, as soon as it is read.
        let flushed_ns = read_ns + IDLE_FLUSH.as_nanos() as i64;
        let pushed_ns = if self.protocol == Protocol::Nmea {
            flushed_ns
        } else {
            read_ns
        };
        let Self {
            decoder,
            fixes,
            gnss_service,
            time_pulse_service,
            event_service,
            raw_service,
            nav_data_service,
            char_ns,
            ..
        } = self;
        let fix_at = |fix: &navsync_shared::samples::GnssFix, delivered_ns: i64| Published {
            service: gnss_service.clone(),
            delivered_ns,
            sample: AnySample::GnssFix(*fix),
        };
        let mut extras = Vec::new();
        decoder.push_extras(
            bytes,
            read_ns,
            *char_ns,
            &mut |fix| fixes.push_back(fix_at(fix, pushed_ns)),
            &mut |x| {
                let (service, sample) = match x {
                    GnssExtra::TimePulse(tp) => (&*time_pulse_service, AnySample::TimePulse(*tp)),
                    GnssExtra::Event(e) => (&*event_service, AnySample::Event(*e)),
                    GnssExtra::Raw(r) => (&*raw_service, AnySample::Raw(*r)),
                    GnssExtra::NavData(n) => (&*nav_data_service, AnySample::NavData(*n)),
                    _ => return,
                };
                extras.push(Published {
                    service: service.clone(),
                    delivered_ns: read_ns,
                    sample,
                });
            },
        );
        decoder.flush(&mut |fix| fixes.push_back(fix_at(fix, flushed_ns)));
        fixes.extend(extras);
        fixes.make_contiguous().sort_by_key(|p| p.delivered_ns);
    }
}

impl Iterator for PublishedStream {
    type Item = Published;

    fn next(&mut self) -> Option<Published> {
        loop {
            let ev_ns = self.next_event.as_ref().map(SimEvent::host_ns);
            if let Some(f) = self.fixes.front()
                && ev_ns.is_none_or(|e| f.delivered_ns <= e)
            {
                return self.fixes.pop_front();
            }
            let ev = self.next_event.take()?;
            self.next_event = self.world.next_event();
            match ev {
                SimEvent::Imu { index, sample } => {
                    return Some(Published {
                        service: self.imu_services[index].clone(),
                        delivered_ns: sample.stamp.host_ns,
                        sample: AnySample::Imu(sample),
                    });
                }
                SimEvent::Pps(e) => {
                    return Some(Published {
                        service: self.pps_service.clone(),
                        delivered_ns: e.stamp.host_ns,
                        sample: AnySample::PpsEdge(e),
                    });
                }
                SimEvent::Truth(t) => {
                    return Some(Published {
                        service: self.truth_service.clone(),
                        delivered_ns: t.host_ns,
                        sample: AnySample::Truth(t),
                    });
                }
                SimEvent::Nmea { host_ns, bytes, .. } => self.decode_burst(host_ns, &bytes),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::SimConfig;
    use navsync_shared::time::gps_ns_from_utc_ns;

    const H0: i64 = 5_000_000_000_000;
    const U0: i64 = 1_790_000_000_400_000_000;

    /// The default drive's first 20 s, UBX.
    fn ubx_cfg() -> SimConfig {
        let mut cfg = SimConfig::default_drive();
        cfg.trajectory.segments.truncate(1);
        cfg.trajectory.segments[0].duration_s = 20.0;
        cfg.set_gnss_protocol(OutputProtocol::Ubx);
        cfg
    }

    fn run(cfg: &SimConfig) -> (World, Vec<Published>) {
        let world = World::new(cfg, H0, U0).expect("world");
        let stream = PublishedStream::new(world.clone());
        let events = stream.filter(|p| matches!(p.sample, AnySample::Event(_))).collect();
        (world, events)
    }

    /// The camera's marks come out of the driver's decoder on `navsync/gnss/0/event`, each
    /// within its accuracy estimate of the exposure's true time and after it.
    #[test]
    fn time_marks_are_published_with_the_exposures_times() {
        let mut cfg = ubx_cfg();
        cfg.set_gnss_rate_hz(2);
        cfg.set_camera_rate_hz(2.0);
        cfg.set_camera_exposure_offset_s(0.1);
        cfg.gnss.timepulse_quantization_ns = 20.83;
        let (world, events) = run(&cfg);
        let camera = world.camera().expect("a camera");
        // Exposures from 1 s to 20.4 s into the scenario reported by the last epoch (20 s).
        assert_eq!(events.len(), 38);
        for (k, p) in events.iter().enumerate() {
            let AnySample::Event(e) = p.sample else { unreachable!() };
            assert_eq!(&*p.service, "navsync/gnss/0/event");
            let x = camera.exposure(k as u64).expect("exposure");
            assert_eq!((e.count, e.channel, e.accuracy_ns), (k as u16 + 1, 0, 21));
            for (reported, truth) in [(e.rising_gps_ns, x.rising_utc_ns), (e.falling_gps_ns, x.falling_utc_ns)] {
                let err = reported - gps_ns_from_utc_ns(truth);
                assert!((0..=i64::from(e.accuracy_ns)).contains(&err), "exposure {k}: {err} ns");
            }
            assert_eq!((e.rising_host_ns, e.falling_host_ns), (i64::MIN, i64::MIN));
            // Reported after the epoch that follows the exposure, plus the output latency.
            assert!(p.delivered_ns > world.host_ns_at_utc(x.falling_utc_ns) + 600_000_000);
            // Its receipt stamp: the first of its 36 bytes, the last of the burst, at 115 200 Bd.
            let after_first = p.delivered_ns - e.stamp.host_ns - 35 * 10 * NS_PER_S / 115_200;
            assert!(after_first.abs() < 1000, "{after_first} ns");
        }
    }

    #[test]
    fn a_ubx_receiver_has_a_1_hz_camera_by_default_nmea_none() {
        let (world, events) = run(&ubx_cfg());
        assert_eq!(world.camera().map(|c| c.rate_hz()), Some(1.0));
        assert_eq!(events.len(), 19);
        let mut nmea = ubx_cfg();
        nmea.set_gnss_protocol(OutputProtocol::Nmea);
        let (world, events) = run(&nmea);
        assert!(world.camera().is_none() && events.is_empty());
    }
}
