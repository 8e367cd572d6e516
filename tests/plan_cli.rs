//! `solidtex plan` end to end: where the slice lies, boxes, and boxes too
//! large for exact chains.

mod common;

use common::{leather_stx, solidtex_json};
use serde_json::Value;

fn plan(args: &[&str]) -> Value {
    let stx = leather_stx().to_str().expect("a UTF-8 temporary path");
    solidtex_json(&[&["plan", stx, "--json"][..], args].concat())
}

fn total(scheme: &Value, key: &str) -> u64 {
    scheme[key]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_u64().unwrap())
        .sum()
}

#[test]
fn plan_places_slices_and_counts_boxes() {
    // An x slice at x = 5: u is y, v is z.
    let v = plan(&["--slice", "16", "--axis", "x", "--at", "5", "--v0", "-3"]);
    let schemes = v["schemes"].as_array().unwrap();
    assert_eq!(schemes.len(), 2);
    for s in schemes {
        assert_eq!(s["origin"], serde_json::json!([5, 0, -3]), "{s}");
        assert_eq!(s["size"], serde_json::json!([1, 16, 16]), "{s}");
        // Every requested voxel is corrected at the finest level.
        let finest = &s["exact_per_level"][0];
        assert!(finest["corrections"].as_u64().unwrap() >= 256, "{s}");
    }
    // The same voxels asked for as a box give the same counts.
    let b = plan(&["--region", "5,0,-3,1,16,16"]);
    for (s, t) in schemes.iter().zip(b["schemes"].as_array().unwrap()) {
        assert_eq!(s["voxels_per_level"], t["voxels_per_level"]);
        assert_eq!(s["exact_per_level"], t["exact_per_level"]);
    }
    // Beyond 2^20 voxels only the engine's counts are given.
    let big = plan(&["--region", "0,0,0,128,128,65"]);
    for s in big["schemes"].as_array().unwrap() {
        assert!(s["exact_per_level"].is_null(), "{s}");
        assert!(total(s, "corrections_per_level") >= 128 * 128 * 65, "{s}");
    }
}

#[test]
fn the_preview_flag_spells_out_the_preview_parameters() {
    let preview = plan(&["--slice", "16", "--at", "3", "--preview"]);
    let spelled = plan(&[
        "--slice",
        "16",
        "--at",
        "3",
        "--passes",
        "1",
        "--finest-passes",
        "0",
        "--fine-levels",
        "1",
    ]);
    assert_eq!(preview["schemes"], spelled["schemes"]);
    for s in preview["schemes"].as_array().unwrap() {
        // The finest level is upsampled, never corrected.
        assert_eq!(s["corrections_per_level"][0], 0, "{s}");
        assert!(s["corrections_per_level"][1].as_u64().unwrap() > 0, "{s}");
    }
    // The preview sets the passes: giving them too is a contradiction.
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_solidtex"))
        .args(["plan", "--preview", "--passes", "2"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--preview"));
}

#[test]
fn parity_levels_reach_the_planner() {
    // Odd x planes chain through the block subpasses into more planes of
    // the finest level than parity subpasses, which need the plane and
    // half of each plane beside it.
    let finest = |extra: &[&str]| {
        let v = plan(&[&["--slice", "16", "--axis", "x", "--at", "5"][..], extra].concat());
        v["schemes"].as_array().unwrap()[0]["corrections_per_level"][0]
            .as_u64()
            .unwrap()
    };
    let (parity, blocks) = (finest(&[]), finest(&["--parity-levels", "0"]));
    assert!((2 * 256..2 * 256 + 2 * 18).contains(&parity), "{parity}");
    assert!(blocks > parity, "{blocks} {parity}");
}

/// A reader that stops reading (`solidtex plan … | head`) ends the command
/// quietly and successfully: a write to the closed pipe is not a panic.
#[test]
fn a_closed_stdout_ends_the_command_quietly() {
    let stx = leather_stx();
    for json in [false, true] {
        let mut cmd = std::process::Command::new(env!("CARGO_BIN_EXE_solidtex"));
        cmd.arg("plan").arg(stx).args(["--slice", "16"]);
        if json {
            cmd.arg("--json");
        }
        let mut child = cmd
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        // Closed before the command has planned anything, so its first
        // write finds no reader.
        drop(child.stdout.take());
        let out = child.wait_with_output().unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(
            out.status.success(),
            "json {json}: {:?}\n{stderr}",
            out.status
        );
        assert!(!stderr.contains("panicked"), "json {json}: {stderr}");
    }
}
