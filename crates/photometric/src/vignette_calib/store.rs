//! The sample store: the frames' samples kept once in the order the passes visit them, in
//! memory up to the budget, beyond it in a scratch file; and the one visit of the frames that
//! fills the stores and the observation graph.

use rayon::prelude::*;

use super::problem::{Geom, Graph, Parts, Prepared, Problem, Samples};
use crate::PhotometricError;

/// A frame with a plane pose as the passes over the store see it: its number and what the
/// passes need of it.
pub(super) struct View {
    pub(super) i: usize,
    pub(super) geom: Geom,
}

/// The samples of every frame with a plane pose in the visiting order of a problem, block
/// by block ([`Problem::blocks`]) and in a block frame by frame: a pass over a block reads
/// them in a row. In memory when they fit in [`VignetteOptions::memory_mb`], else in the
/// scratch file of [`PlaneFrames::scratch`] when there is one (read back a chunk of blocks
/// at a time: memory stays flat at any number of frames); without either, every pass
/// decodes the frames again.
pub(super) struct Store {
    pub(super) views: Vec<View>,
    /// Frames the layout has room for (every frame of the source: those without a pose
    /// leave their room empty).
    pub(super) room: usize,
    pub(super) data: StoreData,
}

pub(super) enum StoreData {
    U8(Vec<u8>),
    U16(Vec<u16>),
    /// In a file of `bytes`, little-endian samples of one byte or (`wide`) two.
    File {
        file: std::fs::File,
        wide: bool,
        bytes: usize,
    },
}

/// The samples of one block of one frame, or of all frames of a block.
#[derive(Clone, Copy)]
pub(super) enum SamplesRef<'a> {
    U8(&'a [u8]),
    U16(&'a [u16]),
}

impl SamplesRef<'_> {
    /// The samples `range` of these.
    pub(super) fn slice(&self, range: std::ops::Range<usize>) -> SamplesRef<'_> {
        match self {
            SamplesRef::U8(d) => SamplesRef::U8(&d[range]),
            SamplesRef::U16(d) => SamplesRef::U16(&d[range]),
        }
    }
}

/// Samples a job reads from a store's file at a time (whole blocks, at least one).
pub(super) const CHUNK_SAMPLES: usize = 4 << 20;

/// The part of a file-backed store a job has read ([`Store::block`]).
#[derive(Default)]
pub(super) struct Chunk {
    /// The position in the store of the first sample held.
    pub(super) start: usize,
    pub(super) bytes: Vec<u8>,
    pub(super) wide: Vec<u16>,
}

/// The error of the scratch file.
pub(super) fn scratch_error(what: &str, bytes: usize, e: std::io::Error) -> PhotometricError {
    PhotometricError::Scratch(format!(
        "{what} the scratch file that holds the frames' samples ({} MiB in all; raise memory_mb to keep them in memory, or free disk space): {e}",
        bytes.div_ceil(1 << 20)
    ))
}

#[cfg(unix)]
pub(super) fn read_at(file: &std::fs::File, buf: &mut [u8], offset: u64) -> std::io::Result<()> {
    std::os::unix::fs::FileExt::read_exact_at(file, buf, offset)
}

#[cfg(unix)]
pub(super) fn write_at(file: &std::fs::File, buf: &[u8], offset: u64) -> std::io::Result<()> {
    std::os::unix::fs::FileExt::write_all_at(file, buf, offset)
}

#[cfg(windows)]
pub(super) fn read_at(
    file: &std::fs::File,
    mut buf: &mut [u8],
    mut offset: u64,
) -> std::io::Result<()> {
    while !buf.is_empty() {
        match std::os::windows::fs::FileExt::seek_read(file, buf, offset)? {
            0 => return Err(std::io::ErrorKind::UnexpectedEof.into()),
            n => {
                buf = &mut buf[n..];
                offset += n as u64;
            }
        }
    }
    Ok(())
}

#[cfg(windows)]
pub(super) fn write_at(
    file: &std::fs::File,
    mut buf: &[u8],
    mut offset: u64,
) -> std::io::Result<()> {
    while !buf.is_empty() {
        match std::os::windows::fs::FileExt::seek_write(file, buf, offset)? {
            0 => return Err(std::io::ErrorKind::WriteZero.into()),
            n => {
                buf = &buf[n..];
                offset += n as u64;
            }
        }
    }
    Ok(())
}

impl Store {
    /// An empty store for the frames of `p` with `bits`-bit samples: in memory if it fits in
    /// `budget` bytes, else in the scratch file of `p`'s frames, if they give one.
    pub(super) fn new(
        p: &Problem<'_>,
        bits: u32,
        budget: usize,
    ) -> Result<Option<Store>, PhotometricError> {
        let room = p.frames.len();
        let wide = bits > 8;
        let Some(bytes) = room
            .checked_mul(p.order.len())
            .and_then(|n| n.checked_mul(if wide { 2 } else { 1 }))
        else {
            return Ok(None);
        };
        let n = room * p.order.len();
        let data = if bytes <= budget {
            if wide {
                StoreData::U16(vec![0; n])
            } else {
                StoreData::U8(vec![0; n])
            }
        } else {
            let Some(file) = p
                .frames
                .scratch()
                .map_err(|e| scratch_error("cannot open", bytes, e))?
            else {
                return Ok(None);
            };
            // the room of frames without a pose is never written: the file has its size
            file.set_len(bytes as u64)
                .map_err(|e| scratch_error("cannot size", bytes, e))?;
            StoreData::File { file, wide, bytes }
        };
        Ok(Some(Store {
            views: Vec::with_capacity(room),
            room,
            data,
        }))
    }

    /// The bytes the store holds in memory.
    pub(super) fn memory_bytes(&self) -> usize {
        match &self.data {
            StoreData::U8(d) => d.len(),
            StoreData::U16(d) => 2 * d.len(),
            StoreData::File { .. } => 0,
        }
    }

    /// Where the samples of view `v` of `block` start.
    pub(super) fn at(&self, block: &std::ops::Range<usize>, v: usize) -> usize {
        block.start * self.room + v * block.len()
    }

    /// The samples of every view of `block` (view `v` at `v * block.len()`), from memory or
    /// through `chunk` from the file, which reads ahead up to the block ending at `end`.
    pub(super) fn block<'b>(
        &'b self,
        block: &std::ops::Range<usize>,
        end: usize,
        chunk: &'b mut Chunk,
    ) -> Result<SamplesRef<'b>, PhotometricError> {
        let (a, n) = (self.at(block, 0), block.len() * self.room);
        match &self.data {
            StoreData::U8(d) => Ok(SamplesRef::U8(&d[a..a + n])),
            StoreData::U16(d) => Ok(SamplesRef::U16(&d[a..a + n])),
            StoreData::File { file, wide, bytes } => {
                let held = if *wide {
                    chunk.wide.len()
                } else {
                    chunk.bytes.len()
                };
                if a < chunk.start || a + n > chunk.start + held {
                    let to = (a + CHUNK_SAMPLES.max(n)).min(end * self.room).max(a + n);
                    let size = if *wide { 2 } else { 1 };
                    chunk.start = a;
                    chunk.bytes.resize((to - a) * size, 0);
                    read_at(file, &mut chunk.bytes, (a * size) as u64)
                        .map_err(|e| scratch_error("cannot read", *bytes, e))?;
                    if *wide {
                        chunk.wide.clear();
                        chunk.wide.extend(
                            chunk
                                .bytes
                                .chunks_exact(2)
                                .map(|b| u16::from_le_bytes([b[0], b[1]])),
                        );
                    }
                }
                let r = a - chunk.start..a - chunk.start + n;
                Ok(if *wide {
                    SamplesRef::U16(&chunk.wide[r])
                } else {
                    SamplesRef::U8(&chunk.bytes[r])
                })
            }
        }
    }

    /// Adds the prepared frames `frames` (frame index, samples, and their geometry on this
    /// store's problem `p`) as the next views.
    pub(super) fn add(
        &mut self,
        p: &Problem<'_>,
        frames: &[(usize, &Samples, Geom)],
    ) -> Result<(), PhotometricError> {
        let (first, room) = (self.views.len(), self.room);
        match &mut self.data {
            StoreData::U8(d) => fill_blocks(d, p, room, first, frames, |v| v as u8),
            StoreData::U16(d) => fill_blocks(d, p, room, first, frames, |v| v),
            StoreData::File { file, wide, bytes } => {
                let (file, wide, total) = (&*file, *wide, *bytes);
                let size = if wide { 2 } else { 1 };
                p.blocks.par_iter().try_for_each(|b| {
                    let pix = &p.ordered_pix[b.clone()];
                    let mut bytes = Vec::with_capacity(frames.len() * b.len() * size);
                    for (_, samples, _) in frames {
                        for &q in pix {
                            let v = samples.get(q as usize);
                            if wide {
                                bytes.extend_from_slice(&v.to_le_bytes());
                            } else {
                                bytes.push(v as u8);
                            }
                        }
                    }
                    let at = b.start * room + first * b.len();
                    write_at(file, &bytes, (at * size) as u64)
                        .map_err(|e| scratch_error("cannot write", total, e))
                })?;
            }
        }
        self.views
            .extend(frames.iter().map(|&(i, _, geom)| View { i, geom }));
        Ok(())
    }
}

/// Writes the samples of `frames` into the store `data` of problem `p` (room for `room`
/// frames) as views `first ..`: the blocks own disjoint parts of the data, filled in
/// parallel.
pub(super) fn fill_blocks<T: Copy + Send>(
    data: &mut [T],
    p: &Problem<'_>,
    room: usize,
    first: usize,
    frames: &[(usize, &Samples, Geom)],
    conv: impl Fn(u16) -> T + Sync,
) {
    let mut parts = Vec::with_capacity(p.blocks.len());
    let mut rest = data;
    for b in &p.blocks {
        let (head, tail) = rest.split_at_mut(b.len() * room);
        parts.push((b, head));
        rest = tail;
    }
    parts.into_par_iter().for_each(|(b, part)| {
        let pix = &p.ordered_pix[b.clone()];
        for (k, (_, samples, _)) in frames.iter().enumerate() {
            let v = first + k;
            let dst = &mut part[v * b.len()..(v + 1) * b.len()];
            for (d, &q) in dst.iter_mut().zip(pix) {
                *d = conv(samples.get(q as usize));
            }
        }
    });
}

/// Frames decoded at a time while the stores are filled.
pub(super) const LOAD_CHUNK: usize = 16;

/// One visit of the frames before the iterations: the observation graph's connected parts
/// (see [`Graph`]) and the stores of `problems` that fit in `budget` bytes together (the
/// first problems first). Every frame is decoded once.
pub(super) fn load(
    graph_problem: &Problem<'_>,
    problems: &[&Problem<'_>],
    budget: usize,
) -> Result<(Parts, Vec<Option<Store>>), PhotometricError> {
    let n = graph_problem.frames.len();
    let bits = graph_problem.u.len().trailing_zeros();
    let mut left = budget;
    let mut stores: Vec<Option<Store>> = Vec::with_capacity(problems.len());
    for p in problems {
        let s = Store::new(p, bits, left)?;
        left -= s.as_ref().map_or(0, Store::memory_bytes);
        stores.push(s);
    }
    let mut graph = Graph::new(graph_problem);
    let indices: Vec<usize> = (0..n).collect();
    for chunk in indices.chunks(LOAD_CHUNK.max(rayon::current_num_threads())) {
        let prepared: Vec<(usize, Prepared)> = chunk
            .par_iter()
            .map(|&i| Ok(graph_problem.prepare(i)?.map(|pf| (i, pf))))
            .collect::<Result<Vec<_>, PhotometricError>>()?
            .into_iter()
            .flatten()
            .collect();
        for (_, pf) in &prepared {
            graph.add(pf);
        }
        for (store, p) in stores.iter_mut().zip(problems) {
            let Some(store) = store else {
                continue;
            };
            let frames: Vec<(usize, &Samples, Geom)> = prepared
                .iter()
                .filter_map(|(i, pf)| {
                    p.geom(&pf.pose, pf.geom.exposure_ms)
                        .map(|g| (*i, &pf.samples, g))
                })
                .collect();
            store.add(p, &frames)?;
        }
    }
    Ok((graph.finish(), stores))
}
