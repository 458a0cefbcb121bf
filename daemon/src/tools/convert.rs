//! `navsync convert IN.mcap OUT.mcap [--encoding cdr|json] [--ros-std]`: rewrites a recording
//! in another encoding (e.g. a JSON recording of an earlier navsync as a ROS 2 bag), with the
//! same samples, times and channel metadata.
//!
//! The output is written beside its target and renamed into place when complete
//! (`navsync_recording::output`): the input is never opened for writing, whatever path names
//! it (`./b.mcap`, a link); an existing recording is replaced only with `--force`; a failed
//! conversion leaves nothing. A corrupt chunk of the input is skipped and reported with its
//! time range; the rest is converted.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use navsync_recording::channels::{META_LAYOUT, META_QOS};
use navsync_recording::output::Overwrite;
use navsync_recording::ros_std::META_ORIGIN;
use navsync_recording::{SampleReader, SampleRecorder};

use crate::config::Loaded;
use crate::config::recording::RecordingFlags;

/// `navsync convert`.
#[derive(Debug, Clone, clap::Args)]
pub struct Options {
    /// The recording to read (MCAP; CDR or JSON).
    pub input: PathBuf,
    /// The recording to write.
    pub output: PathBuf,
    /// Replace an existing recording at OUTPUT (never the input itself).
    #[arg(long)]
    pub force: bool,
    /// Encoding and standard messages of the output.
    #[command(flatten)]
    pub format: RecordingFlags,
}

/// Runs `navsync convert`; prints what it wrote.
pub fn run(opts: &Options, cfg: &Loaded) -> Result<()> {
    let inputs = [opts.input.as_path()];
    let mut writer = SampleRecorder::create(
        &opts.output,
        &Overwrite::new(&inputs, opts.force),
        opts.format.options(&cfg.config.recording),
    )?;
    let mut reader = SampleReader::open(&opts.input)?;
    let mut seen = std::collections::HashSet::new();
    let mut n = 0u64;
    while let Some(s) = reader.next_sample()? {
        let service = s.service.to_string();
        let (sample, log_time, publish_time) = (s.sample, s.log_time, s.publish_time);
        if seen.insert(service.clone()) {
            // What the data were made with travels along; what the writer adds itself does not.
            for (k, v) in reader.channel_metadata(&service) {
                if k != META_LAYOUT && k != META_QOS && k != META_ORIGIN {
                    writer.set_channel_metadata(&service, &k, &v)?;
                }
            }
        }
        writer.write(&service, &sample, log_time, publish_time)?;
        n += 1;
    }
    let truncated = reader
        .scan_end()
        .is_some_and(|e| *e != navsync_recording::mcap_reader::ScanEnd::Clean);
    for c in reader.skipped_chunks() {
        eprintln!("convert: {}: {c}; converted the rest", opts.input.display());
    }
    for (topic, why) in reader.skipped_channels() {
        if !why.contains("(--ros-std)") {
            eprintln!("convert: skipped channel {topic}: {why}");
        }
    }
    if n == 0 {
        // The writer is dropped unclosed: no output appears.
        bail!("{}: no navsync samples to convert", opts.input.display());
    }
    writer.close()?;
    let size = std::fs::metadata(&opts.output)
        .with_context(|| opts.output.display().to_string())?
        .len();
    println!(
        "{} samples from {} ({} bytes) to {} ({size} bytes){}",
        n,
        opts.input.display(),
        std::fs::metadata(&opts.input).map(|m| m.len()).unwrap_or(0),
        opts.output.display(),
        if truncated {
            "; the input was cut short (its writer died)"
        } else {
            ""
        }
    );
    Ok(())
}
