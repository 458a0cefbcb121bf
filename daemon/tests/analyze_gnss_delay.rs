//! `navsync analyze gnss-delay` on a simulated recording with a 0.8 s receiver latency: the
//! least-squares fits from east and north data and the online estimate all find the delay.

use std::process::Command;

#[test]
fn offline_fits_and_online_estimate_find_the_receiver_latency() {
    let dir = std::env::temp_dir().join(format!("navsync-analyze-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let rec = dir.join("drive.mcap");
    let bin = env!("CARGO_BIN_EXE_navsync");
    let out = Command::new(bin)
        .args(["sim", "--fast", "--record"])
        .arg(&rec)
        .args([
            "--imus",
            "1",
            "--imu-preset",
            "industrial",
            "--gnss-latency",
            "0.8",
            "--duration",
            "300",
        ])
        .output()
        .unwrap();
    assert!(out.status.success(), "sim: {}", String::from_utf8_lossy(&out.stderr));
    let out = Command::new(bin)
        .args(["analyze", "gnss-delay"])
        .arg(&rec)
        .args(["--segments", "40:300"])
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout).to_string();
    assert!(
        out.status.success(),
        "analyze: {}\n{text}",
        String::from_utf8_lossy(&out.stderr)
    );
    println!("{text}");
    let row = text.lines().nth(1).expect("one segment row");
    let nums: Vec<f64> = row
        .split(|c: char| !(c.is_ascii_digit() || c == '.' || c == '-'))
        .filter_map(|t| t.parse().ok())
        .collect();
    // 40, 300, fixes, east, ±, north, ±, online, ±
    assert_eq!(nums.len(), 9, "{row}");
    assert!(nums[2] > 200.0, "fixes {}", nums[2]);
    for (est, sd, what) in [
        (nums[3], nums[4], "east"),
        (nums[5], nums[6], "north"),
        (nums[7], nums[8], "online"),
    ] {
        assert!(
            (est - 0.8).abs() <= 4.0 * sd + 0.005,
            "Δ from {what}: {est} ± {sd} s (true 0.8 s)"
        );
        assert!(sd < 0.05, "Δ from {what}: σ {sd} s");
    }
    let _ = std::fs::remove_dir_all(dir);
}
