//! The `rc10-sim` command line as a user runs it.
#![allow(clippy::expect_used)] // test code: a binary that does not start should stop the test

use std::path::PathBuf;
use std::process::{Command, Output};

fn rc10_sim(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_rc10-sim"))
        .args(args)
        .output()
        .expect("the rc10-sim binary runs")
}

fn out_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("rc10-cli-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

#[test]
fn sweep_prints_the_ranking_and_writes_every_run() {
    let dir = out_dir("sweep");
    let o = rc10_sim(&[
        "sweep",
        "m3508-speed-step",
        "--kp",
        "0.01,0.6",
        "--ki",
        "0.1,8",
        "--jobs",
        "2",
        "--out",
        dir.to_str().unwrap(),
    ]);
    let stdout = text(&o.stdout);
    assert!(o.status.success(), "{stdout}{}", text(&o.stderr));
    assert!(
        stdout.contains("motor 1, speed loop: 4 combination(s) of 400 ms"),
        "{stdout}"
    );
    // The scenario's row, then the four runs best first: kp 0.6 (180 A asked for at the
    // step: full current, it settles within 50 ms) before kp 0.01 (3 A, a sixth of the C620's
    // 20 A: too slow with ki 0.1, barely damped with ki 8; neither qualifies).
    let rows: Vec<&str> = stdout
        .lines()
        .skip_while(|l| !l.starts_with("rank"))
        .skip(1)
        .take_while(|l| !l.is_empty())
        .collect();
    assert_eq!(rows.len(), 5, "{stdout}");
    // The scenario's own kp 0.6, ki 8 ties the grid's run of them and would rank after it.
    assert!(rows[0].starts_with("(2)"), "{stdout}");
    let kp = |row: &str| row.split_whitespace().nth(1).map(str::to_string);
    for row in &rows[1..3] {
        assert_eq!(kp(row).as_deref(), Some("0.6"), "{stdout}");
        assert!(row.trim_end().ends_with("yes"), "{stdout}");
    }
    for row in &rows[3..] {
        assert_eq!(kp(row).as_deref(), Some("0.01"), "{stdout}");
        assert!(row.trim_end().ends_with("no"), "{stdout}");
    }
    let csv = std::fs::read_to_string(dir.join("sweep.csv")).unwrap();
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(lines.len(), 6, "{csv}");
    assert!(lines[0].starts_with("index,kp,ki,kd,qualifies,iae_rpm_s,step1_at_ms,step1_rise_ms"));
    assert!(lines[1].starts_with("scenario,0.6,8,0,1,"), "{csv}");
    // Grid order: kp slowest.
    assert!(lines[2].starts_with("0,0.01,0.1,0,0,"), "{csv}");
    assert!(lines[5].starts_with("3,0.6,8,0,1,"), "{csv}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn sweep_refuses_bad_arguments_with_a_reason() {
    for (args, reason) in [
        (&["sweep", "--kp", "1:2"][..], "--kp: `1:2` is neither"),
        (&["sweep", "--motor", "0"][..], "--motor counts from 1"),
        (&["sweep", "--motor", "2", "--kp", "1"][..], "no motor 2"),
        (
            &["sweep", "--jobs", "0", "--kp", "1"][..],
            "--jobs must be 1 or more",
        ),
        (&["sweep"][..], "no candidate gains"),
        (
            &["sweep", "--kp", "1", "--seeds", "0"][..],
            "--seeds must be 1 or more",
        ),
        (&["sweep", "--kp", "1,1"][..], "--kp: 1 comes twice"),
        (
            &["sweep", "--loop", "angle", "--kp", "1"][..],
            "no angle target",
        ),
        (&["sweep", "--max-overshoot=-1"][..], "--max-overshoot"),
        (
            &["sweep", "m3508-speed-step-rc10lib", "--kp", "1"][..],
            "RC10_LIB's demo loop",
        ),
    ] {
        let dir = out_dir("refused");
        let mut with_out = args.to_vec();
        with_out.extend(["--out", dir.to_str().unwrap()]);
        let o = rc10_sim(&with_out);
        assert!(!o.status.success(), "{args:?}");
        let stderr = text(&o.stderr);
        assert!(stderr.contains(reason), "{args:?}: {stderr}");
        // Refused before anything is written.
        assert!(!dir.exists(), "{args:?} made {}", dir.display());
    }
}
