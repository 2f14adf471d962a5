//! Photometric calibration of a sequence folder, as `monovo calib` runs it: reading the
//! frames of a response sweep at their own bit depth ([`load_exposed_frames`],
//! [`load_exposed_deep_frames`]), the vignette calibration of a marker-plane video
//! ([`calibrate_vignette_sequence`]: plane poses from the marker or a poses file, 8- or
//! 16-bit frames, frames cached or streamed), writing its maps ([`write_vignette_maps`]),
//! and the figures of both calibrations ([`response_figure`], [`vignette_figure`]).

use std::path::{Path, PathBuf};

use camera_model::Image;
use dataset_io::Sequence;

use crate::figures::{self, Chart, Corner, Figure, Panel, Series, PALETTE};
use crate::{Observer, PipelineError, Result, WithContext};

/// Reads every frame of a sequence at its own bit depth with its exposure; errors when
/// exposures are missing.
fn load_exposed_native(
    seq: &Sequence,
    observer: &dyn Observer,
) -> Result<(Vec<dataset_io::GrayImage>, Vec<f64>)> {
    if let Some((k, line)) = seq.times().first_unknown_exposure() {
        return Err(PipelineError::Invalid(format!(
            "{}: line {line}: the exposure of frame {k} is unknown (0 or missing); calibration needs the exposure time of every frame (third column, > 0)",
            seq.times_path().display()
        )));
    }
    let idx = seq.indices(0..seq.len(), false);
    observer.begin(idx.len() as u64, "decoding", "frames");
    let mut frames = Vec::with_capacity(idx.len());
    let mut exposures = Vec::with_capacity(idx.len());
    seq.process_native(
        &idx,
        rayon::current_num_threads() * 4,
        |f| {
            observer.advance(1);
            Ok::<_, PipelineError>(f)
        },
        |f| {
            exposures.push(f.exposure_ms.unwrap_or(0.0));
            frames.push(f.image);
            Ok(())
        },
    )?;
    observer.finish();
    Ok((frames, exposures))
}

/// The frames of `seq` (read by [`load_exposed_native`]) as one sample type; a frame of the
/// other depth is an error naming it.
fn same_depth<T>(
    seq: &Sequence,
    frames: Vec<dataset_io::GrayImage>,
    pick: impl Fn(dataset_io::GrayImage) -> Option<Image<T>>,
) -> Result<Vec<Image<T>>> {
    let bits = seq.bits_per_sample();
    frames
        .into_iter()
        .enumerate()
        .map(|(i, f)| {
            let other = f.bits();
            pick(f).ok_or_else(|| {
                PipelineError::Invalid(format!(
                    "{}: a {other}-bit frame in a {bits}-bit sequence",
                    seq.names()[i]
                ))
            })
        })
        .collect()
}

/// Reads every frame of an 8-bit sequence with its exposure; errors when exposures are
/// missing.
pub fn load_exposed_frames(
    seq: &Sequence,
    observer: &dyn Observer,
) -> Result<(Vec<Image<u8>>, Vec<f64>)> {
    let (frames, exposures) = load_exposed_native(seq, observer)?;
    let frames = same_depth(seq, frames, |f| match f {
        dataset_io::GrayImage::U8(i) => Some(i),
        dataset_io::GrayImage::U16(_) => None,
    })?;
    Ok((frames, exposures))
}

/// Reads every frame of a 16-bit sequence with its exposure, with the values as `bits`-bit
/// samples (see [`deep_layout`]); returns the frames, exposures and bit depth.
pub fn load_exposed_deep_frames(
    seq: &Sequence,
    bit_depth: Option<u32>,
    observer: &dyn Observer,
) -> Result<(Vec<Image<u16>>, Vec<f64>, u32)> {
    let (frames, exposures) = load_exposed_native(seq, observer)?;
    let mut frames = same_depth(seq, frames, |f| match f {
        dataset_io::GrayImage::U16(i) => Some(i),
        dataset_io::GrayImage::U8(_) => None,
    })?;
    let (bits, shift) = deep_layout(&frames, bit_depth)?;
    if shift > 0 {
        observer.warn(&format!(
            "the {bits}-bit values are in the high bits of the 16-bit samples (every value is a multiple of {}); shifted down by {shift} bits",
            1u32 << shift
        ));
        for f in &mut frames {
            for v in f.data_mut() {
                *v >>= shift;
            }
        }
    }
    Ok((frames, exposures, bits))
}

/// The bit depth of 16-bit frames and the shift that brings their values to the low bits:
/// `bit_depth` or the fewest bits (at least 8) that hold the brightest value, and a shift
/// when the given depth's values sit in the high bits.
pub fn deep_layout(frames: &[Image<u16>], bit_depth: Option<u32>) -> Result<(u32, u32)> {
    let summary = frames
        .iter()
        .fold((0u16, 0u16), |acc, f| sample_summary(acc, f.data()));
    layout_of(summary, bit_depth)
}

/// The largest value and the bitwise OR of all values, added to `acc`.
pub fn sample_summary(acc: (u16, u16), data: &[u16]) -> (u16, u16) {
    data.iter().fold(acc, |(m, o), &v| (m.max(v), o | v))
}

/// [`deep_layout`] from the largest value and the OR of all values of the frames.
pub fn layout_of((max, or): (u16, u16), bit_depth: Option<u32>) -> Result<(u32, u32)> {
    let needed = (16 - max.leading_zeros()).max(8);
    let Some(k) = bit_depth else {
        return Ok((needed, 0));
    };
    if needed <= k {
        return Ok((k, 0));
    }
    let shift = 16 - k;
    if or & ((1u16 << shift) - 1) == 0 {
        return Ok((k, shift));
    }
    Err(PipelineError::Invalid(format!(
        "--bit-depth {k}: the frames have the value {max}, more than {k} bits hold (at most {}), and their low bits are not all zero (so the values are not {k}-bit values in the high bits either); the frames need at least {needed} bits",
        (1u32 << k) - 1
    )))
}

/// What the sweep offers before calibrating: exposures and grey values (`top` is the
/// saturated value, 255 for 8-bit frames).
pub fn sweep_report<T: Copy + Into<u32>>(
    frames: &[Image<T>],
    top: u32,
    exposures: &[f64],
) -> String {
    let mut sorted: Vec<f64> = exposures.to_vec();
    sorted.sort_by(f64::total_cmp);
    sorted.dedup_by(|a, b| (*a / *b - 1.0).abs() < 1e-6);
    let step = sorted
        .windows(2)
        .map(|p| p[1] / p[0])
        .fold(1.0f64, f64::max);
    let top = top as usize;
    let mut hist = vec![0u64; top + 1];
    for f in frames {
        for &v in f.data() {
            hist[(v.into() as usize).min(top)] += 1;
        }
    }
    let total: u64 = hist.iter().sum();
    let lo = (0..=top).find(|&k| hist[k] > 0).unwrap_or(0);
    let hi = (0..top).rev().find(|&k| hist[k] > 0).unwrap_or(0);
    let rare = (lo..=hi).filter(|&k| hist[k] < 100).count();
    format!(
        "{} frames, {} exposures from {:.4} to {:.4} ms (largest step x{:.3}); grey values {lo}..{hi} observed ({} of them fewer than 100 times), {:.2}% of the observations saturated",
        frames.len(),
        sorted.len(),
        sorted.first().copied().unwrap_or(0.0),
        sorted.last().copied().unwrap_or(0.0),
        step,
        rare,
        100.0 * hist[top] as f64 / total.max(1) as f64
    )
}

/// Plots U with its 2-sigma band (and the truth, when known), the standard errors, and the
/// observations per grey value, for a table of any bit depth (`truth` has as many values).
pub fn response_figure(
    cal: &photometric::ResponseCalibration,
    truth: Option<&[f64]>,
    path: &Path,
) -> Result<()> {
    let u = cal.response.table();
    let n = u.len();
    let top = (n - 1) as f64;
    let sd = &cal.std_error;
    // at most about 1024 points per curve
    let stride = (n / 1024).max(1);
    let idx: Vec<usize> = (0..n).step_by(stride).chain([n - 1]).collect();
    let below_top: Vec<usize> = idx.iter().copied().filter(|&k| k < n - 1).collect();
    let curve = |ks: &[usize], f: &dyn Fn(usize) -> f64| -> Vec<[f64; 2]> {
        ks.iter().map(|&k| [k as f64, f(k)]).collect()
    };
    let scale = format!("U({}) = 255", n - 1);
    let mut c1 = Chart::new(
        "inverse response U",
        "grey value I",
        format!("U(I) (scaled to {scale})"),
    );
    c1.legend = Some(Corner::TopLeft);
    c1.x_range = Some([0.0, top]);
    c1.series.push(Series::band(
        "2-sigma band",
        curve(&idx, &|k| u[k] - 2.0 * sd[k]),
        curve(&idx, &|k| u[k] + 2.0 * sd[k]),
        PALETTE[0],
    ));
    c1.series.push(Series::line(
        "U estimated",
        curve(&idx, &|k| u[k]),
        PALETTE[0],
    ));
    if let Some(t) = truth {
        c1.series
            .push(Series::line("U true", curve(&idx, &|k| t[k]), PALETTE[2]).dashed());
    }
    c1.series
        .push(Series::line("linear", vec![[0.0, 0.0], [top, 255.0]], PALETTE[7]).dashed());
    let mut c2 = Chart::new(
        "uncertainty of U",
        "grey value I",
        format!("grey values ({scale} scale)"),
    );
    c2.legend = Some(Corner::TopLeft);
    c2.x_range = Some([0.0, top]);
    c2.series.push(Series::line(
        "standard error",
        curve(&below_top, &|k| sd[k]),
        PALETTE[0],
    ));
    c2.series.push(
        Series::line(
            "its systematic part",
            curve(&below_top, &|k| cal.systematic_error[k]),
            PALETTE[3],
        )
        .dashed(),
    );
    if let Some(t) = truth {
        c2.series.push(Series::line(
            "|U - U true|",
            curve(&below_top, &|k| (u[k] - t[k]).abs()),
            PALETTE[2],
        ));
    }
    let mut c3 = Chart::new(
        "observations",
        "grey value I",
        "log10 of the number of observations",
    );
    c3.legend = Some(Corner::TopRight);
    c3.x_range = Some([0.0, top]);
    // counts in bins of `width` grey values (below the top value), as steps
    let steps = |h: &[u64], width: f64| -> Vec<[f64; 2]> {
        let group = ((n / 256).max(1) as f64 / width).round().max(1.0) as usize;
        let last = ((top / width).ceil() as usize).min(h.len());
        h[..last]
            .chunks(group)
            .enumerate()
            .flat_map(|(i, c)| {
                let v = (c.iter().sum::<u64>() as f64).max(1.0).log10();
                let x0 = (i * group) as f64 * width;
                [[x0, v], [(x0 + group as f64 * width).min(top), v]]
            })
            .collect()
    };
    let per = if n > 256 {
        format!(" (per {} values)", n / 256)
    } else {
        String::new()
    };
    c3.series.push(Series::line(
        format!("observed values{per}"),
        steps(&cal.histogram, 1.0),
        PALETTE[1],
    ));
    c3.series.push(Series::line(
        format!("used (by prediction){per}"),
        steps(&cal.used, cal.knot_step),
        PALETTE[4],
    ));
    let fig = Figure {
        width: 1650,
        height: 520,
        panels: vec![
            (Panel::Chart(c1), [0.0, 0.0, 0.26, 1.0]),
            (Panel::Chart(c2), [0.26, 0.0, 0.25, 1.0]),
            (Panel::Chart(c3), [0.51, 0.0, 0.245, 1.0]),
            (
                Panel::Chart(noise_chart(cal, top)),
                [0.755, 0.0, 0.245, 1.0],
            ),
        ],
    };
    Ok(figures::save(&fig, path)?)
}

/// The noise of one observation per predicted grey value: measured from the residuals (the
/// weights use it), the shot/read/ADC model fitted to it (a description only), and the noise
/// after the clip where it was measured.
fn noise_chart(cal: &photometric::ResponseCalibration, top: f64) -> Chart {
    let mut c = Chart::new(
        "noise of an observation",
        "predicted grey value",
        "standard deviation (grey values)",
    );
    c.legend = Some(Corner::TopLeft);
    c.x_range = Some([0.0, top]);
    let measured: Vec<[f64; 2]> = cal
        .measured_noise
        .iter()
        .filter(|b| b.variance.is_finite() && b.variance >= 0.0)
        .map(|b| [b.grey, b.variance.sqrt()])
        .collect();
    if !measured.is_empty() {
        c.series
            .push(Series::line("measured", measured.clone(), PALETTE[0]));
    }
    if let Some(m) = &cal.noise {
        let u = cal.response.table();
        let step = (u.len() / 256).max(1);
        let model: Vec<[f64; 2]> = (0..u.len())
            .step_by(step)
            .map(|k| [k as f64, m.variance(u, k as f64).max(0.0).sqrt()])
            .filter(|p| p[1].is_finite())
            .collect();
        c.series
            .push(Series::line("shot/read/ADC model", model, PALETTE[3]).dashed());
    }
    if cal.noise_after_clip > 0.0 {
        // measured on the saturated pixels, it is added after the response to every value:
        // a floor under the measured noise; from 0, with room above for the legend
        let sd = cal.noise_after_clip;
        let highest = measured.iter().map(|p| p[1]).fold(sd, f64::max);
        c.y_range = Some([0.0, 1.5 * highest]);
        c.series
            .push(Series::line("after the clip", vec![[0.0, sd], [top, sd]], PALETTE[2]).dotted());
    }
    c
}

/// Frames of a sequence with poses, decoded when the calibration asks (it keeps what it
/// needs in memory when that fits its `memory_mb`, else in a scratch file in `scratch`, else
/// asks again on every pass). 16-bit
/// frames are `bits`-bit samples after a right shift by `shift` (see [`deep_layout`]).
struct SequencePlaneFrames<'a> {
    seq: &'a Sequence,
    frames: Vec<(usize, f64, photometric::PlanePose)>,
    deep: Option<DeepLayout>,
    scratch: Option<&'a Path>,
}

/// The bit depth of the samples of a 16-bit sequence and the shift that brings them to the
/// low bits.
#[derive(Clone, Copy, Debug)]
struct DeepLayout {
    bits: u32,
    shift: u32,
}

impl DeepLayout {
    /// A frame as the calibration reads it.
    fn plane_image(&self, image: dataset_io::GrayImage) -> photometric::PlaneImage {
        match image {
            dataset_io::GrayImage::U8(i) => photometric::PlaneImage::U8(i),
            dataset_io::GrayImage::U16(mut image) => {
                if self.shift > 0 {
                    for v in image.data_mut() {
                        *v >>= self.shift;
                    }
                }
                photometric::PlaneImage::U16 {
                    image,
                    bits: self.bits,
                }
            }
        }
    }

    /// A frame as 8-bit grey for the marker detector (full range: `v 255 / (2^bits - 1)`).
    fn eight_bit(&self, image: &dataset_io::GrayImage) -> Image<u8> {
        match image {
            dataset_io::GrayImage::U8(i) => i.clone(),
            dataset_io::GrayImage::U16(i) => {
                let top = ((1u32 << self.bits) - 1) as f32;
                let scale = 255.0 / top;
                i.map(|v| ((v >> self.shift) as f32 * scale).round().min(255.0) as u8)
            }
        }
    }
}

impl SequencePlaneFrames<'_> {
    fn decode(&self, k: usize) -> Result<photometric::PlaneImage> {
        Ok(match self.deep {
            Some(d) => d.plane_image(self.seq.decode_native(k)?),
            None => photometric::PlaneImage::U8(self.seq.decode(k)?),
        })
    }
}

impl photometric::PlaneFrames for SequencePlaneFrames<'_> {
    fn len(&self) -> usize {
        self.frames.len()
    }
    fn frame(&self, i: usize) -> Result<photometric::PlaneFrame, photometric::PhotometricError> {
        let (k, exposure_ms, pose) = self.frames[i];
        let image = self
            .decode(k)
            .map_err(|e| photometric::PhotometricError::Calibration(crate::error_chain(&e)))?;
        Ok(photometric::PlaneFrame {
            image,
            exposure_ms,
            pose,
        })
    }
    fn scratch(&self) -> std::io::Result<Option<std::fs::File>> {
        self.scratch
            .map(|dir| dataset_io::scratch_file(dir).map_err(std::io::Error::other))
            .transpose()
    }
}

/// The maps, their cross-sections through the image centre with 2-sigma bands (and the
/// truth, when known), the standard error and the coverage.
pub fn vignette_figure(
    cal: &photometric::VignetteCalibration,
    truth: Option<&[f32]>,
    path: &Path,
) -> Result<()> {
    let v = &cal.vignette;
    let (w, h) = v.size();
    let heat = |title: &str, values: Vec<f32>, range: [f32; 2], label: &str| {
        Panel::Heatmap(figures::Heatmap {
            title: title.into(),
            width: w,
            height: h,
            values,
            range,
            label: label.into(),
        })
    };
    let sd = cal.std_error.data();
    // the colour scale of the standard error ends at its 99th percentile: a few border
    // pixels with little data would otherwise leave the rest of the map one colour
    let mut sd_sorted: Vec<f32> = sd.iter().copied().filter(|v| v.is_finite()).collect();
    sd_sorted.sort_unstable_by(f32::total_cmp);
    let sd_max = sd_sorted
        .get(sd_sorted.len() * 99 / 100)
        .copied()
        .unwrap_or(0.0)
        .max(1e-6);
    let counts: Vec<f32> = cal.counts.data().iter().map(|&c| c as f32).collect();
    let c_max = counts.iter().copied().fold(0.0f32, f32::max).max(1.0);
    let section = |title: &str, axis: &str, n: usize, at: &dyn Fn(usize) -> usize, legend: bool| {
        let mut c = Chart::new(title, axis, "V");
        // one legend for both cross-sections
        c.legend = legend.then_some(Corner::BottomRight);
        let val = |img: &Image<f32>, i: usize| img.data()[at(i)] as f64;
        c.series.push(Series::band(
            "recommended, 2 sigma",
            (0..n)
                .map(|i| [i as f64, val(v, i) - 2.0 * sd[at(i)] as f64])
                .collect(),
            (0..n)
                .map(|i| [i as f64, val(v, i) + 2.0 * sd[at(i)] as f64])
                .collect(),
            PALETTE[0],
        ));
        let mut raw = Series::line(
            "raw (the paper's)",
            (0..n).map(|i| [i as f64, val(&cal.raw, i)]).collect(),
            PALETTE[7],
        );
        raw.width = 1.0;
        c.series.push(raw);
        c.series.push(Series::line(
            "recommended",
            (0..n).map(|i| [i as f64, val(v, i)]).collect(),
            PALETTE[0],
        ));
        if let Some(t) = truth {
            c.series.push(
                Series::line(
                    "true",
                    (0..n).map(|i| [i as f64, t[at(i)] as f64]).collect(),
                    PALETTE[2],
                )
                .dashed(),
            );
        }
        Panel::Chart(c)
    };
    let fig = Figure {
        width: 1650,
        height: 900,
        panels: vec![
            (
                heat(
                    &format!("recommended V (smoothing {:.1} px)", cal.smoothing.sigma_px),
                    v.data().to_vec(),
                    [0.0, 1.0],
                    "V",
                ),
                [0.0, 0.0, 0.34, 0.42],
            ),
            (
                heat(
                    "standard error of V (colours clipped at 99%)",
                    sd.to_vec(),
                    [0.0, sd_max],
                    "standard error",
                ),
                [0.34, 0.0, 0.33, 0.42],
            ),
            (
                heat("coverage", counts, [0.0, c_max], "observations per pixel"),
                [0.67, 0.0, 0.33, 0.42],
            ),
            (
                section("middle row", "x (pixels)", w, &|x| (h / 2) * w + x, true),
                [0.0, 0.42, 0.5, 0.58],
            ),
            (
                section("middle column", "y (pixels)", h, &|y| y * w + w / 2, false),
                [0.5, 0.42, 0.5, 0.58],
            ),
        ],
    };
    Ok(figures::save(&fig, path)?)
}

/// Frames with a plane pose (index, exposure in ms, pose) and the count of skipped frames
/// per reason.
/// The bit depth of a 16-bit sequence's samples for `calib vignette`: `--bit-depth`, else
/// the depth of a table of more than 256 values, else the fewest bits that hold the
/// brightest value; one pass over the frames tells whether the values sit in the high bits.
fn sequence_layout(
    seq: &Sequence,
    bit_depth: Option<u32>,
    response: &photometric::InverseResponse,
    observer: &dyn Observer,
) -> Result<DeepLayout> {
    let idx = seq.indices(0..seq.len(), false);
    observer.begin(idx.len() as u64, "bit depth", "frames");
    let mut summary = (0u16, 0u16);
    seq.process_native(
        &idx,
        rayon::current_num_threads() * 4,
        |f| {
            observer.advance(1);
            Ok::<_, PipelineError>(match f.image {
                dataset_io::GrayImage::U16(i) => sample_summary((0, 0), i.data()),
                dataset_io::GrayImage::U8(i) => {
                    (i.data().iter().copied().max().unwrap_or(0) as u16, 0xFF)
                }
            })
        },
        |s| {
            summary = (summary.0.max(s.0), summary.1 | s.1);
            Ok(())
        },
    )?;
    observer.finish();
    let table_bits = response.bits();
    let wanted = bit_depth.or((table_bits > 8).then_some(table_bits));
    let (bits, shift) = layout_of(summary, wanted).map_err(|e| {
        e.context(if bit_depth.is_none() && wanted.is_some() {
            format!(
                "the bit depth {table_bits} of the pcalib.txt table (give --bit-depth to override)"
            )
        } else {
            seq.dir().display().to_string()
        })
    })?;
    if shift > 0 {
        observer.warn(&format!(
            "the {bits}-bit values are in the high bits of the 16-bit samples (every value is a multiple of {}); shifted down by {shift} bits",
            1u32 << shift
        ));
    }
    if table_bits > 8 && table_bits != bits {
        observer.warn(&format!(
            "pcalib.txt has {} values ({table_bits}-bit) but the frames are taken as {bits}-bit: the table is read by full range",
            1u32 << table_bits
        ));
    }
    Ok(DeepLayout { bits, shift })
}

type PosedFrames = (
    Vec<(usize, f64, photometric::PlanePose)>,
    std::collections::BTreeMap<&'static str, usize>,
);

/// The plane pose of every frame: from a poses file, or from the marker.
fn plane_poses(
    a: &VignetteJob,
    seq: &Sequence,
    cam: &camera_model::CameraFile,
    deep: Option<DeepLayout>,
    observer: &dyn Observer,
) -> Result<PosedFrames> {
    use camera_model::{output_intrinsics, OutputMode, RectifyMap};
    use photometric::marker::PoseFromMarker;
    let rows = &seq.times().rows;
    let mut frames = Vec::new();
    let mut skipped: std::collections::BTreeMap<&'static str, usize> = Default::default();
    if let Some(pp) = &a.poses {
        let poses: std::collections::HashMap<String, photometric::PlanePose> =
            photometric::marker::parse_plane_poses(&dataset_io::read_text(pp)?)
                .map_err(|source| PipelineError::Photometric {
                    context: pp.display().to_string(),
                    source,
                })?
                .into_iter()
                .collect();
        for (k, row) in rows.iter().enumerate() {
            match poses.get(&row.id) {
                Some(p) => frames.push((k, row.exposure_ms.unwrap_or(0.0), *p)),
                None => *skipped.entry("no pose in the poses file").or_default() += 1,
            }
        }
        return Ok((frames, skipped));
    }
    let cam_path = a.sequence.join("camera.txt");
    if cam.output == OutputMode::None && !cam.input.is_pinhole() {
        return Err(PipelineError::Invalid(format!(
            "{}: line 3 is `none`, but the {} camera must be rectified to a pinhole to find the marker; use crop, full or an explicit pinhole (or give --poses)",
            cam_path.display(),
            cam.input.name()
        )));
    }
    let camera_error = |source| PipelineError::Camera {
        context: cam_path.display().to_string(),
        source,
    };
    let k_out = output_intrinsics(&cam.input, cam.input_size, &cam.output, cam.output_size)
        .map_err(camera_error)?;
    let map = RectifyMap::new(&cam.input, cam.input_size, k_out, cam.output_size)
        .map_err(camera_error)?;
    let idx = seq.indices(0..seq.len(), false);
    observer.begin(idx.len() as u64, "markers", "frames");
    let mut found: Vec<(usize, PoseFromMarker)> = Vec::new();
    let detect = |index: usize, image: &Image<u8>| -> Result<(usize, PoseFromMarker)> {
        let r = photometric::marker::pose_from_marker(&map, &k_out, image, a.marker_id).map_err(
            |source| PipelineError::Photometric {
                context: seq.names()[index].clone(),
                source,
            },
        )?;
        observer.advance(1);
        Ok((index, r))
    };
    let sink = |r| {
        found.push(r);
        Ok(())
    };
    let chunk = rayon::current_num_threads() * 4;
    match deep {
        // deep frames are scaled to 8 bits by their bit depth (a 12-bit frame read as 8
        // bits of 16 would be black)
        Some(d) => seq.process_native(
            &idx,
            chunk,
            |f| detect(f.index, &d.eight_bit(&f.image)),
            sink,
        )?,
        None => seq.process(&idx, chunk, |f| detect(f.index, &f.image), sink)?,
    }
    observer.finish();
    for (k, result) in found {
        match result {
            PoseFromMarker::Found(p) => frames.push((k, rows[k].exposure_ms.unwrap_or(0.0), p)),
            PoseFromMarker::NoMarker => *skipped.entry("no marker").or_default() += 1,
            PoseFromMarker::NoPose => *skipped.entry("no pose from the corners").or_default() += 1,
            PoseFromMarker::Several(_) => {
                *skipped.entry("several markers with the id").or_default() += 1
            }
        }
    }
    Ok((frames, skipped))
}

/// What `monovo calib vignette` calibrates: a sequence folder with its camera, the inverse
/// response, where the plane poses come from, and the options.
#[derive(Clone, Debug)]
pub struct VignetteJob {
    /// The sequence folder (images, times.txt with exposures, camera.txt).
    pub sequence: PathBuf,
    /// The inverse response (default: the sequence's pcalib.txt).
    pub pcalib: Option<PathBuf>,
    /// Plane poses per frame (`id r11 .. r33 tx ty tz`) instead of marker detection.
    pub poses: Option<PathBuf>,
    /// Id of the marker (original ArUco dictionary).
    pub marker_id: u16,
    /// Bits per sample of 16-bit frames (default: the table's depth when it has more than
    /// 256 values, else the fewest bits that hold the brightest value).
    pub bit_depth: Option<u32>,
    /// The calibration options.
    pub options: photometric::VignetteOptions,
    /// The folder for a scratch file (hidden, removed at once) that holds the frames'
    /// samples when they exceed `options.memory_mb`, so that the iterations read them back
    /// instead of decoding every frame on every pass (`monovo calib vignette` gives the
    /// output's folder). `None`: decode on every pass.
    pub scratch: Option<PathBuf>,
}

/// A vignette calibration of a sequence, as `monovo calib vignette` runs it.
#[derive(Clone, Debug)]
pub struct VignetteRun {
    /// The calibration.
    pub cal: photometric::VignetteCalibration,
    /// Frames with a plane pose.
    pub used: usize,
    /// Frames in the sequence.
    pub frames: usize,
    /// Frames without a pose, by reason.
    pub skipped: std::collections::BTreeMap<&'static str, usize>,
    /// Bits per sample the frames were read with (8, or the depth of 16-bit frames).
    pub bits: u32,
    /// Whether the frames are JPEG. Their compression biases some pixels by more than the
    /// noise, so that the defect search (`cal.smoothing.defects`) counts those with the
    /// sensor's hot and dead pixels: 150 synthetic frames of 640x512 with about 66 defects
    /// give 27 at quality 100, 190 at 95, 1867 at 90 and 2901 at 75, and 13 as PNG.
    pub jpeg: bool,
}

impl VignetteRun {
    /// "N of M frames have a plane pose (k: reason, ...)".
    pub fn poses_text(&self) -> String {
        let reasons = if self.skipped.is_empty() {
            String::new()
        } else {
            format!(
                " ({})",
                self.skipped
                    .iter()
                    .map(|(k, v)| format!("{v}: {k}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        };
        format!(
            "{} of {} frames have a plane pose{reasons}",
            self.used, self.frames
        )
    }
}

/// Poses (from the marker or the poses file) and the calibration, without writing anything:
/// the calibration keeps the frames in memory when they fit in its `memory_mb` (80 MiB by
/// default), else in a scratch file in `job.scratch`, else decodes them on every pass.
/// Progress goes to `observer` (stages as `begin`/`advance`, iterations as `status`).
pub fn calibrate_vignette_sequence(
    job: &VignetteJob,
    observer: &dyn Observer,
) -> Result<VignetteRun> {
    let a = job;
    job.options
        .check()
        .map_err(|source| PipelineError::Photometric {
            context: "the vignette options".into(),
            source,
        })?;
    let seq = Sequence::open(&a.sequence)?;
    for w in &seq.times().warnings {
        observer.warn(w);
    }
    let cam_path = a.sequence.join("camera.txt");
    let Some(cam) = seq.camera() else {
        return Err(PipelineError::Invalid(format!(
            "{}: missing; vignette calibration needs the camera model",
            cam_path.display()
        )));
    };
    let Some(pcalib_path) = a.pcalib.clone().or(seq.pcalib_path.clone()) else {
        return Err(PipelineError::Invalid(format!(
            "{}: no pcalib.txt; vignette calibration needs the inverse response (run `monovo calib response` first, or give --pcalib FILE)",
            a.sequence.display()
        )));
    };
    let (response, notes) =
        photometric::InverseResponse::parse_with_notes(&dataset_io::read_text(&pcalib_path)?)
            .map_err(|source| PipelineError::Photometric {
                context: pcalib_path.display().to_string(),
                source,
            })?;
    for n in notes {
        observer.warn(&format!("{}: {n}", pcalib_path.display()));
    }
    if let Some((k, line)) = seq.times().first_unknown_exposure() {
        return Err(PipelineError::Invalid(format!(
            "{}: line {line}: the exposure of frame {k} is unknown (0 or missing); vignette calibration needs the exposure time of every frame (third column, > 0)",
            seq.times_path().display()
        )));
    }
    let deep = if seq.bits_per_sample() == 16 {
        Some(sequence_layout(&seq, a.bit_depth, &response, observer)?)
    } else {
        if let Some(k) = a.bit_depth {
            return Err(PipelineError::Invalid(format!(
                "--bit-depth {k}: the frames of {} are 8-bit; --bit-depth describes 16-bit frames",
                a.sequence.display()
            )));
        }
        None
    };
    let (frames, skipped) = plane_poses(a, &seq, cam, deep, observer)?;
    if frames.is_empty() {
        return Err(PipelineError::Invalid(format!(
            "{}: no frame has a plane pose (marker id {} was not found in any of {} frames{}); check --marker-id, the dictionary (original ArUco) and that the marker is fully visible",
            a.sequence.display(),
            a.marker_id,
            seq.len(),
            if a.poses.is_some() { ", or the ids in the poses file" } else { "" }
        )));
    }
    let source = SequencePlaneFrames {
        seq: &seq,
        frames,
        deep,
        scratch: a.scratch.as_deref(),
    };
    observer.status("calibrating");
    let cal = photometric::calibrate_vignette(
        &cam.input,
        cam.input_size,
        &response,
        &source,
        &job.options,
        &|i, change| {
            observer.status(&format!(
                "iteration {i}, V changed by {:.4}%",
                100.0 * change
            ));
        },
    );
    observer.finish();
    let cal = cal.map_err(|source| PipelineError::Photometric {
        context: a.sequence.display().to_string(),
        source,
    })?;
    Ok(VignetteRun {
        cal,
        used: source.frames.len(),
        frames: seq.len(),
        skipped,
        bits: deep.map_or(8, |d| d.bits),
        jpeg: seq.is_jpeg(),
    })
}

/// `stem_suffix.ext` beside `path` (`vignette.png` -> `vignette_raw.png`).
pub fn sibling(path: &Path, suffix: &str) -> PathBuf {
    let stem = path
        .file_stem()
        .map_or("out".into(), |s| s.to_string_lossy().into_owned());
    let ext = path
        .extension()
        .map_or(String::new(), |e| format!(".{}", e.to_string_lossy()));
    path.with_file_name(format!("{stem}{suffix}{ext}"))
}

/// The maps `monovo calib vignette` writes: the recommended map and, beside it,
/// `NAME_raw`, `NAME_std` and `NAME_coverage` (all 16-bit grey PNG).
#[derive(Clone, Debug)]
pub struct VignetteFiles {
    /// The recommended map (vignette.png).
    pub output: PathBuf,
    /// The paper's raw map.
    pub raw: PathBuf,
    /// The standard error of the recommended map.
    pub std: PathBuf,
    /// Observations per pixel.
    pub coverage: PathBuf,
}

impl VignetteFiles {
    /// The files beside `output`.
    pub fn beside(output: &Path) -> VignetteFiles {
        VignetteFiles {
            output: output.to_path_buf(),
            raw: sibling(output, "_raw"),
            std: sibling(output, "_std"),
            coverage: sibling(output, "_coverage"),
        }
    }

    /// All four paths.
    pub fn all(&self) -> [&Path; 4] {
        [&self.output, &self.raw, &self.std, &self.coverage]
    }
}

/// The scales of the written maps: `raw = value / 65535 * raw_scale`, `std = value / 65535
/// * std_scale`.
#[derive(Clone, Copy, Debug)]
pub struct MapScales {
    /// Scale of the raw map (its maximum, at least 1).
    pub raw_scale: f32,
    /// Scale of the standard-error map (its maximum).
    pub std_scale: f64,
}

/// Writes the four maps of a vignette calibration (atomically each), with their scales in
/// PNG text chunks: the recommended map (`V = value / 65535`, as DSO reads it), the raw map
/// (its unknown pixels take the recommended value), the standard error and the coverage.
pub fn write_vignette_maps(
    cal: &photometric::VignetteCalibration,
    files: &VignetteFiles,
) -> Result<MapScales> {
    let (w, h) = cal.vignette.size();
    let to16 = |values: &[f32], scale: f32| -> Vec<u16> {
        values
            .iter()
            .map(|v| (v / scale * 65535.0).round().clamp(0.0, 65535.0) as u16)
            .collect()
    };
    let rec = cal.vignette.data();
    let raw_filled: Vec<f32> = cal
        .raw
        .data()
        .iter()
        .zip(rec)
        .map(|(r, s)| if r.is_finite() { *r } else { *s })
        .collect();
    let raw_max = raw_filled.iter().copied().fold(1.0f32, f32::max);
    let std_scale = cal
        .std_error
        .data()
        .iter()
        .copied()
        .fold(0.0f32, f32::max)
        .max(1e-9) as f64;
    dataset_io::write_png_u16_with_text(
        &files.output,
        w,
        h,
        &to16(rec, 1.0),
        &[(
            "monovo:map",
            "recommended vignette, V = value / 65535".into(),
        )],
    )?;
    dataset_io::write_png_u16_with_text(
        &files.raw,
        w,
        h,
        &to16(&raw_filled, raw_max),
        &[(
            "monovo:map",
            format!(
                "raw vignette (the paper's), V = value / 65535 * {raw_max} on the scale of the recommended map"
            ),
        )],
    )?;
    dataset_io::write_png_u16_with_text(
        &files.std,
        w,
        h,
        &to16(cal.std_error.data(), std_scale as f32),
        &[
            ("monovo:std_scale", format!("{std_scale}")),
            (
                "monovo:map",
                format!("standard error of the recommended vignette = value / 65535 * {std_scale}"),
            ),
        ],
    )?;
    let cov: Vec<u16> = cal
        .counts
        .data()
        .iter()
        .map(|&c| c.min(65535) as u16)
        .collect();
    dataset_io::write_png_u16_with_text(
        &files.coverage,
        w,
        h,
        &cov,
        &[("monovo:map", "observations per pixel".into())],
    )?;
    Ok(MapScales {
        raw_scale: raw_max,
        std_scale,
    })
}

/// What `monovo calib response` calibrates: a sweep folder and the options.
#[derive(Clone, Debug)]
pub struct ResponseJob {
    /// The sequence folder (a static scene, times.txt with exposures).
    pub sequence: PathBuf,
    /// Bits per sample of 16-bit frames (see [`deep_layout`]; `None`: the fewest bits that
    /// hold the brightest value).
    pub bit_depth: Option<u32>,
    /// The calibration options.
    pub options: photometric::ResponseOptions,
}

/// A response calibration of a sweep, as `monovo calib response` runs it.
#[derive(Clone, Debug)]
pub struct ResponseRun {
    /// The calibration.
    pub cal: photometric::ResponseCalibration,
    /// Frames used.
    pub frames: usize,
    /// What the sweep offers (exposures and grey values, see [`sweep_report`]), and for
    /// deep frames the knots of the estimate.
    pub report: String,
}

/// Reads a sweep (8-bit frames, or 16-bit frames at their bit depth) and calibrates the
/// inverse response; the frames' decoding and the iterations are reported to `observer`.
pub fn calibrate_response_sequence(
    job: &ResponseJob,
    observer: &dyn Observer,
) -> Result<ResponseRun> {
    let seq = Sequence::open(&job.sequence)?;
    for w in &seq.times().warnings {
        observer.warn(w);
    }
    if seq.len() < 2 {
        return Err(PipelineError::Invalid(format!(
            "{}: response calibration needs at least 2 frames at different exposures, found {}",
            job.sequence.display(),
            seq.len()
        )));
    }
    let context = || job.sequence.display().to_string();
    let tick = |i: usize, change: f64| {
        observer.status(&format!(
            "iteration {i}, U changed by {change:.4} grey values"
        ));
    };
    // JPEG frames: a saturated area decodes to values just under the top
    let mut options = job.options.clone();
    options.jpeg |= seq.is_jpeg();
    let run = if seq.bits_per_sample() == 16 {
        let (frames, exposures, bits) = load_exposed_deep_frames(&seq, job.bit_depth, observer)?;
        let report = format!(
            "{}\n{bits}-bit frames: U is estimated on {} knots and written as {} values",
            sweep_report(&frames, (1u32 << bits) - 1, &exposures),
            (1usize << bits).min(photometric::MAX_KNOTS),
            1u32 << bits
        );
        let cal = photometric::calibrate_response_deep(&frames, bits, &exposures, &options, &tick);
        observer.finish();
        ResponseRun {
            cal: cal.with_context(context)?,
            frames: frames.len(),
            report,
        }
    } else {
        if let Some(k) = job.bit_depth.filter(|&k| k != 8) {
            return Err(PipelineError::Invalid(format!(
                "--bit-depth {k}: the frames of {} are 8-bit; --bit-depth describes 16-bit frames",
                job.sequence.display()
            )));
        }
        let (mut frames, exposures) = load_exposed_frames(&seq, observer)?;
        let report = sweep_report(&frames, 255, &exposures);
        let cal = photometric::calibrate_response(&mut frames, &exposures, &options, &tick);
        observer.finish();
        ResponseRun {
            cal: cal.with_context(context)?,
            frames: frames.len(),
            report,
        }
    };
    Ok(run)
}

/// Writes pcalib.txt and, at `std_path`, the standard error of every `U(k)` on one line.
pub fn write_response(
    cal: &photometric::ResponseCalibration,
    output: &Path,
    std_path: &Path,
) -> Result<()> {
    dataset_io::write_atomic(output, cal.response.to_text().as_bytes())?;
    let std_text = cal
        .std_error
        .iter()
        .map(|v| format!("{v}"))
        .collect::<Vec<_>>()
        .join(" ");
    dataset_io::write_atomic(std_path, format!("{std_text}\n").as_bytes())?;
    Ok(())
}

/// The options of a calibration config file (`--config FILE`): a `[response]` and a
/// `[vignette]` table with any fields of [`photometric::ResponseOptions`] and
/// [`photometric::VignetteOptions`] (data/calib.toml lists them all with their defaults).
/// Absent fields and tables keep the defaults; an unknown field is an error naming it.
#[derive(Debug, Default, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CalibConfig {
    /// Options of the response calibration.
    pub response: photometric::ResponseOptions,
    /// Options of the vignette calibration.
    pub vignette: photometric::VignetteOptions,
}

impl CalibConfig {
    /// Parses a config file's text.
    pub fn parse(text: &str) -> std::result::Result<CalibConfig, toml::de::Error> {
        toml::from_str(text)
    }

    /// Reads the config file, or gives the defaults without one.
    pub fn load(path: Option<&Path>) -> Result<CalibConfig> {
        let Some(path) = path else {
            return Ok(CalibConfig::default());
        };
        let text = dataset_io::read_text(path)?;
        CalibConfig::parse(&text).map_err(|e| {
            PipelineError::Invalid(format!(
                "{}: not a calibration config: {}",
                path.display(),
                e.to_string().trim_end()
            ))
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The example config in the repository.
    const EXAMPLE: &str = include_str!("../../../data/calib.toml");

    fn json<T: serde::Serialize>(v: &T) -> serde_json::Value {
        serde_json::to_value(v).unwrap()
    }

    #[test]
    fn the_example_config_lists_every_option_with_its_default() {
        use photometric::{ResponseOptions, VignetteOptions};
        let c = CalibConfig::parse(EXAMPLE).unwrap();
        assert_eq!(json(&c.response), json(&ResponseOptions::default()));
        assert_eq!(json(&c.vignette), json(&VignetteOptions::default()));
        // a new option must be added to the example (commented out when it has no value)
        for (table, options) in [
            ("response", json(&ResponseOptions::default())),
            ("vignette", json(&VignetteOptions::default())),
        ] {
            let section = EXAMPLE.split(&format!("[{table}]")).nth(1).unwrap();
            let section = section.split("\n[").next().unwrap();
            for key in options.as_object().unwrap().keys() {
                assert!(
                    section.contains(&format!("\n{key} = "))
                        || section.contains(&format!("\n# {key} = ")),
                    "data/calib.toml has no `{key}` in [{table}]"
                );
            }
        }
    }

    #[test]
    fn unknown_keys_and_wrong_types_are_errors_that_name_them() {
        let e = CalibConfig::parse("[response]\nmax_iteration = 3\n").unwrap_err();
        assert!(e.to_string().contains("max_iteration"), "{e}");
        let e = CalibConfig::parse("[respons]\ntolerance = 0.1\n").unwrap_err();
        assert!(e.to_string().contains("respons"), "{e}");
        let e = CalibConfig::parse("[vignette]\ngrid = \"fine\"\n").unwrap_err();
        assert!(e.to_string().contains("grid"), "{e}");
        // an empty file is the defaults
        let c = CalibConfig::parse("").unwrap();
        assert_eq!(
            json(&c.vignette),
            json(&photometric::VignetteOptions::default())
        );
    }
}
