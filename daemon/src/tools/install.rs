//! `navsync install`: the binary, the systemd units, sysusers/tmpfiles/udev files and the
//! example configuration into place (docs/guide/install.md).
//!
//! Two layouts. Without `--prefix`, the administrator's system install: the binary to
//! `/usr/local/bin/navsync`, everything else to `/etc` (where systemd, udev and every navsync
//! command look first). With `--prefix DIR`, everything under `DIR` and nothing outside it:
//! `DIR/bin/navsync`, `DIR/lib/systemd/system/`, `DIR/lib/sysusers.d/`, `DIR/lib/tmpfiles.d/`,
//! `DIR/lib/udev/rules.d/` and `DIR/etc/navsync/`, the units naming that binary and that
//! configuration file (systemd, systemd-sysusers, systemd-tmpfiles and udev read
//! `/usr/local/lib/…` as well as `/etc`, so `--prefix /usr/local` is a working install).
//! `--root DIR` stages either layout below DIR (an image or a package tree: the files go to
//! `DIR/…`, the units name the paths without `DIR`). `--dry-run` writes nothing and lists
//! what would be written. An existing configuration file is never overwritten.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};

/// `navsync install`.
#[derive(clap::Args, Debug)]
pub struct Options {
    /// Install everything under DIR and nothing outside it: DIR/bin/navsync, the units in
    /// DIR/lib/systemd/system, sysusers, tmpfiles and udev files in DIR/lib/…, the
    /// configuration in DIR/etc/navsync (the units name both). Without it: the binary to
    /// /usr/local/bin and the rest to /etc.
    #[arg(long, value_name = "DIR")]
    pub prefix: Option<PathBuf>,
    /// Staging root (an image or a package tree): every file goes below DIR, while the units
    /// name the paths as they will be on the target (without DIR).
    #[arg(long, value_name = "DIR", default_value = "/")]
    pub root: PathBuf,
    /// Write nothing: list every file that would be written (and an existing configuration
    /// that would be kept).
    #[arg(long)]
    pub dry_run: bool,
}

/// Installs (or, with `--dry-run`, lists) every file and says what to do next.
pub fn run(opts: Options) -> Result<()> {
    let layout = Layout::new(opts.prefix.as_deref())?;
    let plan = plan(&layout, &opts.root)?;
    let mut out = std::io::stdout().lock();
    use std::io::Write as _;
    for step in &plan {
        match step {
            Step::Write { path, .. } | Step::CopySelf { path } if opts.dry_run => {
                writeln!(out, "would write {}", path.display())?;
            }
            Step::Keep { path } if opts.dry_run => {
                writeln!(out, "would keep {} (it exists: never overwritten)", path.display())?;
            }
            Step::Keep { path } => {
                eprintln!("kept {}: it exists and is never overwritten", path.display());
            }
            _ => {}
        }
    }
    if opts.dry_run {
        eprintln!("dry run: nothing was written");
        return Ok(());
    }
    for step in &plan {
        if let Some(path) = apply(step)? {
            writeln!(out, "{}", path.display())?;
        }
    }
    let conf = layout.config.display();
    let check = if layout.config == Path::new(crate::config::DEFAULT_PATH) {
        "navsync check-config".to_string()
    } else {
        format!("navsync --config {conf} check-config")
    };
    eprintln!(
        "then: systemd-sysusers; systemd-tmpfiles --create; udevadm control --reload; systemctl daemon-reload; \
         edit {conf}; {check}; systemctl enable navsync-estimator navsync-gnss@0 navsync-pps@0 navsync-imu@0 \
         (one instance per device of {conf}; optional: navsync-ntpshm navsync-gpsd-server navsync-web navsync-record); \
         systemctl start navsync.target"
    );
    Ok(())
}

/// The units, rules and example shipped with the binary (`navsync install`).
const SHIPPED: &[(&str, &str)] = &[
    ("navsync.target", include_str!("../../../systemd/navsync.target")),
    (
        "navsync-gnss@.service",
        include_str!("../../../systemd/navsync-gnss@.service"),
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
        "navsync-nmea-out@.service",
        include_str!("../../../systemd/navsync-nmea-out@.service"),
    ),
    (
        "navsync-pps-out@.service",
        include_str!("../../../systemd/navsync-pps-out@.service"),
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
    (
        "navsync-web.service",
        include_str!("../../../systemd/navsync-web.service"),
    ),
    (
        "navsync-bridge-zenoh.service",
        include_str!("../../../systemd/navsync-bridge-zenoh.service"),
    ),
];
const SYSUSERS: &str = include_str!("../../../systemd/navsync.sysusers");
const TMPFILES: &str = include_str!("../../../systemd/navsync.tmpfiles");
const UDEV: &str = include_str!("../../../systemd/99-navsync.rules");
const EXAMPLE: &str = include_str!("../../../systemd/navsync.toml.example");

/// Where the installed files go on the target (without `--root`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Layout {
    /// The binary the units run.
    pub bin: PathBuf,
    /// The systemd system units.
    pub units: PathBuf,
    /// The sysusers.d file.
    pub sysusers: PathBuf,
    /// The tmpfiles.d file.
    pub tmpfiles: PathBuf,
    /// The udev rule.
    pub udev: PathBuf,
    /// The configuration file the units read (the example beside it, `.example`).
    pub config: PathBuf,
}

impl Layout {
    /// Without a prefix the system layout (binary in `/usr/local/bin`, the rest in `/etc`);
    /// with one, everything under it.
    pub fn new(prefix: Option<&Path>) -> Result<Self> {
        let Some(p) = prefix else {
            return Ok(Self {
                bin: "/usr/local/bin/navsync".into(),
                units: "/etc/systemd/system".into(),
                sysusers: "/etc/sysusers.d/navsync.conf".into(),
                tmpfiles: "/etc/tmpfiles.d/navsync.conf".into(),
                udev: "/etc/udev/rules.d/99-navsync.rules".into(),
                config: crate::config::DEFAULT_PATH.into(),
            });
        };
        anyhow::ensure!(p.is_absolute(), "--prefix {}: expected an absolute path", p.display());
        anyhow::ensure!(
            p.components().all(|c| !matches!(c, std::path::Component::ParentDir)),
            "--prefix {}: expected a path without `..`",
            p.display()
        );
        anyhow::ensure!(
            p != Path::new("/"),
            "--prefix /: expected a directory other than / (use no --prefix for the system layout)"
        );
        Ok(Self {
            bin: p.join("bin/navsync"),
            units: p.join("lib/systemd/system"),
            sysusers: p.join("lib/sysusers.d/navsync.conf"),
            tmpfiles: p.join("lib/tmpfiles.d/navsync.conf"),
            udev: p.join("lib/udev/rules.d/99-navsync.rules"),
            config: p.join("etc/navsync/navsync.toml"),
        })
    }

    /// The example configuration, beside the configuration.
    pub fn example(&self) -> PathBuf {
        self.config.with_extension("toml.example")
    }

    /// A shipped unit's text with its paths made this layout's: the binary and the
    /// configuration directory.
    pub fn unit_text(&self, unit: &str) -> String {
        let conf_dir = self.config.parent().unwrap_or(Path::new("/etc/navsync"));
        rewrite_exec(unit, &self.bin).replace("/etc/navsync/", &format!("{}/", conf_dir.display()))
    }
}

/// One thing the install does.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Step {
    /// This executable copied to `path`.
    CopySelf {
        /// Where (under the root).
        path: PathBuf,
    },
    /// `text` written to `path` with `mode`.
    Write {
        /// Where (under the root).
        path: PathBuf,
        /// The contents.
        text: String,
        /// Permission bits.
        mode: u32,
    },
    /// An existing configuration file left as it is.
    Keep {
        /// Where (under the root).
        path: PathBuf,
    },
}

/// Every step of an install of `layout` below `root`, in order; nothing is touched.
pub fn plan(layout: &Layout, root: &Path) -> Result<Vec<Step>> {
    anyhow::ensure!(
        root.is_absolute(),
        "--root {}: expected an absolute path",
        root.display()
    );
    let under = |p: &Path| root.join(p.strip_prefix("/").unwrap_or(p));
    let write = |p: &Path, text: String, mode: u32| Step::Write {
        path: under(p),
        text,
        mode,
    };
    let mut steps = vec![Step::CopySelf {
        path: under(&layout.bin),
    }];
    for (name, text) in SHIPPED {
        steps.push(write(&layout.units.join(name), layout.unit_text(text), 0o644));
    }
    steps.push(write(&layout.sysusers, SYSUSERS.to_string(), 0o644));
    // The configuration is written root's, 0640; tmpfiles.d(5) `z` gives it the navsync group
    // once systemd-sysusers has created it, so the services (user navsync) can read it.
    let tmpfiles = format!(
        "{TMPFILES}# The configuration file: readable by the services (group navsync), not by others.\nz {} 0640 root navsync -\n",
        layout.config.display()
    );
    steps.push(write(&layout.tmpfiles, tmpfiles, 0o644));
    steps.push(write(&layout.udev, UDEV.to_string(), 0o644));
    steps.push(write(&layout.example(), EXAMPLE.to_string(), 0o644));
    let conf = under(&layout.config);
    // symlink_metadata: a dangling link is something there too, never written through.
    if conf.symlink_metadata().is_ok() {
        steps.push(Step::Keep { path: conf });
    } else {
        steps.push(write(&layout.config, EXAMPLE.to_string(), 0o640));
    }
    Ok(steps)
}

/// Carries out one step; the path written, if any.
fn apply(step: &Step) -> Result<Option<PathBuf>> {
    use std::os::unix::fs::PermissionsExt;
    let mkdir = |p: &Path| -> Result<()> {
        if let Some(d) = p.parent() {
            std::fs::create_dir_all(d).with_context(|| format!("creating {}", d.display()))?;
        }
        Ok(())
    };
    match step {
        Step::CopySelf { path } => {
            let exe = std::env::current_exe().context("locating this executable")?;
            mkdir(path)?;
            // Copy to a temporary name and rename: replacing a running binary in place fails
            // (ETXTBSY).
            let tmp = path.with_extension("new");
            std::fs::copy(&exe, &tmp).with_context(|| format!("copying {} to {}", exe.display(), tmp.display()))?;
            std::fs::rename(&tmp, path).with_context(|| format!("renaming {} to {}", tmp.display(), path.display()))?;
            Ok(Some(path.clone()))
        }
        Step::Write { path, text, mode } => {
            mkdir(path)?;
            std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))?;
            std::fs::set_permissions(path, std::fs::Permissions::from_mode(*mode))
                .with_context(|| format!("setting the mode of {}", path.display()))?;
            Ok(Some(path.clone()))
        }
        Step::Keep { .. } => Ok(None),
    }
}

/// The unit text with `/usr/local/bin/navsync` replaced by `bin`.
pub fn rewrite_exec(unit: &str, bin: &Path) -> String {
    unit.replace("/usr/local/bin/navsync", &bin.display().to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn units_point_at_the_installed_binary() {
        for (name, text) in SHIPPED.iter().filter(|(n, _)| n.ends_with(".service")) {
            assert!(text.contains("ExecStart=/usr/local/bin/navsync "), "{name}");
            let r = rewrite_exec(text, Path::new("/opt/ns/bin/navsync"));
            assert!(r.contains("ExecStart=/opt/ns/bin/navsync "), "{name}");
        }
    }

    #[test]
    fn a_prefix_holds_every_path_and_the_units_name_its_binary_and_configuration() {
        let l = Layout::new(Some(Path::new("/opt/ns"))).unwrap();
        let steps = plan(&l, Path::new("/")).unwrap();
        assert_eq!(steps.len(), SHIPPED.len() + 6);
        for s in &steps {
            let (Step::CopySelf { path } | Step::Write { path, .. } | Step::Keep { path }) = s;
            assert!(path.starts_with("/opt/ns/"), "{}", path.display());
        }
        for (name, text) in SHIPPED.iter().filter(|(n, _)| n.ends_with(".service")) {
            let t = l.unit_text(text);
            assert!(t.contains("ExecStart=/opt/ns/bin/navsync "), "{name}");
            assert!(
                !t.replace("/opt/ns/etc/navsync/", "").contains("/etc/navsync/"),
                "{name}: {t}"
            );
            assert!(!t.contains("/usr/local/bin/"), "{name}");
        }
        let est = l.unit_text(
            SHIPPED
                .iter()
                .find(|(n, _)| *n == "navsync-estimator.service")
                .unwrap()
                .1,
        );
        assert!(
            est.contains("--config /opt/ns/etc/navsync/navsync.toml estimator"),
            "{est}"
        );
        let staged = plan(&l, Path::new("/stage")).unwrap();
        assert!(matches!(&staged[0], Step::CopySelf { path } if path == Path::new("/stage/opt/ns/bin/navsync")));
        for bad in ["rel/dir", "/a/../etc", "/"] {
            assert!(Layout::new(Some(Path::new(bad))).is_err(), "{bad}");
        }
        let sys = Layout::new(None).unwrap();
        assert_eq!(sys.config, Path::new("/etc/navsync/navsync.toml"));
        assert_eq!(
            sys.unit_text("--config /etc/navsync/navsync.toml"),
            "--config /etc/navsync/navsync.toml"
        );
    }
}
