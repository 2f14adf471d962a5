//! One module per subcommand, and what several of them share.

pub mod calib;
pub mod camera;
pub mod demo;
pub mod eval;
pub mod eval_batch;
pub mod experiment;
pub mod exposure;
pub mod info;
pub mod plot;
pub mod rectify;
pub mod synth;

use std::path::Path;

use anyhow::Result;
use camera_model::ImageSize;
use dataset_io::Sequence;
use photometric::Vignette;

/// Opens and validates a sequence folder and prints what times.txt's reading repaired or
/// could not (interpolated zero exposures, unknown exposures, ids that do not name the
/// images) as warnings.
pub fn open_sequence(dir: &Path) -> Result<Sequence> {
    let seq = Sequence::open(dir)?;
    for w in &seq.times().warnings {
        crate::warn(format_args!("{w}"));
    }
    Ok(seq)
}

/// Reads vignette.png as rectify uses it: 8- or 16-bit grey, a valid map, at the size of
/// the images.
pub fn read_vignette(path: &Path, images: ImageSize) -> Result<Vignette> {
    Ok(monovo_pipelines::read_vignette(path, images)?)
}
