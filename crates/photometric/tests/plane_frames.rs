//! Frames of a synthetic marker-plane video in memory with their true poses, for the
//! vignette tests and the vignette bench (which includes this file).
use camera_model::Image;
use photometric::{PhotometricError, PlaneFrame, PlaneFrames, PlaneImage, PlanePose};
use synthetic::plane::{PlaneConfig, PlaneSequence};
use synthetic::sensor::Sensor;

/// Frames of a synthetic plane sequence (8-bit, or deeper samples in 16 bits) with their
/// true poses.
pub struct Frames {
    pub images: Vec<PlaneImage>,
    pub seq: PlaneSequence,
}

impl PlaneFrames for Frames {
    fn len(&self) -> usize {
        self.images.len()
    }
    fn frame(&self, i: usize) -> Result<PlaneFrame, PhotometricError> {
        let p = self.seq.poses[i];
        Ok(PlaneFrame {
            image: self.images[i].clone(),
            exposure_ms: self.seq.exposures_ms[i],
            pose: PlanePose { r: p.r, t: p.t },
        })
    }
}

/// `n` frames of `w`x`h` of the plane video of `seed` with `sensor` (8-bit).
pub fn set(seed: u64, w: usize, h: usize, n: usize, sensor: Sensor) -> Frames {
    let seq = PlaneSequence::new(
        seed,
        PlaneConfig {
            width: w,
            height: h,
            frames: n,
            sensor,
            ..PlaneConfig::default()
        },
    );
    Frames {
        images: (0..n)
            .map(|i| Image::new(w, h, seq.frame(i).unwrap()).unwrap().into())
            .collect(),
        seq,
    }
}
