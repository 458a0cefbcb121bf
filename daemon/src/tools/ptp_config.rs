//! `navsync ptp-config`: linuxptp's configuration for the vehicle network, navsync's machine as
//! the PTP grandmaster fed from the disciplined system clock (navsync → chrony → system clock →
//! `phc2sys -s CLOCK_REALTIME` → the NIC's PTP hardware clock → `ptp4l`), or another machine as
//! a slave. A pure generator (settings → files as text) and a thin writer. The keys and their
//! meaning: ptp4l(8), phc2sys(8), timemaster(8) of linuxptp; the attributes (domainNumber,
//! priority1, clockClass, timeSource): IEEE 1588-2019, 7.1, 7.6.2. docs/guide/timing.md says how
//! to run it and what software time stamping cannot do.

use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::{Context, Result};

/// What this machine is in the PTP domain.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Role {
    /// The domain's time base: its ports are master only (navsync's machine).
    Grandmaster,
    /// Follows the grandmaster: slave only (the vehicle's other machines, or a test).
    Slave,
}

/// Where packets are time-stamped.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Timestamping {
    /// By the NIC at the wire, against its PTP hardware clock (PHC): sub-µs.
    Hardware,
    /// By the kernel's network stack, against the system clock: tens of µs.
    Software,
}

/// How PTP messages travel.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Transport {
    /// UDP over IPv4 (IEEE 1588 Annex C): the default profile, what LiDARs and cameras speak.
    Udpv4,
    /// Raw Ethernet (IEEE 1588 Annex F), as automotive networks use; still end-to-end delay
    /// and IEEE 1588, not the 802.1AS (gPTP) profile.
    L2,
}

/// `navsync ptp-config`.
#[derive(clap::Args, Debug)]
pub struct Options {
    /// Network interface ptp4l runs a port on (repeat for more ports; each name as `ip link`
    /// shows it).
    #[arg(long = "interface", value_name = "IFACE", required = true)]
    pub interfaces: Vec<String>,
    /// grandmaster: the domain's time base, from this machine's disciplined system clock;
    /// slave: follows the grandmaster.
    #[arg(long, value_enum, default_value_t = Role::Grandmaster)]
    pub role: Role,
    /// hardware: the NIC's PTP hardware clock stamps packets (sub-µs; phc2sys feeds it from the
    /// system clock); software: the kernel stamps them against the system clock (tens of µs).
    #[arg(long, value_enum, default_value_t = Timestamping::Hardware)]
    pub timestamping: Timestamping,
    /// PTP domain number (0..=127): every clock of the vehicle network in the same one.
    #[arg(long, value_name = "N", default_value_t = 0)]
    pub domain: u32,
    /// priority1 (0..=255, lower wins, compared before the clock class) [default: 128 for the
    /// grandmaster, IEEE 1588's default, 255 for a slave].
    #[arg(long, value_name = "N")]
    pub priority1: Option<u8>,
    /// udpv4: UDP/IPv4, the IEEE 1588 default profile most sensors speak; l2: raw Ethernet.
    #[arg(long, value_enum, default_value_t = Transport::Udpv4)]
    pub transport: Transport,
    /// ptp4l never adjusts its clock (`free_running 1`): a slave only measures and reports its
    /// offset. Always so for a grandmaster with software time stamping.
    #[arg(long)]
    pub free_running: bool,
    /// Write the files into DIR (created if missing) instead of printing them.
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
}

/// A flag value the generator refuses.
#[derive(Debug, PartialEq, Eq, thiserror::Error)]
pub enum PtpConfigError {
    /// Not a usable interface name.
    #[error("--interface {name:?}: {why}")]
    Interface {
        /// The name given.
        name: String,
        /// What is wrong with it.
        why: &'static str,
    },
    /// The same interface twice.
    #[error("--interface {0} is given twice")]
    DuplicateInterface(String),
    /// Outside IEEE 1588-2019's domain numbers for users.
    #[error("--domain {0}: a PTP domain number is 0..=127 (IEEE 1588-2019, 7.1)")]
    Domain(u32),
}

/// Checks a Linux interface name (shorter than IFNAMSIZ = 16) and keeps to the characters
/// interface and systemd unit names share, so that it can name a ptp4l section and a unit.
fn check_interface(name: &str) -> Result<(), PtpConfigError> {
    let why = if name.is_empty() {
        Some("empty")
    } else if name.len() > 15 {
        Some("longer than 15 characters (IFNAMSIZ)")
    } else if name == "." || name == ".." {
        Some("not an interface name")
    } else if !name.bytes().all(|b| b.is_ascii_alphanumeric() || b"._-".contains(&b)) {
        Some("only letters, digits, '.', '_' and '-' are taken")
    } else {
        None
    };
    why.map_or(Ok(()), |why| {
        Err(PtpConfigError::Interface {
            name: name.to_string(),
            why,
        })
    })
}

/// One `key value` line of a ptp4l configuration, with its comment above it.
fn key(out: &mut String, comment: &str, key: &str, value: impl std::fmt::Display) {
    for line in comment.lines() {
        let _ = writeln!(out, "# {line}");
    }
    let _ = writeln!(out, "{key:<24}{value}");
}

/// The files for `o`: (file name, text), ptp4l.conf first.
pub fn generate(o: &Options) -> Result<Vec<(String, String)>, PtpConfigError> {
    for (i, name) in o.interfaces.iter().enumerate() {
        check_interface(name)?;
        if o.interfaces[..i].contains(name) {
            return Err(PtpConfigError::DuplicateInterface(name.clone()));
        }
    }
    if o.domain > 127 {
        return Err(PtpConfigError::Domain(o.domain));
    }
    let gm = o.role == Role::Grandmaster;
    let hw = o.timestamping == Timestamping::Hardware;
    let ifaces = o.interfaces.join(" ");
    let mut c = String::new();
    let _ = writeln!(
        c,
        "# ptp4l.conf by `navsync ptp-config`: {} on {ifaces}, {} time stamping.\n\
         # Keys: ptp4l(8); attributes: IEEE 1588-2019. Install as /etc/linuxptp/ptp4l.conf and run\n\
         # Debian's ptp4l@{first}.service (ptp4l -f /etc/linuxptp/ptp4l.conf -i {first}).",
        if gm { "grandmaster" } else { "slave" },
        if hw { "hardware" } else { "software" },
        first = o.interfaces[0],
    );
    if gm {
        c.push_str(if hw {
            "# Chain: navsync -> chrony -> system clock (UTC) -> phc2sys (navsync-phc2sys-*.service)\n\
             # -> the NIC's PHC (PTP time scale) -> ptp4l -> the network.\n"
        } else {
            "# Chain: navsync -> chrony -> system clock -> ptp4l (kernel time stamps) -> the network;\n\
             # no phc2sys: the system clock is the clock ptp4l stamps against.\n"
        });
        c.push_str(
            "# timemaster(8) composes ptp4l and phc2sys only for slaves (its ptp4l runs slaveOnly and\n\
             # feeds chronyd), so a grandmaster runs them directly as written here.\n",
        );
    }
    c.push_str("\n[global]\n");
    key(
        &mut c,
        "Two-step: Follow_Up carries the Sync's time; one-step needs NIC support.",
        "twoStepFlag",
        1,
    );
    key(
        &mut c,
        "The vehicle network's domain (0..=127).",
        "domainNumber",
        o.domain,
    );
    let p1 = o.priority1.unwrap_or(if gm { 128 } else { 255 });
    key(
        &mut c,
        "Best master clock algorithm: lower wins, before clockClass.",
        "priority1",
        p1,
    );
    // IEEE 1588-2019 Table 4 (clockClass) and Table 6 (timeSource).
    let class_comment = "IEEE 1588-2019 clockClass: 6 synchronized to a primary reference (GNSS), PTP time scale;\n\
         7 was 6, now in holdover within specification; 13 as 6 with an application-specific\n\
         (ARB) time scale, which is what ptp4l announces with software time stamping (UTC);\n\
         248 the default (none of these); 255 slave only. Static: ptp4l keeps announcing it when\n\
         GNSS is lost (`pmc 'SET GRANDMASTER_SETTINGS_NP'` changes it at run time).";
    if gm {
        key(&mut c, class_comment, "clockClass", if hw { 6 } else { 13 });
        key(
            &mut c,
            "IEEE 1588-2019 timeSource 0x20: GNSS (informational).",
            "timeSource",
            "0x20",
        );
    } else {
        key(
            &mut c,
            "A slave-only clock (IEEE 1588-2019 clockClass 255).",
            "slaveOnly",
            1,
        );
        key(&mut c, class_comment, "clockClass", 255);
    }
    key(
        &mut c,
        if hw {
            "The NIC stamps at the wire against its PTP hardware clock."
        } else {
            "The kernel stamps against the system clock: tens of µs of stack and driver latency."
        },
        "time_stamping",
        if hw { "hardware" } else { "software" },
    );
    key(
        &mut c,
        "UDPv4 (IEEE 1588 Annex C) or L2 (Ethernet, Annex F).",
        "network_transport",
        match o.transport {
            Transport::Udpv4 => "UDPv4",
            Transport::L2 => "L2",
        },
    );
    key(&mut c, "Delay request-response, end to end.", "delay_mechanism", "E2E");
    if hw && o.interfaces.len() > 1 {
        key(
            &mut c,
            "Ports on NICs with separate PHCs (each fed from the system clock).",
            "boundary_clock_jbod",
            1,
        );
    }
    let free = o.free_running || (gm && !hw);
    let free_comment = match (free, gm) {
        (true, true) => {
            "1: ptp4l never touches the system clock, which chronyd disciplines (with 0 it\nwould read and rewrite its frequency and leap state at start)."
        }
        (true, false) => {
            "1: ptp4l never adjusts the clock (\"Don't adjust the local clock\", ptp4l(8)):\nit only measures and reports the offset to the master."
        }
        (false, true) => "0: ptp4l holds the PHC that phc2sys steers; masterOnly keeps it from steering it.",
        (false, false) => {
            "0: ptp4l steers its clock to the master (the PHC with hardware time stamping,\nthe system clock with software)."
        }
    };
    key(&mut c, free_comment, "free_running", u8::from(free));
    for iface in &o.interfaces {
        let _ = writeln!(c, "\n[{iface}]");
        if gm {
            key(
                &mut c,
                "Never a slave, and deaf to other masters' Announce: this is the time base.",
                "masterOnly",
                1,
            );
        }
    }
    let mut files = vec![("ptp4l.conf".to_string(), c)];
    if gm && hw {
        for iface in &o.interfaces {
            files.push((
                format!("navsync-phc2sys-{iface}.service"),
                phc2sys_unit(iface, &o.interfaces[0], o.domain),
            ));
        }
    }
    if !gm {
        files.push(("timemaster.conf".to_string(), timemaster_conf(o, &ifaces)));
    }
    Ok(files)
}

/// The systemd unit that keeps `iface`'s PHC on the system clock (phc2sys(8)).
fn phc2sys_unit(iface: &str, first: &str, domain: u32) -> String {
    format!(
        "# navsync-phc2sys-{iface}.service by `navsync ptp-config`: {iface}'s PTP hardware clock follows\n\
         # the system clock, which chronyd disciplines from navsync. Install in /etc/systemd/system.\n\
         # -s CLOCK_REALTIME the source, -c {iface} the PHC; -w waits for ptp4l and takes TAI - UTC\n\
         # (37 s since 2017) from it, so that the PHC keeps the PTP time scale (phc2sys(8), TIME\n\
         # SCALE USAGE); `-O 37` would fix it by hand, and `-O 0` would put UTC into the PHC, 37 s\n\
         # off for every slave on the PTP time scale.\n\
         [Unit]\n\
         Description=PHC of {iface} from the system clock (phc2sys)\n\
         Documentation=man:phc2sys(8)\n\
         Requires=ptp4l@{first}.service\n\
         After=ptp4l@{first}.service chrony.service\n\
         \n\
         [Service]\n\
         ExecStart=/usr/sbin/phc2sys -s CLOCK_REALTIME -c {iface} -w -n {domain} -m -q\n\
         Restart=on-failure\n\
         \n\
         [Install]\n\
         WantedBy=multi-user.target\n"
    )
}

/// timemaster.conf for a slave machine whose chronyd takes PTP as one reference (timemaster(8)).
fn timemaster_conf(o: &Options, ifaces: &str) -> String {
    let transport = match o.transport {
        Transport::Udpv4 => "UDPv4",
        Transport::L2 => "L2",
    };
    format!(
        "# timemaster.conf by `navsync ptp-config --role slave`: instead of ptp4l.conf on a machine\n\
         # whose chronyd should take the vehicle's PTP time as a reference clock. timemaster(8) starts\n\
         # ptp4l (slaveOnly; hardware time stamping where the NIC has a PHC, then phc2sys too), hands\n\
         # their offsets to chronyd through NTP SHM refclocks and runs chronyd itself.\n\
         [ptp_domain {domain}]\n\
         interfaces {ifaces}\n\
         \n\
         [ptp4l.conf]\n\
         network_transport {transport}\n\
         delay_mechanism E2E\n\
         \n\
         [timemaster]\n\
         ntp_program chronyd\n",
        domain = o.domain
    )
}

/// Prints the files, or writes them into `--out DIR`.
pub fn run(o: &Options) -> Result<()> {
    let files = generate(o)?;
    let Some(dir) = &o.out else {
        for (name, text) in &files {
            println!("# ---- {name} ----\n{text}");
        }
        return Ok(());
    };
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    for (name, text) in &files {
        let path = dir.join(name);
        std::fs::write(&path, text).with_context(|| format!("writing {}", path.display()))?;
        println!("{}", path.display());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn opts(ifaces: &[&str], role: Role, ts: Timestamping) -> Options {
        Options {
            interfaces: ifaces.iter().map(|s| s.to_string()).collect(),
            role,
            timestamping: ts,
            domain: 0,
            priority1: None,
            transport: Transport::Udpv4,
            free_running: false,
            out: None,
        }
    }

    /// The value of `key` in `section` of a ptp4l-style file (comments skipped).
    fn value(text: &str, section: &str, key: &str) -> Option<String> {
        let mut here = false;
        for line in text.lines().filter(|l| !l.starts_with('#')) {
            if let Some(s) = line.strip_prefix('[') {
                here = s.trim_end_matches(']') == section;
            } else if here && let Some(v) = line.strip_prefix(key).filter(|v| v.starts_with(' ')) {
                return Some(v.trim().to_string());
            }
        }
        None
    }

    #[test]
    fn a_hardware_grandmaster_is_gnss_class_master_only_and_fed_by_phc2sys() {
        let files = generate(&opts(&["eth0"], Role::Grandmaster, Timestamping::Hardware)).unwrap();
        let conf = &files[0].1;
        for (k, v) in [
            ("twoStepFlag", "1"),
            ("domainNumber", "0"),
            ("priority1", "128"),
            ("clockClass", "6"),
            ("timeSource", "0x20"),
            ("time_stamping", "hardware"),
            ("network_transport", "UDPv4"),
            ("free_running", "0"),
        ] {
            assert_eq!(value(conf, "global", k).as_deref(), Some(v), "{k}");
        }
        assert_eq!(value(conf, "eth0", "masterOnly").as_deref(), Some("1"));
        assert_eq!(value(conf, "global", "slaveOnly"), None);
        assert_eq!(files[1].0, "navsync-phc2sys-eth0.service");
        assert!(
            files[1]
                .1
                .contains("ExecStart=/usr/sbin/phc2sys -s CLOCK_REALTIME -c eth0 -w -n 0 -m -q\n")
        );
        assert_eq!(files.len(), 2);
    }

    #[test]
    fn a_software_grandmaster_never_touches_the_clock_and_needs_no_phc2sys() {
        let files = generate(&opts(&["veth0"], Role::Grandmaster, Timestamping::Software)).unwrap();
        let conf = &files[0].1;
        assert_eq!(value(conf, "global", "time_stamping").as_deref(), Some("software"));
        assert_eq!(value(conf, "global", "free_running").as_deref(), Some("1"));
        assert_eq!(value(conf, "global", "clockClass").as_deref(), Some("13"));
        assert_eq!(files.len(), 1);
    }

    #[test]
    fn a_slave_is_slave_only_free_running_on_request_with_a_timemaster_alternative() {
        let mut o = opts(&["vethb"], Role::Slave, Timestamping::Software);
        o.transport = Transport::L2;
        o.domain = 24;
        let steer = generate(&o).unwrap();
        assert_eq!(value(&steer[0].1, "global", "free_running").as_deref(), Some("0"));
        o.free_running = true;
        let files = generate(&o).unwrap();
        let conf = &files[0].1;
        for (k, v) in [
            ("slaveOnly", "1"),
            ("priority1", "255"),
            ("clockClass", "255"),
            ("free_running", "1"),
            ("network_transport", "L2"),
            ("domainNumber", "24"),
        ] {
            assert_eq!(value(conf, "global", k).as_deref(), Some(v), "{k}");
        }
        assert!(conf.contains("\n[vethb]\n") && value(conf, "vethb", "masterOnly").is_none());
        assert_eq!(files[1].0, "timemaster.conf");
        assert!(files[1].1.contains("[ptp_domain 24]\ninterfaces vethb\n"));
    }

    #[test]
    fn several_hardware_ports_get_jbod_and_a_phc2sys_each() {
        let mut o = opts(&["eth0", "eth1"], Role::Grandmaster, Timestamping::Hardware);
        o.priority1 = Some(10);
        let files = generate(&o).unwrap();
        assert_eq!(
            value(&files[0].1, "global", "boundary_clock_jbod").as_deref(),
            Some("1")
        );
        assert_eq!(value(&files[0].1, "global", "priority1").as_deref(), Some("10"));
        assert_eq!(value(&files[0].1, "eth1", "masterOnly").as_deref(), Some("1"));
        assert!(files[2].1.contains("-c eth1 ") && files[2].1.contains("Requires=ptp4l@eth0.service"));
    }

    #[test]
    fn bad_values_are_refused_with_what_is_wrong() {
        let gm = |ifaces: &[&str]| generate(&opts(ifaces, Role::Grandmaster, Timestamping::Hardware));
        for (name, why) in [
            ("", "empty"),
            ("a_very_long_name0", "longer than 15 characters (IFNAMSIZ)"),
            ("eth 0", "only letters, digits, '.', '_' and '-' are taken"),
            ("eth0]", "only letters, digits, '.', '_' and '-' are taken"),
            ("..", "not an interface name"),
        ] {
            assert_eq!(
                gm(&[name]).unwrap_err(),
                PtpConfigError::Interface {
                    name: name.to_string(),
                    why
                }
            );
        }
        assert_eq!(
            gm(&["eth0", "eth0"]).unwrap_err().to_string(),
            "--interface eth0 is given twice"
        );
        let mut o = opts(&["eth0"], Role::Grandmaster, Timestamping::Hardware);
        o.domain = 128;
        assert_eq!(
            generate(&o).unwrap_err().to_string(),
            "--domain 128: a PTP domain number is 0..=127 (IEEE 1588-2019, 7.1)"
        );
    }
}
