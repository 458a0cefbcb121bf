//! `navsync geotag --events REC.mcap --images DIR (--out DIR | --in-place) [--csv FILE]
//! [--odm-geo FILE]`: the pose of each camera exposure a receiver marked (the `EventPose`s of a
//! recording, `navsync/event/{id}/pose`) written into the matching JPEG's Exif GPS tags, and as
//! the image lists photogrammetry tools import (a CSV; OpenDroneMap's `geo.txt`).
//!
//! **Pairing.** By default by the receiver's edge counter (`--match count`): the images in
//! file-name order are the exposures one after the other, the first image is the first event's
//! counter (or `--first-count N`), image k the counter k further on. An event that never reached
//! the recording leaves its image untagged (warned, by name and counter), and the images after it
//! keep their own events: a lost TIM-TM2 cannot shift the later images onto their neighbours'
//! poses. `--match time` pairs each image's own capture time (Exif `DateTimeOriginal`,
//! `SubSecTimeOriginal`, `OffsetTimeOriginal`) plus `--time-offset` with the nearest event within
//! `--tolerance`. Counts that do not agree (more images than counters, events past the last
//! image, images without an event in time) are an error with the numbers unless `--partial`.
//! An event without a pose (`source` 0) leaves its image untagged, named in a warning.
//!
//! **Tags.** GPSVersionID 2.3, GPSLatitude/Ref, GPSLongitude/Ref (1e-6″), GPSAltitude/Ref
//! (height above mean sea level: the ellipsoidal height less the EGM96 undulation,
//! `navsync_drivers::gnss::geoid`; the Exif standard's altitude is "based on sea level"; mm),
//! GPSTimeStamp and GPSDateStamp (the event's UTC, µs), GPSImgDirection/Ref (`T`: the body's yaw,
//! true north), GPSSpeed/Ref (`K`, km/h, horizontal), GPSHPositioningError (√(σ_N² + σ_E²), m),
//! GPSMapDatum `WGS-84`. Every other Exif field of the image is kept (its GPS fields are
//! replaced); the other segments (JFIF, XMP, ICC, the image data) are copied byte for byte.
//!
//! **Files.** Each image is read whole, rebuilt in memory and written through
//! `navsync_recording::output` (a temporary file beside the target, renamed over it once
//! complete): into `--out DIR` (the originals untouched; an existing file there only with
//! `--force`), or over the image itself with `--in-place` (its permissions kept). Every image
//! is checked (a JPEG, readable Exif, a pose) and every target before the first is written.

use std::collections::{BTreeMap, BTreeSet};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, anyhow, bail};
use exif::experimental::Writer;
use exif::{Field, In, Rational, Tag, Value};
use img_parts::jpeg::Jpeg;
use img_parts::{Bytes, ImageEXIF};
use navsync_recording::SampleReader;
use navsync_recording::output::{Overwrite, same_file, write_file};
use navsync_shared::reflect::str_of;
use navsync_shared::samples::{AnySample, EVENT_EDGE_FALLING, EVENT_EDGE_RISING, EventPose};
use navsync_shared::time::{Civil, civil_from_utc_ns, days_from_civil};

/// How images are paired with events.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum MatchBy {
    /// The k-th image in file-name order is the k-th edge by the receiver's counter.
    Count,
    /// Each image's Exif capture time (plus --time-offset) is its nearest event's UTC.
    Time,
}

/// Which edge of the camera's signal is the exposure.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Edge {
    /// Rising edges (TIM-TM2 `timeRising`).
    Rising,
    /// Falling edges (TIM-TM2 `timeFalling`).
    Falling,
}

/// `navsync geotag`.
#[derive(Debug, Clone, clap::Args)]
pub struct Options {
    /// The recording with the event poses (`navsync/event/{id}/pose`: `navsync record` beside
    /// the estimator, or `navsync replay REC --estimate --out OUT.mcap`).
    #[arg(long, value_name = "REC.mcap")]
    pub events: PathBuf,
    /// The folder of the images: its `*.jpg`/`*.jpeg` files (any case); other files are left
    /// alone.
    #[arg(long, value_name = "DIR")]
    pub images: PathBuf,
    /// Write the tagged images into this folder (created if missing; the originals are not
    /// touched); images left untagged are copied unchanged.
    #[arg(long, value_name = "DIR", conflicts_with = "in_place")]
    pub out: Option<PathBuf>,
    /// Rewrite the images in their folder (each through a temporary file renamed over it).
    #[arg(long)]
    pub in_place: bool,
    /// Also write one CSV row per tagged image: name, latitude, longitude, ellipsoidal height,
    /// height above sea level, roll, pitch, yaw, σ, UTC, the event's counter.
    #[arg(long, value_name = "FILE")]
    pub csv: Option<PathBuf>,
    /// Also write OpenDroneMap's image geolocation file (`geo.txt`: EPSG:4326, longitude
    /// latitude altitude yaw pitch roll, horizontal and vertical accuracy).
    #[arg(long, value_name = "FILE")]
    pub odm_geo: Option<PathBuf>,
    /// How images are paired with events.
    #[arg(long = "match", value_enum, default_value = "count", value_name = "HOW")]
    pub match_by: MatchBy,
    /// `--match count`: the event counter of the first image (default: the first event's).
    #[arg(long, value_name = "N")]
    pub first_count: Option<u16>,
    /// `--match time`: seconds added to an image's capture time to make it UTC (after its
    /// OffsetTimeOriginal, when it has one), e.g. -7200 for a camera clock on UTC+2.
    #[arg(long, value_name = "S", allow_negative_numbers = true)]
    pub time_offset: Option<f64>,
    /// `--match time`: the largest difference between an image's time and its event's, s.
    #[arg(long, value_name = "S")]
    pub tolerance: Option<f64>,
    /// The receiver whose events to use (the ID of `navsync/event/ID/pose`), when the recording
    /// has several.
    #[arg(long, value_name = "ID")]
    pub device: Option<String>,
    /// The event input to use (u-blox: 0 EXTINT0, 1 EXTINT1), when the events come on several.
    #[arg(long, value_name = "N")]
    pub channel: Option<u8>,
    /// Which edge of the camera's signal marks the exposure.
    #[arg(long, value_enum, default_value = "rising")]
    pub edge: Edge,
    /// Tag what pairs when the numbers of images and events differ (a warning with the
    /// numbers instead of an error).
    #[arg(long)]
    pub partial: bool,
    /// Replace existing files in --out DIR.
    #[arg(long)]
    pub force: bool,
}

/// Default of `--tolerance`, s.
const DEFAULT_TOLERANCE_S: f64 = 0.5;
/// How many names a message lists before "…".
const LIST_AT_MOST: usize = 8;

/// One image of the folder.
#[derive(Debug, Clone)]
struct Image {
    path: PathBuf,
    name: String,
    /// Capture time from its Exif, UTC ns after the offset (`--match time` only).
    taken_utc_ns: Option<i64>,
}

/// The events chosen from the recording, in time order, with their counters unwrapped.
#[derive(Debug, Clone)]
struct Events {
    poses: Vec<EventPose>,
    /// The edge counter of each, unwrapped past 65535 (strictly increasing).
    counter: Vec<i64>,
    /// The device they came from.
    device: String,
    /// What else was in the recording and not chosen (for the summary).
    other: usize,
}

/// Runs `navsync geotag`; prints what it wrote.
pub fn run(opts: &Options) -> Result<()> {
    check_options(opts)?;
    let events = read_events(opts)?;
    let mut images = list_images(&opts.images)?;
    if images.is_empty() {
        bail!(
            "{}: no JPEG images (*.jpg, *.jpeg) in the folder",
            opts.images.display()
        );
    }
    // Every image is a JPEG whose Exif reads, before anything is written.
    let offset_ns = (opts.time_offset.unwrap_or(0.0) * 1e9).round() as i64;
    for img in &mut images {
        let bytes = std::fs::read(&img.path).with_context(|| format!("reading {}", img.path.display()))?;
        let info = inspect_jpeg(bytes).with_context(|| img.path.display().to_string())?;
        img.taken_utc_ns = info.taken_utc_ns.map(|t| t + offset_ns);
        if opts.match_by == MatchBy::Time && img.taken_utc_ns.is_none() {
            bail!(
                "{}: no capture time in its Exif (DateTimeOriginal): --match time needs one in every image",
                img.path.display()
            );
        }
    }
    let pairing = match opts.match_by {
        MatchBy::Count => pair_by_count(images.len(), &events, opts.first_count)?,
        MatchBy::Time => pair_by_time(
            &images,
            &events,
            (opts.tolerance.unwrap_or(DEFAULT_TOLERANCE_S) * 1e9).round() as i64,
        )?,
    };
    if let Some(problem) = &pairing.mismatch {
        if !opts.partial {
            bail!("{problem}; nothing written (--partial tags the images that pair)");
        }
        eprintln!("geotag: warning: {problem}; tagging the images that pair (--partial)");
    }

    // What each image gets.
    let mut plan: Vec<(usize, Option<Tagged>)> = Vec::with_capacity(images.len());
    let mut untagged: Vec<String> = Vec::new();
    for (i, img) in images.iter().enumerate() {
        let tagged = match pairing.event_of[i] {
            Some(e) => {
                let p = &events.poses[e];
                match Tagged::of(p) {
                    Some(t) => Some(t),
                    None => {
                        untagged.push(format!(
                            "{}: its event (counter {}, {}) has no pose",
                            img.name,
                            p.count,
                            utc_text(p.utc_ns)
                        ));
                        None
                    }
                }
            }
            None => {
                untagged.push(format!("{}: {}", img.name, pairing.why_none[i]));
                None
            }
        };
        plan.push((i, tagged));
    }
    for u in &untagged {
        eprintln!("geotag: warning: {u}: not tagged");
    }
    // Each image's new Exif is made once before any is written (it must fit its segment).
    if opts.out.is_some() || opts.in_place {
        for (i, t) in &plan {
            if let Some(t) = t {
                let img = &images[*i];
                let bytes = std::fs::read(&img.path).with_context(|| format!("reading {}", img.path.display()))?;
                tag_jpeg(bytes, &t.fields).with_context(|| img.path.display().to_string())?;
            }
        }
    }

    // The targets, all checked before the first is written.
    let targets: Vec<PathBuf> = match &opts.out {
        Some(dir) => {
            if dir.exists() && same_file(dir, &opts.images) {
                bail!(
                    "--out {} is the images' folder: give another folder, or --in-place to rewrite the images",
                    dir.display()
                );
            }
            std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
            let t: Vec<PathBuf> = images.iter().map(|i| dir.join(&i.name)).collect();
            let existing: Vec<String> = t
                .iter()
                .filter(|p| std::fs::symlink_metadata(p).is_ok())
                .map(|p| p.display().to_string())
                .collect();
            if !existing.is_empty() && !opts.force {
                bail!(
                    "{} of the images exist in {} already ({}): --force replaces them",
                    existing.len(),
                    dir.display(),
                    list(&existing)
                );
            }
            t
        }
        None if opts.in_place => images.iter().map(|i| i.path.clone()).collect(),
        None => Vec::new(),
    };
    let mut side_outputs: Vec<&Path> = Vec::new();
    side_outputs.extend(opts.csv.as_deref());
    side_outputs.extend(opts.odm_geo.as_deref());
    for s in &side_outputs {
        if images.iter().any(|i| same_file(&i.path, s)) || same_file(s, &opts.events) {
            bail!("{}: is one of the inputs; refused as an output", s.display());
        }
    }
    if opts.odm_geo.is_some()
        && let Some(bad) = plan
            .iter()
            .filter(|(_, t)| t.is_some())
            .map(|(i, _)| &images[*i].name)
            .find(|n| n.chars().any(char::is_whitespace))
    {
        bail!(
            "{bad}: a name with a space cannot be a row of OpenDroneMap's geo.txt (its columns are separated by spaces)"
        );
    }

    let mut written = 0usize;
    let mut copied = 0usize;
    if !targets.is_empty() {
        let inputs: Vec<&Path> = vec![opts.events.as_path()];
        for (i, tagged) in &plan {
            let img = &images[*i];
            let target = &targets[*i];
            let rules = if opts.in_place {
                Overwrite::new(&[], true)
            } else {
                Overwrite::new(&inputs, opts.force)
            };
            let original = std::fs::read(&img.path).with_context(|| format!("reading {}", img.path.display()))?;
            let bytes = match tagged {
                Some(t) => tag_jpeg(original, &t.fields).with_context(|| img.path.display().to_string())?,
                None if opts.in_place => continue,
                None => original,
            };
            let mode = std::fs::metadata(&img.path).map(|m| m.permissions()).ok();
            write_file(target, &rules, &bytes).with_context(|| format!("writing {}", target.display()))?;
            if opts.in_place
                && let Some(mode) = mode
            {
                std::fs::set_permissions(target, mode)
                    .with_context(|| format!("restoring the permissions of {}", target.display()))?;
            }
            if tagged.is_some() {
                written += 1;
            } else {
                copied += 1;
            }
        }
    }

    let rows: Vec<(&str, &Tagged)> = plan
        .iter()
        .filter_map(|(i, t)| t.as_ref().map(|t| (images[*i].name.as_str(), t)))
        .collect();
    let event_input = [opts.events.as_path()];
    let rules = Overwrite::new(&event_input, false);
    if let Some(p) = &opts.csv {
        write_file(p, &rules, csv_text(&rows).as_bytes()).with_context(|| format!("writing {}", p.display()))?;
    }
    if let Some(p) = &opts.odm_geo {
        write_file(p, &rules, odm_geo_text(&rows).as_bytes()).with_context(|| format!("writing {}", p.display()))?;
    }

    let mut summary = format!(
        "{} images in {}, {} events of receiver {} ({} with a pose); ",
        images.len(),
        opts.images.display(),
        events.poses.len(),
        events.device,
        events.poses.iter().filter(|p| p.source != 0).count()
    );
    match (&opts.out, opts.in_place) {
        (Some(dir), _) => {
            let _ = write!(summary, "tagged {written} into {}", dir.display());
            if copied > 0 {
                let _ = write!(summary, " ({copied} copied untagged)");
            }
        }
        (None, true) => {
            let _ = write!(summary, "tagged {written} in place");
        }
        (None, false) => {
            let _ = write!(summary, "{} posed (images not written)", rows.len());
        }
    }
    if let Some(p) = &opts.csv {
        let _ = write!(summary, "; {} rows in {}", rows.len(), p.display());
    }
    if let Some(p) = &opts.odm_geo {
        let _ = write!(summary, "; {} rows in {}", rows.len(), p.display());
    }
    if events.other > 0 {
        let _ = write!(
            summary,
            "; {} other events not used (another edge, input or receiver)",
            events.other
        );
    }
    println!("{summary}");
    Ok(())
}

fn check_options(opts: &Options) -> Result<()> {
    if opts.out.is_none() && !opts.in_place && opts.csv.is_none() && opts.odm_geo.is_none() {
        bail!("nothing to write: give --out DIR (tagged copies), --in-place, --csv FILE or --odm-geo FILE");
    }
    match opts.match_by {
        MatchBy::Count => {
            if opts.time_offset.is_some() || opts.tolerance.is_some() {
                bail!("--time-offset and --tolerance are for --match time");
            }
        }
        MatchBy::Time => {
            if opts.first_count.is_some() {
                bail!("--first-count is for --match count");
            }
            if let Some(t) = opts.tolerance
                && !(t.is_finite() && t > 0.0 && t <= 3600.0)
            {
                bail!("--tolerance {t}: expected seconds above 0, at most 3600");
            }
            if let Some(o) = opts.time_offset
                && !(o.is_finite() && o.abs() <= 1e8)
            {
                bail!("--time-offset {o}: expected seconds, at most 1e8 either way");
            }
        }
    }
    if !opts.images.is_dir() {
        bail!("--images {}: not a folder", opts.images.display());
    }
    Ok(())
}

/// "1 image", "2 images".
fn plural(n: usize, what: &str) -> String {
    if n == 1 {
        format!("1 {what}")
    } else {
        format!("{n} {what}s")
    }
}

/// A list of names for a message, the first few.
fn list(names: &[String]) -> String {
    let mut s = names.iter().take(LIST_AT_MOST).cloned().collect::<Vec<_>>().join(", ");
    if names.len() > LIST_AT_MOST {
        let _ = write!(s, ", … ({} more)", names.len() - LIST_AT_MOST);
    }
    s
}

/// The event poses of the recording for the edge, device and input asked for.
fn read_events(opts: &Options) -> Result<Events> {
    let path = &opts.events;
    let mut reader = SampleReader::open(path)?;
    let mut all: Vec<EventPose> = Vec::new();
    let mut raw_events = 0u64;
    while let Some(s) = reader.next_sample()? {
        match s.sample {
            AnySample::EventPose(p) => all.push(p),
            AnySample::Event(_) => raw_events += 1,
            _ => {}
        }
    }
    for c in reader.skipped_chunks() {
        eprintln!("geotag: warning: {}: {c}", path.display());
    }
    if all.is_empty() {
        let hint = if raw_events > 0 {
            format!(
                " (it has {raw_events} receiver event reports: `navsync replay {} --estimate --out OUT.mcap` poses them)",
                path.display()
            )
        } else {
            String::new()
        };
        bail!(
            "{}: no event poses (navsync/event/{{id}}/pose) in the recording{hint}",
            path.display()
        );
    }
    let edge = match opts.edge {
        Edge::Rising => EVENT_EDGE_RISING,
        Edge::Falling => EVENT_EDGE_FALLING,
    };
    let total = all.len();
    let mut devices: BTreeSet<String> = all.iter().map(|p| str_of(&p.device_id).to_string()).collect();
    if let Some(d) = &opts.device {
        if !devices.contains(d) {
            bail!(
                "{}: no events of receiver {d} (there are events of {})",
                path.display(),
                devices.iter().cloned().collect::<Vec<_>>().join(", ")
            );
        }
        devices = BTreeSet::from([d.clone()]);
    }
    if devices.len() > 1 {
        bail!(
            "{}: events of several receivers ({}): choose one with --device ID",
            path.display(),
            devices.iter().cloned().collect::<Vec<_>>().join(", ")
        );
    }
    let device = devices.into_iter().next().unwrap_or_default();
    all.retain(|p| str_of(&p.device_id) == device);
    let mut channels: BTreeSet<u8> = all.iter().map(|p| p.channel).collect();
    if let Some(c) = opts.channel {
        if !channels.contains(&c) {
            bail!(
                "{}: no events of receiver {device} on input {c} (there are on {:?})",
                path.display(),
                channels
            );
        }
        channels = BTreeSet::from([c]);
    }
    if channels.len() > 1 {
        bail!(
            "{}: receiver {device} marked events on several inputs {:?}: choose one with --channel N",
            path.display(),
            channels
        );
    }
    let channel = channels.into_iter().next().unwrap_or(0);
    all.retain(|p| p.channel == channel);
    all.retain(|p| p.edge == edge);
    if all.is_empty() {
        bail!(
            "{}: no {} edges of receiver {device} on input {channel} (--edge chooses the other)",
            path.display(),
            match opts.edge {
                Edge::Rising => "rising",
                Edge::Falling => "falling",
            }
        );
    }
    let (poses, counter) = order_and_unwrap(all).map_err(|e| anyhow!("{}: {e}", path.display()))?;
    Ok(Events {
        other: total - poses.len(),
        poses,
        counter,
        device,
    })
}

/// The events in time order (GPS time, else host time), exact repeats dropped, and their
/// 16-bit counters unwrapped into a strictly increasing sequence.
fn order_and_unwrap(mut all: Vec<EventPose>) -> Result<(Vec<EventPose>, Vec<i64>), String> {
    all.sort_by_key(|p| (p.gps_ns, p.host_ns, p.count));
    all.dedup_by(|b, a| a.gps_ns == b.gps_ns && a.count == b.count && a.host_ns == b.host_ns);
    let mut counter = Vec::with_capacity(all.len());
    for (i, p) in all.iter().enumerate() {
        let u = match i {
            0 => i64::from(p.count),
            _ => {
                let prev = &all[i - 1];
                let step = i64::from(p.count.wrapping_sub(prev.count));
                if step == 0 {
                    return Err(format!(
                        "two events with the same counter {} ({} and {}): the counter does not say which exposure is which",
                        p.count,
                        utc_text(prev.utc_ns),
                        utc_text(p.utc_ns)
                    ));
                }
                counter[i - 1] + step
            }
        };
        counter.push(u);
    }
    Ok((all, counter))
}

/// The JPEG files of `dir` (`.jpg`/`.jpeg`, any case; not hidden), in file-name order.
fn list_images(dir: &Path) -> Result<Vec<Image>> {
    let mut images = Vec::new();
    let mut others = Vec::new();
    for entry in std::fs::read_dir(dir).with_context(|| format!("reading the folder {}", dir.display()))? {
        let entry = entry.with_context(|| format!("reading the folder {}", dir.display()))?;
        let path = entry.path();
        let Some(name) = entry.file_name().to_str().map(str::to_string) else {
            bail!("{}: a file name that is not UTF-8", path.display());
        };
        if name.starts_with('.') || !path.is_file() {
            continue;
        }
        let ext = Path::new(&name)
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        if matches!(ext.as_deref(), Some("jpg" | "jpeg")) {
            images.push(Image {
                path,
                name,
                taken_utc_ns: None,
            });
        } else {
            others.push(name);
        }
    }
    if !others.is_empty() {
        others.sort();
        eprintln!(
            "geotag: {} in {} not *.jpg/*.jpeg, left alone: {}",
            plural(others.len(), "file"),
            dir.display(),
            list(&others)
        );
    }
    images.sort_by(|a, b| a.name.cmp(&b.name));
    Ok(images)
}

/// What pass 1 learns of an image.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct JpegInfo {
    /// DateTimeOriginal (+ SubSecTimeOriginal, − OffsetTimeOriginal) as UTC ns (the camera's
    /// clock taken as UTC when it has no offset tag).
    taken_utc_ns: Option<i64>,
}

/// Checks that `bytes` are a JPEG whose Exif (if any) reads, and finds its capture time.
fn inspect_jpeg(bytes: Vec<u8>) -> Result<JpegInfo> {
    let jpeg = Jpeg::from_bytes(Bytes::from(bytes)).map_err(|e| anyhow!("not a JPEG file ({e})"))?;
    let Some(raw) = jpeg.exif() else {
        return Ok(JpegInfo { taken_utc_ns: None });
    };
    let exif = exif::Reader::new()
        .read_raw(raw.to_vec())
        .map_err(|e| anyhow!("its Exif cannot be read ({e})"))?;
    Ok(JpegInfo {
        taken_utc_ns: capture_time(&exif),
    })
}

/// DateTimeOriginal with its sub-seconds and offset, UTC ns.
fn capture_time(exif: &exif::Exif) -> Option<i64> {
    let ascii = |tag: Tag| match exif.get_field(tag, In::PRIMARY).map(|f| &f.value) {
        Some(Value::Ascii(v)) => v.first().cloned(),
        _ => None,
    };
    let mut dt = exif::DateTime::from_ascii(&ascii(Tag::DateTimeOriginal)?).ok()?;
    if let Some(s) = ascii(Tag::SubSecTimeOriginal) {
        let _ = dt.parse_subsec(&s);
    }
    if let Some(o) = ascii(Tag::OffsetTimeOriginal) {
        let _ = dt.parse_offset(&o);
    }
    if !(1..=12).contains(&dt.month) || !(1..=31).contains(&dt.day) || dt.hour > 23 || dt.minute > 59 || dt.second > 60
    {
        return None;
    }
    let days = days_from_civil(i64::from(dt.year), u32::from(dt.month), u32::from(dt.day));
    let s = days * 86_400 + i64::from(dt.hour) * 3600 + i64::from(dt.minute) * 60 + i64::from(dt.second)
        - i64::from(dt.offset.unwrap_or(0)) * 60;
    Some(s * 1_000_000_000 + i64::from(dt.nanosecond.unwrap_or(0)))
}

/// Which event each image gets, and why not.
#[derive(Debug, Clone, PartialEq)]
struct Pairing {
    /// Per image, the index of its event.
    event_of: Vec<Option<usize>>,
    /// Per image without an event, why.
    why_none: Vec<String>,
    /// When the numbers do not agree: what, with the numbers.
    mismatch: Option<String>,
}

/// Image k ↔ the event whose counter is the first image's counter + k.
fn pair_by_count(n_images: usize, ev: &Events, first_count: Option<u16>) -> Result<Pairing> {
    let c0 = ev.counter[0];
    let u0 = match first_count {
        None => c0,
        // The counter nearest the first event's with these low 16 bits.
        Some(c) => c0 + i64::from(c.wrapping_sub(ev.poses[0].count) as i16),
    };
    let by_counter: BTreeMap<i64, usize> = ev.counter.iter().enumerate().map(|(i, &u)| (u, i)).collect();
    let Some((&u_last, _)) = by_counter.range(u0..).next_back() else {
        bail!(
            "no event has counter {} or later (the events' counters run from {} to {})",
            first_count.unwrap_or(ev.poses[0].count),
            ev.poses[0].count,
            ev.poses[ev.poses.len() - 1].count
        );
    };
    let slots = usize::try_from(u_last - u0 + 1).unwrap_or(usize::MAX);
    let before = by_counter.range(..u0).count();
    let low16 = |u: i64| (u.rem_euclid(65_536)) as u16;
    let present = by_counter.range(u0..).count();
    let missing = slots - present;
    let mut event_of = Vec::with_capacity(n_images);
    let mut why_none = Vec::with_capacity(n_images);
    for k in 0..n_images {
        let u = u0 + k as i64;
        match by_counter.get(&u) {
            Some(&e) => {
                event_of.push(Some(e));
                why_none.push(String::new());
            }
            None if u <= u_last => {
                event_of.push(None);
                why_none.push(format!("no event with counter {} in the recording", low16(u)));
            }
            None => {
                event_of.push(None);
                why_none.push(format!("beyond the last event (counter {})", low16(u_last)));
            }
        }
    }
    let mismatch = (n_images != slots).then(|| {
        let mut s = format!(
            "{n_images} images, but the events' counter runs from {}{} to {}: {slots} exposures",
            low16(u0),
            if first_count.is_some() { " (--first-count)" } else { "" },
            low16(u_last),
        );
        if missing > 0 {
            let _ = write!(s, " ({missing} of them not in the recording)");
        }
        if n_images < slots {
            let _ = write!(s, "; {} past the last image", plural(slots - n_images, "event"));
        } else {
            let _ = write!(s, "; {} past the last event", plural(n_images - slots, "image"));
        }
        s
    });
    if before > 0 {
        eprintln!(
            "geotag: {before} events before counter {} (the first image) are not used",
            low16(u0)
        );
    }
    Ok(Pairing {
        event_of,
        why_none,
        mismatch,
    })
}

/// Each image ↔ the event nearest its capture time, within `tolerance_ns`; an event within the
/// tolerance of two images, or two events within that of one image, is an error.
fn pair_by_time(images: &[Image], ev: &Events, tolerance_ns: i64) -> Result<Pairing> {
    let mut times: Vec<(i64, usize)> = ev
        .poses
        .iter()
        .enumerate()
        .filter(|(_, p)| p.utc_ns != i64::MIN)
        .map(|(i, p)| (p.utc_ns, i))
        .collect();
    times.sort_unstable();
    let mut event_of = Vec::with_capacity(images.len());
    let mut why_none = Vec::with_capacity(images.len());
    let mut taken: BTreeMap<usize, &str> = BTreeMap::new();
    let mut unpaired: Vec<String> = Vec::new();
    for img in images {
        let t = img.taken_utc_ns.unwrap_or(i64::MIN);
        let at = times.partition_point(|(u, _)| *u < t);
        let mut near: Vec<(i64, usize)> = times[at.saturating_sub(2)..(at + 2).min(times.len())]
            .iter()
            .map(|&(u, i)| ((u - t).abs(), i))
            .filter(|(d, _)| *d <= tolerance_ns)
            .collect();
        near.sort_unstable();
        match near.as_slice() {
            [] => {
                event_of.push(None);
                why_none.push(format!(
                    "no event within the tolerance of its capture time {}",
                    utc_text(t)
                ));
                unpaired.push(img.name.clone());
            }
            [(_, e), (_, e2), ..] => bail!(
                "{}: two events within the tolerance of its capture time {} ({} and {}): a tolerance under half the interval between exposures pairs them",
                img.name,
                utc_text(t),
                utc_text(ev.poses[*e].utc_ns),
                utc_text(ev.poses[*e2].utc_ns)
            ),
            [(_, e)] => {
                if let Some(other) = taken.insert(*e, &img.name) {
                    bail!(
                        "{} and {} both pair with the event at {}: the images' times are closer than the tolerance",
                        other,
                        img.name,
                        utc_text(ev.poses[*e].utc_ns)
                    );
                }
                event_of.push(Some(*e));
                why_none.push(String::new());
            }
        }
    }
    let mismatch = (!unpaired.is_empty()).then(|| {
        format!(
            "{} images, {} events: {} images have no event within the tolerance ({})",
            images.len(),
            ev.poses.len(),
            unpaired.len(),
            list(&unpaired)
        )
    });
    Ok(Pairing {
        event_of,
        why_none,
        mismatch,
    })
}

/// An image's pose as it is written.
#[derive(Debug, Clone)]
struct Tagged {
    lat_deg: f64,
    lon_deg: f64,
    height_m: f64,
    /// Height above mean sea level (EGM96), m.
    msl_m: f64,
    rpy_deg: [f64; 3],
    /// √(σ_N² + σ_E²), m.
    horizontal_std_m: f64,
    vertical_std_m: f64,
    utc_ns: i64,
    count: u16,
    fields: Vec<Field>,
}

impl Tagged {
    /// The tags of an event's pose; `None` without a usable pose (source 0, NaN, off the globe,
    /// no UTC).
    fn of(p: &EventPose) -> Option<Self> {
        if p.source == 0
            || !(p.lat_deg.abs() <= 90.0 && p.lon_deg.abs() <= 180.0 && p.height_m.is_finite())
            || p.utc_ns == i64::MIN
        {
            return None;
        }
        let n = navsync_drivers::gnss::geoid::egm96_separation_m(p.lat_deg, p.lon_deg)?;
        let msl_m = p.height_m - n;
        let [sn, se, sd] = p.pos_std_ned_m;
        let vh = p.vel_ned_mps[0].hypot(p.vel_ned_mps[1]);
        let yaw_deg = p.rpy_rad[2].to_degrees();
        let horizontal_std_m = sn.hypot(se);
        Some(Self {
            lat_deg: p.lat_deg,
            lon_deg: p.lon_deg,
            height_m: p.height_m,
            msl_m,
            rpy_deg: p.rpy_rad.map(f64::to_degrees),
            horizontal_std_m,
            vertical_std_m: sd,
            utc_ns: p.utc_ns,
            count: p.count,
            fields: gps_fields(p.lat_deg, p.lon_deg, msl_m, p.utc_ns, yaw_deg, vh, horizontal_std_m),
        })
    }
}

/// A field of the primary image (its IFD0 and the IFDs hung from it: Exif, GPS).
fn primary(tag: Tag, value: Value) -> Field {
    Field {
        tag,
        ifd_num: In::PRIMARY,
        value,
    }
}

fn ascii(s: &str) -> Value {
    Value::Ascii(vec![s.as_bytes().to_vec()])
}

/// `x` ≥ 0 as a rational with denominator `denom` (rounded), `None` when it does not fit.
fn rational(x: f64, denom: u32) -> Option<Rational> {
    let num = (x * f64::from(denom)).round();
    (x.is_finite() && (0.0..=f64::from(u32::MAX)).contains(&num)).then_some(Rational { num: num as u32, denom })
}

/// |deg| as degrees, minutes and seconds (seconds to 1e-6″, carried when they round up).
fn dms(deg: f64) -> Vec<Rational> {
    let total = (deg.abs() * 3_600e6).round() as u64; // µ-arcseconds; ≤ 6.5e11
    let (d, rest) = (total / 3_600_000_000, total % 3_600_000_000);
    let (m, s) = (rest / 60_000_000, rest % 60_000_000);
    vec![
        Rational {
            num: d as u32,
            denom: 1,
        },
        Rational {
            num: m as u32,
            denom: 1,
        },
        Rational {
            num: s as u32,
            denom: 1_000_000,
        },
    ]
}

/// The GPS IFD's fields of a pose (see the module doc).
fn gps_fields(
    lat_deg: f64,
    lon_deg: f64,
    msl_m: f64,
    utc_ns: i64,
    yaw_deg: f64,
    speed_mps: f64,
    horizontal_std_m: f64,
) -> Vec<Field> {
    let c: Civil = civil_from_utc_ns(utc_ns);
    let mut f = vec![
        primary(Tag::GPSVersionID, Value::Byte(vec![2, 3, 0, 0])),
        primary(Tag::GPSLatitudeRef, ascii(if lat_deg < 0.0 { "S" } else { "N" })),
        primary(Tag::GPSLatitude, Value::Rational(dms(lat_deg))),
        primary(Tag::GPSLongitudeRef, ascii(if lon_deg < 0.0 { "W" } else { "E" })),
        primary(Tag::GPSLongitude, Value::Rational(dms(lon_deg))),
        primary(
            Tag::GPSTimeStamp,
            Value::Rational(vec![
                Rational { num: c.hour, denom: 1 },
                Rational {
                    num: c.minute,
                    denom: 1,
                },
                Rational {
                    num: c.second * 1_000_000 + c.nanos / 1000,
                    denom: 1_000_000,
                },
            ]),
        ),
        primary(
            Tag::GPSDateStamp,
            ascii(&format!("{:04}:{:02}:{:02}", c.year, c.month, c.day)),
        ),
        primary(Tag::GPSMapDatum, ascii("WGS-84")),
    ];
    if let Some(alt) = rational(msl_m.abs(), 1000) {
        f.push(primary(Tag::GPSAltitudeRef, Value::Byte(vec![u8::from(msl_m < 0.0)])));
        f.push(primary(Tag::GPSAltitude, Value::Rational(vec![alt])));
    }
    if yaw_deg.is_finite() {
        let mut d = yaw_deg.rem_euclid(360.0);
        if (d * 1e4).round() >= 360e4 {
            d = 0.0;
        }
        if let Some(r) = rational(d, 10_000) {
            f.push(primary(Tag::GPSImgDirectionRef, ascii("T")));
            f.push(primary(Tag::GPSImgDirection, Value::Rational(vec![r])));
        }
    }
    if let Some(r) = rational(speed_mps * 3.6, 1000) {
        f.push(primary(Tag::GPSSpeedRef, ascii("K")));
        f.push(primary(Tag::GPSSpeed, Value::Rational(vec![r])));
    }
    if let Some(r) = rational(horizontal_std_m, 1000) {
        f.push(primary(Tag::GPSHPositioningError, Value::Rational(vec![r])));
    }
    f
}

/// `jpeg` with its Exif's GPS fields replaced by `gps_fields`; every other field and segment
/// kept. An error when the Exif cannot be read or does not fit its segment.
fn tag_jpeg(jpeg: Vec<u8>, gps_fields: &[Field]) -> Result<Vec<u8>> {
    let mut jpeg = Jpeg::from_bytes(Bytes::from(jpeg)).map_err(|e| anyhow!("not a JPEG file ({e})"))?;
    let old = match jpeg.exif() {
        Some(raw) => Some(
            exif::Reader::new()
                .read_raw(raw.to_vec())
                .map_err(|e| anyhow!("its Exif cannot be read ({e})"))?,
        ),
        None => None,
    };
    let mut writer = Writer::new();
    let mut kept: Vec<&Field> = Vec::new();
    let mut thumbnail: Option<&[u8]> = None;
    if let Some(old) = &old {
        kept.extend(
            old.fields()
                .filter(|f| f.tag.context() != exif::Context::Gps && !matches!(f.value, Value::Unknown(..))),
        );
        let at = |t: Tag| old.get_field(t, In::THUMBNAIL).and_then(|f| f.value.get_uint(0));
        if let (Some(off), Some(len)) = (at(Tag::JPEGInterchangeFormat), at(Tag::JPEGInterchangeFormatLength)) {
            thumbnail = old.buf().get(off as usize..(off as usize).saturating_add(len as usize));
        }
        // A thumbnail whose data is not carried over (uncompressed strips, or an offset past
        // the Exif) goes with its IFD, which would point nowhere.
        let strips = old.get_field(Tag::StripOffsets, In::THUMBNAIL).is_some();
        if strips || (thumbnail.is_none() && old.get_field(Tag::JPEGInterchangeFormat, In::THUMBNAIL).is_some()) {
            kept.retain(|f| f.ifd_num != In::THUMBNAIL);
            thumbnail = None;
        }
    }
    // A new Exif gets the fields the standard requires of a JPEG's IFD0, as exiftool writes
    // them: 72 dpi (what JFIF's default aspect gives no better value for), centred chroma.
    let required = [
        primary(Tag::XResolution, Value::Rational(vec![Rational { num: 72, denom: 1 }])),
        primary(Tag::YResolution, Value::Rational(vec![Rational { num: 72, denom: 1 }])),
        primary(Tag::ResolutionUnit, Value::Short(vec![2])),
        primary(Tag::YCbCrPositioning, Value::Short(vec![1])),
    ];
    if old.is_none() {
        kept.extend(required.iter());
    }
    for f in &kept {
        writer.push_field(f);
    }
    for f in gps_fields {
        writer.push_field(f);
    }
    if let Some(t) = thumbnail {
        writer.set_jpeg(t, In::THUMBNAIL);
    }
    let mut buf = std::io::Cursor::new(Vec::new());
    writer
        .write(&mut buf, old.as_ref().is_some_and(exif::Exif::little_endian))
        .map_err(|e| anyhow!("writing its Exif ({e})"))?;
    let exif_len = buf.get_ref().len();
    jpeg.set_exif(Some(Bytes::from(buf.into_inner())));
    if jpeg.exif().is_none() {
        bail!("its Exif with the GPS tags ({exif_len} bytes) does not fit one JPEG segment (64 KiB)");
    }
    Ok(jpeg.encoder().bytes().to_vec())
}

/// ISO 8601 UTC with microseconds.
fn utc_text(utc_ns: i64) -> String {
    if utc_ns == i64::MIN {
        return "unknown time".into();
    }
    let c = civil_from_utc_ns(utc_ns);
    format!(
        "{:04}-{:02}-{:02}T{:02}:{:02}:{:02}.{:06}Z",
        c.year,
        c.month,
        c.day,
        c.hour,
        c.minute,
        c.second,
        c.nanos / 1000
    )
}

/// A CSV field, quoted when it must be (RFC 4180).
fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

/// The generic CSV: one header line, one row per tagged image.
fn csv_text(rows: &[(&str, &Tagged)]) -> String {
    let mut s = String::from(
        "image,latitude_deg,longitude_deg,height_ellipsoid_m,altitude_msl_m,roll_deg,pitch_deg,yaw_deg,horizontal_std_m,vertical_std_m,utc,event_count\n",
    );
    for (name, t) in rows {
        let _ = writeln!(
            s,
            "{},{:.9},{:.9},{:.3},{:.3},{:.4},{:.4},{:.4},{:.3},{:.3},{},{}",
            csv_field(name),
            t.lat_deg,
            t.lon_deg,
            t.height_m,
            t.msl_m,
            t.rpy_deg[0],
            t.rpy_deg[1],
            t.rpy_deg[2].rem_euclid(360.0),
            t.horizontal_std_m,
            t.vertical_std_m,
            utc_text(t.utc_ns),
            t.count
        );
    }
    s
}

/// OpenDroneMap's image geolocation file: `EPSG:4326`, then per image `name lon lat alt yaw
/// pitch roll horizontal_accuracy vertical_accuracy` (altitude above mean sea level, as in the
/// images' Exif).
fn odm_geo_text(rows: &[(&str, &Tagged)]) -> String {
    let mut s = String::from("EPSG:4326\n");
    for (name, t) in rows {
        let _ = writeln!(
            s,
            "{} {:.9} {:.9} {:.3} {:.4} {:.4} {:.4} {:.3} {:.3}",
            name,
            t.lon_deg,
            t.lat_deg,
            t.msl_m,
            t.rpy_deg[2].rem_euclid(360.0),
            t.rpy_deg[1],
            t.rpy_deg[0],
            t.horizontal_std_m,
            t.vertical_std_m
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A valid 8×8 grey baseline JPEG (one block: DC 0, end of block).
    fn tiny_jpeg() -> Vec<u8> {
        let mut j = vec![0xFF, 0xD8];
        j.extend([0xFF, 0xDB, 0x00, 0x43, 0x00]);
        j.extend([1u8; 64]);
        j.extend([
            0xFF, 0xC0, 0x00, 0x0B, 0x08, 0x00, 0x08, 0x00, 0x08, 0x01, 0x01, 0x11, 0x00,
        ]);
        for class in [0x00u8, 0x10] {
            j.extend([0xFF, 0xC4, 0x00, 0x14, class, 0x01]);
            j.extend([0u8; 15]);
            j.push(0x00);
        }
        j.extend([
            0xFF, 0xDA, 0x00, 0x08, 0x01, 0x01, 0x00, 0x00, 0x3F, 0x00, 0x3F, 0xFF, 0xD9,
        ]);
        j
    }

    fn pose(count: u16, utc_s: f64, source: u8) -> EventPose {
        let mut p = <EventPose as navsync_shared::reflect::Reflect>::zeroed();
        p.count = count;
        p.utc_ns = (utc_s * 1e9) as i64;
        p.gps_ns = p.utc_ns;
        p.source = source;
        p.lat_deg = -33.5;
        p.lon_deg = -70.25;
        p.height_m = 500.0;
        p.rpy_rad = [0.1, -0.2, -0.5];
        p.pos_std_ned_m = [0.3, 0.4, 0.9];
        p
    }

    fn events(counts: &[u16]) -> Events {
        let all = counts
            .iter()
            .enumerate()
            .map(|(i, &c)| pose(c, 1.7e9 + i as f64, 2))
            .collect();
        let (poses, counter) = order_and_unwrap(all).unwrap();
        Events {
            poses,
            counter,
            device: "0".into(),
            other: 0,
        }
    }

    #[test]
    fn degrees_minutes_seconds_carry() {
        let r = dms(-33.999_999_999_99);
        assert_eq!((r[0].num, r[1].num, r[2].num), (34, 0, 0));
        let r = dms(12.5);
        assert_eq!((r[0].num, r[1].num, r[2].num, r[2].denom), (12, 30, 0, 1_000_000));
        let back = |r: &[Rational]| r[0].to_f64() + r[1].to_f64() / 60.0 + r[2].to_f64() / 3600.0;
        for x in [0.0, 47.123_456_789, 179.999_999, 89.000_000_3] {
            assert!((back(&dms(x)) - x).abs() < 1e-9 / 3.6, "{x}");
        }
    }

    #[test]
    fn counters_unwrap_and_gaps_leave_images_untagged() {
        let ev = events(&[65534, 65535, 0, 2]);
        assert_eq!(ev.counter, vec![65534, 65535, 65536, 65538]);
        let p = pair_by_count(5, &ev, None).unwrap();
        assert_eq!(p.event_of, vec![Some(0), Some(1), Some(2), None, Some(3)]);
        assert!(p.why_none[3].contains("counter 1"), "{}", p.why_none[3]);
        assert!(p.mismatch.is_none());
        // One image too many, one too few: the numbers in the message.
        let m = pair_by_count(6, &ev, None).unwrap().mismatch.unwrap();
        assert!(
            m.contains("6 images") && m.contains("5 exposures") && m.contains("1 of them not in"),
            "{m}"
        );
        let m = pair_by_count(3, &ev, None).unwrap().mismatch.unwrap();
        assert!(m.contains("2 events past the last image"), "{m}");
        // A first counter before the recording's first event: the images before it untagged.
        let p = pair_by_count(7, &ev, Some(65532)).unwrap();
        assert_eq!(p.event_of[..3], [None, None, Some(0)]);
        assert!(p.mismatch.is_none(), "{:?}", p.mismatch);
    }

    #[test]
    fn the_same_counter_twice_is_an_error() {
        let all = vec![pose(3, 1.7e9, 2), pose(3, 1.7e9 + 1.0, 2)];
        let e = order_and_unwrap(all).unwrap_err();
        assert!(e.contains("same counter 3"), "{e}");
    }

    #[test]
    fn time_pairing_is_nearest_within_the_tolerance_and_never_ambiguous() {
        let ev = events(&[1, 2, 3]);
        let img = |name: &str, t: f64| Image {
            path: PathBuf::from(name),
            name: name.into(),
            taken_utc_ns: Some((t * 1e9) as i64),
        };
        let imgs = [
            img("a.jpg", 1.7e9 + 0.1),
            img("b.jpg", 1.7e9 + 2.05),
            img("c.jpg", 1.7e9 + 7.0),
        ];
        let p = pair_by_time(&imgs, &ev, 200_000_000).unwrap();
        assert_eq!(p.event_of, vec![Some(0), Some(2), None]);
        assert!(p.mismatch.unwrap().contains("c.jpg"));
        let e = pair_by_time(&imgs[..1], &ev, 2_000_000_000).unwrap_err();
        assert!(e.to_string().contains("two events within the tolerance"), "{e}");
        let two = [img("a.jpg", 1.7e9 + 0.1), img("b.jpg", 1.7e9 + 0.2)];
        let e = pair_by_time(&two, &ev, 300_000_000).unwrap_err();
        assert!(e.to_string().contains("a.jpg and b.jpg"), "{e}");
    }

    #[test]
    fn tags_read_back_with_the_exif_reader() {
        let t = Tagged::of(&pose(7, 1_767_225_600.25 + 1e-6, 2)).unwrap();
        let out = tag_jpeg(tiny_jpeg(), &t.fields).unwrap();
        let raw = Jpeg::from_bytes(Bytes::from(out.clone())).unwrap().exif().unwrap();
        let exif = exif::Reader::new().read_raw(raw.to_vec()).unwrap();
        let get = |tag| exif.get_field(tag, In::PRIMARY).unwrap().display_value().to_string();
        assert_eq!(get(Tag::GPSLatitudeRef), "S");
        assert_eq!(get(Tag::GPSLongitudeRef), "W");
        assert_eq!(get(Tag::GPSDateStamp), "2026-01-01");
        assert!(
            get(Tag::GPSTimeStamp).starts_with("00:00:00.25"),
            "{}",
            get(Tag::GPSTimeStamp)
        );
        // Tagging again replaces the GPS fields, and the image data is the same bytes.
        let again = tag_jpeg(out, &t.fields).unwrap();
        let raw2 = Jpeg::from_bytes(Bytes::from(again.clone())).unwrap().exif().unwrap();
        assert_eq!(raw, raw2);
        assert!(again.ends_with(&tiny_jpeg()[tiny_jpeg().len() - 13..]));
        assert!(t.msl_m < t.height_m + 100.0 && t.msl_m > t.height_m - 100.0);
    }

    #[test]
    fn no_pose_no_tags_and_bad_bytes_are_errors() {
        assert!(Tagged::of(&pose(1, 1.7e9, 0)).is_none());
        let mut p = pose(1, 1.7e9, 2);
        p.lat_deg = f64::NAN;
        assert!(Tagged::of(&p).is_none());
        assert!(inspect_jpeg(b"not a jpeg".to_vec()).is_err());
        assert!(inspect_jpeg(tiny_jpeg()[..40].to_vec()).is_err());
        assert_eq!(inspect_jpeg(tiny_jpeg()).unwrap(), JpegInfo { taken_utc_ns: None });
    }

    #[test]
    fn csv_and_geo_txt_rows() {
        let t = Tagged::of(&pose(7, 1_767_225_600.25 + 1e-6, 2)).unwrap();
        let csv = csv_text(&[("a,b.jpg", &t)]);
        let row = csv.lines().nth(1).unwrap();
        assert!(
            row.starts_with("\"a,b.jpg\",-33.500000000,-70.250000000,500.000,"),
            "{row}"
        );
        assert!(row.ends_with(",2026-01-01T00:00:00.250000Z,7"), "{row}");
        let geo = odm_geo_text(&[("a.jpg", &t)]);
        let mut l = geo.lines();
        assert_eq!(l.next(), Some("EPSG:4326"));
        let cols: Vec<&str> = l.next().unwrap().split(' ').collect();
        assert_eq!(cols.len(), 9);
        assert_eq!(cols[1], "-70.250000000");
        assert_eq!(cols[2], "-33.500000000");
        assert_eq!(cols[4], format!("{:.4}", (-0.5f64).to_degrees().rem_euclid(360.0)));
        assert_eq!(cols[7], "0.500");
    }
}
