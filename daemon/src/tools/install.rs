//! `navsync install`: the binary, the systemd units, sysusers/tmpfiles/udev files and the
//! example configuration into place (README "## Running as a service").

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};

/// `navsync install`.
#[derive(clap::Args, Debug)]
pub struct Options {
    /// Installation prefix: the binary goes to PREFIX/bin/navsync, which the units run.
    #[arg(long, default_value = "/usr/local")]
    pub prefix: PathBuf,
    /// Staging root (an image or package tree): every file goes below it.
    #[arg(long, default_value = "/")]
    pub root: PathBuf,
}

/// Installs and prints every file written and what to do next.
pub fn run(opts: Options) -> Result<()> {
    let done = install(&opts.prefix, &opts.root)?;
    for f in &done.files {
        println!("{}", f.display());
    }
    eprintln!(
        "then: systemd-sysusers; systemd-tmpfiles --create; udevadm control --reload; systemctl daemon-reload; \
         edit /etc/navsync/navsync.toml; navsync check-config; systemctl enable --now navsync.target"
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
        "navsync-bridge-zenoh.service",
        include_str!("../../../systemd/navsync-bridge-zenoh.service"),
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
    fn units_point_at_the_installed_binary() {
        for (name, text) in SHIPPED.iter().filter(|(n, _)| n.ends_with(".service")) {
            assert!(text.contains("ExecStart=/usr/local/bin/navsync "), "{name}");
            let r = rewrite_exec(text, Path::new("/opt/ns/bin/navsync"));
            assert!(r.contains("ExecStart=/opt/ns/bin/navsync "), "{name}");
        }
    }
}
