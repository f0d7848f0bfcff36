//! Grey camera frames in memory and as 8- or 16-bit grey PNG files.

use std::path::Path;

use image::{DynamicImage, ImageBuffer, Luma};
use serde::{Deserialize, Serialize};

use crate::VisionError;

/// Bits per pixel of a grey frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum BitDepth {
    /// Grey levels 0..=255.
    Eight,
    /// Grey levels 0..=65535.
    Sixteen,
}

impl BitDepth {
    /// The largest grey level.
    pub fn max_level(self) -> f32 {
        match self {
            BitDepth::Eight => 255.0,
            BitDepth::Sixteen => 65535.0,
        }
    }
}

/// `level` rounded to the nearest integer (halves away from zero) and
/// clamped to `[0, max]`. The rounding is done as the floor of `level + 1/2`
/// in `f64` (exact for any `f32`), taken by truncation after clamping at
/// zero, which gives `level.round()` bit for bit without a call to `roundf`.
pub(crate) fn quantise(level: f32, max: f32) -> f32 {
    ((f64::from(level.max(0.0)) + 0.5) as u64 as f32).min(max)
}

/// A grey frame: row-major grey levels (`pixels[row * width + column]`), as
/// `f32` in the range of its bit depth. Pixel $(u, v)$ has its centre at
/// column $u$, row $v$.
#[derive(Debug, Clone, PartialEq)]
pub struct GreyFrame {
    /// Columns.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// The bit depth the frame was read with or will be written with.
    pub bit_depth: BitDepth,
    /// Grey levels, row-major.
    pub pixels: Vec<f32>,
}

impl GreyFrame {
    /// A frame filled with one grey level.
    pub fn filled(width: usize, height: usize, bit_depth: BitDepth, level: f32) -> GreyFrame {
        GreyFrame {
            width,
            height,
            bit_depth,
            pixels: vec![level; width * height],
        }
    }

    /// Grey level at column `u`, row `v`.
    pub fn at(&self, u: usize, v: usize) -> f32 {
        self.pixels[v * self.width + u]
    }

    /// Standard deviation of the grey levels (a frame-level contrast check).
    pub fn grey_level_spread(&self) -> f64 {
        let count = self.pixels.len().max(1) as f64;
        let mean = self.pixels.iter().map(|&p| p as f64).sum::<f64>() / count;
        let variance = self
            .pixels
            .iter()
            .map(|&p| (p as f64 - mean).powi(2))
            .sum::<f64>()
            / count;
        variance.sqrt()
    }

    /// Read an 8- or 16-bit grey PNG.
    pub fn read_png(path: &Path) -> Result<GreyFrame, VisionError> {
        let bytes = std::fs::read(path).map_err(|source| VisionError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let decoded = image::load_from_memory_with_format(&bytes, image::ImageFormat::Png)
            .map_err(|e| VisionError::Png {
                path: path.to_path_buf(),
                reason: e.to_string(),
            })?;
        let (width, height) = (decoded.width() as usize, decoded.height() as usize);
        match decoded {
            DynamicImage::ImageLuma8(buffer) => Ok(GreyFrame {
                width,
                height,
                bit_depth: BitDepth::Eight,
                pixels: buffer.into_raw().into_iter().map(f32::from).collect(),
            }),
            DynamicImage::ImageLuma16(buffer) => Ok(GreyFrame {
                width,
                height,
                bit_depth: BitDepth::Sixteen,
                pixels: buffer.into_raw().into_iter().map(f32::from).collect(),
            }),
            other => Err(VisionError::PixelFormat {
                path: path.to_path_buf(),
                found: format!("{:?}", other.color()),
            }),
        }
    }

    /// Write as a grey PNG of the frame's bit depth, rounding and clamping
    /// each grey level. The file appears under its final name only once it
    /// is complete.
    pub fn write_png(&self, path: &Path) -> Result<(), VisionError> {
        let max = self.bit_depth.max_level();
        let image: DynamicImage = match self.bit_depth {
            BitDepth::Eight => DynamicImage::ImageLuma8(
                ImageBuffer::<Luma<u8>, _>::from_raw(
                    self.width as u32,
                    self.height as u32,
                    self.pixels
                        .iter()
                        .map(|&p| quantise(p, max) as u8)
                        .collect(),
                )
                .ok_or_else(|| self.size_error(path))?,
            ),
            BitDepth::Sixteen => DynamicImage::ImageLuma16(
                ImageBuffer::<Luma<u16>, _>::from_raw(
                    self.width as u32,
                    self.height as u32,
                    self.pixels
                        .iter()
                        .map(|&p| quantise(p, max) as u16)
                        .collect(),
                )
                .ok_or_else(|| self.size_error(path))?,
            ),
        };
        let partial = path.with_extension("png.partial");
        image
            .save_with_format(&partial, image::ImageFormat::Png)
            .map_err(|e| VisionError::Png {
                path: path.to_path_buf(),
                reason: e.to_string(),
            })?;
        std::fs::rename(&partial, path).map_err(|source| VisionError::Io {
            path: path.to_path_buf(),
            source,
        })
    }

    fn size_error(&self, path: &Path) -> VisionError {
        VisionError::InvalidParameter {
            field: "frame",
            reason: format!(
                "{}: {} pixels do not fill {} x {}",
                path.display(),
                self.pixels.len(),
                self.width,
                self.height
            ),
        }
    }
}
