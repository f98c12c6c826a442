//! A newcomer's first commands: help texts with examples, the demo on wgpu's
//! OpenGL backend (a machine without Mesa's Vulkan driver), and a machine
//! without any usable adapter: a working run or one line saying what to
//! install, never a panic or a backtrace.

use std::process::{Command, Output};

/// Runs the client binary with `args` and extra environment.
fn client(args: &[&str], env: &[(&str, &str)]) -> Output {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_client"));
    cmd.args(args)
        .env("RUST_BACKTRACE", "1")
        .env_remove("WGPU_ADAPTER_NAME");
    for (k, v) in env {
        cmd.env(k, v);
    }
    cmd.output().expect("the client binary runs")
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

/// No panic and no backtrace, whatever happened.
fn assert_no_panic(out: &Output, what: &str) {
    let err = text(&out.stderr);
    assert!(!err.contains("panicked"), "{what} panicked:\n{err}");
    assert!(
        !err.contains("backtrace"),
        "{what} printed a backtrace:\n{err}"
    );
}

#[test]
fn every_help_has_an_example() {
    let top = client(&["--help"], &[]);
    assert!(top.status.success());
    let top = text(&top.stdout);
    for word in [
        "run",
        "connect",
        "eval",
        "repeat",
        "reproject",
        "gffe",
        "interp",
        "--adapter",
        "mesa-vulkan-drivers",
    ] {
        assert!(top.contains(word), "`client --help` lacks {word}:\n{top}");
    }
    for sub in ["run", "connect", "eval"] {
        let out = client(&[sub, "--help"], &[]);
        assert!(out.status.success(), "client {sub} --help");
        let help = text(&out.stdout);
        assert!(
            help.contains("Example"),
            "`client {sub} --help` has no example:\n{help}"
        );
        assert!(help.contains(&format!("client {sub}")), "{help}");
    }
    let run = text(&client(&["run", "--help"], &[]).stdout);
    assert!(
        run.contains("interp"),
        "`client run --help` does not list interp:\n{run}"
    );
}

/// The README's run command (a short one) and `eval` with wgpu's OpenGL
/// backend forced: frames are presented, or the run ends with one
/// `Error:` line naming the remedy.
#[test]
fn the_demo_and_eval_run_on_opengl() {
    let dir = tempfile::tempdir().unwrap();
    let out_dir = dir.path().join("report");
    let runs: [(&str, Vec<&str>); 3] = [
        (
            "client run",
            vec!["run", "--seconds", "1", "--window", "off"],
        ),
        (
            "client run --backend wgpu",
            vec![
                "run",
                "--seconds",
                "1",
                "--window",
                "off",
                "--backend",
                "wgpu",
            ],
        ),
        (
            "client eval",
            vec![
                "eval",
                "--sweep",
                "methods",
                "--frames",
                "6",
                "--warmup",
                "1",
                "--out",
                out_dir.to_str().unwrap(),
            ],
        ),
    ];
    for (what, args) in runs {
        let out = client(&args, &[("WGPU_BACKEND", "gl")]);
        assert_no_panic(&out, what);
        let (stdout, stderr) = (text(&out.stdout), text(&out.stderr));
        if out.status.success() {
            let done = if what == "client eval" {
                "evaluated 1 scenes"
            } else {
                "displayed:"
            };
            assert!(stdout.contains(done), "{what}:\n{stdout}\n{stderr}");
        } else {
            let lines: Vec<_> = stderr.lines().filter(|l| l.starts_with("Error:")).collect();
            assert_eq!(lines.len(), 1, "{what}: one error line:\n{stderr}");
            assert!(
                lines[0].contains("apt-get install"),
                "{what}: no remedy:\n{stderr}"
            );
        }
        eprintln!(
            "{what} on OpenGL: {}",
            if out.status.success() {
                "ran"
            } else {
                "typed error"
            }
        );
    }
}

/// No adapter at all (a backend this build lacks): a non-zero exit and one
/// line that says what to install, even with RUST_BACKTRACE=1.
#[test]
fn no_adapter_is_one_line_with_the_remedy() {
    let out = client(
        &["run", "--seconds", "1", "--window", "off"],
        &[("WGPU_BACKEND", "dx12")],
    );
    assert!(!out.status.success());
    assert_no_panic(&out, "client run without an adapter");
    let stderr = text(&out.stderr);
    let errors: Vec<_> = stderr.lines().filter(|l| l.starts_with("Error:")).collect();
    assert_eq!(errors.len(), 1, "{stderr}");
    assert!(
        errors[0].contains("apt-get install -y mesa-vulkan-drivers libvulkan1"),
        "{stderr}"
    );
    // An adapter asked for by name that does not exist names those found.
    let out = client(
        &[
            "--adapter",
            "no-such-gpu",
            "run",
            "--seconds",
            "1",
            "--window",
            "off",
        ],
        &[],
    );
    assert!(!out.status.success());
    assert_no_panic(&out, "client --adapter no-such-gpu");
    assert!(
        text(&out.stderr).contains("no-such-gpu"),
        "{}",
        text(&out.stderr)
    );
}
