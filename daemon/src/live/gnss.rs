//! `navsync gnss` (alias `gps`): the GNSS receiver driver process (NMEA, u-blox UBX)
//! (`navsync_drivers::gnss::driver`) with its settings: flag, else `[gnss.ID]`, else default.

use anyhow::{Context, Result, bail};
use navsync_drivers::gnss::Protocol;
use navsync_drivers::gnss::driver::{Baud, GnssArgs};

use crate::config::Loaded;
use crate::config::estimator::parse_id;

/// `navsync gnss`: a receiver on a serial port to `navsync/gnss/{id}/fix`.
#[derive(clap::Args, Debug)]
pub struct Options {
    /// Serial device (e.g. /dev/ttyUSB0, or a pseudo-terminal) [default: [gnss.ID].port].
    #[arg(long)]
    pub port: Option<String>,
    /// Line rate, or `auto` to hunt the common rates [default: [gnss.ID].baud, else 9600].
    #[arg(long)]
    pub baud: Option<Baud>,
    /// The receiver's protocol: auto (UBX navigation when the port carries it, else NMEA: the
    /// bytes say which), nmea, or ubx (u-blox binary) [default: [gnss.ID].protocol, else auto].
    #[arg(long)]
    pub protocol: Option<Protocol>,
    /// Publish the receiver's own IMU readings (UBX ESF-MEAS) as this IMU id, one more IMU of
    /// the array [default: [gnss.ID].imu_id, else not published].
    #[arg(long, value_parser = parse_id)]
    pub imu_id: Option<String>,
    /// Set a u-blox receiver up for navsync when the port opens (NAV-PVT, NAV-EOE, NAV-SAT,
    /// TIM-TP, TIM-TM2, RXM-RAWX, RXM-SFRBX, ESF-MEAS on every epoch and a 1 Hz time pulse;
    /// CFG-MSG/CFG-TP5 on M8, CFG-VALSET on F9; RAM only), each command checked with
    /// ACK/NAK [default: [gnss.ID].configure, else off: navsync never writes to a receiver].
    #[arg(long)]
    pub configure: bool,
    /// Receiver id.
    #[arg(long, default_value = "0", value_parser = parse_id)]
    pub id: String,
}

impl Options {
    /// The driver's settings.
    pub fn resolve(self, cfg: &Loaded) -> Result<GnssArgs> {
        let section = cfg.config.gnss.get(&self.id);
        let Some(port) = self.port.or_else(|| section.map(|s| s.port.clone())) else {
            bail!("no --port, and no [gnss.{}] in {}", self.id, cfg.shown());
        };
        Ok(GnssArgs {
            port,
            baud: self.baud.or(section.and_then(|s| s.baud)).unwrap_or(Baud::Fixed(9600)),
            protocol: self.protocol.or(section.and_then(|s| s.protocol)).unwrap_or_default(),
            imu_id: self.imu_id.or_else(|| section.and_then(|s| s.imu_id.clone())),
            configure: self.configure || section.and_then(|s| s.configure).unwrap_or(false),
            id: self.id,
        })
    }
}

/// Runs the driver until SIGINT/SIGTERM.
pub fn run(opts: Options, cfg: &Loaded) -> Result<()> {
    let args = opts.resolve(cfg)?;
    navsync_drivers::gnss::driver::run(&args).with_context(|| format!("gnss driver on {}", args.port))
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use super::*;

    #[test]
    fn flags_win_over_the_file_and_the_file_over_defaults() {
        let cfg = Loaded::parse("[gps.0]\nport = \"/dev/a\"\nbaud = 4800\n", Path::new("t.toml")).unwrap();
        let opts = |port: Option<&str>, baud: Option<Baud>, id: &str| Options {
            port: port.map(str::to_string),
            baud,
            protocol: None,
            imu_id: None,
            configure: false,
            id: id.into(),
        };
        let g = opts(None, None, "0").resolve(&cfg).unwrap();
        assert_eq!(
            (g.port.as_str(), g.baud, g.protocol),
            ("/dev/a", Baud::Fixed(4800), Protocol::Auto)
        );
        let g = opts(Some("/dev/b"), Some(Baud::Auto), "0").resolve(&cfg).unwrap();
        assert_eq!((g.port.as_str(), g.baud), ("/dev/b", Baud::Auto));
        assert!(opts(None, None, "1").resolve(&cfg).is_err());
        let g = opts(Some("/dev/c"), None, "1").resolve(&cfg).unwrap();
        assert_eq!(g.baud, Baud::Fixed(9600));
    }
}
