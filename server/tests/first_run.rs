//! `server`'s first commands: help texts with examples, `record` on wgpu's
//! OpenGL backend (a machine without Mesa's Vulkan driver) and with no
//! usable adapter: a dump, or one line saying what to install, never a
//! panic or a backtrace.

use std::process::{Command, Output};

fn server(args: &[&str], backend: Option<&str>) -> Output {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_server"));
    cmd.args(args)
        .env("RUST_BACKTRACE", "1")
        .env_remove("WGPU_ADAPTER_NAME");
    if let Some(b) = backend {
        cmd.env("WGPU_BACKEND", b);
    }
    let out = cmd.output().expect("the server binary runs");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !stderr.contains("panicked") && !stderr.contains("backtrace"),
        "server {args:?}:\n{stderr}"
    );
    out
}

#[test]
fn every_help_has_an_example() {
    let top = String::from_utf8(server(&["--help"], None).stdout).unwrap();
    for word in [
        "record",
        "serve",
        "inspect",
        "import",
        "--adapter",
        "mesa-vulkan-drivers",
    ] {
        assert!(top.contains(word), "`server --help` lacks {word}:\n{top}");
    }
    for sub in ["record", "serve", "info", "inspect", "import"] {
        let out = server(&[sub, "--help"], None);
        assert!(out.status.success(), "server {sub} --help");
        let help = String::from_utf8(out.stdout).unwrap();
        assert!(help.contains("Example"), "`server {sub} --help`:\n{help}");
        assert!(help.contains(&format!("server {sub}")), "{help}");
    }
}

#[test]
fn record_on_opengl_or_one_line_remedy() {
    let dir = tempfile::tempdir().unwrap();
    let out_dir = dir.path().join("dump");
    let args = [
        "record",
        "--size",
        "160x90",
        "--seconds",
        "0.2",
        "--out",
        out_dir.to_str().unwrap(),
    ];
    let out = server(&args, Some("gl"));
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    if out.status.success() {
        assert!(out_dir.join("manifest.json").exists(), "{stderr}");
        let dump = protocol::dump::DumpReader::open(&out_dir).unwrap();
        assert_eq!(dump.manifest().frame_count, 6);
    } else {
        let errors: Vec<_> = stderr.lines().filter(|l| l.starts_with("Error:")).collect();
        assert_eq!(errors.len(), 1, "{stderr}");
        assert!(errors[0].contains("apt-get install"), "{stderr}");
    }
    // No adapter at all: a non-zero exit and the remedy.
    let out = server(&args, Some("dx12"));
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("apt-get install -y mesa-vulkan-drivers libvulkan1"),
        "{stderr}"
    );
}
