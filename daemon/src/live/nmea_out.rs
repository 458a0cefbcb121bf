//! `navsync nmea-out --port DEV [--baud N]`: GNSS time for sensors. Right after each GNSS
//! second (UTC by navsync's time mapping, `navsync/time/state`) it writes `$GPRMC` and
//! `$GPZDA` of that second into a serial port, as LiDARs (Velodyne, Ouster, Hesai) and cameras
//! expect beside a PPS line: the sentence names the second whose pulse just passed.
//!
//! Sentences as NMEA 0183 defines them (RMC: time, status, position, speed in knots, course,
//! date, mode; ZDA: time, day, month, year, zone 00:00). RMC's status is `A` with the fused
//! position while the estimator's state is aligned and fresh, else `V` with empty position
//! fields (the time is valid whenever a sentence is written). Nothing is written while the time
//! mapping is not usable (acquiring, unknown, or no `TimeState` for [`ntpshm::STALE_AFTER_NS`](crate::live::ntpshm::STALE_AFTER_NS)), or
//! when its 1σ exceeds `--max-std-us`: a sensor then keeps its own clock rather than take a
//! wrong second. Counters in `navsync/health/nmea-out`.

use std::io::Write;
use std::path::PathBuf;
use std::time::Duration;

use crate::live::gnss_seconds::{SecondPacer, Tick};
use navsync_shared::health_reporter::HealthReporter;
use navsync_shared::samples::{NavState, NavStatus};
use navsync_shared::services;
use navsync_shared::time::{civil_from_utc_ns, monotonic_now_ns};
use navsync_sim::nmea::{KNOTS_PER_MPS, format_lat, format_lon, frame};
use tracing::{info, info_span, warn};

/// A `NavState` older than this gives no position (RMC status `V`), ns.
const NAV_FRESH_NS: i64 = 500_000_000;

/// `navsync nmea-out`.
#[derive(Debug, Clone, clap::Args)]
pub struct NmeaOutArgs {
    /// Serial port the sentences go to (e.g. /dev/ttyS1; a LiDAR's or camera's NMEA input).
    #[arg(long)]
    pub port: PathBuf,
    /// Line rate, baud (the sensor's; Velodyne and Ouster take 9600).
    #[arg(long, default_value_t = 9600, value_parser = clap::value_parser!(u32).range(1200..=921_600))]
    pub baud: u32,
    /// Write nothing while the time mapping's 1σ exceeds this many µs.
    #[arg(long, default_value_t = 1000.0, value_name = "US")]
    pub max_std_us: f64,
}

/// `$GPRMC` and `$GPZDA` of the GNSS second `utc_s_ns` (UTC ns, a whole second), with the
/// fused state `nav` when it is usable. Pure.
pub fn sentences(utc_s_ns: i64, nav: Option<&NavState>) -> Vec<u8> {
    let c = civil_from_utc_ns(utc_s_ns);
    let time = format!("{:02}{:02}{:02}.00", c.hour, c.minute, c.second);
    let date = format!("{:02}{:02}{:02}", c.day, c.month, c.year.rem_euclid(100));
    let mut out = Vec::with_capacity(160);
    let rmc = match nav.filter(|n| n.lat_deg.is_finite() && n.lon_deg.is_finite()) {
        Some(n) => {
            let [vn, ve, _] = n.vel_ned_mps;
            let speed = vn.hypot(ve);
            let course = ve.atan2(vn).to_degrees().rem_euclid(360.0);
            let course = if course >= 359.95 { 0.0 } else { course };
            format!(
                "GPRMC,{time},A,{},{},{:.2},{:.1},{date},,,A",
                format_lat(n.lat_deg),
                format_lon(n.lon_deg),
                speed * KNOTS_PER_MPS,
                course
            )
        }
        None => format!("GPRMC,{time},V,,,,,,,{date},,,N"),
    };
    frame(&rmc, &mut out);
    frame(
        &format!("GPZDA,{time},{:02},{:02},{:04},00,00", c.day, c.month, c.year),
        &mut out,
    );
    out
}

/// Errors of `navsync nmea-out`.
#[derive(Debug, thiserror::Error)]
pub enum NmeaOutError {
    /// The port could not be opened.
    #[error("{port}: {source}")]
    Open {
        /// The port.
        port: String,
        /// Cause.
        source: serialport::Error,
    },
    /// IPC failure.
    #[error(transparent)]
    Ipc(#[from] navsync_shared::ipc::IpcError),
    /// A health counter could not be registered.
    #[error(transparent)]
    Health(#[from] navsync_shared::health_reporter::HealthError),
}

/// Runs `navsync nmea-out` until SIGINT/SIGTERM.
pub fn run(args: &NmeaOutArgs) -> Result<(), NmeaOutError> {
    let port_name = args.port.display().to_string();
    let _span = info_span!("nmea-out", port = %port_name).entered();
    let node = navsync_shared::ipc::IpcNode::new("nmea-out")?;
    let mut pacer = SecondPacer::new(&node, args.max_std_us * 1e3, 0)?;
    let nav = node.subscriber::<NavState>(services::NAV_STATE)?;
    let mut health = HealthReporter::new(&node, "nmea-out")?;
    let c_written = health.counter("seconds_written")?;
    let c_skipped = health.counter("seconds_not_written")?;
    let c_failed = health.counter("write_failed")?;
    let mut port = serialport::new(&port_name, args.baud)
        .timeout(Duration::from_millis(200))
        .open_native()
        .map_err(|source| NmeaOutError::Open {
            port: port_name.clone(),
            source,
        })?;
    info!(baud = args.baud, "nmea-out running");
    navsync_shared::sd_notify::ready("nmea-out running");
    let mut latest_nav: Option<NavState> = None;
    while !node.termination_requested() {
        navsync_shared::sd_notify::watchdog();
        while let Some(n) = nav.receive()? {
            latest_nav = Some(n);
        }
        // Sleep to the next second's beginning (at most 200 ms at a time, to see a stop request).
        let second = match pacer.next(&node)? {
            Tick::Second { second, .. } => second,
            Tick::Pending => continue,
            Tick::Unusable => {
                health.add(c_skipped, 1);
                let _ = health.maybe_publish(monotonic_now_ns());
                continue;
            }
        };
        let fresh_nav = latest_nav.as_ref().filter(|n| {
            n.status != NavStatus::Aligning as u8 && monotonic_now_ns().saturating_sub(n.host_ns).abs() < NAV_FRESH_NS
        });
        let bytes = sentences(second, fresh_nav);
        match port.write_all(&bytes) {
            Ok(()) => health.add(c_written, 1),
            Err(e) => {
                health.add(c_failed, 1);
                warn!("writing: {e}");
            }
        }
        let _ = health.maybe_publish(monotonic_now_ns());
    }
    navsync_shared::sd_notify::stopping();
    let _ = health.publish_final();
    info!("nmea-out stopped");
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use navsync_shared::time::NS_PER_S;

    #[test]
    fn rmc_and_zda_of_a_second() {
        // 2026-12-04 21:30:05 UTC.
        let t = 1_796_419_805 * NS_PER_S;
        let text = String::from_utf8(sentences(t, None)).unwrap();
        let lines: Vec<&str> = text.split("\r\n").filter(|l| !l.is_empty()).collect();
        assert_eq!(lines.len(), 2, "{text}");
        assert!(
            lines[0].starts_with("$GPRMC,213005.00,V,,,,,,,041226,,,N*"),
            "{}",
            lines[0]
        );
        assert!(
            lines[1].starts_with("$GPZDA,213005.00,04,12,2026,00,00*"),
            "{}",
            lines[1]
        );
        for l in &lines {
            let (body, cs) = l[1..].split_once('*').unwrap();
            assert_eq!(
                u8::from_str_radix(cs, 16).unwrap(),
                navsync_sim::nmea::checksum(body.as_bytes())
            );
        }
        let mut n = <NavState as navsync_shared::reflect::Reflect>::zeroed();
        n.lat_deg = -23.5;
        n.lon_deg = 11.25;
        n.vel_ned_mps = [0.0, 10.0, 0.0];
        let text = String::from_utf8(sentences(t, Some(&n))).unwrap();
        assert!(
            text.starts_with("$GPRMC,213005.00,A,2330.0000000,S,01115.0000000,E,19.44,90.0,041226,,,A*"),
            "{text}"
        );
    }
}
