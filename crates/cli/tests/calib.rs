//! `monovo calib response`.
use crate::common::{monovo, stderr, stdout, temp_dir};

#[test]
fn response_calibration_end_to_end_and_bad_sweeps() {
    let d = temp_dir("calib_response");
    let sweep = d.join("sweep");
    let o = monovo(&[
        "synth",
        "sweep",
        "-o",
        sweep.to_str().unwrap(),
        "--size",
        "320x256",
        "--frames",
        "30",
        "--step",
        "1.2",
        "--png",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let pcalib = d.join("pcalib.txt");
    let plot = d.join("response.svg");
    let o = monovo(&[
        "calib",
        "response",
        sweep.to_str().unwrap(),
        "-o",
        pcalib.to_str().unwrap(),
        "--plot",
        plot.to_str().unwrap(),
        "--json",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_str(stdout(&o).trim()).unwrap();
    assert_eq!(v["converged"], true);
    let got =
        photometric::InverseResponse::parse(&std::fs::read_to_string(&pcalib).unwrap()).unwrap();
    let truth = photometric::InverseResponse::parse(
        &std::fs::read_to_string(sweep.join("truth_pcalib.txt")).unwrap(),
    )
    .unwrap();
    let max = (0..255)
        .map(|k| (got.values()[k] - truth.values()[k]).abs())
        .fold(0.0, f64::max);
    assert!(max < 3.0, "max error {max}");
    assert!(std::fs::read_to_string(&plot).unwrap().contains("<svg"));

    // all frames at one exposure: a clear error and no output
    let same = d.join("same");
    std::fs::create_dir_all(&same).unwrap();
    std::fs::copy(sweep.join("images.zip"), same.join("images.zip")).unwrap();
    let t: String = std::fs::read_to_string(sweep.join("times.txt"))
        .unwrap()
        .lines()
        .map(|l| {
            let f: Vec<&str> = l.split_whitespace().collect();
            format!("{} {} 5.0\n", f[0], f[1])
        })
        .collect();
    std::fs::write(same.join("times.txt"), &t).unwrap();
    let out = d.join("same_pcalib.txt");
    let o = monovo(&[
        "calib",
        "response",
        same.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("same exposure"), "{}", stderr(&o));
    assert!(!out.exists());

    // no exposures
    let t2: String = t
        .lines()
        .map(|l| l.split_whitespace().take(2).collect::<Vec<_>>().join(" ") + "\n")
        .collect();
    std::fs::write(same.join("times.txt"), t2).unwrap();
    let o = monovo(&[
        "calib",
        "response",
        same.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("times.txt") && stderr(&o).contains("exposure"),
        "{}",
        stderr(&o)
    );
    assert!(!out.exists());
}
