//! `navsync`: one multi-call binary; each subcommand is one role and runs as its own process.
//! This file only parses the command line and dispatches: every verb's options struct and
//! code live in its module (`live/` process shells, `tools/` offline tools).

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context, Result};
use clap::{Parser, Subcommand};
use navsync::live::{
    bridge, demo, echo, estimator, feed, gnss, gpsd_server, imu, nmea_out, ntpshm, pps, pps_out, record, replay, sim,
    status, trigger, web,
};
use navsync::tools::{
    analyze, check_config, convert, decode, eval, geotag, install, kf_gins, ptp_config, python_types, report,
    rinex_export, spp,
};
use navsync::{config, logging};

#[derive(Parser)]
#[command(name = "navsync", version, about = "GNSS/INS time-synchronisation daemon")]
struct Cli {
    /// Configuration file (default /etc/navsync/navsync.toml when it exists); flags override it.
    #[arg(long, global = true, value_name = "FILE")]
    config: Option<PathBuf>,
    /// Debug logging (unless RUST_LOG says otherwise), and an error's backtrace when one was
    /// captured (RUST_BACKTRACE=1). Without it, an error is one message and no backtrace.
    #[arg(short, long, global = true)]
    verbose: bool,
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// GNSS receiver driver: a serial port (NMEA) to `navsync/gnss/{id}/fix`.
    #[command(visible_alias = "gps")]
    Gnss(gnss::Options),
    /// IMU driver: samples from an IIO device, an Xsens MTi or the simulator to `navsync/imu/{id}/sample`.
    Imu(imu::Options),
    /// 1 PPS driver: validated edges to `navsync/pps/{id}/edge`.
    Pps(pps::Options),
    /// Plays a capture (receiver log or raw bytes) into a pseudo-terminal, as the device would send it.
    Feed(feed::Options),
    /// The estimator: time mapping and navigation filter from the sensor services.
    Estimator(estimator::Options),
    /// The simulated sensor world: IMUs and PPS to their services, NMEA into a pseudo-terminal.
    Sim(Box<sim::Options>),
    /// Runs sim, gnss and estimator as child processes with a live status line.
    Demo(demo::DemoArgs),
    /// Prints the samples of any navsync service, one per line.
    Echo(echo::EchoArgs),
    /// Every navsync process and service on this host: rates, last-sample ages, subscribers,
    /// health counters, time-sync state, receiver latency d0, GNSS delay and IMU offsets.
    Status(status::StatusArgs),
    /// Records navsync services into an MCAP file until Ctrl-C/SIGTERM or --duration.
    Record(record::Options),
    /// Publishes a recording into the live services with its original timing, or runs the
    /// estimator over it offline (--estimate).
    Replay(replay::Options),
    /// Rewrites a recording in another encoding (e.g. an older JSON recording as a ROS 2 bag).
    Convert(convert::Options),
    /// Bridges to other hosts: `navsync bridge zenoh` (needs the `zenoh` feature).
    #[command(subcommand)]
    Bridge(bridge::Command),
    /// Exports GNSS time (`navsync/time/state`) to chrony/ntpd as an NTP shared-memory refclock.
    Ntpshm(ntpshm::NtpShmArgs),
    /// Writes $GPRMC and $GPZDA right after each GNSS second into a serial port, for LiDARs
    /// and cameras that take NMEA time beside a PPS line.
    NmeaOut(nmea_out::NmeaOutArgs),
    /// A pulse at each GNSS second for sensors: a GPIO line, a PTP hardware clock's periodic
    /// output, or a file (tests).
    PpsOut(pps_out::PpsOutArgs),
    /// A trigger input stamped on the host (a camera's strobe on a GPIO line; simulated), each
    /// edge an event the estimator gives its pose (`navsync estimator --triggers ID`).
    Trigger(trigger::TriggerArgs),
    /// Serves the fused state to gpsd clients (gpsd JSON protocol).
    GpsdServer(gpsd_server::GpsdArgs),
    /// The running system in a browser (a live page, Server-Sent Events) and Prometheus
    /// metrics (/metrics), on 127.0.0.1:8080 by default.
    Web(web::WebArgs),
    /// Offline analyses of a recording.
    #[command(subcommand)]
    Analyze(analyze::Command),
    /// Imports another system's data files into a navsync recording.
    #[command(subcommand)]
    Import(kf_gins::ImportCommand),
    /// Writes a recording's data in another system's file formats.
    #[command(subcommand)]
    Export(rinex_export::ExportCommand),
    /// Position, velocity and attitude error statistics of a trajectory against a reference.
    Eval(eval::EvalArgs),
    /// GPS single-point positioning of a recording's raw data and navigation data, epoch by
    /// epoch, and its errors against a reference position.
    Spp(spp::SppArgs),
    /// One self-contained HTML page with SVG plots of a recording.
    Report(report::Options),
    /// Writes the pose of each camera exposure a receiver marked (a recording's event poses)
    /// into the images' Exif GPS tags, and as a CSV or OpenDroneMap's geo.txt.
    Geotag(Box<geotag::Options>),
    /// Decodes a receiver capture offline (same code as the live driver): one JSON object per epoch.
    #[command(visible_alias = "nmea")]
    Decode(decode::Options),
    /// Prints the sample layouts as Python ctypes structures (shared/python/navsync_types.py).
    PythonTypes,
    /// Prints the configuration reference of the estimator's settings as Markdown
    /// (docs/guide/configuration.md), generated from their declarations.
    ConfigReference,
    /// Checks the configuration file (--config, default /etc/navsync/navsync.toml) without
    /// starting anything: errors name the file, line, field and what was expected.
    CheckConfig,
    /// Installs the binary, the systemd units, sysusers/tmpfiles/udev files and the example
    /// configuration (docs/guide/install.md).
    Install(install::Options),
    /// Writes linuxptp's configuration for the vehicle network: ptp4l as the grandmaster fed
    /// from the disciplined system clock (phc2sys), or a slave (docs/guide/timing.md).
    PtpConfig(ptp_config::Options),
}

fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => return flag_error(e),
    };
    let verbose = cli.verbose || logging::debug_requested();
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            // The message and its causes on one line; a backtrace only when asked for: a
            // configuration or flag error is the user's to fix, not a crash to debug.
            eprintln!("Error: {e:#}");
            if verbose && e.backtrace().status() == std::backtrace::BacktraceStatus::Captured {
                eprintln!("\nBacktrace:\n{}", e.backtrace());
            }
            ExitCode::FAILURE
        }
    }
}

/// A command-line error in the user's words: the standard library's number parsers say
/// "invalid digit found in string" or "invalid float literal"; the message says what was
/// expected. Help and version go out as clap prints them.
fn flag_error(e: clap::Error) -> ExitCode {
    use clap::error::ErrorKind;
    if matches!(
        e.kind(),
        ErrorKind::DisplayHelp | ErrorKind::DisplayVersion | ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand
    ) {
        e.exit();
    }
    eprint!("{}", user_words(&e.render().to_string()));
    ExitCode::from(u8::try_from(e.exit_code()).unwrap_or(2))
}

/// Rust's wording of a number that did not parse, as the user would say it.
fn user_words(message: &str) -> String {
    [
        ("invalid digit found in string", "expected a whole number"),
        ("invalid float literal", "expected a number"),
        ("cannot parse integer from empty string", "expected a whole number"),
        ("cannot parse float from empty string", "expected a number"),
        ("number too large to fit in target type", "a number too large"),
        ("number too small to fit in target type", "a number too small"),
    ]
    .iter()
    .fold(message.to_string(), |m, (rust, user)| m.replace(rust, user))
}

fn run(cli: Cli) -> Result<()> {
    if matches!(cli.cmd, Cmd::CheckConfig) {
        return check_config::run(cli.config.as_deref());
    }
    if matches!(cli.cmd, Cmd::ConfigReference) {
        use std::io::Write;
        return std::io::stdout()
            .write_all(config::estimator::reference().as_bytes())
            .context("writing stdout");
    }
    let cfg = config::load(cli.config.as_deref())?;
    let level = if cli.verbose {
        Some("debug")
    } else {
        cfg.config.logging.level.as_deref()
    };
    logging::init(level);
    match cli.cmd {
        Cmd::Gnss(o) => gnss::run(o, &cfg),
        Cmd::Imu(o) => imu::run(o, &cfg),
        Cmd::Pps(o) => pps::run(o, &cfg),
        Cmd::Feed(o) => feed::run(o),
        Cmd::Estimator(o) => estimator::main(o, &cfg),
        Cmd::Sim(o) => sim::run(*o, &cfg),
        Cmd::Demo(o) => demo::run(&o).context("demo"),
        Cmd::Echo(o) => match &o.zenoh {
            Some(ep) => bridge::echo(ep, &o).with_context(|| format!("echo {} through {ep}", o.service)),
            None => echo::run(&o).with_context(|| format!("echo {}", o.service)),
        },
        Cmd::Status(o) => match &o.zenoh {
            Some(ep) => bridge::status(ep, o.window, o.json).with_context(|| format!("status through {ep}")),
            None => status::run(&o).context("status"),
        },
        Cmd::Bridge(c) => bridge::main(c, &cfg).context("bridge"),
        Cmd::Record(o) => record::main(o, &cfg),
        Cmd::Replay(o) => replay::main(o, &cfg),
        Cmd::Convert(o) => convert::run(&o, &cfg).context("convert"),
        Cmd::Ntpshm(o) => ntpshm::main(o, &cfg),
        Cmd::NmeaOut(o) => nmea_out::run(&o).context("nmea-out"),
        Cmd::PpsOut(o) => pps_out::run(&o).context("pps-out"),
        Cmd::Trigger(o) => trigger::run(&o).context("trigger"),
        Cmd::GpsdServer(o) => gpsd_server::run(&o).context("gpsd-server"),
        Cmd::Web(o) => web::run(&o).context("web"),
        Cmd::Analyze(c) => analyze::main(c, &cfg),
        Cmd::Import(c) => kf_gins::main(c),
        Cmd::Export(c) => rinex_export::main(c).context("export"),
        Cmd::Eval(o) => eval::run(&o).map(drop).context("eval"),
        Cmd::Spp(o) => spp::run(&o).context("spp"),
        Cmd::Report(o) => report::main(o, &cfg),
        Cmd::Geotag(o) => geotag::run(&o).context("geotag"),
        Cmd::Decode(o) => decode::run(o),
        Cmd::PythonTypes => python_types::run().context("writing stdout"),
        Cmd::CheckConfig | Cmd::ConfigReference => Ok(()),
        Cmd::Install(o) => install::run(o),
        Cmd::PtpConfig(o) => ptp_config::run(&o).context("ptp-config"),
    }
}

#[cfg(test)]
mod tests {
    use clap::CommandFactory;

    /// clap's own consistency checks of every subcommand (unique ids and groups, valid
    /// `requires`/`conflicts_with` references), which otherwise only fire when a debug build
    /// parses that subcommand.
    #[test]
    fn number_flags_say_what_was_expected() {
        use clap::Parser;
        for (args, wanted) in [
            (
                &["echo", "navsync/nav/state", "--count", "x"][..],
                "expected a whole number",
            ),
            (&["echo", "navsync/nav/state", "--rate", "fast"], "expected a number"),
        ] {
            let e = super::Cli::try_parse_from(std::iter::once("navsync").chain(args.iter().copied()))
                .err()
                .unwrap_or_else(|| panic!("{args:?} accepted"));
            let text = super::user_words(&e.render().to_string());
            assert!(text.contains(wanted), "{args:?}: {text}");
            assert!(
                !text.contains("invalid digit") && !text.contains("float literal"),
                "{text}"
            );
        }
    }

    #[test]
    fn the_command_line_is_consistent() {
        super::Cli::command().debug_assert();
    }

    /// A flag's value is checked as the file's is (the check of the setting's declaration),
    /// and the error names the flag.
    #[test]
    fn bad_estimator_flags_are_errors_that_name_the_flag() {
        use clap::Parser;
        for (args, flag) in [
            (
                &["replay", "x.mcap", "--estimate", "--gate-scale", "-1"][..],
                "--gate-scale",
            ),
            (&["replay", "x.mcap", "--estimate", "--horizon", "100"], "--horizon"),
            (&["estimator", "--gnss-vel-std", "nan"], "--gnss-vel-std"),
            (&["estimator", "--imus", "a,b c"], "--imus"),
            (&["estimator", "--lever-arm", "1,2"], "--lever-arm"),
            (&["sim", "--fast", "--estimate", "--align-speed", "0"], "--align-speed"),
        ] {
            let e = super::Cli::try_parse_from(std::iter::once("navsync").chain(args.iter().copied()))
                .err()
                .unwrap_or_else(|| panic!("{args:?} accepted"));
            assert!(e.to_string().contains(flag), "{args:?}: {e}");
        }
        let ok = super::Cli::try_parse_from(["navsync", "estimator", "--gate-scale", "2", "--lever-arm", "-1,0,0.5"]);
        assert!(ok.is_ok(), "{:?}", ok.err());
    }
}
