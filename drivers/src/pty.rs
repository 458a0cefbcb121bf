//! Pseudo-terminals: the simulator's receiver and the capture feeder write NMEA into the
//! master side; the GPS driver opens the slave side with `serialport` exactly as it would open
//! `/dev/ttyUSB0`.
//!
//! The master is non-blocking: when nobody reads the slave and the line discipline's input
//! buffer is full, bytes are dropped and counted, as on a real serial line with no listener.
//! The slave is kept open by the creator (in raw mode, no echo), so the driver can close and
//! reopen it, and data written before it opens is not echoed back.

use std::ffi::CStr;
use std::fs::File;
use std::io;
use std::os::fd::{AsRawFd, FromRawFd, OwnedFd};
use std::path::{Path, PathBuf};

/// A pseudo-terminal pair with an optional stable symlink to the slave device.
pub struct Pty {
    master: File,
    _slave: OwnedFd,
    path: PathBuf,
    link: Option<PathBuf>,
    dropped_bytes: u64,
}

fn check(rc: libc::c_int) -> io::Result<libc::c_int> {
    if rc < 0 {
        Err(io::Error::last_os_error())
    } else {
        Ok(rc)
    }
}

impl Pty {
    /// Opens a new pseudo-terminal in raw mode; `link`, if given, is (re)created as a symlink
    /// to the slave device (e.g. `/tmp/navsync/gnss0`).
    pub fn open(link: Option<&Path>) -> io::Result<Self> {
        // SAFETY: plain libc calls on descriptors we own; buffers are sized and checked.
        unsafe {
            let m = check(libc::posix_openpt(
                libc::O_RDWR | libc::O_NOCTTY | libc::O_NONBLOCK | libc::O_CLOEXEC,
            ))?;
            let master = File::from_raw_fd(m);
            check(libc::grantpt(m))?;
            check(libc::unlockpt(m))?;
            let mut buf = [0 as libc::c_char; 128];
            let rc = libc::ptsname_r(m, buf.as_mut_ptr(), buf.len());
            if rc != 0 {
                return Err(io::Error::from_raw_os_error(rc));
            }
            let path = PathBuf::from(CStr::from_ptr(buf.as_ptr()).to_string_lossy().into_owned());
            let cpath = std::ffi::CString::new(path.as_os_str().as_encoded_bytes())
                .map_err(|_| io::Error::new(io::ErrorKind::InvalidInput, "pty path"))?;
            let s = check(libc::open(
                cpath.as_ptr(),
                libc::O_RDWR | libc::O_NOCTTY | libc::O_CLOEXEC,
            ))?;
            let slave = OwnedFd::from_raw_fd(s);
            let mut tio: libc::termios = std::mem::zeroed();
            check(libc::tcgetattr(s, &mut tio))?;
            libc::cfmakeraw(&mut tio);
            check(libc::tcsetattr(s, libc::TCSANOW, &tio))?;
            let link = match link {
                Some(l) => {
                    if let Some(dir) = l.parent() {
                        std::fs::create_dir_all(dir)?;
                    }
                    let _ = std::fs::remove_file(l);
                    std::os::unix::fs::symlink(&path, l)?;
                    Some(l.to_path_buf())
                }
                None => None,
            };
            Ok(Self {
                master,
                _slave: slave,
                path,
                link,
                dropped_bytes: 0,
            })
        }
    }

    /// The slave device, e.g. `/dev/pts/7`.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The symlink to the slave, if one was made.
    pub fn link(&self) -> Option<&Path> {
        self.link.as_deref()
    }

    /// Writes `bytes` without blocking; what does not fit is dropped and counted.
    /// Returns the number of bytes written.
    pub fn write(&mut self, bytes: &[u8]) -> io::Result<usize> {
        let mut done = 0;
        while done < bytes.len() {
            // SAFETY: writing from a valid slice to our own descriptor.
            let n = unsafe {
                libc::write(
                    self.master.as_raw_fd(),
                    bytes[done..].as_ptr().cast(),
                    bytes.len() - done,
                )
            };
            if n < 0 {
                let e = io::Error::last_os_error();
                match e.kind() {
                    io::ErrorKind::Interrupted => continue,
                    io::ErrorKind::WouldBlock => break,
                    _ => return Err(e),
                }
            }
            done += n as usize;
        }
        self.dropped_bytes += (bytes.len() - done) as u64;
        Ok(done)
    }

    /// Reads what the other side wrote into the slave (a driver's commands to its device);
    /// `Ok(0)` when nothing is waiting (the master is non-blocking).
    pub fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        use std::io::Read;
        match self.master.read(buf) {
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => Ok(0),
            r => r,
        }
    }

    /// Bytes dropped because the slave's input buffer was full.
    pub fn dropped_bytes(&self) -> u64 {
        self.dropped_bytes
    }
}

impl Drop for Pty {
    fn drop(&mut self) {
        if let Some(l) = &self.link {
            let _ = std::fs::remove_file(l);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Read;

    #[test]
    fn bytes_reach_the_slave_through_serialport() {
        let dir = std::env::temp_dir().join(format!("navsync-pty-test-{}", std::process::id()));
        let link = dir.join("gnss0");
        let mut pty = Pty::open(Some(&link)).unwrap();
        let mut port = serialport::new(link.to_string_lossy(), 115_200)
            .timeout(std::time::Duration::from_millis(500))
            .open_native()
            .unwrap();
        pty.write(b"$GPGGA,hello*00\r\n").unwrap();
        let mut buf = [0u8; 64];
        let n = port.read(&mut buf).unwrap();
        assert_eq!(&buf[..n], b"$GPGGA,hello*00\r\n");
        drop(pty);
        assert!(!link.exists(), "symlink removed on drop");
        let _ = std::fs::remove_dir(dir);
    }

    #[test]
    fn a_full_line_drops_instead_of_blocking() {
        let mut pty = Pty::open(None).unwrap();
        let chunk = [b'x'; 4096];
        let mut written = 0;
        for _ in 0..64 {
            written += pty.write(&chunk).unwrap();
        }
        assert!(pty.dropped_bytes() > 0 && written < 64 * 4096);
    }
}
