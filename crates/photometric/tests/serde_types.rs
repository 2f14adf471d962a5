//! Options read back what was written; results serialise to JSON.
use photometric::{InverseResponse, PlanePose, ResponseOptions, VignetteOptions};

#[test]
fn options_round_trip_through_json() {
    let r = ResponseOptions {
        max_iterations: 7,
        smoothness: 0.5,
        ..ResponseOptions::default()
    };
    let back: ResponseOptions = serde_json::from_str(&serde_json::to_string(&r).unwrap()).unwrap();
    assert_eq!(format!("{back:?}"), format!("{r:?}"));
    let v = VignetteOptions {
        grid: 300,
        smoothing_px: Some(2.5),
        ..VignetteOptions::default()
    };
    let back: VignetteOptions = serde_json::from_str(&serde_json::to_string(&v).unwrap()).unwrap();
    assert_eq!(format!("{back:?}"), format!("{v:?}"));
    let p = PlanePose {
        r: [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]],
        t: [0.1, 0.2, 2.0],
    };
    let back: PlanePose = serde_json::from_str(&serde_json::to_string(&p).unwrap()).unwrap();
    assert_eq!(back, p);
}

#[test]
fn the_inverse_response_serialises_its_table() {
    let table: Vec<f64> = (0..256).map(|k| k as f64).collect();
    let u = InverseResponse::from_values(table).unwrap();
    let v: serde_json::Value = serde_json::to_value(&u).unwrap();
    assert_eq!(v["table"].as_array().unwrap().len(), 256);
    assert_eq!(v["table"][255], 255.0);
}
