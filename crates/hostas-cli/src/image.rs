//! RGBA8 images for the `hostas` command's rendered output, saved as PNG.

use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

/// An 8-bit RGBA image, rows top to bottom, pixels left to right.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Image {
    pub width: u32,
    pub height: u32,
    /// `width * height * 4` bytes.
    pub rgba: Vec<u8>,
}

/// Why an image could not be saved.
#[derive(Debug, thiserror::Error)]
pub enum ImageError {
    #[error("{path}: cannot write: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: cannot encode PNG: {source}")]
    Encode {
        path: PathBuf,
        #[source]
        source: png::EncodingError,
    },
    #[error("{path}: image is {width}x{height} but has {len} bytes of pixels")]
    BadSize {
        path: PathBuf,
        width: u32,
        height: u32,
        len: usize,
    },
}

impl Image {
    /// A transparent black image.
    pub fn new(width: u32, height: u32) -> Self {
        Image {
            width,
            height,
            rgba: vec![0; width as usize * height as usize * 4],
        }
    }

    /// Sets the pixel at column `x`, row `y` (row 0 is the top).
    ///
    /// # Panics
    /// If the pixel is outside the image.
    pub fn put(&mut self, x: u32, y: u32, rgba: [u8; 4]) {
        assert!(
            x < self.width && y < self.height,
            "pixel ({x}, {y}) is outside the {}x{} image",
            self.width,
            self.height
        );
        let at = (y as usize * self.width as usize + x as usize) * 4;
        self.rgba[at..at + 4].copy_from_slice(&rgba);
    }

    /// The pixel at column `x`, row `y`, or `None` outside the image.
    pub fn get(&self, x: u32, y: u32) -> Option<[u8; 4]> {
        if x >= self.width || y >= self.height {
            return None;
        }
        let at = (y as usize * self.width as usize + x as usize) * 4;
        self.rgba.get(at..at + 4)?.try_into().ok()
    }

    /// Writes the image as an 8-bit RGBA PNG.
    pub fn save_png(&self, path: &Path) -> Result<(), ImageError> {
        if self.rgba.len() != self.width as usize * self.height as usize * 4 {
            return Err(ImageError::BadSize {
                path: path.to_owned(),
                width: self.width,
                height: self.height,
                len: self.rgba.len(),
            });
        }
        let encode_error = |source| ImageError::Encode {
            path: path.to_owned(),
            source,
        };
        let file = File::create(path).map_err(|source| ImageError::Io {
            path: path.to_owned(),
            source,
        })?;
        let mut encoder = png::Encoder::new(BufWriter::new(file), self.width, self.height);
        encoder.set_color(png::ColorType::Rgba);
        encoder.set_depth(png::BitDepth::Eight);
        let mut writer = encoder.write_header().map_err(encode_error)?;
        writer.write_image_data(&self.rgba).map_err(encode_error)?;
        writer.finish().map_err(encode_error)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn png_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.png");
        let mut image = Image::new(5, 3);
        image.put(4, 2, [10, 20, 30, 255]);
        image.put(0, 0, [255, 0, 0, 128]);
        image.save_png(&path).unwrap();

        let decoder = png::Decoder::new(std::io::BufReader::new(File::open(&path).unwrap()));
        let mut reader = decoder.read_info().unwrap();
        let mut buf = vec![0; reader.output_buffer_size().unwrap()];
        let info = reader.next_frame(&mut buf).unwrap();
        assert_eq!((info.width, info.height), (5, 3));
        assert_eq!(info.color_type, png::ColorType::Rgba);
        assert_eq!(info.bit_depth, png::BitDepth::Eight);
        let pixels = &buf[..info.buffer_size()];
        assert_eq!(pixels, image.rgba.as_slice());
        let at = (2 * 5 + 4) * 4;
        assert_eq!(pixels[at..at + 4], [10, 20, 30, 255]);
        assert_eq!(pixels[..4], [255, 0, 0, 128]);
        assert_eq!(image.get(4, 2), Some([10, 20, 30, 255]));
        assert_eq!(image.get(5, 0), None);
    }

    #[test]
    fn wrong_buffer_size_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        let mut image = Image::new(2, 2);
        image.rgba.pop();
        let err = image.save_png(&dir.path().join("bad.png")).unwrap_err();
        assert!(matches!(err, ImageError::BadSize { .. }), "{err}");
    }

    #[test]
    #[should_panic(expected = "outside")]
    fn put_outside_panics() {
        Image::new(2, 2).put(2, 0, [0; 4]);
    }
}
