//! The viewer page in a real headless browser (Chromium), and `embodied view` on logs and plans.
//!
//! The browser tests need Chromium (`/usr/bin/chromium`, or the program named by
//! `EMBODIED_CHROMIUM`); `.ci/run` installs it. Without it they fail and say so.
#![allow(clippy::unwrap_used)]

mod common;
use std::path::{Path, PathBuf};
use std::process::Command;

use common::{TempDir, embodied};

/// Screenshot size; the page's bottom bar is 96 px high, its HUD boxes sit at the top.
const WIDTH: u32 = 1200;
const HEIGHT: u32 = 800;

fn chromium() -> PathBuf {
    if let Some(p) = std::env::var_os("EMBODIED_CHROMIUM") {
        return PathBuf::from(p);
    }
    for name in ["/usr/bin/chromium", "/usr/bin/chromium-browser", "/usr/bin/google-chrome"] {
        if Path::new(name).exists() {
            return PathBuf::from(name);
        }
    }
    panic!(
        "no Chromium found (looked for /usr/bin/chromium, chromium-browser, google-chrome): the viewer test needs \
         a headless browser; install one (`apt-get install chromium`, as .ci/run does) or set EMBODIED_CHROMIUM"
    );
}

/// Run headless Chromium on `url` with `extra` arguments, in a fresh profile; stdout.
fn browse(dir: &Path, url: &str, extra: &[String]) -> String {
    static NEXT: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    let k = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let profile = dir.join(format!("profile-{k}"));
    let out = Command::new(chromium())
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--enable-unsafe-swiftshader",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--hide-scrollbars",
            "--virtual-time-budget=8000",
            &format!("--window-size={WIDTH},{HEIGHT}"),
            &format!("--user-data-dir={}", profile.display()),
        ])
        .args(extra)
        .arg(url)
        .output()
        .expect("chromium runs");
    assert!(out.status.success(), "chromium failed: {}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8_lossy(&out.stdout).into_owned()
}

fn body_attr(dom: &str, name: &str) -> Option<String> {
    let body = &dom[dom.find("<body")?..];
    let body = &body[..body.find('>')?];
    let key = format!("{name}=\"");
    let start = body.find(&key)? + key.len();
    Some(body[start..start + body[start..].find('"')?].to_string())
}

fn screenshot(dir: &Path, page: &Path, t: f64, name: &str) -> Vec<u8> {
    let file = dir.join(name);
    let url = format!("file://{}#t={t}", page.display());
    browse(dir, &url, &[format!("--screenshot={}", file.display())]);
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(&file).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!((info.width, info.height), (WIDTH, HEIGHT), "screenshot size");
    let channels = match info.color_type {
        png::ColorType::Rgb => 3,
        png::ColorType::Rgba => 4,
        other => panic!("screenshot colour type {other:?}"),
    };
    assert_eq!(info.bit_depth, png::BitDepth::Eight);
    buf.truncate(info.buffer_size());
    // As RGB.
    buf.chunks(channels).flat_map(|p| [p[0], p[1], p[2]]).collect()
}

/// Pixels of the 3-D view (below the HUD boxes, above the timeline bar) that differ, and their
/// bounding box (x0, y0, x1, y1).
fn view_difference(a: &[u8], b: &[u8]) -> (usize, (u32, u32, u32, u32)) {
    let (mut count, mut bbox) = (0, (u32::MAX, u32::MAX, 0, 0));
    for y in 130..HEIGHT - 100 {
        for x in 0..WIDTH {
            let i = ((y * WIDTH + x) * 3) as usize;
            let d: i32 = (0..3).map(|c| (i32::from(a[i + c]) - i32::from(b[i + c])).abs()).sum();
            if d > 30 {
                count += 1;
                bbox = (bbox.0.min(x), bbox.1.min(y), bbox.2.max(x), bbox.3.max(y));
            }
        }
    }
    (count, bbox)
}

#[test]
fn the_default_run_page_loads_draws_and_moves_in_chromium() {
    let dir = TempDir::new("viewer");
    let page = dir.join("carry.html");
    let (code, out, err) = embodied(&["run", "--html", page.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("viewer page written to"), "{out}");
    let text = std::fs::read_to_string(&page).unwrap();
    // Self-contained: no script, style or image is loaded from anywhere.
    assert!(!text.contains("<script src") && !text.contains("<link") && !text.contains("<img"), "loads nothing");

    // The page runs without an error and builds the scene: the two arms' links, the stands,
    // the wall and the bar.
    let dom = browse(&dir, &format!("file://{}#t=1.5", page.display()), &["--dump-dom".to_string()]);
    assert_eq!(
        body_attr(&dom, "data-status").as_deref(),
        Some("ok"),
        "page status; error: {:?}",
        body_attr(&dom, "data-error")
    );
    let meshes: usize = body_attr(&dom, "data-meshes").unwrap().parse().unwrap();
    assert!(meshes >= 15, "{meshes} shapes drawn");
    assert_eq!(body_attr(&dom, "data-frame").as_deref(), Some("60"), "#t=1.5 opens frame 60 (25 ms frames)");
    assert!(dom.contains("grasp") && dom.contains("release"), "the event list names the grasp and the release");

    // Two times, two pictures: where the arms moved, the pixels differ; the same time twice
    // gives the same picture.
    let early = screenshot(&dir, &page, 0.5, "early.png");
    let carrying = screenshot(&dir, &page, 2.5, "carrying.png");
    let early_again = screenshot(&dir, &page, 0.5, "early-again.png");
    let (moved, bbox) = view_difference(&early, &carrying);
    let (noise, _) = view_difference(&early, &early_again);
    eprintln!(
        "view pixels changed: {moved} between t=0.5 s and 2.5 s (box {bbox:?}), {noise} between two shots at 0.5 s"
    );
    assert!(moved > 2000, "only {moved} pixels of the view changed between t=0.5 s and t=2.5 s");
    assert!(noise * 50 < moved, "same time twice differs in {noise} pixels (moved: {moved})");
    // The change is in the middle of the picture, where the robots are, not at its edges.
    assert!(bbox.0 > 100 && bbox.2 < WIDTH - 100, "changed region {bbox:?}");
}

#[test]
fn view_reads_a_run_log_and_a_plan_file() {
    let dir = TempDir::new("view-inputs");
    let log = dir.join("run.jsonl");
    let (code, _, err) = embodied(&["run", "--log", log.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    let page = dir.join("run.html");
    let (code, out, err) = embodied(&["view", log.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("viewer page written to") && page.exists(), "{out}");
    let html = std::fs::read_to_string(&page).unwrap();
    assert!(html.contains("\"format\":\"embodied-view/1\""));

    let plan = dir.join("plan.json");
    let (code, _, err) = embodied(&["plan", "two-irp6-carry", "-o", plan.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    let plan_page = dir.join("plan-view.html");
    let (code, _, err) = embodied(&["view", plan.to_str().unwrap(), "-o", plan_page.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    assert!(std::fs::read_to_string(&plan_page).unwrap().contains("two-irp6-carry: plan"));

    // Bad input: a clear error naming the file, exit status 2.
    let bad = dir.join("bad.jsonl");
    std::fs::write(&bad, "{\"header\": {\"scenario\": \"two-irp6-carry\"}}\nnot json\n").unwrap();
    let (code, _, err) = embodied(&["view", bad.to_str().unwrap()]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("bad.jsonl:2:") && err.contains("not a JSON line"), "{err}");
    let (code, _, err) = embodied(&["view", dir.join("missing.json").to_str().unwrap()]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("missing.json"), "{err}");
}
