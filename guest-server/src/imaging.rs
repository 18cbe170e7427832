//! Platform-neutral image work: encoding, downscaling, black-frame detection
//! and drawing the cursor, shared by every backend and both APIs.

use std::io::Cursor;

use arena_shared::fastimg;
use arena_shared::geometry::Point;
use arena_shared::observation::ImageFormat;
use image::RgbaImage;

/// An image could not be encoded or decoded.
#[derive(Debug, thiserror::Error)]
#[error("{what}: {source}")]
pub struct ImagingError {
    what: &'static str,
    #[source]
    source: image::ImageError,
}

/// Encodes `image` as PNG (fast compression) or JPEG at `quality` (1 to 100).
///
/// JPEG goes through [`fastimg::encode_jpeg`] (SIMD, 4:2:0 like Pillow), which drops
/// the alpha byte as converting to RGB first would.
///
/// # Errors
///
/// [`ImagingError`] if the encoder fails.
pub fn encode(image: &RgbaImage, format: ImageFormat, quality: u8) -> Result<Vec<u8>, ImagingError> {
    let what = if format == ImageFormat::Jpeg { "encoding JPEG" } else { "encoding PNG" };
    arena_shared::imaging::encode(image, format, quality).map_err(|source| ImagingError { what, source })
}

/// Largest image side accepted for decoding: four 4K screens side by side.
pub const MAX_DECODED_SIDE: u32 = 16_384;
/// Most memory one decode may allocate: a 8K screen in RGBA with room to spare.
pub const MAX_DECODED_BYTES: u64 = 256 << 20;

/// Decodes PNG, JPEG (or any format this build reads) into RGBA, refusing one that
/// claims more than [`MAX_DECODED_SIDE`] pixels a side, or whose RGBA form would take
/// more than [`MAX_DECODED_BYTES`], from its header, before any pixel is decoded.
///
/// The size counted is the RGBA one every caller converts to, not the file's own
/// pixel format: a gray or 1-bit PNG takes a quarter or a thirty-second of its RGBA
/// size to decode, then is expanded, so counting its native size let a 250 KB gray
/// PNG claim 1 GiB of RGBA. The native decode is bounded by the same figure, so one
/// decode holds at most twice [`MAX_DECODED_BYTES`] at its peak (native and RGBA).
///
/// # Errors
///
/// The bytes are not an image this build decodes, or the image is over the limits.
pub fn decode(bytes: &[u8]) -> Result<RgbaImage, ImagingError> {
    use image::ImageDecoder as _;
    let mut reader = image::ImageReader::new(Cursor::new(bytes))
        .with_guessed_format()
        .map_err(|err| ImagingError { what: "reading image", source: image::ImageError::IoError(err) })?;
    // Checked from the header, before any pixel is decoded: a few hundred KB of PNG
    // can claim gigabytes of pixels.
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(MAX_DECODED_SIDE);
    limits.max_image_height = Some(MAX_DECODED_SIDE);
    limits.max_alloc = Some(MAX_DECODED_BYTES);
    reader.limits(limits.clone());
    let mut decoder = reader.into_decoder().map_err(|source| ImagingError { what: "decoding image", source })?;
    let (width, height) = decoder.dimensions();
    let rgba = u64::from(width) * u64::from(height) * 4;
    if rgba > MAX_DECODED_BYTES {
        return Err(ImagingError {
            what: "decoding image",
            source: image::ImageError::Limits(image::error::LimitError::from_kind(
                image::error::LimitErrorKind::InsufficientMemory,
            )),
        });
    }
    decoder.set_limits(limits).map_err(|source| ImagingError { what: "decoding image", source })?;
    image::DynamicImage::from_decoder(decoder)
        .map(|img| img.into_rgba8())
        .map_err(|source| ImagingError { what: "decoding image", source })
}

/// Downscales `image` so that its longer side is at most `max_side`, keeping the aspect ratio.
///
/// Returns the image and the scale, in source pixels per returned pixel (1.0 when unchanged).
pub fn downscale_to_fit(image: RgbaImage, max_side: u32) -> (RgbaImage, f64) {
    let longest = image.width().max(image.height());
    if max_side == 0 || longest <= max_side {
        return (image, 1.0);
    }
    let scale = f64::from(longest) / f64::from(max_side);
    let width = ((f64::from(image.width()) / scale).round() as u32).max(1);
    let height = ((f64::from(image.height()) / scale).round() as u32).max(1);
    // The bilinear (triangle) convolution the `image` crate's `Triangle` is, with SIMD; an
    // image with a side of 0 (the one case the fast path refuses) takes the old path.
    let resized = fastimg::resize_rgba(&image, width, height, fastimg::Filter::Bilinear)
        .unwrap_or_else(|_| image::imageops::resize(&image, width, height, image::imageops::FilterType::Triangle));
    (resized, scale)
}

/// Whether every pixel is black (a locked, secure or disconnected desktop).
pub fn is_black(image: &RgbaImage) -> bool {
    image.pixels().all(|p| p.0[0] == 0 && p.0[1] == 0 && p.0[2] == 0)
}

/// Width and height of the area around the cursor's hot spot that a drawn cursor may cover
/// (Windows cursors are at most 32x32 at 100 % scale, 64x64 at 200 %).
pub const CURSOR_BOX: u32 = 64;

/// Whether every pixel outside the `size`x`size` box whose top-left corner is `at` is black:
/// [`is_black`] for a frame with a cursor drawn into it.
pub fn is_black_outside(image: &RgbaImage, at: Point, size: u32) -> bool {
    let size = i64::from(size);
    image.enumerate_pixels().all(|(x, y, p)| {
        let (dx, dy) = (i64::from(x) - i64::from(at.x), i64::from(y) - i64::from(at.y));
        let covered = (0..size).contains(&dx) && (0..size).contains(&dy);
        covered || (p.0[0] == 0 && p.0[1] == 0 && p.0[2] == 0)
    })
}

/// The arrow cursor upstream pastes into `/screenshot`: 13x21 pixels, tip at the top-left.
/// `#` is the black outline, `o` the white fill.
const CURSOR: [&str; 21] = [
    "#            ",
    "##           ",
    "#o#          ",
    "#oo#         ",
    "#ooo#        ",
    "#oooo#       ",
    "#ooooo#      ",
    "#oooooo#     ",
    "#ooooooo#    ",
    "#oooooooo#   ",
    "#ooooooooo#  ",
    "#oooooooooo# ",
    "#oooooo######",
    "#ooo#oo#     ",
    "#oo# #oo#    ",
    "#o#  #oo#    ",
    "##    #oo#   ",
    "#     #oo#   ",
    "       #oo#  ",
    "       #oo#  ",
    "        ##   ",
];

/// Draws the arrow cursor with its tip at `at`, clipped to the image.
pub fn draw_cursor(image: &mut RgbaImage, at: Point) {
    for (dy, row) in CURSOR.iter().enumerate() {
        for (dx, c) in row.chars().enumerate() {
            let color = match c {
                '#' => image::Rgba([0, 0, 0, 255]),
                'o' => image::Rgba([255, 255, 255, 255]),
                _ => continue,
            };
            let (x, y) = (at.x + dx as i32, at.y + dy as i32);
            if x >= 0 && y >= 0 && (x as u32) < image.width() && (y as u32) < image.height() {
                image.put_pixel(x as u32, y as u32, color);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use arena_test_support::png_claiming as png_claiming_as;

    #[test]
    fn png_round_trips() {
        let mut img = RgbaImage::from_pixel(40, 30, image::Rgba([10, 20, 30, 255]));
        draw_cursor(&mut img, Point::new(5, 5));
        let bytes = encode(&img, ImageFormat::Png, 90).unwrap();
        assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
        let back = decode(&bytes).unwrap();
        assert_eq!(back, img);
    }

    /// A PNG of `width` x `height` in RGBA whose header is all there is: what a
    /// decompression bomb claims before a single pixel is read.
    fn png_claiming(width: u32, height: u32) -> Vec<u8> {
        png_claiming_as(width, height, 8, 6)
    }

    #[test]
    fn images_claiming_too_many_pixels_are_refused_before_decoding() {
        let limited = |result: Result<RgbaImage, ImagingError>| {
            matches!(result, Err(ImagingError { source: image::ImageError::Limits(_), .. }))
        };
        // 20 000 pixels a side: over the side limit.
        assert!(limited(decode(&png_claiming(20_000, 10))));
        // 12 000 x 12 000 RGBA is 576 MB: under the side limit, over the memory limit.
        assert!(limited(decode(&png_claiming(12_000, 12_000))));
        // A small claim passes the limits and fails on its (empty) pixel data instead.
        let small = decode(&png_claiming(4, 4));
        assert!(small.is_err() && !limited(small), "a 4x4 image is within the limits");
        // Gray and 1-bit images are counted as the RGBA they become: 16384 x 16000 gray
        // is 250 MiB natively, under the limit, but 1000 MiB as RGBA.
        assert!(limited(decode(&png_claiming_as(16_384, 16_000, 8, 0))));
        assert!(limited(decode(&png_claiming_as(16_384, 16_384, 1, 0))));
        // 8000 x 8000 gray is 244 MiB as RGBA: within the limits.
        let gray = decode(&png_claiming_as(8_000, 8_000, 8, 0));
        assert!(gray.is_err() && !limited(gray), "8000 x 8000 gray is within the limits");
    }

    #[test]
    fn jpeg_has_its_magic() {
        let img = RgbaImage::from_pixel(16, 16, image::Rgba([200, 0, 0, 255]));
        let bytes = encode(&img, ImageFormat::Jpeg, 80).unwrap();
        assert_eq!(&bytes[..2], &[0xFF, 0xD8]);
        let back = decode(&bytes).unwrap();
        assert_eq!(back.dimensions(), (16, 16));
        let p = back.get_pixel(8, 8).0;
        assert!(p[0] > 180 && p[1] < 30 && p[2] < 30, "{p:?}");
    }

    #[test]
    fn downscale_keeps_colours_and_survives_an_empty_side() {
        let img = RgbaImage::from_fn(1440, 900, |x, _| {
            if x < 720 {
                image::Rgba([0, 0, 255, 255])
            } else {
                image::Rgba([255, 255, 0, 255])
            }
        });
        let (small, _) = downscale_to_fit(img, 720);
        assert_eq!(small.get_pixel(100, 200).0, [0, 0, 255, 255]);
        assert_eq!(small.get_pixel(600, 200).0, [255, 255, 0, 255]);
        let (empty, _) = downscale_to_fit(RgbaImage::new(2000, 0), 720);
        assert_eq!(empty.width(), 720);
    }

    #[test]
    fn downscale_keeps_aspect_and_states_scale() {
        let img = RgbaImage::new(1440, 900);
        let (small, scale) = downscale_to_fit(img, 720);
        assert_eq!((small.width(), small.height()), (720, 450));
        assert!((scale - 2.0).abs() < 1e-9);
        let (same, scale) = downscale_to_fit(RgbaImage::new(100, 50), 720);
        assert_eq!((same.width(), scale), (100, 1.0));
    }

    #[test]
    fn black_detection() {
        let mut img = RgbaImage::from_pixel(8, 8, image::Rgba([0, 0, 0, 255]));
        assert!(is_black(&img));
        img.put_pixel(3, 3, image::Rgba([0, 1, 0, 255]));
        assert!(!is_black(&img));
    }

    #[test]
    fn a_drawn_cursor_does_not_hide_a_black_frame() {
        let mut img = RgbaImage::from_pixel(100, 100, image::Rgba([0, 0, 0, 255]));
        draw_cursor(&mut img, Point::new(40, 40));
        assert!(!is_black(&img));
        assert!(is_black_outside(&img, Point::new(40, 40), CURSOR_BOX));
        img.put_pixel(5, 5, image::Rgba([9, 9, 9, 255]));
        assert!(!is_black_outside(&img, Point::new(40, 40), CURSOR_BOX));
    }

    #[test]
    fn cursor_is_clipped_at_edges() {
        let mut img = RgbaImage::new(10, 10);
        draw_cursor(&mut img, Point::new(8, 8));
        draw_cursor(&mut img, Point::new(-5, -5));
        assert_eq!(img.get_pixel(8, 8).0, [0, 0, 0, 255]);
    }

    #[test]
    fn garbage_is_not_an_image() {
        assert!(decode(b"not an image").is_err());
    }
}
