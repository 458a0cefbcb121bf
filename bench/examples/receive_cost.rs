//! The user-space cost of navsync's iceoryx2 path on one thread, caches warm: an empty
//! `receive`, a `publish`, a `receive` that finds a sample, and `publish` followed by
//! `Subscriber::wait_with` (the notification already pending, so no sleep). What stays of a
//! subscriber's CPU per sample in `navsync-bench ipc` beyond these is sleeping and waking
//! (kernel, scheduler) and caches gone cold: the "cold" columns time `wait_with` after 32 MiB
//! were written since the sample was published, and the same cold read of the futex-floor
//! ring and of a Unix-domain socket (`recv`), for comparison.
//!
//! `cargo run --release -p navsync-bench --example receive_cost [-- ITERATIONS]`

use std::os::fd::{AsRawFd, FromRawFd, OwnedFd};
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

use navsync_bench::ipc::floor;

use navsync_shared::ipc::IpcNode;
use navsync_shared::reflect::Reflect;
use navsync_shared::samples::ImuSample;

fn sample(i: u64) -> ImuSample {
    let mut s = ImuSample::zeroed();
    s.stamp.seq = i;
    s
}

/// Mean ns per call of `f` over `n` calls.
fn per_call<E>(n: u64, mut f: impl FnMut(u64) -> Result<(), E>) -> Result<f64, E> {
    let t = Instant::now();
    for i in 0..n {
        f(i)?;
    }
    Ok(t.elapsed().as_nanos() as f64 / n as f64)
}

/// Writes every cache line of `junk` (evicting caches and the TLB's entries of other pages).
fn evict(junk: &mut [u8], i: u64) {
    for b in junk.iter_mut().step_by(64) {
        *b = b.wrapping_add(i as u8 | 1);
    }
    std::hint::black_box(&junk);
}

/// Mean ns of `take(i)` over `n` samples, each sent by `send(i)` before 32 MiB are written
/// (caches and TLB full of other data, as after a sleep while other processes ran); only
/// `take` is timed.
fn cold_ns<E>(
    n: u64,
    junk: &mut [u8],
    mut send: impl FnMut(u64) -> Result<(), E>,
    mut take: impl FnMut(u64) -> Result<(), E>,
) -> Result<f64, E> {
    let mut total = 0u128;
    for i in 0..n {
        send(i)?;
        evict(junk, i);
        let t = Instant::now();
        take(i)?;
        total += t.elapsed().as_nanos();
    }
    Ok(total as f64 / n as f64)
}

/// A connected pair of Unix-domain SOCK_SEQPACKET sockets (the socket transport's kind).
fn socket_pair() -> std::io::Result<[OwnedFd; 2]> {
    let mut fds = [0; 2];
    // SAFETY: socketpair writes two descriptors into `fds`.
    if unsafe { libc::socketpair(libc::AF_UNIX, libc::SOCK_SEQPACKET, 0, fds.as_mut_ptr()) } != 0 {
        return Err(std::io::Error::last_os_error());
    }
    // SAFETY: both descriptors are new and ours.
    Ok(fds.map(|fd| unsafe { OwnedFd::from_raw_fd(fd) }))
}

/// Sends one sample on a socket.
fn send_sample(fd: &OwnedFd, s: &ImuSample) -> std::io::Result<()> {
    // SAFETY: sending the bytes of a plain-data sample.
    let sent = unsafe {
        libc::send(
            fd.as_raw_fd(),
            (s as *const ImuSample).cast(),
            size_of::<ImuSample>(),
            0,
        )
    };
    if sent < 0 {
        return Err(std::io::Error::last_os_error());
    }
    Ok(())
}

/// Receives one sample from a socket (blocking).
fn recv_sample(fd: &OwnedFd, buf: &mut ImuSample) -> std::io::Result<()> {
    // SAFETY: receiving at most size_of::<ImuSample>() bytes into an ImuSample.
    let got = unsafe {
        libc::recv(
            fd.as_raw_fd(),
            (buf as *mut ImuSample).cast(),
            size_of::<ImuSample>(),
            0,
        )
    };
    if got < 0 {
        return Err(std::io::Error::last_os_error());
    }
    Ok(())
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let n: u64 = match std::env::args().nth(1) {
        Some(a) => a.parse().map_err(|e| format!("ITERATIONS {a:?}: {e}"))?,
        None => 200_000,
    };
    if n == 0 {
        return Err("ITERATIONS must be at least 1".into());
    }
    // A prefix of its own: nothing else under it, nothing left behind.
    let prefix = format!("navsync_receive_cost_{}_", std::process::id());
    let result = measure(n, &prefix);
    navsync_bench::util::remove_prefix_files(&prefix);
    result
}

fn measure(n: u64, prefix: &str) -> Result<(), Box<dyn std::error::Error>> {
    let node = IpcNode::with_prefix("receive-cost", prefix)?;
    let service = "navsync/imu/receive-cost/sample";
    let mut publisher = node.publisher::<ImuSample>(service)?;
    let subscriber = node.subscriber::<ImuSample>(service)?;
    let mut junk = vec![0u8; 32 << 20];
    let ring_path = std::path::PathBuf::from(format!("/dev/shm/{prefix}floor"));
    floor::create(&ring_path, size_of::<ImuSample>())?;
    let ring = floor::Ring::open(&ring_path, size_of::<ImuSample>());
    let _ = std::fs::remove_file(&ring_path);
    let ring = ring?;
    let sockets = socket_pair()?;
    println!(
        "| round | empty receive ns | publish ns | receive ns (queue drained) | publish + wait_with ns | cold: wait_with ns | cold: futex-floor ring ns | cold: socket recv ns |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for round in 1..=3 {
        let empty = per_call(n, |_| subscriber.receive_with(|s| s.stamp.seq).map(drop))?;
        let publish = per_call(n, |i| publisher.publish(&sample(i)))?;
        // The subscriber's queue holds its capacity of the samples just published.
        let t = Instant::now();
        let mut got = 0u64;
        while subscriber.receive_with(|s| s.stamp.seq)?.is_some() {
            got += 1;
        }
        if got == 0 {
            return Err("the subscriber received nothing of what was published".into());
        }
        let receive = t.elapsed().as_nanos() as f64 / got as f64;
        let round_trip = per_call(n, |i| -> Result<(), Box<dyn std::error::Error>> {
            publisher.publish(&sample(i))?;
            match subscriber.wait_with(Duration::MAX, |s| s.stamp.seq)? {
                Some(seq) if seq == i => Ok(()),
                other => Err(format!("published {i}, received {other:?}").into()),
            }
        })?;
        let cold_n = (n / 100).max(10);
        let cold = cold_ns(
            cold_n,
            &mut junk,
            |i| {
                publisher
                    .publish(&sample(i))
                    .map_err(Box::<dyn std::error::Error>::from)
            },
            |i| match subscriber.wait_with(Duration::MAX, |s| s.stamp.seq)? {
                Some(seq) if seq == i => Ok(()),
                other => Err(format!("published {i}, received {other:?}").into()),
            },
        )?;
        let stop = AtomicBool::new(false);
        let ring_cold = cold_ns(
            cold_n,
            &mut junk,
            |i| {
                ring.publish(i, || sample(i));
                Ok::<_, std::io::Error>(())
            },
            |i| match ring.wait_with(i, &stop, |s: &ImuSample| s.stamp.seq) {
                Some((seq, _)) if seq == i => Ok(()),
                other => Err(std::io::Error::other(format!("ring: wrote {i}, read {other:?}"))),
            },
        )?;
        let mut buf = ImuSample::zeroed();
        let socket_cold = cold_ns(
            cold_n,
            &mut junk,
            |i| send_sample(&sockets[0], &sample(i)),
            |_| recv_sample(&sockets[1], &mut buf),
        )?;
        println!(
            "| {round} | {empty:.0} | {publish:.0} | {receive:.0} ({got} samples) | {round_trip:.0} | {cold:.0} | {ring_cold:.0} | {socket_cold:.0} |"
        );
    }
    Ok(())
}
