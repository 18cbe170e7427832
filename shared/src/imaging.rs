//! Cropping as Pillow crops, the one crop both sides use, and the one image encoder.
//!
//! Agent code asks for regions of screenshots (`pyautogui.screenshot(region=...)`,
//! `computer.clipboard.copy_image`), and upstream's guest answers them with
//! Pillow's `Image.crop`, which pads whatever lies outside the image with black.
//! The guest's script host, the WAA observation route and the host's agent
//! executor all crop through [`crop_padded`], so the same code gives the same
//! pixels wherever it runs.
//!
//! [`encode`] is the one PNG encoder and the way to JPEG (through
//! [`crate::fastimg::encode_jpeg`], which the model-image path of [`crate::fastimg`]
//! uses too): the guest's screenshot routes, its MCP screenshot, and both script hosts'
//! saved screenshots and clipboard images. (The host's agents still encode PNG in three
//! places of their own, which the host's part of issue 28 brings here.)

use image::error::{EncodingError, ImageFormatHint};
use image::{ImageEncoder, Rgba, RgbaImage};

use crate::fastimg::{self, Layout};
use crate::observation::ImageFormat;

/// Largest crop in pixels (256 Mpx): a bigger box is refused rather than allocated.
pub const MAX_CROP_PIXELS: u64 = 1 << 28;

/// Why a box cannot be cropped; the first two are Pillow's own `ValueError` texts.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CropError {
    #[error("Coordinate 'right' is less than 'left'")]
    RightBeforeLeft,
    #[error("Coordinate 'lower' is less than 'upper'")]
    LowerBeforeUpper,
    #[error("a {width}x{height} crop is too large")]
    TooLarge { width: u64, height: u64 },
}

/// `image.crop((left, top, right, bottom))` with Pillow's semantics: the result is
/// `right - left` by `bottom - top`, and parts outside `image` are black. The result is
/// opaque (screenshots are RGB in Pillow; alpha is set to 255).
///
/// # Errors
///
/// A box whose right edge is left of its left edge (or bottom above top), or one of
/// more than [`MAX_CROP_PIXELS`] pixels.
pub fn crop_padded(image: &RgbaImage, left: i64, top: i64, right: i64, bottom: i64) -> Result<RgbaImage, CropError> {
    if right < left {
        return Err(CropError::RightBeforeLeft);
    }
    if bottom < top {
        return Err(CropError::LowerBeforeUpper);
    }
    let (width, height) = (right.abs_diff(left), bottom.abs_diff(top));
    if width.saturating_mul(height) > MAX_CROP_PIXELS {
        return Err(CropError::TooLarge { width, height });
    }
    // A zero-height box may still be absurdly wide; such a size does not fit in u32.
    let too_large = || CropError::TooLarge { width, height };
    let (w, h) = (u32::try_from(width).map_err(|_| too_large())?, u32::try_from(height).map_err(|_| too_large())?);
    let mut out = RgbaImage::from_pixel(w, h, Rgba([0, 0, 0, 255]));
    // The part of the box that lies on the image, in image coordinates.
    let x0 = left.clamp(0, i64::from(image.width()));
    let x1 = right.clamp(0, i64::from(image.width()));
    let y0 = top.clamp(0, i64::from(image.height()));
    let y1 = bottom.clamp(0, i64::from(image.height()));
    for sy in y0..y1 {
        for sx in x0..x1 {
            // In range by the clamps above.
            let mut pixel = *image.get_pixel(sx as u32, sy as u32);
            pixel.0[3] = 255;
            out.put_pixel((sx - left) as u32, (sy - top) as u32, pixel);
        }
    }
    Ok(out)
}

/// Encodes `image` as PNG (fast compression) or JPEG at `quality` (1 to 100).
///
/// JPEG goes through [`fastimg::encode_jpeg`] (SIMD, 4:2:0 like Pillow), which drops
/// the alpha byte as converting to RGB first would. [`ImageFormat::Unknown`] is PNG.
///
/// # Errors
///
/// The encoder's error, for example a JPEG side over 65 535 pixels.
pub fn encode(image: &RgbaImage, format: ImageFormat, quality: u8) -> Result<Vec<u8>, image::ImageError> {
    match format {
        ImageFormat::Jpeg => {
            fastimg::encode_jpeg(image.as_raw(), image.width(), image.height(), Layout::Rgba8, quality).map_err(|err| {
                image::ImageError::Encoding(EncodingError::new(ImageFormatHint::Exact(image::ImageFormat::Jpeg), err))
            })
        }
        ImageFormat::Png | ImageFormat::Unknown => {
            let mut out = Vec::with_capacity(image.as_raw().len() / 4);
            image::codecs::png::PngEncoder::new_with_quality(
                &mut out,
                image::codecs::png::CompressionType::Fast,
                image::codecs::png::FilterType::Adaptive,
            )
            .write_image(image.as_raw(), image.width(), image.height(), image::ExtendedColorType::Rgba8)?;
            Ok(out)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 4x4 image whose pixel (x, y) is (x, y, 7, 40).
    fn image() -> RgbaImage {
        RgbaImage::from_fn(4, 4, |x, y| Rgba([x as u8, y as u8, 7, 40]))
    }

    /// A pixel of the crop and the source pixel it must show (`None`: black padding).
    type Expect = ((u32, u32), Option<(u8, u8)>);

    /// Crops `ltrb` and compares size and a few pixels.
    fn check(ltrb: [i64; 4], size: (u32, u32), pixels: &[Expect]) {
        let [l, t, r, b] = ltrb;
        let crop = crop_padded(&image(), l, t, r, b).expect("crop");
        assert_eq!(crop.dimensions(), size, "{ltrb:?}");
        for &((x, y), want) in pixels {
            let got = crop.get_pixel(x, y).0;
            let want = want.map_or([0, 0, 0, 255], |(sx, sy)| [sx, sy, 7, 255]);
            assert_eq!(got, want, "{ltrb:?} at ({x}, {y})");
        }
    }

    #[test]
    fn crops_inside_the_image() {
        check([1, 1, 3, 4], (2, 3), &[((0, 0), Some((1, 1))), ((1, 2), Some((2, 3)))]);
        check([0, 0, 4, 4], (4, 4), &[((3, 3), Some((3, 3)))]);
    }

    #[test]
    fn pads_what_lies_outside_with_black_like_pillow() {
        check([2, 2, 6, 5], (4, 3), &[((0, 0), Some((2, 2))), ((1, 1), Some((3, 3))), ((2, 0), None), ((3, 2), None)]);
        check(
            [-2, -1, 2, 1],
            (4, 2),
            &[((0, 0), None), ((1, 1), None), ((2, 1), Some((0, 0))), ((3, 1), Some((1, 0)))],
        );
        // Entirely off the image: all black, still the asked size.
        check([-32000, -32000, -31990, -31995], (10, 5), &[((0, 0), None), ((9, 4), None)]);
        check([2, 2, 2, 3], (0, 1), &[]);
    }

    #[test]
    fn refuses_inverted_and_huge_boxes() {
        let img = image();
        assert_eq!(crop_padded(&img, 3, 0, 1, 1), Err(CropError::RightBeforeLeft));
        assert_eq!(crop_padded(&img, 0, 3, 1, 1), Err(CropError::LowerBeforeUpper));
        assert_eq!(CropError::RightBeforeLeft.to_string(), "Coordinate 'right' is less than 'left'");
        assert!(matches!(crop_padded(&img, 0, 0, 1 << 20, 1 << 20), Err(CropError::TooLarge { .. })));
        assert!(matches!(crop_padded(&img, i64::MIN, 0, i64::MAX, 1), Err(CropError::TooLarge { .. })));
    }
}
