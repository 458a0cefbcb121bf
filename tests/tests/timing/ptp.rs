//! `navsync ptp-config`'s files run by the real linuxptp: network namespaces `A` and `B` joined
//! by a veth pair; `ptp4l -S` in A with the grandmaster configuration the binary writes
//! (`--role grandmaster --timestamping software`), `ptp4l -S` in B with the slave's (`--role
//! slave --timestamping software --free-running`). Checked: A takes the grandmaster role, B
//! selects A's clock as its best master within 30 s and reports its offset to it (`master
//! offset N s0 freq F path delay D`), |offset| p95 below 1 ms; the figures are printed.
//!
//! Neither ptp4l touches the clock: both configurations must say `free_running 1` (checked
//! before they start; ptp4l(8): "Don't adjust the local clock"). So the slave's servo never
//! runs: it stays in state s0 and its port in UNCALIBRATED (the move to SLAVE follows the
//! servo's lock, s2), and "locked" here is "B follows A and measures its offset". Not proved:
//! hardware time stamping (veth has none), phc2sys and a disciplined PHC, the time scale (both
//! ends read one system clock, so the offset is the time stamping's error, not a clock
//! difference), and a servo steering a clock.
//!
//! Needs root (namespaces) and Debian's `linuxptp` (`.ci/run` installs it when it can); without
//! them the test prints why and is skipped.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use navsync_bench::netns::{NetnsPair, StopOnDrop};
use navsync_tests::{TestEnv, navsync_bin};

/// How long the slave may take to follow the grandmaster (announce timeout, BMCA, first offset).
const LOCK_WITHIN: Duration = Duration::from_secs(30);
/// Offsets to collect after that (ptp4l prints one every 2 s when free-running).
const OFFSETS: usize = 8;
/// |offset| p95 bound, ns: software time stamps on one clock are µs-level, not ms.
const P95_BOUND_NS: f64 = 1e6;

fn find_ptp4l() -> Option<PathBuf> {
    [
        "/usr/sbin/ptp4l",
        "/sbin/ptp4l",
        "/usr/local/sbin/ptp4l",
        "/usr/bin/ptp4l",
    ]
    .iter()
    .map(PathBuf::from)
    .find(|p| p.exists())
}

/// `navsync ptp-config ARGS --out DIR`: the written ptp4l.conf.
fn generate(dir: &Path, args: &[&str]) -> PathBuf {
    let out = Command::new(navsync_bin())
        .arg("ptp-config")
        .args(args)
        .arg("--out")
        .arg(dir)
        .output()
        .expect("running navsync ptp-config");
    assert!(
        out.status.success(),
        "navsync ptp-config {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let conf = dir.join("ptp4l.conf");
    let text = std::fs::read_to_string(&conf).expect("ptp4l.conf");
    // Never start a ptp4l that could adjust this machine's clock.
    assert!(
        text.lines().any(|l| l.split_whitespace().eq(["free_running", "1"])),
        "{args:?} must give free_running 1:\n{text}"
    );
    conf
}

/// `(offset ns, state, path delay ns)` of a `master offset N sS freq F path delay D` line.
fn offset_line(line: &str) -> Option<(i64, String, i64)> {
    let w: Vec<&str> = line.split_whitespace().collect();
    let i = w.iter().position(|&x| x == "offset")?;
    let d = w.iter().position(|&x| x == "delay")?;
    (w.get(i.checked_sub(1)?) == Some(&"master")).then_some(())?;
    Some((
        w.get(i + 1)?.parse().ok()?,
        w.get(i + 2)?.to_string(),
        w.get(d + 1)?.parse().ok()?,
    ))
}

#[test]
fn ptp4l_slave_follows_the_generated_grandmaster_over_veth() {
    let _alone = navsync_tests::alone();
    let Some(ptp4l) = find_ptp4l() else {
        println!("SKIPPED: ptp4l is not installed (Debian package `linuxptp`; .ci/run installs it as root)");
        return;
    };
    // SAFETY: geteuid has no preconditions.
    let uid = unsafe { libc::geteuid() };
    if uid != 0 {
        println!("SKIPPED: network namespaces need root; this test runs as uid {uid}");
        return;
    }
    let link = match NetnsPair::new("ptp") {
        Ok(l) => l,
        Err(e) => {
            println!("SKIPPED: cannot create network namespaces here: {e}");
            return;
        }
    };
    let env = TestEnv::new("ptp");
    let (gm_dir, sl_dir) = (env.dir.join("gm"), env.dir.join("slave"));
    let gm_conf = generate(
        &gm_dir,
        &[
            "--interface",
            &link.veth[0],
            "--role",
            "grandmaster",
            "--timestamping",
            "software",
        ],
    );
    let sl_conf = generate(
        &sl_dir,
        &[
            "--interface",
            &link.veth[1],
            "--role",
            "slave",
            "--timestamping",
            "software",
            "--free-running",
        ],
    );
    // Each its own management socket (the default /var/run/ptp4l is one path for both).
    let start = |i: usize, conf: &Path, dir: &Path| {
        let (conf, uds) = (
            conf.display().to_string(),
            format!("--uds_address={}", dir.join("ptp4l.sock").display()),
        );
        let log = dir.join("ptp4l.log");
        let child = link
            .command(i, &ptp4l, &["-f", &conf, "-i", &link.veth[i], "-S", "-m", "-q", &uds])
            .stdout(std::fs::File::create(&log).expect("log"))
            .stderr(Stdio::null())
            .spawn()
            .expect("spawning ptp4l");
        (StopOnDrop(child), log)
    };
    let t0 = Instant::now();
    let (_gm, gm_log) = start(0, &gm_conf, &gm_dir);
    let (_slave, sl_log) = start(1, &sl_conf, &sl_dir);
    let read = |p: &Path| std::fs::read_to_string(p).unwrap_or_default();

    // A's clock identity, once it takes the grandmaster role; B following it.
    let mut gm_id = None;
    let mut followed = None;
    let mut offsets = Vec::new();
    while t0.elapsed() < LOCK_WITHIN + Duration::from_secs(2 * OFFSETS as u64 + 3) {
        std::thread::sleep(Duration::from_millis(200));
        let (gm_text, sl_text) = (read(&gm_log), read(&sl_log));
        if gm_id.is_none() && gm_text.contains("assuming the grand master role") {
            gm_id = gm_text.lines().find_map(|l| {
                let rest = l.split("selected local clock ").nth(1)?;
                Some(rest.split_whitespace().next()?.to_string())
            });
        }
        if let (None, Some(id)) = (followed, &gm_id)
            && sl_text.contains(&format!("selected best master clock {id}"))
            && sl_text.contains("LISTENING to UNCALIBRATED on RS_SLAVE")
        {
            followed = Some(t0.elapsed());
        }
        offsets = sl_text.lines().filter_map(offset_line).collect();
        if followed.is_none() && t0.elapsed() > LOCK_WITHIN {
            break;
        }
        if followed.is_some() && offsets.len() >= OFFSETS {
            break;
        }
    }
    let logs = || format!("grandmaster:\n{}\nslave:\n{}", read(&gm_log), read(&sl_log));
    let gm_id = gm_id.unwrap_or_else(|| panic!("the grandmaster never took the role\n{}", logs()));
    let followed =
        followed.unwrap_or_else(|| panic!("the slave did not follow {gm_id} within {LOCK_WITHIN:?}\n{}", logs()));
    assert!(
        offsets.len() >= OFFSETS,
        "{} offsets, {OFFSETS} expected\n{}",
        offsets.len(),
        logs()
    );
    // s1 (a step) or s2 would mean a servo adjusting the clock: never with free_running 1.
    assert!(offsets.iter().all(|(_, s, _)| s == "s0"), "a servo ran:\n{}", logs());

    let mut abs: Vec<f64> = offsets.iter().map(|(o, _, _)| o.unsigned_abs() as f64).collect();
    abs.sort_by(f64::total_cmp);
    let p95 = abs[((abs.len() as f64 * 0.95).ceil() as usize).min(abs.len()) - 1];
    let rms = (offsets.iter().map(|(o, _, _)| (*o as f64).powi(2)).sum::<f64>() / offsets.len() as f64).sqrt();
    let delay = offsets.iter().map(|(_, _, d)| *d as f64).sum::<f64>() / offsets.len() as f64;
    println!(
        "ptp4l -S over veth: grandmaster {gm_id}; the slave followed it after {:.1} s; {} offsets: \
         RMS {rms:.0} ns, |offset| p95 {p95:.0} ns, max {:.0} ns; mean path delay {delay:.0} ns \
         (offsets {:?} ns)",
        followed.as_secs_f64(),
        offsets.len(),
        abs[abs.len() - 1],
        offsets.iter().map(|(o, _, _)| *o).collect::<Vec<_>>()
    );
    assert!(
        p95 < P95_BOUND_NS,
        "|offset| p95 {p95} ns ≥ {P95_BOUND_NS} ns\n{}",
        logs()
    );
    assert!(
        delay > 0.0 && delay < P95_BOUND_NS,
        "mean path delay {delay} ns\n{}",
        logs()
    );
}
