//! `navsync geotag`: a recording with known event poses (written with the recording library:
//! both hemispheres, a height below sea level, a yaw west of north, an event without a pose, the
//! falling edges beside the rising ones) and a folder of small JPEGs generated here (a valid
//! 8×8 baseline image each); the tags are read back with the real `exiftool` (Debian's
//! `libimage-exiftool-perl`, which `.ci/run` installs; without it the test says so and checks
//! the rest), the CSV and OpenDroneMap's geo.txt against the poses; then pairing by capture time
//! in place (Exif times written by exiftool, the camera's other tags kept), and the inputs that
//! must be clear errors.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use navsync_recording::output::Overwrite;
use navsync_recording::{RecordingOptions, SampleRecorder};
use navsync_shared::reflect::Reflect;
use navsync_shared::samples::{AnySample, EVENT_EDGE_FALLING, EVENT_EDGE_RISING, EventPose, GnssEvent};
use navsync_shared::services;
use navsync_tests::TestEnv;

/// 2026-03-01T10:00:00Z, ns since 1970.
const T0_NS: i64 = 1_772_359_200_000_000_000;
/// The first event's counter.
const FIRST_COUNT: u16 = 65_531;
const N: usize = 10;
/// The event (index) without a pose.
const UNPOSED: usize = 6;

/// A valid 8×8 grey baseline JPEG (JFIF, one block: DC 0, end of block) with a comment that
/// makes each frame's bytes its own.
fn tiny_jpeg(frame: usize) -> Vec<u8> {
    let mut j = vec![0xFF, 0xD8];
    j.extend([0xFF, 0xE0, 0x00, 0x10]);
    j.extend(b"JFIF\0");
    j.extend([0x01, 0x01, 0x00, 0x00, 0x01, 0x00, 0x01, 0x00, 0x00]);
    let comment = format!("frame {frame}");
    j.extend([0xFF, 0xFE, 0x00, (comment.len() + 2) as u8]);
    j.extend(comment.as_bytes());
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

fn device(id: &str) -> [u8; 8] {
    let mut d = [0u8; 8];
    d[..id.len()].copy_from_slice(id.as_bytes());
    d
}

/// The k-th exposure's rising edge with its pose (`source` 2), or without (`UNPOSED`).
fn pose(k: usize) -> EventPose {
    let mut p = EventPose::zeroed();
    p.utc_ns = T0_NS + k as i64 * 1_000_000_000 + 123_456_000;
    p.gps_ns = p.utc_ns - 315_964_800_000_000_000 + 18_000_000_000;
    p.host_ns = 5_000_000_000 + k as i64 * 1_000_000_000;
    p.report_host_ns = p.host_ns + 300_000_000;
    p.seq = k as u64 + 1;
    p.device_id = device("0");
    p.count = FIRST_COUNT.wrapping_add(k as u16);
    p.edge = EVENT_EDGE_RISING;
    let (lat, lon, h) = match k {
        3 => (-33.456_789_123, -70.654_321_987, 560.25), // Santiago: S, W
        5 => (31.5, 35.5, -390.0),                       // the Dead Sea: below sea level
        _ => (
            47.376_887_5 + k as f64 * 1e-4,
            8.541_694 + k as f64 * 2e-4,
            480.0 + k as f64,
        ),
    };
    p.lat_deg = lat;
    p.lon_deg = lon;
    p.height_m = h;
    p.vel_ned_mps = [3.0, 4.0, 0.1];
    let yaw_deg = -30.0 + 25.0 * k as f64; // −30° (330°) … 195°
    p.rpy_rad = [0.02 * k as f64, -0.01, yaw_deg.to_radians()];
    p.q_nb = [1.0, 0.0, 0.0, 0.0];
    p.pos_std_ned_m = [0.03, 0.04, 0.08];
    p.vel_std_ned_mps = [0.01; 3];
    p.att_std_rad = [0.001; 3];
    p.source = 2;
    if k == UNPOSED {
        p.source = 0;
        p.lat_deg = f64::NAN;
        p.lon_deg = f64::NAN;
        p.height_m = f64::NAN;
        p.rpy_rad = [f64::NAN; 3];
        p.host_ns = i64::MIN;
    }
    p
}

fn write_recording(path: &Path, samples: &[(String, AnySample)]) {
    let mut w = SampleRecorder::create(path, &Overwrite::default(), RecordingOptions::default()).unwrap();
    for (i, (service, s)) in samples.iter().enumerate() {
        w.write(service, s, T0_NS as u64 + i as u64, 1_000 + i as u64).unwrap();
    }
    w.close().unwrap();
}

/// The poses' recording: each exposure's rising edge, and its falling edge 5 ms later.
fn events_recording(path: &Path) {
    let mut samples = Vec::new();
    for k in 0..N {
        let rising = pose(k);
        let mut falling = rising;
        falling.edge = EVENT_EDGE_FALLING;
        falling.utc_ns += 5_000_000;
        falling.gps_ns += 5_000_000;
        falling.lat_deg += 1.0;
        samples.push((services::event_pose("0"), AnySample::EventPose(rising)));
        samples.push((services::event_pose("0"), AnySample::EventPose(falling)));
    }
    write_recording(path, &samples);
}

fn images_folder(dir: &Path, n: usize) -> Vec<PathBuf> {
    std::fs::create_dir_all(dir).unwrap();
    (0..n)
        .map(|k| {
            let p = dir.join(format!("IMG_{:04}.jpg", k + 1));
            std::fs::write(&p, tiny_jpeg(k)).unwrap();
            p
        })
        .collect()
}

fn geotag(env: &TestEnv, args: &[&str]) -> Output {
    let mut all = vec!["geotag"];
    all.extend_from_slice(args);
    env.command(&all).output().unwrap()
}

fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Why exiftool cannot be used, if it cannot.
fn exiftool_missing() -> Option<String> {
    match Command::new("exiftool").arg("-ver").output() {
        Ok(o) if o.status.success() => None,
        Ok(o) => Some(format!("`exiftool -ver` failed: {}", text(&o))),
        Err(e) => Some(format!(
            "exiftool is not installed ({e}; Debian: libimage-exiftool-perl, which .ci/run installs)"
        )),
    }
}

/// `exiftool -n -j -G` of `files`: one JSON object per file, numbers as numbers.
fn exiftool_json(files: &[PathBuf]) -> Vec<serde_json::Value> {
    let o = Command::new("exiftool")
        .args(["-n", "-j", "-G"])
        .args(files)
        .output()
        .unwrap();
    assert!(o.status.success(), "exiftool: {}", text(&o));
    serde_json::from_slice::<Vec<serde_json::Value>>(&o.stdout).unwrap()
}

fn num(tags: &serde_json::Value, key: &str) -> f64 {
    tags.get(key)
        .and_then(serde_json::Value::as_f64)
        .unwrap_or_else(|| panic!("no number {key} in {tags:#}"))
}

fn txt<'a>(tags: &'a serde_json::Value, key: &str) -> &'a str {
    tags.get(key)
        .and_then(serde_json::Value::as_str)
        .unwrap_or_else(|| panic!("no text {key} in {tags:#}"))
}

fn msl(p: &EventPose) -> f64 {
    p.height_m - navsync_drivers::gnss::geoid::egm96_separation_m(p.lat_deg, p.lon_deg).unwrap()
}

/// What exiftool reads back from an image tagged with the k-th pose equals the pose within
/// the rationals' steps (1e-6″, 1 mm, 1e-4°, 1 µs).
fn assert_tags_are_the_pose(tags: &serde_json::Value, k: usize) {
    let p = pose(k);
    let file = txt(tags, "SourceFile");
    let (lat, lon) = (num(tags, "Composite:GPSLatitude"), num(tags, "Composite:GPSLongitude"));
    assert!(
        (lat - p.lat_deg).abs() < 1e-9,
        "{file}: latitude {lat} vs {}",
        p.lat_deg
    );
    assert!(
        (lon - p.lon_deg).abs() < 1e-9,
        "{file}: longitude {lon} vs {}",
        p.lon_deg
    );
    assert_eq!(
        txt(tags, "EXIF:GPSLatitudeRef"),
        if p.lat_deg < 0.0 { "S" } else { "N" }
    );
    assert_eq!(
        txt(tags, "EXIF:GPSLongitudeRef"),
        if p.lon_deg < 0.0 { "W" } else { "E" }
    );
    let alt = num(tags, "Composite:GPSAltitude");
    assert!(
        (alt - msl(&p)).abs() <= 0.0005 + 1e-9,
        "{file}: altitude {alt} vs {}",
        msl(&p)
    );
    assert_eq!(num(tags, "EXIF:GPSAltitudeRef"), if msl(&p) < 0.0 { 1.0 } else { 0.0 });
    let yaw = p.rpy_rad[2].to_degrees().rem_euclid(360.0);
    let dir = num(tags, "EXIF:GPSImgDirection");
    assert!((dir - yaw).abs() <= 0.5e-4 + 1e-9, "{file}: direction {dir} vs {yaw}");
    assert_eq!(txt(tags, "EXIF:GPSImgDirectionRef"), "T");
    assert!((num(tags, "EXIF:GPSSpeed") - 18.0).abs() < 1e-9, "5 m/s = 18 km/h");
    assert_eq!(txt(tags, "EXIF:GPSSpeedRef"), "K");
    assert!((num(tags, "EXIF:GPSHPositioningError") - 0.05).abs() < 1e-9);
    assert_eq!(txt(tags, "EXIF:GPSMapDatum"), "WGS-84");
    assert_eq!(txt(tags, "EXIF:GPSDateStamp"), "2026:03:01");
    assert_eq!(
        txt(tags, "Composite:GPSDateTime"),
        format!("2026:03:01 10:00:{:02}.123456Z", k),
        "{file}"
    );
}

#[test]
fn geotag_writes_tags_exiftool_reads_back_as_the_poses() {
    let env = TestEnv::new("geotag");
    let rec = env.dir.join("events.mcap");
    events_recording(&rec);
    let imgs = env.dir.join("images");
    let files = images_folder(&imgs, N);
    std::fs::write(imgs.join("notes.txt"), "not an image").unwrap();
    let out = env.dir.join("tagged");
    let (csv, geo) = (env.dir.join("poses.csv"), env.dir.join("geo.txt"));
    let o = geotag(
        &env,
        &[
            "--events",
            s(&rec),
            "--images",
            s(&imgs),
            "--out",
            s(&out),
            "--csv",
            s(&csv),
            "--odm-geo",
            s(&geo),
        ],
    );
    let said = text(&o);
    println!("{said}");
    assert!(o.status.success(), "{said}");
    // The event without a pose, named with its image; the other file left alone.
    assert!(
        said.contains("IMG_0007.jpg: its event (counter 1, 2026-03-01T10:00:06.123456Z) has no pose"),
        "{said}"
    );
    assert!(said.contains("notes.txt"), "{said}");
    assert!(
        said.contains("tagged 9 into") && said.contains("1 copied untagged"),
        "{said}"
    );
    assert!(said.contains("10 other events not used"), "the falling edges: {said}");
    // The originals are untouched; the untagged image is copied as it was.
    for (k, f) in files.iter().enumerate() {
        assert_eq!(std::fs::read(f).unwrap(), tiny_jpeg(k), "{}", f.display());
    }
    let tagged: Vec<PathBuf> = (0..N).map(|k| out.join(format!("IMG_{:04}.jpg", k + 1))).collect();
    assert_eq!(std::fs::read(&tagged[UNPOSED]).unwrap(), tiny_jpeg(UNPOSED));
    // The image data is the original's: the tagged file ends with the same scan.
    let scan = &tiny_jpeg(0)[tiny_jpeg(0).len() - 13..];
    assert!(std::fs::read(&tagged[0]).unwrap().ends_with(scan));
    assert_eq!(std::fs::read_dir(&out).unwrap().count(), N, "no temporary files left");

    // The CSV and geo.txt: one row per posed image, the poses.
    let csv_text = std::fs::read_to_string(&csv).unwrap();
    let mut rows = csv_text.lines();
    assert_eq!(
        rows.next(),
        Some(
            "image,latitude_deg,longitude_deg,height_ellipsoid_m,altitude_msl_m,roll_deg,pitch_deg,yaw_deg,horizontal_std_m,vertical_std_m,utc,event_count"
        )
    );
    let rows: Vec<Vec<String>> = rows.map(|l| l.split(',').map(str::to_string).collect()).collect();
    assert_eq!(rows.len(), N - 1, "{csv_text}");
    let geo_text = std::fs::read_to_string(&geo).unwrap();
    let mut geo_lines = geo_text.lines();
    assert_eq!(geo_lines.next(), Some("EPSG:4326"));
    let geo_rows: Vec<Vec<String>> = geo_lines.map(|l| l.split(' ').map(str::to_string).collect()).collect();
    assert_eq!(geo_rows.len(), N - 1, "{geo_text}");
    let posed: Vec<usize> = (0..N).filter(|&k| k != UNPOSED).collect();
    for ((row, g), &k) in rows.iter().zip(&geo_rows).zip(&posed) {
        let p = pose(k);
        let f = |c: &str| c.parse::<f64>().unwrap();
        assert_eq!(row[0], format!("IMG_{:04}.jpg", k + 1));
        assert!((f(&row[1]) - p.lat_deg).abs() < 1e-9 && (f(&row[2]) - p.lon_deg).abs() < 1e-9);
        assert!((f(&row[3]) - p.height_m).abs() < 5e-4 && (f(&row[4]) - msl(&p)).abs() < 5e-4);
        assert!((f(&row[7]) - p.rpy_rad[2].to_degrees().rem_euclid(360.0)).abs() < 5e-5);
        assert_eq!((row[8].as_str(), row[9].as_str()), ("0.050", "0.080"));
        assert_eq!(row[10], format!("2026-03-01T10:00:{k:02}.123456Z"));
        assert_eq!(row[11], FIRST_COUNT.wrapping_add(k as u16).to_string());
        assert_eq!(g.len(), 9, "{g:?}");
        assert_eq!(g[0], row[0]);
        assert!(
            (f(&g[1]) - p.lon_deg).abs() < 1e-9 && (f(&g[2]) - p.lat_deg).abs() < 1e-9,
            "lon lat"
        );
        assert_eq!(
            (g[3].as_str(), g[7].as_str(), g[8].as_str()),
            (row[4].as_str(), "0.050", "0.080")
        );
    }

    match exiftool_missing() {
        Some(why) => println!("SKIPPED the exiftool read-back: {why}"),
        None => {
            let json = exiftool_json(&tagged);
            for (k, tags) in json.iter().enumerate() {
                if k == UNPOSED {
                    assert!(tags.get("EXIF:GPSLatitude").is_none(), "{tags:#}");
                    continue;
                }
                assert_tags_are_the_pose(tags, k);
                assert_eq!(num(tags, "File:ImageWidth"), 8.0);
                assert_eq!(
                    txt(tags, "File:Comment"),
                    format!("frame {k}"),
                    "the other segments are kept"
                );
            }
            assert_eq!(validate(&tagged[0]), Vec::<String>::new(), "exiftool -validate");
            let t = &json[3];
            println!(
                "exiftool read back IMG_0004.jpg: {} {} {} {} alt {} (ref {}) dir {} speed {} km/h herr {} m {}",
                num(t, "Composite:GPSLatitude"),
                txt(t, "EXIF:GPSLatitudeRef"),
                num(t, "Composite:GPSLongitude"),
                txt(t, "EXIF:GPSLongitudeRef"),
                num(t, "Composite:GPSAltitude"),
                num(t, "EXIF:GPSAltitudeRef"),
                num(t, "EXIF:GPSImgDirection"),
                num(t, "EXIF:GPSSpeed"),
                num(t, "EXIF:GPSHPositioningError"),
                txt(t, "Composite:GPSDateTime"),
            );
            println!(
                "exiftool read back IMG_0006.jpg: alt {} (ref {})",
                num(&json[5], "Composite:GPSAltitude"),
                num(&json[5], "EXIF:GPSAltitudeRef")
            );
        }
    }

    // Tagged copies exist now: only --force replaces them.
    let again = ["--events", s(&rec), "--images", s(&imgs), "--out", s(&out)];
    let o = geotag(&env, &again);
    assert!(
        !o.status.success() && text(&o).contains("--force replaces them"),
        "{}",
        text(&o)
    );
    let mut forced = again.to_vec();
    forced.push("--force");
    let o = geotag(&env, &forced);
    assert!(o.status.success(), "{}", text(&o));
    env.finish();
}

#[test]
fn geotag_by_capture_time_in_place_keeps_the_cameras_tags() {
    if let Some(why) = exiftool_missing() {
        println!("SKIPPED: this test writes the camera's capture times with exiftool: {why}");
        return;
    }
    let env = TestEnv::new("geotagtime");
    let rec = env.dir.join("events.mcap");
    events_recording(&rec);
    let imgs = env.dir.join("images");
    images_folder(&imgs, N);
    // The camera's clock runs on UTC+1 without an offset tag, 40 ms late; the file names run
    // against time, so file-name order would pair every image wrongly.
    let mut named = Vec::new();
    let thumb = env.dir.join("thumb.jpg");
    std::fs::write(&thumb, tiny_jpeg(99)).unwrap();
    for k in 0..N {
        let from = imgs.join(format!("IMG_{:04}.jpg", k + 1));
        let to = imgs.join(format!("shot_{:02}.jpg", N - k));
        std::fs::rename(&from, &to).unwrap();
        let o = Command::new("exiftool")
            .args([
                "-q",
                "-overwrite_original",
                &format!("-DateTimeOriginal=2026:03:01 11:00:{k:02}"),
                "-SubSecTimeOriginal=163",
                "-Make=TestCam",
                "-Model=Rig 1",
                &format!("-ThumbnailImage<={}", s(&thumb)),
            ])
            .arg(&to)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", text(&o));
        named.push(to);
    }
    // What exiftool's validation says of the camera's Exif (exiftool's own leaves out
    // ExifImageWidth/Height): geotag adds nothing to it.
    let before = validate(&named[0]);
    let o = geotag(
        &env,
        &[
            "--events",
            s(&rec),
            "--images",
            s(&imgs),
            "--in-place",
            "--match",
            "time",
            "--time-offset",
            "-3600",
            "--tolerance",
            "0.2",
        ],
    );
    let said = text(&o);
    println!("{said}");
    assert!(o.status.success(), "{said}");
    assert!(said.contains("tagged 9 in place"), "{said}");
    assert!(
        said.contains(&format!("shot_{:02}.jpg: its event", N - UNPOSED)),
        "{said}"
    );
    assert_eq!(std::fs::read_dir(&imgs).unwrap().count(), N, "no temporary files left");
    let json = exiftool_json(&named);
    assert_eq!(validate(&named[0]), before, "exiftool -validate finds nothing new");
    for (k, tags) in json.iter().enumerate() {
        // The camera's tags and its thumbnail are kept.
        assert_eq!(txt(tags, "EXIF:Make"), "TestCam", "{tags:#}");
        let t = Command::new("exiftool")
            .args(["-b", "-ThumbnailImage"])
            .arg(&named[k])
            .output()
            .unwrap();
        assert_eq!(t.stdout, tiny_jpeg(99), "{}: the thumbnail", named[k].display());
        assert_eq!(txt(tags, "EXIF:DateTimeOriginal"), format!("2026:03:01 11:00:{k:02}"));
        if k == UNPOSED {
            assert!(tags.get("EXIF:GPSLatitude").is_none(), "{tags:#}");
        } else {
            assert_tags_are_the_pose(tags, k);
        }
    }
    env.finish();
}

/// The warnings and errors of `exiftool -validate`.
fn validate(file: &Path) -> Vec<String> {
    let o = Command::new("exiftool")
        .args(["-validate", "-warning", "-error", "-a"])
        .arg(file)
        .output()
        .unwrap();
    String::from_utf8_lossy(&o.stdout)
        .lines()
        .filter(|l| l.starts_with("Warning") || l.starts_with("Error"))
        .map(str::to_string)
        .collect()
}

#[test]
fn geotag_refuses_what_would_mis_tag_and_says_why() {
    let env = TestEnv::new("geotagbad");
    let rec = env.dir.join("events.mcap");
    events_recording(&rec);
    let imgs = env.dir.join("images");
    images_folder(&imgs, N + 1);
    let out = env.dir.join("tagged");
    let base = |images: &Path| {
        vec![
            "--events".to_string(),
            s(&rec).into(),
            "--images".into(),
            s(images).into(),
        ]
    };
    let run = |args: Vec<String>| {
        let a: Vec<&str> = args.iter().map(String::as_str).collect();
        geotag(&env, &a)
    };
    let with = |mut v: Vec<String>, more: &[&str]| {
        v.extend(more.iter().map(|m| m.to_string()));
        v
    };

    // One image more than the events' counters: an error with the numbers, nothing written.
    let o = run(with(base(&imgs), &["--out", s(&out)]));
    let said = text(&o);
    assert!(!o.status.success(), "{said}");
    assert!(
        said.contains("11 images, but the events' counter runs from 65531 to 4: 10 exposures"),
        "{said}"
    );
    assert!(!out.exists(), "nothing written");
    // --partial tags what pairs and names the rest.
    let o = run(with(base(&imgs), &["--out", s(&out), "--partial"]));
    let said = text(&o);
    assert!(o.status.success(), "{said}");
    assert!(
        said.contains("IMG_0011.jpg: beyond the last event (counter 4)"),
        "{said}"
    );
    assert!(said.contains("tagged 9 into"), "{said}");
    // The first image's counter given: one image before the recording's first event.
    let o = run(with(
        base(&imgs),
        &["--csv", s(&env.dir.join("c.csv")), "--first-count", "65530"],
    ));
    let said = text(&o);
    assert!(o.status.success(), "{said}");
    assert!(said.contains("IMG_0001.jpg: no event with counter 65530"), "{said}");
    let first = std::fs::read_to_string(env.dir.join("c.csv")).unwrap();
    assert!(
        first.lines().nth(1).unwrap().starts_with("IMG_0002.jpg,47.3768875"),
        "{first}"
    );
    std::fs::remove_file(imgs.join("IMG_0011.jpg")).unwrap();

    // A file named .jpg that is not a JPEG: named.
    std::fs::write(imgs.join("IMG_0004.jpg"), b"GIF89a....").unwrap();
    let o = run(with(base(&imgs), &["--csv", s(&env.dir.join("x.csv"))]));
    let said = text(&o);
    assert!(!o.status.success(), "{said}");
    assert!(said.contains("IMG_0004.jpg: not a JPEG file"), "{said}");
    assert!(!said.contains("panicked"), "{said}");
    std::fs::write(imgs.join("IMG_0004.jpg"), tiny_jpeg(3)).unwrap();

    // The images' own folder as --out; nothing to write; a time option with count pairing.
    let o = run(with(base(&imgs), &["--out", s(&imgs)]));
    assert!(!o.status.success() && text(&o).contains("--in-place"), "{}", text(&o));
    let o = run(base(&imgs));
    assert!(
        !o.status.success() && text(&o).contains("nothing to write"),
        "{}",
        text(&o)
    );
    let o = run(with(base(&imgs), &["--in-place", "--tolerance", "1"]));
    assert!(!o.status.success() && text(&o).contains("--match time"), "{}", text(&o));
    // --match time on images without a capture time.
    let o = run(with(base(&imgs), &["--in-place", "--match", "time"]));
    let said = text(&o);
    assert!(
        !o.status.success() && said.contains("IMG_0001.jpg: no capture time"),
        "{said}"
    );

    // A recording without event poses (only the receiver's reports): says how to make them.
    let raw = env.dir.join("raw.mcap");
    let mut ev = GnssEvent::zeroed();
    ev.count = 1;
    write_recording(&raw, &[(services::gnss_event("0"), AnySample::Event(ev))]);
    let o = geotag(&env, &["--events", s(&raw), "--images", s(&imgs), "--in-place"]);
    let said = text(&o);
    assert!(!o.status.success(), "{said}");
    assert!(
        said.contains("no event poses") && said.contains("--estimate --out"),
        "{said}"
    );
    // Not a recording at all.
    let o = geotag(
        &env,
        &[
            "--events",
            s(&imgs.join("IMG_0001.jpg")),
            "--images",
            s(&imgs),
            "--in-place",
        ],
    );
    assert!(!o.status.success() && text(&o).contains("IMG_0001.jpg"), "{}", text(&o));
    // Events of two receivers: which one.
    let two = env.dir.join("two.mcap");
    let mut other = pose(0);
    other.device_id = device("cam2");
    write_recording(
        &two,
        &[
            (services::event_pose("0"), AnySample::EventPose(pose(0))),
            (services::event_pose("cam2"), AnySample::EventPose(other)),
        ],
    );
    let o = geotag(&env, &["--events", s(&two), "--images", s(&imgs), "--in-place"]);
    let said = text(&o);
    assert!(
        !o.status.success() && said.contains("0, cam2") && said.contains("--device"),
        "{said}"
    );
    // Nothing was changed by any of these.
    for k in 0..N {
        let f = imgs.join(format!("IMG_{:04}.jpg", k + 1));
        assert_eq!(std::fs::read(&f).unwrap(), tiny_jpeg(k), "{}", f.display());
    }
    env.finish();
}
