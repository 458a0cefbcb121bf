//! navsync's GNSS time reaches a real `chronyd` through the NTP shared-memory refclock:
//! sim (GNSS time set 0.125 s ahead of the system clock, `--utc-offset`) → pty → gps, sim →
//! pps → estimator → `navsync/time/state` → `navsync ntpshm --unit U` → SHM segment
//! 0x4e545030 + U → `chronyd -x` (never touches the clock; its own config, pid, drift and
//! command socket in the test's scratch directory; `refclock SHM U`). `chronyc tracking` must
//! report the system clock 0.125 s slow of the reference within 1 ms. The same samples go to
//! chrony's socket refclock as well (`ntpshm --sock`, `refclock SOCK PATH … noselect`): chrony
//! must measure the same offset through it, within 1 ms of the SHM refclock's.
//!
//! Needs the Debian package `chrony` (`.ci/run` installs it when it can). Where `chronyd` is
//! not installed or cannot start (e.g. not root), the test prints why and is skipped.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use navsync_shared::samples::{TimeState, TimeStatus};
use navsync_shared::services;
use navsync_tests::TestEnv;

/// GNSS time minus the system clock in the simulation, s.
const UTC_OFFSET_S: f64 = 0.125;

fn find_chronyd() -> Option<PathBuf> {
    [
        "/usr/sbin/chronyd",
        "/sbin/chronyd",
        "/usr/bin/chronyd",
        "/usr/local/sbin/chronyd",
    ]
    .iter()
    .map(PathBuf::from)
    .find(|p| p.exists())
}

fn chronyc(sock: &Path, args: &[&str]) -> Option<String> {
    let out = Command::new("chronyc")
        .arg("-h")
        .arg(sock)
        .args(args)
        .stderr(Stdio::null())
        .output()
        .ok()?;
    out.status
        .success()
        .then(|| String::from_utf8_lossy(&out.stdout).into_owned())
}

/// "System time" of `chronyc -c tracking` (CSV field 5): seconds the system clock is slow
/// (positive) or fast (negative) of the reference, with the reference's refid.
fn tracking_offset(csv: &str) -> Option<(String, f64)> {
    let f: Vec<&str> = csv.trim().split(',').collect();
    Some((f.get(1)?.to_string(), f.get(4)?.parse().ok()?))
}

/// Source `name`'s reach register (octal, as chronyc prints it) and last sample's adjusted
/// offset (s) from `chronyc -c sources` (fields: mode, state, name, stratum, poll, reach, last rx,
/// adjusted offset, measured offset, error).
fn source_offset(csv: &str, name: &str) -> Option<(String, f64)> {
    csv.lines().find_map(|l| {
        let f: Vec<&str> = l.trim().split(',').collect();
        (f.get(2) == Some(&name)).then(|| Some((f.get(5)?.to_string(), f.get(7)?.parse().ok()?)))?
    })
}

struct Chronyd {
    child: Child,
}

impl Drop for Chronyd {
    fn drop(&mut self) {
        // SAFETY: signalling our own child by pid.
        unsafe { libc::kill(self.child.id() as libc::pid_t, libc::SIGTERM) };
        let t0 = Instant::now();
        while t0.elapsed() < Duration::from_secs(5) {
            if let Ok(Some(_)) = self.child.try_wait() {
                return;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn remove_shm(unit: u32) {
    let key = 0x4e54_5030i32.wrapping_add(unit as i32);
    // SAFETY: System V shm calls; removing the segment this test's processes used.
    unsafe {
        let id = libc::shmget(key, 0, 0);
        if id >= 0 {
            libc::shmctl(id, libc::IPC_RMID, std::ptr::null_mut());
        }
    }
}

#[test]
fn chrony_sees_the_gnss_time_offset_within_1_ms() {
    let _alone = navsync_tests::alone();
    let Some(chronyd) = find_chronyd() else {
        println!("SKIPPED: chronyd is not installed (Debian package `chrony`; .ci/run installs it as root)");
        return;
    };
    let mut env = TestEnv::new("chrony");
    // A unit of its own (key 0x4e545030 + unit) so parallel runs and a real gpsd never meet.
    let unit = 4000 + std::process::id() % 20_000;
    remove_shm(unit);
    let cdir = env.dir.join("chrony");
    std::fs::create_dir_all(&cdir).expect("chrony dir");
    // chronyd refuses a command-socket directory that others can access.
    std::fs::set_permissions(&cdir, std::os::unix::fs::PermissionsExt::from_mode(0o700)).expect("chmod 700");
    let sock = cdir.join("chronyd.sock");
    let refclock_sock = cdir.join("navsync.sock");
    let conf = cdir.join("chrony.conf");
    std::fs::write(
        &conf,
        format!(
            "refclock SHM {unit} refid NAVS poll 2 dpoll 0 precision 1e-6\n\
             refclock SOCK {rs} refid NSCK poll 2 precision 1e-6 noselect\n\
             pidfile {d}/chronyd.pid\n\
             driftfile {d}/chrony.drift\n\
             bindcmdaddress {sock}\n\
             cmdport 0\n\
             port 0\n",
            d = cdir.display(),
            sock = sock.display(),
            rs = refclock_sock.display()
        ),
    )
    .expect("chrony.conf");

    let node = env.node("observer");
    let time = node.subscriber::<TimeState>(services::TIME_STATE).unwrap();
    let link = env.dir.join("gnss0");
    let link_s = link.display().to_string();
    let offset = UTC_OFFSET_S.to_string();
    let unit_s = unit.to_string();
    env.spawn(
        "sim",
        &[
            "sim",
            "--pty-link",
            &link_s,
            "--imus",
            "1",
            "--duration",
            "90",
            "--utc-offset",
            &offset,
        ],
    );
    env.wait_for_path(&link, Duration::from_secs(20));
    env.spawn("gnss", &["gnss", "--port", &link_s, "--baud", "115200", "--id", "0"]);
    env.spawn("pps", &["pps", "--source", "sim", "--id", "0"]);
    env.spawn("estimator", &["estimator", "--gnss", "0", "--pps", "0", "--imus", "0"]);
    let refclock_sock_s = refclock_sock.display().to_string();
    env.spawn("ntpshm", &["ntpshm", "--unit", &unit_s, "--sock", &refclock_sock_s]);

    // SAFETY: geteuid has no preconditions.
    let root = unsafe { libc::geteuid() } == 0;
    let log = std::fs::File::create(cdir.join("chronyd.log")).expect("log");
    let mut cmd = Command::new(&chronyd);
    cmd.args(["-x", "-d", "-f"]).arg(&conf);
    if root {
        cmd.args(["-u", "root"]);
    } else {
        cmd.arg("-U");
    }
    let child = match cmd.stdout(Stdio::null()).stderr(log).spawn() {
        Ok(c) => c,
        Err(e) => {
            println!("SKIPPED: cannot start {}: {e}", chronyd.display());
            remove_shm(unit);
            return;
        }
    };
    let mut chrony = Chronyd { child };

    let t0 = Instant::now();
    let mut locked = false;
    let mut last: Option<(String, f64)> = None;
    let mut good = 0;
    while t0.elapsed() < Duration::from_secs(75) {
        std::thread::sleep(Duration::from_millis(1000));
        env.assert_running();
        if let Ok(Some(st)) = chrony.child.try_wait() {
            let log = std::fs::read_to_string(cdir.join("chronyd.log")).unwrap_or_default();
            println!("SKIPPED: chronyd could not run here ({st}):\n{log}");
            drop((time, node));
            remove_shm(unit);
            env.finish();
            return;
        }
        while let Some(t) = time.receive().unwrap() {
            locked = t.status() == TimeStatus::Locked;
        }
        if let Some(csv) = chronyc(&sock, &["-n", "-c", "tracking"]) {
            last = tracking_offset(&csv);
            if let Some((refid, off)) = &last
                && refid == "NAVS"
                && locked
            {
                if (off - UTC_OFFSET_S).abs() < 1e-3 {
                    good += 1;
                    if good >= 3 {
                        break;
                    }
                } else {
                    good = 0;
                }
            }
        }
    }
    // The socket refclock: measured (reached) with the same offset as the SHM one.
    let mut by_sock = None;
    let t1 = Instant::now();
    while t1.elapsed() < Duration::from_secs(20) {
        let csv = chronyc(&sock, &["-n", "-c", "sources"]).unwrap_or_default();
        by_sock = source_offset(&csv, "NSCK").zip(source_offset(&csv, "NAVS"));
        if by_sock.as_ref().is_some_and(|((reach, _), _)| reach != "0") {
            break;
        }
        std::thread::sleep(Duration::from_millis(1000));
    }
    let sources = chronyc(&sock, &["-n", "sources", "-v"]).unwrap_or_default();
    let stats = chronyc(&sock, &["-n", "sourcestats"]).unwrap_or_default();
    println!("chrony tracking (refid, system clock slow of reference by s): {last:?}\n{sources}\n{stats}");
    drop(chrony);
    let chrony_log = std::fs::read_to_string(cdir.join("chronyd.log")).unwrap_or_default();
    assert!(locked, "the time mapping never locked\n{}", env.log("estimator"));
    let (refid, off) = last.unwrap_or_else(|| panic!("no tracking from chronyc\nchronyd log:\n{chrony_log}"));
    assert_eq!(
        refid, "NAVS",
        "chrony did not select the SHM refclock\n{sources}\n{chrony_log}"
    );
    assert!(
        (off - UTC_OFFSET_S).abs() < 1e-3,
        "chrony sees the system clock {off} s slow of navsync's GNSS time, expected {UTC_OFFSET_S} ± 0.001 s"
    );
    assert!(good >= 3, "offset not stable over three readings");
    let ((reach, off_sock), (_, off_shm)) =
        by_sock.unwrap_or_else(|| panic!("no SOCK refclock in chronyc sources\n{sources}\n{chrony_log}"));
    assert_ne!(
        reach,
        "0",
        "chrony never received a SOCK sample\n{sources}\n{}",
        env.log("ntpshm")
    );
    // Adjusted offsets (chrony's clock model already holds the 0.125 s the tracking shows):
    // the two refclocks agree, so the SOCK samples carry the same 0.125 s.
    assert!(
        (off_sock - off_shm).abs() < 1e-3,
        "the SOCK refclock's adjusted offset {off_sock} s against the SHM refclock's {off_shm} s\n{sources}"
    );
    drop((time, node));
    remove_shm(unit);
    env.finish();
}
