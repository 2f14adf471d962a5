//! A minimal owned, row-major, single-channel image shared by the monovo crates.

use crate::CameraError;

/// A single-channel image stored row by row, `data[y * width + x]`.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Image<T> {
    width: usize,
    height: usize,
    data: Vec<T>,
}

impl<T: Copy> Image<T> {
    /// Wraps a buffer; fails when its length is not `width * height`.
    pub fn new(width: usize, height: usize, data: Vec<T>) -> Result<Self, CameraError> {
        if width.checked_mul(height) != Some(data.len()) {
            return Err(CameraError::BufferLength {
                width,
                height,
                len: data.len(),
            });
        }
        Ok(Image {
            width,
            height,
            data,
        })
    }

    /// An image with every pixel set to `value`.
    pub fn filled(width: usize, height: usize, value: T) -> Self {
        Image {
            width,
            height,
            data: vec![value; width * height],
        }
    }

    /// An image whose pixel `(x, y)` is `f(x, y)`.
    pub fn from_fn(width: usize, height: usize, mut f: impl FnMut(usize, usize) -> T) -> Self {
        let mut data = Vec::with_capacity(width * height);
        for y in 0..height {
            for x in 0..width {
                data.push(f(x, y));
            }
        }
        Image {
            width,
            height,
            data,
        }
    }

    /// Width in pixels.
    #[inline]
    pub fn width(&self) -> usize {
        self.width
    }

    /// Height in pixels.
    #[inline]
    pub fn height(&self) -> usize {
        self.height
    }

    /// `(width, height)`.
    #[inline]
    pub fn size(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    /// The pixel at `(x, y)`, or `None` outside the image.
    #[inline]
    pub fn get(&self, x: usize, y: usize) -> Option<T> {
        if x < self.width && y < self.height {
            self.data.get(y * self.width + x).copied()
        } else {
            None
        }
    }

    /// The pixels, row by row.
    #[inline]
    pub fn data(&self) -> &[T] {
        &self.data
    }

    /// The pixels, row by row, mutable.
    #[inline]
    pub fn data_mut(&mut self) -> &mut [T] {
        &mut self.data
    }

    /// Row `y`.
    #[inline]
    pub fn row(&self, y: usize) -> &[T] {
        &self.data[y * self.width..(y + 1) * self.width]
    }

    /// Gives the buffer back.
    pub fn into_data(self) -> Vec<T> {
        self.data
    }

    /// Applies `f` to every pixel.
    pub fn map<U: Copy>(&self, f: impl FnMut(T) -> U) -> Image<U> {
        Image {
            width: self.width,
            height: self.height,
            data: self.data.iter().copied().map(f).collect(),
        }
    }
}
