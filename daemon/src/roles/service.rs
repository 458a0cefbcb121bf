//! Running as a system service: the configuration file applied to each role's arguments
//! (flags given on the command line win), `navsync check-config`, `navsync install`, and the
//! logging setup for the journal.
//!
//! Each role reads its part of the file: `navsync gps --id ID` reads `[gps.ID]`,
//! `navsync imu --id ID` reads `[imu.ID]`, `navsync pps --id ID` reads `[pps.ID]`,
//! `navsync estimator` reads `[estimator]`, `[timing]`, the `mounting` of each of its IMUs and
//! the `lever_arm_m` of its first receiver, `navsync ntpshm` and `navsync record` read
//! `[outputs.*]`; every role reads `[logging]` and `[ipc]`.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use clap::ArgMatches;
use clap::parser::ValueSource;
use navsync_drivers::gps::driver::{Baud, GpsArgs};
use navsync_drivers::imu::axes::AxisMap;
use navsync_drivers::imu::{ImuArgs, ImuSource};
use navsync_drivers::pps::{PpsArgs, SourceSpec};
use navsync_shared::config::{BaudSetting, ConfigError, Loaded};
use navsync_shared::imu_spec::ImuPreset;

use navsync_estimator::settings::{ImuMounting, Settings};

/// Whether the flag `id` was given on the command line (or by an environment variable), as
/// opposed to taking its default.
fn given(m: Option<&ArgMatches>, id: &str) -> bool {
    m.and_then(|m| m.try_contains_id(id).ok().filter(|b| *b).and(m.value_source(id)))
        .is_some_and(|s| matches!(s, ValueSource::CommandLine | ValueSource::EnvVariable))
}

/// Loads `--config FILE`, else `/etc/navsync/navsync.toml` when it exists, else nothing; and
/// applies `[ipc].prefix` when `$NAVSYNC_IPC_PREFIX` is not set.
pub fn load(explicit: Option<&Path>) -> Result<Loaded> {
    let loaded = Loaded::load_or_default(explicit).map_err(anyhow::Error::new)?;
    if let Some(p) = &loaded.config.ipc.prefix
        && std::env::var_os(navsync_shared::services::PREFIX_ENV).is_none()
    {
        // SAFETY: called at the start of main, before any thread exists.
        unsafe { std::env::set_var(navsync_shared::services::PREFIX_ENV, p) };
    }
    Ok(loaded)
}

/// `navsync gps`: `--port`/`--baud` or `[gps.ID]`.
pub fn gps_args(cfg: &Loaded, m: Option<&ArgMatches>, port: Option<String>, baud: Baud, id: String) -> Result<GpsArgs> {
    let section = cfg.config.gps.get(&id);
    let port = match (port, section) {
        (Some(p), _) => p,
        (None, Some(s)) => s.port.clone(),
        (None, None) => bail!("no --port, and no [gps.{id}] in {}", shown(cfg)),
    };
    let baud = match section.and_then(|s| s.baud) {
        Some(b) if !given(m, "baud") => match b {
            BaudSetting::Fixed(b) => Baud::Fixed(b),
            BaudSetting::Auto => Baud::Auto,
        },
        _ => baud,
    };
    Ok(GpsArgs { port, baud, id })
}

/// `navsync pps`: `--source` or `[pps.ID].source`.
pub fn pps_args(cfg: &Loaded, source: Option<SourceSpec>, id: String) -> Result<PpsArgs> {
    let source = match (source, cfg.config.pps.get(&id)) {
        (Some(s), _) => s,
        (None, Some(p)) => pps_source(cfg, &id, &p.source)?,
        (None, None) => bail!("no --source, and no [pps.{id}] in {}", shown(cfg)),
    };
    Ok(PpsArgs { source, id })
}

fn pps_source(cfg: &Loaded, id: &str, s: &str) -> Result<SourceSpec, ConfigError> {
    s.parse::<SourceSpec>()
        .map_err(|e| cfg.error_at(&format!("pps.{id}.source"), e.to_string()))
}

fn imu_source(cfg: &Loaded, id: &str, s: &str) -> Result<ImuSource, ConfigError> {
    s.parse::<ImuSource>()
        .map_err(|e| cfg.error_at(&format!("imu.{id}.source"), e))
}

fn imu_axes(cfg: &Loaded, id: &str, s: &str) -> Result<AxisMap, ConfigError> {
    s.parse::<AxisMap>()
        .map_err(|e| cfg.error_at(&format!("imu.{id}.axes"), e))
}

/// `navsync imu`: flags, else `[imu.ID]`. `build` makes the arguments from the source and
/// the flags; the file then fills in what was not given on the command line.
pub fn imu_args(
    cfg: &Loaded,
    m: Option<&ArgMatches>,
    id: &str,
    source: Option<ImuSource>,
    build: impl FnOnce(ImuSource) -> ImuArgs,
) -> Result<ImuArgs> {
    let section = cfg.config.imu.get(id);
    let source = match (source, section) {
        (Some(s), _) => s,
        (None, Some(s)) => imu_source(cfg, id, &s.source)?,
        (None, None) => bail!("no --source, and no [imu.{id}] in {}", shown(cfg)),
    };
    let mut a = build(source);
    let Some(s) = section else { return Ok(a) };
    if !given(m, "rate") && s.rate_hz.is_some() {
        a.rate_hz = s.rate_hz;
    }
    if !given(m, "axes")
        && let Some(axes) = &s.axes
    {
        a.axes = imu_axes(cfg, id, axes)?;
    }
    if !given(m, "gyro_range_dps") && s.gyro_range_dps.is_some() {
        a.gyro_range_dps = s.gyro_range_dps;
    }
    if !given(m, "accel_range_g") && s.accel_range_g.is_some() {
        a.accel_range_g = s.accel_range_g;
    }
    if !given(m, "buffer_length")
        && let Some(b) = s.buffer_length
    {
        a.buffer_length = b;
    }
    if !given(m, "sysfs_root")
        && let Some(d) = &s.sysfs_root
    {
        a.sysfs_root = d.clone();
    }
    if !given(m, "dev_root")
        && let Some(d) = &s.dev_root
    {
        a.dev_root = d.clone();
    }
    Ok(a)
}

/// `navsync estimator`: flags, else `[estimator]`/`[timing]`; mountings and the antenna lever
/// arm always come from the file (there are no flags for them).
pub fn estimator_args(cfg: &Loaded, m: Option<&ArgMatches>, mut a: Settings) -> Result<Settings> {
    let c = &cfg.config;
    let e = &c.estimator;
    if !given(m, "gnss")
        && let Some(ids) = cfg.estimator_gnss()
    {
        a.gnss_ids = ids;
    }
    if !given(m, "pps")
        && let Some(ids) = cfg.estimator_pps()
    {
        a.pps_ids = ids;
    }
    if !given(m, "imus")
        && let Some(ids) = cfg.estimator_imus()
    {
        a.imu_ids = ids;
    }
    if !given(m, "software_sync")
        && let Some(s) = c.timing.software_sync
    {
        a.software_sync = s;
    }
    if !given(m, "imu_model")
        && let Some(model) = &e.imu_model
    {
        a.imu_model = model
            .parse::<ImuPreset>()
            .map_err(|msg| cfg.error_at("estimator.imu_model", msg))?;
    }
    if !given(m, "no_delay_state")
        && let Some(d) = e.estimate_delay
    {
        a.estimate_delay = d;
    }
    if !given(m, "gnss_vel_std")
        && let Some(v) = e.gnss_vel_std_mps
    {
        a.gnss_vel_std_mps = v;
    }
    if let Some(o) = e.estimate_imu_offsets {
        a.estimate_imu_offsets = o;
    }
    a.imu_mountings = c
        .imu
        .iter()
        .map(|(id, i)| {
            (
                id.clone(),
                ImuMounting {
                    c_b_s: i.mounting.c_b_s(),
                    lever_b_m: i.mounting.lever_arm_m,
                },
            )
        })
        .collect();
    if let Some(g) = a.gnss_ids.first().and_then(|id| c.gps.get(id)) {
        a.gnss_lever_arm_m = g.lever_arm_m;
    }
    let t = &c.timing;
    if t.oscillator_white_fm_adev_1s.is_some() || t.oscillator_random_walk_fm_adev_1s.is_some() {
        a.oscillator_adev_1s = Some((
            t.oscillator_white_fm_adev_1s.unwrap_or(1e-10),
            t.oscillator_random_walk_fm_adev_1s.unwrap_or(1e-10),
        ));
    }
    Ok(a)
}

/// `navsync ntpshm`: `--unit` or `[outputs.ntpshm].unit`.
pub fn ntpshm_unit(cfg: &Loaded, m: Option<&ArgMatches>, unit: u32) -> u32 {
    match &cfg.config.outputs.ntpshm {
        Some(n) if !given(m, "unit") => n.unit,
        _ => unit,
    }
}

/// `navsync record`: the output file and services from the arguments or `[outputs.record]`.
pub fn record_target(cfg: &Loaded, out: Option<PathBuf>, services: Vec<String>) -> Result<(PathBuf, Vec<String>)> {
    let r = cfg.config.outputs.record.as_ref();
    let out = match (out, r) {
        (Some(o), _) => o,
        (None, Some(r)) => r.path.clone(),
        (None, None) => bail!("no output file, and no [outputs.record] in {}", shown(cfg)),
    };
    let services = if services.is_empty() {
        r.map(|r| r.services.clone()).unwrap_or_default()
    } else {
        services
    };
    Ok((out, services))
}

fn shown(cfg: &Loaded) -> String {
    if cfg.from_file() {
        cfg.file.display().to_string()
    } else {
        format!(
            "a configuration file (none at {})",
            navsync_shared::config::DEFAULT_PATH
        )
    }
}

/// `navsync check-config`: parses and checks the whole file, including the device strings
/// each role parses; prints what every role would run. Starts nothing.
pub fn check_config(explicit: Option<&Path>) -> Result<()> {
    let path = explicit.unwrap_or(Path::new(navsync_shared::config::DEFAULT_PATH));
    let cfg = Loaded::load(path).map_err(anyhow::Error::new)?;
    let c = &cfg.config;
    for (id, p) in &c.pps {
        pps_source(&cfg, id, &p.source)?;
    }
    for (id, i) in &c.imu {
        imu_source(&cfg, id, &i.source)?;
        if let Some(axes) = &i.axes {
            imu_axes(&cfg, id, axes)?;
        }
    }
    let est = estimator_args(&cfg, None, Settings::default())?;
    let mut warnings = Vec::new();
    for (kind, ids, known) in [
        ("gnss", &est.gnss_ids, c.gps.keys().collect::<Vec<_>>()),
        ("pps", &est.pps_ids, c.pps.keys().collect()),
        ("imus", &est.imu_ids, c.imu.keys().collect()),
    ] {
        for id in ids {
            if !known.contains(&id) {
                warnings.push(format!(
                    "estimator.{kind} names `{id}`, which has no section in this file (its driver must get its device on the command line)"
                ));
            }
        }
    }
    println!("{}: OK", cfg.file.display());
    for (id, g) in &c.gps {
        println!(
            "  navsync gps --id {id}: {} at {:?}",
            g.port,
            g.baud.unwrap_or(BaudSetting::Fixed(9600))
        );
    }
    for (id, p) in &c.pps {
        println!("  navsync pps --id {id}: {}", p.source);
    }
    for (id, i) in &c.imu {
        println!(
            "  navsync imu --id {id}: {} (rotation {:?}°, lever arm {:?} m)",
            i.source, i.mounting.rotation_deg, i.mounting.lever_arm_m
        );
    }
    println!(
        "  navsync estimator: gnss {:?}, pps {:?}, imus {:?}, {} sync, {:?} IMU noise",
        est.gnss_ids,
        est.pps_ids,
        est.imu_ids,
        if est.software_sync { "software" } else { "PPS" },
        est.imu_model
    );
    if let Some(n) = &c.outputs.ntpshm {
        println!("  navsync ntpshm: unit {}", n.unit);
    }
    if let Some(r) = &c.outputs.record {
        println!("  navsync record: {}", r.path.display());
    }
    for w in warnings {
        println!("warning: {w}");
    }
    Ok(())
}

/// The units, rules and example shipped with the binary (`navsync install`).
const SHIPPED: &[(&str, &str)] = &[
    ("navsync.target", include_str!("../../../systemd/navsync.target")),
    (
        "navsync-gps@.service",
        include_str!("../../../systemd/navsync-gps@.service"),
    ),
    (
        "navsync-pps@.service",
        include_str!("../../../systemd/navsync-pps@.service"),
    ),
    (
        "navsync-imu@.service",
        include_str!("../../../systemd/navsync-imu@.service"),
    ),
    (
        "navsync-estimator.service",
        include_str!("../../../systemd/navsync-estimator.service"),
    ),
    (
        "navsync-ntpshm.service",
        include_str!("../../../systemd/navsync-ntpshm.service"),
    ),
    (
        "navsync-record.service",
        include_str!("../../../systemd/navsync-record.service"),
    ),
    (
        "navsync-gpsd-server.service",
        include_str!("../../../systemd/navsync-gpsd-server.service"),
    ),
];
const SYSUSERS: &str = include_str!("../../../systemd/navsync.sysusers");
const TMPFILES: &str = include_str!("../../../systemd/navsync.tmpfiles");
const UDEV: &str = include_str!("../../../systemd/99-navsync.rules");
const EXAMPLE: &str = include_str!("../../../systemd/navsync.toml.example");

/// Where `navsync install` put what.
#[derive(Debug, Default)]
pub struct Installed {
    /// Every file written.
    pub files: Vec<PathBuf>,
}

/// `navsync install --prefix PREFIX [--root ROOT]`: the binary to `ROOT/PREFIX/bin/navsync`,
/// the units (their `ExecStart=` pointing at `PREFIX/bin/navsync`) to
/// `ROOT/etc/systemd/system/`, sysusers.d, tmpfiles.d and the udev rules to `ROOT/etc/…`,
/// the example to `ROOT/etc/navsync/navsync.toml.example` and, when there is none yet,
/// `ROOT/etc/navsync/navsync.toml`. `ROOT` (default `/`) stages an image or a package.
pub fn install(prefix: &Path, root: &Path) -> Result<Installed> {
    anyhow::ensure!(
        prefix.is_absolute(),
        "--prefix {}: expected an absolute path",
        prefix.display()
    );
    let under = |p: &Path| root.join(p.strip_prefix("/").unwrap_or(p));
    let bin = prefix.join("bin/navsync");
    let mut done = Installed::default();
    let exe = std::env::current_exe().context("locating this executable")?;
    let bin_dst = under(&bin);
    std::fs::create_dir_all(bin_dst.parent().expect("bin dir"))?;
    // Copy to a temporary name and rename: replacing a running binary in place fails (ETXTBSY).
    let tmp = bin_dst.with_extension("new");
    std::fs::copy(&exe, &tmp).with_context(|| format!("copying {} to {}", exe.display(), tmp.display()))?;
    std::fs::rename(&tmp, &bin_dst)?;
    done.files.push(bin_dst);
    let mut write = |path: PathBuf, text: &str, mode: u32| -> Result<()> {
        use std::os::unix::fs::PermissionsExt;
        if let Some(d) = path.parent() {
            std::fs::create_dir_all(d).with_context(|| format!("creating {}", d.display()))?;
        }
        std::fs::write(&path, text).with_context(|| format!("writing {}", path.display()))?;
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(mode))?;
        done.files.push(path);
        Ok(())
    };
    let unit_dir = under(Path::new("/etc/systemd/system"));
    for (name, text) in SHIPPED {
        write(unit_dir.join(name), &rewrite_exec(text, &bin), 0o644)?;
    }
    write(under(Path::new("/etc/sysusers.d/navsync.conf")), SYSUSERS, 0o644)?;
    write(under(Path::new("/etc/tmpfiles.d/navsync.conf")), TMPFILES, 0o644)?;
    write(under(Path::new("/etc/udev/rules.d/99-navsync.rules")), UDEV, 0o644)?;
    write(under(Path::new("/etc/navsync/navsync.toml.example")), EXAMPLE, 0o644)?;
    let conf = under(Path::new("/etc/navsync/navsync.toml"));
    if !conf.exists() {
        write(conf, EXAMPLE, 0o640)?;
    }
    Ok(done)
}

/// The unit text with `/usr/local/bin/navsync` replaced by `bin`.
pub fn rewrite_exec(unit: &str, bin: &Path) -> String {
    unit.replace("/usr/local/bin/navsync", &bin.display().to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flags_win_over_the_file_and_the_file_over_defaults() {
        let cfg = Loaded::parse(
            "[gps.0]\nport = \"/dev/a\"\nbaud = 4800\nlever_arm_m = [1, 2, 3]\n[imu.0]\nsource = \"sim\"\nrate_hz = 100\nmounting = { lever_arm_m = [0.5, 0, 0] }\n[estimator]\nimu_model = \"consumer\"\n",
            Path::new("t.toml"),
        )
        .unwrap();
        let g = gps_args(&cfg, None, None, Baud::Fixed(9600), "0".into()).unwrap();
        assert_eq!((g.port.as_str(), g.baud), ("/dev/a", Baud::Fixed(4800)));
        let g = gps_args(&cfg, None, Some("/dev/b".into()), Baud::Fixed(9600), "0".into()).unwrap();
        assert_eq!(g.port, "/dev/b");
        assert!(gps_args(&cfg, None, None, Baud::Fixed(9600), "1".into()).is_err());
        let e = estimator_args(&cfg, None, Settings::default()).unwrap();
        assert_eq!(e.imu_model, ImuPreset::Consumer);
        assert_eq!(e.gnss_lever_arm_m, [1.0, 2.0, 3.0]);
        assert_eq!(e.imu_mountings["0"].lever_b_m, [0.5, 0.0, 0.0]);
        let pc = e.pipeline_config();
        assert_eq!(pc.nav.lever_arm_b_m.x, 1.0);
        assert_eq!(pc.array.units[0].lever_b_m.x, 0.5);
    }

    #[test]
    fn device_strings_are_located() {
        let cfg = Loaded::parse("[imu.0]\nsource = \"spi:0\"\n", Path::new("t.toml")).unwrap();
        let e = imu_args(&cfg, None, "0", None, |_| unreachable!()).unwrap_err();
        let text = format!("{e:#}");
        assert!(text.starts_with("t.toml:2:10: imu.0.source:"), "{text}");
    }

    #[test]
    fn units_point_at_the_installed_binary() {
        for (name, text) in SHIPPED.iter().filter(|(n, _)| n.ends_with(".service")) {
            assert!(text.contains("ExecStart=/usr/local/bin/navsync "), "{name}");
            let r = rewrite_exec(text, Path::new("/opt/ns/bin/navsync"));
            assert!(r.contains("ExecStart=/opt/ns/bin/navsync "), "{name}");
        }
    }
}
