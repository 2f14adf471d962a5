//! The files of the TUM monoVO benchmark: sequence folders ([`Sequence`]: `images.zip` or
//! `images/`, `times.txt`, `camera.txt`, calibration files) with random access, backwards
//! playback and parallel ordered decoding; writing sequences ([`SequenceWriter`]); evaluation
//! trees (ground truths and results); PNG; and atomic writes and output folders that never
//! leave a half-written output.
//!
//! dataset-io owns the file system; the text formats themselves are parsed by the crate that
//! owns the concept (camera.txt in camera-model, trajectories in eval-metrics).
//!
//! # Example
//!
//! ```
//! use dataset_io::{scan_results, write_atomic};
//!
//! let root = std::env::temp_dir().join(format!("dataset-io-doc-{}", std::process::id()));
//! let seq = root.join("dso/sequence_01");
//! std::fs::create_dir_all(&seq)?;
//! write_atomic(&seq.join("fwd_0.txt"), b"1 0 0 0 0 0 0 1\n")?;
//! write_atomic(&seq.join("notes.md"), b"stray")?;
//! let tree = scan_results(&root)?;
//! assert_eq!(tree.runs.len(), 1);
//! assert_eq!(tree.runs[0].method, "dso");
//! assert_eq!(tree.stray.len(), 1);
//! std::fs::remove_dir_all(&root)?;
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
#![deny(missing_docs)]

mod atomic;
mod error;
mod jpeg;
mod layouts;
mod ordered;
mod outdir;
mod png;
mod results;
mod sequence;
mod temporaries;
mod times;
mod writer;
mod zipimages;

pub use atomic::{check_output_file, read_text, scratch_file, write_atomic, write_atomic_with};
pub use error::DatasetError;
pub use jpeg::{decode_jpeg_gray8_half, HALF_DECODE, JPEG_DECODER};
pub use layouts::{parse_data_csv, parse_exposure_csv, parse_rgb_list, Layout};
pub use outdir::OutputDir;
pub use png::{
    encode_jpeg_gray, encode_png_u16, encode_png_u8, read_png_text, write_png_u16,
    write_png_u16_with_text, write_png_u8, PngSpeed,
};
pub use results::{parse_run_name, scan_ground_truths, scan_results, ResultsTree, RunFile};
pub use sequence::{
    decode_gray, decode_gray16, decode_gray8, decode_gray_map, read_gray16, read_gray8,
    read_gray_map, Frame, GrayImage, NativeFrame, Sequence,
};
pub use temporaries::{
    in_flight as temporaries_in_flight, remove_all_and_block as remove_temporaries_and_block,
    remove_stale as remove_stale_temporaries, temp_sibling,
};
pub use times::{ns_to_seconds_text, parse_times, seconds_to_ns, times_text, TimeRow, Times};
pub use writer::{write_images_zip, write_stored_zip, SequenceWriter};
pub use zipimages::ImagesZip;
