//! `navsync bridge zenoh`: settings from the flags, else `[bridge.zenoh]`, else the defaults,
//! handed to `navsync_bridge_zenoh` (built with the `zenoh` feature).

use std::path::PathBuf;
use std::time::Duration;

use anyhow::{Result, bail};

use crate::config::Loaded;
use crate::config::bridge::ZenohMode;

/// `navsync bridge …`.
#[derive(Debug, clap::Subcommand)]
pub enum Command {
    /// Forwards navsync services to Zenoh key expressions (and imports a remote host's).
    Zenoh(ZenohOptions),
}

/// `navsync bridge zenoh`.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct ZenohOptions {
    /// This host's name in the keys (navsync/<instance>/nav/state) [default:
    /// [bridge.zenoh].instance, else the host name].
    #[arg(long)]
    pub instance: Option<String>,
    /// Services (names or patterns) to export [default: [bridge.zenoh].export, else
    /// navsync/nav/state navsync/time/state navsync/health/**].
    #[arg(long, num_args = 1..)]
    pub export: Vec<String>,
    /// Export nothing (an importing host).
    #[arg(long, conflicts_with = "export")]
    pub no_export: bool,
    /// Rate limit SERVICE=HZ (name or pattern), e.g. navsync/nav/state=50 [default: [bridge.zenoh].rates].
    #[arg(long = "rate", value_parser = parse_rate)]
    pub rates: Vec<(String, f64)>,
    /// Import this remote instance's services (`*`: every other instance) into the local
    /// iceoryx2 under the same names [default: [bridge.zenoh].import].
    #[arg(long)]
    pub import: Option<String>,
    /// With --import: which services (patterns) [default: every navsync service].
    #[arg(long, num_args = 1..)]
    pub import_services: Vec<String>,
    /// A Zenoh configuration file (JSON5), passed through [default: [bridge.zenoh].zenoh_config].
    #[arg(long)]
    pub zenoh_config: Option<PathBuf>,
    /// peer, client or router [default: [bridge.zenoh].mode, else the Zenoh config's, else peer].
    #[arg(long, value_parser = parse_mode)]
    pub mode: Option<ZenohMode>,
    /// Endpoints to connect to, e.g. tcp/192.168.1.10:7447 [default: [bridge.zenoh].connect].
    #[arg(long, num_args = 1..)]
    pub connect: Vec<String>,
    /// Endpoints to listen on, e.g. tcp/0.0.0.0:7447 [default: [bridge.zenoh].listen].
    #[arg(long, num_args = 1..)]
    pub listen: Vec<String>,
    /// Stop after this many seconds.
    #[arg(long = "duration")]
    pub duration_s: Option<f64>,
}

fn parse_rate(s: &str) -> Result<(String, f64), String> {
    let (svc, hz) = s.split_once('=').ok_or_else(|| format!("`{s}`: expected SERVICE=HZ"))?;
    match hz.parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok((svc.to_string(), v)),
        _ => Err(format!("`{hz}`: expected a positive rate in Hz")),
    }
}

fn parse_mode(s: &str) -> Result<ZenohMode, String> {
    match s {
        "peer" => Ok(ZenohMode::Peer),
        "client" => Ok(ZenohMode::Client),
        "router" => Ok(ZenohMode::Router),
        _ => Err(format!("`{s}`: expected peer, client or router")),
    }
}

/// The host name (for the default instance).
fn host_name() -> String {
    let mut buf = [0u8; 256];
    // SAFETY: gethostname writes at most `len` bytes into the buffer.
    let r = unsafe { libc::gethostname(buf.as_mut_ptr().cast(), buf.len()) };
    let name = if r == 0 {
        navsync_shared::reflect::str_of(&buf).to_string()
    } else {
        String::new()
    };
    let clean: String = name
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect();
    if clean.is_empty() { "navsync".into() } else { clean }
}

/// Runs `navsync bridge`.
pub fn main(cmd: Command, cfg: &Loaded) -> Result<()> {
    let Command::Zenoh(o) = cmd;
    let file = cfg.config.bridge.zenoh.clone().unwrap_or_default();
    let export = if o.no_export {
        Vec::new()
    } else if !o.export.is_empty() {
        o.export
    } else {
        file.export
            .clone()
            .unwrap_or_else(|| DEFAULT_EXPORT.iter().map(|s| s.to_string()).collect())
    };
    let rates = if o.rates.is_empty() {
        file.rates.iter().map(|(k, v)| (k.clone(), *v)).collect()
    } else {
        o.rates
    };
    for (svc, hz) in &rates {
        if !(hz.is_finite() && *hz > 0.0) {
            bail!(
                "{}: [bridge.zenoh] rates: `{svc}` = {hz}: expected a positive rate in Hz",
                cfg.shown()
            );
        }
    }
    let settings = Settings {
        instance: o.instance.or(file.instance).unwrap_or_else(host_name),
        export,
        rates,
        import: o.import.or(file.import),
        import_services: if o.import_services.is_empty() {
            file.import_services
        } else {
            o.import_services
        },
        zenoh_config: o.zenoh_config.or(file.zenoh_config),
        mode: o.mode.or(file.mode),
        connect: if o.connect.is_empty() { file.connect } else { o.connect },
        listen: if o.listen.is_empty() { file.listen } else { o.listen },
        duration: o.duration_s.map(Duration::from_secs_f64),
    };
    run(settings)
}

/// The default export list (as the bridge crate's).
const DEFAULT_EXPORT: [&str; 3] = ["navsync/nav/state", "navsync/time/state", "navsync/health/**"];

/// The resolved settings.
#[derive(Debug, Clone)]
pub struct Settings {
    /// Instance name.
    pub instance: String,
    /// Exported services.
    pub export: Vec<String>,
    /// Rate limits.
    pub rates: Vec<(String, f64)>,
    /// Imported instance.
    pub import: Option<String>,
    /// Imported services.
    pub import_services: Vec<String>,
    /// Zenoh file.
    pub zenoh_config: Option<PathBuf>,
    /// Mode.
    pub mode: Option<ZenohMode>,
    /// Connect endpoints.
    pub connect: Vec<String>,
    /// Listen endpoints.
    pub listen: Vec<String>,
    /// Stop after.
    pub duration: Option<Duration>,
}

#[cfg(feature = "zenoh")]
fn run(s: Settings) -> Result<()> {
    use navsync_bridge_zenoh as z;
    let mode = s.mode.map(|m| match m {
        ZenohMode::Peer => z::Mode::Peer,
        ZenohMode::Client => z::Mode::Client,
        ZenohMode::Router => z::Mode::Router,
    });
    z::bridge::run(&z::BridgeSettings {
        instance: s.instance,
        export: s.export,
        rates: s
            .rates
            .into_iter()
            .map(|(pattern, max_hz)| z::RateLimit { pattern, max_hz })
            .collect(),
        import: s.import,
        import_services: s.import_services,
        session: z::SessionSettings {
            config_file: s.zenoh_config,
            mode,
            connect: s.connect,
            listen: s.listen,
        },
        duration: s.duration,
    })?;
    Ok(())
}

#[cfg(not(feature = "zenoh"))]
fn run(_: Settings) -> Result<()> {
    bail!("{NO_ZENOH}")
}

/// What a navsync without the `zenoh` feature says.
pub const NO_ZENOH: &str =
    "this navsync was built without Zenoh (`--no-default-features`): build it with the default features";

/// `navsync echo --zenoh ENDPOINT SERVICE`.
#[cfg(feature = "zenoh")]
pub fn echo(endpoint: &str, o: &super::echo::EchoArgs) -> Result<()> {
    let e = navsync_bridge_zenoh::remote::RemoteEcho {
        endpoint: endpoint.to_string(),
        service: o.service.clone(),
        instance: o.instance.clone(),
        count: o.count,
        timeout: o.timeout,
    };
    let n = navsync_bridge_zenoh::remote::echo(&e, &mut std::io::stdout().lock())?;
    if n == 0 {
        bail!("no sample of {} through {endpoint}", o.service);
    }
    Ok(())
}

/// `navsync echo --zenoh ENDPOINT SERVICE`.
#[cfg(not(feature = "zenoh"))]
pub fn echo(_: &str, _: &super::echo::EchoArgs) -> Result<()> {
    bail!("{NO_ZENOH}")
}

/// `navsync status --zenoh ENDPOINT`: instances and services heard, JSON or a table.
#[cfg(feature = "zenoh")]
pub fn status(endpoint: &str, window: Duration, json: bool) -> Result<()> {
    let st = navsync_bridge_zenoh::remote::status(endpoint, window)?;
    if json {
        println!("{}", serde_json::to_string(&st)?);
        return Ok(());
    }
    for (instance, services) in &st.services {
        println!("{instance}");
        for (service, h) in services {
            println!("  {service:<32} {:>8.1} Hz  {:>6} lost", h.rate_hz, h.lost);
        }
        for (process, counters) in st.health.get(instance).into_iter().flatten() {
            let list: Vec<String> = counters.iter().map(|(k, v)| format!("{k}={v}")).collect();
            println!("  health {process}: {}", list.join(" "));
        }
    }
    for (key, why) in &st.refused {
        println!("refused {key}: {why}");
    }
    Ok(())
}

/// `navsync status --zenoh ENDPOINT`.
#[cfg(not(feature = "zenoh"))]
pub fn status(_: &str, _: Duration, _: bool) -> Result<()> {
    bail!("{NO_ZENOH}")
}
