//! `serial-dcd:/dev/ttyX` (and `serial-cts:`): a PPS wired to a modem-status line.
//!
//! `ioctl(TIOCMIWAIT, mask)` sleeps until the line changes; the edge is stamped with
//! `CLOCK_MONOTONIC` when the waiting thread wakes up, so the stamp carries the interrupt and
//! scheduling latency (tens of µs, occasionally more): this jitter is measured by the edge
//! validator and published with every edge and in Health (`jitter_ns`). `TIOCMGET` tells
//! whether the line is now active (assert) or not (clear); `TIOCGICOUNT`'s per-line
//! transition counter reveals transitions that happened while the thread was not waiting
//! (missed edges), as gpsd does.
//!
//! `TIOCMIWAIT` has no timeout and is restarted after signals, so it runs on its own thread
//! that hands events over a channel; the process shell waits on the channel with a timeout
//! and can always stop. A pseudo-terminal has no modem lines: opening one fails with
//! [`PpsError::Unsupported`].

use std::fs::{File, OpenOptions};
use std::os::fd::AsRawFd;
use std::os::unix::fs::OpenOptionsExt;
use std::path::Path;
use std::sync::mpsc::{Receiver, RecvTimeoutError, channel};
use std::time::Duration;

use navsync_shared::time::monotonic_now_ns;

use super::PpsError;
use super::edge_validator::RawEdge;

/// Which modem-status line carries the PPS.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Line {
    /// Data Carrier Detect (pin 1 of a DE-9), the usual PPS input.
    Dcd,
    /// Clear To Send (pin 8).
    Cts,
}

impl Line {
    /// The `TIOCM_*` bit.
    pub fn mask(self) -> libc::c_int {
        match self {
            Self::Dcd => libc::TIOCM_CD,
            Self::Cts => libc::TIOCM_CTS,
        }
    }
}

/// `struct serial_icounter_struct` (`linux/serial.h`): per-line transition counters.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SerialIcounter {
    /// CTS transitions.
    pub cts: i32,
    /// DSR transitions.
    pub dsr: i32,
    /// RI transitions.
    pub rng: i32,
    /// DCD transitions.
    pub dcd: i32,
    /// Bytes received.
    pub rx: i32,
    /// Bytes sent.
    pub tx: i32,
    /// Framing errors.
    pub frame: i32,
    /// Overruns.
    pub overrun: i32,
    /// Parity errors.
    pub parity: i32,
    /// Breaks.
    pub brk: i32,
    /// Buffer overruns.
    pub buf_overrun: i32,
    /// Reserved.
    pub reserved: [i32; 9],
}

impl SerialIcounter {
    /// Transitions counted on `line`.
    pub fn transitions(&self, line: Line) -> i32 {
        match line {
            Line::Dcd => self.dcd,
            Line::Cts => self.cts,
        }
    }
}

/// One wake-up of the waiting thread.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LineEvent {
    /// `CLOCK_MONOTONIC` at wake-up, ns.
    pub host_ns: i64,
    /// Line level after the change (true: active, the assert edge).
    pub active: bool,
    /// The kernel's transition counter of the line, when `TIOCGICOUNT` works.
    pub transitions: Option<i32>,
}

/// Turns line events into edges and counts missed transitions. Pure.
#[derive(Debug, Clone, Default)]
pub struct LineDecoder {
    last_transitions: Option<i32>,
    asserts: u64,
    /// Transitions the kernel counted that were not seen as wake-ups.
    pub missed_transitions: u64,
}

impl LineDecoder {
    /// The edge of one wake-up.
    pub fn decode(&mut self, ev: &LineEvent) -> RawEdge {
        if let Some(t) = ev.transitions {
            if let Some(prev) = self.last_transitions {
                let d = t.wrapping_sub(prev);
                if d > 1 {
                    self.missed_transitions += (d - 1) as u64;
                }
            }
            self.last_transitions = Some(t);
        }
        if ev.active {
            self.asserts += 1;
        }
        RawEdge {
            host_ns: ev.host_ns,
            source_seq: if ev.active { self.asserts } else { 0 },
            assert: ev.active,
        }
    }
}

/// A serial port whose modem line is watched by a background thread.
pub struct SerialDcd {
    events: Receiver<Result<LineEvent, String>>,
    decoder: LineDecoder,
    path: String,
}

fn modem_bits(fd: libc::c_int) -> std::io::Result<libc::c_int> {
    let mut bits: libc::c_int = 0;
    // SAFETY: TIOCMGET writes one int.
    let rc = unsafe { libc::ioctl(fd, libc::TIOCMGET, &mut bits) };
    if rc < 0 {
        return Err(std::io::Error::last_os_error());
    }
    Ok(bits)
}

fn icount(fd: libc::c_int) -> Option<SerialIcounter> {
    let mut c = SerialIcounter::default();
    // SAFETY: TIOCGICOUNT writes one serial_icounter_struct.
    let rc = unsafe { libc::ioctl(fd, libc::TIOCGICOUNT, &mut c) };
    (rc == 0).then_some(c)
}

impl SerialDcd {
    /// Opens the port (non-blocking open, so a missing carrier does not block) and starts the
    /// waiting thread.
    pub fn open(path: &Path, line: Line) -> Result<Self, PpsError> {
        let shown = path.display().to_string();
        let file: File = OpenOptions::new()
            .read(true)
            .write(true)
            .custom_flags(libc::O_NOCTTY | libc::O_NONBLOCK)
            .open(path)
            .map_err(|source| PpsError::Open {
                path: shown.clone(),
                source,
            })?;
        let fd = file.as_raw_fd();
        // A device without modem lines (pseudo-terminal, pipe) cannot carry a PPS.
        if let Err(e) = modem_bits(fd) {
            return Err(PpsError::Unsupported {
                path: shown,
                what: format!("no modem-status lines (TIOCMGET: {e})"),
            });
        }
        let (tx, rx) = channel();
        std::thread::Builder::new()
            .name("pps-line-wait".into())
            .spawn(move || {
                let fd = file.as_raw_fd();
                loop {
                    // SAFETY: TIOCMIWAIT takes the line mask by value.
                    let rc = unsafe { libc::ioctl(fd, libc::TIOCMIWAIT, line.mask() as libc::c_ulong) };
                    let host_ns = monotonic_now_ns();
                    let ev = if rc < 0 {
                        let e = std::io::Error::last_os_error();
                        if e.kind() == std::io::ErrorKind::Interrupted {
                            continue;
                        }
                        Err(format!("TIOCMIWAIT: {e}"))
                    } else {
                        match modem_bits(fd) {
                            Ok(bits) => Ok(LineEvent {
                                host_ns,
                                active: bits & line.mask() != 0,
                                transitions: icount(fd).map(|c| c.transitions(line)),
                            }),
                            Err(e) => Err(format!("TIOCMGET: {e}")),
                        }
                    };
                    let fatal = ev.is_err();
                    if tx.send(ev).is_err() || fatal {
                        return;
                    }
                }
            })
            .map_err(|source| PpsError::Open {
                path: shown.clone(),
                source,
            })?;
        Ok(Self {
            events: rx,
            decoder: LineDecoder::default(),
            path: shown,
        })
    }

    /// The next line change within `timeout` (assert or clear), if any.
    pub fn next_edge(&mut self, timeout: Duration) -> Result<Option<RawEdge>, PpsError> {
        match self.events.recv_timeout(timeout) {
            Ok(Ok(ev)) => Ok(Some(self.decoder.decode(&ev))),
            Ok(Err(what)) => Err(PpsError::Device {
                path: self.path.clone(),
                what,
            }),
            Err(RecvTimeoutError::Timeout) => Ok(None),
            Err(RecvTimeoutError::Disconnected) => Err(PpsError::Device {
                path: self.path.clone(),
                what: "line watcher stopped".into(),
            }),
        }
    }

    /// Transitions missed so far.
    pub fn missed_transitions(&self) -> u64 {
        self.decoder.missed_transitions
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decoder_counts_missed_transitions_and_numbers_asserts() {
        let mut d = LineDecoder::default();
        let ev = |host_ns, active, t| LineEvent {
            host_ns,
            active,
            transitions: Some(t),
        };
        let e = d.decode(&ev(10, true, 1));
        assert_eq!((e.assert, e.source_seq), (true, 1));
        assert!(!d.decode(&ev(20, false, 2)).assert);
        // Two transitions (a whole pulse) happened unseen.
        let e = d.decode(&ev(30, true, 5));
        assert_eq!((e.assert, e.source_seq, d.missed_transitions), (true, 2, 2));
        // Counter wrap.
        d.last_transitions = Some(i32::MAX);
        d.decode(&ev(40, false, i32::MIN));
        assert_eq!(d.missed_transitions, 2);
    }

    #[test]
    fn a_pseudo_terminal_has_no_modem_lines() {
        let pty = crate::pty::Pty::open(None).expect("pty");
        let err = SerialDcd::open(pty.path(), Line::Dcd).err().expect("must fail");
        assert!(
            matches!(err, PpsError::Unsupported { .. }) || matches!(err, PpsError::Open { .. }),
            "{err}"
        );
    }

    #[test]
    fn icounter_has_the_kernel_size() {
        // 11 counters + reserved[9], all int.
        assert_eq!(size_of::<SerialIcounter>(), 80);
    }
}
