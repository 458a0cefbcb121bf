//! The RFC 2783 ioctl structures and request numbers of `drivers/src/pps/kernel.rs` against the
//! system's `linux/pps.h`: a tiny C program compiled with `cc` prints sizeof/offsetof of every
//! structure and the ioctl numbers (which encode `sizeof(struct pps_fdata *)`, a pointer), and
//! this test compares them with the Rust definitions. Also `struct serial_icounter_struct`
//! (`linux/serial.h`) and the modem-line ioctls of the serial-DCD source.

use std::mem::offset_of;
use std::path::Path;
use std::process::Command;

use navsync_drivers::pps::kernel::*;
use navsync_drivers::pps::serial_dcd::SerialIcounter;

const PROGRAM: &str = r#"
#include <stdio.h>
#include <stddef.h>
#include <sys/ioctl.h>
#include <linux/pps.h>
#include <linux/serial.h>
#define S(t) printf(#t " size %zu\n", sizeof(struct t))
#define O(t, f) printf(#t "." #f " %zu\n", offsetof(struct t, f))
int main(void) {
    S(pps_ktime); O(pps_ktime, sec); O(pps_ktime, nsec); O(pps_ktime, flags);
    S(pps_kinfo); O(pps_kinfo, assert_sequence); O(pps_kinfo, clear_sequence);
    O(pps_kinfo, assert_tu); O(pps_kinfo, clear_tu); O(pps_kinfo, current_mode);
    S(pps_kparams); O(pps_kparams, api_version); O(pps_kparams, mode);
    O(pps_kparams, assert_off_tu); O(pps_kparams, clear_off_tu);
    S(pps_fdata); O(pps_fdata, info); O(pps_fdata, timeout);
    S(serial_icounter_struct); O(serial_icounter_struct, dcd); O(serial_icounter_struct, cts);
    printf("PPS_GETPARAMS %lu\n", (unsigned long)PPS_GETPARAMS);
    printf("PPS_SETPARAMS %lu\n", (unsigned long)PPS_SETPARAMS);
    printf("PPS_GETCAP %lu\n", (unsigned long)PPS_GETCAP);
    printf("PPS_FETCH %lu\n", (unsigned long)PPS_FETCH);
    printf("PPS_CAPTUREASSERT %d\n", PPS_CAPTUREASSERT);
    printf("PPS_CANWAIT %d\n", PPS_CANWAIT);
    printf("PPS_TSFMT_TSPEC %d\n", PPS_TSFMT_TSPEC);
    printf("PPS_TIME_INVALID %d\n", PPS_TIME_INVALID);
    printf("PPS_API_VERS_1 %d\n", PPS_API_VERS_1);
    printf("TIOCMIWAIT %lu\n", (unsigned long)TIOCMIWAIT);
    printf("TIOCGICOUNT %lu\n", (unsigned long)TIOCGICOUNT);
    return 0;
}
"#;

#[test]
fn rust_definitions_match_linux_pps_h() {
    let header = Path::new("/usr/include/linux/pps.h");
    assert!(
        header.exists(),
        "{} is missing: install the Linux API headers (Debian: linux-libc-dev)",
        header.display()
    );
    let dir = std::env::temp_dir().join(format!("navsync-pps-abi-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("scratch dir");
    let src = dir.join("abi.c");
    let exe = dir.join("abi");
    std::fs::write(&src, PROGRAM).expect("write C source");
    let out = Command::new("cc")
        .arg(&src)
        .arg("-o")
        .arg(&exe)
        .output()
        .expect("running cc (a C compiler is needed for this test)");
    assert!(
        out.status.success(),
        "cc failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let run = Command::new(&exe).output().expect("running the ABI probe");
    let _ = std::fs::remove_dir_all(&dir);
    assert!(run.status.success());
    let text = String::from_utf8(run.stdout).expect("utf-8");
    let c = |key: &str| -> u64 {
        text.lines()
            .find_map(|l| {
                let (k, v) = l.rsplit_once(' ')?;
                if k == key { v.parse().ok() } else { None }
            })
            .unwrap_or_else(|| panic!("{key} not printed:\n{text}"))
    };
    let rust: Vec<(&str, u64)> = vec![
        ("pps_ktime size", size_of::<PpsKtime>() as u64),
        ("pps_ktime.sec", offset_of!(PpsKtime, sec) as u64),
        ("pps_ktime.nsec", offset_of!(PpsKtime, nsec) as u64),
        ("pps_ktime.flags", offset_of!(PpsKtime, flags) as u64),
        ("pps_kinfo size", size_of::<PpsKinfo>() as u64),
        (
            "pps_kinfo.assert_sequence",
            offset_of!(PpsKinfo, assert_sequence) as u64,
        ),
        ("pps_kinfo.clear_sequence", offset_of!(PpsKinfo, clear_sequence) as u64),
        ("pps_kinfo.assert_tu", offset_of!(PpsKinfo, assert_tu) as u64),
        ("pps_kinfo.clear_tu", offset_of!(PpsKinfo, clear_tu) as u64),
        ("pps_kinfo.current_mode", offset_of!(PpsKinfo, current_mode) as u64),
        ("pps_kparams size", size_of::<PpsKparams>() as u64),
        ("pps_kparams.api_version", offset_of!(PpsKparams, api_version) as u64),
        ("pps_kparams.mode", offset_of!(PpsKparams, mode) as u64),
        (
            "pps_kparams.assert_off_tu",
            offset_of!(PpsKparams, assert_off_tu) as u64,
        ),
        ("pps_kparams.clear_off_tu", offset_of!(PpsKparams, clear_off_tu) as u64),
        ("pps_fdata size", size_of::<PpsFdata>() as u64),
        ("pps_fdata.info", offset_of!(PpsFdata, info) as u64),
        ("pps_fdata.timeout", offset_of!(PpsFdata, timeout) as u64),
        ("serial_icounter_struct size", size_of::<SerialIcounter>() as u64),
        ("serial_icounter_struct.dcd", offset_of!(SerialIcounter, dcd) as u64),
        ("serial_icounter_struct.cts", offset_of!(SerialIcounter, cts) as u64),
        ("PPS_GETPARAMS", PPS_GETPARAMS),
        ("PPS_SETPARAMS", PPS_SETPARAMS),
        ("PPS_GETCAP", PPS_GETCAP),
        ("PPS_FETCH", PPS_FETCH),
        ("PPS_CAPTUREASSERT", PPS_CAPTUREASSERT as u64),
        ("PPS_CANWAIT", PPS_CANWAIT as u64),
        ("PPS_TSFMT_TSPEC", PPS_TSFMT_TSPEC as u64),
        ("PPS_TIME_INVALID", PPS_TIME_INVALID as u64),
        ("PPS_API_VERS_1", PPS_API_VERS_1 as u64),
        ("TIOCMIWAIT", libc::TIOCMIWAIT),
        ("TIOCGICOUNT", libc::TIOCGICOUNT),
    ];
    let mismatches: Vec<String> = rust
        .iter()
        .filter(|(k, v)| c(k) != *v)
        .map(|(k, v)| format!("{k}: Rust {v}, C {}", c(k)))
        .collect();
    assert!(mismatches.is_empty(), "ABI mismatches:\n{}", mismatches.join("\n"));
    // The ioctl size field is the pointer's, not the structure's (the header's quirk).
    assert_eq!((PPS_FETCH >> 16) & 0x3fff, size_of::<*mut PpsFdata>() as u64);
}
