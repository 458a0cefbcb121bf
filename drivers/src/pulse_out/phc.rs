//! `phc:/dev/ptpN:CHANNEL[:PIN]`: a PTP hardware clock's periodic output (Linux
//! `include/uapi/linux/ptp_clock.h`, Documentation/driver-api/ptp.rst).
//!
//! Programmed once: `PTP_PEROUT_REQUEST2` on channel `CHANNEL` with a period of 1 s starting at
//! a whole second of the PHC's own time, and a pulse width (`PTP_PEROUT_DUTY_CYCLE`) where the
//! driver takes one (else the driver's own width). From then on the NIC's counter times every
//! edge, ns-level and independent of any process's scheduling: the edges are on whole
//! seconds of the PHC's time, so they are on GNSS seconds exactly as far as the PHC keeps GNSS
//! time. That is phc2sys's job (`phc2sys -s CLOCK_REALTIME -c IFACE -w`, the system clock
//! disciplined by chrony from navsync's refclock: docs/guide/timing.md, "PTP for the vehicle
//! network"). With `-w` the PHC keeps TAI, whose seconds begin with UTC's (TAI − UTC is a
//! whole number of seconds), so its whole seconds are GNSS whole seconds.
//!
//! `PIN`, when given, first routes the channel to that programmable pin (`PTP_PIN_SETFUNC2`,
//! function `PTP_PF_PEROUT`), as `testptp -L PIN,2` does; NICs with fixed-function outputs
//! need none. The `…2` requests (Linux ≥ 5.8) check that reserved fields are zero. Dropping a
//! programmed [`PhcPeriodic`] stops the output (a zero period): the output is the process's.
//!
//! Not exercised on the development machine: it has no PHC; opening a device that is not
//! there is [`PulseOutError::Missing`].

use std::fs::{File, OpenOptions};
use std::os::fd::AsRawFd;
use std::path::Path;

use navsync_shared::time::{NS_PER_S, monotonic_now_ns};

use super::{PulseOutError, require_device};
use crate::pps::kernel::ioc;

/// `struct ptp_clock_time`: seconds (signed, the sign applies to the whole value) and
/// nanoseconds of a PHC time or duration.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PtpClockTime {
    /// Seconds.
    pub sec: i64,
    /// Nanoseconds, 0..1e9.
    pub nsec: u32,
    /// Reserved, zero.
    pub reserved: u32,
}

impl PtpClockTime {
    /// `ns` (≥ 0) as seconds and nanoseconds.
    pub fn from_ns(ns: i64) -> Self {
        Self {
            sec: ns.div_euclid(NS_PER_S),
            nsec: ns.rem_euclid(NS_PER_S) as u32,
            reserved: 0,
        }
    }
}

/// `struct ptp_perout_request` (56 bytes): `PTP_PEROUT_REQUEST2`'s argument.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PtpPeroutRequest {
    /// Absolute start time on the PHC (the union's `start`; `phase` with `PTP_PEROUT_PHASE`).
    pub start: PtpClockTime,
    /// Period; zero disables the output.
    pub period: PtpClockTime,
    /// The periodic output channel, below `ptp_clock_caps.n_per_out`.
    pub index: u32,
    /// `PTP_PEROUT_*` flags.
    pub flags: u32,
    /// The pulse's high time with [`PTP_PEROUT_DUTY_CYCLE`] (the union's `on`), else zero
    /// (the union's `rsv[4]`).
    pub on: PtpClockTime,
}

/// `struct ptp_pin_desc` (96 bytes): `PTP_PIN_SETFUNC2`'s argument.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PtpPinDesc {
    /// The pin's name (set by the kernel on `PTP_PIN_GETFUNC`, ignored on set).
    pub name: [u8; 64],
    /// Pin index, below `ptp_clock_caps.n_pins`.
    pub index: u32,
    /// `PTP_PF_*` function.
    pub func: u32,
    /// The function's channel (the `index` of `PTP_PEROUT_REQUEST2`).
    pub chan: u32,
    /// Reserved, zero.
    pub rsv: [u32; 5],
}

/// `struct ptp_clock_caps` (80 bytes): what the PHC has (`PTP_CLOCK_GETCAPS2`).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PtpClockCaps {
    /// Largest frequency adjustment, ppb.
    pub max_adj: i32,
    /// Programmable alarms.
    pub n_alarm: i32,
    /// External time stamp channels.
    pub n_ext_ts: i32,
    /// Programmable periodic outputs.
    pub n_per_out: i32,
    /// Whether the clock has a PPS callback.
    pub pps: i32,
    /// Programmable pins.
    pub n_pins: i32,
    /// Precise system/device cross time stamps.
    pub cross_timestamping: i32,
    /// Phase adjustment.
    pub adjust_phase: i32,
    /// `max_phase_adj` and reserved fields (newer kernels take more from here).
    pub rsv: [i32; 12],
}

const IOC_WRITE: u64 = 1;
const IOC_READ: u64 = 2;
/// `PTP_CLK_MAGIC`.
const PTP_CLK_MAGIC: u8 = b'=';
/// `_IOR(PTP_CLK_MAGIC, 10, struct ptp_clock_caps)`.
pub const PTP_CLOCK_GETCAPS2: u64 = ioc(IOC_READ, PTP_CLK_MAGIC, 10, size_of::<PtpClockCaps>());
/// `_IOW(PTP_CLK_MAGIC, 12, struct ptp_perout_request)`.
pub const PTP_PEROUT_REQUEST2: u64 = ioc(IOC_WRITE, PTP_CLK_MAGIC, 12, size_of::<PtpPeroutRequest>());
/// `_IOW(PTP_CLK_MAGIC, 16, struct ptp_pin_desc)`.
pub const PTP_PIN_SETFUNC2: u64 = ioc(IOC_WRITE, PTP_CLK_MAGIC, 16, size_of::<PtpPinDesc>());
/// `PTP_PEROUT_DUTY_CYCLE`: `on` holds the high time.
pub const PTP_PEROUT_DUTY_CYCLE: u32 = 1 << 1;
/// `PTP_PF_PEROUT` of `enum ptp_pin_function`.
pub const PTP_PF_PEROUT: u32 = 2;

/// The first start the output is programmed for: a whole second of the PHC's time at least
/// one second after `phc_now_ns`, so that the request reaches the driver before it (some
/// drivers refuse a start in the past, others start at once, off the second). Pure.
pub fn first_start_s(phc_now_ns: i64) -> i64 {
    phc_now_ns.div_euclid(NS_PER_S) + 2
}

/// The request for one pulse a second on `channel` from whole second `start_s`, `width_ns`
/// high when given (else the driver's width); `None` disables the channel. Pure.
pub fn perout_request(channel: u32, start_s: Option<i64>, width_ns: Option<i64>) -> PtpPeroutRequest {
    let Some(start_s) = start_s else {
        return PtpPeroutRequest {
            index: channel,
            ..Default::default()
        };
    };
    PtpPeroutRequest {
        start: PtpClockTime {
            sec: start_s,
            ..Default::default()
        },
        period: PtpClockTime::from_ns(NS_PER_S),
        index: channel,
        flags: if width_ns.is_some() { PTP_PEROUT_DUTY_CYCLE } else { 0 },
        on: width_ns.map(PtpClockTime::from_ns).unwrap_or_default(),
    }
}

/// How far the PHC's second boundaries are from GNSS time's, ns, in [−0.5 s, 0.5 s): PHC
/// time minus GNSS time of one instant, whole seconds taken out (the PHC's TAI or UTC scale
/// alike). Positive: the PHC is ahead, its edges come early. Pure.
pub fn phase_error_ns(phc_ns: i64, gnss_ns: i64) -> i64 {
    (phc_ns - gnss_ns + NS_PER_S / 2).rem_euclid(NS_PER_S) - NS_PER_S / 2
}

/// What [`PhcPeriodic::program`] set up.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Programmed {
    /// The first edge, whole seconds of the PHC's time.
    pub start_s: i64,
    /// The pulse width the driver took; `None`: it has no duty-cycle control and uses its own.
    pub width_ns: Option<i64>,
}

/// A PTP hardware clock's periodic output channel.
pub struct PhcPeriodic {
    file: File,
    path: String,
    channel: u32,
    pin: Option<u32>,
    programmed: bool,
}

impl PhcPeriodic {
    /// Opens `device` (`/dev/ptpN`, read-write: the kernel refuses output requests on a
    /// read-only descriptor) and checks that it has periodic output `channel` (and `pin`).
    pub fn open(device: &Path, channel: u32, pin: Option<u32>) -> Result<Self, PulseOutError> {
        require_device(
            device,
            "a PTP hardware clock, /dev/ptpN, of a NIC with hardware time stamping",
        )?;
        let path = device.display().to_string();
        let file = OpenOptions::new()
            .read(true)
            .write(true)
            .open(device)
            .map_err(|source| PulseOutError::Open {
                path: path.clone(),
                source,
            })?;
        let out = Self {
            file,
            path,
            channel,
            pin,
            programmed: false,
        };
        let mut caps = PtpClockCaps::default();
        out.ioctl("PTP_CLOCK_GETCAPS2", PTP_CLOCK_GETCAPS2, &mut caps)?;
        if i64::from(channel) >= i64::from(caps.n_per_out) {
            return Err(out.unsupported(format!(
                "periodic output channel {channel} asked, the clock has {} (n_per_out)",
                caps.n_per_out
            )));
        }
        if let Some(p) = pin
            && i64::from(p) >= i64::from(caps.n_pins)
        {
            return Err(out.unsupported(format!("pin {p} asked, the clock has {} (n_pins)", caps.n_pins)));
        }
        Ok(out)
    }

    fn unsupported(&self, what: String) -> PulseOutError {
        PulseOutError::Unsupported {
            path: self.path.clone(),
            what,
        }
    }

    fn ioctl<T>(&self, what: &'static str, request: u64, arg: &mut T) -> Result<(), PulseOutError> {
        // SAFETY: `request` encodes `size_of::<T>()` and T is the `#[repr(C)]` structure the
        // request takes; the descriptor is open for the duration of the call.
        let rc = unsafe { libc::ioctl(self.file.as_raw_fd(), request as _, arg as *mut T) };
        if rc < 0 {
            return Err(PulseOutError::Ioctl {
                what,
                path: self.path.clone(),
                source: std::io::Error::last_os_error(),
            });
        }
        Ok(())
    }

    /// The PHC as a POSIX clock (`FD_TO_CLOCKID`: `(~fd << 3) | CLOCKFD`).
    fn clock_id(&self) -> libc::clockid_t {
        const CLOCKFD: libc::clockid_t = 3;
        (!(self.file.as_raw_fd() as libc::clockid_t) << 3) | CLOCKFD
    }

    /// The PHC's time now, ns (its own scale: TAI under `phc2sys -w`).
    pub fn now_ns(&self) -> Result<i64, PulseOutError> {
        let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
        // SAFETY: a valid, writable timespec; the clock id names our open descriptor.
        if unsafe { libc::clock_gettime(self.clock_id(), &mut ts) } != 0 {
            return Err(PulseOutError::Ioctl {
                what: "clock_gettime",
                path: self.path.clone(),
                source: std::io::Error::last_os_error(),
            });
        }
        Ok(ts.tv_sec * NS_PER_S + ts.tv_nsec)
    }

    /// One instant on both clocks: `(host_ns, phc_ns)`, host time the middle of the
    /// `CLOCK_MONOTONIC` readings around the PHC's (a PHC read through the NIC's bus takes
    /// µs; the tightest of three brackets).
    pub fn read_against_host(&self) -> Result<(i64, i64), PulseOutError> {
        let mut best = (i64::MAX, 0, 0);
        for _ in 0..3 {
            let a = monotonic_now_ns();
            let phc = self.now_ns()?;
            let b = monotonic_now_ns();
            if b - a < best.0 {
                best = (b - a, a + (b - a) / 2, phc);
            }
        }
        Ok((best.1, best.2))
    }

    /// Routes the channel to its pin (when one was given) and starts one pulse a second,
    /// `width_ns` high, from the first whole PHC second at least a second ahead. A driver
    /// without duty-cycle control (`EOPNOTSUPP`, `EINVAL` for the flag) gets the request
    /// again without it and keeps its own width.
    pub fn program(&mut self, width_ns: i64) -> Result<Programmed, PulseOutError> {
        if let Some(pin) = self.pin {
            let mut desc = PtpPinDesc {
                name: [0; 64],
                index: pin,
                func: PTP_PF_PEROUT,
                chan: self.channel,
                rsv: [0; 5],
            };
            self.ioctl("PTP_PIN_SETFUNC2", PTP_PIN_SETFUNC2, &mut desc)?;
        }
        let start_s = first_start_s(self.now_ns()?);
        let mut req = perout_request(self.channel, Some(start_s), Some(width_ns));
        let width_ns = match self.ioctl("PTP_PEROUT_REQUEST2", PTP_PEROUT_REQUEST2, &mut req) {
            Ok(()) => Some(width_ns),
            Err(PulseOutError::Ioctl { source, .. })
                if matches!(source.raw_os_error(), Some(libc::EOPNOTSUPP | libc::EINVAL)) =>
            {
                let mut req = perout_request(self.channel, Some(start_s), None);
                self.ioctl("PTP_PEROUT_REQUEST2", PTP_PEROUT_REQUEST2, &mut req)?;
                None
            }
            Err(e) => return Err(e),
        };
        self.programmed = true;
        Ok(Programmed { start_s, width_ns })
    }

    /// Stops the output (period zero).
    pub fn stop(&mut self) -> Result<(), PulseOutError> {
        let mut req = perout_request(self.channel, None, None);
        self.ioctl("PTP_PEROUT_REQUEST2", PTP_PEROUT_REQUEST2, &mut req)?;
        self.programmed = false;
        Ok(())
    }

    /// The output in words, for logs.
    pub fn describe(&self) -> String {
        match self.pin {
            Some(p) => format!("PHC {} periodic output {} on pin {p}", self.path, self.channel),
            None => format!("PHC {} periodic output {}", self.path, self.channel),
        }
    }
}

impl Drop for PhcPeriodic {
    fn drop(&mut self) {
        if self.programmed {
            let _ = self.stop();
        }
    }
}

#[cfg(test)]
mod tests {
    use std::mem::offset_of;

    use super::*;

    /// The layouts and request numbers of `linux/ptp_clock.h` as the header documents them
    /// (x86-64, ARM64: `__s64` 8-aligned).
    #[test]
    fn layouts_and_requests_are_the_kernel_headers() {
        assert_eq!(size_of::<PtpClockTime>(), 16);
        assert_eq!(size_of::<PtpPeroutRequest>(), 56);
        assert_eq!(offset_of!(PtpPeroutRequest, start), 0);
        assert_eq!(offset_of!(PtpPeroutRequest, period), 16);
        assert_eq!(offset_of!(PtpPeroutRequest, index), 32);
        assert_eq!(offset_of!(PtpPeroutRequest, flags), 36);
        assert_eq!(offset_of!(PtpPeroutRequest, on), 40);
        assert_eq!(size_of::<PtpPinDesc>(), 96);
        assert_eq!(offset_of!(PtpPinDesc, index), 64);
        assert_eq!(offset_of!(PtpPinDesc, func), 68);
        assert_eq!(offset_of!(PtpPinDesc, chan), 72);
        assert_eq!(size_of::<PtpClockCaps>(), 80);
        assert_eq!(offset_of!(PtpClockCaps, n_per_out), 12);
        assert_eq!(offset_of!(PtpClockCaps, n_pins), 20);
        assert_eq!(PTP_CLOCK_GETCAPS2, 0x8050_3d0a);
        assert_eq!(PTP_PEROUT_REQUEST2, 0x4038_3d0c);
        assert_eq!(PTP_PIN_SETFUNC2, 0x4060_3d10);
    }

    #[test]
    fn one_pulse_a_second_from_a_whole_second_ahead() {
        // PHC at 1000.999 999 s: the first start is 1002 s, not 1001 s a µs away.
        assert_eq!(first_start_s(1_000 * NS_PER_S + 999_999_000), 1_002);
        assert_eq!(first_start_s(1_000 * NS_PER_S), 1_002);
        let r = perout_request(1, Some(1_002), Some(100_000_000));
        assert_eq!(
            (r.start.sec, r.start.nsec, r.period.sec, r.period.nsec),
            (1_002, 0, 1, 0)
        );
        assert_eq!((r.index, r.flags), (1, PTP_PEROUT_DUTY_CYCLE));
        assert_eq!((r.on.sec, r.on.nsec), (0, 100_000_000));
        let r = perout_request(1, Some(1_002), None);
        assert_eq!((r.flags, r.on), (0, PtpClockTime::default()));
        let off = perout_request(3, None, None);
        assert_eq!((off.index, off.period), (3, PtpClockTime::default()));
    }

    #[test]
    fn phase_error_takes_out_whole_seconds() {
        let utc = 1_796_419_805 * NS_PER_S + 250_000_000;
        // A PHC on TAI (37 s ahead) and 1.5 µs ahead of GNSS time.
        assert_eq!(phase_error_ns(utc + 37 * NS_PER_S + 1_500, utc), 1_500);
        assert_eq!(phase_error_ns(utc - 2_000, utc), -2_000);
        assert_eq!(phase_error_ns(utc + 499_999_999, utc), 499_999_999);
        assert_eq!(phase_error_ns(utc + 500_000_000, utc), -500_000_000);
    }
}
