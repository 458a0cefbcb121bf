//! Logging to stderr through `tracing`: the level from `$RUST_LOG`, else the configuration's
//! `[logging].level`, else info. Under systemd (`$JOURNAL_STREAM` set: stderr is the journal)
//! without colours and time stamps (the journal stamps every line); on a terminal with colours.

use tracing::Level;
use tracing_subscriber::filter::Targets;
use tracing_subscriber::prelude::*;

/// Whether `$RUST_LOG` asks for debug (or trace) messages: then an error also shows its
/// backtrace, as with `-v`.
pub fn debug_requested() -> bool {
    std::env::var("RUST_LOG").is_ok_and(|s| {
        let s = s.to_ascii_lowercase();
        s.contains("debug") || s.contains("trace")
    })
}

/// Installs the subscriber (once; later calls do nothing).
pub fn init(config_level: Option<&str>) {
    let filter: Targets = std::env::var("RUST_LOG")
        .ok()
        .and_then(|s| s.parse().ok())
        .or_else(|| config_level.and_then(|s| s.parse().ok()))
        .unwrap_or_else(|| Targets::new().with_default(Level::INFO));
    let journal = std::env::var_os("JOURNAL_STREAM").is_some();
    let tty = std::io::IsTerminal::is_terminal(&std::io::stderr());
    let layer = tracing_subscriber::fmt::layer()
        .with_writer(std::io::stderr)
        .with_target(false)
        .with_ansi(tty && !journal);
    let registry = tracing_subscriber::registry().with(filter);
    let _ = if journal {
        registry.with(layer.without_time()).try_init()
    } else {
        registry.with(layer).try_init()
    };
}
