//! ArUco detection and plane poses on synthetic marker-plane frames.
use camera_model::{CameraFile, Image, OutputMode, RectifyMap};
use photometric::marker::{
    aruco_bits, detect_markers, homography, marker_pose, ARUCO_WORDS, MARKER_CORNERS,
};
use synthetic::plane::{aruco_bitmap, PlaneConfig, PlaneSequence};

/// The inner 5x5 cells of original-dictionary ArUco markers, written out by hand from the
/// dictionary's published rule (independently of the code under test): each row is one of
/// the four words 10000, 10111, 01001, 01110 (1 = white, leftmost cell first), chosen by two
/// bits of the id, the top row by its two most significant bits.
const KNOWN: [(u16, [&str; 5]); 5] = [
    (0, ["10000", "10000", "10000", "10000", "10000"]),
    (1, ["10000", "10000", "10000", "10000", "10111"]),
    // 213 = 00 11 01 01 01
    (213, ["10000", "01110", "10111", "10111", "10111"]),
    // 626 = 10 01 11 00 10
    (626, ["01001", "10111", "01110", "10000", "01001"]),
    (1023, ["01110", "01110", "01110", "01110", "01110"]),
];

fn rows(bits: impl Fn(usize, usize) -> bool) -> [String; 5] {
    [0, 1, 2, 3, 4].map(|y| (0..5).map(|x| if bits(y, x) { '1' } else { '0' }).collect())
}

#[test]
fn dictionary_matches_the_published_patterns() {
    for (id, want) in KNOWN {
        let got = aruco_bits(id);
        assert_eq!(rows(|y, x| got[y][x]), want, "detector's id {id}");
        // the synthetic generator draws the same marker, inside a black border
        let drawn = aruco_bitmap(id);
        assert_eq!(
            rows(|y, x| drawn[y + 1][x + 1]),
            want,
            "generator's id {id}"
        );
        assert!((0..7).all(|i| !drawn[0][i] && !drawn[6][i] && !drawn[i][0] && !drawn[i][6]));
    }
    // the four words are 3 bits apart or more: one flipped cell per row is never another word
    for a in ARUCO_WORDS {
        for b in ARUCO_WORDS {
            if a != b {
                assert!((a ^ b).count_ones() >= 3, "{a:05b} {b:05b}");
            }
        }
    }
}

/// A marker drawn upright, rotated by 90, 180 and 270 degrees, reads as its own id every
/// time, with corner 0 at the bitmap's top-left.
#[test]
fn rendered_markers_are_detected_in_every_rotation() {
    for id in [213u16, 626, 1] {
        let bm = aruco_bitmap(id);
        for quarter in 0..4 {
            // 7 cells of 20 px, centred in a 240x240 white image
            let img = Image::from_fn(240, 240, |x, y| {
                let (cx, cy) = (x as i64 - 50, y as i64 - 50);
                if !(0..140).contains(&cx) || !(0..140).contains(&cy) {
                    return 235;
                }
                let (c, r) = ((cx / 20) as usize, (cy / 20) as usize);
                // rotate the image's cell (c, r) back into the bitmap
                let (bc, br) = match quarter {
                    0 => (c, r),
                    1 => (r, 6 - c),
                    2 => (6 - c, 6 - r),
                    _ => (6 - r, c),
                };
                if bm[br][bc] {
                    235
                } else {
                    20
                }
            });
            let det = detect_markers(&img);
            assert_eq!(det.len(), 1, "id {id} quarter {quarter}: {det:?}");
            assert_eq!(det[0].id, id, "quarter {quarter}");
            // where the bitmap's top-left corner went (the outline spans 49.5..189.5)
            let want = match quarter {
                0 => [49.5, 49.5],
                1 => [189.5, 49.5],
                2 => [189.5, 189.5],
                _ => [49.5, 189.5],
            };
            let c0 = det[0].corners[0];
            assert!(
                (c0[0] - want[0]).abs() < 1.0 && (c0[1] - want[1]).abs() < 1.0,
                "id {id} quarter {quarter}: corner 0 at {c0:?}, want {want:?}"
            );
        }
    }
}

/// The homography maps the four points exactly, and three collinear points have none.
#[test]
fn homography_maps_the_points_and_refuses_collinear_ones() {
    let src = [[0.0, 0.0], [7.0, 0.0], [7.0, 7.0], [0.0, 7.0]];
    let dst = [[10.0, 12.0], [80.0, 5.0], [95.0, 90.0], [3.0, 70.0]];
    let h = homography(&src, &dst).unwrap();
    for (s, d) in src.iter().zip(&dst) {
        let w = h[2][0] * s[0] + h[2][1] * s[1] + h[2][2];
        let u = (h[0][0] * s[0] + h[0][1] * s[1] + h[0][2]) / w;
        let v = (h[1][0] * s[0] + h[1][1] * s[1] + h[1][2]) / w;
        assert!((u - d[0]).abs() < 1e-9 && (v - d[1]).abs() < 1e-9);
    }
    let line = [[0.0, 0.0], [1.0, 1.0], [2.0, 2.0], [3.0, 3.0]];
    assert!(homography(&line, &dst).is_none());
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
