//! `navsync estimator`: subscribes to the timing and sensor services, runs the estimator
//! library and publishes `navsync/time/state` (and, with the navigation filter,
//! `navsync/nav/state`).
//!
//! The loop sleeps on one event, [`navsync_shared::services::WAKE`], which every driver
//! notifies after publishing (with its sample's kind); on every wake-up by an input it drains
//! the services (IMUs first, then PPS and GNSS) into [`InputOrder`], which hands them to the
//! pipeline in an order that depends on the samples alone (a PPS edge or fix goes in right
//! before the first reference-IMU sample stamped a fixed hold after it; see
//! [`navsync_estimator::input_order`]), so the results are the same whatever the scheduling, and
//! `navsync replay --estimate` of a recording of the same samples reproduces them bit for bit.

use std::time::Duration;

use navsync_shared::health_reporter::HealthReporter;
use navsync_shared::history;
use navsync_shared::ipc::{IpcError, IpcNode, Publisher, Subscriber};
use navsync_shared::latency_histogram::LatencyHistogram;
use navsync_shared::samples::{
    AnySample, EstimatorSettings, EventPose, GnssEvent, GnssFix, GnssNavData, GnssRaw, GnssTimePulse, ImuSample,
    NavState, NavStatus, NetworkTime, PpsEdge, TimeState,
};
use navsync_shared::services::{self, ServiceKind};
use navsync_shared::time::{NS_PER_S, monotonic_now_ns};
use tracing::{info, info_span, warn};

use navsync_estimator::feed::Feed;
use navsync_estimator::input_order::Input;
use navsync_estimator::settings::Settings;

use super::liveness::{Change, Liveness, STALE_MARGIN_NS};
use crate::config::Loaded;
use crate::config::estimator::EstimatorFlags;

/// `navsync estimator`: time mapping and navigation filter from the sensor services.
#[derive(clap::Args, Debug)]
pub struct Options {
    /// The estimator's settings.
    #[command(flatten)]
    pub est: EstimatorFlags,
    /// Hold the CPU wake-up latency at 0 µs while running (`/dev/cpu_dma_latency`, as
    /// cyclictest does): idle CPUs poll, so waking the estimator costs no exit from a
    /// halted CPU. For low-latency deployments, with SCHED_FIFO; costs an idle core's power.
    #[arg(long)]
    pub idle_polling: bool,
    /// Spin on the inputs instead of sleeping between samples: no wake-up latency and no
    /// wake-up system call for the drivers, for an estimator pinned to an isolated core
    /// (`taskset`, `isolcpus`); costs that whole core. Off by default.
    #[arg(long)]
    pub busy_poll: bool,
}

/// Runs the estimator process with its settings (flags, else the file, else defaults).
pub fn main(opts: Options, cfg: &Loaded) -> anyhow::Result<()> {
    use anyhow::Context;
    let settings = opts.est.settings(cfg)?;
    let _hold = opts
        .idle_polling
        .then(navsync_shared::cpu_wakeup::CpuWakeupHold::take)
        .transpose()
        .context("--idle-polling: holding /dev/cpu_dma_latency at 0")?;
    run(&settings, opts.busy_poll).context("estimator")
}

/// How often the estimator's reclaimer thread ([`super::reclaimer`]) removes dead nodes, so a
/// killed driver's publisher no longer counts.
const RECLAIM_INTERVAL: std::time::Duration = std::time::Duration::from_millis(40);

/// How often the estimator's loop looks for inputs whose publishing process is gone (a
/// publisher count of 0 on the input's service), ns. With [`RECLAIM_INTERVAL`] and the
/// wake-up latency this bounds the time from a driver's death to its stale flag, whatever the
/// input's rate.
const PUBLISHER_CHECK_INTERVAL_NS: i64 = 20_000_000;
/// How often the usability of the output is checked (a warning each time it fails), ns.
const OUTPUT_CHECK_INTERVAL_NS: i64 = 60 * NS_PER_S;

/// The published navigation status while every GNSS input is gone: an aligned (or degraded)
/// filter is inertial-only from that moment, not only after the navigator's outage time.
fn status_without_gnss(status: u8) -> u8 {
    if status == NavStatus::Aligned as u8 || status == NavStatus::Degraded as u8 {
        NavStatus::InsOnly as u8
    } else {
        status
    }
}

/// Notes a sample of input `i`; true (and logged) when the input was stale until now.
fn resumed(live: &mut Liveness, i: usize, stamp_ns: i64, rx_ns: i64) -> bool {
    match live.seen(i, stamp_ns, rx_ns) {
        Some(Change::Resumed { stale_ns }) => {
            info!(input = %live.inputs()[i].name, stale_ms = stale_ns / 1_000_000, "input back");
            true
        }
        _ => false,
    }
}

/// Errors of the estimator process.
#[derive(Debug, thiserror::Error)]
pub enum EstimatorError {
    /// IPC failure.
    #[error(transparent)]
    Ipc(#[from] IpcError),
    /// The dead-node reclaimer thread could not be started.
    #[error("starting the dead-node reclaimer thread: {0}")]
    Reclaimer(#[from] std::io::Error),
    /// The network time reader thread could not be started.
    #[error("starting the network time reader thread: {0}")]
    NetworkTime(std::io::Error),
    /// A health counter could not be registered.
    #[error(transparent)]
    Health(#[from] navsync_shared::health_reporter::HealthError),
}

/// Runs the estimator until SIGINT/SIGTERM; `busy_poll`: see [`Options::busy_poll`].
pub fn run(args: &Settings, busy_poll: bool) -> Result<(), EstimatorError> {
    let _span = info_span!("estimator").entered();
    let node = IpcNode::new("estimator")?;
    // Dead drivers' publishers stop counting once their node is reclaimed: off this loop.
    let _reclaimer = super::reclaimer::Reclaimer::start("estimator-reclaim", RECLAIM_INTERVAL)?;
    // A network time service instead of the receivers' PPS (a host without a receiver).
    let network = super::network_time::NetworkTimeReader::start(args.inputs.time_source, &args.inputs.chrony_address)
        .map_err(EstimatorError::NetworkTime)?;
    let mut network_pub = match network {
        Some(_) => Some(node.publisher::<NetworkTime>(services::NETWORK_TIME)?),
        None => None,
    };
    let pps: Vec<Subscriber<PpsEdge>> = args
        .inputs
        .pps
        .iter()
        .filter(|_| network.is_none())
        .map(|id| node.input(&services::pps_edge(id)))
        .collect::<Result<_, _>>()?;
    let gnss: Vec<Subscriber<GnssFix>> = args
        .inputs
        .gnss
        .iter()
        .map(|id| node.input(&services::gnss_fix(id)))
        .collect::<Result<_, _>>()?;
    // The receivers' reports of their next time pulse (UBX TIM-TP), where they send them.
    let time_pulses: Vec<Subscriber<GnssTimePulse>> = args
        .inputs
        .gnss
        .iter()
        .map(|id| node.input(&services::gnss_time_pulse(id)))
        .collect::<Result<_, _>>()?;
    // Tightly coupled: the receivers' raw measurements (UBX RXM-RAWX) and navigation data
    // (RXM-SFRBX).
    let tight = args.nav.coupling.uses_raw();
    let raws: Vec<Subscriber<GnssRaw>> = args
        .inputs
        .gnss
        .iter()
        .filter(|_| tight)
        .map(|id| node.input(&services::gnss_raw(id)))
        .collect::<Result<_, _>>()?;
    let nav_data: Vec<Subscriber<GnssNavData>> = args
        .inputs
        .gnss
        .iter()
        .filter(|_| tight)
        .map(|id| node.input(&services::gnss_nav_data(id)))
        .collect::<Result<_, _>>()?;
    // Each receiver's event marks (TIM-TM2) and each trigger input's edges, posed once the
    // delayed filter passes them and published on `navsync/event/{id}/pose`.
    let event_ids: Vec<(String, &String)> = (args.inputs.gnss.iter().map(|id| (services::gnss_event(id), id)))
        .chain(args.inputs.triggers.iter().map(|id| (services::trigger_event(id), id)))
        .collect();
    let events: Vec<(Subscriber<GnssEvent>, [u8; 8])> = event_ids
        .iter()
        .map(|(service, id)| Ok::<_, IpcError>((node.input(service)?, navsync_shared::reflect::fixed_str(id))))
        .collect::<Result<_, _>>()?;
    let mut event_pubs: Vec<([u8; 8], Publisher<EventPose>)> = Vec::new();
    let imus: Vec<Subscriber<ImuSample>> = args
        .inputs
        .imus
        .iter()
        .map(|id| node.input(&services::imu_sample(id)))
        .collect::<Result<_, _>>()?;
    let mut time_pub = node.publisher::<TimeState>(services::TIME_STATE)?;
    // The settings in force, with every health report: a recording of this run replays with
    // them (`replay --estimate`).
    let mut settings_pub = node.publisher::<EstimatorSettings>(services::ESTIMATOR_SETTINGS)?;
    let mut settings_sample = EstimatorSettings::new(0, 0, &args.in_force_json());
    if settings_sample.is_none() {
        warn!(
            "the settings in force exceed {} bytes of JSON: not published, a recording of this run will not hold them",
            navsync_shared::samples::SETTINGS_JSON_BYTES
        );
    }
    let mut publish_settings = |now_ns: i64| -> Result<(), IpcError> {
        if let Some(s) = &mut settings_sample {
            s.host_ns = now_ns;
            settings_pub.publish(s)?;
            s.seq += 1;
        }
        Ok(())
    };
    publish_settings(monotonic_now_ns())?;
    let mut health = HealthReporter::new(&node, "estimator")?;
    // The time source's counters: the PPS edges', or the network time readings' (the slots of a
    // Health report are few: 64, and the other source's would stay 0).
    let (c_time_used, c_time_rej) = if network.is_some() {
        (
            health.counter("network_time_used")?,
            health.counter("network_time_rejected")?,
        )
    } else {
        (health.counter("pps_used")?, health.counter("pps_rejected")?)
    };
    let c_pps_rx = if network.is_some() {
        None
    } else {
        Some(health.counter("pps_labelled_by_rx")?)
    };
    let c_fixes = health.counter("gnss_fixes")?;
    let c_imu = health.counter("imu_samples")?;
    let c_imu_gap = health.counter("imu_seq_gaps")?;
    let r_imu = health.rate("imu_samples")?;
    let r_fix = health.rate("gnss_fixes")?;

    // One wake-up for every input: each publisher notifies `navsync/wake` with its kind.
    let wake = node.wake()?;
    wake.set_busy_poll(busy_poll);
    const INPUT_KINDS: [ServiceKind; 7] = [
        ServiceKind::ImuSample,
        ServiceKind::PpsEdge,
        ServiceKind::GnssFix,
        ServiceKind::GnssTimePulse,
        ServiceKind::GnssRaw,
        ServiceKind::GnssNavData,
        ServiceKind::GnssEvent,
    ];

    let mut feed: Feed = Feed::new(args.pipeline_config());
    let mut nav_pub = node.publisher::<NavState>(services::NAV_STATE)?;
    // The states of the last `history_s` in shared memory, for `state_at` queries.
    let mut history = history::HistoryWriter::create(
        &navsync_shared::ipc::prefix(),
        history::capacity_for(args.inputs.history_s),
    )
    .inspect_err(|e| warn!("no history of states for state_at queries: {e}"))
    .ok();
    let c_nav = health.counter("nav_states")?;
    let c_event_poses = health.counter("event_poses")?;
    let c_events_unposed = health.counter("events_without_pose")?;
    // Never silent: states usable by a subscriber (aligned, with a GNSS time); a warning
    // with the reason every minute while they are missing or far fewer than the states.
    let c_usable = health.counter("nav_usable")?;
    let mut next_check_ns = monotonic_now_ns() + OUTPUT_CHECK_INTERVAL_NS;
    let c_fix_used = health.counter("fixes_used")?;
    let c_fix_rej = health.counter("fixes_rejected")?;
    let c_fix_old = health.counter("fixes_too_old")?;
    let c_late = health.counter("inputs_late")?;
    // Faults in the data (issue 8): GNSS resets after persistent rejections, PPS holdovers and
    // relocks, IMU samples rejected by the estimator (non-finite, time-reversed, saturated).
    let c_gnss_resets = health.counter("gnss_resets")?;
    let c_gnss_resets_full = health.counter("gnss_resets_full")?;
    let c_holdovers = health.counter("time_holdovers")?;
    let c_relocks = health.counter("time_relocks")?;
    let c_imu_invalid = health.counter("imu_rejected_invalid")?;
    let c_imu_back = health.counter("imu_rejected_backwards")?;
    let c_imu_sat = health.counter("imu_rejected_saturated")?;
    // Output latency: from taking an IMU sample off its queue to its NavState being published.
    let c_lat_p99 = health.counter("nav_latency_p99_us")?;
    let c_lat_max = health.counter("nav_latency_max_us")?;
    let mut latency = LatencyHistogram::default();
    let mut last_imu_seq: Vec<Option<u64>> = vec![None; imus.len()];
    let mut last_state_ns = 0i64;
    let mut last_status = feed.pipeline().time().status();
    // Staleness of every input (roles/liveness.rs): IMUs first, then PPS, then GNSS, as
    // drained below; flagged in Health at once (`stale_<kind>_<id>`: host ns when declared).
    let mut live = Liveness::default();
    let mut c_stale = Vec::new();
    let pps_ids: &[String] = if network.is_some() { &[] } else { &args.inputs.pps };
    for (kind, ids, nominal_ns) in [
        ("imu", args.inputs.imus.as_slice(), 10_000_000),
        ("pps", pps_ids, NS_PER_S),
        ("gnss", args.inputs.gnss.as_slice(), NS_PER_S),
    ] {
        for id in ids {
            live.add(&format!("{kind}_{id}"), nominal_ns);
            c_stale.push(health.counter(&format!("stale_{kind}_{id}"))?);
        }
    }
    let c_stale_n = health.counter("stale_inputs")?;
    let c_stale_events = health.counter("stale_events")?;
    // The groups of counters below fill the report's remaining slots; those that do not fit
    // (many inputs, tightly coupled) are named in one warning instead of stopping the
    // estimator.
    let mut left_out: Vec<&'static str> = Vec::new();
    let mut group = |names: Vec<&'static str>, health: &mut HealthReporter| -> Vec<Option<_>> {
        names
            .into_iter()
            .map(|name| {
                let c = health.counter(name).ok();
                if c.is_none() {
                    left_out.push(name);
                }
                c
            })
            .collect()
    };
    // Each kind of measurement's counters (`zupt_used`, …), whatever kinds there are.
    let mut c_measurements = Vec::new();
    feed.pipeline()
        .nav()
        .measurement_states()
        .each_counter(&mut |name, _| c_measurements.push(name));
    let c_measurements = group(c_measurements, &mut health);
    // The integrity monitor's counters (`integrity_resets`, …).
    let mut c_integrity = Vec::new();
    feed.pipeline()
        .nav()
        .integrity()
        .each(&mut |name, _| c_integrity.push(name));
    let c_integrity = group(c_integrity, &mut health);
    // Tightly coupled: the raw-measurement path's counters (`raw_no_ephemeris`, …).
    let mut c_raw = Vec::new();
    if tight {
        feed.pipeline().each_raw_counter(&mut |name, _| c_raw.push(name));
    }
    let c_raw = group(c_raw, &mut health);
    if !left_out.is_empty() {
        warn!(
            "the health report has no room for {} counters ({} slots): {} are not reported",
            left_out.len(),
            navsync_shared::samples::MAX_COUNTERS,
            left_out.join(", ")
        );
    }
    let (n_imu, n_pps) = (imus.len(), pps.len());
    let mut next_publisher_check_ns = monotonic_now_ns();
    info!(pps = ?args.inputs.pps, gnss = ?args.inputs.gnss, imus = ?args.inputs.imus, "estimator running");
    navsync_shared::sd_notify::ready(&format!(
        "estimator: gnss {:?}, pps {:?}, imus {:?}",
        args.inputs.gnss, args.inputs.pps, args.inputs.imus
    ));

    loop {
        navsync_shared::sd_notify::watchdog();
        // Wake at the nearest staleness deadline at the latest.
        let now = monotonic_now_ns();
        let wait_ns = live
            .next_deadline()
            .map_or(next_publisher_check_ns, |d| d.min(next_publisher_check_ns))
            .saturating_sub(now)
            .clamp(1_000_000, 100_000_000);
        if !node.wait(&wake, Duration::from_nanos(wait_ns as u64))? {
            break;
        }
        // Woken only by other samples (its own outputs, other processes' health): nothing to
        // drain unless a deadline is due.
        if wake.fired() != 0 && !INPUT_KINDS.iter().any(|&k| wake.fired_kind(k)) && monotonic_now_ns() < now + wait_ns {
            continue;
        }
        let mut updated = false;
        let rx_ns = monotonic_now_ns();
        let mut liveness_changed = false;
        // IMUs first: a PPS edge or fix published before the IMU sample that releases it is
        // then always among what this wake-up drains.
        for (i, (s, last)) in imus.iter().zip(last_imu_seq.iter_mut()).enumerate() {
            s.drain(|sample| {
                liveness_changed |= resumed(&mut live, i, sample.stamp.host_ns, rx_ns);
                if let Some(prev) = *last
                    && sample.stamp.seq > prev + 1
                {
                    health.add(c_imu_gap, sample.stamp.seq - prev - 1);
                }
                *last = Some(sample.stamp.seq);
                health.add(c_imu, 1);
                health.tick(r_imu);
                feed.push(AnySample::Imu(sample), ());
                true
            })?;
        }
        for (j, s) in pps.iter().enumerate() {
            s.drain(|edge| {
                liveness_changed |= resumed(&mut live, n_imu + j, edge.stamp.host_ns, rx_ns);
                feed.push(AnySample::PpsEdge(edge), ());
                true
            })?;
        }
        for (k, s) in gnss.iter().enumerate() {
            s.drain(|fix| {
                liveness_changed |= resumed(&mut live, n_imu + n_pps + k, fix.stamp.host_ns, rx_ns);
                health.add(c_fixes, 1);
                health.tick(r_fix);
                feed.push(AnySample::GnssFix(fix), ());
                true
            })?;
        }
        if let (Some(reader), Some(publisher)) = (&network, &mut network_pub) {
            reader.drain(|t| {
                if let Err(e) = publisher.publish(&t) {
                    warn!("publishing network time: {e}");
                }
                feed.push(AnySample::NetworkTime(t), ());
            });
        }
        for s in &time_pulses {
            s.drain(|tp| {
                feed.push(AnySample::TimePulse(tp), ());
                true
            })?;
        }
        for s in &raws {
            s.drain(|raw| {
                feed.push(AnySample::Raw(raw), ());
                true
            })?;
        }
        for s in &nav_data {
            s.drain(|d| {
                feed.push(AnySample::NavData(d), ());
                true
            })?;
        }
        for (s, id) in &events {
            s.drain(|e| {
                feed.push(Input::Event(e, *id), ());
                true
            })?;
        }
        // NavStates say inertial-only at once when every receiver's driver is gone.
        let gnss_gone = !gnss.is_empty() && live.inputs()[n_imu + n_pps..].iter().all(|x| x.is_gone());
        // Without IMUs (or with the reference IMU silent) nothing releases the waiting samples.
        let release_all = imus.is_empty() || feed.order().stalled(monotonic_now_ns());
        loop {
            let t_in = monotonic_now_ns();
            let Some(mut step) = feed.next(release_all) else { break };
            updated |= step.time_changed;
            if let Some(state) = &mut step.nav {
                if gnss_gone {
                    state.status = status_without_gnss(state.status);
                }
                if let Err(e) = nav_pub.publish(state) {
                    warn!("publishing nav state: {e}");
                }
                if let Some(h) = &mut history {
                    h.append(state, history::Source::Predicted);
                }
                latency.record(monotonic_now_ns() - t_in);
                health.add(c_nav, 1);
            }
            if let Some(h) = feed.finish(&step) {
                warn!(
                    from = navsync_shared::reflect::str_of(&h.from),
                    to = navsync_shared::reflect::str_of(&h.to),
                    "reference IMU stale: handed over to a live IMU"
                );
            }
            if step.nav.is_some() {
                health.set(c_usable, feed.check().usable);
            }
            // The delayed filter's states into the history (they answer queries of the
            // instants it has passed), and the events it posed.
            let pipeline = feed.pipeline_mut();
            if let Some(h) = &mut history {
                pipeline.drain_fused(&mut |s| {
                    h.append(s, history::Source::Fused);
                });
            } else {
                pipeline.drain_fused(&mut |_| {});
            }
            pipeline.drain_event_poses(&mut |e| {
                let publisher = match event_pubs.iter().position(|(id, _)| *id == e.device_id) {
                    Some(i) => Some(&mut event_pubs[i].1),
                    None => {
                        // The id as given (the sample holds its first 8 bytes).
                        let id = event_ids
                            .iter()
                            .find(|(_, id)| navsync_shared::reflect::fixed_str::<8>(id) == e.device_id)
                            .map_or_else(
                                || navsync_shared::reflect::str_of(&e.device_id).to_string(),
                                |(_, id)| (*id).clone(),
                            );
                        match node.publisher::<EventPose>(&services::event_pose(&id)) {
                            Ok(p) => {
                                event_pubs.push((e.device_id, p));
                                event_pubs.last_mut().map(|x| &mut x.1)
                            }
                            Err(err) => {
                                warn!("no service for the event poses of {id}: {err}");
                                None
                            }
                        }
                    }
                };
                if let Some(p) = publisher
                    && let Err(err) = p.publish(e)
                {
                    warn!("publishing an event pose: {err}");
                }
            });
            let ec = feed.pipeline().event_counters();
            health.set(c_event_poses, ec.posed);
            health.set(c_events_unposed, ec.without_pose);
        }
        health.set(c_late, feed.order().late());
        let now = monotonic_now_ns();
        if now >= next_check_ns {
            next_check_ns = now + OUTPUT_CHECK_INTERVAL_NS;
            if let Some(why) = feed.problem() {
                warn!(states = feed.check().states, usable = feed.check().usable, "{why}");
            }
        }
        live.check(now, |_, x, _| {
            warn!(
                input = %x.name,
                silent_ms = (x.interval_ns() * 1e-6 + (STALE_MARGIN_NS / 1_000_000) as f64).round(),
                "input stale: nothing for its interval plus the margin"
            );
            health.add(c_stale_events, 1);
            liveness_changed = true;
        });
        if now >= next_publisher_check_ns {
            next_publisher_check_ns = now + PUBLISHER_CHECK_INTERVAL_NS;
            let publishers = imus
                .iter()
                .map(Subscriber::publisher_count)
                .chain(pps.iter().map(Subscriber::publisher_count))
                .chain(gnss.iter().map(Subscriber::publisher_count));
            for (i, n) in publishers.enumerate() {
                if n == 0 && live.gone(i, now).is_some() {
                    warn!(input = %live.inputs()[i].name, "input stale: its publisher is gone");
                    health.add(c_stale_events, 1);
                    liveness_changed = true;
                }
            }
        }
        if liveness_changed {
            for (c, x) in c_stale.iter().zip(live.inputs()) {
                health.set(*c, x.stale_since_ns().map_or(0, |t| t.max(1) as u64));
            }
            health.set(c_stale_n, live.stale_count() as u64);
            if let Err(e) = health.publish_now(now) {
                warn!("publishing health: {e}");
            }
        }
        if feed.pipeline().time().status() != last_status {
            info!(
                from = last_status.name(),
                to = feed.pipeline().time().status().name(),
                "time status"
            );
            last_status = feed.pipeline().time().status();
        }
        if updated || now - last_state_ns >= NS_PER_S {
            let state = feed.pipeline_mut().time_state(now);
            if let Err(e) = time_pub.publish(&state) {
                warn!("publishing time state: {e}");
            }
            last_state_ns = now;
        }
        let tc = *feed.pipeline().time().counters();
        if network.is_some() {
            health.set(c_time_used, tc.network_used);
            health.set(c_time_rej, tc.network_rejected);
        } else {
            health.set(c_time_used, tc.pps_used);
            health.set(c_time_rej, tc.rejected());
        }
        if let Some(c) = c_pps_rx {
            health.set(c, tc.pps_labelled_by_receiver);
        }
        health.set(c_holdovers, tc.holdovers);
        health.set(c_relocks, tc.relocks);
        let est = feed.pipeline();
        let nc = est.nav().counters();
        health.set(c_fix_used, nc.fixes_used);
        health.set(c_fix_rej, nc.fixes_rejected);
        health.set(c_fix_old, nc.fixes_too_old);
        health.set(c_gnss_resets, nc.gnss_resets);
        health.set(c_gnss_resets_full, nc.gnss_resets_full);
        let ac = *est.array().counters();
        health.set(c_imu_invalid, ac.invalid);
        health.set(c_imu_back, ac.backwards);
        health.set(c_imu_sat, ac.saturated);
        let mut k = 0;
        est.nav().measurement_states().each_counter(&mut |_, v| {
            if let Some(Some(c)) = c_measurements.get(k) {
                health.set(*c, v);
            }
            k += 1;
        });
        let mut k = 0;
        est.nav().integrity().each(&mut |_, v| {
            if let Some(Some(c)) = c_integrity.get(k) {
                health.set(*c, v);
            }
            k += 1;
        });
        let mut k = 0;
        est.each_raw_counter(&mut |_, v| {
            if let Some(Some(c)) = c_raw.get(k) {
                health.set(*c, v);
            }
            k += 1;
        });
        health.set(c_lat_p99, latency.quantile_us(0.99) as u64);
        health.set(c_lat_max, (latency.max_ns() as u64).div_ceil(1000));
        if health.maybe_publish(now)? {
            latency.clear();
            publish_settings(now)?;
        }
    }
    navsync_shared::sd_notify::stopping();
    health.publish_final()?;
    info!("estimator stopped");
    Ok(())
}
