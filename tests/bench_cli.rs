//! `solidtex bench --quick` end to end, as CI runs it: the engine suite,
//! both schemes' dependency sets, a short load test, and the Markdown page.

mod common;

use common::solidtex_json;
use serde_json::Value;

#[test]
fn quick_bench_measures_everything_and_writes_the_page() {
    let dir = tempfile::tempdir().unwrap();
    let page = dir.path().join("BENCHMARKS.md");
    let v: Value = solidtex_json(&[
        "bench",
        "--quick",
        "--json",
        "--load",
        "--load-duration",
        "1s",
        "--load-clients",
        "4",
        "--exemplars",
        "tests/fixtures/exemplars",
        "--markdown",
        page.to_str().unwrap(),
    ]);
    let rows = v["rows"].as_array().unwrap();
    let row = |name: &str| {
        rows.iter()
            .find(|r| r["name"].as_str().unwrap().starts_with(name))
            .unwrap_or_else(|| panic!("no row {name}: {v}"))
    };
    for name in [
        "precompute 64×64",
        "single voxel, cold",
        "brick 8³ cold",
        "brick 8³ warm",
        "full volume 16³ cold",
        "axis slice 32² cold",
        "axis slice 32² warm",
        "oblique cut 32² cold",
        "oblique cut 32² warm",
    ] {
        let r = row(name);
        let s = r["seconds"].as_f64().unwrap_or_else(|| panic!("{r}"));
        assert!(s > 0.0, "{r}");
    }
    // Cold synthesis allocates; a warm request is a cheap copy.
    let cold = row("axis slice 32² cold")["peak_bytes"].as_u64().unwrap();
    let warm = row("axis slice 32² warm")["peak_bytes"].as_u64().unwrap();
    assert!(cold > 1 << 18 && warm * 8 < cold, "{cold} {warm}");
    assert!(
        row("axis slice 32² warm")["seconds"].as_f64()
            < row("axis slice 32² cold")["seconds"].as_f64()
    );

    // The preview parameters skip the finest level's correction and a
    // pass at the coarse ones: far fewer corrections for the same slice.
    let corrections = |name: &str| -> u64 {
        let r = row(name);
        let detail = r["detail"].as_str().unwrap();
        let words: Vec<&str> = detail.split_whitespace().collect();
        let at = words
            .iter()
            .position(|w| w.starts_with("corrections"))
            .unwrap_or_else(|| panic!("{r}"));
        words[at - 1].parse().unwrap()
    };
    for name in [
        "preview: axis slice 16² cold",
        "preview: brick 8³ cold",
        "preview: full volume 16³ cold",
    ] {
        assert!(row(name)["seconds"].as_f64().unwrap() > 0.0);
    }
    assert!(
        4 * corrections("preview: axis slice 16² cold") < corrections("axis slice 16² cold"),
        "{v}"
    );

    // The dual grid needs fewer voxels than the standard scheme for a
    // slice, and never more for a single voxel (with one finest pass and
    // two levels, the chain stays inside one cell and both are equal).
    let plans = v["plans"].as_array().unwrap();
    assert_eq!(plans.len(), 14);
    let total = |scheme: &str, request: &str| -> u64 {
        plans
            .iter()
            .find(|p| p["scheme"] == scheme && p["request"].as_str().unwrap().starts_with(request))
            .unwrap()["voxels_per_level"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_u64().unwrap())
            .sum()
    };
    let slice = "32² axis slice (4³ tiles";
    assert!(total("dual-grid", slice) < total("standard", slice));
    let single = "single voxel";
    assert!(total("dual-grid", single) <= total("standard", single));

    let load = v["load"].as_array().unwrap();
    assert_eq!(load.len(), 5);
    for l in load {
        let t = &l["report"]["total"];
        assert!(t["requests"].as_u64().unwrap() >= 1, "{l}");
        assert_eq!(t["statuses"]["other"], 0, "{l}");
        assert_eq!(t["statuses"]["transport_errors"], 0, "{l}");
    }

    let md = std::fs::read_to_string(&page).unwrap();
    for needle in [
        "# Benchmarks",
        "| machine |",
        "| command | `solidtex bench --quick",
        "Dong 2008",
        "## Service under load",
        "dual-grid",
        "preview parameters",
    ] {
        assert!(md.contains(needle), "page lacks {needle:?}:\n{md}");
    }
}

#[test]
fn a_bad_wait_limit_is_refused_before_anything_runs() {
    for bad in ["0", "soon", "1e9"] {
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_solidtex"))
            .args(["bench", "--quick", "--load", "--load-max-wait", bad])
            .output()
            .unwrap();
        assert!(!out.status.success(), "--load-max-wait {bad} accepted");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains("--load-max-wait"), "{err}");
    }
}
