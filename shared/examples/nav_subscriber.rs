//! A subscriber of navsync's navigation state in a few lines, with the client API of
//! `navsync_shared::client`: waits for states (1 s timeout), prints one line per state (at most
//! 10 per second), and warns when the newest state is older than 100 ms.
//!
//! ```sh
//! cargo run --release -- demo &                                   # something to listen to
//! cargo run -p navsync-shared --example nav_subscriber -- --count 50
//! ```
//!
//! `--count N` stops after N printed lines; `$NAVSYNC_IPC_PREFIX` selects the navsync instance.
//! Exits with status 2 when no state arrives for 10 s.

use std::time::{Duration, Instant};

use navsync_shared::client::NavClient;
use navsync_shared::samples::NavStatus;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let count: Option<u64> = args
        .iter()
        .position(|a| a == "--count")
        .and_then(|i| args.get(i + 1))
        .map(|n| n.parse())
        .transpose()?;

    let mut nav = NavClient::connect()?;
    let (mut printed, mut last_print, mut last_any) = (0u64, None::<Instant>, Instant::now());
    while count.is_none_or(|c| printed < c) && !nav.termination_requested() {
        let Some(s) = nav.next(Duration::from_secs(1))? else {
            if last_any.elapsed() > Duration::from_secs(10) {
                eprintln!("no navigation state on {} for 10 s", nav.service());
                std::process::exit(2);
            }
            continue;
        };
        last_any = Instant::now();
        if last_print.is_some_and(|t| t.elapsed() < Duration::from_millis(100)) {
            continue;
        }
        last_print = Some(Instant::now());
        println!(
            "seq {} {} lat {:.7} lon {:.7} h {:.2} m  v [{:.2} {:.2} {:.2}] m/s  yaw {:.2}°  ±{:.2} m",
            s.seq,
            NavStatus::name(s.status),
            s.lat_deg,
            s.lon_deg,
            s.height_m,
            s.vel_ned_mps[0],
            s.vel_ned_mps[1],
            s.vel_ned_mps[2],
            s.rpy_rad[2].to_degrees(),
            s.pos_std_ned_m[0].hypot(s.pos_std_ned_m[1]),
        );
        printed += 1;
        // The staleness check: the newest state must be at most 100 ms old on the host clock.
        if nav.latest(Duration::from_millis(100))?.is_none()
            && let Some((_, age)) = nav.latest_with_age()?
        {
            eprintln!("navigation state is stale: {:.3} s old", age.as_secs_f64());
        }
    }
    println!("{printed} states printed, {} received", nav.received());
    Ok(())
}
