//! pcalib.txt and vignette maps.
use camera_model::Image;
use photometric::{InverseResponse, PhotometricError, Vignette};
use synthetic::camera::ground_truth_response;

#[test]
fn pcalib_round_trips_at_full_precision() {
    let u = InverseResponse::new(ground_truth_response()).unwrap();
    let text = u.to_text();
    assert_eq!(text.lines().count(), 1);
    let back = InverseResponse::parse(&text).unwrap();
    assert_eq!(back, u);
    // several lines are fine too
    let multi = text.replace(' ', "\n");
    assert_eq!(InverseResponse::parse(&multi).unwrap(), u);
}

#[test]
fn bad_pcalib_is_refused_with_the_reason() {
    let mut vals: Vec<String> = (0..256).map(|k| k.to_string()).collect();
    vals[17] = "nan".into();
    let e = InverseResponse::parse(&vals.join(" ")).unwrap_err();
    assert!(
        matches!(
            e,
            PhotometricError::NotFinite {
                index: 17,
                line: 1,
                ..
            }
        ),
        "{e}"
    );
    let mut vals: Vec<String> = (0..256).map(|k| k.to_string()).collect();
    vals[100] = "98.5".into();
    let e = InverseResponse::parse(&vals.join(" ")).unwrap_err();
    assert!(
        matches!(e, PhotometricError::NotIncreasing { index: 100, .. }),
        "{e}"
    );
    assert!(e.to_string().contains("U(100)"));
    let e = InverseResponse::parse("1 2 3").unwrap_err();
    assert!(
        e.to_string()
            == "line 1: expected 2^k values (256 for 8-bit, 65536 for 16-bit images, or 513 to 65536 for a deeper table that ends at the saturation value), found 3 numbers",
        "{e}"
    );
    let e = InverseResponse::parse(&format!(
        "{} x",
        (0..255)
            .map(|k| k.to_string())
            .collect::<Vec<_>>()
            .join(" ")
    ))
    .unwrap_err();
    assert!(matches!(e, PhotometricError::Parse { line: 1, .. }));
    let e = InverseResponse::parse(
        &(0..257)
            .map(|k| k.to_string())
            .collect::<Vec<_>>()
            .join(" "),
    )
    .unwrap_err();
    assert!(
        matches!(
            e,
            PhotometricError::ValueCount {
                line: 1,
                found: 257
            }
        ),
        "{e}"
    );
    assert!(e.to_string().contains("expected 2^k values"), "{e}");
    let e = InverseResponse::parse("0 0,5 1").unwrap_err();
    assert!(
        e.to_string().contains("decimal separator must be '.'"),
        "{e}"
    );
}

/// 2^k values for k = 8..16: DM-VIO's TUM-VI calibration has 65536, for 16-bit frames.
#[test]
fn pcalib_of_any_power_of_two_from_256_to_65536() {
    for k in 8..=16u32 {
        let n = 1usize << k;
        let text = (0..n)
            .map(|i| format!("{}", (i as f64 / (n - 1) as f64).powf(2.0) * 1000.0))
            .collect::<Vec<_>>()
            .join(" ");
        let u = InverseResponse::parse(&text).unwrap();
        assert_eq!((u.bits(), u.table().len()), (k, n));
        assert_eq!(u.max_value(), 1000.0);
        // the 8-bit table samples the curve at full range
        for v in [0u8, 1, 100, 254, 255] {
            let want = (v as f64 / 255.0).powf(2.0) * 1000.0;
            let tol = if k == 8 || k == 16 { 1e-9 } else { 1e-2 };
            assert!(
                (u.get(v) - want).abs() < tol,
                "k={k} v={v}: {} {want}",
                u.get(v)
            );
        }
        // exact lookup at the table's own depth
        assert_eq!(u.table_for_bits(k).unwrap(), u.table());
        let t12 = u.table_for_bits(12).unwrap();
        assert_eq!(t12.len(), 4096);
        assert_eq!((t12[0], t12[4095]), (0.0, 1000.0));
        assert!(t12.windows(2).all(|w| w[1] > w[0]));
    }
    for n in [128usize, 300, 65537] {
        let text = (0..n).map(|i| i.to_string()).collect::<Vec<_>>().join(" ");
        let e = InverseResponse::parse(&text).unwrap_err();
        assert!(
            e.to_string().contains(&format!("found {n} numbers")),
            "{n}: {e}"
        );
    }
    assert!(InverseResponse::linear().table_for_bits(17).is_err());
}

/// A byte-order mark, CRLF, and a trailing line of text (DSSO's `vis_exponent: 1.0`) are
/// read like DSO reads line 1.
#[test]
fn pcalib_reads_line_one_like_dso() {
    let vals = (0..256)
        .map(|k| k.to_string())
        .collect::<Vec<_>>()
        .join(" ");
    let (u, notes) =
        InverseResponse::parse_with_notes(&format!("\u{feff}{vals}\r\nvis_exponent: 1.000000\r\n"))
            .unwrap();
    assert_eq!(u, InverseResponse::linear());
    assert_eq!(notes.len(), 2, "{notes:?}");
    assert!(notes[1].contains("line 2") && notes[1].contains("vis_exponent"));
    let (_, notes) = InverseResponse::parse_with_notes(&format!("{vals}\n\n")).unwrap();
    assert!(notes.is_empty());
    // a non-monotone table names the line
    let e = InverseResponse::parse(&vals.replace(" 200 ", " 198 ")).unwrap_err();
    assert!(
        e.to_string()
            .starts_with("line 1: the inverse response must strictly increase"),
        "{e}"
    );
}

#[test]
fn vignette_is_normalised_and_zero_pixels_are_masked() {
    let img = Image::from_fn(
        8,
        6,
        |x, _| if x == 0 { 0u16 } else { 1000 + x as u16 * 100 },
    );
    let v = Vignette::from_u16(&img).unwrap();
    assert_eq!(v.values().get(7, 3), Some(1.0));
    assert_eq!(v.masked(), 6);
    assert!((v.min_positive() - 1100.0 / 1700.0).abs() < 1e-6);
    assert_eq!(v.to_u16().get(7, 0), Some(65535));
    assert!(Vignette::from_u16(&Image::filled(4, 4, 0u16)).is_err());
    assert!(Vignette::from_values(Image::filled(4, 4, f32::NAN)).is_err());
    assert!(v.check_size(8, 6).is_ok() && v.check_size(6, 8).is_err());
}

proptest::proptest! {
    /// The vectorised scans of `from_values` and `min_positive` against their plain
    /// definitions, over lengths that leave every remainder of the lanes, with zeros and any
    /// one bad value (NaN, an infinity, a negative) anywhere, the remainder included.
    #[test]
    fn vignette_scans_match_their_definitions(
        vals in proptest::collection::vec(proptest::prop_oneof![
            3 => 0.0f32..1000.0,
            1 => proptest::strategy::Just(0.0f32),
        ], 1..70),
        bad in proptest::option::of((0usize..70, proptest::prop_oneof![
            proptest::strategy::Just(f32::NAN),
            proptest::strategy::Just(f32::INFINITY),
            proptest::strategy::Just(f32::NEG_INFINITY),
            -5.0f32..-1e-6,
        ])),
    ) {
        let mut vals = vals;
        if let Some((at, v)) = bad {
            let at = at % vals.len();
            vals[at] = v;
        }
        let n = vals.len();
        let got = Vignette::from_values(Image::new(n, 1, vals.clone()).unwrap());
        let valid = vals.iter().all(|v| v.is_finite() && *v >= 0.0);
        let max = vals.iter().copied().fold(0.0f32, f32::max);
        if !valid {
            let first = vals.iter().find(|v| !(v.is_finite() && **v >= 0.0)).unwrap();
            let e = got.unwrap_err().to_string();
            proptest::prop_assert!(e.contains(&format!("value {first} ")), "{e}");
        } else if max <= 0.0 {
            proptest::prop_assert!(got.is_err());
        } else {
            let v = got.unwrap();
            let want: Vec<f32> = vals.iter().map(|x| x / max).collect();
            proptest::prop_assert_eq!(v.values().data(), &want[..]);
            proptest::prop_assert_eq!(v.masked(), vals.iter().filter(|x| **x == 0.0).count());
            let min = want.iter().copied().filter(|x| *x > 0.0).fold(1.0, f32::min);
            proptest::prop_assert_eq!(v.min_positive(), min);
        }
    }
}

#[test]
fn response_errors_are_scale_aware() {
    let truth = ground_truth_response();
    let u = InverseResponse::new(truth).unwrap();
    assert_eq!(u.errors_against(&truth), (0.0, 0.0));
    // a scaled copy has a max error but no RMS error after the best scale
    let scaled = InverseResponse::new(truth.map(|v| v * 1.05)).unwrap();
    let (max, rms) = scaled.errors_against(&truth);
    assert!((max - 0.05 * truth[254]).abs() < 1e-9, "{max}");
    assert!(rms < 1e-9, "{rms}");
}

/// A deep table that ends at the saturation value, as the 16-bit forks of the authors' tools
/// write it (saturation value + 1 numbers): read as a table of the next power of two whose
/// values above the saturation value are saturated, written back as given, with a note.
#[test]
fn a_table_ending_at_the_saturation_value_is_read_as_the_forks_write_it() {
    let values: Vec<f64> = (0..4001)
        .map(|k| (k as f64 / 4000.0).powf(1.8) * 255.0)
        .collect();
    let text = values
        .iter()
        .map(|v| format!("{v}"))
        .collect::<Vec<_>>()
        .join(" ");
    let (u, notes) = InverseResponse::parse_with_notes(&text).unwrap();
    assert_eq!(u.bits(), 12);
    assert_eq!(u.saturation_value(), 4000);
    assert_eq!(u.table().len(), 4096);
    assert_eq!(&u.table()[..4001], &values[..]);
    assert!(u.table()[4001..].iter().all(|&v| v == values[4000]));
    assert_eq!(u.max_value(), values[4000]);
    assert!(
        notes
            .iter()
            .any(|n| n.contains("4001 values") && n.contains("saturation value 4000")),
        "{notes:?}"
    );
    // the 12-bit lookup indexes it directly; values above 4000 are saturated
    let t12 = u.table_for_bits(12).unwrap();
    assert_eq!(t12[1234], values[1234]);
    assert_eq!(t12[4095], values[4000]);
    // written back with 4001 numbers, and read again to the same table
    let again = InverseResponse::parse(&u.to_text()).unwrap();
    assert_eq!(u.to_text().split_whitespace().count(), 4001);
    assert_eq!(again, u);
    // a table must still increase where it is given
    let mut bad = values.clone();
    bad[3000] = bad[2999];
    let e = InverseResponse::from_values(bad).unwrap_err();
    assert!(
        matches!(e, PhotometricError::NotIncreasing { index: 3000, .. }),
        "{e}"
    );
    // short odd lengths are no deep table: most likely a damaged 8-bit file
    for n in [255, 257, 300, 511, 512] {
        let r = InverseResponse::from_values((0..n).map(|k| k as f64).collect());
        assert_eq!(r.is_ok(), n == 512, "{n} values");
    }
}
