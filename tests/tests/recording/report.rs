//! `navsync report`: one self-contained HTML page of a recording (the checked-in simulator
//! recording, which has no navigation states, so the report runs the estimator over it; and a
//! file with the states `replay --estimate --out` wrote), with its SVG plots filled with data;
//! rendered in headless Chromium (`--dump-dom` and `--screenshot`) when Chromium is installed
//! (`.ci/run` installs Debian's `chromium`; without it that part is skipped with the reason
//! printed).

use std::path::{Path, PathBuf};

use navsync_tests::{TestEnv, chromium, run_chromium};

fn data_file() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("data/record_drive.mcap")
}

/// `data-title` and `data-points` of every `<svg class="plot…">`.
fn plots(html: &str) -> Vec<(String, usize)> {
    html.split("<svg class=\"plot")
        .skip(1)
        .map(|s| {
            let attr = |name: &str| {
                let k = format!("{name}=\"");
                let i = s.find(&k).unwrap() + k.len();
                s[i..i + s[i..].find('"').unwrap()].to_string()
            };
            (attr("data-title"), attr("data-points").parse().unwrap())
        })
        .collect()
}

#[test]
fn the_report_shows_its_plots() {
    let env = TestEnv::new("report");
    let html_p = env.dir.join("report.html");
    let o = env
        .command(&[
            "report",
            &data_file().display().to_string(),
            "-o",
            &html_p.display().to_string(),
        ])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let html = std::fs::read_to_string(&html_p).unwrap();
    assert!(!html.contains("<script"), "the page must not need scripts");
    assert!(
        !html.contains(" src=\"") && !html.contains("href=\"http"),
        "no external resources"
    );
    let p = plots(&html);
    println!("{} bytes, plots: {p:?}", html.len());
    let titles: Vec<&str> = p.iter().map(|(t, _)| t.as_str()).collect();
    for want in [
        "Trajectory",
        "Position error against the truth",
        "Velocity error against the truth",
        "Attitude error against the truth",
        "GNSS delay estimate Δ",
        "Clock offset: mapped GNSS time minus the truth",
        "Host clock drift (fractional frequency error)",
        "Receiver latency d0: first NMEA byte minus its PPS edge",
    ] {
        let (_, n) = p
            .iter()
            .find(|(t, _)| t == want)
            .unwrap_or_else(|| panic!("no plot `{want}`: {titles:?}"));
        assert!(*n >= 20, "plot `{want}` has {n} points");
    }
    assert!(html.contains("computed by the estimator over the recording"));
    assert!(html.contains("horizontal position error"));
    // The accuracy comes first, the sample counts after the figures.
    let first_count = html.find(" samples</td>").expect("sample counts");
    let first_plot = html.find("<svg").expect("figures");
    assert!(first_plot < first_count, "sample counts before the figures");
    // d0 of the recording: the simulator's 0.6 s receiver latency.
    let bars = html.matches("class=\"bar\"").count();
    assert!(bars >= 5, "{bars} histogram bars");
    assert!(
        html.contains("receiver latency d0</th><td>median 6"),
        "d0 ≈ 600 ms expected"
    );

    // A file with recorded navigation states: plotted as recorded.
    let nav = env.dir.join("nav.mcap");
    let o = env
        .command(&[
            "replay",
            &data_file().display().to_string(),
            "--estimate",
            "--out",
            &nav.display().to_string(),
        ])
        .output()
        .unwrap();
    assert!(o.status.success());
    let html2_p = env.dir.join("nav.html");
    let o = env
        .command(&[
            "report",
            &nav.display().to_string(),
            "-o",
            &html2_p.display().to_string(),
        ])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let html2 = std::fs::read_to_string(&html2_p).unwrap();
    assert!(html2.contains("as recorded"));
    let p2 = plots(&html2);
    assert!(p2.iter().any(|(t, n)| t == "Trajectory" && *n > 100), "{p2:?}");
    assert!(
        p2.iter().any(|(t, n)| t.starts_with("Clock offset") && *n > 10),
        "{p2:?}"
    );

    // Headless Chromium renders it.
    let Some(bin) = chromium() else {
        println!("SKIPPED the Chromium part: no chromium on PATH (.ci/run installs Debian's `chromium`)");
        env.finish();
        return;
    };
    let profile = env.dir.join("chromium-profile");
    std::fs::create_dir_all(&profile).unwrap();
    let url = format!("file://{}", html_p.display());
    let dom = run_chromium(&bin, &profile, &["--dump-dom".into(), url.clone()]);
    let rendered = plots(&dom);
    assert_eq!(
        rendered.len(),
        p.len(),
        "Chromium's DOM has {} plots: {}",
        rendered.len(),
        &dom[..dom.len().min(500)]
    );
    assert!(dom.matches("<polyline").count() >= 10, "polylines in the rendered DOM");
    let shot = env.dir.join("report.png");
    run_chromium(
        &bin,
        &profile,
        &[
            format!("--screenshot={}", shot.display()),
            "--window-size=1000,2400".into(),
            url,
        ],
    );
    let png = std::fs::read(&shot).unwrap_or_default();
    assert!(png.starts_with(b"\x89PNG"), "no screenshot written");
    // A blank page compresses to a few kB; plots with lines and text do not.
    assert!(png.len() > 40_000, "screenshot only {} bytes", png.len());
    println!(
        "Chromium: {} plots in the DOM, screenshot {} bytes",
        rendered.len(),
        png.len()
    );
    env.finish();
}
