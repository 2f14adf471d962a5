//! Ground truth in the other datasets' formats (EuRoC/TUM-VI csv, 4Seasons GNSSPoses, KITTI,
//! TUM) and the per-frame ground truth made from them.
use eval_metrics::nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use eval_metrics::{
    detect_ground_truth_format, parse_euroc, parse_gnss_poses, parse_ground_truth_trajectory,
    GroundTruth, GroundTruthFormat,
};

fn fixture(rel: &str) -> String {
    let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../tests/fixtures/datasets")
        .join(rel);
    std::fs::read_to_string(&p).unwrap()
}

#[test]
fn formats_are_told_apart() {
    let euroc = "#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], q_RS_z [], v_RS_R_x [m s^-1], v_RS_R_y [m s^-1], v_RS_R_z [m s^-1], b_w_RS_S_x [rad s^-1], b_w_RS_S_y [rad s^-1], b_w_RS_S_z [rad s^-1], b_a_RS_S_x [m s^-2], b_a_RS_S_y [m s^-2], b_a_RS_S_z [m s^-2]\n1403636580838555648,4.688319,-1.786938,0.783338,0.534108,-0.153029,-0.827383,-0.082152,-0.027876,0.033207,0.800006,-0.003172,0.021267,0.078502,-0.025266,0.136696,0.075593\n";
    assert_eq!(detect_ground_truth_format(euroc), GroundTruthFormat::Euroc);
    let mocap = "#timestamp [ns],p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m],q_RS_w [],q_RS_x [],q_RS_y [],q_RS_z []\n1520530308199447626,0.88,-0.29,1.20,0.71,0.03,-0.02,-0.69\n";
    assert_eq!(detect_ground_truth_format(mocap), GroundTruthFormat::Euroc);
    let gnss = "# timestamp, tx, ty, tz, qx, qy, qz, qw, scale, fusion_quality, v3_quality\n1585067782140857088,1.0,2.0,3.0,0,0,0,1,2.5,1,1\n";
    assert_eq!(
        detect_ground_truth_format(gnss),
        GroundTruthFormat::GnssPoses
    );
    // DM-VIO's 4Seasons ground truth, converted to TUM format (real head)
    let tum = fixture("heads/dm-vio-python-tools__4seasons_office__gt.head.txt");
    assert_eq!(detect_ground_truth_format(&tum), GroundTruthFormat::Tum);
    let t = parse_ground_truth_trajectory(&tum, GroundTruthFormat::Tum, None).unwrap();
    assert_eq!(t.poses.len(), 20);
    let e = parse_euroc(euroc).unwrap();
    assert_eq!(e.poses[0].orientation.w, 0.534108, "w first");
}

#[test]
fn gnss_poses_scale_the_translation() {
    let gnss = "# header\n1000000000000,1.0,2.0,3.0,0,0,0,1,2.5,1,1\n2000000000000,2.0,2.0,3.0,0,0,0,1,2.5,1,1\n";
    let t = parse_gnss_poses(gnss).unwrap();
    assert_eq!(t.poses[0].position, Vector3::new(2.5, 5.0, 7.5));
    assert_eq!(t.poses[1].t, 2000.0);
    let e = parse_gnss_poses("1,2,3\n").unwrap_err().to_string();
    assert!(e.contains("line 1") && e.contains("scale"), "{e}");
    let e = parse_gnss_poses("1000000000000,1,2,3,0,0,0,1,-1,1\n")
        .unwrap_err()
        .to_string();
    assert!(e.contains("positive scale"), "{e}");
}

/// An IMU pose moved to the camera: `world_from_imu * imu_from_camera`; sampled at frame
/// times by linear interpolation, NaN across gaps wider than the limit.
#[test]
fn per_frame_ground_truth_from_body_poses() {
    // the IMU turned by 90 degrees about z, moving along x
    let q = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::FRAC_PI_2);
    let text: String = (0..5)
        .map(|i| {
            format!(
                "{},{},0,0,{},{},{},{}\n",
                1_000_000_000i64 * (10 + i),
                i as f64,
                q.w,
                q.i,
                q.j,
                q.k
            )
        })
        .chain(std::iter::once("20000000000,9,0,0,1,0,0,0\n".to_string()))
        .collect();
    let traj = parse_euroc(&text).unwrap();
    let imu_from_camera =
        Isometry3::from_parts(Translation3::new(0.1, 0.0, 0.0), UnitQuaternion::identity());
    let gt = GroundTruth::from_trajectory(
        &traj,
        Some(&imu_from_camera),
        Some(&[10.0, 11.5, 16.0, 30.0]),
        1.5,
    )
    .unwrap();
    let p = gt.positions();
    // at t = 10: IMU at 0, the camera 0.1 along the IMU's x = world y
    assert!((p[0] - Vector3::new(0.0, 0.1, 0.0)).norm() < 1e-12);
    assert!((p[1] - Vector3::new(1.5, 0.1, 0.0)).norm() < 1e-12);
    // 14 .. 20 is a gap of 6 s: no ground truth there, nor after the end
    assert!(p[2].x.is_nan() && p[3].x.is_nan());
    // without frame times, the rows themselves
    let rows = GroundTruth::from_trajectory(&traj, None, None, 0.0).unwrap();
    assert_eq!(rows.len(), 6);
}
