//! `navsync pps`: the PPS driver process (`navsync_drivers::pps`) with its source: flag, else
//! `[pps.ID].source`.

use anyhow::{Context, Result, bail};
use navsync_drivers::pps::{PpsArgs, SourceSpec};

use crate::config::Loaded;
use crate::config::estimator::parse_id;

/// `navsync pps`: edges from a kernel PPS device, a serial modem line or the simulator,
/// validated (missing/duplicate/early/late counted), to `navsync/pps/{id}/edge`.
#[derive(clap::Args, Debug)]
pub struct Options {
    /// kernel:/dev/ppsN, serial-dcd:/dev/ttyX, serial-cts:/dev/ttyX, or sim
    /// [default: [pps.ID].source].
    #[arg(long)]
    pub source: Option<SourceSpec>,
    /// PPS id.
    #[arg(long, default_value = "0", value_parser = parse_id)]
    pub id: String,
}

/// Runs the driver until SIGINT/SIGTERM.
pub fn run(opts: Options, cfg: &Loaded) -> Result<()> {
    let Some(source) = opts
        .source
        .or_else(|| cfg.config.pps.get(&opts.id).map(|p| p.source.clone()))
    else {
        bail!("no --source, and no [pps.{}] in {}", opts.id, cfg.shown());
    };
    let shown = source.to_string();
    navsync_drivers::pps::run(&PpsArgs { source, id: opts.id }).with_context(|| format!("pps driver on {shown}"))
}
