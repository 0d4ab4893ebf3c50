//! `verdant eval sway` from the command line: the CSV's rows and the charts.

use std::process::Command;

#[test]
fn eval_sway_writes_the_csv_and_the_charts() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("sway");
    let run = Command::new(env!("CARGO_BIN_EXE_verdant"))
        .args(["eval", "sway", "--out", out.to_str().unwrap()])
        .output()
        .expect("run verdant");
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(
        run.status.success(),
        "stdout: {stdout}\nstderr: {}",
        String::from_utf8_lossy(&run.stderr)
    );
    assert!(stdout.contains("renderer integrator: exact"), "{stdout}");

    let csv = std::fs::read_to_string(out.join("sway.csv")).unwrap();
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    assert_eq!(
        header[..8],
        [
            "preset",
            "integrator",
            "dt_s",
            "rms_error",
            "max_error",
            "ns_per_step",
            "stable",
            "blew_up_at_s"
        ]
    );
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    // 2 presets x 3 integrators x 9 time steps.
    assert_eq!(rows.len(), 2 * 3 * 9);
    let dts = [
        1.0 / 240.0,
        1.0 / 144.0,
        1.0 / 120.0,
        1.0 / 60.0,
        1.0 / 30.0,
        1.0 / 20.0,
        1.0 / 10.0,
        1.0 / 5.0,
        0.5,
    ];
    for preset in ["stiff", "soft"] {
        for integrator in ["explicit", "semi-implicit", "exact"] {
            for dt in dts {
                let row = rows
                    .iter()
                    .find(|r| {
                        r[0] == preset
                            && r[1] == integrator
                            && (r[2].parse::<f64>().unwrap() - dt).abs() < 1e-6
                    })
                    .unwrap_or_else(|| panic!("no row for {preset} {integrator} {dt}"));
                assert_eq!(row.len(), header.len());
                let ns: f64 = row[5].parse().unwrap();
                assert!(ns > 0.0 && ns < 1e5, "{row:?}");
                let stable: bool = row[6].parse().unwrap();
                // Stable rows have a finite error and no blow-up time; the others a time.
                assert_eq!(row[7].is_empty(), stable, "{row:?}");
                if stable {
                    assert!(row[3].parse::<f64>().unwrap().is_finite(), "{row:?}");
                } else {
                    let t: f64 = row[7].parse().unwrap();
                    assert!(t > 0.0 && t <= 20.0 + 1e-9, "{row:?}");
                }
                if integrator == "exact" {
                    assert!(stable, "{row:?}");
                }
            }
        }
    }
    // Explicit Euler blows up on the stiff spring at the hitch.
    assert!(
        rows.iter().any(|r| r[0] == "stiff"
            && r[1] == "explicit"
            && r[2] == "0.500000"
            && r[6] == "false")
    );

    for chart in ["sway_error.png", "sway_stability.png"] {
        let img = image::open(out.join(chart))
            .unwrap_or_else(|e| panic!("{chart}: {e}"))
            .to_rgb8();
        assert!(img.width() >= 800 && img.height() >= 500, "{chart}");
    }
}
