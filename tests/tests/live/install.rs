//! `navsync install --prefix DIR` writes below DIR and nowhere else; `--dry-run` writes
//! nothing and lists what it would write; an existing configuration file is kept; `--root`
//! stages the same layout below another directory.
//!
//! The install runs as a real process. Where unprivileged user and mount namespaces work
//! (`unshare -rm`), it runs in a private mount namespace in which every top-level directory
//! but the one holding the test's scratch directory (and /proc, /sys, /dev) is bind-mounted
//! read-only: a write outside the prefix fails the install instead of changing the host. In
//! any case, every path with `navsync` in its name under the directories an install could
//! write to (/etc, /usr/local, /usr/lib/systemd, /usr/lib/sysusers.d, /usr/lib/tmpfiles.d,
//! /usr/lib/udev, /lib/udev) is listed with its modification time before and after, and the
//! lists must be equal.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::SystemTime;

use navsync_tests::{TestEnv, navsync_bin};

/// Where an install outside its prefix would leave files.
const WATCHED: [&str; 7] = [
    "/etc",
    "/usr/local",
    "/usr/lib/systemd",
    "/usr/lib/sysusers.d",
    "/usr/lib/tmpfiles.d",
    "/usr/lib/udev",
    "/lib/udev",
];

/// Every path under `dir` (not following links), with its modification time.
fn walk(dir: &Path, out: &mut BTreeMap<PathBuf, Option<SystemTime>>) {
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    for e in entries.flatten() {
        let p = e.path();
        let meta = std::fs::symlink_metadata(&p).ok();
        out.insert(p.clone(), meta.as_ref().and_then(|m| m.modified().ok()));
        if meta.is_some_and(|m| m.is_dir()) {
            walk(&p, out);
        }
    }
}

/// The paths named `*navsync*` under [`WATCHED`], with their modification times.
fn navsync_paths_on_the_host() -> BTreeMap<PathBuf, Option<SystemTime>> {
    let mut all = BTreeMap::new();
    for d in WATCHED {
        walk(Path::new(d), &mut all);
    }
    all.retain(|p, _| p.to_string_lossy().contains("navsync"));
    all
}

/// `sh` text that bind-mounts every top-level directory read-only but `keep`, /proc, /sys
/// and /dev (/etc, /usr and /var must succeed; another one whose mounts cannot be rebound in
/// the namespace is left as it is, the listing still watching it), then runs its arguments.
fn read_only_script(keep: &str) -> String {
    format!(
        r#"for d in /*; do
  [ -d "$d" ] && [ ! -L "$d" ] || continue
  case "$d" in /proc|/sys|/dev|/{keep}) continue ;; esac
  if ! {{ mount --rbind "$d" "$d" && mount -o remount,bind,ro "$d"; }} 2>/dev/null; then
    case "$d" in /etc|/usr|/var) echo "cannot make $d read-only" >&2; exit 99 ;; esac
  fi
done
exec "$@""#
    )
}

/// Whether `unshare -rm` and a read-only bind mount work here.
fn namespaces_work() -> bool {
    Command::new("unshare")
        .args([
            "-rm",
            "sh",
            "-c",
            "mount --bind /etc /etc && mount -o remount,bind,ro /etc && ! touch /etc/.navsync-probe 2>/dev/null",
        ])
        .output()
        .is_ok_and(|o| o.status.success())
}

struct Installer {
    /// The top-level directory of the scratch directory (left writable in the namespace).
    keep: String,
    isolated: bool,
}

impl Installer {
    fn run(&self, args: &[&str]) -> Output {
        let mut c = if self.isolated {
            let mut c = Command::new("unshare");
            c.args(["-rm", "sh", "-c", &read_only_script(&self.keep), "sh"])
                .arg(navsync_bin());
            c
        } else {
            Command::new(navsync_bin())
        };
        // No configuration file of the host, whatever there is: install reads none.
        c.arg("install").args(args).env("RUST_LOG", "warn");
        c.output().expect("running navsync install")
    }
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// Every file under `dir`.
fn files_under(dir: &Path) -> Vec<PathBuf> {
    let mut all = BTreeMap::new();
    walk(dir, &mut all);
    let mut files: Vec<PathBuf> = all.into_keys().filter(|p| p.is_file()).collect();
    files.sort();
    files
}

#[test]
fn install_stays_in_its_prefix_lists_on_dry_run_and_keeps_a_configuration() {
    let env = TestEnv::new("install");
    let isolated = namespaces_work();
    if !isolated {
        println!("no private mount namespace here (unshare -rm failed): comparing the host's listings only");
    }
    let keep = env
        .dir
        .components()
        .nth(1)
        .map(|c| c.as_os_str().to_string_lossy().into_owned())
        .expect("scratch dir below /");
    let inst = Installer { keep, isolated };
    let before = navsync_paths_on_the_host();

    let prefix = env.dir.join("opt/navsync");
    let p = prefix.to_str().unwrap();

    // --dry-run: the list, and nothing written.
    let o = inst.run(&["--prefix", p, "--dry-run"]);
    assert!(o.status.success(), "{}\n{}", o.status, text(&o.stderr));
    let listed: Vec<String> = text(&o.stdout).lines().map(str::to_string).collect();
    assert_eq!(listed.len(), 18, "{listed:?}");
    for l in &listed {
        let path = l.strip_prefix("would write ").unwrap_or_else(|| panic!("{l}"));
        assert!(Path::new(path).starts_with(&prefix), "{l}");
    }
    assert!(listed.contains(&format!("would write {p}/bin/navsync")), "{listed:?}");
    assert!(
        listed.contains(&format!("would write {p}/etc/navsync/navsync.toml")),
        "{listed:?}"
    );
    assert!(!prefix.exists(), "--dry-run wrote {}", prefix.display());

    // The install: every file under the prefix, exactly the ones it printed.
    let o = inst.run(&["--prefix", p]);
    assert!(o.status.success(), "{}\n{}", o.status, text(&o.stderr));
    let mut printed: Vec<PathBuf> = text(&o.stdout).lines().map(PathBuf::from).collect();
    printed.sort();
    assert_eq!(printed, files_under(&prefix), "printed vs written");
    assert_eq!(printed.len(), 18, "{printed:?}");
    assert!(
        text(&o.stderr).contains(&format!("--config {p}/etc/navsync/navsync.toml check-config")),
        "{}",
        text(&o.stderr)
    );
    let unit = std::fs::read_to_string(prefix.join("lib/systemd/system/navsync-estimator.service")).unwrap();
    assert!(
        unit.contains(&format!(
            "ExecStart={p}/bin/navsync --config {p}/etc/navsync/navsync.toml estimator"
        )),
        "{unit}"
    );
    for f in files_under(&prefix.join("lib/systemd/system")) {
        // Every path the unit names is the prefix's.
        let t = std::fs::read_to_string(&f)
            .unwrap()
            .replace(&format!("{p}/etc/navsync/"), "CONF/")
            .replace(&format!("{p}/bin/navsync"), "BIN");
        assert!(
            !t.contains("/etc/navsync") && !t.contains("/usr/local/bin"),
            "{}: {t}",
            f.display()
        );
    }
    let conf = prefix.join("etc/navsync/navsync.toml");
    // The configuration (0640, root's) gets the services' group from tmpfiles.d.
    let tmpfiles = std::fs::read_to_string(prefix.join("lib/tmpfiles.d/navsync.conf")).unwrap();
    assert!(
        tmpfiles.contains(&format!("z {} 0640 root navsync -", conf.display())),
        "{tmpfiles}"
    );
    let o = Command::new(navsync_bin())
        .args(["--config", conf.to_str().unwrap(), "check-config"])
        .output()
        .unwrap();
    assert!(o.status.success(), "the installed configuration: {}", text(&o.stderr));

    // An existing configuration is kept, and said so; the dry run says so too.
    std::fs::write(&conf, "# mine\n").unwrap();
    let o = inst.run(&["--prefix", p]);
    assert!(o.status.success(), "{}\n{}", o.status, text(&o.stderr));
    assert_eq!(std::fs::read_to_string(&conf).unwrap(), "# mine\n");
    assert!(!text(&o.stdout).contains("navsync.toml\n"), "{}", text(&o.stdout));
    assert!(text(&o.stderr).contains("never overwritten"), "{}", text(&o.stderr));
    let o = inst.run(&["--prefix", p, "--dry-run"]);
    assert!(
        text(&o.stdout).contains(&format!("would keep {p}/etc/navsync/navsync.toml")),
        "{}",
        text(&o.stdout)
    );

    // --root stages below another directory; the units name the target's paths.
    let stage = env.dir.join("stage");
    let o = inst.run(&["--prefix", "/opt/navsync", "--root", stage.to_str().unwrap()]);
    assert!(o.status.success(), "{}\n{}", o.status, text(&o.stderr));
    let staged = files_under(&stage);
    assert_eq!(staged.len(), 18, "{staged:?}");
    assert!(
        staged.iter().all(|f| f.starts_with(stage.join("opt/navsync"))),
        "{staged:?}"
    );
    let unit = std::fs::read_to_string(stage.join("opt/navsync/lib/systemd/system/navsync-ntpshm.service")).unwrap();
    assert!(unit.contains("ExecStart=/opt/navsync/bin/navsync "), "{unit}");

    // Documented in --help.
    let o = Command::new(navsync_bin())
        .args(["install", "--help"])
        .output()
        .unwrap();
    for flag in ["--prefix", "--root", "--dry-run"] {
        assert!(text(&o.stdout).contains(flag), "{flag}: {}", text(&o.stdout));
    }

    assert_eq!(
        navsync_paths_on_the_host(),
        before,
        "the install changed the host outside its prefix"
    );
    let _ = std::fs::remove_dir_all(&env.dir);
}
