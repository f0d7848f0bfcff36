//! Whether a file is a PNG image of 8- or 16-bit grey, as the format asks of
//! camera frames and calibration images, judged from its first 26 bytes.
//!
//! The bundle reader does not decode images (the vision crate does), but a
//! frame that is not such an image would otherwise pass validation and stop
//! the tracker only after the calibration and the earlier frames; the header
//! alone catches a corrupt, empty, colour or misnamed file before any
//! computation.

use std::fs::File;
use std::io::Read;
use std::path::Path;

/// Every PNG file starts with these eight bytes.
const SIGNATURE: [u8; 8] = [0x89, b'P', b'N', b'G', b'\r', b'\n', 0x1a, b'\n'];

/// The PNG colour type of grey without alpha.
const GREY: u8 = 0;

/// Why the file at `path` is not a PNG of 8- or 16-bit grey, if it is not.
pub(crate) fn grey_png_problem(path: &Path) -> Option<String> {
    let mut head = [0u8; 26];
    let read = File::open(path).and_then(|mut file| {
        let mut filled = 0;
        while filled < head.len() {
            match file.read(&mut head[filled..])? {
                0 => break,
                n => filled += n,
            }
        }
        Ok(filled)
    });
    let filled = match read {
        Ok(filled) => filled,
        Err(err) => return Some(format!("cannot be read: {err}")),
    };
    if filled < SIGNATURE.len() || head[..8] != SIGNATURE {
        return Some("is not a PNG image (its first bytes are not PNG's signature)".to_owned());
    }
    // The first chunk must be IHDR, 13 bytes long.
    if filled < head.len() || head[8..16] != [0, 0, 0, 13, b'I', b'H', b'D', b'R'] {
        return Some("is a truncated or malformed PNG (no image header)".to_owned());
    }
    let width = u32::from_be_bytes([head[16], head[17], head[18], head[19]]);
    let height = u32::from_be_bytes([head[20], head[21], head[22], head[23]]);
    let (depth, colour) = (head[24], head[25]);
    if width == 0 || height == 0 {
        return Some(format!("is an empty image ({width} x {height} pixels)"));
    }
    if colour != GREY || !matches!(depth, 8 | 16) {
        return Some(format!(
            "is a PNG of colour type {colour} at {depth} bits; the format asks for 8- or 16-bit grey (colour type 0)"
        ));
    }
    None
}

#[cfg(test)]
mod tests {
    use super::grey_png_problem;

    /// A PNG header: signature, IHDR length and name, size, depth, colour.
    fn header(width: u32, height: u32, depth: u8, colour: u8) -> Vec<u8> {
        let mut bytes = super::SIGNATURE.to_vec();
        bytes.extend_from_slice(&[0, 0, 0, 13]);
        bytes.extend_from_slice(b"IHDR");
        bytes.extend_from_slice(&width.to_be_bytes());
        bytes.extend_from_slice(&height.to_be_bytes());
        bytes.extend_from_slice(&[depth, colour, 0, 0, 0]);
        bytes
    }

    fn problem(bytes: &[u8]) -> Option<String> {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("000001.png");
        std::fs::write(&path, bytes).unwrap();
        grey_png_problem(&path)
    }

    #[test]
    fn grey_of_8_and_16_bits_passes_and_the_rest_is_named() {
        assert_eq!(problem(&header(2056, 1544, 8, 0)), None);
        assert_eq!(problem(&header(4, 3, 16, 0)), None);
        let colour = problem(&header(4, 3, 8, 2)).unwrap();
        assert!(colour.contains("colour type 2"), "{colour}");
        let one_bit = problem(&header(4, 3, 1, 0)).unwrap();
        assert!(one_bit.contains("at 1 bits"), "{one_bit}");
        assert!(
            problem(&header(0, 3, 8, 0))
                .unwrap()
                .contains("empty image")
        );
        assert!(problem(b"garbage\n").unwrap().contains("not a PNG"));
        assert!(problem(b"").unwrap().contains("not a PNG"));
        assert!(
            problem(&header(4, 3, 8, 0)[..20])
                .unwrap()
                .contains("truncated")
        );
    }

    #[test]
    fn images_the_png_encoder_writes_pass_in_grey_and_fail_in_colour() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("000001.png");
        image::ImageBuffer::<image::Luma<u16>, _>::new(4, 3)
            .save(&path)
            .unwrap();
        assert_eq!(grey_png_problem(&path), None);
        image::GrayImage::new(4, 3).save(&path).unwrap();
        assert_eq!(grey_png_problem(&path), None);
        image::RgbImage::new(4, 3).save(&path).unwrap();
        assert!(grey_png_problem(&path).unwrap().contains("colour type 2"));
    }
}
