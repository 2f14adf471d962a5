//! ArUco detection and plane poses on synthetic marker-plane frames.
use camera_model::{CameraFile, Image, OutputMode, RectifyMap};
use photometric::marker::{aruco_bits, detect_markers, marker_pose, MARKER_CORNERS};
use synthetic::plane::{aruco_bitmap, PlaneConfig, PlaneSequence};

#[test]
fn dictionary_matches_the_generator() {
    for id in [0u16, 1, 213, 512, 1023] {
        let a = aruco_bits(id);
        let b = aruco_bitmap(id);
        for y in 0..5 {
            for x in 0..5 {
                assert_eq!(a[y][x], b[y + 1][x + 1]);
            }
        }
    }
}

/// Corners found in the full-view pinhole rectification of synthetic FOV frames agree with
/// the true projection to better than 0.1 px RMS; the pose from them maps the marker corners
/// back onto their pixels.
#[test]
fn detected_corners_are_sub_pixel_accurate() {
    let seq = PlaneSequence::new(
        3,
        PlaneConfig {
            width: 640,
            height: 512,
            frames: 12,
            ..PlaneConfig::default()
        },
    );
    let cam = CameraFile::parse(&seq.camera.camera_txt((640, 512))).unwrap();
    let map = RectifyMap::for_mode(
        &cam.input,
        cam.input_size,
        &OutputMode::Full,
        cam.input_size,
    )
    .unwrap();
    let k = map.camera();
    let (mut sq, mut n, mut found) = (0.0, 0usize, 0);
    for i in 0..12 {
        let raw = Image::new(640, 512, seq.render(i)).unwrap();
        let rect = map.remap_u8(&raw).unwrap();
        let det = detect_markers(&rect);
        let Some(d) = det.iter().find(|d| d.id == 213) else {
            continue;
        };
        found += 1;
        assert_eq!(det.iter().filter(|d| d.id == 213).count(), 1);
        let p = seq.poses[i];
        for (c, got) in MARKER_CORNERS.iter().zip(&d.corners) {
            let x = [
                p.r[0][0] * c[0] + p.r[0][1] * c[1] + p.t[0],
                p.r[1][0] * c[0] + p.r[1][1] * c[1] + p.t[1],
                p.r[2][0] * c[0] + p.r[2][1] * c[1] + p.t[2],
            ];
            let want = k.normalized_to_pixel([x[0] / x[2], x[1] / x[2]]);
            let e2 = (got[0] - want[0]).powi(2) + (got[1] - want[1]).powi(2);
            assert!(e2.sqrt() < 0.5, "frame {i}: {got:?} vs {want:?}");
            sq += e2;
            n += 1;
        }
        let pose = marker_pose(&k, &d.corners).unwrap();
        for j in 0..3 {
            assert!(
                (pose.t[j] - p.t[j]).abs() < 0.02 * p.t[2],
                "t {:?} vs {:?}",
                pose.t,
                p.t
            );
        }
    }
    assert!(found >= 10, "marker found in {found} of 12 frames");
    let rms = (sq / n as f64).sqrt();
    eprintln!("corner RMS {rms:.4} px over {n} corners in {found} frames");
    assert!(rms < 0.1, "corner RMS {rms} px");
}

#[test]
fn no_marker_no_detection() {
    let img = Image::from_fn(320, 240, |x, y| (200 + ((x + y) % 7)) as u8);
    assert!(detect_markers(&img).is_empty());
}
