//! The window presenter under a virtual X server (`xvfb-run`, installed by
//! `.ci/run`): the client runs its demo for two seconds in a window and
//! saves a screenshot, which must show a picture and the stats overlay.

use std::process::Command;

#[test]
fn the_window_shows_frames_and_the_overlay() {
    shows_frames_and_the_overlay(None);
}

/// The same on wgpu's OpenGL backend (EGL on X11), what a machine without
/// Mesa's Vulkan driver presents with.
#[test]
fn the_window_shows_frames_on_opengl() {
    shows_frames_and_the_overlay(Some("gl"));
}

fn shows_frames_and_the_overlay(backend: Option<&str>) {
    // One virtual X server at a time: `xvfb-run -a` races for a free
    // display number when two start together.
    static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());
    let _turn = ONE_AT_A_TIME.lock().unwrap_or_else(|p| p.into_inner());
    let which = Command::new("sh")
        .args(["-c", "command -v xvfb-run"])
        .output()
        .unwrap();
    assert!(
        which.status.success(),
        "xvfb-run is not installed (apt-get install xvfb; .ci/run does)"
    );
    let dir = tempfile::tempdir().unwrap();
    let shot = dir.path().join("window.png");
    let mut cmd = Command::new("xvfb-run");
    if let Some(b) = backend {
        cmd.env("WGPU_BACKEND", b);
    }
    let out = cmd
        .args(["-a", "-s", "-screen 0 1280x720x24"])
        .arg(env!("CARGO_BIN_EXE_client"))
        .args([
            "run",
            "--window",
            "on",
            "--seconds",
            "2",
            "--size",
            "160x90",
            "--backend",
            "cpu",
        ])
        .arg("--screenshot")
        .arg(&shot)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "client failed:\n{stdout}\n{stderr}");
    assert!(stdout.contains("presenting in a window"), "{stdout}");
    assert!(stdout.contains("MsBetweenPresents"), "{stdout}");

    let img = image::open(&shot).expect("screenshot written").to_rgb8();
    let (w, h) = img.dimensions();
    assert!(w >= 320 && h >= 180, "{w}x{h}");
    // Not blank: the picture has real variation.
    let lum: Vec<f64> = img
        .pixels()
        .map(|p| f64::from(p[0]) + f64::from(p[1]) + f64::from(p[2]))
        .collect();
    let mean = lum.iter().sum::<f64>() / lum.len() as f64;
    let var = lum.iter().map(|l| (l - mean).powi(2)).sum::<f64>() / lum.len() as f64;
    assert!(
        var.sqrt() > 20.0,
        "the screenshot is nearly uniform (σ = {:.1})",
        var.sqrt()
    );
    // The overlay: pure white text in the top-left corner. The display
    // transform (Reinhard) never reaches pure white on these scenes, so
    // white pixels there are the overlay's glyphs.
    let white = |x0: u32, y0: u32, x1: u32, y1: u32| {
        (y0..y1)
            .flat_map(|y| (x0..x1).map(move |x| (x, y)))
            .filter(|&(x, y)| img.get_pixel(x, y).0.iter().all(|&c| c >= 250))
            .count()
    };
    let corner = white(0, 0, w.min(520), h.min(100));
    assert!(
        corner > 100,
        "no overlay text in the top-left corner ({corner} white pixels)"
    );
}
