//! `navsync replay REC.mcap --estimate`: the estimator over a recording, offline.
//!
//! The samples the live estimator would subscribe to (`--gnss`, `--pps`, `--imus` ids) go in
//! recorded order through [`offline::estimate`] with the settings the live process builds
//! from the same flags and file, as fast as the CPU allows. Both go through
//! [`navsync_estimator::input_order`], so the `NavState`s are bit-identical to the live
//! process's for the same samples, and bit-identical from run to run.

use navsync_recording::output::{Overwrite, check_target, write_file};
use std::collections::HashSet;
use std::path::{Path, PathBuf};

use navsync_estimator::evaluation::Summary;
use navsync_estimator::input_order::Input;
use navsync_estimator::offline::{self, Output};
use navsync_estimator::settings::Settings;
use navsync_recording::mcap_reader::ScanEnd;
use navsync_recording::{RecordingError, SampleReader, SampleRecorder, channels};
use navsync_shared::samples::AnySample;
use navsync_shared::services;
use tracing::{info_span, warn};

use super::kf_gins::{KfGinsError, ResultWriter};
use crate::config::estimator::EstimatorFlags;
use crate::config::{ConfigError, Loaded};

/// Output format of `--out`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Format {
    /// The estimator's outputs in an MCAP file (see `--out`).
    Mcap,
    /// KF-GINS's navigation result (11 columns; a directory gets its IMU_ERR and STD files too).
    KfGins,
}

/// What `replay --estimate` writes, and the estimator's settings.
#[derive(clap::Args, Debug, Clone)]
pub struct EstimateOptions {
    /// Write the estimator's outputs into this file (with --estimate): mcap: its NavStates
    /// (`navsync/nav/state`), TimeStates and event poses (`navsync/event/{id}/pose`).
    #[arg(long, requires = "estimate")]
    pub out: Option<PathBuf>,
    /// Format of --out: `mcap`, or `kf-gins` (KF-GINS's result layout; a directory gets
    /// KF_GINS_Navresult.nav, KF_GINS_IMU_ERR.txt and KF_GINS_STD.txt).
    #[arg(long, default_value = "mcap", requires = "out")]
    pub format: Format,
    /// Write the accuracy summary as JSON to this file (with --estimate).
    #[arg(long, requires = "estimate")]
    pub summary_json: Option<PathBuf>,
    /// The best estimate of each instant instead of the real-time one: a Rauch–Tung–Striebel
    /// smoother over the delayed filter, with its smoothed σ (for --out, --format kf-gins and
    /// the summary). Without it every output is the state published live.
    #[arg(long, requires = "estimate")]
    pub smooth: bool,
    /// With --out (mcap): also the delayed filter's states (`navsync/nav/fused`: the state of
    /// each instant once every measurement up to it is fused, what the history of states
    /// answers for an instant the filter has passed).
    #[arg(long, requires = "out")]
    pub fused: bool,
    /// Replace an existing recording at --out or --summary-json (never the input itself).
    #[arg(long, requires = "estimate")]
    pub force: bool,
    /// The estimator's settings.
    #[command(flatten)]
    pub est: EstimatorFlags,
    /// With --out (mcap): encoding and standard messages.
    #[command(flatten)]
    pub recording: crate::config::recording::RecordingFlags,
}

/// Errors of `navsync replay --estimate`.
#[derive(Debug, thiserror::Error)]
pub enum EstimateError {
    /// Reading the recording or writing the output.
    #[error(transparent)]
    Recording(#[from] RecordingError),
    /// Writing the KF-GINS result.
    #[error(transparent)]
    KfGins(#[from] KfGinsError),
    /// The settings.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// Writing the summary.
    #[error("writing {path}: {source}")]
    Io {
        /// File.
        path: String,
        /// Cause.
        source: std::io::Error,
    },
    /// The run finished, but the estimator produced no usable states or far fewer than
    /// expected (the summary and its JSON say the same).
    #[error("{0}")]
    Unusable(String),
}

/// Samples per batch handed from the reading thread to the estimator.
const BATCH: usize = 4096;

type Batch = Vec<(Input, u64)>;

/// The samples of a recording that `settings` fuses, and the simulator's truth, with their
/// `log_time`, read and decoded by a thread of their own (decompression and decoding overlap
/// the estimator; the order is the file's). A read error ends the stream; [`finish`]
/// gives it back with the reader.
///
/// [`finish`]: RecordedInputs::finish
pub struct RecordedInputs {
    full: std::sync::mpsc::Receiver<Batch>,
    empty: std::sync::mpsc::SyncSender<Batch>,
    batch: Batch,
    pos: usize,
    thread: Option<std::thread::JoinHandle<(SampleReader, Option<RecordingError>)>>,
}

impl RecordedInputs {
    /// Starts reading the estimator's inputs of `reader`.
    pub fn new(mut reader: SampleReader, settings: &Settings) -> Self {
        let mut wanted: HashSet<String> = settings.input_services().into_iter().collect();
        wanted.insert(services::SIM_TRUTH.to_string());
        // Two batches in flight and two being recycled: bounded memory, no allocation per batch.
        let (full_tx, full) = std::sync::mpsc::sync_channel::<Batch>(2);
        let (empty, empty_rx) = std::sync::mpsc::sync_channel::<Batch>(4);
        for _ in 0..3 {
            let _ = empty.send(Vec::with_capacity(BATCH));
        }
        let thread = std::thread::Builder::new()
            .name("read-recording".into())
            .spawn(move || {
                let mut batch = empty_rx.recv().unwrap_or_default();
                let error = loop {
                    match reader.next_sample() {
                        Ok(Some(m)) if wanted.contains(m.service) => {
                            batch.push((Input::from_service(m.sample, m.service), m.log_time));
                            if batch.len() >= BATCH {
                                let next = empty_rx.recv().unwrap_or_default();
                                if full_tx.send(core::mem::replace(&mut batch, next)).is_err() {
                                    break None;
                                }
                                batch.clear();
                            }
                        }
                        Ok(Some(_)) => {}
                        Ok(None) => break None,
                        Err(e) => break Some(e),
                    }
                };
                if !batch.is_empty() {
                    let _ = full_tx.send(batch);
                }
                (reader, error)
            })
            .ok();
        Self {
            full,
            empty,
            batch: Vec::new(),
            pos: 0,
            thread,
        }
    }

    /// Waits for the reading thread: the reader (for how its scan ended) and the read error
    /// that ended the stream, if any.
    pub fn finish(self) -> (Option<SampleReader>, Option<RecordingError>) {
        let Self {
            full, empty, thread, ..
        } = self;
        // Unblocks the thread wherever it waits, should the stream not have been read to its end.
        drop(full);
        drop(empty);
        match thread.map(|t| t.join()) {
            Some(Ok((reader, error))) => (Some(reader), error),
            _ => (None, None),
        }
    }
}

impl Iterator for RecordedInputs {
    type Item = (Input, u64);
    fn next(&mut self) -> Option<(Input, u64)> {
        loop {
            if let Some(x) = self.batch.get_mut(self.pos) {
                self.pos += 1;
                // Taken out (the batch's storage is reused); a key stays in its place.
                let key = x.0.key();
                return Some(std::mem::replace(x, (Input::Other(key), 0)));
            }
            let next = self.full.recv().ok()?;
            let mut done = core::mem::replace(&mut self.batch, next);
            self.pos = 0;
            done.clear();
            let _ = self.empty.try_send(done);
        }
    }
}

/// The settings a live estimator published into a recording (its first
/// `navsync/estimator/settings` sample), as JSON; `None` when it holds none.
fn recorded_settings(path: &Path) -> Result<Option<String>, RecordingError> {
    let mut r = SampleReader::open(path)?;
    let has_channel = r.summary().map(|s| {
        s.channels
            .iter()
            .any(|c| channels::service_of(&c.topic) == services::ESTIMATOR_SETTINGS)
    });
    if has_channel == Some(false) {
        return Ok(None);
    }
    // The estimator publishes them when it starts and with every health report (about 1 Hz),
    // and a recorder started later gets the last one at once: they come early in the file.
    let mut left = if has_channel == Some(true) { u64::MAX } else { 1_000_000 };
    while let Some(s) = r.next_sample()? {
        if let AnySample::Settings(x) = s.sample {
            return Ok(x.text().map(str::to_string));
        }
        left -= 1;
        if left == 0 {
            break;
        }
    }
    Ok(None)
}

/// The estimator's settings for a recording: those of the live estimator that made it (its
/// published settings in force), else its defaults; over them what the recording says it was
/// made with (channel metadata: the IMU's noise model, the antenna lever arm, the receiver's
/// velocity σ, a known initial state), then the configuration file, then the flags.
pub fn settings_for_recording(
    est: &EstimatorFlags,
    cfg: &Loaded,
    reader: &SampleReader,
) -> Result<Settings, ConfigError> {
    let path = reader.mcap().path().to_path_buf();
    let mut defaults = Settings::default();
    let live = recorded_settings(&path).map_err(|e| ConfigError {
        file: path.clone(),
        line: None,
        field: Some(services::ESTIMATOR_SETTINGS.into()),
        message: e.to_string(),
    })?;
    if let Some(json) = &live {
        defaults.apply_in_force(json).map_err(|message| ConfigError {
            file: path.clone(),
            line: None,
            field: Some(format!(
                "{} (the live estimator's settings)",
                services::ESTIMATOR_SETTINGS
            )),
            message,
        })?;
    }
    // The inputs: the flags', else the file's, else the live run's, else the defaults.
    let ids = est.settings_over(cfg, defaults.clone())?;
    defaults.inputs = ids.inputs.clone();
    let meta = |service: Option<String>| service.map(|s| reader.channel_metadata(&s)).unwrap_or_default();
    let imu = meta(ids.inputs.imus.first().map(|id| services::imu_sample(id)));
    let gnss = meta(ids.inputs.gnss.first().map(|id| services::gnss_fix(id)));
    let value = |list: &[(String, String)], key: &str| list.iter().find(|(k, _)| k == key).map(|(_, v)| v.clone());
    let bad = |key: &str, e: serde_json::Error| ConfigError {
        file: reader.mcap().path().to_path_buf(),
        line: None,
        field: Some(format!("channel metadata {key}")),
        message: e.to_string(),
    };
    if let Some(v) = value(&imu, channels::META_IMU_NOISE) {
        defaults.imu.imu_noise = Some(serde_json::from_str(&v).map_err(|e| bad(channels::META_IMU_NOISE, e))?);
    }
    if let Some(v) = value(&imu, channels::META_INITIAL_STATE) {
        defaults.nav.initial_state = Some(serde_json::from_str(&v).map_err(|e| bad(channels::META_INITIAL_STATE, e))?);
    }
    if let Some(v) = value(&imu, channels::META_TIME_AXIS) {
        defaults.time.time_axis = Some(serde_json::from_str(&v).map_err(|e| bad(channels::META_TIME_AXIS, e))?);
    }
    if let Some(v) = value(&gnss, channels::META_LEVER_ARM) {
        defaults.nav.gnss_lever_arm_m = serde_json::from_str(&v).map_err(|e| bad(channels::META_LEVER_ARM, e))?;
    }
    if let Some(v) = value(&gnss, channels::META_GNSS_VEL_STD) {
        defaults.gnss.gnss_vel_std_mps = serde_json::from_str(&v).map_err(|e| bad(channels::META_GNSS_VEL_STD, e))?;
    }
    est.settings_over(cfg, defaults)
}

/// Warns when the recording was not closed properly (its end is missing).
pub fn warn_if_truncated(reader: &SampleReader, path: &Path) {
    if let Some(ScanEnd::Truncated { offset, record }) = reader.scan_end() {
        warn!(
            "{}: the recording stops at byte {offset} ({record}): it was not closed properly; estimated over what precedes",
            path.display()
        );
    }
    warn_skipped_chunks(reader, path);
}

/// Warns about every damaged chunk the reader skipped (where, which time range, why).
pub fn warn_skipped_chunks(reader: &SampleReader, path: &Path) {
    for c in reader.skipped_chunks() {
        warn!("{}: {c}; the rest of the recording was read", path.display());
    }
}

/// Runs the estimator over a recording as fast as the CPU allows; prints the summary table
/// (to stdout) and returns it.
pub fn run(input: &Path, opts: &EstimateOptions, cfg: &Loaded) -> Result<Summary, EstimateError> {
    let _span = info_span!("replay-estimate").entered();
    // Every output goes to a temporary file renamed into place at the end
    // (navsync_recording::output): the input is never opened for writing, whatever path
    // names it, and an existing recording is replaced only with --force.
    let inputs = [input];
    let rules = Overwrite::new(&inputs, opts.force);
    if let Some(p) = &opts.summary_json {
        check_target(p, &rules)?;
    }
    let reader = SampleReader::open(input)?;
    let settings = settings_for_recording(&opts.est, cfg, &reader)?;
    let mut out = match &opts.out {
        Some(p) if opts.format == Format::Mcap => Some(SampleRecorder::create(
            p,
            &rules,
            opts.recording.options(&cfg.config.recording),
        )?),
        _ => None,
    };
    let mut kf_gins = match &opts.out {
        Some(p) if opts.format == Format::KfGins => Some(ResultWriter::create(p, &rules)?),
        _ => None,
    };
    let mut kf_gins_err: Option<KfGinsError> = None;
    let mut write_err: Option<RecordingError> = None;
    let mut inputs = RecordedInputs::new(reader, &settings);
    let time_states = out.is_some();
    let on_output = |o: Output<'_>, &log_time: &u64| {
        if kf_gins_err.is_none()
            && let (Some(w), Output::Nav(n)) = (kf_gins.as_mut(), o)
        {
            kf_gins_err = w.write(n).err();
        }
        let Some(rec) = out.as_mut() else { return };
        if write_err.is_some() {
            return;
        }
        let r = match o {
            Output::Nav(n) => rec.write(
                services::NAV_STATE,
                &AnySample::Nav(*n),
                log_time,
                n.host_ns.max(0) as u64,
            ),
            Output::Time(t) => rec.write(
                services::TIME_STATE,
                &AnySample::Time(*t),
                log_time,
                t.computed_host_ns.max(0) as u64,
            ),
            Output::Event(e) => rec.write(
                &services::event_pose(navsync_shared::reflect::str_of(&e.device_id)),
                &AnySample::EventPose(*e),
                log_time,
                e.report_host_ns.max(0) as u64,
            ),
            Output::Fused(_) if !opts.fused => return,
            Output::Fused(n) => rec.write(
                services::NAV_FUSED,
                &AnySample::Nav(*n),
                log_time,
                n.host_ns.max(0) as u64,
            ),
        };
        if let Err(e) = r {
            write_err = Some(e);
        }
    };
    let run = if opts.smooth {
        offline::estimate_smoothed(&settings, inputs.by_ref(), time_states, on_output)
    } else {
        offline::estimate(&settings, inputs.by_ref(), time_states, on_output)
    };
    let (reader, read_err) = inputs.finish();
    if let Some(e) = read_err.or(write_err) {
        return Err(e.into());
    }
    if let Some(reader) = &reader {
        warn_if_truncated(reader, input);
    }
    if let Some(rec) = out {
        rec.close()?;
    }
    if let Some(e) = kf_gins_err {
        return Err(e.into());
    }
    if let Some(w) = kf_gins {
        w.finish()?;
    }
    println!("{}", run.summary.table());
    if let Some(p) = &opts.summary_json {
        let text = serde_json::to_string_pretty(&run.summary).unwrap_or_default();
        write_file(p, &rules, text.as_bytes())?;
    }
    if let Some(p) = run.summary.problem {
        return Err(EstimateError::Unusable(p));
    }
    Ok(run.summary)
}
