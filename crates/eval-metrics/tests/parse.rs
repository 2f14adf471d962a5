//! Trajectory and ground-truth formats.
use eval_metrics::{
    detect_format, parse_euroc, parse_kitti, parse_tum, EvalError, GroundTruth, TrajectoryFormat,
};
use nalgebra::{Point3, Quaternion, Vector3};

#[test]
fn tum_with_comments_blank_lines_and_commas() {
    let t = parse_tum("# timestamp x y z qx qy qz qw\n\n1.0 1 2 3 0 0 0 1\n2.0,4,5,6,0,0,0,1\n")
        .unwrap();
    assert_eq!(t.poses.len(), 2);
    assert_eq!(t.poses[1].position, Vector3::new(4.0, 5.0, 6.0));
    assert_eq!(t.poses[0].orientation, Quaternion::new(1.0, 0.0, 0.0, 0.0));
    // NaN parses: the evaluation turns it into a failed run
    assert!(parse_tum("1 nan 0 0 0 0 0 1\n").unwrap().poses[0].position[0].is_nan());
}

#[test]
fn malformed_lines_are_named() {
    let e = parse_tum("1 2 3 4 5 6 7 8\n1 2 3\n").unwrap_err();
    assert!(matches!(e, EvalError::Parse { line: 2, .. }), "{e}");
    let e = parse_tum("1 2 3 4 5 6 7 8\n\n# c\n1 2 3 x 5 6 7 8\n").unwrap_err();
    assert!(
        e.to_string().starts_with("line 4: expected 8 numbers"),
        "{e}"
    );
    let e = parse_tum("1 2 3 4 5 6 7 8 9\n").unwrap_err();
    assert!(matches!(e, EvalError::Parse { line: 1, .. }));
    let e = GroundTruth::parse("1 0 0 0 0 0 0 1\n1 0 0 0 0 0 0 1\n").unwrap_err();
    assert!(
        matches!(e, EvalError::GroundTruthOrder { line: 2, .. }),
        "{e}"
    );
    assert_eq!(
        GroundTruth::parse("# nothing\n").unwrap_err(),
        EvalError::EmptyGroundTruth
    );
}

#[test]
fn kitti_and_euroc_read_the_same_trajectory_as_tum() {
    let tum =
        parse_tum("10.5 1 2 3 0 0 0.7071067811865476 0.7071067811865476\n11.5 4 5 6 0 0 0 1\n")
            .unwrap();
    let kitti = parse_kitti(
        "0 -1 0 1 1 0 0 2 0 0 1 3\n1 0 0 4 0 1 0 5 0 0 1 6\n",
        "10.5\n11.5\n",
    )
    .unwrap();
    let euroc = parse_euroc(
        "#timestamp [ns],p_x,p_y,p_z,q_w,q_x,q_y,q_z\n10500000000,1,2,3,0.7071067811865476,0,0,0.7071067811865476,9,9\n11500000000,4,5,6,1,0,0,0\n",
    )
    .unwrap();
    for other in [&kitti, &euroc] {
        for (a, b) in tum.poses.iter().zip(&other.poses) {
            assert!((a.t - b.t).abs() < 1e-9);
            assert_eq!(a.position, b.position);
            assert!(
                (a.orientation.coords - b.orientation.coords).amax() < 1e-12,
                "{a:?} {b:?}"
            );
            // the same rigid transform: the camera's x axis in the world
            let x = Point3::new(1.0, 0.0, 0.0);
            let (wa, wb) = (
                a.world_from_camera().unwrap(),
                b.world_from_camera().unwrap(),
            );
            assert!((wa * x - wb * x).amax() < 1e-12);
        }
    }
    let e = parse_kitti("0 -1 0 1 1 0 0 2 0 0 1 3\n", "1\n2\n").unwrap_err();
    assert_eq!(e, EvalError::KittiCount { poses: 1, times: 2 });
    assert_eq!(detect_format("1 2 3 4 5 6 7 8\n"), TrajectoryFormat::Tum);
    assert_eq!(
        detect_format("1 0 0 4 0 1 0 5 0 0 1 6\n"),
        TrajectoryFormat::Kitti
    );
    assert_eq!(
        detect_format("#h\n1403636579763555584,1,2,3,1,0,0,0\n"),
        TrajectoryFormat::Euroc
    );
}

#[test]
fn ground_truth_windows_follow_floor_and_ceil_of_half() {
    let rows = |n: usize| {
        (0..n)
            .map(|i| format!("{i} 0 0 0 0 0 0 1\n"))
            .collect::<String>()
    };
    // n = 5: start rows 1..=2, end rows 3..=5 (1-based)
    assert_eq!(
        GroundTruth::parse(&rows(5)).unwrap().window_bounds(),
        (1, 2)
    );
    // n = 4: start rows 1..=2, end rows 2..=4
    assert_eq!(
        GroundTruth::parse(&rows(4)).unwrap().window_bounds(),
        (1, 1)
    );
    let gt = GroundTruth::parse(
        "0 0 0 0 0 0 0 1\n1 NaN NaN NaN NaN NaN NaN NaN\n2 1 1 1 0 0 0 1\n3 2 2 2 0 0 0 1\n",
    )
    .unwrap();
    assert_eq!(gt.segment_sizes(), (1, 2));
    assert_eq!(gt.associate(2.0009, 0.001), Some(2));
    assert_eq!(gt.associate(2.5, 0.001), None);
}

/// A UTF-8 byte-order mark and CRLF do not matter; a decimal comma gets a hint; DSO's
/// result.txt has double blanks (Eigen's column padding).
#[test]
fn byte_order_mark_crlf_double_blanks_and_decimal_commas() {
    let t = parse_tum("\u{feff}# t x y z qx qy qz qw\r\n191.7 -6.0e-06  4.0e-07 0 0 0 0 1\r\n")
        .unwrap();
    assert_eq!(t.poses.len(), 1);
    assert_eq!(t.poses[0].position, Vector3::new(-6.0e-06, 4.0e-07, 0.0));
    let gt = GroundTruth::parse("\u{feff}0 0 0 0 0 0 0 1\r\n1 1 0 0 0 0 0 1\r\n").unwrap();
    assert_eq!(gt.len(), 2);
    assert_eq!(
        detect_format("\u{feff}1 0 0 4 0 1 0 5 0 0 1 6\n"),
        TrajectoryFormat::Kitti
    );
    let e = parse_tum("1,5 0,1 0 0 0 0 0 1\n").unwrap_err();
    assert!(matches!(e, EvalError::DecimalComma { line: 1, .. }), "{e}");
    assert!(
        e.to_string().contains("decimal separator must be '.'"),
        "{e}"
    );
    let e = GroundTruth::parse("0 0 0 0 0 0 0 1\n1 0,5 0 0 0 0 0 1\n").unwrap_err();
    assert!(matches!(e, EvalError::DecimalComma { line: 2, .. }), "{e}");
}

#[test]
fn zero_quaternions_and_singular_rotations_are_refused_with_the_line() {
    let e = parse_tum("1 0 0 0 0 0 0 1\n2 1 0 0 0 0 0 0\n").unwrap_err();
    assert!(matches!(e, EvalError::NotARotation { line: 2, .. }), "{e}");
    assert!(e.to_string().contains("not a rotation"));
    let e = parse_euroc("1000000000000,0,0,0,0,0,0,0\n").unwrap_err();
    assert!(matches!(e, EvalError::NotARotation { line: 1, .. }), "{e}");
    let e = parse_kitti("0 0 0 1 0 0 0 2 0 0 0 3\n", "0.0\n").unwrap_err();
    assert!(matches!(e, EvalError::NotARotation { line: 1, .. }), "{e}");
    // NaN stays allowed: the run failed, it is not malformed
    assert!(parse_tum("1 0 0 0 nan nan nan nan\n").is_ok());
    // a non-unit quaternion is a rotation too
    assert!(parse_tum("1 0 0 0 0 0 0 2\n").is_ok());
}

/// The camera-to-world transform of a TUM pose: position and normalised quaternion; none
/// for a zero quaternion (which the parsers refuse, but a `Pose` can hold).
#[test]
fn world_from_camera_is_the_pose_as_an_isometry() {
    let t = parse_tum("1 1 2 3 0 0 0 2\n").unwrap();
    let iso = t.poses[0].world_from_camera().unwrap();
    assert_eq!(iso.translation.vector, Vector3::new(1.0, 2.0, 3.0));
    assert!(iso.rotation.angle() < 1e-15);
    let zero = eval_metrics::Pose {
        t: 2.0,
        position: Vector3::new(1.0, 2.0, 3.0),
        orientation: Quaternion::new(0.0, 0.0, 0.0, 0.0),
    };
    assert!(zero.world_from_camera().is_none());
    assert!(zero.is_finite());
    let json = serde_json::to_string(&t.poses[0]).unwrap();
    let back: eval_metrics::Pose = serde_json::from_str(&json).unwrap();
    assert_eq!(back, t.poses[0]);
}
